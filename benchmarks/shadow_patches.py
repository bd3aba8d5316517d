"""Exact shadows per patch: tol -> solve time -> actual error of every patch, in three scenes.

Run: python -m benchmarks.shadow_patches [open_cube resting_sphere closed_box]   (prints markdown;
not part of the test suite)

Each scene has one reflecting receiver whose patches take light straight from an emitter past
black occluders, so each patch's radiosity is rho E F_vis(patch -> emitter) exactly and has a
reference that shares no code with core/:

1. Open 12 m cube: the floor emits E = 1 (rho 0), the ceiling reflects (rho 0.5), a black unit
   sphere at the centre. Reference: the patch mean (12 x 12 Gauss-Legendre) of F(x -> floor
   rectangle) - F(x -> whole sphere): Lambert's polygon formula minus (r/d)^2 cos(gamma) (Siegel &
   Howell, app. C), exact while the sphere's shadow lies inside the floor (the 16 central ceiling
   patches); the integrand is analytic there, so the reference is exact to ~1e-12.
2. A black sphere resting on a 4 x 4 m floor (rho 0.5, 8 x 8 patches) under a small disk lamp
   (r 0.25 m, 2 m up, off-axis): contact shadow, umbra, penumbra, patches that see a sliver.
3. A closed 4 m box (black walls and ceiling, floor rho 0.5, 8 x 8 patches per face) with two black
   spheres, one resting on the floor, and a disk lamp under the ceiling.
References of 2 and 3: deterministic patch means of F_vis(x -> lamp) past the spheres
(`tests/reference/occluded_radial.floor_reference_exact`: polar integration over the lamp with
exact breakpoints and a closed-form radial integral, patch means by iterated integration split
at the umbra and penumbra curves; its own error bar, ~1e-11 relative, is reported as "noise").
Errors are counted on patches whose value exceeds 20 times that bar (the others are the umbra,
exactly 0: "dark" is the largest absolute value there); "max beyond 3 sigma" takes off 3 error
bars (with this reference it equals the max). A separate column gives the largest error over
the patches whose value is at least 1 % of the brightest one's (the others see a sliver).
"""

import sys
import time
from pathlib import Path

import numpy as np

import core

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from reference.occluded_exact import open_cube_reference  # noqa: E402
from reference.occluded_radial import floor_reference_exact  # noqa: E402

TOLS = (1e-2, 1e-3, 1e-4)
MODES = ("sampled", True, "exact")  # rays alone (the former default), the default, every pair exact


# ---------------------------------------------------------------------------- scenes
def open_cube(m=8):
    side, rho, center, radius = 12.0, 0.5, np.array([0.0, 0.0, 6.0]), 1.0
    h = side / 2

    def build():
        scene = core.Scene()
        scene.add(
            core.Quad((-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)),
            emission=1.0,
            reflectance=0.0,
            patches=(m, m),
        )
        ceiling = scene.add(
            core.Quad((-h, -h, side), (-h, h, side), (h, h, side), (h, -h, side)),
            reflectance=rho,
            patches=(m, m),
        )
        scene.add(core.Sphere(center, radius), reflectance=0.0, patches=(4, 8))
        return scene, ceiling

    return (
        "open 12 m cube, sphere between emitting floor and ceiling",
        build,
        lambda: open_cube_reference(side, rho, center, radius, m),
    )


def resting_sphere(m=8):
    half, rho, E, lamp, radius = 2.0, 0.5, 10.0, (0.3, 0.0, 2.0), 0.25
    ball = ((0.0, 0.0, 0.5), 0.5)

    def build():
        scene = core.Scene()
        floor = scene.add(
            core.Quad((-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)),
            reflectance=rho,
            patches=(m, m),
        )
        scene.add(core.Sphere(*ball), reflectance=0.0, patches=(4, 8))
        scene.add(core.Disk(lamp, (0, 0, -1), radius), emission=E, reflectance=0.0, occluder=False)
        return scene, floor

    return (
        "sphere resting on a floor under a small disk lamp",
        build,
        lambda: floor_reference_exact(half, m, lamp, radius, [ball], rho, E),
    )


