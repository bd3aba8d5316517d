"""Occluders: segment visibility against exact spheres, quads, disks, cylinders and NURBS proxies.

References are closed forms written out in the tests: a segment a + t (b - a) meets the sphere
|x - c| = R where |a - c + t d|^2 = R^2 (a quadratic in t), a plane n . x = k at
t = (k - n . a) / (n . d); a NURBS surface is compared with the analytic shape it represents
exactly (Piegl & Tiller, "The NURBS Book", ch. 7-8: nine-point circle, surfaces of revolution).
"""

import numpy as np
import pytest

# exact NURBS circle and sphere (Piegl & Tiller A8.1), shared with the NURBS tests
from test_nurbs import CIRCLE, CIRCLE_KNOTS, CIRCLE_W, nurbs_sphere

from core import Cylinder, Disk, NurbsSurface, Quad, Sphere
from core.occlusion import CYLINDER, DISK, MESH, QUAD, SPHERE, Occluders
from core.visibility import blocked_rays


def nurbs_cylinder(radius, height):
    """Exact NURBS cylinder about z: nine-point circle x straight segment."""
    ring = np.c_[radius * CIRCLE, np.zeros(9)]
    points = np.stack([ring, ring + [0.0, 0.0, height]], 1)
    return NurbsSurface(points, np.stack([CIRCLE_W, CIRCLE_W], 1), 3, 2, CIRCLE_KNOTS, [0, 0, 1, 1])


def sphere_crossing(a, b, center, radius):
    """Reference: the open segment a -> b crosses the sphere (a root of the quadratic in (0, 1)).

    Returns the answer and the closest distance of the line to the centre (for band tests).
    """
    d, f = b - a, a - center
    A, B, C = (d * d).sum(1), (f * d).sum(1), (f * f).sum(1) - radius**2
    disc = B * B - A * C
    root = np.sqrt(np.maximum(disc, 0.0))
    t1, t2 = (-B - root) / A, (-B + root) / A
    crosses = (disc > 0) & (((t1 > 0) & (t1 < 1)) | ((t2 > 0) & (t2 < 1)))
    closest = np.sqrt(np.maximum(C + radius**2 - B * B / A, 0.0))
    return crosses, closest


def cylinder_crossing(a, b, radius, height, band=0.0):
    """Reference for the cylinder x^2 + y^2 = R^2, 0 < z < h: roots of |xy(t)|^2 = R^2 in (0, 1).

    Returns the answer and whether the segment is within `band` (m) of changing it: an endpoint
    near the lateral surface, a crossing near a rim, or a line near tangency.
    """
    d = b - a
    A = d[:, 0] ** 2 + d[:, 1] ** 2
    B = a[:, 0] * d[:, 0] + a[:, 1] * d[:, 1]
    C = a[:, 0] ** 2 + a[:, 1] ** 2 - radius**2
    disc = B * B - A * C
    root = np.sqrt(np.maximum(disc, 0.0))
    crosses = np.zeros(len(a), bool)
    near = np.abs(np.sqrt(np.maximum(C + radius**2 - B * B / A, 0.0)) - radius) < band  # tangency
    for t in ((-B - root) / A, (-B + root) / A):
        z = a[:, 2] + t * d[:, 2]
        crosses |= (disc > 0) & (t > 0) & (t < 1) & (z > 0) & (z < height)
        near |= (disc > 0) & (t > 0) & (t < 1) & ((np.abs(z) < band) | (np.abs(z - height) < band))
    for p in (a, b):
        r = np.hypot(p[:, 0], p[:, 1])
        near |= (np.abs(r - radius) < band) & (p[:, 2] > -band) & (p[:, 2] < height + band)
    return crosses, near


def random_segments(n, lo, hi, seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, (n, 3)), rng.uniform(lo, hi, (n, 3))


def sample(surface, n=40):
    """Points of a patch on an n x n grid of its domain, shape (n * n, 3)."""
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.meshgrid(np.linspace(u0, u1, n), np.linspace(v0, v1, n), indexing="ij")
    P, N = surface.evaluate(u.ravel(), v.ravel())
    return P, N


def one(occ, a, b, m=0):
    return bool(occ.blocked(np.atleast_2d(a), np.atleast_2d(b), [m])[0])


