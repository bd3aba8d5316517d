"""Whether a NURBS net is exactly a whole ellipsoid (a sphere under an affine map), and which.

A NURBS sphere or ellipsoid (Piegl & Tiller, "The NURBS Book", ch. 8: a revolved rational
semicircle, under any affine map, knot insertion or degree elevation) is, to the light, the same
surface as the `Sphere` primitive: the exact kernels for whole ellipsoids (the contour of the part
a point sees, `ellipsoid.whole_ellipsoid`; F = 1, 0 or a lune from inside or on it; exact shadows
through round cones, `cones`) apply to it whatever its parametrisation, and it is convex (it
never occludes its own patches). This module proves the identity.

In the net's local frame x = (P - origin) / scale, with w the rational denominator, on one knot
span of degrees (p, q), both w x and w are polynomials of degrees (p, q); for an ellipsoid
E = {c + L t : |t| = 1}, w^2 (|L^-1 (x - c)|^2 - 1) is then a polynomial of degrees (2p, 2q),
so it vanishes on the whole span when it vanishes on a (2p + 1) x (2q + 1) grid. So:

1. fit the quadric through such grids on every span (the null vector of the monomials'
   matrix, by SVD); it must be unique and an ellipsoid, and every sample must lie on it to
   ON_QUADRIC (rounding: the grid equality then holds as polynomials);
2. the net must be closed: each edge of the parameter box is a single point (a pole) or
   coincides with the opposite edge (a seam), at the same grid of samples (a polynomial
   identity again), so the map from the closed box to the ellipsoid has a degree;
3. it must cover the ellipsoid once: in t = L^-1 (x - c) (the unit sphere) the signed area
   integral of t . (t_u x t_v) (4 pi times the degree) and the unsigned area of |t_u x t_v| are
   both 4 pi to COVER_RTOL. Equal signed and unsigned areas mean the Jacobian keeps one
   sign, so with a degree of +-1 every point of the ellipsoid is covered exactly once.

Anything else (a sphere patch, a net covering part of a sphere twice, a torus, a surface whose
integrals do not settle) is not recognised and keeps the generic kernels.
"""

from dataclasses import dataclass

import numpy as np

from .quadrature import gauss_legendre

ON_QUADRIC = 1e-10  # |t|^2 - 1 allowed at the samples (local units: the net spans about 1)
COVER_RTOL = 1e-9  # the signed and unsigned areas of the unit-sphere image must be 4 pi to this
GAUSS_ORDERS = (8, 16, 32)  # Gauss-Legendre points per span and parameter, tried in turn
MAX_SAMPLES = 200_000  # nets with more samples than this are not examined


@dataclass(frozen=True)
class Ellipsoid:
    """The ellipsoid {center + linear t : |t| = 1} that a net covers once.

    Attributes
    ----------
    center : ndarray, shape (3,)
    linear : ndarray, shape (3, 3)
    outward : bool
        Whether dP/du x dP/dv points out of the ellipsoid.
    """

    center: np.ndarray
    linear: np.ndarray
    outward: bool


def exact_ellipsoid(geometry):
    """The `Ellipsoid` a `NurbsGeometry` is over its natural domain, or None (module docstring)."""
    su, sv = geometry.span_indices()
    nu, nv = 2 * geometry.order_u, 2 * geometry.order_v  # (2p + 2 points per span)
    if su.size * sv.size * nu * nv > MAX_SAMPLES:
        return None
    s, t = np.linspace(0.0, 1.0, nu), np.linspace(0.0, 1.0, nv)
    x, _, _ = _span_grid(geometry, su, sv, s, t)
    fit = _fit(x.reshape(-1, 3))
    if fit is None or not _closed(x):
        return None
    center, linear = fit
    inverse = np.linalg.inv(linear)
    last = None
    for n in GAUSS_ORDERS:
        rule = gauss_legendre(n)
        p, pu, pv = _span_grid(geometry, su, sv, rule.points, rule.points)
        local = (p - center) @ inverse.T
        normal = np.cross(pu @ inverse.T, pv @ inverse.T)
        weight = np.multiply.outer(rule.weights, rule.weights)
        signed = (np.einsum("...k,...k->...", local, normal) * weight).sum()
        unsigned = (np.linalg.norm(normal, axis=-1) * weight).sum()
        if last is not None:
            settled = max(abs(signed - last[0]), abs(unsigned - last[1])) <= 0.1 * COVER_RTOL * 4 * np.pi
            if settled:
                break
        last = (signed, unsigned)
    else:
        return None
    once = abs(abs(signed) - 4 * np.pi) <= COVER_RTOL * 4 * np.pi
    if not (once and abs(unsigned - 4 * np.pi) <= COVER_RTOL * 4 * np.pi):
        return None
    # signed is in t; in the world dP/du x dP/dv . (P - c) carries det(linear) too
    outward = signed * np.linalg.det(linear) > 0
    world_center = geometry.origin + geometry.scale * center
    return Ellipsoid(world_center, geometry.scale * linear, bool(outward))


