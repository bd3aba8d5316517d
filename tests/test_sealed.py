"""The inside of a whole sphere (or ellipsoid) sees nothing outside it (`Elements.exchange`): its
own shell is in the way, so the hierarchy links none of those pairs instead of tracing them to
V = 0. (`Elements.live` keeps them: an enclosure's identity counts their unoccluded factors.)"""

import numpy as np

import core
from core.elements import Elements


def quad(p00, p10, p11, p01):
    return core.Quad(p00, p01, p11, p10)


FLOOR = quad((-2, -2, 0), (-2, 2, 0), (2, 2, 0), (2, -2, 0))  # front +z


def elements(surfaces):
    return Elements(surfaces, np.arange(len(surfaces)))


def test_a_whole_spheres_inside_does_not_see_the_floor_it_rests_on():
    ball = core.Sphere((0.0, 0.0, 0.5), 0.5)
    inside = ball.flipped().split(3, 4)
    e = elements([FLOOR] + inside)
    n = len(inside)
    assert not e.exchange(np.zeros(n, int), np.arange(1, n + 1)).any()
    assert not e.exchange(np.arange(1, n + 1), np.zeros(n, int)).any()
    # among themselves the inner patches still exchange light
    assert e.exchange(np.full(n - 1, 1), np.arange(2, n + 1)).any()


def test_an_ellipsoids_inside_and_a_touching_plane():
    """A near-sphere (Blender's float32 UV sphere is not exactly round) and a true ellipsoid."""
    for scale in ((1.0, 1.0, 1.0 + 1e-6), (1.5, 0.8, 0.5)):
        linear = np.diag(scale)
        ball = core.Sphere((0.0, 0.0, 0.0), 1.0).transformed(
            np.block([[linear, np.c_[[0, 0, scale[2]]]], [np.zeros(3), 1]])
        )
        inside = ball.flipped().split(2, 3)
        e = elements([FLOOR] + inside)
        assert not e.exchange(np.zeros(len(inside), int), np.arange(1, len(inside) + 1)).any(), scale


def test_what_is_inside_the_sphere_or_a_part_of_it_stays_live():
    """A small ball inside a big sphere sees its inside; a hemisphere's inside (open) sees the
    floor under it."""
    big = core.Sphere((0.0, 0.0, 0.0), 2.0).flipped()
    small = core.Sphere((0.0, 0.0, -1.0), 0.3)
    e = elements([small, big])
    assert e.exchange(np.array([0]), np.array([1])).all()
    bowl = core.Sphere((0.0, 0.0, 1.0), 1.0).subpatch(u=(0.0, np.pi / 2)).flipped()  # upper half, inside
    e = elements([FLOOR, bowl])
    assert e.exchange(np.array([0]), np.array([1])).all()


def test_a_two_sided_ball_under_a_lamp():
    """Culling changes no result: a two-sided ball resting on a floor under a lamp: its inside
    gets no light, and the floor and the ball's outside agree between the two paths as without
    a back side (the pairs with the inside were V = 0 before, and are culled now)."""
    values = {}
    for method, extra in (
        ("pairs", dict(occlusion="exact")),
        ("hierarchical", dict(contact_levels=0, light_levels=0)),
    ):
        for two_sided in (True, False):
            scene = core.Scene()
            floor = scene.add(FLOOR, reflectance=0.5, patches=4)
            ball = scene.add(
                core.Sphere((0.0, 0.0, 0.5), 0.5), reflectance=0.5, patches=(3, 4), two_sided=two_sided
            )
            lamp = quad((-0.5, -0.5, 3.0), (0.5, -0.5, 3.0), (0.5, 0.5, 3.0), (-0.5, 0.5, 3.0)).flipped()
            scene.add(lamp, emission=5.0, reflectance=0.0, patches=1, occluder=False)
            solution = scene.solve(tol=1e-3, method=method, **extra)
            if two_sided:
                assert np.all(solution.radiosity(ball, side="back") == 0.0)
            values[method, two_sided] = np.concatenate([solution.radiosity(floor), solution.radiosity(ball)])
    for method in ("pairs", "hierarchical"):
        np.testing.assert_allclose(values[method, True], values[method, False], rtol=1e-9)
    np.testing.assert_allclose(values["hierarchical", True], values["pairs", True], rtol=2e-3)


def test_pairs_across_a_closed_occluding_shell_are_blocked_exactly():
    """A two-sided ball over a floor: every pair of its inside with the floor or the lamp is
    parted by its shell, so the solve gives it V = 0 exactly (sampled rays let some through
    before) and the gather takes nothing across it. A ball that does not occlude seals nothing."""
    for occluder in (True, False):
        scene = core.Scene()
        floor = scene.add(
            core.Quad((-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)), reflectance=0.5, patches=4
        )
        ball = scene.add(
            core.Sphere((0.3, 0.1, 0.6), 0.5), reflectance=0.5, two_sided=True, occluder=occluder
        )
        lamp = core.Quad((-0.5, -0.5, 3), (-0.5, 0.5, 3), (0.5, 0.5, 3), (0.5, -0.5, 3))
        scene.add(lamp, emission=5.0, reflectance=0.0, occluder=False)
        solution = scene.solve(tol=1e-3, method="pairs")
        geometry = solution._geometry  # (the test reaches into the solution's pair store)
        i, j = geometry.pair_i, geometry.pair_j
        sealed = geometry.known_sealed(i, j)
        if not occluder:
            assert not sealed.any()
            continue
        assert sealed.sum() >= 16  # the inside with each floor patch and the lamp
        assert np.all(geometry.V[sealed] == 0.0)
        # the inside of the ball sees only its own inside: B = E + rho * (the inside's own light)
        inside = solution.radiosity_at(ball, [1.0, 2.0], [1.0, 4.0], side="back")
        np.testing.assert_allclose(inside, 0.0, atol=0.0)
        assert solution.radiosity_at(floor, [0.5], [0.5]).max() > 0
