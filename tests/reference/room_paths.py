"""Independent reference for full light transport in a closed room: path tracing with exact ray tests.

Shares no code with core/. The room is the inside of an axis-aligned box, furnished with
axis-aligned boxes and spheres, all diffuse, lit by one axis-aligned rectangular lamp that faces
down (-z) and, as a Cycles light, neither blocks nor reflects. The outgoing radiance at a surface
point x is estimated by paths from x (Kajiya, "The rendering equation", SIGGRAPH 1986):
- at every vertex of a path, next-event estimation toward the lamp (a uniform point on the
  rectangle, its exact shadow ray against the boxes and spheres; the room is convex and the lamp
  inside it, so its walls never block);
- the path goes on along a cosine-distributed direction (Malley's method: a uniform point of the
  unit disk lifted to the hemisphere), which leaves the weight rho per bounce;
- Russian roulette after MIN_BOUNCES with survival probability rho (Arvo & Kirk, SIGGRAPH 1990),
  so the estimate is unbiased at every depth.
Ray tests written here: the slab method for boxes (Kay & Kajiya, SIGGRAPH 1986), the quadratic
for spheres, the exit distance for the room's inside. The error bar is the standard error of the
mean over independent paths.
"""

from dataclasses import dataclass, field

import numpy as np

MIN_BOUNCES = 3  # bounces before Russian roulette
OFFSET = 1e-6  # a path leaves its surface this far along the normal, relative to the room's size
# (points read from float32 data lie up to ~1e-7 inside a curved surface)