# --------------------------------------------------------------------------- attributes
def test_bounds_hold_every_surface_and_planes_are_right():
    """Boxes and balls hold dense samples of each patch; flat ones report n . x = d."""
    surfaces = [
        Sphere([1, 2, 3], 0.5).subpatch(u=(0.3, 1.2), v=(5.5, 2 * np.pi)),
        Sphere([0, 0, 0], 1.0).transformed(np.diag([2.0, 1.0, 0.5, 1.0])),
        Quad([0, 0, 0], [1, 0, 0.2], [1, 1, 0.2], [0, 1, 0]).subpatch(u=(0.2, 0.7)),
        Disk([0, 1, 0], [1, 1, 0], 2.0).subpatch(u=(0.5, 2.0), v=(1.0, 2.5)),
        Cylinder([0, 0, 0], [0, 1, 1], 0.7, 2.0).subpatch(u=(4.0, 6.0)),
        nurbs_sphere(1.5, np.array([3.0, 0.0, 0.0])).subpatch(u=(0.1, 0.6)),
        Quad([0, 0, 0], [1, 0, 0], [1, 1, 1], [0, 1, 0]),  # twisted: z = u v, a mesh occluder
    ]
    occ = Occluders(surfaces)
    assert list(occ.kind) == [SPHERE, SPHERE, QUAD, DISK, CYLINDER, MESH, MESH]
    for m, surface in enumerate(surfaces):
        P, N = sample(surface)
        assert np.all(P >= occ.box_min[m]) and np.all(P <= occ.box_max[m]), m
        assert np.linalg.norm(P - occ.center[m], axis=1).max() <= occ.radius[m], m
        if occ.planar[m]:
            assert np.abs(P @ occ.plane_normal[m] - occ.plane_offset[m]).max() < 1e-12
            assert abs(np.linalg.norm(occ.plane_normal[m]) - 1.0) < 1e-14
    # the hemisphere-cap subpatch's box is much smaller than the whole sphere's
    assert occ.box_max[0, 2] - occ.box_min[0, 2] < 0.5 * (2 * 0.5)
    assert list(occ.planar) == [False, False, True, True, False, False, False]
    assert list(occ.convex) == [True, True, True, True, True, False, False]
    # scale is the diagonal of the union box; eps follows it (and the chord error for meshes)
    assert occ.scale == pytest.approx(np.linalg.norm(occ.box_max.max(0) - occ.box_min.min(0)))
    assert occ.chord_error[5] > 0.0 and occ.chord_error[:5].max() == 0.0
    assert occ.eps[5] == pytest.approx(1e-9 * occ.scale + 2 * occ.chord_error[5])


# --------------------------------------------------------------------------- sphere
def test_sphere_between_and_beside():
    occ = Occluders([Sphere([0, 0, 0], 1.0)])
    assert one(occ, [-3, 0, 0], [3, 0, 0])
    assert one(occ, [-3, 0.99, 0], [3, 0.99, 0])
    assert not one(occ, [-3, 1.01, 0], [3, 1.01, 0])  # passes beside
    assert not one(occ, [-3, 0, 0], [-1.5, 0, 0])  # stops short
    assert one(occ, [0, 0, 0], [0, 0, 5])  # from inside out
    assert not one(occ, [0, 0, 0], [0.1, 0.2, 0.3])  # wholly inside
    assert not one(occ, [1, 1, 1], [1, 1, 1])  # a point: no warning, not blocked


def test_sphere_matches_quadratic_on_random_segments():
    """Exact agreement with the reference quadratic away from tangency (no band needed)."""
    a, b = random_segments(20000, -2.5, 2.5, seed=1)
    center, radius = np.array([0.2, -0.1, 0.3]), 1.1
    occ = Occluders([Sphere(center, radius), Sphere(center, radius).flipped()])
    ref, closest = sphere_crossing(a, b, center, radius)
    for m in (0, 1):
        got = occ.blocked(a, b, np.full(len(a), m))
        bad = got != ref
        # only tangent lines (closest approach within 1e-6 of R) could differ
        assert np.all(np.abs(closest[bad] - radius) < 1e-6)
        assert bad.sum() == 0
    assert 0.1 < ref.mean() < 0.9


