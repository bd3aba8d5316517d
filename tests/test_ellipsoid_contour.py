"""Whole ellipsoids as inner targets: the contour integral around the visible part (core/ellipsoid.py).

Identities checked:
- a sphere is an ellipsoid: the contour equals the exact sphere factors of `contour.sphere_patch`
  and Nusselt's r^2 cos / d^2, also where the point's horizon cuts the sphere;
- an independent integral over directions: F = 1/pi * integral of max(0, n1 . d) over the
  directions d of the tangent cone from the point, parametrised through the ellipsoid's local
  frame (where the cone is circular), split where the horizon meets the cone's outline and
  integrated between the horizon's roots in closed form, so every piece is smooth (Gauss);
- F(dA -> whole ellipsoid) = F(dA -> upper half) + F(dA -> lower half) (additivity; the halves
  are not whole, so they go through the adaptive cubature of `cellrule`, which agrees to 1e-9:
  near silhouettes it is off by up to ~4e-10 against both methods above while estimating 1e-14);
- the pair factors built on it: reciprocity and the sum over halves, at tol 1e-8.
"""

import numpy as np
import pytest

import core
from core.bounds import lengths
from core.ellipsoid import whole_ellipsoid
from core.formfactor import FormFactorSolver


def ellipsoid(axes=(1.0, 0.6, 0.4), center=(0.0, 0.0, 0.0), angle=0.4):
    """Semi-axes `axes`, turned by `angle` about (1, 1, 1), centred at `center`."""
    k = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    M = np.eye(4)
    M[:3, :3] = R @ np.diag(axes)
    M[:3, 3] = center
    return core.Sphere((0.0, 0.0, 0.0), 1.0).transformed(M)


def points_around(count, seed, low=1.05, high=4.0):
    """Points at random directions and distances low .. high from the origin, random unit normals."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(count, 3))
    x *= rng.uniform(low, high, count)[:, None] / lengths(x)[:, None]
    n = rng.normal(size=(count, 3))
    return x, n / lengths(n)[:, None]


def contour(surface, x, n, tolerance=1e-13, inward=False):
    L = surface.geometry.linear
    K = len(x)
    return whole_ellipsoid(
        x,
        n,
        np.broadcast_to(surface.geometry.offset, (K, 3)),
        np.broadcast_to(L, (K, 3, 3)),
        np.broadcast_to(np.linalg.inv(L), (K, 3, 3)),
        np.full(K, inward),
        np.full(K, tolerance),
    )


def by_directions(surface, x, n, order=80):
    """F(dA -> whole ellipsoid) for one point, integrated over the directions of its tangent cone.

    In local coordinates p = L^-1 (y - c) the cone from q = L^-1 (x - c) to the unit sphere is
    circular: u(theta, phi) = cos(theta) a + sin(theta) (cos(phi) e1 + sin(phi) e2), a = -q/|q|,
    theta <= asin(1/|q|). A world direction is d = L u / |L u|, with solid angle
    |det L| / |L u|^3 per local one. The horizon n1 . L u = A cos(theta) + B(phi) sin(theta) = 0
    has its root in closed form; phi is split where that root reaches the cone's outline.
    """
    L = surface.geometry.linear
    q = np.linalg.solve(L, x - surface.geometry.offset)
    a = -q / np.linalg.norm(q)
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    top = np.arcsin(1.0 / np.linalg.norm(q))
    m = L.T @ n
    A, b1, b2 = m @ a, m @ e1, m @ e2
    breaks = [0.0, 2.0 * np.pi]
    r = -A / (np.hypot(b1, b2) * np.tan(top))
    if abs(r) < 1.0:
        breaks += [(np.arctan2(b2, b1) + s * np.arccos(r)) % (2.0 * np.pi) for s in (1.0, -1.0)]
    nodes, weights = np.polynomial.legendre.leggauss(order)
    total = 0.0
    for p0, p1 in zip(np.sort(breaks)[:-1], np.sort(breaks)[1:]):
        for phi, w_phi in zip(p0 + (p1 - p0) * (nodes + 1) / 2, (p1 - p0) / 2 * weights):
            B = b1 * np.cos(phi) + b2 * np.sin(phi)
            lo, hi = 0.0, top
            root = np.arctan(-A / B) if B != 0.0 else np.pi / 2
            if 0.0 < root < top:
                lo, hi = (0.0, root) if A > 0 else (root, top)
            elif A * np.cos(top / 2) + B * np.sin(top / 2) <= 0.0:
                continue  # this line is wholly below the horizon
            theta = lo + (hi - lo) * (nodes + 1) / 2
            u = np.cos(theta)[:, None] * a + np.sin(theta)[:, None] * (np.cos(phi) * e1 + np.sin(phi) * e2)
            Lu = u @ L.T
            size = np.linalg.norm(Lu, axis=-1)
            cosine = np.maximum(0.0, Lu @ n / size)
            total += w_phi * (hi - lo) / 2 * (cosine * np.sin(theta) / size**3 @ weights)
    return total * abs(np.linalg.det(L)) / np.pi


def test_sphere_as_ellipsoid_matches_exact_sphere_factors():
    """L = r I: every point (horizon clear, cut, or wholly behind) within 1e-13 of the exact factor."""
    sphere = core.Sphere((0.0, 0.0, 0.0), 1.2)
    x, n = points_around(400, 3, low=1.25, high=5.0)
    exact, _, _ = FormFactorSolver([sphere]).inner(x, n, np.zeros(len(x), dtype=int), np.full(len(x), 1e-15))
    F, error, done, _ = contour(sphere, x, n)
    assert done.all()
    assert np.abs(F - exact).max() <= 1e-13
    # the set covers all three cases: clear of the horizon, cut by it, wholly behind it
    height = np.einsum("ki,ki->k", -x, n)
    assert (height > 1.2).any() and (np.abs(height) < 1.2).any() and (height < -1.2).any()
    assert (error <= 1e-13).all()


def test_ellipsoid_matches_the_integral_over_directions():
    """Contour = the direction-space integral (an independent method) within 1e-13, at points
    near and far, clear of the horizon and cut by it."""
    body = ellipsoid()
    x, n = points_around(60, 5, low=1.1, high=3.0)
    F, error, done, evaluations = contour(body, x, n, tolerance=1e-13)
    assert done.all() and evaluations < 600 * len(x)
    reference = np.array([by_directions(body, xk, nk) for xk, nk in zip(x, n)])
    np.testing.assert_allclose(F, reference, rtol=0, atol=1e-13)
    assert (F > 0).sum() > 20 and (F == 0).sum() > 5
    # some points see the ellipsoid cut by their horizon (the outline meets it)
    assert (error >= 0).all()


def test_ellipsoid_equals_the_sum_of_its_halves():
    """Contour on the whole ellipsoid = adaptive cubature on its two halves (tol 1e-12 per point),
    within the cubature's accuracy near silhouettes (1e-9, see the module docstring)."""
    body = ellipsoid()
    x, n = points_around(60, 5, low=1.1, high=3.0)
    F, _, done, _ = contour(body, x, n, tolerance=1e-12)
    solver = FormFactorSolver(body.split(2, 1))
    parts = [solver.inner(x, n, np.full(len(x), k), np.full(len(x), 1e-12))[0] for k in range(2)]
    np.testing.assert_allclose(F, parts[0] + parts[1], rtol=0, atol=1e-9)


