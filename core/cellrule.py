"""Cached samples of target cells and the line rule that integrates the kernel over them.

A dyadic cell (lu, lv, i, j) of a target patch is sampled once, on n lines at the Gauss-Legendre
abscissas across it, each with m Chebyshev-Lobatto points along it (both cell edges included).
Every point that integrates over the cell reuses those samples: surface evaluation, the costly
part for NURBS, is shared by all points instead of repeated per point.

Along a line the *unclipped* kernel g1 g2 / (pi L^4) is smooth; the clipped kernel is that smooth
function between the roots of g1 = n1 . e (the point's horizon) and g2 = n2 . (x1 - x2) (the
patch's silhouette). So each line integral is the integral, between the roots, of the polynomial
interpolating the unclipped kernel at the m samples ("product integration" with Chebyshev
antiderivatives; Clenshaw & Curtis 1960 when the line is whole); the roots come from the
interpolants of g1 and g2 by the Illinois method. Across lines the Gauss weights sum the line
integrals. The kink of the clipped kernel never falls inside a polynomial rule.
"""

import numpy as np
from numpy.polynomial import chebyshev

from .bounds import lengths, unit_vectors
from .quadrature import gauss_legendre

LINES = 6  # Gauss lines across a cell
SAMPLES = 9  # Chebyshev-Lobatto samples along a line
ROOT_ITERATIONS = 12
MAX_LEVEL = 18  # finest cell level in either direction (keys hold 18 bits per index)
MAX_PATCHES = 1 << 17  # patches a cache can tell apart (keys hold 17 bits for the patch)
MAX_CELLS = 40_000  # the cache starts afresh beyond this many cells (about 200 MB)


class LineBasis:
    """Chebyshev-Lobatto interpolation on [0, 1] with m points, as matrices.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Nodes, t[0] = 0, t[-1] = 1.
    to_coefficients : ndarray, shape (m, m)
        Values at the nodes -> Chebyshev coefficients (in x = 2 t - 1).
    antiderivative : ndarray, shape (m, m + 1)
        Values -> coefficients of the antiderivative vanishing at t = 0 (in t units).
    fine_t : ndarray, shape (M,)
        A uniform grid, M = 4 (m - 1) + 1.
    upsample : ndarray, shape (M, m)
        Values at the nodes -> values of the interpolant on `fine_t`.
    """

    def __init__(self, m):
        x = -np.cos(np.pi * np.arange(m) / (m - 1))
        self.t = 0.5 * (x + 1.0)
        vandermonde = chebyshev.chebvander(x, m - 1)
        self.to_coefficients = np.linalg.inv(vandermonde)
        # integrate each coefficient vector from x = -1; dt = dx / 2
        self.antiderivative = 0.5 * chebyshev.chebint(self.to_coefficients, lbnd=-1.0, axis=0).T
        # values -> interpolant on a grid four times finer (for sign changes between samples)
        self.fine_t = np.linspace(0.0, 1.0, 4 * (m - 1) + 1)
        self.upsample = self.chebyshev_values(self.fine_t, m - 1) @ self.to_coefficients

    @staticmethod
    def chebyshev_values(t, degree):
        """T_q(2 t - 1) for q = 0 .. degree, shape t.shape + (degree + 1,)."""
        x = 2.0 * t - 1.0
        T = np.empty(t.shape + (degree + 1,))
        T[..., 0] = 1.0
        if degree:
            T[..., 1] = x
        for q in range(2, degree + 1):
            T[..., q] = 2.0 * x * T[..., q - 1] - T[..., q - 2]
        return T

    def interpolate(self, values, t):
        """Interpolant of `values` (shape (..., m)) at t (shape (...)), shape (...)."""
        coefficients = values @ self.to_coefficients.T
        return np.einsum("...q,...q->...", coefficients, self.chebyshev_values(t, len(self.t) - 1))

    def integration_weights(self, lo, hi):
        """Weights w_k with sum_k f(t_k) w_k = integral of the interpolant over [lo, hi], shape (..., m)."""
        m = len(self.t)
        return (self.chebyshev_values(hi, m) - self.chebyshev_values(lo, m)) @ self.antiderivative.T


BASIS = LineBasis(SAMPLES)