def test_hemisphere_blocks_only_on_its_side():
    """u = polar angle from +z: u in (0, pi/2) is the northern half z > 0."""
    north = Sphere([0, 0, 0], 1.0).subpatch(u=(0.0, np.pi / 2))
    south = Sphere([0, 0, 0], 1.0).subpatch(u=(np.pi / 2, np.pi))
    occ = Occluders([north, south])
    a, b = (
        np.array([[-3, 0, 0.5], [-3, 0, -0.5], [0, 0, -3], [0, 0, 0.0]]),
        np.array([[3, 0, 0.5], [3, 0, -0.5], [0, 0, 0.0], [0, 0, 3]]),
    )
    np.testing.assert_array_equal(occ.blocked(a, b, np.zeros(4, int)), [True, False, False, True])
    np.testing.assert_array_equal(occ.blocked(a, b, np.ones(4, int)), [False, True, True, False])


def test_azimuth_wraparound_subpatch():
    """v in (5.5, 2 pi): azimuths from -0.78 to 0 rad; a ray at azimuth -0.3 hits, +0.3 does not."""
    occ = Occluders([Sphere([0, 0, 0], 1.0).subpatch(v=(5.5, 2 * np.pi))])
    for phi, expected in ((-0.3, True), (0.3, False), (-0.7, True), (-0.85, False)):
        direction = np.array([np.cos(phi), np.sin(phi), 0.1])
        assert one(occ, [0, 0, 0], 3 * direction) == expected, phi


def test_segments_on_the_sphere_itself():
    """Endpoints on the sphere: outward rays and chords are free; inward rays hit the far side."""
    sphere = Sphere([0.5, 0, 0], 2.0)
    occ = Occluders([sphere])
    P, N = sample(sphere, 30)
    keep = np.linalg.norm(N, axis=1) > 1e-6  # the poles repeat
    P, N = P[keep], N[keep] / np.linalg.norm(N[keep], axis=1)[:, None]
    zero = np.zeros(len(P), int)
    assert not occ.blocked(P, P + 3 * N, zero).any()  # leaving outward
    assert not occ.blocked(P + 3 * N, P, zero).any()  # arriving from outside
    assert occ.blocked(P, P - 5 * N, zero).all()  # inward: crosses the far side at distance 4
    # chords between random pairs of sphere points (the sphere is convex)
    rng = np.random.default_rng(3)
    i, j = rng.integers(0, len(P), (2, 3000))
    assert not occ.blocked(P[i], P[j], np.zeros(3000, int)).any()
    assert occ.convex[0]


def test_ellipsoid_blocks_where_the_ellipsoid_is():
    """diag(2, 1, 1) stretches x: x^2 / 4 + y^2 + z^2 = 1; x = 1.5 is inside it, not in the unit sphere."""
    ellipsoid = Sphere([0, 0, 0], 1.0).transformed(np.diag([2.0, 1.0, 1.0, 1.0]))
    occ = Occluders([ellipsoid, Sphere([0, 0, 0], 1.0)])
    a, b = np.array([[1.5, -3, 0], [2.1, -3, 0]]), np.array([[1.5, 3, 0], [2.1, 3, 0]])
    np.testing.assert_array_equal(occ.blocked(a, b, [0, 0]), [True, False])
    assert not occ.blocked(a, b, [1, 1]).any()
    # random segments: the ellipsoid is the unit sphere after x -> x / 2 (t is kept by the map)
    a, b = random_segments(5000, -3, 3, seed=5)
    scale = np.array([0.5, 1.0, 1.0])
    ref, closest = sphere_crossing(a * scale, b * scale, np.zeros(3), 1.0)
    got = occ.blocked(a, b, np.zeros(5000, int))
    assert np.all(np.abs(closest[got != ref] - 1.0) < 1e-6) and (got != ref).sum() == 0


def test_split_sphere_blocks_like_the_whole():
    """Seams between split patches block from both sides, so any_blocked(parts) == whole."""
    whole = Sphere([0, 0, 0], 1.0)
    parts = whole.split(4, 6)
    occ = Occluders([whole] + parts)
    a, b = random_segments(4000, -2, 2, seed=7)
    # include segments straight through seam points (u = pi / 4, v = pi / 3, the pole)
    seam = whole.evaluate(np.array([np.pi / 4, np.pi / 2, 0.0]), np.array([np.pi / 3, 0.0, 1.0]))[0]
    a = np.vstack([a, -2 * seam])
    b = np.vstack([b, 2 * seam])
    ref = occ.blocked(a, b, np.zeros(len(a), int))
    np.testing.assert_array_equal(occ.any_blocked(a, b, np.arange(1, len(parts) + 1)), ref)
    assert ref[-3:].all()


