"""F(dA1 -> cell) by the contour of the cell's boundary, for cells a point sees wholly, front on.

For a point x1 with unit normal n1 and a smooth piece S of a surface with front normal n2,
the kernel n1.R (-n2.R) / (pi |R|^4), R = y - x1, is the flux through S of the divergence-free
field -(n1.R) R / (pi |R|^4), which is the curl of -(n1 x R) / (2 pi |R|^2) away from x1. By
Stokes' theorem, for any S not containing x1,

    integral over S of n1.R (-n2.R) / (pi |R|^4) dA = -1/(2 pi) contour integral of n1 . (R x dR) / |R|^2

around the boundary of S, oriented with n2 (counter-clockwise seen from the front). The
*clipped* kernel (both cosines positive) is this smooth one on S when every point of S is above
x1's horizon (n1.R > 0) and faces x1 (n2.R < 0): then the form factor F(dA1 -> S) depends on
S's boundary only. This is Lambert's formula for polygons and Sparrow's contour method for any
surface (E. M. Sparrow, "A new and simpler formulation for radiative angle factors", J. Heat
Transfer 85 (1963) 81-88; Siegel & Howell, "Thermal Radiation Heat Transfer", the contour
integral method of the configuration-factor chapter).

A dyadic cell's boundary is the image of its parameter box's four edges. Along each edge the
integrand is analytic where x1 is off the curve, so Gauss-Legendre rules converge
geometrically, at a rate set by the edge's length over its distance to x1. Each cell's edges
are sampled once at the nodes of two Gauss-Legendre orders (`ORDERS`; shared by every point that
integrates over the cell, as the line samples of `cellrule.CellCache`); the finer order's sum is
the value. Its error estimate follows QUADPACK's rule for a pair of embedded rules (Piessens,
de Doncker-Kapenga, Ueberhuber & Kahaner, "QUADPACK", Springer 1983, routine QK15): with d the
difference of the two orders and M the integral of |integrand| (by the finer rule),
error = max(d min(1, (200 d / M)^1.5), 50 eps M): the finer rule converges at about twice the
rate of the coarser, so d alone would overstate its error by many orders. Poles (edges of zero
length) add nothing: their tangents vanish.

Whether a point sees a cell wholly and front on is decided by the caller from bounds
(`bounds.facing_code`, `bounds.cone_code`); a cell for which that is not proved must not be
given to `contour_rule` (its value would be the integral of the unclipped kernel).
"""

import numpy as np

from .cellrule import KeyedCache
from .quadrature import gauss_legendre

ORDERS = (8, 16)  # Gauss-Legendre nodes per cell edge: error estimate, value
EDGES = 4
NODES = EDGES * sum(ORDERS)  # edge samples per cell


def _edge_parameters():
    """Parameters of the edge samples on the unit box, counter-clockwise, and their weights.

    Returns
    -------
    s, t : ndarray, shape (NODES,)
        Unit-box coordinates (u, v) of the samples: for each order in ORDERS, the edges
        v = 0 (u rising), u = 1 (v rising), v = 1 (u falling), u = 0 (v falling) in turn.
    du, dv : ndarray, shape (NODES,)
        d(s, t)/d(edge parameter) times the Gauss weight (so sum f(P) (Pu du + Pv dv) is the
        rule for the line integral of f dP over the unit box's boundary).
    order : ndarray of int, shape (NODES,)
        Index into ORDERS of each sample.
    """
    s, t, du, dv, order = [], [], [], [], []
    for k, n in enumerate(ORDERS):
        rule = gauss_legendre(n)
        a, w = rule.points, rule.weights
        one, zero = np.ones(n), np.zeros(n)
        s += [a, one, 1.0 - a, zero]
        t += [zero, a, one, 1.0 - a]
        du += [w, zero, -w, zero]
        dv += [zero, w, zero, -w]
        order += [np.full(EDGES * n, k)]
    return tuple(np.concatenate(x) for x in (s, t, du, dv, order))


EDGE_S, EDGE_T, EDGE_DU, EDGE_DV, EDGE_ORDER = _edge_parameters()


