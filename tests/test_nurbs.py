"""NurbsSurface: exact conics, derivatives, edge cases, transforms, input checks, Blender's knots.

References: Piegl & Tiller, "The NURBS Book" (2nd ed.), ch. 2 (basis functions), ch. 7 (the
nine-point rational quadratic circle, weights sqrt(2)/2 at the corners) and ch. 8 (surfaces of
revolution); Blender's knot rule is `calcknots` in source/blender/blenkernel/intern/curve.cc.
"""

import tracemalloc

import numpy as np
import pytest

from core import Quad, nurbs
from core.nurbs import NurbsSurface, basis_functions, blender_knots, find_spans, nonempty_spans

S = np.sqrt(0.5)
CIRCLE = np.array([(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)], float)
CIRCLE_W = np.array([1, S, 1, S, 1, S, 1, S, 1])
CIRCLE_KNOTS = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]
HALF = np.array([(0, -1), (1, -1), (1, 0), (1, 1), (0, 1)], float)  # (radius, z), south to north
HALF_W = np.array([1, S, 1, S, 1])
HALF_KNOTS = [0, 0, 0, 0.5, 0.5, 1, 1, 1]


def revolve(profile, profile_w, radius):
    """Control net of the surface of revolution about z (Piegl & Tiller A8.1): u around, v along.

    Returns
    -------
    points : ndarray, shape (9, m, 3)
    weights : ndarray, shape (9, m)
    """
    r, z = profile[:, 0], profile[:, 1]
    points = np.stack(
        [
            CIRCLE[:, None, 0] * r[None, :],
            CIRCLE[:, None, 1] * r[None, :],
            np.broadcast_to(z[None, :], (9, r.size)),
        ],
        -1,
    )
    return radius * points, CIRCLE_W[:, None] * profile_w[None, :]


def nurbs_sphere(radius=1.5, center=(0.0, 0.0, 0.0)):
    points, weights = revolve(HALF, HALF_W, radius)
    return NurbsSurface(points + center, weights, 3, 3, CIRCLE_KNOTS, HALF_KNOTS)