# --------------------------------------------------------------------------- quads
def test_flat_quad_inside_outside_and_endpoint():
    quad = Quad([0, 0, 1], [2, 0, 1], [2, 1, 1], [0, 1, 1])
    occ = Occluders([quad, quad.subpatch(u=(0.5, 1.0))])
    assert one(occ, [1, 0.5, 0], [1, 0.5, 2])
    assert not one(occ, [2.1, 0.5, 0], [2.1, 0.5, 2])  # beside the quad
    assert not one(occ, [1, 0.5, 1], [1, 0.5, 3])  # starts on the quad
    assert not one(occ, [0.3, 0.2, 0], [1, 0.5, 1])  # ends on it
    assert not one(occ, [0, 0.5, 1], [2, 0.5, 1])  # lies in its plane
    # subpatch u in (0.5, 1): x in (1, 2)
    assert not one(occ, [0.6, 0.5, 0], [0.6, 0.5, 2], 1)
    assert one(occ, [1.4, 0.5, 0], [1.4, 0.5, 2], 1)


def test_triangle_quad():
    """p01 = p00: the triangle (0,0), (1,0), (1,1) in z = 0 holds points with y < x."""
    occ = Occluders([Quad([0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0])])
    assert one(occ, [0.7, 0.2, -1], [0.7, 0.2, 1])
    assert not one(occ, [0.2, 0.7, -1], [0.2, 0.7, 1])
    rng = np.random.default_rng(2)
    xy = rng.uniform(-0.2, 1.2, (5000, 2))
    a = np.c_[xy, -np.ones(5000)]
    b = np.c_[xy + rng.normal(0, 0.01, (5000, 2)), np.ones(5000)]
    mid = 0.5 * (a + b)[:, :2]  # where the segment meets z = 0
    ref = (mid[:, 1] < mid[:, 0]) & (mid[:, 1] > 0) & (mid[:, 0] < 1)
    got = occ.blocked(a, b, np.zeros(5000, int))
    margin = np.minimum.reduce(
        [np.abs(mid[:, 1] - mid[:, 0]) / np.sqrt(2), np.abs(mid[:, 1]), np.abs(1 - mid[:, 0])]
    )
    assert np.all(margin[got != ref] < 1e-9)


def test_twisted_quad_uses_the_proxy():
    """Bilinear quad with p11 lifted: z = u v over the unit square; a vertical segment hits z = x y."""
    occ = Occluders([Quad([0, 0, 0], [1, 0, 0], [1, 1, 1], [0, 1, 0])])
    assert occ.kind[0] == MESH and not occ.convex[0]
    assert one(occ, [0.5, 0.5, -1], [0.5, 0.5, 2])
    assert not one(occ, [0.5, 0.5, 0.3], [0.5, 0.5, 2])  # starts above z = 0.25
    assert not one(occ, [0.5, 0.5, -1], [0.5, 0.5, 0.2])  # stops below it
    rng = np.random.default_rng(4)
    xy = rng.uniform(-0.1, 1.1, (3000, 2))
    z0, z1 = rng.uniform(-0.5, 1.5, (2, 3000))
    a, b = np.c_[xy, z0], np.c_[xy, z1]
    h = xy[:, 0] * xy[:, 1]
    ref = (np.minimum(z0, z1) < h) & (h < np.maximum(z0, z1)) & np.all((xy > 0) & (xy < 1), axis=1)
    got = occ.blocked(a, b, np.zeros(3000, int))
    band = 2 * occ.eps[0]
    near = (np.minimum(np.abs(z0 - h), np.abs(z1 - h)) < band) | np.any(
        np.minimum(np.abs(xy), np.abs(1 - xy)) < 1e-9, axis=1
    )
    assert np.all(near[got != ref])


