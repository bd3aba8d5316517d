"""Point, spot and sun lights: direct irradiance with shadows, in Cycles' conventions.

- Point light: radiant intensity I (W/sr, RGB) in every direction; irradiance I cos(theta) / d^2.
- Spot light: a point light cut by a cone about `direction` (Cycles: the cone never concentrates
  the light) with Cycles' soft edge smoothstep((cos(phi) - cos(size / 2)) / ((1 - cos(size / 2))
  * blend)), phi the angle from the axis.
- Sun light: irradiance E (W/m^2, RGB) on a plane facing it, arriving along `direction` (the
  direction the light travels).
A light's `radius` (point, spot) softens its shadows: visibility is averaged over points of the
disk of that radius facing the receiver.
"""

import numpy as np

from . import checks

SOFT_SAMPLES = 8  # points on the disk of a light with a radius (plus its centre)


class PointLight:
    """A point light (optionally with a radius for soft shadows).

    Parameters
    ----------
    position : array_like, shape (3,)
    intensity : float or array_like, shape (3,)
        Radiant intensity (W/sr).
    radius : float
        Radius (m) of the emitting ball, >= 0.
    """

    kind = "point"

    def __init__(self, position, intensity, radius=0.0, name=None):
        self.position = checks.point(position, "light position")
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
        return ("point", tuple(self.position), self.radius)

    def targets(self, x, scale):
        """Sample points toward the light from each point, shape (K, S, 3), and their ball radius."""
        return _disk_samples(x, self.position, self.radius), self.radius

    def profile(self, away):
        """Fraction of the intensity sent in directions `away` (K, 3): 1 for a point light."""
        return 1.0

    def unshadowed(self, x, n):
        """Irradiance per unit intensity, cos(theta) / d^2 (times the spot profile), shape (K,)."""
        toward = self.position - x
        d2 = np.einsum("ki,ki->k", toward, toward)
        cos = np.einsum("ki,ki->k", toward, n)
        ok = (cos > 0) & (d2 > 0)
        d2s = np.where(ok, d2, 1.0)
        return np.where(ok, cos / (d2s * np.sqrt(d2s)), 0.0) * self.profile(-toward)


class SpotLight(PointLight):
    """A spot light: a point light cut by a cone of full angle `spot_size` with soft edge `spot_blend`."""

    kind = "spot"

    def __init__(self, position, direction, intensity, spot_size, spot_blend, radius=0.0, name=None):
        super().__init__(position, intensity, radius, name)
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
    """A distant light: irradiance (W/m^2) on a plane facing it, travelling along `direction`."""

    kind = "sun"

    def __init__(self, direction, irradiance, name=None):
        self.direction = checks.direction(direction, "sun direction")
        self.irradiance = checks.rgb(irradiance, "sun irradiance")
        self.radius = 0.0
        self.name = name

    @property
    def power(self):
        return self.irradiance

    def geometry_key(self):
        return ("sun", tuple(self.direction))

    def targets(self, x, scale):
        """A far point up-sun of each point (beyond the scene), shape (K, 1, 3)."""
        return (x - 4.0 * scale * self.direction)[:, None], 0.0

    def unshadowed(self, x, n):
        """cos(theta) per unit irradiance, shape (K,)."""
        return np.maximum(0.0, -(n @ self.direction))


def _disk_samples(x, center, radius):
    """Points toward the light from each x, shape (K, S, 3): its centre for radius 0, else
    SOFT_SAMPLES equal-area points of the disk of that radius facing x."""
    K = len(x)
    if radius <= 0:
        return np.broadcast_to(center, (K, 1, 3))
    axis = x - center
    axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(axis, e1)
    # equal-area rings: radii sqrt((i + 0.5) / S) on a golden-angle spiral
    i = np.arange(SOFT_SAMPLES)
    r = radius * np.sqrt((i + 0.5) / SOFT_SAMPLES)
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    offsets = r[None, :, None] * (
        np.cos(phi)[None, :, None] * e1[:, None] + np.sin(phi)[None, :, None] * e2[:, None]
    )
    return center[None, None] + offsets