def _span_grid(geometry, su, sv, s, t):
    """Local points and derivatives (per unit of each span's parameters) on every span's grid.

    Returns
    -------
    x, xs, xt : ndarray, shape (U, V, len(s), len(t), 3)
        U x V spans.
    """
    U, V, m, n = su.size, sv.size, s.size, t.size
    shape = (U, V, m, n)
    span_u = np.broadcast_to(su[:, None, None, None], shape).ravel()
    span_v = np.broadcast_to(sv[None, :, None, None], shape).ravel()
    hu = (geometry.knots_u[su + 1] - geometry.knots_u[su])[:, None, None, None]
    hv = (geometry.knots_v[sv + 1] - geometry.knots_v[sv])[None, :, None, None]
    offset_u = np.broadcast_to(hu * s[None, None, :, None], shape).ravel()
    offset_v = np.broadcast_to(hv * t[None, None, None, :], shape).ravel()
    width_u = np.broadcast_to(hu, shape).ravel()
    width_v = np.broadcast_to(hv, shape).ravel()
    x, xs, xt = geometry.local_derivatives(span_u, offset_u, width_u, span_v, offset_v, width_v)
    return (a.reshape(shape + (3,)) for a in (x, xs, xt))


def _fit(x):
    """(center, linear) of the one ellipsoid through the points x (K, 3), or None."""
    if len(x) < 10:
        return None
    X, Y, Z = x.T
    design = np.column_stack([X * X, Y * Y, Z * Z, X * Y, X * Z, Y * Z, X, Y, Z, np.ones_like(X)])
    _, sing, vt = np.linalg.svd(design, full_matrices=False)
    if not (sing[-1] <= 1e-8 * sing[0] and sing[-2] > 1e-6 * sing[0]):
        return None  # no quadric, or a pencil of them (planes, lines)
    a = vt[-1]
    A = np.array([[a[0], a[3] / 2, a[4] / 2], [a[3] / 2, a[1], a[5] / 2], [a[4] / 2, a[5] / 2, a[2]]])
    eigen = np.linalg.eigvalsh(A)
    # (definite by a margin: a cylinder's quadric has an eigenvalue that is zero to rounding)
    if eigen[0] * eigen[-1] <= 0 or np.abs(eigen).min() <= 1e-9 * np.abs(eigen).max():
        return None
    if eigen[0] < 0:
        A, a = -A, -a
    center = np.linalg.solve(A, -0.5 * a[6:9])
    rho = center @ A @ center - a[9]
    if not rho > 0:
        return None
    values, vectors = np.linalg.eigh(A / rho)
    linear = vectors / np.sqrt(values)
    local = (x - center) @ np.linalg.inv(linear).T
    if np.abs(np.einsum("ki,ki->k", local, local) - 1.0).max() > ON_QUADRIC:
        return None
    return center, linear


def _closed(x):
    """Whether each edge of the sampled box (U, V, m, n, 3) is a pole or the opposite edge."""
    first_u, last_u = x[0, :, 0], x[-1, :, -1]  # u = u0 and u = u1: shape (V, n, 3)
    first_v, last_v = x[:, 0, :, 0], x[:, -1, :, -1]  # v = v0 and v = v1: shape (U, m, 3)

    def pole(edge):
        return np.abs(edge - edge.reshape(-1, 3)[0]).max() <= ON_QUADRIC

    def seam(a, b):
        return np.abs(a - b).max() <= ON_QUADRIC

    return all(seam(a, b) or (pole(a) and pole(b)) for a, b in ((first_u, last_u), (first_v, last_v)))