def test_inside_of_an_ellipsoid_seen_from_outside():
    """The inward side of a whole ellipsoid seen from outside (through its near wall) gives the
    same factor as its outside: the evaluator's value equals the flipped halves' cubature."""
    body = ellipsoid().flipped()
    x, n = points_around(40, 9, low=1.1, high=3.0)
    solver = FormFactorSolver([body])
    assert solver.inner.whole_ellipsoid[0]
    F, _, _ = solver.inner(x, n, np.zeros(len(x), dtype=int), np.full(len(x), 1e-12))
    halves = FormFactorSolver(body.split(2, 1))
    parts = [halves.inner(x, n, np.full(len(x), k), np.full(len(x), 1e-12))[0] for k in range(2)]
    np.testing.assert_allclose(F, parts[0] + parts[1], rtol=0, atol=1e-9)
    assert (F > 0).sum() > 10


def test_points_inside_see_all_or_nothing_and_points_on_it_a_lune():
    """From inside, the inward front fills the hemisphere above the horizon (F = 1, the enclosure
    rule) and the outward one shows only its back (F = 0), whatever the normal. From a point on
    the surface the inside fills the lune between the tangent plane and the horizon:
    (1 + n . m) / 2 with m the inward normal, against an independent sampling of directions."""
    body = ellipsoid()
    L, c = body.geometry.linear, body.geometry.offset
    rng = np.random.default_rng(4)
    p = rng.normal(size=(30, 3))
    p *= (rng.uniform(0.0, 0.999, 30) ** (1 / 3) / lengths(p))[:, None]  # inside the unit ball
    on = np.array([0.6, -0.48, 0.64])  # a unit vector: c + L on lies on the ellipsoid
    x = np.vstack([c + p @ L.T, c + L @ on, [3.0, 0.0, 0.0]])
    n = rng.normal(size=(len(x), 3))
    n /= lengths(n)[:, None]
    for inward, expected in ((True, 1.0), (False, 0.0)):
        F, error, done, _ = contour(body, x, n, inward=inward)
        assert done.all()
        assert F[:30].tolist() == [expected] * 30 and error[:31].tolist() == [0.0] * 31
        if not inward:
            assert F[30] == 0.0
    # the lune by directions: cosine-weighted directions above the horizon that enter the body
    # (a ray from the surface point enters when it makes a negative angle with the outward normal)
    outward_normal = np.linalg.solve(L.T, on)
    outward_normal /= np.linalg.norm(outward_normal)
    d = rng.normal(size=(2_000_000, 3))
    d /= lengths(d)[:, None]
    cos = d @ n[30]
    lune = 4.0 * np.mean(np.where((cos > 0) & (d @ outward_normal < 0), cos, 0.0))  # (1/pi) int cos
    F, _, _, _ = contour(body, x[30:31], n[30:31], inward=True)
    assert abs(F[0] - lune) < 5e-3  # (the sampling error is about 9e-4)
    assert F[0] == pytest.approx(0.5 * (1.0 - n[30] @ outward_normal), abs=1e-15)


