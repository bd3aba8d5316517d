"""Whole spheres and sphere patches as exact shadow targets (their silhouette disks): time against error.

Run: python -m benchmarks.sphere_targets   (prints markdown; not part of the test suite)

1. `form_factor(sphere, sphere, occluders=[sphere, triangle])`, a pair with no flat side, at
   falling tol: time, the estimate, and the error against randomised QMC on both spheres' caps
   with its own ray tests (`tests/reference/occluded_mc.sphere_pair_factor`, 2^22 points x 8
   shifts, its standard error shown).
2. A glowing whole sphere (E = 1, one patch) over a floor (rho 0.5) past a black sphere and a
   black triangle: `radiosity_at` on the floor at points across the shadows, exact (the default)
   against rays (`Solution.exact_shadows = False`), each against QMC on the lamp's visible cap
   (`sphere_point_factor`, 2^20 points x 8 shifts).
3. `form_factor(patch, patch, occluders=[sphere, triangle])` between patches of the two spheres
   of 1. (`sphere_target.SpherePatchTargets`), both ways round, against QMC on both patches
   (`sphere_patch_pair_factor`, 2^22 points x 8 shifts, four seeds: their spread shown too).
"""

import sys
import time
import warnings
from pathlib import Path

import numpy as np

import core

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from reference.occluded_mc import (  # noqa: E402
    sphere_pair_factor,
    sphere_patch_pair_factor,
    sphere_point_factor,
)

A, B = ((0.0, 0.0, 0.0), 1.0), ((5.0, 0.0, 0.0), 0.8)
BETWEEN = ((2.5, 0.5, 0.1), 0.6)
WEDGE = ((2.0, -1.2, -0.4), (3.2, -0.6, -0.2), (2.4, -0.3, 0.8))
LAMP = ((0.0, 0.0, 2.0), 0.4)
BALL = ((0.3, 0.1, 0.9), 0.3)
FLAT = ((-0.9, 0.3, 1.2), (-0.1, 0.5, 1.3), (-0.5, -0.4, 1.1))
PATCH_A, PATCH_B = (0.3, 2.2, 0.0, 1.4), (0.6, 2.6, 2.0, 4.4)  # (u0, u1, v0, v1) of A and of B


def pair_table():
    reference, se = sphere_pair_factor(A, B, [BETWEEN], [WEDGE], count=1 << 22)
    print(f"QMC reference F = {reference:.8f} +- {se:.1e} ({se / reference:.1e} relative)\n")
    print("| tol | time (s) | F | estimate (rel.) | error vs QMC (rel.) |")
    print("|---|---|---|---|---|")
    occluders = [core.Sphere(*BETWEEN), core.Quad(WEDGE[0], WEDGE[1], WEDGE[2], WEDGE[0])]
    for tol in (1e-2, 1e-3, 1e-4, 1e-5):
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = core.form_factor_estimate(core.Sphere(*A), core.Sphere(*B), tol=tol, occluders=occluders)
        seconds = time.perf_counter() - start
        print(
            f"| {tol:g} | {seconds:.2f} | {est.value:.8f} | {est.error / est.value:.1e} | "
            f"{(est.value - reference) / reference:+.1e} |"
        )


def patch_table():
    source, target = (*A, PATCH_A), (*B, PATCH_B)
    runs = [
        sphere_patch_pair_factor(source, target, [BETWEEN], [WEDGE], count=1 << 22, seed=s) for s in range(4)
    ]
    values = np.array([r[0] for r in runs])
    reference, se = values.mean(), np.mean([r[1] for r in runs]) / 2.0  # (4 independent runs)
    print(
        f"QMC reference F = {reference:.8f} +- {se:.1e} ({se / reference:.1e} relative; the four runs' "
        f"spread {values.std(ddof=1) / 2.0 / reference:.1e})\n"
    )
    print(
        "| tol | patch A -> B: time (s) | F | estimate (rel.) | error vs QMC (rel.) "
        "| B -> A, reciprocal: time (s) | error |"
    )
    print("|---|---|---|---|---|---|---|")
    occluders = [core.Sphere(*BETWEEN), core.Quad(WEDGE[0], WEDGE[1], WEDGE[2], WEDGE[0])]
    a = core.Sphere(*A).subpatch(PATCH_A[:2], PATCH_A[2:])
    b = core.Sphere(*B).subpatch(PATCH_B[:2], PATCH_B[2:])
    for tol in (1e-2, 1e-3, 1e-4):
        start = time.perf_counter()
        est = core.form_factor_estimate(a, b, tol=tol, occluders=occluders)
        middle = time.perf_counter()
        back = core.form_factor_estimate(b, a, tol=tol, occluders=occluders).value * b.area() / a.area()
        end = time.perf_counter()
        print(
            f"| {tol:g} | {middle - start:.2f} | {est.value:.8f} | {est.error / est.value:.1e} | "
            f"{(est.value - reference) / reference:+.1e} | {end - middle:.2f} | "
            f"{(back - reference) / reference:+.1e} |"
        )


def gather_table(count=24):
    floor = core.Quad((-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0))
    scene = core.Scene()
    scene.add(core.Sphere(*LAMP), emission=1.0, reflectance=0.0, patches=1)
    handle = scene.add(floor, reflectance=0.5, patches=(4, 4))
    scene.add(core.Sphere(*BALL), reflectance=0.0)
    scene.add(core.Quad(*FLAT, FLAT[0]), reflectance=0.0)
    solution = scene.solve(tol=1e-3)
    # points along a line through both shadows
    t = np.linspace(0.0, 1.0, count)
    u, v = 0.30 + 0.35 * t, 0.55 - 0.15 * t
    x, normal = floor.evaluate(u, v)
    reference = np.zeros(count)
    noise = np.zeros(count)
    for k in range(count):
        unit = normal[k] / np.linalg.norm(normal[k])
        F, se = sphere_point_factor(x[k], unit, LAMP, [BALL], [FLAT], count=1 << 20)
        reference[k], noise[k] = 0.5 * F, 0.5 * se
    print("| gather | time (s) | rays | shadow lines | max rel. error | rms rel. error | max QMC noise |")
    print("|---|---|---|---|---|---|---|")
    for exact in (True, False):
        solution.exact_shadows = exact
        before = {key: solution.stats.get(key, 0) for key in ("gather_rays", "gather_shadow_lines")}
        start = time.perf_counter()
        values = solution.radiosity_at(handle, u, v)[:, 0]
        seconds = time.perf_counter() - start
        stats = {key: solution.stats.get(key, 0) - before[key] for key in before}  # (the stats add up)
        error = (values - reference) / reference
        worst, rms = np.abs(error).max(), np.sqrt(np.mean(error**2))
        print(
            f"| {'exact' if exact else 'rays'} | {seconds:.2f} | {stats['gather_rays']} | "
            f"{stats['gather_shadow_lines']} | {worst:.1e} | {rms:.1e} | {(noise / reference).max():.1e} |"
        )


def main():
    print("### sphere -> sphere past a sphere and a triangle (`form_factor_estimate`)\n")
    pair_table()
    print("\n### radiosity_at under a glowing ball past a sphere and a triangle (24 points)\n")
    gather_table()
    print("\n### sphere patch -> sphere patch past a sphere and a triangle (`form_factor_estimate`)\n")
    patch_table()


if __name__ == "__main__":
    main()