class EdgeCache(KeyedCache):
    """Boundary samples of target cells for `contour_rule`, computed on first use.

    Per cell row: `points` (NODES, 3), the surface at the edge samples, and `steps` (NODES, 3),
    the weighted tangents (dP/du du + dP/dv dv) w, signed so that the boundary runs
    counter-clockwise about the patch's front normal, in parameter units of the cell's box.

    Parameters
    ----------
    surfaces : SurfaceSet
    """

    def __init__(self, surfaces):
        super().__init__(surfaces)
        self.points = np.zeros((0, NODES, 3))
        self.steps = np.zeros((0, NODES, 3))

    def _grow(self, needed):
        capacity = self.points.shape[0]
        if needed <= capacity:
            return
        capacity = max(needed, 2 * capacity, 256)
        for name in ("points", "steps"):
            old = getattr(self, name)
            new = np.zeros((capacity,) + old.shape[1:])
            new[: self.size] = old[: self.size]
            setattr(self, name, new)

    def _fill(self, rows, patch, lu, lv, i, j):
        """Sample the boundaries of new cells into `rows`."""
        box = self.surfaces.cell_boxes(patch, lu, lv, i, j)
        width, height = box[:, 1] - box[:, 0], box[:, 3] - box[:, 2]
        u = box[:, :1] + width[:, None] * EDGE_S
        v = box[:, 2:3] + height[:, None] * EDGE_T
        index = np.repeat(patch, NODES)
        P, Pu, Pv = self.surfaces.derivatives(index, u.ravel(), v.ravel())
        self.evaluations += u.size
        # the front normal is orientation * (Pu x Pv): a reversed front reverses the boundary
        sign = self.surfaces.orientation[patch]
        scale_u = (sign * width)[:, None] * EDGE_DU
        scale_v = (sign * height)[:, None] * EDGE_DV
        steps = Pu.reshape(-1, NODES, 3) * scale_u[..., None] + Pv.reshape(-1, NODES, 3) * scale_v[..., None]
        self.points[rows] = P.reshape(-1, NODES, 3)
        self.steps[rows] = steps


def contour_rule(x1, n1, points, steps):
    """F(dA1 -> cell) by the boundary contour, at the two orders of ORDERS.

    Valid only for cells that every point sees wholly above its horizon and front on (see the
    module docstring); the caller proves that.

    Parameters
    ----------
    x1, n1 : ndarray, shape (K, 3)
        Points and unit normals.
    points, steps : ndarray, shape (K, NODES, 3)
        Each point's target cell's boundary samples (`EdgeCache`).

    Returns
    -------
    value, error : ndarray, shape (K,)
        The values by the finer order of ORDERS and their error estimates (module docstring).
    """
    R = points - x1[:, None, :]
    # n1 . (R x dR) as the triple product det[n1, R, dR]
    cross = np.empty_like(R)
    cross[..., 0] = R[..., 1] * steps[..., 2] - R[..., 2] * steps[..., 1]
    cross[..., 1] = R[..., 2] * steps[..., 0] - R[..., 0] * steps[..., 2]
    cross[..., 2] = R[..., 0] * steps[..., 1] - R[..., 1] * steps[..., 0]
    numerator = np.einsum("ki,kni->kn", n1, cross)
    L2 = np.einsum("kni,kni->kn", R, R)
    f = numerator / np.where(L2 > 0.0, L2, 1.0)
    split = EDGES * ORDERS[0]
    coarse = f[:, :split].sum(1) * (-0.5 / np.pi)
    fine = f[:, split:].sum(1) * (-0.5 / np.pi)
    return fine, quadpack_error(np.abs(fine - coarse), np.abs(f[:, split:]).sum(1) * (0.5 / np.pi))


def quadpack_error(difference, magnitude):
    """QUADPACK's error estimate of the finer of two rules (QK15), shape (K,).

    Parameters
    ----------
    difference : ndarray, shape (K,)
        |finer - coarser|.
    magnitude : ndarray, shape (K,)
        The integral of |integrand| (its scale, for the rounding floor and the rate).
    """
    eps = np.finfo(np.float64).eps
    ratio = np.divide(200.0 * difference, magnitude, out=np.ones_like(difference), where=magnitude > 0)
    return np.maximum(difference * np.minimum(1.0, ratio**1.5), 50.0 * eps * magnitude)
