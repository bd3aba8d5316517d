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