def random_surface(seed=3, order_u=4, order_v=3, nu=7, nv=5, log_weight=1.0):
    """A curved, non-uniform, rational surface with repeated interior knots."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    points = np.stack([i, j, np.sin(i) * np.cos(j)], -1) + 0.2 * rng.standard_normal((nu, nv, 3))
    weights = 10.0 ** rng.uniform(-log_weight, log_weight, (nu, nv))
    inner_u = np.sort(rng.uniform(0.1, 0.9, nu - order_u))
    inner_u[1] = inner_u[0]  # a double interior knot
    knots_u = np.concatenate([np.zeros(order_u), inner_u, np.ones(order_u)])
    knots_v = np.concatenate([[-1.0] * order_v, np.linspace(-1, 2, nv - order_v + 2)[1:-1], [2.0] * order_v])
    return NurbsSurface(points, weights, order_u, order_v, knots_u, knots_v)


def grid(surface, n=23):
    (u0, u1), (v0, v1) = surface.domain
    return np.meshgrid(np.linspace(u0, u1, n), np.linspace(v0, v1, n), indexing="ij")


def cox_de_boor(knots, i, k, t, last):
    """B-spline N_{i,k} (order k) by the recursive definition; right-continuous except at `last`."""
    if k == 1:
        if knots[i] <= t < knots[i + 1] or (t == last and knots[i] < t == knots[i + 1]):
            return 1.0
        return 0.0
    out = 0.0
    if knots[i + k - 1] > knots[i]:
        out += (t - knots[i]) / (knots[i + k - 1] - knots[i]) * cox_de_boor(knots, i, k - 1, t, last)
    if knots[i + k] > knots[i + 1]:
        out += (knots[i + k] - t) / (knots[i + k] - knots[i + 1]) * cox_de_boor(knots, i + 1, k - 1, t, last)
    return out


# --------------------------------------------------------------------------- exact shapes
def test_degree_one_equals_bilinear_quad():
    """Order 2 x 2 with knots (0, 0, 1, 1) is the bilinear patch through the four corners."""
    p00, p10, p11, p01 = np.array([[0, 0, 0], [2, 0, 0.3], [2.2, 1.5, -0.2], [-0.1, 1, 0.1]])
    quad = Quad(p00, p10, p11, p01)
    nurbs = NurbsSurface([[p00, p01], [p10, p11]], np.ones((2, 2)), 2, 2, [0, 0, 1, 1], [0, 0, 1, 1])
    u, v = grid(quad, 11)
    for a, b in zip(quad.evaluate(u, v), nurbs.evaluate(u, v)):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-14)
    assert nurbs.area() == pytest.approx(quad.area(), rel=1e-12)
    assert nurbs.geometry.plane is None


def test_flat_quad_has_plane_along_front_normal():
    """A flat control net reports its plane, oriented like dP/du x dP/dv, as `Quad` does."""
    p00, p10, p11, p01 = np.array([[0, 0, 1], [2, 0, 1], [2, 1, 1], [0, 1, 1]], float)
    nurbs = NurbsSurface([[p00, p01], [p10, p11]], np.ones((2, 2)), 2, 2, [0, 0, 1, 1], [0, 0, 1, 1])
    origin, normal = nurbs.geometry.plane
    np.testing.assert_allclose(normal, Quad(p00, p10, p11, p01).geometry.plane[1], atol=1e-15)
    assert origin[2] == pytest.approx(1.0)
    assert nurbs.area() == pytest.approx(2.0, rel=1e-13)


def test_sphere_of_revolution_is_exact():
    """Nine-point circle x five-point half circle (P&T ch. 7-8): |P - c| = R and area 4 pi R^2."""
    radius, center = 1.5, np.array([0.3, -0.2, 1.0])
    sphere = nurbs_sphere(radius, center)
    u, v = grid(sphere, 41)
    points, normals = sphere.evaluate(u, v)
    np.testing.assert_allclose(np.linalg.norm(points - center, axis=-1), radius, rtol=1e-14)
    # the front is the outside: the normal points away from the centre
    outward = np.einsum("...i,...i", normals, points - center)
    assert np.all(outward >= -1e-12)
    assert sphere.area() == pytest.approx(4 * np.pi * radius**2, rel=1e-10)
    assert sphere.geometry.plane is None


def test_cylinder_of_revolution_is_exact():
    """Nine-point circle x straight segment: radius R, area 2 pi R h, normal outward."""
    radius, height = 0.7, 2.5
    points = np.stack([np.c_[radius * CIRCLE, np.zeros(9)], np.c_[radius * CIRCLE, np.full(9, height)]], 1)
    weights = np.stack([CIRCLE_W, CIRCLE_W], 1)
    cylinder = NurbsSurface(points, weights, 3, 2, CIRCLE_KNOTS, [0, 0, 1, 1])
    u, v = grid(cylinder, 37)
    p, n = cylinder.evaluate(u, v)
    np.testing.assert_allclose(np.hypot(p[..., 0], p[..., 1]), radius, rtol=1e-14)
    assert np.all(np.einsum("...i,...i", n[..., :2], p[..., :2]) > 0)
    assert cylinder.area() == pytest.approx(2 * np.pi * radius * height, rel=1e-10)


# --------------------------------------------------------------------------- basis and derivatives
def test_basis_matches_cox_de_boor_and_sums_to_one():
    """A2.2/A2.3 basis equals the recursive definition; values sum to 1 and derivatives to 0."""
    knots = np.array([0, 0, 0, 0, 0.2, 0.2, 0.5, 0.9, 1, 1, 1, 1], float)
    order, count = 4, 8
    t = np.concatenate([np.linspace(0, 1, 57), [0.2, 0.5, 1.0]])
    span = find_spans(*nonempty_spans(knots, order, count), t)
    N, dN = basis_functions(knots, order, span, t)
    np.testing.assert_allclose(N.sum(1), 1.0, atol=1e-15)
    np.testing.assert_allclose(dN.sum(1), 0.0, atol=1e-12)
    assert np.all(N >= 0)
    for k in range(t.size):
        for r in range(order):
            i = span[k] - order + 1 + r
            assert N[k, r] == pytest.approx(cox_de_boor(knots, i, order, t[k], 1.0), abs=1e-14)


def test_constant_net_gives_constant_surface():
    """Partition of unity of the rational basis: equal control points give a constant P, zero dP."""
    base = random_surface()
    point = np.array([0.5, -2.0, 3.0])
    # a constant net has no area, so NurbsSurface rejects it: evaluate the geometry directly
    geometry = type(base.geometry)(
        np.broadcast_to(point, base.points.shape),
        base.weights,
        4,
        3,
        base.geometry.knots_u,
        base.geometry.knots_v,
    )
    u, v = grid(base, 15)
    P, Pu, Pv = geometry.derivatives(u, v)
    np.testing.assert_allclose(P, np.broadcast_to(point, P.shape), rtol=1e-14)
    assert np.abs(Pu).max() < 1e-11 and np.abs(Pv).max() < 1e-11


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_derivatives_match_central_differences(seed):
    """dP/du and dP/dv equal central differences (h = 1e-6) away from knots, to ~1e-7."""
    surface = random_surface(seed)
    rng = np.random.default_rng(seed)
    (u0, u1), (v0, v1) = surface.domain
    u = rng.uniform(u0 + 0.01, u1 - 0.01, 200)
    v = rng.uniform(v0 + 0.01, v1 - 0.01, 200)
    knots_u, knots_v = surface.geometry.knots_u, surface.geometry.knots_v
    h = 1e-6
    keep = (np.abs(u[:, None] - knots_u).min(1) > 2 * h) & (np.abs(v[:, None] - knots_v).min(1) > 2 * h)
    u, v = u[keep], v[keep]
    _, Pu, Pv = surface.derivatives(u, v)
    fu = (surface.derivatives(u + h, v)[0] - surface.derivatives(u - h, v)[0]) / (2 * h)
    fv = (surface.derivatives(u, v + h)[0] - surface.derivatives(u, v - h)[0]) / (2 * h)
    scale = np.abs(Pu).max() + np.abs(Pv).max()
    assert np.abs(Pu - fu).max() < 1e-7 * scale, f"seed {seed}"
    assert np.abs(Pv - fv).max() < 1e-7 * scale, f"seed {seed}"


def test_batched_evaluation_matches_pointwise_and_keeps_shape():
    """One call on a (5, 4) grid equals 20 scalar calls; outputs have shape S + (3,)."""
    surface = random_surface()
    u, v = grid(surface, 20)
    u, v = u[::4, ::5], v[::4, ::5]
    P, Pu, Pv = surface.derivatives(u, v)
    assert P.shape == Pu.shape == Pv.shape == u.shape + (3,)
    for idx in np.ndindex(u.shape):
        p, pu, pv = surface.derivatives(u[idx], v[idx])
        assert p.shape == (3,)
        np.testing.assert_allclose(np.stack([p, pu, pv]), np.stack([P[idx], Pu[idx], Pv[idx]]), rtol=1e-13)


# --------------------------------------------------------------------------- edge cases
def test_end_of_domain_interpolates_corners():
    """At u, v = last knot a clamped surface passes through the corner control points."""
    surface = random_surface()
    (u0, u1), (v0, v1) = surface.domain
    corners = surface.evaluate(np.array([u0, u1, u1, u0]), np.array([v0, v0, v1, v1]))[0]
    net = surface.points
    np.testing.assert_allclose(corners, [net[0, 0], net[-1, 0], net[-1, -1], net[0, -1]], atol=1e-13)
    # the end value is the limit from inside
    inside = surface.evaluate(u1 - 1e-10, v1 - 1e-10)[0]
    np.testing.assert_allclose(inside, net[-1, -1], atol=1e-8)
    assert np.all(np.isfinite(surface.evaluate(u1, v1)[1]))


def test_unclamped_knots_end_of_domain():
    """Uniform (unclamped) knots, as Blender's plain splines: the last span is closed at knots[n]."""
    knots = np.arange(9.0)
    points = np.stack([*np.meshgrid(np.arange(5.0), np.arange(4.0), indexing="ij"), np.zeros((5, 4))], -1)
    surface = NurbsSurface(points, np.ones((5, 4)), 4, 4, knots, knots[:8])
    (u0, u1), (v0, v1) = surface.domain
    assert (u0, u1, v0, v1) == (3.0, 5.0, 3.0, 4.0)
    end = surface.evaluate(u1, v1)[0]
    np.testing.assert_allclose(end, surface.evaluate(u1 - 1e-9, v1 - 1e-9)[0], atol=1e-8)
    # a uniform cubic B-spline ends at (P_{n-3} + 4 P_{n-2} + P_{n-1}) / 6
    np.testing.assert_allclose(end[:2], [(2 + 4 * 3 + 4) / 6, (1 + 4 * 2 + 3) / 6], atol=1e-14)


