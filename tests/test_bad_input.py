"""Bad and extreme input at every public entry point: a named error or a correct finite value.

Rejected input raises a ValueError, or an `ArgumentTypeError` (both a TypeError and a ValueError)
for a value of the wrong kind, whose message names the argument. Extreme but valid input (tiny
or huge scales, far from the origin, unnormalised directions of any length, saddle quads) gives
finite values that match a closed form or an independent brute-force quadrature.
"""

import numpy as np
import pytest

import core
from core import checks

SEED_EXACT = np.arctan(1.0 / np.sqrt(24.0)) / np.pi  # sphere r over a 6r x 6r square at 6r (seed case 1)
COAXIAL_HALF = 3.0 - np.sqrt(8.0)  # coaxial unit disks 2 apart, Howell C-41 with R1 = R2 = 1/2


def sphere():
    return core.Sphere((0, 0, 6), 1.0)


def square(scale=1.0, offset=(0.0, 0.0, 0.0)):
    corners = np.array([(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)], dtype=float) * scale + offset
    return core.Quad(*corners)


def solved_scene():
    scene = core.Scene()
    ball = scene.add(sphere(), emission=1.0, patches=(2, 2))
    scene.add(square(), patches=(2, 2))
    return scene, ball


def in_scene(call):
    """call(scene, ball handle) on a small two-surface scene."""
    return lambda: call(*solved_scene())


def solution(call):
    """call(solution, ball handle) on the solved small scene."""

    def run():
        scene, ball = solved_scene()
        return call(scene.solve(tol=1e-2), ball)

    return run


SADDLE = ((-1, -1, -0.8), (1, -1, 0.8), (1, 1, -0.8), (-1, 1, 0.8))  # corner normals 97 degrees apart

V = ValueError
T = checks.ArgumentTypeError

