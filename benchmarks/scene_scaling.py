"""Scene scaling (issue 5, part c): a Cornell box with curved objects at growing patch counts.

Five walls, a ceiling light quad, two spheres and a curved NURBS shell, split into ~100, 250, 500
and 1000 patches. For each size: `core.Scene.solve` with occlusion (per-stage times from
`Solution.stats`), memory (tracemalloc peak of the solve and the process's peak RSS), gathering
`radiosity_at` on ~20 points per patch (solve and gather timed REPEAT times, medians), a relight
(`set_material` then `solve`), and a solve with each culling rule off (the `cull=` argument of
`Scene.solve`).

Run alone: python -m benchmarks.scene_scaling [--quick]
"""

import argparse
import resource
import statistics
import time
import tracemalloc

import numpy as np

import core

SIZES = (100, 250, 500, 1000)
CULL_RULES = ("facing", "shaft", "rows", "columns")
GATHER_PER_PATCH = 20
REPEAT = 3  # timed solve + gather runs per size (a shared machine: medians)
WITH_NURBS = [True]  # the NURBS shell makes the form-factor stage slow (generic inner integral)


def have_scene():
    return hasattr(core, "Scene")


def nurbs_shell():
    """A curved NURBS shell (a quarter-cylinder-like bent sheet, degree 2 x 2) in the box."""
    u = np.linspace(0, 1, 4)
    v = np.linspace(0, 1, 4)
    U, V = np.meshgrid(u, v, indexing="ij")
    pts = np.stack([3.4 + 1.0 * U, 1.0 + 1.2 * np.sin(np.pi * U) * 0.6 + 0.0 * V, 2.8 + 1.3 * V], -1)
    pts[..., 1] += 0.3 * np.sin(np.pi * V)
    knots = [0, 0, 0, 0.5, 1, 1, 1]
    return core.NurbsSurface(pts, np.ones((4, 4)), 3, 3, knots, knots)


def cornell_box():
    """[(surface, reflectance, emission, share of patches, occluder)] of a 5.5 m Cornell-like box."""
    L = 5.5
    white, red, green = (0.73, 0.73, 0.73), (0.65, 0.05, 0.05), (0.12, 0.45, 0.15)

    def q(p00, p10, p11, p01):  # written counter-clockwise seen from outside: reverse for inward fronts
        return core.Quad(p00, p01, p11, p10)

    items = [
        (q((0, 0, 0), (0, L, 0), (L, L, 0), (L, 0, 0)), white, 0.0, 3, True),  # floor, facing +z
        (q((0, 0, L), (L, 0, L), (L, L, L), (0, L, L)), white, 0.0, 3, True),  # ceiling, facing -z
        (q((0, L, 0), (0, L, L), (L, L, L), (L, L, 0)), white, 0.0, 3, True),  # back wall, facing -y
        (q((0, 0, 0), (0, 0, L), (0, L, L), (0, L, 0)), red, 0.0, 3, True),  # left wall, facing +x
        (q((L, 0, 0), (L, L, 0), (L, L, L), (L, 0, L)), green, 0.0, 3, True),  # right wall, facing -x
        # light just below the ceiling, facing down, not an occluder (like Blender's area light)
        (
            q((2.2, 2.2, L - 1e-3), (3.3, 2.2, L - 1e-3), (3.3, 3.3, L - 1e-3), (2.2, 3.3, L - 1e-3)),
            0.0,
            15.0,
            1,
            False,
        ),
        (core.Sphere((1.6, 2.0, 1.0), 1.0), white, 0.0, 3, True),
        (core.Sphere((3.9, 3.6, 0.8), 0.8), white, 0.0, 2, True),
        (nurbs_shell(), white, 0.0, 2, True),
    ]
    return items if WITH_NURBS[0] else items[:-1]


def patch_grids(total):
    """(nu, nv) per object so that the patch count is about `total`."""
    items = cornell_box()
    shares = np.array([it[3] for it in items], float)
    grids = []
    for it, share in zip(items, shares):
        n = max(1, total * share / shares.sum())
        if isinstance(it[0], core.Sphere):
            nu = max(1, int(round(np.sqrt(n / 2))))
            grids.append((nu, 2 * nu))
        else:
            k = max(1, int(round(np.sqrt(n))))
            grids.append((k, k))
    return grids


def build(total):
    scene = core.Scene()
    handles = []
    for (surface, rho, emit, _, occ), grid in zip(cornell_box(), patch_grids(total)):
        handles.append(scene.add(surface, reflectance=rho, emission=emit, patches=grid, occluder=occ))
    return scene, handles, patch_grids(total)


def gather(sol, handles, grids, rng):
    """radiosity_at on ~20 random points per patch of every object; returns (points, seconds)."""
    count, start = 0, time.perf_counter()
    scene_objects = cornell_box()
    for h, grid, item in zip(handles, grids, scene_objects):
        (u0, u1), (v0, v1) = item[0].domain
        k = GATHER_PER_PATCH * grid[0] * grid[1]
        u = u0 + (u1 - u0) * rng.random(k)
        v = v0 + (v1 - v0) * rng.random(k)
        out = sol.radiosity_at(h, u, v)
        assert np.all(np.isfinite(out))
        count += k
    return count, time.perf_counter() - start