def test_repeated_interior_knots_interpolate_and_stay_continuous():
    """Knots of multiplicity p (the circle's 0.25, 0.5, 0.75) give P = control point there, C0."""
    sphere = nurbs_sphere(1.0)
    for k, t in enumerate([0.0, 0.25, 0.5, 0.75, 1.0]):
        p = sphere.evaluate(t, 0.5)[0]
        np.testing.assert_allclose(p, sphere.points[2 * k, 2], atol=1e-15)
        left, right = sphere.evaluate(np.array([t - 1e-12, t + 1e-12]), 0.5)[0]
        np.testing.assert_allclose(left, p, atol=1e-11)
        np.testing.assert_allclose(right, p, atol=1e-11)


def test_extreme_weights_stay_finite_and_in_hull():
    """Weights from 1e-4 to 1e4: finite points and derivatives inside the control points' box."""
    surface = random_surface(seed=5, log_weight=4.0)
    assert surface.weights.min() < 1e-3 and surface.weights.max() > 1e3
    u, v = grid(surface, 61)
    P, Pu, Pv = surface.derivatives(u, v)
    assert np.all(np.isfinite(P)) and np.all(np.isfinite(Pu)) and np.all(np.isfinite(Pv))
    lo, hi = surface.points.reshape(-1, 3).min(0), surface.points.reshape(-1, 3).max(0)
    assert np.all(P >= lo - 1e-12) and np.all(P <= hi + 1e-12)


