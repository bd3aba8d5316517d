"""Checks of `reference.occluded_square` (a floor patch's view of a square lamp past a sphere) by
means that share nothing with it: Lambert's polygon formula where the sphere blocks nothing, the
closed form F(x -> lamp) - F(x -> sphere) where the sphere's silhouette lies inside the lamp, and
Monte Carlo with its own ray-sphere test in the penumbra, within its error bar."""

import numpy as np
from reference.occluded_exact import _lambert
from reference.occluded_square import patch_mean, point_factors

LAMP = (0.0, 0.0, 1.0, 5.0)  # the square [-1, 1]^2 at z = 5, facing down
CORNERS = np.array([(-1, -1, 5), (1, -1, 5), (1, 1, 5), (-1, 1, 5)], float)
UP = np.array([0.0, 0.0, 1.0])


def _monte_carlo(x, spheres, N, rng):
    """F_vis(x -> lamp) past the spheres by N uniform lamp points per floor point, with a ray-sphere
    test of its own: (means (X,), standard errors (X,))."""
    means, errors = [], []
    for p in x:
        q = np.c_[rng.uniform(-1, 1, (N, 2)), np.full(N, 5.0)]
        d = q - p
        L2 = np.einsum("ki,ki->k", d, d)
        hit = np.zeros(N, bool)
        for c, r in spheres:
            oc = p - c
            b = d @ oc
            hit |= b * b - L2 * (oc @ oc - r * r) > 0  # (the spheres lie between the planes)
        value = 4.0 * 25.0 / (np.pi * L2 * L2) * ~hit
        means.append(value.mean())
        errors.append(value.std() / np.sqrt(N))
    return np.array(means), np.array(errors)


def test_unblocked_points_are_lamberts_square():
    rng = np.random.default_rng(1)
    x = np.c_[rng.uniform(-4, 4, (200, 2)), np.zeros(200)]
    F = point_factors(x, LAMP, (np.array([30.0, 30.0, 2.0]), 0.01))
    np.testing.assert_allclose(F, _lambert(x, np.tile(UP, (200, 1)), CORNERS), rtol=1e-12)


def test_a_silhouette_inside_the_lamp_takes_the_spheres_factor_off():
    """(r/d)^2 cos(gamma): element to a sphere wholly above its horizon (Siegel & Howell, app. C)."""
    rng = np.random.default_rng(2)
    x = np.c_[rng.uniform(-0.3, 0.3, (200, 2)), np.zeros(200)]
    c, r = np.array([0.1, -0.05, 3.0]), 0.1
    d = c[None] - x
    dist = np.linalg.norm(d, axis=1)
    exact = _lambert(x, np.tile(UP, (200, 1)), CORNERS) - (r / dist) ** 2 * d[:, 2] / dist
    np.testing.assert_allclose(point_factors(x, LAMP, (c, r)), exact, rtol=1e-12)


def test_penumbra_points_against_monte_carlo():
    rng = np.random.default_rng(3)
    c, r = np.array([3.0, -3.0, 0.9]), 0.5
    x = np.array([[3.2, -3.9, 0.0], [2.5, -2.5, 0.0], [3.66, -3.66, 0.0]])
    F = point_factors(x, LAMP, (c, r))
    assert F[2] == 0.0  # (under the ball's umbra)
    mean, error = _monte_carlo(x[:2], [(c, r)], 1_000_000, rng)
    assert np.all(np.abs(mean - F[:2]) < 4.0 * error)


def test_patch_means_converge():
    """The error bar is honest: a loose mean differs from a tight one by less than its bar."""
    c, r = np.array([3.0, -3.0, 0.9]), 0.5
    loose, bar = patch_mean(4 / 3, 4, -4, -4 / 3, LAMP, (c, r), rtol=1e-4)
    tight, tight_bar = patch_mean(4 / 3, 4, -4, -4 / 3, LAMP, (c, r), rtol=2e-6)
    assert tight_bar <= 2e-6 * tight < bar and abs(tight - loose) <= bar


def test_several_spheres_block_the_union_of_their_chords():
    """Shadows apart: F_vis past two spheres = F_vis past each - the unblocked F; shadows that
    overlap: Monte Carlo with its own ray-sphere test, within 4 sigma plus the reference's bar."""
    a, b = (np.array([2.0, -1.0, 0.9]), 0.5), (np.array([-2.0, 1.0, 0.7]), 0.5)
    rng = np.random.default_rng(4)
    x = np.c_[rng.uniform(-4, 4, (300, 2)), np.zeros(300)]
    free = point_factors(x, LAMP, (np.array([30.0, 30.0, 2.0]), 0.01))
    both = point_factors(x, LAMP, [a, b])
    np.testing.assert_allclose(both, point_factors(x, LAMP, a) + point_factors(x, LAMP, b) - free, atol=1e-15)
    # two balls one behind the other from x: their chords overlap on the lamp's rows
    spheres = [(np.array([0.3, 0.0, 1.5]), 0.4), (np.array([0.0, 0.2, 3.0]), 0.3)]
    x = np.array([[0.4, -0.3, 0.0], [0.9, 0.4, 0.0]])
    F, bar = point_factors(x, LAMP, spheres, error=True)
    single = point_factors(x, LAMP, spheres[0])
    assert (F > 0).all() and (F <= single).all() and (F < single).any()
    mean, error = _monte_carlo(x, spheres, 1_000_000, rng)
    assert np.all(np.abs(mean - F) < 4.0 * error + bar)
