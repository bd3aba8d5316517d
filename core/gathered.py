"""Kept gather factors: the light reaching points as a sparse operator on element radiosities.

A gather (`Solution.radiosity_at`) sums F(x -> j) V(x, j) B_j over elements j and adds the
direct light of each point, spot and sun light. Everything in it but B_j and the lights' powers
depends on geometry only, so it can be kept (`Solution.gather_factors`) and re-applied to the
solution of any later solve of the same geometry (a relight: new materials, light powers or
sky) as one sparse matrix-vector product (`Solution.radiosity_from`):

    arriving_k = sum_j W_kj B_j + sum_l D_kl P_l / pi + L (1 - sum_j W_kj o_j)
    B_k = E_h(k) + rho_h(k) arriving_k

with W the kept factors (K x N, sparse), D the direct factors per unit light power (K x lights),
o_j = 1 for the occluders' elements and L the sky radiance; h(k) is the surface of point k.
"""

import numpy as np


class GatherFactors:
    """Sparse gather factors of K points (see the module docstring).

    Attributes
    ----------
    handle : ndarray of int, shape (K,)
        Surface of each point.
    rows, cols : ndarray of int, shape (P,)
        Point and element of each kept factor (rows sorted).
    values : ndarray, shape (P,)
        F(x -> j) V(x, j).
    direct : ndarray, shape (K, n_lights)
        Irradiance per unit light power (with shadows), in the scene's light order.
    targets : ndarray of bool, shape (N,)
        Elements whose factors were kept: a later solution whose radiosity is nonzero elsewhere
        cannot use them (`Solution.radiosity_from` raises).
    geometry : object
        The solve geometry the factors belong to (compared by identity).
    """

    def __init__(self, handle, rows, cols, values, direct, targets, geometry):
        self.handle = handle
        # float32 factors (~1e-7 relative, well inside any solve tolerance); native-size indices,
        # which np.bincount and fancy indexing take without a conversion (20 bytes a factor)
        self.rows, self.cols = rows.astype(np.intp), cols.astype(np.intp)
        self.values = values.astype(np.float32)
        self.direct = direct
        self.targets = targets
        self.geometry = geometry

    def __len__(self):
        return len(self.handle)

    @property
    def nbytes(self):
        return sum(a.nbytes for a in (self.handle, self.rows, self.cols, self.values, self.direct))

    @staticmethod
    def concatenate(parts):
        """One GatherFactors holding the points of `parts` in order (same geometry)."""
        parts = list(parts)
        if not parts:
            raise ValueError("concatenate needs at least one GatherFactors")
        geometry = parts[0].geometry
        if any(p.geometry is not geometry for p in parts):
            raise ValueError("gather factors of different solve geometries cannot be concatenated")
        offsets = np.cumsum([0] + [len(p) for p in parts[:-1]])
        return GatherFactors(
            np.concatenate([p.handle for p in parts]),
            np.concatenate([p.rows + o for p, o in zip(parts, offsets)]),
            np.concatenate([p.cols for p in parts]),
            np.concatenate([p.values for p in parts]),
            np.concatenate([p.direct for p in parts]),
            np.logical_and.reduce([p.targets for p in parts]),
            geometry,
        )

    def take(self, index):
        """The factors of points `index` (ndarray of int, shape (K',)) of this set, in that
        order (repeats allowed): one GatherFactors of K' points."""
        index = np.asarray(index, dtype=np.intp)
        start = np.searchsorted(self.rows, index)
        count = np.searchsorted(self.rows, index, side="right") - start
        total = int(count.sum())
        rows = np.repeat(np.arange(index.size), count)
        entry = np.repeat(start - (np.cumsum(count) - count), count) + np.arange(total)
        return GatherFactors(
            self.handle[index],
            rows,
            self.cols[entry],
            self.values[entry],
            self.direct[index],
            self.targets,
            self.geometry,
        )

    def product(self, B):
        """sum_j W_kj B_j for element values B, shape (N, C) -> (K, C)."""
        K = len(self.handle)
        out = np.empty((K, B.shape[1]))
        Bt = np.ascontiguousarray(B.T)
        for c in range(B.shape[1]):
            out[:, c] = np.bincount(self.rows, weights=self.values * Bt[c][self.cols], minlength=K)
        return out
