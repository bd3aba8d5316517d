"""Surface kinds are declared once (`core.kinds`, `Geometry.kind` / `exact_kind`): every module
reads the same codes, every shape says what it is, and a new shape needs only its own class."""

import numpy as np
import pytest

import core
from core import bvh, inner, kinds, occlusion
from core.surface import Geometry, Surface


def test_modules_share_one_set_of_codes():
    """inner, occlusion and bvh use the codes of core.kinds (no private numbering), all distinct."""
    codes = [kinds.GENERIC, kinds.POLYGON, kinds.SPHERE, kinds.DISK, kinds.CYLINDER, kinds.MESH]
    codes.append(kinds.POLYGON_MESH)
    assert len(set(codes)) == len(codes) == len(kinds.NAMES)
    for name in ("GENERIC", "POLYGON", "SPHERE", "DISK", "CYLINDER"):
        assert getattr(inner, name) == getattr(kinds, name)
    for name in ("SPHERE", "DISK", "CYLINDER", "MESH", "POLYGON_MESH"):
        assert getattr(occlusion, name) == getattr(kinds, name)
    assert occlusion.QUAD == bvh.QUAD == kinds.POLYGON and bvh.SPHERE == kinds.SPHERE
    assert bvh.TRIANGLE == kinds.MESH


def _nurbs_sheet():
    g = np.linspace(0.0, 1.0, 4)
    pts = np.stack(np.meshgrid(g, g, indexing="ij") + [np.zeros((4, 4))], -1)
    pts[1:3, 1:3, 2] = 0.3
    knots = [0, 0, 0, 0, 1, 1, 1, 1]
    return core.NurbsSurface(pts, np.ones((4, 4)), 4, 4, knots, knots)


@pytest.mark.parametrize(
    "build, family, exact",
    [
        (lambda: core.Sphere((0, 0, 0), 1.0), kinds.SPHERE, kinds.SPHERE),
        (
            lambda: core.Sphere((0, 0, 0), 1.0).transformed(np.diag([1.0, 2.0, 0.5, 1.0])),
            kinds.SPHERE,
            kinds.GENERIC,
        ),
        (lambda: core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), kinds.POLYGON, kinds.POLYGON),
        (
            lambda: core.Quad((-1, -1, -0.8), (1, -1, 0.8), (1, 1, -0.8), (-1, 1, 0.8)),
            kinds.GENERIC,
            kinds.GENERIC,
        ),
        (lambda: core.Disk((0, 0, 0), (0, 0, 1), 1.0), kinds.DISK, kinds.DISK),
        (
            lambda: core.Disk((0, 0, 0), (0, 0, 1), 1.0).transformed(np.diag([1.0, 3.0, 1.0, 1.0])),
            kinds.DISK,
            kinds.GENERIC,
        ),
        (lambda: core.Cylinder((0, 0, 0), (0, 0, 1), 0.5, 2.0), kinds.CYLINDER, kinds.CYLINDER),
        (_nurbs_sheet, kinds.GENERIC, kinds.GENERIC),
    ],
    ids=["sphere", "ellipsoid", "flat quad", "twisted quad", "disk", "elliptic disk", "cylinder", "nurbs"],
)
def test_every_shape_declares_its_kind(build, family, exact):
    s = build()
    assert s.geometry.kind == family
    assert s.geometry.exact_kind(s.domain) == exact
    for patch in s.split(2, 2):  # (a part keeps its kind)
        assert patch.geometry.exact_kind(patch.domain) == exact
    whole = family == kinds.SPHERE
    assert s.geometry.whole_ellipsoid(s.domain) == whole
    assert not s.split(2, 1)[0].geometry.whole_ellipsoid(s.split(2, 1)[0].domain)


class _LatLongSphere(Geometry):
    """A unit sphere at c parametrised over [0, 1]^2 (u: polar, v: azimuth): a shape the core has
    never heard of (GENERIC), declared here alone."""

    natural_domain = ((0.0, 1.0), (0.0, 1.0))

    def __init__(self, center):
        self.center = np.asarray(center, dtype=np.float64)

    def derivatives(self, u, v):
        u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
        t, p = np.pi * u, 2.0 * np.pi * v
        st, ct, sp, cp = np.sin(t), np.cos(t), np.sin(p), np.cos(p)
        P = np.stack([st * cp, st * sp, ct], -1) + self.center
        Pu = np.pi * np.stack([ct * cp, ct * sp, -st], -1)
        Pv = 2.0 * np.pi * np.stack([-st * sp, st * cp, np.zeros_like(st)], -1)
        return P, Pu, Pv

    def transformed(self, linear, offset):
        raise NotImplementedError


class _Ball(Surface):
    def __init__(self, center):
        self._init(_LatLongSphere(center))


def test_a_new_shape_needs_only_its_own_class():
    """A sphere given as a new Geometry subclass (generic quadrature, a proxy for rays) gives the
    closed form of a sphere to a coaxial disk, F = (1 - 1 / sqrt(1 + (R / h)^2)) / 2 (Howell's
    catalogue, C-134: sphere of any radius at height h above the centre of a disk of radius R),
    and shades a floor in a scene as the built-in sphere does to 2 % at tol 1e-4 (measured 1.3 %:
    a generic occluder's shadow is sampled by rays through its proxy, the built-in sphere's is
    exact; 5 % at tol 1e-3)."""
    h, R = 2.0, 1.5
    ball = _Ball((0.0, 0.0, h))
    disk = core.Disk((0, 0, 0), (0, 0, 1), R)
    exact = 0.5 * (1.0 - 1.0 / np.sqrt(1.0 + (R / h) ** 2))
    assert abs(core.form_factor(ball, disk, tol=1e-6) - exact) <= 1e-6 * exact

    def floor_radiosity(occluder):
        scene = core.Scene()
        scene.add(core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)), reflectance=0.5, patches=(4, 4))
        scene.add(core.Quad((-3, -3, 4), (-3, 3, 4), (3, 3, 4), (3, -3, 4)), emission=1.0, patches=(1, 1))
        scene.add(occluder, reflectance=0.0, patches=(1, 1))
        return scene.solve(tol=1e-4).radiosity(0)[:, 0]

    new, built_in = (
        floor_radiosity(_Ball((0.2, 0.1, 2.0))),
        floor_radiosity(core.Sphere((0.2, 0.1, 2.0), 1.0)),
    )
    assert new.min() < 0.9 * new.max()  # the shadow is there
    np.testing.assert_allclose(new, built_in, rtol=2e-2)