# ---------------------------------------------------------------------------- rejected input
# (call, exception type, words the message must contain)
REJECTED = [
    # parameters outside a patch's domain (a NURBS net would be clamped there silently)
    pytest.param(
        lambda: sphere().subpatch(u=(0.0, 1.0)).evaluate(1.5, 0.1), V, ["u = 1.5", "domain"], id="u-out"
    ),
    pytest.param(lambda: square().evaluate(0.5, [0.2, np.nan]), V, ["v = nan", "domain"], id="v-nan"),
    # sizes and positions float64 cannot represent
    pytest.param(
        lambda: core.Sphere((0, 0, 6), 1e-155), V, ["sphere radius", "1e-30"], id="sphere-radius-1e-155"
    ),
    pytest.param(lambda: core.Sphere((0, 0, 0), 1e-200), V, ["sphere radius"], id="sphere-radius-1e-200"),
    pytest.param(
        lambda: core.Sphere((0, 0, 6), 1e-12), V, ["sphere radius", "origin"], id="sphere-unresolved"
    ),
    pytest.param(
        lambda: core.Sphere((1e300, 0, 0), 1.0), V, ["sphere center", "1e+30"], id="sphere-at-1e300"
    ),
    pytest.param(lambda: core.Sphere((0, 0, 0), 1e31), V, ["sphere radius"], id="sphere-radius-1e31"),
    pytest.param(lambda: core.Disk((1e12, 0, 0), (0, 0, 1), 1e-6), V, ["disk radius"], id="disk-unresolved"),
    pytest.param(lambda: core.Cylinder((0, 0, 0), (0, 0, 1), 1.0, 1e-40), V, ["cylinder height"], id="cyl-h"),
    pytest.param(
        lambda: core.Quad((1e200, 0, 0), (1e200 + 1e185, 0, 0), (1e200 + 1e185, 1e185, 0), (1e200, 1e185, 0)),
        V,
        ["quad corner p00"],
        id="quad-at-1e200",
    ),
    pytest.param(lambda: square(offset=(1e20, 0, 0)), V, ["quad size"], id="quad-unresolved"),
    pytest.param(
        lambda: sphere().transformed(np.diag([1e-35, 1e-35, 1e-35, 1])),
        V,
        ["transform matrix", "1e-30"],
        id="tiny-T",
    ),
    pytest.param(
        lambda: sphere().transformed(np.diag([1e300, 1, 1, 1])), V, ["transform matrix"], id="huge-T"
    ),
    pytest.param(
        lambda: sphere().subpatch(u=(1.0, np.nextafter(1.0, 2.0))),
        V,
        ["u range", "narrower"],
        id="subpatch-ulp",
    ),
    pytest.param(
        lambda: core.Disk((0, 0, 6), (0, 0, -1), 1.0).subpatch(u=(0, 1e-300)),
        V,
        ["subpatch", "1e-30"],
        id="cap-1e-300",
    ),
    pytest.param(
        lambda: core.Sphere((0, 0, 6), 1.0).subpatch(u=(0, 1e-12)), V, ["subpatch"], id="cap-unresolved"
    ),
    # hangs and memory blow-ups on requests that used to be accepted
    pytest.param(
        lambda: core.form_factor(sphere(), square(), tol=1e-20), V, ["tol", "1e-10"], id="tol-1e-20"
    ),
    pytest.param(
        lambda: core.form_factor(sphere(), square(), tol=1e-11), V, ["tol", "1e-10"], id="tol-1e-11"
    ),
    pytest.param(lambda: solved_scene()[0].solve(tol=1e-15), V, ["tol", "1e-10"], id="solve-tol-1e-15"),
    pytest.param(lambda: sphere().split(10**5, 10**5), V, ["split", "1,000,000"], id="split-1e10"),
    pytest.param(lambda: sphere().split(10**7, 1), V, ["nu", "1,000,000"], id="split-nu-1e7"),
    pytest.param(
        lambda: core.form_factor(sphere(), square(), method="gauss", order=10**6),
        V,
        ["order", "64"],
        id="gauss-1e6",
    ),
    pytest.param(
        in_scene(lambda s, h: s.add(sphere(), patches=(2000, 2000))), V, ["patches"], id="patches-4e6"
    ),
    pytest.param(
        in_scene(lambda s, h: s.add(sphere(), patches=(150, 150)) and s.solve()),
        V,
        ["patches", "20,000"],
        id="N-22500",
    ),
    # counts that are not integers
    pytest.param(lambda: sphere().split(np.inf, 2), V, ["nu", "inf"], id="split-inf"),
    pytest.param(lambda: sphere().split(2, np.nan), V, ["nv", "nan"], id="split-nan"),
    pytest.param(lambda: sphere().split("4", 2), T, ["nu"], id="split-str"),
    pytest.param(lambda: sphere().split(True, 2), T, ["nu"], id="split-bool"),
    pytest.param(
        lambda: core.form_factor(sphere(), square(), method="gauss", order=np.inf),
        V,
        ["order"],
        id="order-inf",
    ),
    pytest.param(
        lambda: core.form_factor(sphere(), square(), method="gauss", order=2.5), V, ["order"], id="order-2.5"
    ),
    pytest.param(
        lambda: core.form_factor(sphere(), square(), order=3), V, ["order", "gauss"], id="order-adaptive"
    ),
    pytest.param(lambda: core.Scene().add(sphere(), patches=np.inf), V, ["patches nu"], id="patches-inf"),
    pytest.param(
        lambda: core.Scene().add(sphere(), patches=(np.nan, 2)), V, ["patches nu"], id="patches-nan"
    ),
    pytest.param(lambda: core.Scene().add(sphere(), patches="4"), T, ["patches"], id="patches-str"),
    pytest.param(
        lambda: core.Scene().add(sphere(), patches=("a", 2)), T, ["patches nu"], id="patches-str-nu"
    ),
    pytest.param(in_scene(lambda s, h: s.solve(max_bounces=np.inf)), V, ["max_bounces"], id="bounces-inf"),
    pytest.param(in_scene(lambda s, h: s.solve(max_bounces="2")), T, ["max_bounces"], id="bounces-str"),
    pytest.param(in_scene(lambda s, h: s.solve(threads=np.inf)), V, ["threads"], id="threads-inf"),
    pytest.param(in_scene(lambda s, h: s.solve(threads=10**6)), V, ["threads", "256"], id="threads-1e6"),
    # numbers given as strings, bools or None
    pytest.param(lambda: core.Sphere((0, 0, 6), "1.0"), T, ["sphere radius"], id="radius-str"),
    pytest.param(lambda: core.Sphere(("0", "0", "6"), 1.0), T, ["sphere center"], id="center-str"),
    pytest.param(lambda: core.Sphere((0, 0, 6), True), T, ["sphere radius"], id="radius-bool"),
    pytest.param(
        lambda: core.Sphere(np.array([True, False, True]), 1.0), T, ["sphere center"], id="center-bool"
    ),
    pytest.param(lambda: core.Sphere((0, None, 6), 1.0), T, ["sphere center"], id="center-none"),
    pytest.param(lambda: core.Sphere((0, 0, 6j), 1.0), T, ["sphere center"], id="center-complex"),
    pytest.param(
        lambda: core.Quad((0, 0, 0), (1, 0, 0), (1, "1", 0), (0, 1, 0)), T, ["p11"], id="corner-str"
    ),
    pytest.param(lambda: core.Disk((0, 0, 0), "up", 1.0), T, ["disk normal"], id="normal-str"),
    pytest.param(lambda: core.form_factor(sphere(), square(), tol="1e-3"), T, ["tol"], id="tol-str"),
    pytest.param(lambda: core.Scene().add(sphere(), emission="1"), T, ["emission"], id="emission-str"),
    pytest.param(
        lambda: core.Scene().add(sphere(), reflectance=None), T, ["reflectance"], id="reflectance-none"
    ),
    pytest.param(lambda: core.Scene().add(sphere(), two_sided="False"), T, ["two_sided"], id="two-sided-str"),
    pytest.param(lambda: core.Scene().add(sphere(), occluder=None), T, ["occluder"], id="occluder-none"),
    pytest.param(lambda: core.Scene().add(sphere(), name=3), T, ["name"], id="name-int"),
    pytest.param(
        lambda: core.Scene().add_point_light((0, 0, 0), 1.0, radius="abc"), T, ["light radius"], id="lr-str"
    ),
    pytest.param(
        lambda: core.Scene().add_point_light((0, 0, 0), 1.0, radius="1"), T, ["light radius"], id="lr-num-str"
    ),
    pytest.param(
        lambda: core.Scene().add_point_light((0, 0, 0), 1.0, radius=np.inf), V, ["light radius"], id="lr-inf"
    ),
    pytest.param(
        lambda: core.Scene().add_point_light((0, 0, 0), 1.0, radius=-1), V, ["light radius"], id="lr-neg"
    ),
    pytest.param(
        lambda: core.Scene().add_point_light((0, 0, 0), "5"), T, ["light intensity"], id="intensity-str"
    ),
    pytest.param(
        lambda: core.Scene().add_spot_light((0, 0, 0), (0, 0, -1), 1.0, "abc", 0.1),
        T,
        ["spot_size"],
        id="size-str",
    ),
    pytest.param(
        lambda: core.Scene().add_spot_light((0, 0, 0), (0, 0, -1), 1.0, 1.0, None),
        T,
        ["spot_blend"],
        id="blend-none",
    ),
    pytest.param(
        lambda: core.Scene().add_spot_light((0, 0, 0), (0, 0, -1), 1.0, np.nan, 0.1),
        V,
        ["spot_size"],
        id="size-nan",
    ),
    pytest.param(lambda: core.Scene().add_sun_light((0, 0, -1), "2"), T, ["sun irradiance"], id="sun-str"),
    pytest.param(
        solution(lambda s, h: s.radiosity_at(h, "abc", [0.5])), T, ["radiosity_at u"], id="at-u-str"
    ),
    pytest.param(
        solution(lambda s, h: s.radiosity_at(h, [0.5], [None])), T, ["radiosity_at v"], id="at-v-none"
    ),
    pytest.param(
        solution(lambda s, h: s.radiosity_at(h, [np.inf], [0.5])), V, ["radiosity_at u"], id="at-u-inf"
    ),
    # handles, rules and surfaces of the wrong kind
    pytest.param(
        in_scene(lambda s, h: s.set_material(True, reflectance=0.1)), T, ["handle"], id="handle-true"
    ),
    pytest.param(
        in_scene(lambda s, h: s.set_material(1.0, reflectance=0.1)), T, ["handle"], id="handle-float"
    ),
    pytest.param(in_scene(lambda s, h: s.set_material(7, reflectance=0.1)), V, ["handle 7"], id="handle-7"),
    pytest.param(
        in_scene(lambda s, h: s.set_light(True, intensity=1.0)), T, ["light handle"], id="light-true"
    ),
    pytest.param(solution(lambda s, h: s.radiosity(True)), T, ["handle"], id="radiosity-true"),
    pytest.param(in_scene(lambda s, h: s.solve(cull={"facng"})), V, ["cull", "facng"], id="cull-misspelt"),
    pytest.param(in_scene(lambda s, h: s.solve(cull="facing")), T, ["cull"], id="cull-str"),
    pytest.param(in_scene(lambda s, h: s.solve(cull=3)), T, ["cull"], id="cull-int"),
    pytest.param(in_scene(lambda s, h: s.solve(occlusion="no")), T, ["occlusion"], id="occlusion-str"),
    pytest.param(in_scene(lambda s, h: s.solve(progress="print")), T, ["progress"], id="progress-str"),
    pytest.param(in_scene(lambda s, h: s.set_surface(h, "ball")), T, ["surface"], id="set-surface-str"),
    pytest.param(lambda: core.form_factors(sphere(), [square()]), T, ["sources"], id="sources-not-list"),
    pytest.param(lambda: core.form_factors([sphere()], [None]), T, ["targets[0]"], id="targets-none"),
    pytest.param(lambda: core.form_factor(sphere(), "square"), T, ["dst"], id="dst-str"),
]