def test_collapsed_edges_poles():
    """Sphere poles (an edge of the control net collapsed to a point): zero normal, no NaN, right area."""
    radius = 2.0
    sphere = nurbs_sphere(radius)
    u = np.linspace(0, 1, 33)
    for v in (0.0, 1.0):
        points, normals = sphere.evaluate(u, np.full_like(u, v))
        assert np.all(np.isfinite(points)) and np.all(np.isfinite(normals))
        np.testing.assert_allclose(
            points, np.broadcast_to([0, 0, radius * (2 * v - 1)], points.shape), atol=1e-15
        )
        assert np.linalg.norm(normals, axis=-1).max() <= 1e-14
    # a cap touching the north pole: area 2 pi R^2 (1 - cos theta) with theta the cap's polar angle
    cap = sphere.subpatch(v=(0.75, 1.0))
    z = cap.evaluate(0.0, 0.75)[0][2]
    assert cap.area() == pytest.approx(2 * np.pi * radius * (radius - z), rel=1e-10)


def test_split_shares_geometry_and_areas_add_up():
    """split() cuts patches that share one geometry; their areas sum to the whole."""
    surface = random_surface()
    parts = surface.split(3, 2)
    assert all(p.geometry is surface.geometry for p in parts)
    assert sum(p.area() for p in parts) == pytest.approx(surface.area(), rel=1e-11)


