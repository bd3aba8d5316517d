"""Parametric surfaces: evaluation, normals, areas, sub-patches, transforms and bad input."""

import numpy as np
import pytest

import core

PI = np.pi


def shapes():
    """One of each analytic surface (and a transformed one), with exact areas where known."""
    return {
        "sphere": (core.Sphere((1, 2, 3), 2.0), 16 * PI),
        "hemisphere": (core.Sphere((0, 0, 0), 1.0).subpatch(u=(0, PI / 2)), 2 * PI),
        "quad": (core.Quad((0, 0, 0), (2, 0, 0), (2, 3, 0), (0, 3, 0)), 6.0),
        "triangle": (core.Quad((0, 0, 0), (2, 0, 0), (0, 2, 0), (0, 0, 0)), 2.0),
        "bilinear": (core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 1), (0, 1, 0)), None),
        "disk": (core.Disk((0, 0, 1), (1, 1, 0), 2.0), 4 * PI),
        "annulus": (core.Disk((0, 0, 1), (0, 0, 1), 2.0).subpatch(u=(1, 2)), 3 * PI),
        "cylinder": (core.Cylinder((0, 0, 0), (0, 1, 1), 0.5, 3.0), 3 * PI),
        "ellipsoid": (core.Sphere((0, 0, 0), 1.0).transformed(np.diag([1.0, 2.0, 3.0, 1.0])), None),
    }


@pytest.mark.parametrize("name", list(shapes()))
def test_normal_is_cross_product_of_tangents(name):
    """evaluate() returns P and dP/du x dP/dv (front side), checked by central differences."""
    surface, _ = shapes()[name]
    (u0, u1), (v0, v1) = surface.domain
    u = np.linspace(u0, u1, 7)[1:-1]
    v = np.linspace(v0, v1, 5)[1:-1]
    U, V = np.meshgrid(u, v, indexing="ij")
    P, N = surface.evaluate(U, V)
    assert P.shape == U.shape + (3,) and N.shape == U.shape + (3,)
    h = 1e-6
    Pu = (surface.evaluate(U + h, V)[0] - surface.evaluate(U - h, V)[0]) / (2 * h)
    Pv = (surface.evaluate(U, V + h)[0] - surface.evaluate(U, V - h)[0]) / (2 * h)
    np.testing.assert_allclose(N, surface.orientation * np.cross(Pu, Pv), atol=1e-6 * np.abs(N).max())


@pytest.mark.parametrize("name", list(shapes()))
def test_area(name):
    """Closed-form areas, and the numeric area of split patches sums to the whole."""
    surface, exact = shapes()[name]
    if exact is not None:
        assert surface.area() == pytest.approx(exact, rel=1e-12)
    parts = surface.split(3, 2)
    assert len(parts) == 6
    assert sum(p.area() for p in parts) == pytest.approx(surface.area(), rel=1e-11)


def test_ellipsoid_area_against_legendre():
    """Ellipsoid (1, 2, 3) area 48.88214630... (Legendre's elliptic-integral formula)."""
    surface = shapes()["ellipsoid"][0]
    assert surface.radius is None
    assert surface.area() == pytest.approx(48.88214630260, rel=1e-10)


def test_sphere_parameters_and_front():
    """u = polar angle from +Z, v = azimuth from +X; the normal points outwards with length r^2 sin u."""
    s = core.Sphere((1, 0, 0), 2.0)
    P, N = s.evaluate(PI / 2, PI / 2)
    np.testing.assert_allclose(P, (1, 2, 0), atol=1e-15)
    np.testing.assert_allclose(N, (0, 4, 0), atol=1e-15)
    P, N = s.evaluate(0.0, 1.0)  # pole: zero area density, no NaN
    np.testing.assert_allclose(P, (1, 0, 2), atol=1e-15)
    assert np.all(np.isfinite(N)) and np.linalg.norm(N) < 1e-15


