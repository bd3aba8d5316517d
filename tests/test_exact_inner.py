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


def test_an_arc_integral_from_a_point_on_its_circle():
    """A point exactly on an arc's circle but off the arc (a Gauss node of one sphere patch on the
    rim of another patch of its sphere: the Cornell example's two-sided ball at tol 1e-4) gets
    the finite integral, the limit of nearby points, not 0 x inf = NaN."""
    from core.contour import arc_integral
    from core.quadrature import gauss_legendre

    def dense(x1, n1, t0, t1, order=200):
        rule = gauss_legendre(order)
        t = t0 + (t1 - t0) * rule.points
        r = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], 1) - x1
        dr = np.stack([-np.sin(t), np.cos(t), np.zeros_like(t)], 1)
        return float((np.cross(r, dr) @ n1 / (r * r).sum(1) * rule.weights).sum() * (t1 - t0))

    one = lambda a: np.array([a])  # noqa: E731
    e1, e2, c = np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), np.zeros((1, 3))
    for x1, n1 in (((-1.0, 0, 0), (0, 0.6, 0.8)), ((0, -1.0, 0), (0.3, 0.4, np.sqrt(0.75)))):
        x1, n1 = np.array([x1]), np.array([n1])
        for t0, t1 in ((0.0, 1.0), (-1.0, 2.5), (0.5, 0.5 + np.pi)):
            if t1 >= 2.0 * np.pi - 0.1 or (t0 <= np.arctan2(x1[0, 1], x1[0, 0]) % (2 * np.pi) <= t1):
                continue
            got = arc_integral(x1, n1, c, e1, e2, one(1.0), one(t0), one(t1))[0]
            assert np.isfinite(got), (x1, t0, t1)
            assert abs(got - dense(x1[0], n1[0], t0, t1)) <= 1e-10 * max(1.0, abs(got)), (x1, t0, t1, got)
            near = arc_integral(x1 * (1 + 1e-9), n1, c, e1, e2, one(1.0), one(t0), one(t1))[0]
            assert abs(got - near) <= 1e-6 * max(1.0, abs(got))
