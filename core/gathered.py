"""Kept gather factors: the light reaching points as a sparse operator on element radiosities.

A gather (`Solution.radiosity_at`) sums F(x -> j) V(x, j) B_j over elements j and adds the
direct light of each point, spot and sun light. Everything in it but B_j and the lights' powers
depends on geometry only, so it can be kept (`Solution.gather_factors`) and re-applied to the
solution of any later solve of the same geometry (a relight: new materials, light powers or
sky) as one matrix-vector product (`Solution.radiosity_from`):

    arriving_k = sum_j W_kj B_j + sum_l D_kl P_l / pi + L (w_k - sum_j W_kj o_j)
    B_k = w_k E_h(k) + rho_h(k) arriving_k

with W the kept factors (K x N, sparse), D the direct factors per unit light power (K x lights),
o_j = 1 for the occluders' elements and L the sky radiance; h(k) is the surface of point k.
A point k may stand for a weighted sum of points of one surface (`GatherFactors.merged`, e.g. the
mean of a vertex's samples): its rows of W and D are then the weighted sums of theirs and w_k
their total weight (1 for a gathered point), so the product gives that sum directly.
"""

import numpy as np

from . import ragged

# bytes of one sparse factor: its point (intp), element (intp) and value (float32)
SPARSE_BYTES = 2 * np.dtype(np.intp).itemsize + 4


