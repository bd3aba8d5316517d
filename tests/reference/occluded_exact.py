"""Exact occluded references that share no code with core/: a ceiling over an emitting floor past a sphere.

For a point x whose view of a sphere lies wholly above its horizon and whose shadow of the
sphere on a plane rectangle lies wholly inside the rectangle, the visible factor of the rectangle
is F(x -> rectangle) - F(x -> sphere): Lambert's polygon formula (Lambert 1760; e.g. Baum,
Rushmeier & Winget, SIGGRAPH 1989, eq. 4) minus (r/d)^2 cos(gamma) (element to a sphere wholly
above its horizon: Siegel & Howell, Thermal Radiation Heat Transfer, app. C). Both are analytic in
x, so a patch mean by a 12 x 12 Gauss-Legendre rule is exact to ~1e-12.
"""

import numpy as np


def _lambert(x, n, polygon):
    """F(dA(x) -> convex polygon wholly above the horizon), Lambert's formula, shape (K,)."""
    r = polygon[None] - x[:, None]
    r2 = np.roll(r, -1, 1)
    c = np.cross(r, r2)
    angle = np.arctan2(np.linalg.norm(c, axis=-1), np.einsum("kvi,kvi->kv", r, r2))
    unit = c / np.linalg.norm(c, axis=-1, keepdims=True)
    return np.abs(np.einsum("kv,kv->k", angle, np.einsum("kvi,ki->kv", unit, n))) / (2 * np.pi)


def _shadow_inside(x, center, radius, half):
    """True where the sphere's tangent cone from x meets the floor z = 0 inside |x|, |y| < half."""
    d = center - x
    dist = np.linalg.norm(d, axis=1)
    a = d / dist[:, None]
    s = radius / dist
    c = np.sqrt(1 - s * s)
    p = np.cross(a, [1.0, 0.0, 0.0])
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    q = np.cross(a, p)
    ok = np.ones(len(x), bool)
    for t in np.linspace(0, 2 * np.pi, 97):
        direction = c[:, None] * a + s[:, None] * (np.cos(t) * p + np.sin(t) * q)
        y = x - (x[:, 2] / direction[:, 2])[:, None] * direction
        ok &= (direction[:, 2] < 0) & (np.abs(y[:, 0]) < half - 0.05) & (np.abs(y[:, 1]) < half - 0.05)
    return ok


def open_cube_reference(side, rho, center, radius, m, order=12):
    """Ceiling patch values (u along y, v along x), NaN where the closed form does not hold."""
    half = side / 2
    floor = np.array([(-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)], float)
    t, w = np.polynomial.legendre.leggauss(order)
    weight = np.outer(w, w).ravel() / 4
    step = side / m
    out = np.full(m * m, np.nan)
    for i in range(m):
        for j in range(m):
            ys, xs = -half + (i + 0.5 * (t + 1)) * step, -half + (j + 0.5 * (t + 1)) * step
            X, Y = np.meshgrid(xs, ys, indexing="ij")
            x = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, side)])
            n = np.tile([0.0, 0.0, -1.0], (len(x), 1))
            if not _shadow_inside(x, center, radius, half).all():
                continue
            d = center - x
            dist = np.linalg.norm(d, axis=1)
            sphere = np.einsum("ki,ki->k", d, n) / dist * radius**2 / dist**2
            out[i * m + j] = rho * (weight * (_lambert(x, n, floor) - sphere)).sum()
    return out, np.zeros(m * m)
