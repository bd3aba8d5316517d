"""Point, spot and sun lights: direct irradiance with shadows, in Cycles' conventions.

- Point light: radiant intensity I (W/sr, RGB) in every direction; irradiance I cos(theta) / d^2.
  With a radius r it is a sphere of uniform radiance I / (pi r^2), as Cycles renders point and
  spot lights with a radius (since Blender 4.0): the same irradiance where the whole sphere is
  above the receiver's horizon, less where it sets, and soft shadows; with Cycles' "Soft
  Falloff" (`soft_falloff`) a disk of radius r facing the receiver instead (checked against
  Cycles bakes in tests/blender/test_cycles_bakes.py).
- Spot light: a point light cut by a cone about `direction` (Cycles: the cone never concentrates
  the light) with Cycles' soft edge smoothstep((cos(phi) - cos(size / 2)) / ((1 - cos(size / 2))
  * blend)), phi the angle from the axis (of the direction from the light's centre).
- Sun light: irradiance E (W/m^2, RGB) on a plane facing it, arriving along `direction` (the
  direction the light travels). With an angular diameter `angle` it is a disk of directions of
  uniform radiance E / (pi sin^2(angle / 2)): soft shadows, and a gradual setting at the horizon.

A light with an extent (sphere or sun disk) is a spherical cap of directions seen from the
receiver, of half-angle sigma. Its unshadowed irradiance is L times the cosine-weighted solid
angle of the cap's part above the horizon, in closed form (`cap_irradiance`); shadows are the
cosine-weighted fraction of CAP_SAMPLES directions in the cap (equal solid angle each) whose
rays are free (a Fibonacci spiral: within 2 % of the visible fraction across a sphere's
penumbra, tests/test_light_extent.py). Probe rays (the cap's centre and CAP_PROBE points on its
rim) are traced first; points whose probes all agree are taken as wholly lit or wholly shadowed.
"""

import numpy as np

from . import checks

CAP_SAMPLES = 128  # shadow rays toward a light with an extent (sphere, sun disk) in its penumbra
CAP_PROBE = 8  # probe rays on the cap's rim (plus its centre) traced first: where all agree, the
# point is taken as wholly lit or in umbra


def cap_irradiance(cos_theta, sin2_sigma):
    """Cosine-weighted solid angle of the part of a spherical cap above a receiver's horizon.

    integral over the cap of max(0, n . w) dw, for a cap of half-angle sigma whose centre makes
    the angle theta with the normal n: pi sin^2(sigma) cos(theta) while the cap is wholly above
    the horizon (cos^2 theta > sin^2 sigma), else the closed form of the clipped cap (Snyder,
    "Area light sources for real-time graphics", Microsoft Research TR-96-11, 1996, as written
    in Lagarde & de Rousiers, "Moving Frostbite to physically based rendering", 2014, sec. 4.7.2).

    Parameters
    ----------
    cos_theta : ndarray, shape (K,)
    sin2_sigma : ndarray, shape (K,)
        sin^2 of the cap's half-angle, in (0, 1].

    Returns
    -------
    ndarray, shape (K,)
    """
    cos_theta = np.clip(cos_theta, -1.0, 1.0)
    sin2_sigma = np.clip(sin2_sigma, 1e-300, 1.0)
    whole = np.pi * sin2_sigma * np.maximum(cos_theta, 0.0)
    partial = cos_theta * cos_theta <= sin2_sigma
    if not partial.any():
        return whole
    c, s2 = cos_theta[partial], sin2_sigma[partial]
    sin_theta = np.sqrt(np.maximum(1.0 - c * c, 1e-300))
    x = np.sqrt(np.maximum(1.0 / s2 - 1.0, 0.0))
    y = np.clip(-x * c / sin_theta, -1.0, 1.0)
    root = sin_theta * np.sqrt(1.0 - y * y)
    clipped = (c * np.arccos(y) - x * root) * s2 + np.arctan2(root, x)
    out = whole.copy()
    out[partial] = np.maximum(clipped, 0.0)
    return out


def cap_probes(axis, cos_sigma):
    """The cap's centre and CAP_PROBE directions evenly spaced on its rim, shape (K, 1 + CAP_PROBE, 3)."""
    e1, e2 = _frame(axis)
    phi = 2.0 * np.pi * np.arange(CAP_PROBE) / CAP_PROBE
    sin_s = np.sqrt(np.maximum(1.0 - cos_sigma * cos_sigma, 0.0))[:, None, None]
    rim = cos_sigma[:, None, None] * axis[:, None] + sin_s * (
        np.cos(phi)[None, :, None] * e1[:, None] + np.sin(phi)[None, :, None] * e2[:, None]
    )
    return np.concatenate([axis[:, None], rim], axis=1)


def _frame(axis):
    """Two unit vectors completing unit axes (K, 3) to orthonormal frames, shapes (K, 3)."""
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(axis, e1)