# --------------------------------------------------------------------------- area anywhere
def quarter_cylinder(radius=1.0, height=2.0, shift=0.0, mobius=1.0, knots_v=(0, 0, 1, 1), z=None):
    """Rational quadratic quarter of a cylinder (u) times a straight segment (v).

    The arc is the Bezier quarter circle of Piegl & Tiller (ch. 7), weights (1, sqrt(2)/2, 1).
    `mobius` = c multiplies weight i by c^i: the same arc under a rational linear (Moebius)
    reparametrisation of the Bezier curve (Piegl & Tiller ch. 6, reparameterization with a
    linear rational function; Farin's "standard form" is the inverse step), so
    the surface, and its area pi r h / 2, do not change while the weights reach c^2. `z` gives
    the heights of the degree-1 v net (knots `knots_v`); they must rise monotonically to height.
    """
    z = np.array([0.0, height] if z is None else z)
    arc = radius * np.array([(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
    points = np.stack(
        [
            np.broadcast_to(arc[:, None, 0], (3, z.size)),
            np.broadcast_to(arc[:, None, 1], (3, z.size)),
            np.broadcast_to(z[None, :], (3, z.size)),
        ],
        -1,
    )
    weights = np.array([1.0, S * mobius, mobius**2])[:, None] * np.ones(z.size)
    return NurbsSurface(points + shift, weights, 3, 2, [0, 0, 0, 1, 1, 1], knots_v)


def flat_sheet(shift=0.0, knots_u=(0, 0, 1, 1), x=(0.0, 1.0)):
    """Degree-1 sheet over the unit square in z = 0 (u along x through the control abscissae `x`)."""
    x = np.asarray(x, float)
    X, Y = np.meshgrid(x, [0.0, 1.0], indexing="ij")
    points = np.stack([X, Y, np.zeros_like(X)], -1) + shift
    return NurbsSurface(points, np.ones(X.shape), 2, 2, knots_u, [0, 0, 1, 1])


SHIFTS = [0.0, 10.0, 1e3, 1e4]


@pytest.mark.parametrize("shift", SHIFTS)
@pytest.mark.parametrize(
    "name, make, exact",
    [
        ("sphere", lambda t: nurbs_sphere(1.5, center=(t, -0.5 * t, 0.25 * t)), 4 * np.pi * 1.5**2),
        ("quarter cylinder", lambda t: quarter_cylinder(shift=t), np.pi / 2 * 2.0),
        ("cylinder, weights 1 .. 1e6", lambda t: quarter_cylinder(shift=t, mobius=1e3), np.pi / 2 * 2.0),
        ("cylinder, weights 1 .. 1e-8", lambda t: quarter_cylinder(shift=t, mobius=1e-4), np.pi / 2 * 2.0),
        ("bilinear sheet", lambda t: flat_sheet(shift=t), 1.0),
    ],
    ids=lambda x: x if isinstance(x, str) else "",
)
def test_area_of_exact_shapes_anywhere(name, make, exact, shift):
    """Area of exactly known NURBS nets at translations 0 .. 1e4 and weights up to 1e6 (ratio).

    Sphere 4 pi r^2 (revolved semicircle), quarter cylinder pi r h / 2 (Bezier arc), a unit
    sheet; within 1e-10 of the exact value, so also of the near-origin value, with an error
    estimate below 1e-12 relative, well inside the budget.
    """
    surface = make(shift)
    value, error, evaluations = surface.area_estimate()
    assert abs(value - exact) <= 1e-10 * exact, f"{name} at {shift}: {value!r} vs {exact!r}"
    assert surface.area() == value
    assert error <= 1e-12 * exact and evaluations < nurbs.AREA_BUDGET


def test_area_sees_shape_inside_tiny_knot_spans():
    """Spans of 1e-200 and 1e-300 carry finite parts of the surface; the area still adds up.

    Degree 1 in u through x = 0, 0.3, 0.7, 1 with knots 0, 0, 1e-200, 2e-200, 1, 1: the first
    70 % of the unit sheet lie in two spans of length 1e-200 (derivatives 3e199, 4e199). A quarter
    cylinder whose height rises to 40 % within v in [0, 1e-300] likewise keeps pi r h / 2.
    """
    sheet = flat_sheet(knots_u=[0, 0, 1e-200, 2e-200, 1, 1], x=[0.0, 0.3, 0.7, 1.0])
    assert sheet.area() == pytest.approx(1.0, rel=1e-12)
    tall = quarter_cylinder(shift=1e3, knots_v=[0, 0, 1e-300, 1, 1], z=[0.0, 0.8, 2.0])
    assert tall.area() == pytest.approx(np.pi, rel=1e-10)
    # points inside the short spans are where they belong, derivatives finite
    P, Pu, Pv = sheet.derivatives(np.array([5e-201, 1.5e-200, 2e-200, 0.5]), np.full(4, 0.5))
    np.testing.assert_allclose(
        P[:, 0], [0.15, 0.5, 0.7, 0.7 + 0.3 * (0.5 - 2e-200) / (1 - 2e-200)], rtol=1e-14
    )
    np.testing.assert_allclose(Pu[:2, 0], [3e199, 4e199], rtol=1e-14)
    assert np.all(np.isfinite(Pu)) and np.all(np.isfinite(Pv))


def test_area_translation_and_weight_scale_invariance_of_a_random_net():
    """A random rational net (weights 1e-2 .. 1e2): moving it by 1e4 or scaling every weight by
    1e6 changes nothing, so its area must agree to 1e-10 (the old evaluation lost 4 digits of
    its derivatives at 1e4 and never met its tolerance)."""
    base = random_surface(seed=8, log_weight=2.0)
    args = (base.geometry.order_u, base.geometry.order_v, base.geometry.knots_u, base.geometry.knots_v)
    moved = NurbsSurface(base.points + [1e4, -1e4, 3e3], base.weights, *args)
    heavy = NurbsSurface(base.points, base.weights * 1e6, *args)
    reference = base.area()
    assert moved.area() == pytest.approx(reference, rel=1e-10)
    assert heavy.area() == pytest.approx(reference, rel=1e-10)


def test_area_budget_is_bounded_and_honest():
    """Budgets too small for the tolerance: area_estimate stops within each; its error estimate
    is inf before any comparison, reaches 1e-12 within a budget of 9000 and, once below 1e-6
    relative (the halves resolve the integrand), bounds the true error; area() raises a
    ValueError saying what was reached."""
    surface = quarter_cylinder(shift=1e3, mobius=1e3)
    exact = np.pi
    errors = []
    for budget in range(100, 9_000, 500):
        value, error, evaluations = surface.area_estimate(max_evaluations=budget)
        assert evaluations <= budget
        errors.append(error)
        if error <= 1e-6 * exact:
            assert abs(value - exact) <= error, f"budget {budget}: error {error} < true {abs(value - exact)}"
    assert errors[0] == np.inf and errors[-1] <= 1e-12 * exact
    tight = quarter_cylinder(shift=1e3, mobius=1e3)
    original = nurbs.AREA_BUDGET
    try:
        nurbs.AREA_BUDGET = 2_000
        with pytest.raises(
            ValueError, match=r"did not converge: .* estimated error .* after \d+ evaluations"
        ):
            tight.area()
    finally:
        nurbs.AREA_BUDGET = original


def test_area_memory_is_bounded():
    """The hardest net here (one weight 1e6 in a 5 x 5 quadratic sheet at 1e3) stays within the
    budget and under 200 MB of traced allocations (the old area died with MemoryError)."""
    i, j = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
    points = np.stack([i, j, 0.3 * np.sin(i + 2 * j)], -1) / 4.0 + 1e3
    weights = np.ones((5, 5))
    weights[1, 3] = 1e6
    knots = [0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1]
    surface = NurbsSurface(points, weights, 3, 3, knots, knots)
    tracemalloc.start()
    try:
        value, error, evaluations = surface.area_estimate()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert evaluations <= nurbs.AREA_BUDGET and peak < 200e6
    assert np.isfinite(value) and error <= nurbs.AREA_ACCEPT * value


# --------------------------------------------------------------------------- transforms
@pytest.mark.parametrize("mirror", [False, True])
def test_transformed_matches_transforming_points(mirror):
    """The image of P under M is P of the image; the front normal follows (also when mirrored)."""
    rng = np.random.default_rng(7)
    linear = rng.standard_normal((3, 3)) + 2 * np.eye(3)
    if mirror:
        linear[:, 0] *= -1
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = linear, [1.0, -2.0, 0.5]
    surface = random_surface()
    image = surface.transformed(matrix)
    u, v = grid(surface, 9)
    P, n = surface.evaluate(u, v)
    Q, m = image.evaluate(u, v)
    np.testing.assert_allclose(Q, P @ linear.T + matrix[:3, 3], atol=1e-12)
    # n transforms as a cofactor: det(L) L^-T n, and the front side is kept: sign by det
    expected = np.sign(np.linalg.det(linear)) * np.linalg.det(linear) * n @ np.linalg.inv(linear)
    np.testing.assert_allclose(m, expected, atol=1e-10 * np.abs(expected).max())
    assert image.orientation == (-1 if mirror else 1)


def test_transformed_sphere_keeps_outside_front():
    """A mirrored, scaled NURBS sphere is still seen from outside and has area (2 R)^2 4 pi."""
    sphere = nurbs_sphere(1.0)
    mirrored = sphere.transformed(np.diag([-2.0, 2.0, 2.0, 1.0]))
    p, n = mirrored.evaluate(*grid(mirrored, 9))
    assert np.all(np.einsum("...i,...i", n, p) >= -1e-12)
    assert mirrored.area() == pytest.approx(16 * np.pi, rel=1e-10)


# --------------------------------------------------------------------------- bad input
GOOD = dict(
    points=np.stack([*np.meshgrid(np.arange(3.0), np.arange(3.0), indexing="ij"), np.eye(3)], -1),
    weights=np.ones((3, 3)),
    order_u=2,
    order_v=3,
    knots_u=[0, 0, 0.5, 1, 1],
    knots_v=[0, 0, 0, 1, 1, 1],
)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(points=np.full((3, 3, 3), np.nan)), "NaN or infinite"),
        (dict(points=np.ones((3, 3, 2))), "shape"),
        (dict(points=np.ones((9, 3))), "shape"),
        (dict(weights=np.ones((3, 2))), "weights must have shape"),
        (dict(weights=np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]])), "positive"),
        (dict(weights=-np.ones((3, 3))), "positive"),
        (dict(weights=np.full((3, 3), np.inf)), "NaN or infinite"),
        (dict(order_u=1, knots_u=[0, 1, 2, 3]), "at least 2"),
        (dict(order_u=2.5), "integer"),
        (dict(order_u=4, knots_u=[0] * 4 + [1] * 3), "too few NURBS points along u"),
        (dict(knots_u=[0, 0, 1, 1]), "knots_u must have shape"),
        (dict(knots_v=[0, 0, 1, 0.5, 1, 1]), "non-decreasing"),
        (dict(knots_u=[0, 0, 0, 0, 1]), "zero-length domain"),
        (dict(knots_v=[0, 0, 0, np.inf, 1, 1]), "NaN or infinite"),
        (dict(points=np.zeros((3, 3, 3))), "no area"),
    ],
)
def test_bad_input_raises_value_error(change, message):
    """Every malformed input raises ValueError whose message names the problem."""
    with pytest.raises(ValueError, match=message):
        NurbsSurface(**{**GOOD, **change})


