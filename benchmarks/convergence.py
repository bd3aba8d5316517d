"""Run time against error for several methods on cases with exact values (issue 5, part a).

Methods per case: the seed's fixed Gauss-Legendre rule (core method="gauss"), the default
error-controlled method (tol 1e-2 ... 1e-10, achieved error plotted), flat tessellation (curved
surfaces replaced by flat facets through grid points, exact flat factors summed with area
weights), seeded Monte Carlo (uniform area sampling) and pyviewfactor on the same facets.

Run alone: python -m benchmarks.convergence [--quick]
"""

import argparse
import time

import numpy as np

import core

from .common import (
    bench_cases,
    facet_polygons,
    flat_tessellation_value,
    limit_threads,
    monte_carlo,
    pyviewfactor_available,
    pyviewfactor_value,
    pyviewfactor_warmup,
    relative,
    sphere_resolutions,
    target_resolution,
    tessellate,
    timed,
)

GAUSS_N = (2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64)
TOLS = tuple(10.0**-k for k in range(2, 11))
MC_N = (100, 1000, 10_000, 100_000, 1_000_000)
LEVELS = (2, 4, 8, 16, 32, 64)
FLOOR = 1e-16  # errors below this are plotted at the floor


def area_weighted(sources, values):
    areas = np.array([s.area() for s in sources])
    return float(areas @ np.asarray(values) / areas.sum())


def run_case(case, quick=False, point_budget=3.0, log=print):
    sources, target = case.build()
    rows = []

    def add(method, param, value, evaluations, seconds, facets=None):
        rows.append(
            dict(
                method=method,
                param=param,
                value=value,
                error=relative(value, case.exact),
                evaluations=evaluations,
                seconds=seconds,
                facets=facets,
            )
        )
        r = rows[-1]
        log(
            f"  {method:<13}{str(param):>10}  err {r['error']:9.2e}  evals {str(evaluations):>10}  "
            f"{seconds * 1e3:10.2f} ms" + (f"  facets {facets}" if facets else "")
        )

    # the seed's fixed rule, per source patch
    for n in GAUSS_N:
        ests, seconds = timed(
            lambda: [core.form_factor_estimate(s, target, method="gauss", order=n) for s in sources],
            repeat=1 if quick else 3,
            budget=0.5,
        )
        add(
            "gauss",
            n,
            area_weighted(sources, [e.value for e in ests]),
            sum(e.evaluations for e in ests),
            seconds,
        )
        if seconds > point_budget:
            break

    # the default error-controlled method
    for tol in TOLS:
        if len(sources) == 1:
            est, seconds = timed(core.form_factor_estimate, sources[0], target, tol, repeat=3, budget=1.0)
            value, evaluations = est.value, est.evaluations
        else:
            ests, seconds = timed(
                lambda: [core.form_factor_estimate(s, target, tol) for s in sources], repeat=3, budget=1.0
            )
            value, evaluations = (
                area_weighted(sources, [e.value for e in ests]),
                sum(e.evaluations for e in ests),
            )
        add("adaptive", f"{tol:.0e}", value, evaluations, seconds)
        if seconds > 3 * point_budget:
            break

    if case.extra.get("skip_flat"):
        return rows

    # flat tessellation: exact flat factors, tolerance well below the previous level's error
    previous = 1e-2
    for res in sphere_resolutions(LEVELS[: 4 if quick else len(LEVELS)]):
        tol = float(np.clip(previous / 1000, 1e-8, 1e-4))
        (value, ns, nt), seconds = timed(
            flat_tessellation_value, sources, target, res, case.curved_target, tol, repeat=1
        )
        add("flat", f"{res[0]}x{res[1]}", value, None, seconds, facets=ns * nt if case.curved_target else ns)
        rows[-1]["src_facets"], rows[-1]["dst_facets"] = ns, nt
        previous = rows[-1]["error"]
        # facet pairs per level (x4, x16 for curved targets), times a tighter tol (about x2)
        growth = 32 if case.curved_target else 8
        if seconds > 4 * point_budget or seconds * growth > 10 * point_budget:
            break

    # seeded Monte Carlo
    for n in MC_N[: 4 if quick else len(MC_N)]:
        value, seconds = timed(monte_carlo, sources, target, n, repeat=1 if n >= 100_000 else 3)
        add("monte carlo", n, value, n, seconds)

    # pyviewfactor on the same facets
    if pyviewfactor_available():
        pyviewfactor_warmup()
        for res in sphere_resolutions(LEVELS[: 4 if quick else 5]):
            src_polys = facet_polygons([f for s in sources for f in tessellate(s, *res)])
            if case.curved_target:
                dst_polys = facet_polygons(tessellate(target, *target_resolution(target, res)))
            else:
                dst_polys = facet_polygons([target])
            if len(src_polys) * len(dst_polys) > 300_000:
                break
            start = time.perf_counter()
            value, seconds = pyviewfactor_value(src_polys, dst_polys)
            total = time.perf_counter() - start
            add(
                "pyviewfactor",
                f"{res[0]}x{res[1]}",
                value,
                None,
                seconds,
                facets=len(src_polys) * len(dst_polys),
            )
            rows[-1]["seconds_with_mesh"] = total
            if seconds > 4 * point_budget:
                break
    return rows