def cap_directions(axis, cos_sigma, count=None):
    """`count` (default CAP_SAMPLES) unit directions of equal solid angle in the cap about each
    axis, shape (K, S, 3).

    A Fibonacci spiral: cos(gamma_i) = 1 - (1 - cos sigma)(i + 1/2) / S, azimuths by the golden
    angle, about unit axes (K, 3) with the caps' cos(sigma) (K,).
    """
    e1, e2 = _frame(axis)
    count = CAP_SAMPLES if count is None else count
    i = np.arange(count)
    cos_g = 1.0 - (1.0 - cos_sigma[:, None]) * (i + 0.5)[None] / count  # (K, S)
    sin_g = np.sqrt(np.maximum(1.0 - cos_g * cos_g, 0.0))
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return (
        cos_g[..., None] * axis[:, None]
        + (sin_g * np.cos(phi))[..., None] * e1[:, None]
        + (sin_g * np.sin(phi))[..., None] * e2[:, None]
    )


class PointLight:
    """A point light (optionally with a radius for soft shadows).

    Parameters
    ----------
    position : array_like, shape (3,)
    intensity : float or array_like, shape (3,)
        Radiant intensity (W/sr).
    radius : float
        Radius (m) of the emitting ball, >= 0.
    soft_falloff : bool
        Cycles' "Soft Falloff" (its default): the light is a disk of that radius facing each
        receiver, of the same intensity along its axis (irradiance I / (d^2 + r^2) straight
        below it instead of the sphere's I / d^2), as Blender before 4.0 rendered every point light.
    """

    kind = "point"

    def __init__(self, position, intensity, radius=0.0, name=None, soft_falloff=False):
        self.position = checks.point(position, "light position")
        self.soft_falloff = checks.flag(soft_falloff, "soft_falloff")
        self.intensity = checks.rgb(intensity, "light intensity")
        self.radius = checks.non_negative(radius, "light radius")
        if self.radius > checks.MAX_COORDINATE:
            raise ValueError(
                f"light radius must be at most {checks.MAX_COORDINATE:.0e} m, got {self.radius!r}"
            )
        self.name = name

    @property
    def power(self):
        """The quantity `set_light` scales: intensity (W/sr, shape (3,))."""
        return self.intensity

    def geometry_key(self):
        return ("point", tuple(self.position), self.radius, self.soft_falloff)

    def targets(self, x, n, scale):
        """Shadow-ray ends toward the light from points x (normals n, (K, 3)).

        Returns
        -------
        ends : ndarray, shape (K, S, 3)
            The centre (radius 0), else CAP_SAMPLES points on the sphere, one per direction of
            equal solid angle in the cap it subtends.
        weights : ndarray, shape (K, S)
            Each ray's share of the unshadowed irradiance (cosine-weighted; rows sum to 1 where lit).
        centre : ndarray, shape (K, 3)
        radius : ndarray, shape (K,)
            A ball holding each point's ends (for the shaft test).
        probes : ndarray, shape (K, P, 3), or None
            Ends of the probe rays (`cap_probes`) of a light with an extent.
        """
        toward = self.position - x
        centre = np.broadcast_to(self.position, x.shape)
        if self.radius <= 0:
            return centre[:, None], np.ones((len(x), 1)), centre, np.zeros(len(x)), None
        d = np.linalg.norm(toward, axis=-1)
        axis = toward / np.maximum(d, 1e-300)[:, None]
        cos_sigma = np.sqrt(1.0 - self._sin2_sigma(d * d))
        w = cap_directions(axis, cos_sigma)
        probes = self._on_sphere(x, d, axis, cap_probes(axis, cos_sigma))
        ends = self._on_sphere(x, d, axis, w)
        return ends, _cosine_weights(w, n), centre, np.full(len(x), self.radius), probes

    def _sin2_sigma(self, d2):
        """sin^2 of the half-angle of the cap the light subtends at squared distances d2 (K,)."""
        r2 = self.radius**2
        if self.soft_falloff:
            return r2 / (d2 + r2)  # a facing disk: tan(sigma) = r / d
        return np.minimum(r2 / np.maximum(d2, 1e-300), 1.0)

    def _on_sphere(self, x, d, axis, w):
        """Where directions w (K, S, 3) from x first meet the light's sphere (its rim: tangent),
        or with soft falloff its disk facing x."""
        cos_g = np.einsum("ksi,ki->ks", w, axis)
        if self.soft_falloff:
            return x[:, None] + (d[:, None] / np.maximum(cos_g, 1e-300))[..., None] * w
        # at distance t = d cos(g) - sqrt(r^2 - d^2 sin^2(g)), g the angle from the axis
        t = d[:, None] * cos_g - np.sqrt(np.maximum(self.radius**2 - (d**2)[:, None] * (1.0 - cos_g**2), 0.0))
        return x[:, None] + np.maximum(t, 0.0)[..., None] * w

    def profile(self, away):
        """Fraction of the intensity sent in directions `away` (K, 3): 1 for a point light."""
        return 1.0

    def unshadowed(self, x, n):
        """Irradiance per unit intensity, shape (K,): cos(theta) / d^2 (times the spot profile),
        for a sphere light its cap's clipped irradiance (`cap_irradiance`) / (pi r^2)."""
        toward = self.position - x
        d2 = np.einsum("ki,ki->k", toward, toward)
        cos = np.einsum("ki,ki->k", toward, n)
        if self.radius > 0:
            d = np.sqrt(d2)
            value = cap_irradiance(cos / np.maximum(d, 1e-300), self._sin2_sigma(d2)) / (
                np.pi * self.radius**2
            )
            if not self.soft_falloff:
                value = np.where(d > self.radius, value, 1.0 / self.radius**2)  # inside: all of it
            return value * self.profile(-toward)
        ok = (cos > 0) & (d2 > 0)
        d2s = np.where(ok, d2, 1.0)
        return np.where(ok, cos / (d2s * np.sqrt(d2s)), 0.0) * self.profile(-toward)