def run_size(total, tol=1e-3, threads=2, culls=True, log=print, repeat=REPEAT):
    # memory: one solve under tracemalloc (which slows Python code, so it is not timed)
    scene1, _, _ = build(total)
    tracemalloc.start()
    scene1.solve(tol=tol, occlusion=True, threads=threads)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # the thread speed-up: one timed solve with one thread
    scene1, _, _ = build(total)
    t0 = time.perf_counter()
    scene1.solve(tol=tol, occlusion=True, threads=1)
    solve1_s = time.perf_counter() - t0
    # the timed run (solve on a fresh scene, then the gather), `repeat` times: medians reported
    runs = []
    for _ in range(repeat):
        scene, handles, grids = build(total)
        t0 = time.perf_counter()
        sol = scene.solve(tol=tol, occlusion=True, threads=threads)
        solve_s = time.perf_counter() - t0
        points, gather_s = gather(sol, handles, grids, np.random.default_rng(0))
        runs.append((solve_s, gather_s))
    patches = sum(a * b for a, b in grids)
    solve_s = statistics.median(r[0] for r in runs)
    gather_s = statistics.median(r[1] for r in runs)
    totals = sorted(r[0] + r[1] for r in runs)
    stats = dict(sol.stats)
    B = np.concatenate([sol.radiosity(h) for h in handles])
    finite = bool(np.all(np.isfinite(B)))
    # relight: change the light's emission and a wall's colour, solve again (geometry cached)
    scene.set_material(handles[5], emission=(10.0, 12.0, 15.0))
    scene.set_material(handles[3], reflectance=(0.2, 0.2, 0.7))
    t0 = time.perf_counter()
    relit = scene.solve(tol=tol, occlusion=True, threads=threads)
    relight_s = time.perf_counter() - t0
    row = dict(
        target=total,
        patches=patches,
        solve_s=solve_s,
        stats=stats,
        tracemalloc_peak=peak,
        rss_peak=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        gather_points=points,
        gather_s=gather_s,
        totals=totals,
        relight_s=relight_s,
        relight_stats=dict(relit.stats),
        threads=threads,
        solve1_s=solve1_s,
        finite=finite,
        cull_off={},
    )
    log(
        f"  {patches:5d} patches (medians of {repeat}; "
        f"solve + gather {', '.join(f'{t:.2f}' for t in totals)} s): "
        f"solve {solve_s:7.2f} s ({threads} threads; 1 thread {solve1_s:.2f} s), "
        f"gather {points} pts {gather_s:6.2f} s, relight {relight_s:6.3f} s, "
        f"tracemalloc peak {peak / 2**20:7.1f} MiB"
    )
    log(f"    stats: {_short(stats)}")
    if culls:
        for rule in CULL_RULES:
            scene2, _, _ = build(total)
            keep = set(CULL_RULES) - {rule}
            t0 = time.perf_counter()
            try:
                s2 = scene2.solve(tol=tol, occlusion=True, threads=threads, cull=keep)
            except TypeError as exc:  # an older Scene without cull=
                log(f"    cull= not supported: {exc}")
                break
            seconds = time.perf_counter() - t0
            B2 = np.concatenate([s2.radiosity(h) for h in range(len(handles))])
            row["cull_off"][rule] = dict(seconds=seconds, max_change=float(np.abs(B2 - B).max()))
            log(
                f"    cull '{rule}' off: solve {seconds:7.2f} s (max radiosity change {np.abs(B2 - B).max():.2e})"  # noqa: E501
            )
    return row


def _short(stats):
    parts = []
    for k, v in stats.items():
        if isinstance(v, dict):
            parts.append(k + "={" + ", ".join(f"{a}: {_fmt(b)}" for a, b in v.items()) + "}")
        else:
            parts.append(f"{k}={_fmt(v)}")
    return "; ".join(parts)


def _fmt(v):
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def measure(quick=False, log=print, budget=600.0):
    if not have_scene():
        log("core.Scene is not available yet (core/scene.py): scene scaling skipped")
        return None
    rows = []
    start = time.perf_counter()
    sizes = SIZES[:2] if quick else SIZES
    for total in sizes:
        culls = total in sizes[:2]  # (each rule off costs a solve: the two smaller sizes)
        rows.append(run_size(total, culls=culls, log=log))
        if time.perf_counter() - start > budget:
            log(f"  stopping: time budget {budget:.0f} s spent")
            break
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--no-nurbs", action="store_true", help="leave the NURBS shell out")
    parser.add_argument(
        "--room",
        metavar="SIZES",
        help="instead: the closed-room scaling of issue 13 (hierarchical against all pairs) at these "
        "patches per wall side, comma separated (12, 24, 48, 96: about 1k, 4k, 16k, 64k patches); "
        "`benchmarks.hierarchy_scaling` with --pairs-max 5000",
    )
    args = parser.parse_args()
    if args.room:
        from . import hierarchy_scaling

        hierarchy_scaling.main(["--sizes", args.room, "--pairs-max", "5000"])
        return
    WITH_NURBS[0] = not args.no_nurbs
    measure(args.quick)


if __name__ == "__main__":
    main()