def test_huge_bounce_counts_stop_at_convergence():
    """max_bounces = 1e300 is a valid (integral) count: the solve stops at convergence instead of
    sweeping (solvers.bounce_count) and gives the converged result."""
    scene = core.Scene()
    scene.add(core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), reflectance=0.5)
    scene.add(core.Quad((0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)), emission=1.0, reflectance=0.5)
    huge = scene.solve(max_bounces=1e300).radiosity(0)
    converged = scene.solve().radiosity(0)
    assert np.allclose(huge, converged, rtol=1e-3)


@pytest.mark.parametrize("call, kind, words", REJECTED)
def test_rejected_with_a_named_error(call, kind, words):
    """Each bad input raises `kind` (a ValueError; type errors are TypeError too) naming the argument."""
    with pytest.raises(kind) as info:
        call()
    assert isinstance(info.value, ValueError)
    if kind is T:
        assert isinstance(info.value, TypeError)
    message = str(info.value)
    for word in words:
        assert word in message, f"{word!r} missing from {message!r}"


# ---------------------------------------------------------------------------- extreme valid input
def seed_pair(scale=1.0, offset=(0.0, 0.0, 0.0)):
    offset = np.asarray(offset, dtype=float)
    return core.Sphere(np.array([0.0, 0.0, 6.0]) * scale + offset, scale), square(scale, offset)