def test_good_input_and_any_float_dtype():
    """The reference input is accepted, also as float32 and ints; data is float64 inside."""
    a = NurbsSurface(**GOOD)
    b = NurbsSurface(**{**GOOD, "points": GOOD["points"].astype(np.float32), "knots_u": [0, 0, 1, 2, 2]})
    assert a.points.dtype == b.points.dtype == np.float64
    assert b.domain == ((0.0, 2.0), (0.0, 1.0))


# --------------------------------------------------------------------------- Blender
@pytest.mark.parametrize(
    "count, order, endpoint, bezier, cyclic, expected",
    [
        # plain: uniform 0, 1, 2, ...
        (4, 4, False, False, False, [0, 1, 2, 3, 4, 5, 6, 7]),
        # endpoint: order-fold ends
        (5, 3, True, False, False, [0, 0, 0, 1, 2, 3, 3, 3]),
        # Bezier: interior knots (order - 1)-fold, head min(2, order - 1)-fold
        (5, 3, False, True, False, [0, 0, 1, 1, 2, 2, 3, 3]),
        (7, 4, False, True, False, [0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]),
        (5, 3, True, True, False, [0, 0, 0, 1, 1, 2, 2, 2]),
        # endpoint + Bezier with an incomplete last group: it merges into the end knot
        (4, 3, True, True, False, [0, 0, 0, 1, 1, 1, 1]),
        # cyclic: count + 2 order - 1 knots, the tail repeats the head's spacing
        (4, 3, False, False, True, [0, 1, 2, 3, 4, 5, 6, 7, 8]),
        (4, 3, True, False, True, [0, 1, 1, 2, 3, 4, 4, 5, 6]),
        (4, 3, False, True, True, [0, 0, 1, 1, 2, 2, 3, 3, 4]),
        (8, 3, True, True, True, [0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6]),
    ],
)
def test_blender_knots_by_hand(count, order, endpoint, bezier, cyclic, expected):
    """Knot vectors derived by hand from `calcknots` (source/blender/blenkernel/intern/curve.cc).

    Blender counts knots from 0 in steps of 1: interior values repeat order - 1 times with the
    Bezier flag (else once); with endpoint the first and last values repeat `order` times; a
    cyclic spline gets count + 2 order - 1 knots whose last 2 order - 1 repeat the spacing of
    the first ones (with endpoint + cyclic: one 0, then order - 1 copies of 1).
    """
    np.testing.assert_array_equal(blender_knots(count, order, endpoint, bezier, cyclic), expected)


