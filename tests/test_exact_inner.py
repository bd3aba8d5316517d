"""Exact point-to-patch factors (polygon, sphere, disk and cylinder contours) against the adaptive
integral of the same kernel, on seeded random configurations that cover the patch kinds."""

import numpy as np
import pytest

import core
from core.formfactor import FormFactorSolver
from core.inner import CYLINDER, DISK, GENERIC, POLYGON, SPHERE

TWO_PI = 2 * np.pi


def random_patch(kind, rng):
    if kind == SPHERE:
        t0, t1 = np.sort(rng.uniform(0, np.pi, 2))
        p0 = rng.uniform(0, np.pi)
        surface = core.Sphere(rng.normal(size=3), rng.uniform(0.5, 2)).subpatch(
            u=(t0, t1), v=(p0, p0 + rng.uniform(0.2, np.pi))
        )
    elif kind == DISK:
        r1 = rng.uniform(0.5, 2)
        p0 = rng.uniform(0, np.pi)
        surface = core.Disk(rng.normal(size=3), rng.normal(size=3), r1).subpatch(
            u=(rng.uniform(0, 0.5 * r1), r1), v=(p0, p0 + rng.uniform(0.2, np.pi))
        )
    elif kind == CYLINDER:
        h = rng.uniform(0.5, 3)
        surface = core.Cylinder(rng.normal(size=3), rng.normal(size=3), rng.uniform(0.3, 2), h)
        u0 = rng.uniform(0, np.pi)
        surface = surface.subpatch(
            u=(u0, u0 + rng.uniform(0.2, np.pi)), v=tuple(np.sort(rng.uniform(0, h, 2)))
        )
    else:
        p = rng.normal(size=3)
        a, b = rng.normal(size=3), rng.normal(size=3)
        surface = core.Quad(p, p + a, p + a + b, p + b)
    if rng.random() < 0.5:
        surface = surface.flipped()
    if rng.random() < 0.3:
        surface = surface.transformed(np.diag([-1.3, 1.3, 1.3, 1.0]))  # mirror + uniform scale
    return surface


@pytest.mark.parametrize(
    "kind", [POLYGON, SPHERE, DISK, CYLINDER], ids=["polygon", "sphere", "disk", "cylinder"]
)
def test_exact_inner_matches_adaptive(kind):
    rng = np.random.default_rng(7 + kind)
    worst = 0.0
    for trial in range(12):
        patch = random_patch(kind, rng)
        solver = FormFactorSolver([patch])
        assert solver.inner.kind[0] == kind
        x1 = patch.evaluate(*[np.mean(r) for r in patch.domain])[0] + rng.normal(size=(6, 3)) * 1.5
        n1 = rng.normal(size=(6, 3))
        n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
        exact, _, _ = solver.inner(x1, n1, np.zeros(6, dtype=int), np.full(6, 1e-12))
        solver.inner.kind[:] = GENERIC
        adaptive, error, _ = solver.inner(x1, n1, np.zeros(6, dtype=int), np.full(6, 1e-12))
        assert np.all(exact >= 0)
        worst = max(worst, np.abs(exact - adaptive).max())
    assert worst < 1e-9, f"exact vs adaptive differ by {worst}"
    assert np.isfinite(worst)
