"""Lights with an extent: point / spot lights with a radius (sphere lights) and suns with an angle.

References: brute-force integration over the cap of directions (a fine midpoint grid in the
cap's own polar coordinates), and a seeded Monte Carlo with its own analytic ray-sphere test
for shadows. Cycles renders the same lights the same way (tests/blender/test_lights.py).
"""

import numpy as np
import pytest

import core
from core.lights import cap_irradiance

RHO = 0.5


def frame(axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return axis, e1, np.cross(axis, e1)


def cap_grid(axis, sigma, n=400):
    """Directions (n*n, 3) and their solid angles (n*n,) tiling the cap of half-angle sigma."""
    a, e1, e2 = frame(axis)
    g = (np.arange(n) + 0.5) / n * sigma
    phi = (np.arange(n) + 0.5) / n * 2.0 * np.pi
    G, P = np.meshgrid(g, phi, indexing="ij")
    w = (
        np.cos(G)[..., None] * a
        + (np.sin(G) * np.cos(P))[..., None] * e1
        + (np.sin(G) * np.sin(P))[..., None] * e2
    )
    return w.reshape(-1, 3), (np.sin(G) * (sigma / n) * (2.0 * np.pi / n)).ravel()


def cap_mc(axis, sigma, n, rng):
    """n directions uniform in solid angle in the cap, shape (n, 3)."""
    a, e1, e2 = frame(axis)
    cos_g = 1.0 - (1.0 - np.cos(sigma)) * rng.random(n)
    sin_g = np.sqrt(1.0 - cos_g**2)
    phi = 2.0 * np.pi * rng.random(n)
    return cos_g[:, None] * a + (sin_g * np.cos(phi))[:, None] * e1 + (sin_g * np.sin(phi))[:, None] * e2


@pytest.mark.parametrize("sigma", [0.05, 0.4, 1.2])
@pytest.mark.parametrize("theta", [0.0, 0.7, 1.45, 1.57, 1.7, 2.5])
def test_cap_irradiance_matches_integration(theta, sigma):
    """integral over the cap of max(0, n . w) dw, whole, setting and set, against a fine grid."""
    n = np.array([0.0, 0.0, 1.0])
    axis = np.array([np.sin(theta), 0.0, np.cos(theta)])
    w, dw = cap_grid(axis, sigma)
    reference = (np.maximum(w @ n, 0.0) * dw).sum()
    got = cap_irradiance(np.array([np.cos(theta)]), np.array([np.sin(sigma) ** 2]))[0]
    assert got == pytest.approx(reference, rel=1e-4, abs=1e-7 * sigma**2)


def floor_scene(occluder=None):
    scene = core.Scene()
    floor = scene.add(core.Quad((-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)), reflectance=RHO, patches=2)
    if occluder is not None:
        scene.add(occluder, reflectance=0.0)
    return scene, floor


def at(sol, floor, xs, y=0.0):
    xs = np.asarray(xs, float)
    return sol.radiosity_at(floor, (xs + 4.0) / 8.0, np.full(xs.size, (y + 4.0) / 8.0))[:, 0]


def test_sphere_light_without_shadows():
    """A sphere light (intensity I, radius r) gives I cos / d^2 where it is wholly above the
    horizon, and I / (pi r^2) times the clipped cap (grid) where it sets."""
    intensity, radius, height = 3.0, 0.5, 0.6
    scene, floor = floor_scene()
    scene.add_point_light((0.0, 0.0, height), intensity, radius=radius)
    sol = scene.solve(tol=1e-4)
    xs = np.array([0.2, 1.0, 1.5, 3.0])
    got = at(sol, floor, xs)
    for x, value in zip(xs, got):
        toward = np.array([-x, 0.0, height])
        d = np.linalg.norm(toward)
        w, dw = cap_grid(toward, np.arcsin(radius / d))
        reference = RHO / np.pi * intensity / (np.pi * radius**2) * (np.maximum(w[:, 2], 0) * dw).sum()
        assert value == pytest.approx(reference, rel=1e-3)
    # far away the sphere is a point
    assert got[-1] == pytest.approx(RHO / np.pi * intensity * height / (9.0 + height**2) ** 1.5, rel=1e-3)


def visible_fraction(x, directions, centre, radius):
    """Cosine-weighted share of `directions` from x that miss the sphere (centre, radius)."""
    oc = centre - x
    b = directions @ oc
    disc = b * b - (oc @ oc - radius**2)
    hit = (disc > 0) & (b - np.sqrt(np.maximum(disc, 0.0)) > 0)
    cos = np.maximum(directions[:, 2], 0.0)
    return (cos * ~hit).sum() / cos.sum()


def test_sphere_light_penumbra():
    """A ball between a sphere light and the floor: umbra 0, lit I cos / d^2, and across the
    penumbra the lit value times the visible share of the light (Monte Carlo, 2e5 rays, seed 1)
    within 0.02 of the lit value (the rule's 128 rays)."""
    intensity, radius = 5.0, 0.3
    light, ball = np.array([0.0, 0.0, 3.0]), (np.array([0.0, 0.0, 1.0]), 0.5)
    scene, floor = floor_scene(core.Sphere(ball[0], ball[1]))
    scene.add_point_light(light, intensity, radius=radius)
    sol = scene.solve(tol=1e-3)
    xs = np.linspace(0.0, 1.4, 15)
    got = at(sol, floor, xs)
    rng = np.random.default_rng(1)
    shares = []
    for x, value in zip(xs, got):
        p = np.array([x, 0.0, 0.0])
        toward = light - p
        d = np.linalg.norm(toward)
        lit = RHO / np.pi * intensity * toward[2] / d**3
        share = visible_fraction(p, cap_mc(toward, np.arcsin(radius / d), 200_000, rng), *ball)
        shares.append(share)
        assert abs(value - lit * share) <= 0.02 * lit, (x, value / lit, share)
    assert min(shares) == 0.0 and max(shares) == 1.0 and any(0.1 < s < 0.9 for s in shares)


def test_sun_with_an_angle():
    """A sun of angular diameter alpha: irradiance E cos(theta) on planes it wholly lights, and a
    penumbra under a ball matching the visible share of its disk (Monte Carlo, seed 2)."""
    E, alpha = 2.0, np.radians(20.0)
    ball = (np.array([0.0, 0.0, 1.0]), 0.5)
    scene, floor = floor_scene(core.Sphere(ball[0], ball[1]))
    scene.add_sun_light((0.0, 0.0, -1.0), E, angle=alpha)
    sol = scene.solve(tol=1e-3)
    lit = RHO / np.pi * E
    xs = np.linspace(0.0, 1.2, 13)
    got = at(sol, floor, xs)
    rng = np.random.default_rng(2)
    shares = []
    for x, value in zip(xs, got):
        p = np.array([x, 0.0, 0.0])
        share = visible_fraction(p, cap_mc((0.0, 0.0, 1.0), 0.5 * alpha, 200_000, rng), *ball)
        shares.append(share)
        assert abs(value - lit * share) <= 0.02 * lit, (x, value / lit, share)
    assert min(shares) == 0.0 and max(shares) == 1.0 and any(0.1 < s < 0.9 for s in shares)


def test_sun_setting_at_the_horizon():
    """A wall edge-on to a sun of angle alpha still gets the half of its disk above the horizon:
    E / (pi sin^2(alpha / 2)) times the clipped cap's integral (grid)."""
    E, alpha = 1.0, np.radians(10.0)
    scene = core.Scene()
    wall = scene.add(core.Quad((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)), reflectance=RHO, patches=1)  # +x
    scene.add_sun_light((0.0, 0.0, -1.0), E, angle=alpha)  # light travels down: grazes the wall
    sol = scene.solve(tol=1e-4)
    w, dw = cap_grid((0.0, 0.0, 1.0), 0.5 * alpha)
    reference = RHO / np.pi * E / (np.pi * np.sin(0.5 * alpha) ** 2) * (np.maximum(w[:, 0], 0) * dw).sum()
    assert sol.radiosity_at(wall, [0.5], [0.5])[0, 0] == pytest.approx(reference, rel=1e-4)
    assert reference > 0.1 * RHO / np.pi * E * np.sin(0.5 * alpha)


@pytest.mark.parametrize("angle", [-0.1, np.pi, np.nan, "wide"])
def test_bad_sun_angle(angle):
    scene = core.Scene()
    with pytest.raises((ValueError, TypeError), match="sun angle"):
        scene.add_sun_light((0.0, 0.0, -1.0), 1.0, angle=angle)


def test_soft_falloff_is_a_facing_disk():
    """Cycles' soft falloff: a disk of radius r facing the receiver, I / (pi r^2) times its cone's
    clipped cap, tan(sigma) = r / d: I / (d^2 + r^2) straight below, less than the sphere's I / d^2."""
    intensity, radius, height = 3.0, 0.5, 2.0
    scene, floor = floor_scene()
    scene.add_point_light((0.0, 0.0, height), intensity, radius=radius, soft_falloff=True)
    sol = scene.solve(tol=1e-4)
    xs = np.array([0.0, 1.0, 3.0])
    got = at(sol, floor, xs)
    assert got[0] == pytest.approx(RHO / np.pi * intensity / (height**2 + radius**2), rel=1e-6)
    for x, value in zip(xs, got):
        toward = np.array([-x, 0.0, height])
        d = np.linalg.norm(toward)
        w, dw = cap_grid(toward, np.arctan(radius / d))
        reference = RHO / np.pi * intensity / (np.pi * radius**2) * (np.maximum(w[:, 2], 0) * dw).sum()
        assert value == pytest.approx(reference, rel=1e-3)


@pytest.mark.parametrize("method", ["pairs", "hierarchical"])
def test_patch_irradiance_of_a_close_lamp_meets_tol(method):
    """A point lamp 0.15 m over the middle of a 0.5 m patch: the lamp's irradiance I cos / r^2
    varies 30-fold over it, and a fixed 3 x 3 rule is 16 % off; each patch's mean meets tol
    against a 64 x 64 Gauss rule of the closed form (one bounce: nothing else reflects)."""
    tol = 1e-3
    scene = core.Scene()
    floor = scene.add(core.Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), reflectance=RHO, patches=2)
    lamp, intensity = np.array([0.25, 0.25, 0.15]), 3.0
    scene.add_point_light(lamp, intensity)
    extra = dict(contact_levels=0, light_levels=0) if method == "hierarchical" else {}
    B = scene.solve(tol=tol, method=method, **extra).radiosity(floor)[:, 0]
    t, w = np.polynomial.legendre.leggauss(64)
    t, w = 0.25 * (t + 1), 0.25 * w  # on [0, 0.5]
    reference = []
    for i in range(2):
        for j in range(2):
            x, y = np.meshgrid(0.5 * i + t, 0.5 * j + t, indexing="ij")
            E = intensity * lamp[2] / ((x - lamp[0]) ** 2 + (y - lamp[1]) ** 2 + lamp[2] ** 2) ** 1.5
            reference.append(RHO / np.pi * (w @ E @ w) / 0.25)
    np.testing.assert_allclose(B, reference, rtol=tol)