def by_transform(matrix):
    s, q = seed_pair()
    return s.transformed(matrix), q.transformed(matrix)


def translation(x):
    M = np.eye(4)
    M[0, 3] = x
    return M


@pytest.mark.parametrize(
    "build",
    [
        pytest.param(lambda: seed_pair(), id="seed"),
        pytest.param(lambda: seed_pair(offset=(1e4, 0, 0)), id="moved-x-1e4"),
        pytest.param(lambda: seed_pair(offset=(-3e5, 2e5, 1e5)), id="moved-3e5"),
        pytest.param(lambda: seed_pair(scale=1e-6), id="scaled-1e-6"),
        pytest.param(lambda: seed_pair(scale=1e6), id="scaled-1e6"),
        pytest.param(lambda: seed_pair(scale=1e-20), id="scaled-1e-20"),
        pytest.param(lambda: seed_pair(scale=1e20), id="scaled-1e20"),
        pytest.param(lambda: seed_pair(scale=1e-6, offset=(1e-2, 0, 0)), id="scaled-1e-6-moved-1e-2"),
        pytest.param(lambda: by_transform(np.diag([1e6, 1e6, 1e6, 1.0])), id="transformed-1e6"),
        pytest.param(lambda: by_transform(translation(1e4)), id="transformed-x-1e4"),
    ],
)
def test_seed_case_at_extreme_scales_and_positions(build):
    """Seed case 1, F = atan(1/sqrt(24))/pi (Baranoski's table; scale and translation invariant),
    computed finite and right wherever float64 can hold the geometry."""
    src, dst = build()
    value = core.form_factor(src, dst, tol=1e-8)
    assert np.isfinite(value)
    assert abs(value - SEED_EXACT) <= 1e-7 * SEED_EXACT, value


