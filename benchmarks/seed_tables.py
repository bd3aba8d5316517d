"""The seed paper's two validation tables, reproduced next to the error-controlled method.

Baranoski (UFRGS), "Aplicacao de radiosidade a sintese de imagens de objetos formados por
superficies curvas" (../shared/seed/; summary in SUMMARY.md there):

1. Sphere of radius r at a = 6 above the centre of a square of side b = 6. Exact
   F = atan((b/2)^2 / (a sqrt(a^2 + 2 (b/2)^2))) / pi = 0.0640942168489749 for every r
   (the paper prints 6.4084e-2 as "analytic", 1.6e-4 off).
2. Sphere r = 1 at the centre of a cube of side 12: F(sphere -> face) = 1/6 exactly, for the
   whole sphere and for the sphere split into 16 and 32 patches (summation rule).

The paper's fixed n-point Gauss rule ("gauss") is run on the same geometry. Its columns for
n = 3 and n = 4 are reproduced to the printed digits when the sphere's polar axis lies along y
(parallel to the square); the paper does not state its orientation, and with the axis along z
the rule gives other numbers (the rule is not rotation invariant). Its n = 5 column is not
reproduced with the correct 5-point Gauss-Legendre constants in any axis orientation we tried.

Run: python -m benchmarks.seed_tables
"""

import time

import numpy as np

import core

EXACT_SQUARE = float(np.arctan(9.0 / (6.0 * np.sqrt(36.0 + 18.0))) / np.pi)
PAPER_GAUSS = {  # Table (a)-(c) of the paper: F for r = 1, 0.1, 0.01, 0.001, 0.0001
    3: [4.1136e-2, 4.6231e-2, 4.6566e-2, 4.6597e-2, 4.6601e-2],
    4: [7.0517e-2, 6.9549e-2, 6.9390e-2, 6.9375e-2, 6.9374e-2],
    5: [6.4600e-2, 6.2445e-2, 6.2298e-2, 6.2298e-2, 6.2298e-2],
}
PAPER_TIME = {3: 1.86, 4: 5.88, 5: 14.44}  # seconds per form factor on a PC-AT 286
PAPER_CUBE = {1: 1.7815e-1, 16: 1.7211e-1, 32: 1.7190e-1}  # 5-point rule


def pole_along_y(center, radius):
    """Sphere with its polar axis along +y (the orientation that reproduces the paper)."""
    rotate = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
    move = np.eye(4)
    move[:3, 3] = center
    return core.Sphere((0.0, 0.0, 0.0), radius).transformed(move @ rotate)


def timed(function, *args, **kwargs):
    start = time.perf_counter()
    result = function(*args, **kwargs)
    return result, time.perf_counter() - start


def square_table():
    square = core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))
    radii = [1.0, 0.1, 0.01, 0.001, 0.0001]
    print("Table 1: sphere (radius r, centre 6 above) -> square of side 6;  exact F = %.16f" % EXACT_SQUARE)
    print(f"{'method':<28}{'r':>8}{'paper F':>12}{'our F':>20}{'rel. error':>12}{'time':>10}")
    for n, paper in PAPER_GAUSS.items():
        for r, printed in zip(radii, paper):
            value, seconds = timed(
                core.form_factor, pole_along_y((0, 0, 6), r), square, method="gauss", order=n
            )
            print(
                f"{'gauss n=%d (paper %.2fs)' % (n, PAPER_TIME[n]):<28}{r:>8g}{printed:>12.4e}{value:>20.12f}"
                f"{abs(value - EXACT_SQUARE) / EXACT_SQUARE:>12.1e}{seconds:>9.4f}s"
            )
    for tol in (1e-4, 1e-7, 1e-10):
        for r in radii:
            estimate, seconds = timed(core.form_factor_estimate, pole_along_y((0, 0, 6), r), square, tol=tol)
            print(
                f"{'adaptive tol=%g' % tol:<28}{r:>8g}{'':>12}{estimate.value:>20.16f}"
                f"{abs(estimate.value - EXACT_SQUARE) / EXACT_SQUARE:>12.1e}{seconds:>9.4f}s"
            )
    print()


def cube_table():
    face = core.Quad((-6, -6, -6), (6, -6, -6), (6, 6, -6), (-6, 6, -6))
    sphere = pole_along_y((0, 0, 0), 1.0)
    print("Table 2: sphere r = 1 at the centre of a cube of side 12 -> one face;  exact F = 1/6")
    print(f"{'method':<28}{'patches':>8}{'paper F':>12}{'our F':>20}{'rel. error':>12}{'time':>10}")
    for count, split in ((1, (1, 1)), (16, (4, 4)), (32, (4, 8))):
        parts = sphere.split(*split)
        areas = np.array([p.area() for p in parts])
        for label, kwargs in (
            ("gauss n=5", dict(method="gauss", order=5)),
            ("adaptive tol=1e-7", dict(tol=1e-7)),
        ):
            start = time.perf_counter()
            values = np.array([core.form_factor(p, face, **kwargs) for p in parts])
            seconds = time.perf_counter() - start
            total = float(areas @ values / areas.sum())
            paper = f"{PAPER_CUBE[count]:>12.4e}" if label.startswith("gauss") else f"{'':>12}"
            print(
                f"{label:<28}{count:>8d}{paper}{total:>20.16f}{abs(total - 1 / 6) * 6:>12.1e}{seconds:>9.4f}s"
            )
    print()


def main():
    square_table()
    cube_table()


if __name__ == "__main__":
    main()
