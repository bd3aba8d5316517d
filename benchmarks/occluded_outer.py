"""Occluded pairs whose outer side is curved: error at tol 1e-3 and 1e-4 against the same pair at 1e-6.

Run: python -m benchmarks.occluded_outer   (not part of the test suite)

The outer integral of `occluded.occluded_form_factor` compares each cell's Gauss rule with its
children's. Over a whole cylinder's 2 x 2 first cells (a quarter turn of the normal each) the two
agreed by chance while both were off (a half disk past a sphere: 2.3e-3 at tol 1e-3, with an
estimate of 4.5e-4); the first cells now follow the normal's turn (`occluded.START_TURN`).
"""

import time

import numpy as np

import core


def cases():
    """{name: (outer patch, inner patch)}, all past one sphere."""
    disk = core.Disk((0.7, 0.0, 0.0), (1.0, 0.0, 0.0), 0.9)
    quad = core.Quad((0.7, -0.7, -0.7), (0.7, 0.7, -0.7), (0.7, 0.7, 0.7), (0.7, -0.7, 0.7))
    a, b = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4), indexing="ij")
    net = np.stack([3.0 + 0.3 * np.sin(3 * a), -1.0 + 2.0 * a, -1.0 + 2.0 * b], -1)
    knots = [0, 0, 0, 0, 1, 1, 1, 1]
    wavy = core.NurbsSurface(net, np.ones((4, 4)), 4, 4, knots, knots).flipped()
    tube = core.Cylinder((3.0, -1.0, -1.0), (0.2, 0.1, 1.0), 0.8, 2.0)
    ball = core.Sphere((3.2, 0.0, 0.0), 0.7)
    return {
        "cylinder -> half disk": (tube, disk.subpatch(None, (0, np.pi))),
        "cylinder -> disk": (tube, disk),
        "sphere -> quad": (ball, quad),
        "sphere -> annulus": (ball, disk.subpatch((0.3, 0.9), None)),
        "wavy NURBS -> half disk": (wavy, disk.subpatch(None, (0, np.pi))),
    }


def main():
    occluders = [core.Sphere((1.7, 0.3, 0.2), 0.3)]
    print("| pair | F (tol 1e-6) | tol 1e-3: error, estimate, time | tol 1e-4: error, estimate, time |")
    print("|---|---|---|---|")
    for name, (a, b) in cases().items():
        reference = core.form_factor_estimate(a, b, tol=1e-6, occluders=occluders).value
        row = []
        for tol in (1e-3, 1e-4):
            start = time.perf_counter()
            est = core.form_factor_estimate(a, b, tol=tol, occluders=occluders)
            seconds = time.perf_counter() - start
            row.append(
                f"{abs(est.value - reference) / reference:.1e}, {est.error / est.value:.1e}, {seconds:.2f} s"
            )
        print(f"| {name} | {reference:.8f} | {row[0]} | {row[1]} |", flush=True)


if __name__ == "__main__":
    main()