@pytest.mark.parametrize("length", [1e-200, 1e-20, 1.0, 1e20, 1e200], ids=lambda x: f"{x:.0e}")
def test_direction_of_any_length(length):
    """A disk normal or cylinder axis is a direction: its length (1e-200 ... 1e200) is ignored.
    Coaxial unit disks 2 apart: F = 3 - sqrt(8) (Howell C-41); the base disk of a cylinder r = 1,
    h = 2 sees its inside with F = 1 - (3 - sqrt(8)) (the enclosure sums to 1)."""
    base = core.Disk((0, 0, 0), (0, 0, length), 1.0)
    top = core.Disk((0, 0, 2), (0, 0, -length), 1.0)
    inside = core.Cylinder((0, 0, 0), (0, 0, length), 1.0, 2.0).flipped()
    np.testing.assert_allclose(base.geometry.plane[1], (0, 0, 1), rtol=0, atol=1e-15)
    assert core.form_factor(base, top, tol=1e-8) == pytest.approx(COAXIAL_HALF, rel=1e-7)
    assert core.form_factor(base, inside, tol=1e-8) == pytest.approx(1.0 - COAXIAL_HALF, rel=1e-7)


def brute_force(src, dst, n=30):
    """F(src -> dst) by an n-point Gauss-Legendre rule in each of the four parameters, written
    here independently of the core (only `evaluate` is used): correct to rounding for smooth,
    wholly facing pairs."""
    x, w = np.polynomial.legendre.leggauss(n)

    def nodes(surface):
        (u0, u1), (v0, v1) = surface.domain
        u, v = np.meshgrid(u0 + (u1 - u0) * (x + 1) / 2, v0 + (v1 - v0) * (x + 1) / 2, indexing="ij")
        weight = np.outer(w, w).ravel() * (u1 - u0) * (v1 - v0) / 4
        P, N = surface.evaluate(u.ravel(), v.ravel())
        return P, N, weight

    P1, N1, W1 = nodes(src)
    P2, N2, W2 = nodes(dst)
    e = P2[None] - P1[:, None]
    L2 = np.einsum("ijk,ijk->ij", e, e)
    c1 = np.maximum(np.einsum("ik,ijk->ij", N1, e), 0.0)
    c2 = np.maximum(-np.einsum("jk,ijk->ij", N2, e), 0.0)
    area = W1 @ np.linalg.norm(N1, axis=1)
    return W1 @ (c1 * c2 / (np.pi * L2 * L2)) @ W2 / area


@pytest.mark.parametrize(
    "target",
    [
        pytest.param(lambda: core.Disk((0, 0, 3), (0, 0, -1), 1.0), id="disk-above"),
        pytest.param(lambda: core.Quad((-2, -2, 4), (-2, 2, 4), (2, 2, 4), (2, -2, 4)), id="square-above"),
    ],
)
def test_saddle_quad_is_valid(target):
    """A saddle whose corner normals differ by 97 degrees (normal (-2(1.6 - 3.2v), -2(1.6 - 3.2u), 4)
    never vanishes) is a valid surface; both directions of its form factor to a target it wholly
    faces match a 30^4-point brute-force rule, and reciprocity holds."""
    saddle = core.Quad(*SADDLE)
    corner_normals = saddle.evaluate(np.array([0.0, 1.0]), np.array([0.0, 1.0]))[1]
    assert corner_normals[0] @ corner_normals[1] < 0  # the case the old test refused
    dst = target()
    forward = core.form_factor(saddle, dst, tol=1e-8)
    backward = core.form_factor(dst, saddle, tol=1e-8)
    assert forward == pytest.approx(brute_force(saddle, dst), rel=1e-7)
    assert backward == pytest.approx(brute_force(dst, saddle), rel=1e-7)
    assert saddle.area() * forward == pytest.approx(dst.area() * backward, rel=1e-7)