# --------------------------------------------------------------------------- disk
def test_disk_annulus_and_sector():
    disk = Disk([0, 0, 0], [0, 0, 1], 1.0)
    occ = Occluders([disk, disk.subpatch(u=(0.5, 1.0)), disk.subpatch(v=(0.0, np.pi / 2))])
    assert one(occ, [0.3, 0.2, -1], [0.3, 0.2, 1])
    assert not one(occ, [0.9, 0.6, -1], [0.9, 0.6, 1])  # r = 1.08 > 1
    assert not one(occ, [0.3, 0.2, -1], [0.3, 0.2, 1], 1)  # r = 0.36 in the hole
    assert one(occ, [0.7, 0.2, -1], [0.7, 0.2, 1], 1)  # r = 0.73 on the ring
    # sector: aim at points of the disk by their parameters (the angle origin e1 is the frame's)
    inside, outside = disk.evaluate(np.array([0.8, 0.8]), np.array([0.3, 3.0]))[0]
    assert one(occ, inside + [0, 0, -1], inside + [0, 0, 1], 2)
    assert not one(occ, outside + [0, 0, -1], outside + [0, 0, 1], 2)
    assert not one(occ, inside, inside + [0.3, 0, 1], 0)  # starts on the disk
    # stretched by diag(2, 1, 1): the ellipse x^2 / 4 + y^2 < 1 holds (1.5, 0.3)
    ellipse = Occluders([disk.transformed(np.diag([2.0, 1.0, 1.0, 1.0]))])
    assert one(ellipse, [1.5, 0.3, -1], [1.5, 0.3, 1])
    assert not one(ellipse, [1.5, 0.7, -1], [1.5, 0.7, 1])  # 0.5625 + 0.49 > 1


# --------------------------------------------------------------------------- cylinder
def test_cylinder_lateral_surface_ends_and_angle():
    cylinder = Cylinder([0, 0, 0], [0, 0, 1], 1.0, 2.0)
    occ = Occluders([cylinder, cylinder.subpatch(u=(0.0, np.pi))])
    assert one(occ, [-3, 0, 1], [3, 0, 1])  # through the side
    assert not one(occ, [-3, 0, 2.5], [3, 0, 2.5])  # above it
    assert not one(occ, [0, 0, -1], [0, 0, 3])  # along the axis through the open ends
    assert not one(occ, [0.5, 0, -1], [0.2, 0.1, 3])  # through both open ends
    assert one(occ, [0.5, 0, 1], [3, 0, 3])  # out through the side
    assert not one(occ, [0.5, 0, 1], [3, 0, 9])  # out through the open top (z = 2 at x = 0.81)
    # half u in (0, pi): from the axis out through P(u, 1)
    for u, expected in ((1.0, True), (3.0, True), (4.0, False), (6.0, False)):
        P = cylinder.evaluate(u, 1.0)[0]
        axis_point = np.array([0, 0, 1.0])
        assert one(occ, axis_point, axis_point + 3 * (P - axis_point), 1) == expected, u
    # points of the cylinder: chords and outward rays are free
    P, N = sample(cylinder, 25)
    N = N / np.linalg.norm(N, axis=1)[:, None]
    rng = np.random.default_rng(8)
    i, j = rng.integers(0, len(P), (2, 2000))
    assert not occ.blocked(P[i], P[j], np.zeros(2000, int)).any()
    assert not occ.blocked(P, P + 2 * N, np.zeros(len(P), int)).any()


def test_cylinder_matches_reference_on_random_segments():
    """Reference: |xy(t)|^2 = R^2 roots in (0, 1) with 0 < z(t) < h, for a cylinder along z."""
    R, h = 0.8, 1.5
    occ = Occluders([Cylinder([0, 0, 0], [0, 0, 1], R, h)])
    a, b = random_segments(20000, -1.5, 2.0, seed=9)
    ref, _ = cylinder_crossing(a, b, R, h)
    got = occ.blocked(a, b, np.zeros(len(a), int))
    assert (got != ref).sum() == 0 and 0.05 < ref.mean() < 0.95


# --------------------------------------------------------------------------- NURBS
def test_nurbs_sphere_agrees_with_the_sphere_outside_a_thin_band():
    """The proxy of an exact NURBS sphere vs the analytic sphere on 4000 random segments.

    They may differ only where the true surface is within the proxy's band (2 chord errors +
    eps) of an endpoint or of tangency (line's closest distance to the centre near R).
    """
    center, radius = np.array([0.3, -0.2, 0.1]), 1.2
    occ = Occluders([nurbs_sphere(radius, center)])
    assert occ.kind[0] == MESH and 0.0 < occ.chord_error[0] < 1e-3 * radius
    a, b = random_segments(4000, -2, 2.5, seed=11)
    # and 2000 short segments starting within 5 % of the radius of the surface
    rng = np.random.default_rng(12)
    u = rng.standard_normal((2000, 3))
    start = center + radius * u / np.linalg.norm(u, axis=1)[:, None] * rng.uniform(0.95, 1.05, (2000, 1))
    a, b = np.vstack([a, start]), np.vstack([b, start + rng.normal(0, 0.3, (2000, 3))])
    ref, closest = sphere_crossing(a, b, center, radius)
    got = occ.blocked(a, b, np.zeros(len(a), int))
    band = 2 * occ.eps[0]
    dist_a = np.abs(np.linalg.norm(a - center, axis=1) - radius)
    dist_b = np.abs(np.linalg.norm(b - center, axis=1) - radius)
    in_band = (np.minimum(dist_a, dist_b) < band) | (np.abs(closest - radius) < band)
    bad = got != ref
    print(f"NURBS sphere: {bad.sum()} of {len(a)} disagree, {in_band.sum()} in the band")
    assert np.all(in_band[bad])
    assert bad.sum() <= 30 and 0.1 < ref.mean() < 0.9


