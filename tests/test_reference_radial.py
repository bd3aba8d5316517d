"""Checks of the deterministic occluded-disk reference (tests/reference/occluded_radial.py).

1. No spheres: the offset plane-element-to-parallel-disk closed form (Howell's catalogue) against
   a direct quadrature written here, and the reference's own phi-integration against it.
2. A sphere on the axis between a floor point and the lamp: the shadow is a centred disk, so
   F_vis = F(lamp) - F(central disk of the shadow's radius), in closed form.
3. Patch means of the resting-sphere scene against the randomised QMC reference.
4. The error estimates are honest: loose-tolerance runs differ from tight ones by less than their
   estimates (patch means in the one- and two-sphere scenes, point factors), and mirror-image
   patches agree within them.
"""

import numpy as np
import pytest
from reference.occluded_mc import disk_pair_factor
from reference.occluded_radial import (
    disk_point_factor_exact,
    floor_patch_factor_exact,
    floor_reference_exact,
    unoccluded_factor,
)

RESTING = dict(lamp_center=(0.3, 0.0, 2.0), lamp_radius=0.25, spheres=[((0.0, 0.0, 0.5), 0.5)])
BOX = dict(
    lamp_center=(0.0, 0.0, 3.95),
    lamp_radius=0.4,
    spheres=[((-0.6, 0.3, 0.7), 0.7), ((0.9, -0.5, 1.8), 0.5)],
)
EDGES = np.linspace(-2.0, 2.0, 9)  # the benchmark's 8 x 8 floor patches


def patch(k):
    """Corners (x0, x1, y0, y1) of patch k = i * 8 + j of the benchmark grid (i along x)."""
    i, j = divmod(k, 8)
    return EDGES[i], EDGES[i + 1], EDGES[j], EDGES[j + 1]


def direct_disk_factor(x, center, radius, n_r=60, n_phi=256):
    """F(dA(x) -> parallel disk) by Gauss-Legendre in r and the (spectrally accurate) trapezoidal
    rule in the periodic phi: H^2 / pi int int r dr dphi / (r^2 + 2 r rho cos phi + rho^2 + H^2)^2."""
    H = center[2] - x[2]
    rho = np.hypot(x[0] - center[0], x[1] - center[1])
    t, w = np.polynomial.legendre.leggauss(n_r)
    r, wr = radius * (t + 1) / 2, radius * w / 2
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    q = r[:, None] ** 2 + 2 * r[:, None] * rho * np.cos(phi)[None] + rho * rho + H * H
    return H * H / np.pi * (2 * np.pi / n_phi) * np.sum(wr[:, None] * r[:, None] / q**2)


@pytest.mark.parametrize("rho", [0.0, 0.1, 0.2499, 0.25, 0.4, 1.3, 3.0])
def test_offset_disk_closed_form(rho):
    center, radius = (0.3, -0.2, 2.0), 0.25
    x = np.array([0.3 + rho * 0.6, -0.2 - rho * 0.8, 0.0])
    F = unoccluded_factor(x[None], center, radius)[0]
    assert F == pytest.approx(direct_disk_factor(x, center, radius), rel=1e-12, abs=1e-15)
    H = 2.0  # the catalogue's form 0.5 (1 - X / Y), as written there
    X, Y = (
        H * H + rho * rho - radius**2,
        np.sqrt((H * H + rho * rho + radius**2) ** 2 - 4 * radius**2 * rho**2),
    )
    assert F == pytest.approx(0.5 * (1 - X / Y), rel=1e-12)


def test_no_spheres_phi_integration_matches_closed_form():
    rng = np.random.default_rng(5)
    points = np.column_stack([rng.uniform(-3, 3, (400, 2)), np.zeros(400)])
    points[:3, :2] = [(0.3, 0.0), (0.55, 0.0), (0.3, 0.25)]  # under the centre, above the rim
    for center, radius in (((0.3, 0.0, 2.0), 0.25), ((0.0, 0.0, 0.5), 1.5)):
        F, err = disk_point_factor_exact(points, center, radius, [], integrate_all=True)
        exact = unoccluded_factor(points, center, radius)
        assert np.all(np.abs(F - exact) <= 1e-12 * exact)
        assert np.all(err <= 1e-12 * exact)


@pytest.mark.parametrize(
    "height, a, radius",
    [(0.8, 0.1, 0.5), (1.2, 0.3, 0.25), (0.4, 0.39, 0.7), (0.8, 0.3, 0.5), (1.9, 0.05, 0.1)],
)
def test_coaxial_sphere_leaves_a_ring(height, a, radius):
    """x right under the sphere and the lamp centre: the shadow of the sphere on the lamp plane
    is the centred disk of radius H a / sqrt(L^2 - a^2), L the sphere centre's height."""
    H, x0 = 2.0, np.array([0.1, 0.2])
    point = np.array([[x0[0], x0[1], 0.0]])
    center = (x0[0], x0[1], H)
    shadow = H * a / np.sqrt(height**2 - a**2)

    def coaxial(r):
        return r * r / (H * H + r * r)

    expected = coaxial(radius) - coaxial(min(shadow, radius))
    spheres = [((x0[0], x0[1], height), a)]
    for integrate_all in (False, True):
        F, err = disk_point_factor_exact(point, center, radius, spheres, integrate_all=integrate_all)
        assert abs(F[0] - expected) <= 1e-12 * coaxial(radius)
        assert err[0] <= 1e-12 * coaxial(radius)