def test_saddle_quad_in_a_scene():
    """A lit saddle solves to finite, positive radiosities; after one bounce from a black emitter
    (E = 1) its patch values average to rho F(saddle -> disk), and its inter-reflections (the saddle
    is concave along one diagonal) only add light."""
    scene = core.Scene()
    saddle = scene.add(core.Quad(*SADDLE), reflectance=0.5, patches=(4, 4))
    scene.add(core.Disk((0, 0, 3), (0, 0, -1), 1.0), emission=1.0, reflectance=0.0, patches=(2, 4))
    areas = np.array([p.area() for p in core.Quad(*SADDLE).split(4, 4)])
    expected = 0.5 * brute_force(core.Quad(*SADDLE), core.Disk((0, 0, 3), (0, 0, -1), 1.0))
    one = scene.solve(tol=1e-4, max_bounces=1).radiosity(saddle)
    assert np.all(np.isfinite(one)) and np.all(one > 0)
    assert areas @ one[:, 0] / areas.sum() == pytest.approx(expected, rel=1e-4)
    every = scene.solve(tol=1e-4).radiosity(saddle)
    assert np.all(every >= one) and areas @ every[:, 0] / areas.sum() > expected * (1 + 1e-3)


@pytest.mark.parametrize(
    "corners, message",
    [
        pytest.param(((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)), "folds", id="bowtie"),
        pytest.param(((0, 0, 0), (2, 0, 0), (1.2, 1.2, 0), (0, 2, 0)), None, id="kite-convex"),
        pytest.param(((0, 0, 0), (2, 0, 0), (0.9, 0.9, 0), (0, 2, 0)), "folds", id="dart-non-convex"),
        pytest.param(((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 0, 0)), None, id="triangle"),
        pytest.param(((0, 0, 0), (1, 0, 0), (-1, -1, 0), (0, 1, 0)), "folds", id="reflex-corner"),
    ],
)
def test_quads_fold_exactly_when_their_normal_vanishes_inside(corners, message):
    """A quad is refused as folded exactly when its (affine) normal has a zero inside the box. For
    p11 = (a, a, 0) and the other corners (0, 0), (2, 0), (0, 2) the normal's z is
    4 + 2 (a - 2)(u + v), zero inside iff a < 1, i.e. iff the quad is non-convex: a bowtie, a dart
    (a = 0.9) and a reflex corner fold, a convex kite (a = 1.2) and a triangle (zero on an edge)
    do not."""
    if message is None:
        quad = core.Quad(*corners)
        assert quad.area() > 0
    else:
        with pytest.raises(ValueError, match=message):
            core.Quad(*corners)


def test_thin_band_has_its_area_and_factor():
    """A sphere band 1e-8 wide (u around 2): its area is 2 pi r^2 (cos u0 - cos u1) without
    cancellation, and its factor to the square equals that of a 1e-4 band (they differ by
    O(width^2))."""
    s = sphere()
    band = s.subpatch(u=(2.0 - 5e-9, 2.0 + 5e-9))
    (u0, u1), _ = band.domain
    assert band.area() == pytest.approx(
        4.0 * np.pi * np.sin(0.5 * (u0 + u1)) * np.sin(0.5 * (u1 - u0)), rel=1e-14
    )
    assert band.area() == pytest.approx(2.0 * np.pi * np.sin(2.0) * 1e-8, rel=1e-7)
    wide = s.subpatch(u=(2.0 - 5e-5, 2.0 + 5e-5))
    thin_value = core.form_factor(band, square(), tol=1e-8)
    assert thin_value > 0.05
    assert thin_value == pytest.approx(core.form_factor(wide, square(), tol=1e-8), rel=1e-7)


def test_empty_form_factor_matrices():
    """form_factors on empty lists returns an empty matrix of the right shape."""
    assert core.form_factors([], []).shape == (0, 0)
    assert core.form_factors([sphere()], []).shape == (1, 0)
    assert core.form_factors((), [square()]).shape == (0, 1)