@pytest.mark.parametrize("offset", [0.0, 1e3, 1e5])
def test_proxy_hierarchy_drops_no_segment_its_triangles_block(offset):
    """The proxy's tile hierarchy (single-precision box tests on padded boxes) against every
    leaf's triangles tested in double precision for every segment: the same hits, for
    segments through the proxy's own vertices (on tile boxes' faces, edges and corners), between
    two of its vertices, and from far away, with the surface at the origin and 1e3 and 1e5 away
    (and the leaves' slab shortcut checked with them)."""
    from core.occlusion import _Proxy

    u = np.linspace(0.0, 1.0, 4)
    U, V = np.meshgrid(u, u, indexing="ij")
    net = np.stack([U, 0.6 * np.sin(np.pi * U) + 0.3 * np.sin(np.pi * V), 1.3 * V], -1) + offset
    knots = [0, 0, 0, 0.5, 1, 1, 1]
    proxy = _Proxy(NurbsSurface(net, np.ones((4, 4)), 3, 3, knots, knots), None)
    nu, nv = proxy.resolution
    P = proxy.v0.transpose(0, 2, 1).reshape(-1, 3)  # (triangle corners: every grid vertex but the last row)
    rng = np.random.default_rng(21)
    through = P[rng.integers(0, len(P), 800)]
    far = through + rng.normal(0.0, 1.0, (800, 3)) * rng.choice([0.05, 1.0, 300.0], (800, 1))
    a = np.vstack([far, through - 1e-3 * (far - through), rng.uniform(-1, 2, (800, 3)) + offset])
    b = np.vstack([2.0 * through - far, through + (far - through), rng.uniform(-1, 2, (800, 3)) + offset])
    # from one triangle corner to the next in storage order, 1e-9 off both
    a = np.vstack([a, P[:-1] + 1e-9])
    b = np.vstack([b, P[1:] - 1e-9])
    D = b - a
    length = np.linalg.norm(D, axis=1)
    eps = np.full(len(a), 1e-9 * (1.0 + offset))

    def brute_force(a, D, length, eps):
        hit = np.zeros(len(a), dtype=bool)
        leaves = proxy.v0.shape[0]
        seg = np.repeat(np.arange(len(a)), leaves)
        leaf = np.tile(np.arange(leaves), len(a))
        proxy._triangles(a[seg], D[seg], length[seg], eps[seg], leaf, seg, hit)
        return hit

    brute = brute_force(a, D, length, eps)
    assert nu * nv > 100 and 0.2 < brute.mean() < 0.98
    assert np.array_equal(proxy.blocked(a, D, length, eps), brute)
    # segments from beyond single precision's range: the box tests keep double (a cast to
    # single would overflow, an error under this suite's warning filter)
    D = 1e40 * (b[:300] - a[:300])
    assert proxy.blocked(b[:300] - D, D, np.linalg.norm(D, axis=1), eps[:300]).shape == (300,)


def test_nurbs_segments_starting_on_the_surface():
    """From points of the NURBS sphere: outward not blocked, inward blocked by the far side."""
    center, radius = np.array([1.0, 0.0, 0.0]), 1.0
    sphere = nurbs_sphere(radius, center)
    occ = Occluders([sphere])
    P, N = sample(sphere, 24)
    keep = np.linalg.norm(N, axis=1) > 1e-6
    P = P[keep]
    out = (P - center) / radius
    zero = np.zeros(len(P), int)
    assert not occ.blocked(P, P + 2 * out, zero).any()
    assert occ.blocked(P, P - 3 * out, zero).all()