def blender_sphere_points(weight=S):
    """Blender's NURBS sphere primitive in its storage order (u fastest), shape (40, 4).

    u: 5-point half circle from (0, 0, -1) to (0, 0, 1) (endpoint + Bezier); v: 8-point circle
    about z (cyclic + endpoint + Bezier). Blender stores the weight 0.7071 in float32; `weight`
    lets the test use the exact sqrt(2)/2.
    """
    profile = np.array([(0, -1, 1), (1, -1, weight), (1, 0, 1), (1, 1, weight), (0, 1, 1)])
    ring = np.array(
        [
            (-1, 0, 1),
            (-1, -1, weight),
            (0, -1, 1),
            (1, -1, weight),
            (1, 0, 1),
            (1, 1, weight),
            (0, 1, 1),
            (-1, 1, weight),
        ]
    )
    co = np.empty((8, 5, 4))
    co[..., 0] = ring[:, None, 0] * profile[None, :, 0]
    co[..., 1] = ring[:, None, 1] * profile[None, :, 0]
    co[..., 2] = profile[None, :, 1]
    co[..., 3] = ring[:, None, 2] * profile[None, :, 2]
    return co.reshape(40, 4)


def test_from_blender_sphere_is_exact_with_poles():
    """Blender's sphere layout with weights sqrt(2)/2: cyclic wrapping gives the unit sphere."""
    sphere = NurbsSurface.from_blender(
        blender_sphere_points(), 3, 3, 5, 8, True, True, True, True, False, True
    )
    assert sphere.points.shape == (5, 10, 3)  # v wrapped by order - 1 = 2 points
    assert sphere.domain == ((0.0, 2.0), (1.0, 5.0))
    p, n = sphere.evaluate(*grid(sphere, 41))
    np.testing.assert_allclose(np.linalg.norm(p, axis=-1), 1.0, rtol=1e-14)
    assert np.all(np.isfinite(n))
    assert sphere.area() == pytest.approx(4 * np.pi, rel=1e-10)
    # closed in v: the seam matches
    np.testing.assert_allclose(sphere.evaluate(0.7, 1.0)[0], sphere.evaluate(0.7, 5.0)[0], atol=1e-15)


