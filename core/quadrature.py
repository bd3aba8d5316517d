"""Quadrature rules as data: nodes, weights, the degree they integrate exactly, and their source.

Rules live on the unit interval [0, 1] (weights sum to 1), so a cell [a, b] maps by
x = a + (b - a) t with weight (b - a) w.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class Rule1D:
    """A one-dimensional quadrature rule on [0, 1].

    Attributes
    ----------
    points : ndarray, shape (n,)
        Nodes in (0, 1), increasing.
    weights : ndarray, shape (n,)
        Positive weights summing to 1.
    degree : int
        Highest polynomial degree integrated exactly.
    source : str
        Where the rule comes from.
    """

    points: np.ndarray
    weights: np.ndarray
    degree: int
    source: str

    @property
    def size(self):
        return self.points.size


@lru_cache(maxsize=None)
def gauss_legendre(n):
    """The n-point Gauss-Legendre rule on [0, 1] (degree 2n - 1).

    Nodes and weights come from `numpy.polynomial.legendre.leggauss` (the Golub-Welsch
    eigenvalue method), mapped from [-1, 1]; nothing is typed in by hand.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"Gauss-Legendre order must be a positive integer, got {n!r}")
    x, w = np.polynomial.legendre.leggauss(int(n))
    points = 0.5 * (x + 1.0)
    weights = 0.5 * w
    points.setflags(write=False)
    weights.setflags(write=False)
    return Rule1D(
        points,
        weights,
        2 * int(n) - 1,
        "Gauss-Legendre; Golub & Welsch (1969), Math. Comp. 23, via numpy.polynomial.legendre.leggauss",
    )


@lru_cache(maxsize=None)
def tensor_rule(n_u, n_v=None):
    """Tensor product of Gauss-Legendre rules on the unit square.

    Returns
    -------
    s, t, w : ndarray, each shape (n_u * n_v,)
        Nodes (s along u, t along v, t running fastest) and weights summing to 1.
    """
    n_v = n_u if n_v is None else n_v
    ru, rv = gauss_legendre(n_u), gauss_legendre(n_v)
    s = np.repeat(ru.points, rv.size)
    t = np.tile(rv.points, ru.size)
    w = np.outer(ru.weights, rv.weights).ravel()
    for a in (s, t, w):
        a.setflags(write=False)
    return s, t, w


# QUADPACK's qk15 abscissae (x >= 0, the Gauss-7 nodes at odd positions) and weights on [-1, 1]:
# R. Piessens, E. de Doncker-Kapenga, C. W. Ueberhuber and D. K. Kahaner, "QUADPACK: a subroutine
# package for automatic integration", Springer (1983), routine QK15. tests/test_quadrature.py
# checks the claimed degrees and that the Gauss part equals leggauss(7).
_KRONROD_15_X = (
    0.991455371120812639206854697526329,
    0.949107912342758524526189684047851,
    0.864864423359769072789712788640926,
    0.741531185599394439863864773280788,
    0.586087235467691130294144845693013,
    0.405845151377397166906606412076961,
    0.207784955007898467600689403773245,
    0.0,
)
_KRONROD_15_W = (
    0.022935322010529224963732008058970,
    0.063092092629978553290700663189204,
    0.104790010322250183839876322541518,
    0.140653259715525918745189590510238,
    0.169004726639267902826583426598550,
    0.190350578064785409913256402421014,
    0.204432940075298892414161999234649,
    0.209482141084727828012999174891714,
)
_GAUSS_7_W = (
    0.129484966168869693270611432679082,
    0.279705391489276667901467771423780,
    0.381830050505118944950369775488975,
    0.417959183673469387755102040816327,
)


@lru_cache(maxsize=None)
def gauss_kronrod_15():
    """The 15-point Gauss-Kronrod rule on [0, 1] and its embedded 7-point Gauss rule.

    Returns
    -------
    kronrod : Rule1D
        15 nodes, degree 22.
    gauss_weights : ndarray, shape (15,)
        Weights of the 7-point Gauss rule (degree 13) on the same nodes, zero at the 8 nodes
        that only the Kronrod rule uses: |kronrod - gauss| is QUADPACK's error estimate.
    """
    x = np.array(_KRONROD_15_X)
    w = np.array(_KRONROD_15_W)
    g = np.zeros(8)
    g[1::2] = _GAUSS_7_W
    # nodes -x (descending), 0, +x: increasing on [-1, 1]
    nodes = np.concatenate([-x[:-1], [0.0], x[:-1][::-1]])
    weights = np.concatenate([w[:-1], [w[-1]], w[:-1][::-1]])
    gauss = np.concatenate([g[:-1], [g[-1]], g[:-1][::-1]])
    points, weights, gauss = 0.5 * (nodes + 1.0), 0.5 * weights, 0.5 * gauss
    for a in (points, weights, gauss):
        a.setflags(write=False)
    source = "Gauss-Kronrod 7-15; Piessens et al., QUADPACK (Springer 1983), routine QK15"
    return Rule1D(points, weights, 22, source), gauss