def test_nurbs_cylinder_matches_cylinder():
    """Exact NURBS cylinder (moved, split in two) vs the reference, outside a thin band."""
    matrix = np.eye(4)
    matrix[:3, 3] = [0.5, 0.0, -0.2]
    parts = nurbs_cylinder(0.8, 1.5).transformed(matrix).split(2, 1)
    occ = Occluders(parts)
    a, b = random_segments(4000, -1.5, 2.0, seed=12)
    got = occ.any_blocked(a, b, [0, 1])
    ref, near = cylinder_crossing(a - matrix[:3, 3], b - matrix[:3, 3], 0.8, 1.5, 2 * occ.eps.max())
    bad = got != ref
    print(f"NURBS cylinder: {bad.sum()} of {len(a)} disagree, {near.sum()} in the band")
    assert np.all(near[bad]) and 0.05 < ref.mean() < 0.95
    assert occ.chord_error.max() < 1e-3 * 0.8


def test_convex_surfaces_never_block_their_own_points():
    """convex: chords between points of one disk, flat quad, sphere cap or cylinder are free."""
    surfaces = [
        Disk([0, 0, 0], [1, 2, 3], 1.0).subpatch(u=(0.3, 1.0)),
        Quad([0, 0, 0], [1, 0, 0], [1, 1, 0.0], [0, 1, 0]),
        Sphere([0, 0, 0], 1.0).transformed(np.diag([1.0, 3.0, 0.5, 1.0])).subpatch(u=(0.2, 2.0)),
        Cylinder([0, 0, 0], [1, 0, 0], 0.5, 1.0),
    ]
    occ = Occluders(surfaces)
    rng = np.random.default_rng(13)
    for m, surface in enumerate(surfaces):
        assert occ.convex[m]
        P, _ = sample(surface, 30)
        i, j = rng.integers(0, len(P), (2, 3000))
        assert not occ.blocked(P[i], P[j], np.full(3000, m)).any(), m


# --------------------------------------------------------------------------- vectorised
def test_100k_segments_against_several_occluders():
    """100k random segments against a sphere, a quad and a NURBS sphere (one call each)."""
    occ = Occluders(
        [
            Sphere([0, 0, 0], 1.0),
            Quad([-1, -1, 1.5], [1, -1, 1.5], [1, 1, 1.5], [-1, 1, 1.5]),
            nurbs_sphere(1.0, np.array([2.5, 0.0, 0.0])),
        ]
    )
    a, b = random_segments(100_000, -3, 4, seed=14)
    index = np.random.default_rng(15).integers(0, 3, 100_000)
    got = occ.blocked(a, b, index)
    ref0, _ = sphere_crossing(a, b, np.zeros(3), 1.0)
    np.testing.assert_array_equal(got[index == 0], ref0[index == 0])
    ref2, closest = sphere_crossing(a, b, np.array([2.5, 0.0, 0.0]), 1.0)
    assert (got[index == 2] != ref2[index == 2]).sum() <= 20
    # the quad: z = 1.5 crossed inside |x|, |y| < 1
    t = (1.5 - a[:, 2]) / (b[:, 2] - a[:, 2])
    x = a + t[:, None] * (b - a)
    ref1 = (t > 0) & (t < 1) & (np.abs(x[:, 0]) < 1) & (np.abs(x[:, 1]) < 1)
    np.testing.assert_array_equal(got[index == 1], ref1[index == 1])
    assert occ.blocked(a[:0], b[:0], index[:0]).shape == (0,)
    assert not occ.any_blocked(a[:5], b[:5], []).any()
    anyb = occ.any_blocked(a[:2000], b[:2000], [0, 1, 2])
    each = np.stack([occ.blocked(a[:2000], b[:2000], np.full(2000, m)) for m in range(3)])
    np.testing.assert_array_equal(anyb, each.any(0))