class SpotLight(PointLight):
    """A spot light: a point light cut by a cone of full angle `spot_size` with soft edge `spot_blend`."""

    kind = "spot"

    def __init__(
        self, position, direction, intensity, spot_size, spot_blend, radius=0.0, name=None, soft_falloff=False
    ):
        super().__init__(position, intensity, radius, name, soft_falloff)
        self.direction = checks.direction(direction, "spot direction")
        size = checks.scalar(spot_size, "spot_size")
        blend = checks.scalar(spot_blend, "spot_blend")
        if not (0 < size <= np.pi + 1e-12):
            raise ValueError(f"spot_size must be in (0, pi], got {size}")
        if not (0 <= blend <= 1):
            raise ValueError(f"spot_blend must be in [0, 1], got {blend}")
        self.spot_size, self.spot_blend = size, blend

    def geometry_key(self):
        return (
            "spot",
            tuple(self.position),
            self.radius,
            tuple(self.direction),
            self.spot_size,
            self.spot_blend,
        )

    def profile(self, away):
        """Cycles' spot attenuation for directions `away` from the light, shape (K,)."""
        length = np.linalg.norm(away, axis=-1)
        cos = np.divide(away @ self.direction, length, out=np.ones(len(away)), where=length > 0)
        edge = np.cos(0.5 * self.spot_size)
        smooth = (1.0 - edge) * self.spot_blend
        inside = cos > edge
        if smooth <= 0:
            return inside.astype(np.float64)
        t = np.clip((cos - edge) / smooth, 0.0, 1.0)
        return np.where(inside, t * t * (3.0 - 2.0 * t), 0.0)


class SunLight:
    """A distant light: irradiance (W/m^2) on a plane facing it, travelling along `direction`.

    angle : float
        Angular diameter (radians, Cycles' `angle`), in [0, pi): a disk of directions of
        uniform radiance irradiance / (pi sin^2(angle / 2)).
    """

    kind = "sun"

    def __init__(self, direction, irradiance, angle=0.0, name=None):
        self.direction = checks.direction(direction, "sun direction")
        self.irradiance = checks.rgb(irradiance, "sun irradiance")
        self.angle = checks.non_negative(angle, "sun angle")
        if self.angle >= np.pi:
            raise ValueError(f"sun angle (angular diameter) must be below pi, got {self.angle!r}")
        self.radius = 0.0
        self.name = name

    @property
    def power(self):
        return self.irradiance

    def geometry_key(self):
        return ("sun", tuple(self.direction), self.angle)

    def targets(self, x, n, scale):
        """Far points up-sun of each point (beyond the scene): one, or CAP_SAMPLES directions of
        equal solid angle in the sun's disk; shapes (K, S, 3), weights (K, S) (see PointLight)."""
        far = 4.0 * scale
        centre = x - far * self.direction
        if self.angle <= 0:
            return centre[:, None], np.ones((len(x), 1)), centre, np.zeros(len(x)), None
        axis = np.ascontiguousarray(np.broadcast_to(-self.direction, x.shape))
        cos_sigma = np.full(len(x), np.cos(0.5 * self.angle))
        w = cap_directions(axis, cos_sigma)
        radius = np.full(len(x), 2.0 * far * np.sin(0.25 * self.angle) * (1.0 + 1e-9))
        probes = x[:, None] + far * cap_probes(axis, cos_sigma)
        return x[:, None] + far * w, _cosine_weights(w, n), centre, radius, probes

    def unshadowed(self, x, n):
        """Irradiance per unit irradiance, shape (K,): cos(theta), or for a disk its clipped cap's
        cosine-weighted solid angle / (pi sin^2(angle / 2)) (`cap_irradiance`)."""
        cos = -(n @ self.direction)
        if self.angle <= 0:
            return np.maximum(0.0, cos)
        sin2 = np.full(len(x), np.sin(0.5 * self.angle) ** 2)
        return cap_irradiance(cos, sin2) / (np.pi * sin2)


def _cosine_weights(w, n):
    """Shares max(0, n . w_s) / sum_s max(0, n . w_s) of directions w (K, S, 3) at normals n (K, 3);
    equal shares where none is above the horizon, shape (K, S)."""
    cos = np.maximum(np.einsum("ksi,ki->ks", w, n), 0.0)
    total = cos.sum(1, keepdims=True)
    return np.where(total > 0, cos / np.where(total > 0, total, 1.0), 1.0 / w.shape[1])