def test_integral_values_of_other_types_are_accepted():
    """Counts given as integral floats or numpy integers, and handles as numpy integers, work."""
    assert len(sphere().split(2.0, np.int64(3))) == 6
    scene = core.Scene()
    h = scene.add(sphere(), emission=1.0, patches=(np.int32(1), 2.0))
    scene.set_material(np.int64(h), emission=2.0)
    sol = scene.solve(tol=1e-2, max_bounces=np.int64(1), cull=["facing", "rows"])
    assert sol.radiosity(np.int64(h)).shape == (2, 3)


def test_smallest_accepted_tolerance():
    """tol = checks.MIN_TOL is accepted and reaches the seed case to 1e-9."""
    value = core.form_factor(sphere(), square(), tol=checks.MIN_TOL)
    assert abs(value - SEED_EXACT) <= 1e-9 * SEED_EXACT


def test_a_non_finite_result_raises(monkeypatch):
    """Should rounding ever break an integral, the public functions raise FloatingPointError rather
    than return NaN (the integrator is replaced by one returning NaN to exercise the guard)."""

    def broken(self, source, target, tol):
        return np.full(np.size(source), np.nan), np.zeros(np.size(source)), 0

    monkeypatch.setattr(core.FormFactorSolver, "pairs", broken)
    with pytest.raises(FloatingPointError, match="nan"):
        core.form_factor(sphere(), square())
    with pytest.raises(FloatingPointError, match="form_factors"):
        core.form_factors([sphere()], [square()])


def lit_scene(scale, offset):
    """A ball over a floor under a point light, every length times `scale`, moved by `offset`
    (in units of the scene); the light's intensity scales with scale^2, so radiosities do not."""
    o = np.array([offset * scale, 0.0, 0.0])
    scene = core.Scene()
    ball = scene.add(core.Sphere(o + (0, 0, scale), 0.5 * scale), reflectance=0.5, patches=(2, 4))
    corners = np.array([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], dtype=float) * scale + o
    floor = scene.add(core.Quad(*corners), reflectance=0.5, patches=(2, 2))
    scene.add_point_light(o + (0, 0, 3 * scale), intensity=scale * scale)
    sol = scene.solve(tol=1e-3)
    return np.concatenate([sol.radiosity(floor)[:, 0], sol.radiosity_at(ball, [1.0, 2.0], [1.0, 4.0])[:, 0]])


@pytest.mark.parametrize(
    "scale, offset",
    [(1e-20, 0.0), (1e-6, 1e3), (1e6, 0.0), (1e20, 1e3)],
    ids=["1e-20", "1e-6-moved", "1e6", "1e20-moved"],
)
def test_scene_at_extreme_scales(scale, offset):
    """Radiosity is invariant under scaling (with intensity ~ length^2) and translation: a scene
    at 1e-20 ... 1e20 m, moved by 1e3 of its size, gives the unit scene's values."""
    reference = lit_scene(1.0, 0.0)
    assert np.all(reference > 0)
    np.testing.assert_allclose(lit_scene(scale, offset), reference, rtol=1e-6)


SPHERES_3R = 0.02959031225055043  # tests/reference/view_factors.sphere_to_sphere(1, 1, 3) (Howell B-43)


@pytest.mark.parametrize("x", [0.0, 1e8, -5e8], ids=["origin", "1e8", "-5e8"])
def test_far_from_the_origin_at_a_fine_tolerance(x):
    """Two unit spheres 3 apart at x = 1e8 (evaluated in place, rounding noise 1e-8) used to refine
    forever at tol 1e-9; moved next to the origin first they give the catalogue value, singly and
    in a batch, and a far hemisphere's self factor stays 1/2 (a repeated patch stays one patch)."""
    pair = core.Sphere((x, 0, 0), 1.0), core.Sphere((x, 0, 3), 1.0)
    assert core.form_factor(*pair, tol=1e-9) == pytest.approx(SPHERES_3R, rel=1e-8)
    F = core.form_factors(list(pair), list(pair), tol=1e-9)
    assert F[0, 1] == pytest.approx(SPHERES_3R, rel=1e-8) and F[0, 0] == 0.0
    hemisphere = core.Sphere((x, 0, 0), 1.0).subpatch(u=(0, np.pi / 2)).flipped()
    assert core.form_factor(hemisphere, hemisphere, tol=1e-9) == pytest.approx(0.5, rel=1e-8)