@dataclass
class Room:
    """A closed room [0, size] with furniture and one rectangular lamp facing -z.

    Attributes
    ----------
    size : tuple of 3 float
    reflectance : float
        Of the room's inside.
    lamp : tuple
        (centre (3,), extent (2,) along x and y, radiance L in W m^-2 sr^-1).
    boxes : list of tuple
        (low corner (3,), high corner (3,), reflectance).
    spheres : list of tuple
        (centre (3,), radius, reflectance).
    """

    size: tuple
    reflectance: float
    lamp: tuple
    boxes: list = field(default_factory=list)
    spheres: list = field(default_factory=list)

    def trace(self, o, d):
        """Nearest hit of rays o + t d (t > 0): points (K, 3), unit normals toward the ray (K, 3),
        reflectances (K,)."""
        K = len(o)
        rows = np.arange(K)
        size = np.asarray(self.size, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(d > 0, (size - o) / d, np.where(d < 0, -o / d, np.inf))
        axis = t.argmin(1)
        best = t[rows, axis]
        normal = np.zeros((K, 3))
        normal[rows, axis] = -np.sign(d[rows, axis])
        rho = np.full(K, float(self.reflectance))
        for lo, hi, r in self.boxes:
            near, box_axis = _slab(o, d, np.asarray(lo, float), np.asarray(hi, float))
            hit = near < best
            best = np.where(hit, near, best)
            n = np.zeros((K, 3))
            n[rows, box_axis] = -np.sign(d[rows, box_axis])
            normal = np.where(hit[:, None], n, normal)
            rho = np.where(hit, r, rho)
        for c, radius, r in self.spheres:
            c = np.asarray(c, dtype=float)
            s = _sphere(o, d, c, radius)
            hit = s < best
            best = np.where(hit, s, best)
            normal = np.where(hit[:, None], (o + s[:, None] * d - c) / radius, normal)
            rho = np.where(hit, r, rho)
        return o + best[:, None] * d, normal, rho

    def blocked(self, o, p):
        """Whether furniture blocks each segment o -> p, shape (K,)."""
        d = p - o
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        d = d / length[:, None]
        out = np.zeros(len(o), dtype=bool)
        for lo, hi, _ in self.boxes:
            near, _ = _slab(o, d, np.asarray(lo, float), np.asarray(hi, float))
            out |= near < length
        for c, radius, _ in self.spheres:
            out |= _sphere(o, d, np.asarray(c, dtype=float), radius) < length
        return out

    def direct(self, x, n, rng):
        """One-sample estimate of the irradiance from the lamp at points x with normals n, (K,)."""
        centre, extent, radiance = self.lamp
        centre, extent = np.asarray(centre, dtype=float), np.asarray(extent, dtype=float)
        K = len(x)
        p = centre + np.column_stack([(rng.random((K, 2)) - 0.5) * extent, np.zeros(K)])
        v = p - x
        d2 = np.einsum("ij,ij->i", v, v)
        distance = np.sqrt(d2)
        cos_x = np.maximum(np.einsum("ij,ij->i", n, v) / distance, 0.0)
        cos_lamp = np.maximum((p[:, 2] - x[:, 2]) / distance, 0.0)  # (the lamp faces -z)
        value = extent.prod() * radiance * cos_x * cos_lamp / d2
        live = np.flatnonzero(value > 0)
        offset = OFFSET * max(self.size)
        value[live[self.blocked(x[live] + offset * n[live], p[live])]] = 0.0
        return value


def _slab(o, d, lo, hi):
    """Entry distance of rays into a box (inf: missed or behind) and the entry axis."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    near = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2))
    far = np.where(np.isnan(t1), np.inf, np.maximum(t1, t2))
    axis = near.argmax(1)
    entry, leave = near.max(1), far.min(1)
    return np.where((entry <= leave) & (entry > 0.0), entry, np.inf), axis


def _sphere(o, d, c, radius):
    """First positive distance of unit rays to a sphere (inf: none)."""
    oc = o - c
    b = np.einsum("ij,ij->i", oc, d)
    disc = b * b - (np.einsum("ij,ij->i", oc, oc) - radius * radius)
    root = np.sqrt(np.maximum(disc, 0.0))
    t = np.where(-b - root > 0.0, -b - root, -b + root)
    return np.where((disc > 0.0) & (t > 0.0), t, np.inf)


def _cosine_directions(n, rng):
    K = len(n)
    r, phi = np.sqrt(rng.random(K)), 2.0 * np.pi * rng.random(K)
    helper = np.where(np.abs(n[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(n, helper)
    t /= np.linalg.norm(t, axis=1)[:, None]
    b = np.cross(n, t)
    up = np.sqrt(np.maximum(1.0 - r * r, 0.0))
    return (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * b + up[:, None] * n


def radiance(room, points, normals, reflectances, paths, seed=0, batch=20000):
    """Outgoing radiance at surface points (lamp light reflected, directly and after bounces).

    Parameters
    ----------
    points, normals : ndarray, shape (K, 3)
        Points on the room's surfaces and their unit normals (into the room).
    reflectances : ndarray, shape (K,)
    paths : int
        Paths per point.

    Returns
    -------
    mean, error : ndarray, shape (K,)
        The estimate and its standard error.
    """
    points, normals = np.asarray(points, dtype=float), np.asarray(normals, dtype=float)
    reflectances = np.broadcast_to(np.asarray(reflectances, dtype=float), len(points))
    rng = np.random.default_rng(seed)
    offset = OFFSET * max(room.size)
    K = len(points)
    total, square, done = np.zeros(K), np.zeros(K), 0
    while done < paths:
        N = min(batch, paths - done)
        x, n = np.repeat(points, N, 0), np.repeat(normals, N, 0)
        weight = np.repeat(reflectances, N) / np.pi  # (outgoing radiance: rho / pi irradiance)
        value = np.zeros(K * N)
        alive, depth = np.arange(K * N), 0
        while alive.size:
            xs, ns = x[alive], n[alive]
            value[alive] += weight[alive] * room.direct(xs, ns, rng)
            y, ny, rho = room.trace(xs + offset * ns, _cosine_directions(ns, rng))
            x[alive], n[alive] = y, ny
            weight[alive] *= rho  # (cosine sampling: the indirect integral's estimate is pi L)
            depth += 1
            if depth >= MIN_BOUNCES:
                survive = rng.random(alive.size) < rho
                weight[alive[survive]] /= rho[survive]
                alive = alive[survive]
        value = value.reshape(K, N)
        total += value.sum(1)
        square += (value * value).sum(1)
        done += N
    mean = total / done
    error = np.sqrt(np.maximum(square / done - mean * mean, 0.0) / done)
    return mean, error
