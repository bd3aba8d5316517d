"""Hierarchical radiosity against all pairs (issue 13): scaling in a closed room, and the Cornell box.

Room: a closed 4 m room, m x m patches per wall, two spheres standing on the floor (m/2 x m
patches each), one point lamp under the ceiling; tol 1e-3. For each size and method: solve time
(per stage), `radiosity_at` at 2 random points per patch, links per patch and bytes per link
(hierarchical), pairs computed (all pairs), peak RSS, and the agreement of the two methods where
both ran. Then the ~961-patch Cornell scene of `scene_scaling` both ways. All pairs is skipped above
--pairs-max patches (its pair data grows as N^2: ~23 GB at 16k patches).

Run alone: python -m benchmarks.hierarchy_scaling [--sizes 12,24,48] [--pairs-max 5000] [--furnace M]
"""

import argparse
import resource
import time

import numpy as np

import core

from . import scene_scaling

TOL = 1e-3
GATHER_PER_PATCH = 2


def quad(p00, p10, p11, p01):
    return core.Quad(p00, p01, p11, p10)


def room(m, L=4.0):
    """(scene, handles, surfaces) of the closed room with two spheres on the floor and a lamp."""
    walls = [
        quad((0, 0, 0), (0, L, 0), (L, L, 0), (L, 0, 0)),
        quad((0, 0, L), (L, 0, L), (L, L, L), (0, L, L)),
        quad((0, L, 0), (0, L, L), (L, L, L), (L, L, 0)),
        quad((0, 0, 0), (0, 0, L), (0, L, L), (0, L, 0)),
        quad((L, 0, 0), (L, L, 0), (L, L, L), (L, 0, L)),
        quad((0, 0, 0), (L, 0, 0), (L, 0, L), (0, 0, L)),
    ]
    scene = core.Scene()
    handles, surfaces = [], []
    for k, wall in enumerate(walls):
        rho = (0.7, 0.7, 0.7) if k != 3 else (0.6, 0.1, 0.1)
        handles.append(scene.add(wall, reflectance=rho, patches=m))
        surfaces.append(wall)
    for centre, radius in (((1.3, 1.5, 0.6), 0.6), ((2.8, 2.6, 0.45), 0.45)):
        sphere = core.Sphere(centre, radius)
        handles.append(scene.add(sphere, reflectance=0.6, patches=(max(1, m // 2), m)))
        surfaces.append(sphere)
    scene.add_point_light((2.0, 2.0, 3.6), 200.0)
    return scene, handles, surfaces


def gather_points(solution, handles, surfaces, rng):
    """radiosity_at at GATHER_PER_PATCH random points per patch of every surface; (points, s)."""
    count, start = 0, time.perf_counter()
    for h, surface in zip(handles, surfaces):
        (u0, u1), (v0, v1) = surface.domain
        k = GATHER_PER_PATCH * len(solution.radiosity(h))
        out = solution.radiosity_at(h, u0 + (u1 - u0) * rng.random(k), v0 + (v1 - v0) * rng.random(k))
        assert np.all(np.isfinite(out))
        count += k
    return count, time.perf_counter() - start


def peak_rss_gib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def run_one(build, method, log, gather=True, light_levels=None):
    scene, handles, surfaces = build()
    start = time.perf_counter()
    extra = dict(light_levels=light_levels) if method == "hierarchical" and light_levels is not None else {}
    solution = scene.solve(tol=TOL, method=method, **extra)
    solve_s = time.perf_counter() - start
    points, gather_s = (
        gather_points(solution, handles, surfaces, np.random.default_rng(1)) if gather else (0, 0.0)
    )
    st = solution.stats
    B = np.concatenate([solution.radiosity(h) for h in handles])
    row = dict(
        method=method,
        patches=st["elements"],
        solve_s=solve_s,
        gather_s=gather_s,
        total_s=solve_s + gather_s,
        points=points,
        stages={k: round(v, 2) for k, v in st["times"].items()},
        rss_gib=peak_rss_gib(),
    )
    if method == "hierarchical":
        row.update(
            links=st["links"],
            links_per_patch=st["links_per_patch"],
            bytes_per_link=st["link_bytes"] / max(st["links"], 1),
            levels=st["levels"],
            patches_refined_by_light=st["patches_refined_by_light"],
            sub_patches=st["sub_patches"],
            passes=st["passes"],
            iterations=st["iterations"],
            residual=st["residual"],
        )
    else:
        row.update(pairs=st["pairs_total"] - st["pairs_culled_facing"], iterations=st["iterations"])
    log(row)
    return row, B


def furnace(m):
    """White furnace in the room with its spheres (issue 13): every surface E = 1, rho = 0.5, the
    lamp off, so B = E / (1 - rho) = 2 everywhere; prints the largest |B / 2 - 1| per patch and
    at GATHER_PER_PATCH random points per patch, and the times."""
    scene, handles, surfaces = room(m)
    for h in handles:
        scene.set_material(h, reflectance=0.5, emission=1.0)
    scene.set_light(0, intensity=0.0)
    start = time.perf_counter()
    solution = scene.solve(tol=TOL, method="hierarchical")
    solve_s = time.perf_counter() - start
    B = np.concatenate([solution.radiosity(h) for h in handles])
    rng = np.random.default_rng(2)
    worst, count, start = 0.0, 0, time.perf_counter()
    for h, surface in zip(handles, surfaces):
        (u0, u1), (v0, v1) = surface.domain
        k = GATHER_PER_PATCH * len(solution.radiosity(h))
        out = solution.radiosity_at(h, u0 + (u1 - u0) * rng.random(k), v0 + (v1 - v0) * rng.random(k))
        worst = max(worst, float(np.abs(out / 2.0 - 1.0).max()))
        count += k
    print(
        f"furnace m={m}: {B.shape[0]} patches, max |B/2 - 1| per patch {np.abs(B / 2.0 - 1.0).max():.3g}, "
        f"at {count} gathered points {worst:.3g} (tol {TOL:g}); solve {solve_s:.1f} s, gather "
        f"{time.perf_counter() - start:.1f} s, {solution.stats['links']} links",
        flush=True,
    )


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="12,24,48", help="patches per wall side, comma separated")
    parser.add_argument("--pairs-max", type=int, default=5000, help="largest patch count for all pairs")
    parser.add_argument("--no-cornell", action="store_true")
    parser.add_argument("--no-gather", action="store_true")
    parser.add_argument("--furnace", type=int, metavar="M", help="instead: the white furnace at m = M")
    parser.add_argument(
        "--light-levels", type=int, default=None, help="hierarchical light_levels (default: core's)"
    )
    parser.add_argument("--no-pairs", action="store_true", help="hierarchical only")
    args = parser.parse_args(argv)
    if args.furnace:
        furnace(args.furnace)
        return
    sizes = [int(x) for x in args.sizes.split(",")]
    rows = []
    for m in sizes:
        patches = 6 * m * m + 2 * max(1, m // 2) * m
        results = {}
        for method in ("hierarchical", "pairs"):
            if method == "pairs" and args.no_pairs:
                continue
            if method == "pairs" and patches > args.pairs_max:
                print(f"room m={m} ({patches} patches): all pairs skipped (above --pairs-max)", flush=True)
                continue
            row, B = run_one(
                lambda m=m: room(m),
                method,
                lambda r: print("room", m, r, flush=True),
                not args.no_gather,
                args.light_levels,
            )
            rows.append(row)
            results[method] = B
        if len(results) == 2:
            rel = np.abs(results["hierarchical"] - results["pairs"]) / np.maximum(results["pairs"], 1e-300)
            print(f"room m={m}: hierarchical vs pairs, max relative difference {rel.max():.3g}", flush=True)
    hier = [r for r in rows if r["method"] == "hierarchical"]
    if len(hier) >= 2:
        first, last = hier[0], hier[-1]
        ratio = last["total_s"] / first["total_s"]
        exponent = np.log(ratio) / np.log(last["patches"] / first["patches"])
        print(
            f"hierarchical t({last['patches']})/t({first['patches']}) = {ratio:.2f} (solve + gather), "
            f"exponent {exponent:.2f}",
            flush=True,
        )
        scale = np.log(last["patches"] / first["patches"])
        stages = {
            name: round(float(np.log(last["stages"][name] / first["stages"][name]) / scale), 2)
            for name in first["stages"]
            if first["stages"][name] > 0 and last["stages"].get(name, 0) > 0
        }
        print(f"hierarchical per-stage exponents: {stages}", flush=True)
    if not args.no_cornell:

        def cornell():
            scene, handles, grids = scene_scaling.build(1000)
            surfaces = [item[0] for item in scene_scaling.cornell_box()]
            return scene, handles, surfaces

        results = {}
        for method in ("hierarchical",) if args.no_pairs else ("hierarchical", "pairs"):
            log = lambda r: print("cornell", r, flush=True)  # noqa: E731
            row, B = run_one(cornell, method, log, not args.no_gather, args.light_levels)
            results[method] = (row, B)
        if args.no_pairs:
            return
        rel = np.abs(results["hierarchical"][1] - results["pairs"][1]) / np.maximum(
            results["pairs"][1], 1e-300
        )
        speedup = results["pairs"][0]["total_s"] / results["hierarchical"][0]["total_s"]
        print(f"cornell: pairs / hierarchical time {speedup:.2f}, max relative difference {rel.max():.3g}")


if __name__ == "__main__":
    main()