def test_off_axis_sphere_both_formulations_agree():
    """The closed form minus the blocked part and the visible part alone agree, in penumbra."""
    xs = np.linspace(-1.1, 0.7, 37)
    points = np.column_stack([xs, np.full_like(xs, 0.3), np.zeros_like(xs)])
    F1, e1 = disk_point_factor_exact(points, **RESTING)
    F2, e2 = disk_point_factor_exact(points, **RESTING, integrate_all=True)
    assert np.all(np.abs(F1 - F2) <= e1 + e2 + 1e-17)
    assert np.all(e1 <= 1e-12 * unoccluded_factor(points, RESTING["lamp_center"], 0.25))


# patches of the resting-sphere scene: lit, penumbra, umbra edge, slivers (most of the patch in
# the umbra), and the mirror images 20 / 36 of 19 / 35
PATCHES = (0, 18, 19, 20, 26, 27, 35, 36)


@pytest.fixture(scope="module")
def resting_exact():
    corners = np.array([patch(k) for k in PATCHES]).T
    tight = floor_patch_factor_exact(*corners, **RESTING, rtol=1e-10)
    loose = floor_patch_factor_exact(*corners, **RESTING, rtol=1e-6)
    return tight, loose


def test_resting_patches_against_qmc(resting_exact):
    (mean, err), _ = resting_exact
    assert np.all(err <= np.maximum(1e-10 * mean, 1e-13))
    for k, m in zip(PATCHES, mean):
        x0, x1, y0, y1 = patch(k)
        source = ((x0, y0, 0.0), (x1 - x0, 0.0, 0.0), (0.0, y1 - y0, 0.0))
        q, se = disk_pair_factor(source, RESTING["lamp_center"], 0.25, RESTING["spheres"], count=1 << 14)
        assert se > 0
        assert abs(q - m) <= 4 * se, (k, m, q, se)


def test_resting_error_estimates_are_honest(resting_exact):
    (tight, tight_err), (loose, loose_err) = resting_exact
    assert np.all(np.abs(loose - tight) <= loose_err + tight_err)
    assert np.all(loose_err <= np.maximum(1e-6 * loose, 1e-13))
    # the scene is symmetric in y: patch (i, j) mirrors (i, 7 - j)
    for a, b in ((19, 20), (35, 36)):
        ia, ib = PATCHES.index(a), PATCHES.index(b)
        assert abs(tight[ia] - tight[ib]) <= tight_err[ia] + tight_err[ib]


def test_closed_box_error_estimates_are_honest():
    """Two spheres, one resting on the floor: penumbra and umbra patches of both."""
    corners = np.array([patch(k) for k in (12, 19, 29, 50, 53)]).T
    tight, tight_err = floor_patch_factor_exact(*corners, **BOX, rtol=1e-10)
    loose, loose_err = floor_patch_factor_exact(*corners, **BOX, rtol=1e-6)
    assert np.all(np.abs(loose - tight) <= loose_err + tight_err)
    assert np.all(tight_err <= np.maximum(1e-10 * tight, 1e-13))


def test_point_error_estimates_are_honest():
    rng = np.random.default_rng(11)
    points = np.column_stack([rng.uniform(-2, 2, (3000, 2)), np.zeros(3000)])
    for scene in (RESTING, BOX):
        tight, tight_err = disk_point_factor_exact(points, **scene, rtol=1e-13)
        loose, loose_err = disk_point_factor_exact(points, **scene, rtol=1e-7)
        assert np.all(np.abs(loose - tight) <= loose_err + tight_err)
        assert np.all(loose_err <= np.maximum(1e-7 * loose, 1e-16))


def test_floor_reference_layout():
    """Patch i * m + j spans [e_i, e_(i+1)] in x and [e_j, e_(j+1)] in y, times rho E."""
    values, errors = floor_reference_exact(2.0, 2, **RESTING, rho=0.5, E=10.0, rtol=1e-6)
    for i in range(2):
        for j in range(2):
            x0, y0 = -2.0 + 2.0 * i, -2.0 + 2.0 * j
            mean, err = floor_patch_factor_exact(x0, x0 + 2.0, y0, y0 + 2.0, **RESTING, rtol=1e-6)
            assert values[i * 2 + j] == pytest.approx(5.0 * mean, rel=1e-12)
            assert errors[i * 2 + j] == pytest.approx(5.0 * err, rel=1e-12)
    assert values[2] > values[0]  # the lamp is off axis towards +x