class GatherFactors:
    """Gather factors of K points (see the module docstring).

    W is held as sparse triplets until the first product (`product`), which stores it as a
    dense matrix over the target elements instead whenever that takes no more memory (a W at
    least about a third full: typical of vertex gathers, where every point sees most of the
    scene): a dense product is one BLAS call, about ten times faster than the sparse sums. It
    holds the float32 factors in float64 and sums in float64, as the sparse sums do, so the two
    forms agree to rounding (a `take` of some points gives their values exactly). `rows`,
    `cols` and `values` read either form (from a dense W: its nonzero entries).

    Attributes
    ----------
    handle : ndarray of int, shape (K,)
        Surface of each point.
    rows, cols : ndarray of int, shape (P,)
        Point and element of each kept factor (rows sorted).
    values : ndarray of float32, shape (P,)
        F(x -> j) V(x, j).
    direct : ndarray, shape (K, n_lights)
        Irradiance per unit light power (with shadows), in the scene's light order.
    targets : ndarray of bool, shape (N,)
        Elements whose factors were kept: a later solution whose radiosity is nonzero elsewhere
        cannot use them (`Solution.radiosity_from` raises).
    geometry : object
        The solve geometry the factors belong to (compared by identity).
    weight : ndarray, shape (K,)
        Total weight of the points each point stands for (1 for a gathered point, see `merged`).
    near : nearfield.NearTerms or None
        The near field (`core.nearfield`): the terms F(x_k -> j) V B_j of near elements j,
        replaced by couplings to nodes on j whose radiosities `Solution.radiosity_from` solves
        again. Those terms are not in W.
    """

    def __init__(self, handle, rows, cols, values, direct, targets, geometry, weight=None, near=None):
        self.handle = handle
        # float32 factors (~1e-7 relative, well inside any solve tolerance); native-size indices,
        # which np.bincount and fancy indexing take without a conversion (20 bytes a factor)
        self._triplets = (rows.astype(np.intp), cols.astype(np.intp), values.astype(np.float32))
        self._matrix = None  # or W over the target columns (K, T), once dense
        self.direct = direct
        self.targets = targets
        self.geometry = geometry
        self.weight = np.ones(len(handle)) if weight is None else np.asarray(weight, dtype=np.float64)
        self.near = near

    @property
    def rows(self):
        return self._sparse()[0]

    @property
    def cols(self):
        return self._sparse()[1]

    @property
    def values(self):
        return self._sparse()[2]

    def _sparse(self):
        if self._triplets is None:  # (rare: W is dense once a product ran)
            rows, at = np.nonzero(self._matrix)
            self._triplets = (rows, np.flatnonzero(self.targets)[at], self._matrix[rows, at])
        return self._triplets

    def __len__(self):
        return len(self.handle)

    @property
    def nbytes(self):
        held = [self._matrix] if self._triplets is None else list(self._triplets)
        total = sum(a.nbytes for a in [self.handle, self.direct, self.weight] + held)
        return total + (self.near.nbytes if self.near is not None else 0)

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
        near = [(p.near, o) for p, o in zip(parts, offsets) if p.near is not None]
        if near:
            near = near[0][0].concatenate([n for n, _ in near], [o for _, o in near])
        return GatherFactors(
            np.concatenate([p.handle for p in parts]),
            np.concatenate([p.rows + o for p, o in zip(parts, offsets)]),
            np.concatenate([p.cols for p in parts]),
            np.concatenate([p.values for p in parts]),
            np.concatenate([p.direct for p in parts]),
            np.logical_and.reduce([p.targets for p in parts]),
            geometry,
            np.concatenate([p.weight for p in parts]),
            near or None,
        )

    def take(self, index):
        """The factors of points `index` (ndarray of int, shape (K',)) of this set, in that
        order (repeats allowed): one GatherFactors of K' points."""
        index = np.asarray(index, dtype=np.intp)
        rows, entry = ragged.runs_of(self.rows, index)
        near = None
        if self.near is not None:
            near = self.near.with_points(*ragged.runs_of(self.near.point, index))
        return GatherFactors(
            self.handle[index],
            rows,
            self.cols[entry],
            self.values[entry],
            self.direct[index],
            self.targets,
            self.geometry,
            self.weight[index],
            near,
        )

    def merged(self, group, weight, count):
        """Weighted sums of points: point g of the result is sum_k weight_k * point k over the
        points k with group_k = g (all on one surface), so `Solution.radiosity_from` gives
        sum_k weight_k B_k for it in one product (e.g. a vertex's mean of its samples).

        Parameters
        ----------
        group : ndarray of int, shape (K,)
            Result point of each point, in 0 .. count - 1; every result point gets at least one.
        weight : ndarray, shape (K,)
        count : int

        Returns
        -------
        GatherFactors
            Of `count` points; a factor per (result point, element) summed in float64 before
            being stored as float32.

        Raises
        ------
        ValueError
            If a group is empty or holds points of different surfaces.
        """
        group = np.asarray(group, dtype=np.intp)
        weight = np.asarray(weight, dtype=np.float64)
        if group.shape != (len(self),) or weight.shape != (len(self),):
            raise ValueError(f"group and weight need shape ({len(self)},), got {group.shape}, {weight.shape}")
        if len(self) and (group.min() < 0 or group.max() >= count):
            raise ValueError(f"group must be in 0 .. {count - 1}")
        if np.any(np.bincount(group, minlength=count) == 0):
            raise ValueError("every merged point needs at least one point")
        handle = np.empty(count, dtype=self.handle.dtype)
        handle[group] = self.handle
        if np.any(handle[group] != self.handle):
            raise ValueError("a merged point can only sum points of one surface")
        N = len(self.targets)
        key, inverse = np.unique(group[self.rows] * N + self.cols, return_inverse=True)
        values = np.bincount(inverse.ravel(), weights=weight[self.rows] * self.values, minlength=key.size)
        direct = np.zeros((count, self.direct.shape[1]))
        for light, d in enumerate(self.direct.T):
            direct[:, light] = np.bincount(group, weights=weight * d, minlength=count)
        near = None
        if self.near is not None:  # each coupling times its point's weight, moved to its group
            point = self.near.point
            near = self.near.with_points(group[point], np.arange(point.size), weight[point])
        return GatherFactors(
            handle,
            key // N,
            key % N,
            values,
            direct,
            self.targets,
            self.geometry,
            np.bincount(group, weights=weight * self.weight, minlength=count),
            near,
        )

    def product(self, B):
        """sum_j W_kj B_j for element values B, shape (N, C) -> (K, C), float64."""
        K = len(self.handle)
        columns = np.flatnonzero(self.targets)
        if self._matrix is None and K * columns.size * 8 <= SPARSE_BYTES * self._triplets[2].size:
            self._densify(columns)
        if self._matrix is not None:
            return self._matrix @ np.asarray(B[columns], dtype=np.float64)
        rows, cols, values = self._triplets
        out = np.empty((K, B.shape[1]))
        Bt = np.ascontiguousarray(B.T)
        for c in range(B.shape[1]):
            out[:, c] = np.bincount(rows, weights=values * Bt[c][cols], minlength=K)
        return out

    def _densify(self, columns):
        """Hold W as a dense matrix over `columns` (the targets) instead of triplets."""
        rows, cols, values = self._triplets
        column = np.full(len(self.targets), -1, dtype=np.intp)
        column[columns] = np.arange(columns.size)
        at = column[cols]
        # factors toward elements left out of joined targets meet a zero B (`radiosity_from`
        # checks): dropped; a repeated (point, element) factor adds up, as in the sparse sums
        kept = at >= 0
        flat = np.bincount((rows * columns.size + at)[kept], values[kept], len(self.handle) * columns.size)
        self._matrix = flat.reshape(len(self.handle), columns.size)
        self._triplets = None
