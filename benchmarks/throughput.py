"""Kernel throughput (issue 5, part b): kernel evaluations per second of core.form_factor_estimate
(evaluations it reports / wall time) against a bare vectorised numpy kernel
cos1 cos2 / (pi r^2), clipped, on large arrays of point pairs, in the same process.

Run alone: python -m benchmarks.throughput
"""

import numpy as np

import core

from .common import bench_cases, square6, timed


def bare_kernel(x1, n1, x2, n2):
    """cos1 cos2 / (pi r^2) for unit normals, zero where the points do not face each other."""
    e = x2 - x1
    L2 = np.einsum("ij,ij->i", e, e)
    c1 = np.einsum("ij,ij->i", n1, e)
    c2 = -np.einsum("ij,ij->i", n2, e)
    ok = (c1 > 0) & (c2 > 0)
    return np.where(ok, c1 * c2 / (np.pi * L2 * L2), 0.0)


def bare_rate(pairs=1_000_000, seed=0):
    rng = np.random.default_rng(seed)
    x1 = rng.normal(size=(pairs, 3))
    x2 = rng.normal(size=(pairs, 3)) + (0, 0, 6)
    n1 = rng.normal(size=(pairs, 3))
    n1 /= np.linalg.norm(n1, axis=1)[:, None]
    n2 = rng.normal(size=(pairs, 3))
    n2 /= np.linalg.norm(n2, axis=1)[:, None]
    _, seconds = timed(bare_kernel, x1, n1, x2, n2, repeat=5)
    return pairs / seconds


def measure(verbose=True):
    cases = {c.id: c for c in bench_cases()}
    runs = [
        (
            "seed sphere->square, default tol=1e-6",
            lambda: (core.Sphere((0, 0, 6), 1.0), square6()),
            {"tol": 1e-6},
        ),
        (
            "seed sphere->square, default tol=1e-10",
            lambda: (core.Sphere((0, 0, 6), 1.0), square6()),
            {"tol": 1e-10},
        ),
        (
            "sphere->sphere, default tol=1e-8",
            lambda: (cases["sphere_to_sphere"].build()[0][0], cases["sphere_to_sphere"].build()[1]),
            {"tol": 1e-8},
        ),
        (
            "coaxial cylinders, default tol=1e-8",
            lambda: (cases["coaxial_cylinders"].build()[0][0], cases["coaxial_cylinders"].build()[1]),
            {"tol": 1e-8},
        ),
        (
            "seed sphere->square, gauss n=64",
            lambda: (core.Sphere((0, 0, 6), 1.0), square6()),
            {"method": "gauss", "order": 64},
        ),
    ]
    bare = bare_rate()
    rows = []
    for label, build, kwargs in runs:
        a, b = build()
        est, seconds = timed(core.form_factor_estimate, a, b, repeat=3, **kwargs)
        rate = est.evaluations / seconds
        rows.append(
            dict(label=label, evaluations=est.evaluations, seconds=seconds, rate=rate, ratio=bare / rate)
        )
    out = dict(bare_rate=bare, rows=rows)
    if verbose:
        print(f"bare numpy kernel on 1e6 point pairs: {bare:.3g} evaluations/s")
        print(f"{'run':<42}{'evaluations':>12}{'time':>11}{'evals/s':>11}{'bare/this':>11}")
        for r in rows:
            print(
                f"{r['label']:<42}{r['evaluations']:>12d}{r['seconds'] * 1e3:>9.1f}ms{r['rate']:>11.3g}"
                f"{r['ratio']:>10.1f}x"
            )
    return out


if __name__ == "__main__":
    measure()