def crossover(rows, level):
    """Cheapest flat-tessellation point reaching `level` (or a power-law extrapolation)."""
    flat = [r for r in rows if r["method"] == "flat"]
    adaptive = [r for r in rows if r["method"] == "adaptive" and r["error"] <= level]
    best_adaptive = min(adaptive, key=lambda r: r["seconds"]) if adaptive else None
    # the first level from which every finer level stays below `level` (an octahedron happens to give
    # the sphere-in-cube value exactly by symmetry: a lucky coarse level is not a crossover)
    hit = [r for k, r in enumerate(flat) if all(q["error"] <= level for q in flat[k:])]
    if hit:
        f = min(hit, key=lambda r: r["facets"])
        return dict(
            level=level, facets=f["facets"], seconds=f["seconds"], measured=True, adaptive=best_adaptive
        )
    if len(flat) >= 2:
        a, b = flat[-2], flat[-1]
        slope = np.log(b["error"] / a["error"]) / np.log(b["facets"] / a["facets"])
        if slope < 0:
            facets = b["facets"] * (level / b["error"]) ** (1 / slope)
            tslope = np.log(b["seconds"] / a["seconds"]) / np.log(b["facets"] / a["facets"])
            seconds = b["seconds"] * (facets / b["facets"]) ** tslope
            return dict(
                level=level,
                facets=float(facets),
                seconds=float(seconds),
                measured=False,
                slope=float(slope),
                adaptive=best_adaptive,
            )
    return dict(level=level, facets=None, seconds=None, measured=False, adaptive=best_adaptive)


def plot(case, rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    styles = {
        "gauss": ("o-", "seed: fixed Gauss n"),
        "adaptive": ("s-", "default (error-controlled)"),
        "flat": ("^-", "flat tessellation (exact flat F)"),
        "monte carlo": ("x-", "Monte Carlo"),
        "pyviewfactor": ("d--", "pyviewfactor on the facets"),
    }
    for method, (style, label) in styles.items():
        sel = [r for r in rows if r["method"] == method]
        if not sel:
            continue
        ax.loglog(
            [max(r["seconds"], 1e-5) for r in sel],
            [max(r["error"], FLOOR) for r in sel],
            style,
            label=label,
            ms=5,
        )
    ax.set_xlabel("wall time per form factor (s, median)")
    ax.set_ylabel("relative error vs exact")
    ax.set_title(case.title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--case", default=None)
    args = parser.parse_args()
    limit_threads()
    for case in bench_cases():
        if args.case and case.id != args.case:
            continue
        print(case.id, "exact", case.exact)
        rows = run_case(case, args.quick)
        for level in (1e-4, 1e-6):
            print("  crossover", crossover(rows, level))


if __name__ == "__main__":
    main()