class KeyedCache:
    """Rows of per-cell data keyed by dyadic cell, filled on first use (base of the cell caches).

    Subclasses allocate their arrays in `_grow(needed)` and fill new rows in
    `_fill(rows, patch, lu, lv, i, j)`. Beyond MAX_CELLS cells the cache starts afresh, so the
    rows a `lookup` returns are valid until the next `lookup`.

    Parameters
    ----------
    surfaces : SurfaceSet
    """

    def __init__(self, surfaces):
        self.surfaces = surfaces
        self.keys = np.zeros(0, dtype=np.int64)
        self.rows = np.zeros(0, dtype=np.int64)
        self.size = 0
        self.evaluations = 0
        self.compact = np.full(len(surfaces), -1, dtype=np.int64)
        self.patches_seen = 0

    @staticmethod
    def key(patch, lu, lv, i, j):
        """One int64 per cell: patch (17 bits), lu, lv (5 bits each), i, j (18 bits each)."""
        return ((((patch.astype(np.int64) << 5 | lu) << 5 | lv) << 18 | i) << 18) | j

    def lookup(self, patch, lu, lv, i, j):
        """Cache rows of cells, sampling the ones not seen before.

        Parameters
        ----------
        patch, lu, lv, i, j : ndarray of int, shape (K,)

        Returns
        -------
        ndarray of int, shape (K,)
        """
        # compact ids for the patches that use the cache (the key holds 17 bits of patch)
        fresh = np.unique(patch[self.compact[patch] < 0])
        if fresh.size:
            if self.patches_seen + fresh.size > MAX_PATCHES:
                raise ValueError(
                    f"too many curved patches in one solve (at most {MAX_PATCHES} use the cell cache)"
                )
            self.compact[fresh] = self.patches_seen + np.arange(fresh.size)
            self.patches_seen += fresh.size
        keys = self.key(self.compact[patch], lu, lv, i, j)
        if self.size + keys.size > MAX_CELLS:
            self.keys = np.zeros(0, dtype=np.int64)
            self.rows = np.zeros(0, dtype=np.int64)
            self.size = 0
        position = np.searchsorted(self.keys, keys)
        found = position < self.keys.size
        found[found] = self.keys[position[found]] == keys[found]
        if not found.all():
            new_keys, first = np.unique(keys[~found], return_index=True)
            new = np.flatnonzero(~found)[first]
            rows = np.arange(self.size, self.size + new.size)
            self._grow(self.size + new.size)
            self._fill(rows, patch[new], lu[new], lv[new], i[new], j[new])
            self.size += new.size
            order = np.argsort(np.concatenate([self.keys, new_keys]), kind="stable")
            self.keys = np.concatenate([self.keys, new_keys])[order]
            self.rows = np.concatenate([self.rows, rows])[order]
            position = np.searchsorted(self.keys, keys)
        return self.rows[position]

    def _grow(self, needed):
        raise NotImplementedError

    def _fill(self, rows, patch, lu, lv, i, j):
        raise NotImplementedError


class CellCache(KeyedCache):
    """Samples and bounds of target cells, computed on first use.

    Per cell row: `center`, `radius`, `axis`, `half` (bounds, `bounds.Pyramid.bounds`), `points`
    and `normals` (shape (2, LINES, SAMPLES, 3): direction-0 lines along v, direction-1 along u),
    `span` and `turn` (shape (2,): length and total normal turn along u and along v, from
    `line_spans`).

    Parameters
    ----------
    surfaces : SurfaceSet
    pyramid : bounds.Pyramid
        Stored bounds of the coarse levels.
    """

    def __init__(self, surfaces, pyramid):
        super().__init__(surfaces)
        self.pyramid = pyramid
        capacity = 0  # (allocated on first use: pairs done by closed forms never sample a cell)
        n, m = LINES, SAMPLES
        self.center = np.zeros((capacity, 3))
        self.radius = np.zeros(capacity)
        self.axis = np.zeros((capacity, 3))
        self.half = np.zeros(capacity)
        self.points = np.zeros((capacity, 2, n, m, 3))
        self.normals = np.zeros((capacity, 2, n, m, 3))
        self.span = np.zeros((capacity, 2))
        self.turn = np.zeros((capacity, 2))

    def _grow(self, needed):
        capacity = self.radius.size
        if needed <= capacity:
            return
        capacity = max(needed, 2 * capacity, 256)
        for name in ("center", "radius", "axis", "half", "points", "normals", "span", "turn"):
            old = getattr(self, name)
            new = np.zeros((capacity,) + old.shape[1:])
            new[: self.size] = old[: self.size]
            setattr(self, name, new)

    def _fill(self, rows, patch, lu, lv, i, j):
        """Sample new cells on both line directions and bound them into `rows`."""
        count = patch.size
        box = self.surfaces.cell_boxes(patch, lu, lv, i, j)
        center, radius, axis, half, _ = self.pyramid.bounds(patch, lu, lv, i, j)
        self.evaluations += 9 * int(((lu != lv) | (lu > self.pyramid.depth)).sum())
        self.center[rows], self.radius[rows], self.axis[rows], self.half[rows] = center, radius, axis, half
        # samples: direction 0 has lines along v (fixed u), direction 1 lines along u
        s = gauss_legendre(LINES).points
        t = BASIS.t
        shape = (count, 2, LINES, SAMPLES)
        across = np.broadcast_to(s[None, None, :, None], shape)
        along = np.broadcast_to(t[None, None, None, :], shape)
        direction = np.broadcast_to(np.arange(2)[None, :, None, None], shape)
        a = np.where(direction == 0, across, along)
        b = np.where(direction == 0, along, across)
        u = box[:, 0, None, None, None] + a * (box[:, 1] - box[:, 0])[:, None, None, None]
        v = box[:, 2, None, None, None] + b * (box[:, 3] - box[:, 2])[:, None, None, None]
        index = np.broadcast_to(patch[:, None, None, None], shape)
        P, N = self.surfaces.evaluate(index.ravel(), u.ravel(), v.ravel())
        self.evaluations += u.size
        self.points[rows] = P.reshape(shape + (3,))
        self.normals[rows] = N.reshape(shape + (3,))
        self.span[rows], self.turn[rows] = line_spans(self.points[rows], self.normals[rows])