def test_from_blender_plain_surface_and_order_clamp():
    """A 4 x 4 plain grid: uniform knots 0..7, domain [3, 4]; order 6 is clamped to 4 like Blender."""
    i, j = np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="xy")  # u fastest
    co = np.stack([i.ravel(), j.ravel(), (i * j).ravel() / 9, np.ones(16)], -1)
    a = NurbsSurface.from_blender(co, 4, 4, 4, 4)
    b = NurbsSurface.from_blender(co, 6, 4, 4, 4)
    assert a.domain == b.domain == ((3.0, 4.0), (3.0, 4.0))
    np.testing.assert_array_equal(a.points[:, 0, 0], [0, 1, 2, 3])  # u runs along storage rows
    np.testing.assert_array_equal(a.geometry.knots_u, np.arange(8.0))
    assert b.geometry.order_u == 4


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(order_u=3, point_count_u=3, use_bezier_u=True), "Bezier option along u needs 1 more"),
        (dict(order_v=3, point_count_v=5, use_bezier_v=True, use_cyclic_v=True), "along v needs 1 more"),
        (dict(point_count_u=1, point_count_v=9), "at least 2 points along u"),
        (dict(order_u=1), "at least 2"),
    ],
)
def test_from_blender_rejects_what_blender_does_not_draw(kwargs, message):
    """Splines Blender's `nurb_check_valid` rejects (curve.cc) raise ValueError here."""
    args = dict(order_u=2, order_v=2, point_count_u=3, point_count_v=3)
    args.update(kwargs)
    n = args["point_count_u"] * args["point_count_v"]
    co = np.c_[np.random.default_rng(0).standard_normal((n, 3)), np.ones(n)]
    with pytest.raises(ValueError, match=message):
        NurbsSurface.from_blender(co, **args)
