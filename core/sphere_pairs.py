"""Form factors between the outsides of two whole spheres, by their symmetry about the line of
centres: a one-dimensional integral over the source point's polar angle.

From a point x on sphere 1 (radius r1) with its outward normal n, the factor to sphere 2 (radius
r2, centre d away) depends only on mu = cos(theta), theta the angle between n and the direction
to sphere 2's centre, so (the axisymmetric reduction Juul integrates numerically: "Investigation
of approximate methods for calculation of the diffuse radiation configuration view factor between
two spheres", Lett. Heat Mass Transfer 3 (1976) 513-522)

    F12 = 1 / (4 pi r1^2) * integral over sphere 1 of F(x -> sphere 2) dA = 1/2 * integral_{-1}^{1} F(mu) dmu.

Sphere 2 lies wholly above x's horizon for mu >= (r1 + r2) / d, where F = r2^2 (d mu - r1) / rho^3,
rho^2 = d^2 + r1^2 - 2 d r1 mu (plane element to a sphere: Siegel & Howell's catalogue of
configuration factors); wholly below for mu <= (r1 - r2) / d (F = 0); between, x's horizon cuts
it and F(mu) is the exact contour of its visible part (`contour.sphere_patch`). Each piece is
smooth inside; the cut piece behaves algebraically at its ends, where the substitution
mu = mu0 + (mu1 - mu0) (1 - cos(pi s)) / 2 gathers Gauss points. Rules double until two agree to
the allowed error.
"""

import numpy as np

from .contour import sphere_patch
from .quadrature import gauss_legendre

FIRST_ORDER = 8  # Gauss points per piece of the first rule
MAX_ORDER = 4096  # the last rule tried (its difference from the one before is the error bound)
WHOLE = np.array([0.0, np.pi, 0.0, 2.0 * np.pi])  # sphere_patch's box of the whole sphere


def whole_sphere_factors(r1, r2, d, allowed):
    """F(sphere 1 -> sphere 2) between outsides of whole spheres that do not meet.

    Parameters
    ----------
    r1, r2 : ndarray, shape (P,)
        Radii of the source and target spheres (m).
    d : ndarray, shape (P,)
        Distance between their centres, d > r1 + r2.
    allowed : ndarray, shape (P,)
        Absolute error allowed in F.

    Returns
    -------
    F : ndarray, shape (P,)
    error : ndarray, shape (P,)
        The last two rules' difference (within `allowed` unless MAX_ORDER was reached).
    evaluations : int
        Point factors computed.
    """
    r1, r2, d, allowed = (np.asarray(t, dtype=np.float64) for t in (r1, r2, d, allowed))
    top = (r1 + r2) / d  # above this mu, sphere 2 is wholly above the horizon
    bottom = (r1 - r2) / d  # below this, wholly below
    F = np.zeros(d.size)
    error = np.full(d.size, np.inf)
    previous = np.full(d.size, np.nan)
    todo = np.arange(d.size)
    evaluations = 0
    order = FIRST_ORDER
    while todo.size and order <= MAX_ORDER:
        s, w = _rule(order)
        value = np.zeros(todo.size)
        for lo, hi, cut in ((top[todo], np.ones(todo.size), False), (bottom[todo], top[todo], True)):
            # mu = lo + (hi - lo) (1 - cos(pi s)) / 2 over s in [0, 1]
            half = 0.5 * (hi - lo)
            mu = lo[:, None] + half[:, None] * (1.0 - np.cos(np.pi * s))
            jacobian = half[:, None] * np.pi * np.sin(np.pi * s)
            f = _point_factor(r1[todo], r2[todo], d[todo], mu, cut)
            value += (f * jacobian * w).sum(1)
            evaluations += mu.size
        value *= 0.5
        error[todo] = np.abs(value - previous[todo])
        previous[todo] = F[todo] = value
        todo = todo[~(error[todo] <= allowed[todo])]
        order *= 2
    return F, error, evaluations


def _rule(order):
    """Gauss-Legendre points and weights on [0, 1], shape (order,) each."""
    rule = gauss_legendre(order)
    return rule.points, rule.weights


def _point_factor(r1, r2, d, mu, cut):
    """F(x(mu) -> sphere 2), shape (P, n), for mu (P, n): the closed form where sphere 2 is wholly
    above the horizon, the exact contour where the horizon cuts it (`cut`)."""
    r1, r2, d = r1[:, None], r2[:, None], d[:, None]
    if not cut:
        rho2 = d * d + r1 * r1 - 2.0 * d * r1 * mu
        return r2 * r2 * (d * mu - r1) / (rho2 * np.sqrt(rho2))
    sin = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    normal = np.stack([sin, np.zeros_like(mu), mu], -1)
    # x relative to sphere 2's centre (on the z axis, d away), in units of r2
    x = np.stack([r1 * sin, np.zeros_like(mu), r1 * mu - d], -1) / r2[..., None]
    x, normal = x.reshape(-1, 3), normal.reshape(-1, 3)
    F, _ = sphere_patch(x, normal, np.tile(WHOLE, (len(x), 1)), np.zeros(len(x), dtype=bool))
    return F.reshape(mu.shape)