def test_rays_meet_the_cheap_occluders_first_and_a_blocked_one_goes_no_further():
    """`visibility.blocked_rays` tests a segment's candidates kind by kind (`kinds.RAY_TEST_ORDER`:
    spheres and quads before a NURBS proxy) and sends to the proxy only the segments nothing
    before it blocked; the answer is each segment's OR over its candidates, tested one by one."""
    shift = np.eye(4)
    shift[:3, 3] = (0.0, 1.0, 0.5)  # the proxy's cylinder behind the sphere, along y
    occ = Occluders([Sphere([0, 0, 1.0], 0.4), nurbs_cylinder(0.3, 1.0).transformed(shift)])
    assert list(occ.kind) == [SPHERE, MESH]
    rng = np.random.default_rng(5)
    R = 4000
    origins = np.c_[rng.uniform(-0.6, 0.6, R), np.full(R, -2.0), rng.uniform(0.4, 1.6, R)]
    ends = np.c_[rng.uniform(-0.6, 0.6, R), np.full(R, 2.0), rng.uniform(0.4, 1.6, R)]
    candidates = np.array([[True, True], [True, False], [False, True]])
    ray_pair = rng.integers(0, 3, R)
    seen = []
    blocked_one = occ.blocked

    def recorded(o, e, which):
        hit = blocked_one(o, e, which)
        seen.append((np.asarray(which).copy(), o.copy(), hit))
        return hit

    occ.blocked = recorded
    blocked, tests = blocked_rays(occ, origins, ends, candidates, ray_pair)
    del occ.blocked
    by_sphere = occ.blocked(origins, ends, np.zeros(R, dtype=int))
    by_proxy = occ.blocked(origins, ends, np.ones(R, dtype=int))
    expected = (candidates[ray_pair, 0] & by_sphere) | (candidates[ray_pair, 1] & by_proxy)
    np.testing.assert_array_equal(blocked, expected)
    assert 0 < by_sphere.sum() and 0 < by_proxy.sum() and np.any(by_sphere & by_proxy)
    # the sphere's tests come first; the proxy sees no segment the sphere blocked
    kinds = [occ.kind[w] for w, _, _ in seen]
    first_proxy = next(k for k, w in enumerate(kinds) if np.any(w == MESH))
    assert all(np.all(w == SPHERE) for w in kinds[:first_proxy])
    assert all(np.all(w == MESH) for w in kinds[first_proxy:])
    sphere_blocked = {tuple(o) for w, os, hit in seen[:first_proxy] for o in os[hit]}
    assert sphere_blocked and not any(
        tuple(o) in sphere_blocked for _, os, _ in seen[first_proxy:] for o in os
    )
    both = candidates[ray_pair].sum(1)
    assert tests == both.sum() - np.sum(candidates[ray_pair, 1] & candidates[ray_pair, 0] & by_sphere)


def test_cannot_block_is_sound_and_as_tight_as_the_cone_angles():
    """`bounds.cannot_block`: where it says a ball meets no segment from x to the target's ball,
    400 segments to random points of that ball all pass it; it agrees with the angle form
    (`cone_angles`: gamma > alpha + beta, or the ball wholly beyond the target's) except within
    rounding of a tie."""
    from core.bounds import cannot_block, cone_angles

    rng = np.random.default_rng(5)
    K = 4000
    x = rng.normal(size=(K, 3))
    target = x + rng.normal(size=(K, 3)) * 3.0
    # occluders about the line from x to the target, some beyond it
    occluder = x + rng.uniform(0.1, 1.3, (K, 1)) * (target - x) + rng.normal(size=(K, 3))
    R, r = rng.uniform(0.05, 1.0, K), rng.uniform(0.05, 1.0, K)
    out = cannot_block(x, target, R, occluder, r)
    reach = np.linalg.norm(target - x, axis=1) + R
    beyond = np.linalg.norm(occluder - x, axis=1) - r > reach * (1 + 1e-9)
    outside = (np.linalg.norm(target - x, axis=1) > R) & (np.linalg.norm(occluder - x, axis=1) > r)
    alpha, beta, gamma, wide = cone_angles(x, target, R, occluder, r)
    angles = outside & ((~wide & (gamma > alpha + beta + 1e-9)) | beyond)
    assert 0.2 * K < out.sum() < 0.9 * K
    assert np.count_nonzero(out != angles) <= 2
    for k in np.flatnonzero(out)[:300]:
        d = rng.normal(size=(400, 3))
        y = target[k] + d / np.linalg.norm(d, axis=1, keepdims=True) * R[k] * rng.uniform(0, 1, (400, 1)) ** (
            1 / 3
        )
        seg = y - x[k]
        t = np.clip((occluder[k] - x[k]) @ seg.T / np.einsum("ki,ki->k", seg, seg), 0.0, 1.0)
        assert np.all(np.linalg.norm(x[k] + t[:, None] * seg - occluder[k], axis=1) > r[k])
