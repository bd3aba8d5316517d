"""Exact shadows: tol -> time -> actual error, against an independent randomised QMC with ray tests.

Run: python -m benchmarks.shadows   (prints markdown; not part of the test suite)

1. Pair factor, square -> parallel square past a sphere and a tilted triangle
   (`core.form_factor(..., occluders=...)`), tol 1e-2 ... 1e-5.
2. Gathered radiosity (`Solution.radiosity_at`) on a floor along a line through the contact shadow
   of a resting black sphere and its penumbra, under a small disk lamp (the README scene):
   B(x) = rho E F_vis(x -> lamp) exactly (nothing else carries light), exact kernel against the
   former sampled rays in the same run.
3. Open 12 m "cube" (floor emitting E = 1, ceiling rho = 0.5, black unit sphere at the centre):
   B on the ceiling = rho F_vis(x -> floor); gathered points above the sphere, and the patch
   values of the solve (still sampled visibility: the per-patch path is not exact yet).
"""

import sys
import time
from pathlib import Path

import numpy as np

import core

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from reference.occluded_mc import pair_factor, point_factor  # noqa: E402
from reference.occluded_radial import disk_point_factor_exact  # noqa: E402


def pair_table():
    source = ((-1.0, -1.0, 0.0), (2.0, 0.0, 0.0), (0.0, 2.0, 0.0))
    target = ((-1.5, -1.5, 2.0), (0.0, 3.0, 0.0), (3.0, 0.0, 0.0))
    sphere = ((0.4, 0.3, 1.1), 0.3)
    triangle = ((-0.5, -0.4, 1.0), (0.6, -0.2, 1.3), (0.1, 0.7, 0.8))
    t0 = time.perf_counter()
    reference, se = pair_factor(source, target, [sphere], [triangle], count=1 << 20, shifts=16)
    reference_time = time.perf_counter() - t0
    a = core.Quad((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0))
    c, u, v = (np.array(p) for p in target)
    b = core.Quad(c, c + u, c + u + v, c + v)
    occluders = [core.Sphere(*sphere), core.Quad(*triangle, triangle[0])]
    lines = [
        "### Pair factor: square -> square past a sphere and a tilted triangle",
        "",
        f"Reference: randomised QMC (16 shifts of 2^20 Halton points), F = {reference:.8f} "
        f"± {se:.1e} (standard error), {reference_time:.1f} s.",
        "",
        "| tol | value | estimated error | actual error (rel.) | within tol | lines | time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for tol in (1e-2, 1e-3, 1e-4, 1e-5):
        t0 = time.perf_counter()
        e = core.form_factor_estimate(a, b, tol=tol, occluders=occluders)
        seconds = time.perf_counter() - t0
        actual = abs(e.value - reference) / reference
        ok = "yes" if actual <= tol + 3 * se / reference else "no"
        row = (f"{tol:.0e}", f"{e.value:.8f}", f"{e.error:.1e}", f"{actual:.1e}", ok, str(e.evaluations))
        lines.append("| " + " | ".join(row + (f"{seconds:.2f}",)) + " |")
    lines.append(f"\n(actual errors below ~{3 * se / reference:.0e} are within the reference's noise)")
    return lines


def _errors(B, reference, se):
    """Max and rms relative error over points with a reference above its noise, and the count."""
    lit = reference > 20 * se
    rel = np.abs(B[lit] - reference[lit]) / reference[lit]
    dark = ~lit
    dark_max = np.abs(B[dark] - reference[dark]).max() if dark.any() else 0.0
    noise = (se[lit] / reference[lit]).max()
    return rel.max(), np.sqrt(np.mean(rel**2)), int(lit.sum()), dark_max, noise


def contact_table():
    rho, E, radius, lamp = 0.5, 10.0, 0.25, (0.3, 0.0, 2.0)
    sphere = ((0.0, 0.0, 0.5), 0.5)
    xs = np.linspace(-1.3, 0.6, 39)
    points = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], 1)
    F, error = disk_point_factor_exact(points, lamp, radius, [sphere])
    reference, se = rho * E * F, rho * E * error
    lines = [
        "### Gathered radiosity across a contact shadow (sphere on a floor under a disk lamp)",
        "",
        "39 points on the floor from x = -1.3 to 0.6 m through the umbra, the penumbra and the contact "
        "point; reference B = rho E F_vis(x -> lamp) by the deterministic reference "
        "(`tests/reference/occluded_radial.py`, its own error bar as 'ref. noise').",
        "Errors relative to each point's own value over the points whose value exceeds 20 times its "
        "error bar; 'dark' is the largest absolute value where the reference is 0 (umbra).",
        "",
        "| tol | visibility | max rel. error | rms rel. error | points | dark max | ref. noise | gather s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for tol in (1e-3, 1e-4):
        scene = core.Scene()
        floor = scene.add(
            core.Quad((-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)), reflectance=rho, patches=(4, 4)
        )
        scene.add(core.Sphere(*sphere), reflectance=0.0, patches=(4, 8))
        scene.add(core.Disk(lamp, (0, 0, -1), radius), emission=E, reflectance=0.0, occluder=False)
        for mode in ("exact", "sampled"):
            solution = scene.solve(tol=tol, occlusion=mode)
            t0 = time.perf_counter()
            B = solution.radiosity_at(floor, (xs + 2) / 4, np.full(xs.size, 0.5))[:, 0]
            seconds = time.perf_counter() - t0
            name = "exact" if mode == "exact" else "sampled rays (before)"
            worst, rms, count, dark, noise = _errors(B, reference, se)
            row = (f"{tol:.0e}", name, f"{worst:.1e}", f"{rms:.1e}", str(count), f"{dark:.1e}")
            row += (f"{noise:.0e}",)
            lines.append("| " + " | ".join(row + (f"{seconds:.2f}",)) + " |")
    return lines


def open_cube_table():
    side, rho = 12.0, 0.5
    h = side / 2
    floor_surface = core.Quad((-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0))  # front +z
    ceiling_surface = core.Quad((-h, -h, side), (-h, h, side), (h, h, side), (h, -h, side))  # front -z
    sphere = ((0.0, 0.0, h), 1.0)
    # ceiling points above the sphere, out to the edge of its shadow
    xs = np.linspace(0.0, 3.0, 16)
    reference, se = np.zeros(xs.size), np.zeros(xs.size)
    target = ((-h, -h, 0.0), (side, 0.0, 0.0), (0.0, side, 0.0))  # front +z, facing the ceiling
    for k, x in enumerate(xs):
        m, s = point_factor(
            np.array([x, 0.0, side]), np.array([0.0, 0.0, -1.0]), target, [sphere], count=1 << 18
        )
        reference[k], se[k] = rho * m, rho * s
    lines = [
        "### Open 12 m cube: emitting floor, ceiling rho = 0.5, black unit sphere at the centre",
        "",
        "16 ceiling points from above the sphere's centre out to 3 m; reference B = rho F_vis(x -> floor) "
        "by randomised QMC (8 shifts of 2^18). The patch values (sol.radiosity) still come from sampled "
        "visibility: their error is listed too (patches of 1.5 m; reference: the mean of 64 QMC points).",
        "",
        "| tol | occlusion | gathered: max rel. error | gathered: rms | ref. noise "
        "| patch above the sphere: rel. error | solve + gather (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    # the reference patch value above the sphere: mean over a grid of points of the patch [0, 1.5]^2
    grid = (np.arange(8) + 0.5) / 8 * 1.5
    patch_ref = (
        np.mean(
            [
                point_factor(
                    np.array([gx, gy, side]), np.array([0.0, 0.0, -1.0]), target, [sphere], count=1 << 14
                )[0]
                for gx in grid
                for gy in grid
            ]
        )
        * rho
    )
    for tol, mode in ((1e-3, True), (1e-4, True), (1e-3, "exact"), (1e-4, "exact")):
        scene = core.Scene()
        scene.add(floor_surface, emission=1.0, reflectance=0.0, patches=(8, 8))
        ceiling = scene.add(ceiling_surface, reflectance=rho, patches=(8, 8))
        scene.add(core.Sphere(*sphere), reflectance=0.0, patches=(4, 8))
        t0 = time.perf_counter()
        solution = scene.solve(tol=tol, occlusion=mode)
        # ceiling parameters: u runs along y (p00 -> p10 = (-h, h)), v along x
        B = solution.radiosity_at(ceiling, np.full(xs.size, 0.5), (xs + h) / side)[:, 0]
        seconds = time.perf_counter() - t0
        worst, rms, _, _, noise = _errors(B, reference, se)
        patch = solution.radiosity(ceiling)[4 * 8 + 4, 0]  # cell (4, 4): y, x in [0, 1.5]
        patch_error = abs(patch - patch_ref) / patch_ref
        row = (f"{tol:.0e}", str(mode), f"{worst:.1e}", f"{rms:.1e}", f"{noise:.0e}", f"{patch_error:.1e}")
        lines.append("| " + " | ".join(row + (f"{seconds:.2f}",)) + " |")
    return lines


def main():
    out = ["## Exact shadows (issue: Exact shadows)", ""]
    for part in (pair_table, contact_table, open_cube_table):
        out += part() + [""]
        print("\n".join(out), flush=True)
    return out


if __name__ == "__main__":
    main()