def test_a_body_inside_a_whole_ellipsoid_sees_only_it():
    """Enclosure rule through the pair factors: a NURBS torus (generic on both sides of the pair)
    inside an ellipsoid's inward front, F = 1 at tol 1e-9 (the cell cubature came to 0.992 with
    an error estimate of 4e-2 in its work budget)."""
    from tests.test_nurbs import CIRCLE, CIRCLE_KNOTS, CIRCLE_W, revolve

    tube = 0.7 * np.array([1.0, 0.0]) + 0.3 * CIRCLE
    points, weights = revolve(tube, CIRCLE_W, 1.0)
    torus = core.NurbsSurface(points, weights, 3, 3, CIRCLE_KNOTS, CIRCLE_KNOTS)
    x, normal = torus.evaluate(0.1, 0.1)
    torus = torus if normal @ x > 0 else torus.flipped()
    room = ellipsoid(axes=(2.4, 1.8, 0.9), angle=0.0).flipped()
    est = core.form_factor_estimate(torus, room, tol=1e-9)
    assert abs(est.value - 1.0) <= 1e-9 and est.error <= 1e-9


@pytest.mark.parametrize("gap", [0.05, 1.0])
def test_pair_with_whole_ellipsoid_matches_its_halves(gap):
    """F(quad -> ellipsoid) = sum over its halves (generic cubature), and reciprocity, at tol 1e-8."""
    body = ellipsoid(center=(0.0, 0.0, 1.0 + gap))
    quad = core.Quad((-1.5, -1.0, 0.0), (1.5, -1.0, 0.0), (1.5, 1.0, 0.2), (-1.5, 1.0, 0.2))
    tol = 1e-8
    whole = core.form_factor_estimate(quad, body, tol=tol)
    halves = sum(core.form_factor(quad, half, tol=tol) for half in body.split(2, 1))
    assert abs(whole.value - halves) <= 3 * tol * halves
    back = core.form_factor(body, quad, tol=tol)
    assert back * body.area() == pytest.approx(whole.value * quad.area(), rel=3 * tol)


def test_two_ellipsoids_reciprocity_and_halves():
    """Two whole ellipsoids near each other (no exact side): reciprocity and additivity at tol 1e-7."""
    a = ellipsoid()
    b = ellipsoid(axes=(0.5, 1.0, 0.7), center=(2.2, 0.3, -0.2), angle=1.1)
    tol = 1e-7
    F_ab = core.form_factor(a, b, tol=tol)
    F_ba = core.form_factor(b, a, tol=tol)
    assert F_ab * a.area() == pytest.approx(F_ba * b.area(), rel=3 * tol)
    halves = sum(core.form_factor(a, half, tol=tol) for half in b.split(1, 2))
    assert F_ab == pytest.approx(halves, rel=3 * tol)


def test_the_inside_of_a_flat_ellipsoid_sees_itself_whole():
    """F(inside -> itself) = 1 for a whole ellipsoid (semi-axes 1, 0.6, 0.15), and from a half of
    it to the whole (each point on it sees the inside through the whole hemisphere above its
    tangent plane); the issue measured over 60 s for the self factor."""
    body = core.Sphere((0.0, 0.0, 0.0), 1.0).transformed(np.diag([1.0, 0.6, 0.15, 1.0])).flipped()
    for source in (body, body.subpatch(u=(0.0, 0.5 * np.pi))):
        est = core.form_factor_estimate(source, body, tol=1e-6)
        assert abs(est.value - 1.0) <= 1e-6 and abs(est.value - 1.0) <= est.error + 1e-15