def test_quad_disk_cylinder_conventions():
    q = core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0))
    np.testing.assert_allclose(q.evaluate(0.25, 0.5)[0], (0.25, 0.5, 0))
    np.testing.assert_allclose(q.evaluate(0.25, 0.5)[1], (0, 0, 1))
    d = core.Disk((0, 0, 1), (0, 0, 2), 3.0)
    P, N = d.evaluate(2.0, 0.3)
    assert np.linalg.norm(P - (0, 0, 1)) == pytest.approx(2.0)
    np.testing.assert_allclose(N / np.linalg.norm(N), (0, 0, 1), atol=1e-15)
    c = core.Cylinder((0, 0, 0), (0, 0, 1), 2.0, 5.0)
    P, N = c.evaluate(1.0, 4.0)
    assert P[2] == pytest.approx(4.0) and np.hypot(P[0], P[1]) == pytest.approx(2.0)
    assert N @ (P - (0, 0, 4)) > 0  # front = outside


def test_subpatch_split_and_flip():
    s = core.Sphere((0, 0, 0), 1.0)
    h = s.subpatch(u=(0, PI / 2))
    assert h.domain == ((0.0, PI / 2), (0.0, 2 * PI))
    assert isinstance(h, core.Sphere)
    parts = s.split(2, 4)
    assert parts[1].domain[0] == (0.0, PI / 2) and parts[1].domain[1][0] == pytest.approx(PI / 2)
    f = h.flipped()
    np.testing.assert_allclose(f.evaluate(0.3, 0.2)[1], -h.evaluate(0.3, 0.2)[1])
    assert f.area() == pytest.approx(h.area())
    with pytest.raises(ValueError, match="outside the surface's range"):
        h.subpatch(u=(0, PI))


def test_transformed_maps_points_and_keeps_front():
    """x' = M x; a mirrored sphere is still seen from outside; a rotated quad keeps its area."""
    M = np.eye(4)
    M[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    M[:3, 3] = (5, 0, 0)
    q = core.Quad((0, 0, 0), (1, 0, 0), (1, 2, 0), (0, 2, 0))
    t = q.transformed(M)
    np.testing.assert_allclose(t.evaluate(1.0, 1.0)[0], (5 - 2, 1, 0), atol=1e-15)
    assert t.area() == pytest.approx(2.0)
    mirror = core.Sphere((0, 0, 0), 1.0).transformed(np.diag([-1.0, 1, 1, 1]))
    P, N = mirror.evaluate(1.0, 0.5)
    assert N @ P > 0
    assert mirror.radius == pytest.approx(1.0)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: core.Sphere((0, np.nan, 0), 1), "NaN"),
        (lambda: core.Sphere((0, 0, 0), np.inf), "NaN or infinite"),
        (lambda: core.Sphere((0, 0, 0), 0), "positive"),
        (lambda: core.Sphere((0, 0), 1), "shape"),
        (lambda: core.Disk((0, 0, 0), (0, 0, 0), 1), "non-zero"),
        (lambda: core.Disk((0, 0, 0), (0, 0, 1), -1), "positive"),
        (lambda: core.Cylinder((0, 0, 0), (0, 0, 0), 1, 1), "non-zero"),
        (lambda: core.Cylinder((0, 0, 0), (0, 0, 1), 1, 0), "height must be positive"),
        (lambda: core.Quad((0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)), "no area"),
        (lambda: core.Quad((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)), "folds"),
        (lambda: core.Quad((0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0)), "no area"),
        (lambda: core.Sphere((0, 0, 0), 1).subpatch(u=(1, 0.5)), "increasing"),
        (lambda: core.Sphere((0, 0, 0), 1).split(0, 2), "positive integer"),
        (lambda: core.Sphere((0, 0, 0), 1).split(1.5, 2), "positive integer"),
        (lambda: core.Sphere((0, 0, 0), 1).transformed(np.diag([1.0, 0, 1, 1])), "singular"),
        (lambda: core.Sphere((0, 0, 0), 1).transformed(np.eye(3)), "shape"),
        (lambda: core.Sphere("abc", 1), "real number"),
    ],
)
def test_bad_input_raises_value_error(make, message):
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.int32, np.longdouble])
def test_any_real_dtype(dtype):
    """Coordinates of any real dtype are accepted and used as float64."""
    s = core.Sphere(np.array([0, 0, 6], dtype=dtype), dtype(1))
    P, N = s.evaluate(np.array(0.5, dtype=dtype), np.array(1.0, dtype=dtype))
    assert P.dtype == np.float64 and N.dtype == np.float64