def line_spans(points, normals):
    """Lengths and total normal turns of cells along u and along v, from their line samples.

    Summed over neighbouring samples of each cell's middle line in either direction, so a closed
    line (a whole azimuth) counts in full; zero normals (poles) turn by nothing.

    Parameters
    ----------
    points, normals : ndarray, shape (C, 2, n, m, 3)
        Cached samples (direction 0: lines along v; direction 1: lines along u).

    Returns
    -------
    span, turn : ndarray, shape (C, 2)
        Column 0 along u, column 1 along v (m and radians).
    """
    mid = points.shape[2] // 2
    span = np.empty((points.shape[0], 2))
    turn = np.empty((points.shape[0], 2))
    for column, d in ((0, 1), (1, 0)):
        span[:, column] = lengths(np.diff(points[:, d, mid], axis=1)).sum(1)
        unit, _ = unit_vectors(normals[:, d, mid])
        cosine = np.einsum("kmi,kmi->km", unit[:, 1:], unit[:, :-1])
        turn[:, column] = np.arccos(np.clip(cosine, -1.0, 1.0)).sum(1)
    return span, turn


def line_rule(x1, n1, points, normals, active1, active2):
    """Integral of the clipped kernel over cells from their cached line samples.

    Parameters
    ----------
    x1, n1 : ndarray, shape (K, 3)
        Points and unit normals.
    points, normals : ndarray, shape (K, n, m, 3)
        Samples of each cell on its n lines (already in the chosen direction).
    active1, active2 : ndarray of bool, shape (K,)
        Whether g1 (horizon) / g2 (silhouette) may change sign in the cell.

    Returns
    -------
    value : ndarray, shape (K,)
        Integral over the unit parameter square (multiply by the cell's parameter area).
    unreliable : ndarray of bool, shape (K,)
        Some line crosses a horizon more than once.
    """
    e = points - x1[:, None, None, :]
    g1 = np.einsum("klmi,ki->klm", e, n1)
    g2 = -np.einsum("klmi,klmi->klm", normals, e)
    L2 = np.einsum("klmi,klmi->klm", e, e)
    safe = np.where(L2 > 0.0, L2, 1.0)
    smooth = np.where(L2 > 0.0, g1 * g2 / (np.pi * safe * safe), 0.0)

    K, n, m = g1.shape
    lo, hi = np.zeros((K, n)), np.ones((K, n))
    unreliable = np.zeros(K, dtype=bool)
    for g, active in ((g1, active1), (g2, active2)):
        # signs on a fine grid of the interpolant: a sliver narrower than the sample spacing still shows
        fine = g @ BASIS.upsample.T
        positive = fine > 0.0
        change = positive[..., 1:] != positive[..., :-1]
        changes = change.sum(-1)
        act = active[:, None]
        unreliable |= active & (changes > 1).any(-1)
        empty = act & (changes == 0) & ~positive[..., 0]
        lo, hi = np.where(empty, 1.0, lo), np.where(empty, 0.0, hi)
        single = act & (changes == 1)
        if not single.any():
            continue
        r, line = np.nonzero(single)
        k = np.argmax(change[r, line], -1)
        grid = BASIS.fine_t
        root = _illinois(g[r, line], grid[k], grid[k + 1], fine[r, line, k], fine[r, line, k + 1])
        rises = ~positive[r, line, 0]
        lo[r, line] = np.where(rises, np.maximum(lo[r, line], root), lo[r, line])
        hi[r, line] = np.where(rises, hi[r, line], np.minimum(hi[r, line], root))
    hi = np.maximum(hi, lo)
    weights = BASIS.integration_weights(lo, hi)  # (K, n, m)
    lines = np.einsum("klm,klm->kl", smooth, weights)
    return lines @ gauss_legendre(n).weights, unreliable


def _illinois(values, a, b, fa, fb):
    """Root of the interpolant of `values` (shape (L, m)) bracketed by [a, b], shape (L,).

    Illinois variant of regula falsi (Dowell & Jarratt 1971, BIT 11:168-174).
    """
    coefficients = values @ BASIS.to_coefficients.T
    degree = values.shape[-1] - 1
    for _ in range(ROOT_ITERATIONS):
        step = np.divide(fb * (b - a), fb - fa, out=np.zeros_like(a), where=fb != fa)
        c = b - step
        fc = np.einsum("lq,lq->l", coefficients, LineBasis.chebyshev_values(c, degree))
        crossed = (fc > 0.0) != (fb > 0.0)
        a, fa = np.where(crossed, b, a), np.where(crossed, fb, 0.5 * fa)
        b, fb = c, fc
    return b
