"""A uniform sky (`Scene.set_sky`): E_sky = pi L (1 - sum_j F(x -> j) V(x, j)) over the occluders.

References are independent of the solver: Lambert's closed form for the factor from a point to
a polygon (Siegel & Howell, *Thermal Radiation Heat Transfer*, the contour-integral form
F = 1 / (2 pi) sum_k gamma_k n . (r_k x r_k+1) / |r_k x r_k+1|), written out here in plain numpy.
"""

import numpy as np
import pytest

import core

RHO = 0.5
FLOOR = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]  # z = 0, front +z
# both paths: every link of the hierarchy carries B_s - L from surfaces that hide the sky
METHODS = pytest.mark.parametrize("method", ["pairs", "hierarchical"])
WALL = [(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)]  # x = 0, front +x (toward the floor)


def lambert(x, n, polygon):
    """Form factor from the point x with unit normal n to a polygon wholly above its horizon."""
    r = np.asarray(polygon, float) - x
    total = 0.0
    for a, b in zip(r, np.roll(r, -1, axis=0)):
        c = np.cross(a, b)
        gamma = np.arctan2(np.linalg.norm(c), a @ b)
        total += gamma * (n @ c) / np.linalg.norm(c)
    return abs(total) / (2.0 * np.pi)


@METHODS
def test_plane_under_the_sky_gets_pi_L(method):
    """Nothing covers a lone plane's hemisphere: E = pi L, so B = rho L (patches and points)."""
    scene = core.Scene()
    h = scene.add(core.Quad(*FLOOR), reflectance=RHO, patches=2)
    scene.set_sky((2.0, 1.0, 0.5))
    sol = scene.solve(tol=1e-3, method=method)
    expected = RHO * np.array([2.0, 1.0, 0.5])
    assert np.allclose(sol.radiosity(h), expected, rtol=1e-12)
    assert np.allclose(sol.radiosity_at(h, [0.0, 0.3, 1.0], [0.0, 0.7, 1.0]), expected, rtol=1e-12)


@METHODS
@pytest.mark.parametrize("u, v", [(0.5, 0.5), (0.05, 0.5), (1e-6, 0.5), (0.3, 0.9), (0.0, 0.5)])
def test_floor_beside_a_black_wall(u, v, method):
    """A black wall covers F(x -> wall) of the floor's sky: B(x) = rho L (1 - F), F by Lambert.
    The wall, black and not emitting, carries no light but still hides the sky. At the wall's
    foot (u = 0) the value is the limit from the floor's side (Lambert at u = 1e-9)."""
    scene = core.Scene()
    floor = scene.add(core.Quad(*FLOOR), reflectance=RHO, patches=4)
    scene.add(core.Quad(*WALL), reflectance=0.0, patches=4)
    scene.set_sky(1.0)
    sol = scene.solve(tol=1e-5, method=method)
    x = np.array([max(u, 1e-9), v, 0.0])
    expected = RHO * (1.0 - lambert(x, np.array([0.0, 0.0, 1.0]), WALL))
    assert sol.radiosity_at(floor, [u], [v])[0, 0] == pytest.approx(expected, rel=1e-4)


@METHODS
def test_patch_sky_fraction_is_one_minus_the_row_sum(method):
    """Per patch, the solve's sky term is rho L (1 - sum_j F_ij) with the solved matrix's factors
    (one bounce: the wall is black): the patch average of the pointwise Lambert value."""
    scene = core.Scene()
    floor = scene.add(core.Quad(*FLOOR), reflectance=RHO, patches=2)
    scene.add(core.Quad(*WALL), reflectance=0.0, patches=2)
    scene.set_sky(1.0)
    sol = scene.solve(tol=1e-6, method=method)
    # midpoint-free reference: 16 x 16 Gauss points of each floor patch
    g, w = np.polynomial.legendre.leggauss(16)
    g, w = 0.25 * (g + 1.0), 0.25 * w  # on [0, 0.5]
    patches = []
    for i in range(2):
        for j in range(2):
            up = np.array([0.0, 0.0, 1.0])
            points = [[np.array([0.5 * i + a, 0.5 * j + b, 0.0]) for b in g] for a in g]
            values = [[1.0 - lambert(x, up, WALL) for x in row] for row in points]
            patches.append(w @ np.array(values) @ w / 0.25)
    assert np.allclose(sol.radiosity(floor)[:, 0], RHO * np.array(patches), rtol=1e-5)


@METHODS
def test_closed_box_sees_no_sky(method):
    """Inside a closed box every direction meets a wall: the sky gives nothing."""
    scene = core.Scene()
    corners = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float
    )
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    walls = [scene.add(core.Quad(*corners[list(f)]).flipped(), reflectance=0.7, patches=3) for f in faces]
    scene.set_sky(1.0)
    sol = scene.solve(tol=1e-3, method=method)
    # without the box the walls would show rho L / (1 - rho) = 2.33 after bounces
    assert max(np.abs(sol.radiosity(h)).max() for h in walls) < 1e-5
    assert np.abs(sol.radiosity_at(walls[0], [0.5, 0.01, 0.0], [0.5, 0.5, 0.0])).max() < 1e-5


@METHODS
def test_area_light_does_not_hide_the_sky(method):
    """Area lights (occluder=False) neither block nor reflect in Cycles: a plane under one gets
    the full sky plus the light's own rho L_light F(x -> light)."""
    scene = core.Scene()
    floor = scene.add(core.Quad(*FLOOR), reflectance=RHO, patches=2)
    lamp = [(0.25, 0.25, 0.5), (0.25, 0.75, 0.5), (0.75, 0.75, 0.5), (0.75, 0.25, 0.5)]  # front -z
    scene.add(core.Quad(*lamp), reflectance=0.0, emission=3.0, patches=1, occluder=False)
    scene.set_sky(1.0)
    sol = scene.solve(tol=1e-5, method=method)
    x = np.array([0.5, 0.5, 0.0])
    expected = RHO * (1.0 + 3.0 * lambert(x, np.array([0.0, 0.0, 1.0]), lamp))
    assert sol.radiosity_at(floor, [0.5], [0.5])[0, 0] == pytest.approx(expected, rel=1e-4)


@METHODS
def test_changing_the_sky_is_a_relight(method):
    """set_sky keeps the form factors (or links): the second solve reuses the geometry and scales
    linearly."""
    scene = core.Scene()
    floor = scene.add(core.Quad(*FLOOR), reflectance=RHO, patches=2)
    scene.add(core.Quad(*WALL), reflectance=RHO, patches=2)
    scene.set_sky(1.0)
    first = scene.solve(tol=1e-4, method=method).radiosity(floor)
    scene.set_sky(3.0)
    sol = scene.solve(tol=1e-4, method=method)
    assert sol.stats["geometry_cached"] is True
    # (the pairs' LU is linear to rounding; the hierarchy's sweeps stop within tol)
    assert np.allclose(sol.radiosity(floor), 3.0 * first, rtol=1e-6 if method == "pairs" else 1e-4)
    scene.set_sky(0.0)
    assert np.all(scene.solve(tol=1e-4, method=method).radiosity(floor) == 0.0)


@pytest.mark.parametrize("value", [-1.0, np.nan, (1.0, 2.0), "blue"])
def test_bad_sky(value):
    """A negative, non-finite, wrong-sized or non-numeric sky is refused with a named error."""
    scene = core.Scene()
    with pytest.raises((ValueError, TypeError), match="sky"):
        scene.set_sky(value)