def closed_box(m=8):
    half, rho, E, lamp, radius = 2.0, 0.5, 20.0, (0.0, 0.0, 3.95), 0.4
    balls = [((-0.6, 0.3, 0.7), 0.7), ((0.9, -0.5, 1.8), 0.5)]
    h, top = half, 2 * half

    def build():
        scene = core.Scene()
        q = core.Quad
        floor = scene.add(q((-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)), reflectance=rho, patches=(m, m))
        for corners in (
            ((-h, -h, top), (-h, h, top), (h, h, top), (h, -h, top)),
            ((-h, -h, 0), (-h, h, 0), (-h, h, top), (-h, -h, top)),
            ((h, -h, 0), (h, -h, top), (h, h, top), (h, h, 0)),
            ((-h, -h, 0), (-h, -h, top), (h, -h, top), (h, -h, 0)),
            ((-h, h, 0), (h, h, 0), (h, h, top), (-h, h, top)),
        ):
            scene.add(q(*corners), reflectance=0.0, patches=(m, m))
        for center, r in balls:
            scene.add(core.Sphere(center, r), reflectance=0.0, patches=(6, 12))
        scene.add(core.Disk(lamp, (0, 0, -1), radius), emission=E, reflectance=0.0, occluder=False)
        return scene, floor

    return (
        "closed 4 m box, two spheres (one resting), lamp under the ceiling",
        build,
        lambda: floor_reference_exact(half, m, lamp, radius, balls, rho, E),
    )


def table(name, build, reference):
    t0 = time.perf_counter()
    ref, se = reference()
    seconds = time.perf_counter() - t0
    known = np.isfinite(ref)
    lit = known & (ref > 20 * se)
    noise = se[lit] / ref[lit]
    lines = [
        f"### {name}",
        "",
        f"{int(lit.sum())} patches with a reference (noise: median {np.median(noise):.1e}, "
        f"max {noise.max():.1e} relative; {seconds:.0f} s).",
        "",
        "| tol | occlusion | solve (s) | max rel. error | rms rel. error | max beyond 3 sigma "
        "| max rel., patches >= 1 % of the brightest | dark max | exact pairs |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for tol in TOLS:
        for mode in MODES:
            scene, receiver = build()
            t0 = time.perf_counter()
            solution = scene.solve(tol=tol, occlusion=mode)
            seconds = time.perf_counter() - t0
            B = solution.radiosity(receiver)[:, 0]
            rel = np.abs(B[lit] - ref[lit]) / ref[lit]
            dark = known & ~lit
            dark_max = float(np.abs(B[dark] - ref[dark]).max()) if dark.any() else 0.0
            row = (
                f"{tol:.0e}",
                str(mode),
                f"{seconds:.2f}",
                f"{rel.max():.1e}",
                f"{np.sqrt(np.mean(rel**2)):.1e}",
            )
            # the error the reference's noise cannot explain: beyond 3 of its standard errors
            beyond = np.maximum(np.abs(B[lit] - ref[lit]) - 3.0 * se[lit], 0.0) / ref[lit]
            row += (f"{beyond.max():.1e}",)
            # patches that see more than a sliver of the emitter
            bright = lit & (ref >= 1e-2 * ref[known].max())
            row += (f"{(np.abs(B[bright] - ref[bright]) / ref[bright]).max():.1e}",)
            row += (f"{dark_max:.1e}", str(solution.stats.get("pairs_exact", 0)))
            lines.append("| " + " | ".join(row) + " |")
            print(lines[-1], flush=True)
    return lines


def main():
    out = ["## Exact shadows per patch (`python -m benchmarks.shadow_patches`)", ""]
    names = sys.argv[1:]
    scenes = {"open_cube": open_cube, "resting_sphere": resting_sphere, "closed_box": closed_box}
    for key in names or scenes:
        scene = scenes[key]()
        out += table(*scene) + [""]
        print("\n".join(out), flush=True)
    return out


if __name__ == "__main__":
    main()
