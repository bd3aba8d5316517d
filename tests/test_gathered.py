"""Kept gather factors (`Solution.gather_factors`, `radiosity_from`): relighting without a new gather."""

import numpy as np
import pytest

import core


def scene_with_everything():
    """A floor, a two-sided wall, a ball, a sphere light and a sky."""
    scene = core.Scene()
    floor = scene.add(core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), reflectance=0.5, patches=4)
    wall = scene.add(
        core.Quad((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)), reflectance=0.3, patches=3, two_sided=True
    )
    ball = scene.add(core.Sphere((0.5, 0.5, 0.4), 0.2), reflectance=0.6, patches=(4, 8))
    light = scene.add_point_light((0.6, 0.4, 1.5), 2.0, radius=0.1)
    scene.set_sky(0.2)
    return scene, floor, wall, ball, light


def points(count, seed=0):
    rng = np.random.default_rng(seed)
    return rng.random(count), rng.random(count)


def test_kept_factors_give_the_gather():
    """Applied to their own solution, the kept factors reproduce radiosity_at (float32 factors:
    1e-6), also for a back side and for factors of several calls joined."""
    scene, floor, wall, _, _ = scene_with_everything()
    sol = scene.solve(tol=1e-3)
    u, v = points(600)
    parts = [sol.gather_factors(floor, u[:300], v[:300]), sol.gather_factors(floor, u[300:], v[300:])]
    joined = core.GatherFactors.concatenate(parts)
    reference = sol.radiosity_at(floor, u, v)
    assert np.allclose(sol.radiosity_from(joined), reference, rtol=1e-6, atol=1e-9)
    back = sol.gather_factors(wall, u[:50], v[:50], side="back")
    assert np.allclose(
        sol.radiosity_from(back), sol.radiosity_at(wall, u[:50], v[:50], side="back"), rtol=1e-6
    )


def test_relight_with_kept_factors():
    """New materials, emission, light power and sky: the kept factors applied to the new solve
    agree with a new gather to the gather's visibility accuracy (the rays a new gather picks
    follow the new light: 5e-3), and scaling every source by 3 scales the result by 3 (to the
    solve's tolerance)."""
    scene, floor, _, ball, light = scene_with_everything()
    sol = scene.solve(tol=1e-3)
    u, v = points(400)
    kept = sol.gather_factors(floor, u, v)
    scene.set_material(floor, reflectance=(0.2, 0.7, 0.4))
    scene.set_material(ball, emission=1.0)
    scene.set_light(light, intensity=5.0)
    scene.set_sky((0.1, 0.3, 0.5))
    relit = scene.solve(tol=1e-3)
    assert relit.stats["geometry_cached"] is True
    got = relit.radiosity_from(kept)
    fresh = relit.radiosity_at(floor, u, v)
    assert np.abs(got - fresh).max() <= 5e-3 * np.abs(fresh).max()
    scene.set_material(ball, emission=3.0)
    scene.set_light(light, intensity=15.0)
    scene.set_sky((0.3, 0.9, 1.5))
    tripled = scene.solve(tol=1e-3).radiosity_from(kept)
    assert np.allclose(tripled, 3.0 * got, rtol=2e-3)


def test_stale_factors_are_refused():
    """Factors of another geometry, with another number of lights, or missing an element that now
    carries light raise a ValueError that says to gather again."""
    scene, floor, _, ball, _ = scene_with_everything()
    scene.set_material(ball, reflectance=0.0)  # black: left out of the kept factors
    scene.set_sky(0.0)
    sol = scene.solve(tol=1e-3)
    kept = sol.gather_factors(floor, [0.5], [0.5])
    scene.set_material(ball, reflectance=0.5)
    with pytest.raises(ValueError, match="gather again"):
        scene.solve(tol=1e-3).radiosity_from(kept)
    scene.add_sun_light((0, 0, -1), 1.0)
    with pytest.raises(ValueError, match="gather again"):
        scene.solve(tol=1e-3).radiosity_from(kept)
    scene.set_surface(ball, core.Sphere((0.5, 0.5, 0.5), 0.2))
    with pytest.raises(ValueError, match="another geometry"):
        scene.solve(tol=1e-3).radiosity_from(kept)
    with pytest.raises(TypeError, match="GatherFactors"):
        sol.radiosity_from("factors")
