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


def test_merged_points_give_weighted_sums():
    """Merged points (`GatherFactors.merged`) give the weighted sums of their points' radiosity
    in one product, with emission, sky and lights (each scaled by the weights), also after a
    relight; a group that mixes surfaces or is empty is refused."""
    scene, floor, wall, ball, light = scene_with_everything()
    scene.set_material(floor, emission=0.3)
    sol = scene.solve(tol=1e-3)
    u, v = points(200)
    both = core.GatherFactors.concatenate(
        [sol.gather_factors(floor, u[:120], v[:120]), sol.gather_factors(wall, u[120:], v[120:])]
    )
    rng = np.random.default_rng(1)
    # 30 merged points of the floor's 120, 20 of the wall's 80 (each gets at least one)
    group = np.concatenate(
        [np.arange(30), rng.integers(0, 30, 90), 30 + np.arange(20), 30 + rng.integers(0, 20, 60)]
    )
    weight = rng.random(200)
    merged = both.merged(group, weight, 50)
    assert len(merged) == 50 and merged.values.size < both.values.size
    scene.set_light(light, intensity=3.0)
    scene.set_material(wall, reflectance=(0.6, 0.2, 0.3))
    relit = scene.solve(tol=1e-3)
    for s in (sol, relit):
        samples = s.radiosity_from(both)
        expected = np.stack([np.bincount(group, weight * samples[:, c], 50) for c in range(3)], axis=1)
        assert np.allclose(s.radiosity_from(merged), expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    with pytest.raises(ValueError, match="one surface"):
        both.merged(np.zeros(200, int), np.ones(200), 1)
    with pytest.raises(ValueError, match="at least one point"):
        both.merged(group, weight, 51)


def dense(factors):
    """W of `factors` as a dense float64 array (K, N), repeated (point, element) factors added."""
    W = np.zeros((len(factors), len(factors.targets)))
    np.add.at(W, (factors.rows, factors.cols), factors.values)
    return W


def test_dense_and_sparse_products_agree():
    """A W dense enough is held as a dense matrix after the first product: the products agree
    with the sparse sums (to rounding), and its factors still read back (`take` after a product)."""
    scene, floor, _, _, _ = scene_with_everything()
    sol = scene.solve(tol=1e-3)
    u, v = points(300)
    kept = sol.gather_factors(floor, u, v)
    W = dense(kept)
    B = np.random.default_rng(2).random((len(kept.targets), 3))
    sparse_bytes = kept.nbytes
    product = kept.product(B)
    assert kept.nbytes < sparse_bytes  # a floor point sees most elements: dense is smaller
    assert np.allclose(product, W @ B, rtol=1e-12, atol=1e-14 * np.abs(W @ B).max())
    again = kept.take(np.arange(len(kept)))
    assert np.allclose(dense(again), W, rtol=1e-6, atol=0)
    assert np.all(np.diff(again.rows) >= 0)
