"""Bounding spheres and normal cones of dyadic patch cells, and the visibility tests they allow.

A cell's bound is a sphere (centre, radius) holding every point of the cell and a cone
(unit axis, half-angle) holding every unit front normal. Bounds are sampled on a grid and
inflated by the sampling error (second differences for points, neighbour angles for normals),
so they hold for smooth patches without a per-shape formula.
"""

import weakref

import numpy as np

SAMPLES = 4  # sample intervals per finest cell edge

# Root bounds of patches bounded before, per sample-grid size: a patch is immutable, so its root
# bound (like its area) is computed once and reused by every later solver that holds it (a loop
# over single pairs, a scene solved again). Rows: centre (3), radius, axis (3), half-angle,
# plane point (3). Entries go with their patch.
_ROOT_BOUNDS = weakref.WeakKeyDictionary()

# visibility codes
HIDDEN, PARTIAL, FULL = 0, 1, 2


def _angle(a, b):
    """Angle between unit vectors, shape (...,)."""
    return np.arccos(np.clip(np.einsum("...i,...i->...", a, b), -1.0, 1.0))


def lengths(vectors):
    """Euclidean lengths along the last axis, shape (...,) (faster than `np.linalg.norm`)."""
    return np.sqrt(np.einsum("...i,...i->...", vectors, vectors))


def unit_vectors(vectors):
    """Unit vectors and lengths; zero vectors stay zero. Shapes (..., 3) and (...,)."""
    length = lengths(vectors)
    safe = np.where(length > 0.0, length, 1.0)
    return vectors / safe[..., None], length


def grid_bounds(P, unit, length):
    """Bounds of cells from a grid of samples over each cell.

    Parameters
    ----------
    P : ndarray, shape (C, m, m, 3)
        Sample points of each cell, corners included.
    unit : ndarray, shape (C, m, m, 3)
        Unit front normals at the samples (zero where the normal vanishes).
    length : ndarray, shape (C, m, m)
        Lengths of the unnormalised normals; samples where it is below 1e-8 of the cell's largest
        (poles, collapsed edges: the direction there is rounding noise) do not shape the cone.

    Returns
    -------
    center : ndarray, shape (C, 3)
    radius : ndarray, shape (C,)
        Sample spread plus twice the chord error (|second difference| bounds the bulge between
        samples).
    axis : ndarray, shape (C, 3)
    half_angle : ndarray, shape (C,)
        Normal spread plus twice the largest turn between neighbouring samples; pi when the
        normals do not define an axis.
    """
    # (reductions run along the last axis: numpy reduces slowly across a trailing axis of 3)
    C = P.shape[0]
    valid = length > 1e-8 * length.reshape(C, -1).max(1)[:, None, None]
    bulge = np.zeros(C)
    if P.shape[1] > 2:
        d2u = lengths(P[:, 2:] - 2 * P[:, 1:-1] + P[:, :-2])
        d2v = lengths(P[:, :, 2:] - 2 * P[:, :, 1:-1] + P[:, :, :-2])
        bulge = d2u.reshape(C, -1).max(1) + d2v.reshape(C, -1).max(1)
    tu = np.where(valid[:, 1:] & valid[:, :-1], _angle(unit[:, 1:], unit[:, :-1]), 0.0)
    tv = np.where(valid[:, :, 1:] & valid[:, :, :-1], _angle(unit[:, :, 1:], unit[:, :, :-1]), 0.0)
    turn = np.maximum(tu.reshape(C, -1).max(1), tv.reshape(C, -1).max(1))

    flatP = P.reshape(C, -1, 3)
    by_axis = np.ascontiguousarray(flatP.transpose(0, 2, 1))  # (C, 3, m*m)
    center = 0.5 * (by_axis.min(-1) + by_axis.max(-1))
    radius = lengths(flatP - center[:, None]).max(1)
    radius += 2.0 * bulge + 1e-12 * lengths(center)
    flatU = unit.reshape(C, -1, 3)
    weights = valid.reshape(C, -1)
    axis, axis_length = unit_vectors(np.einsum("cn,cni->ci", weights.astype(np.float64), flatU))
    spread = np.where(weights, _angle(flatU, axis[:, None]), 0.0).max(1)
    half = np.where(axis_length > 1e-12, np.minimum(spread + 2.0 * turn + 1e-9, np.pi), np.pi)
    return center, radius, axis, half


def sample_cells(surfaces, patch, boxes, intervals):
    """Sample cells on (intervals + 1)^2 grids and bound them (see `grid_bounds`).

    Parameters
    ----------
    surfaces : SurfaceSet
    patch : ndarray of int, shape (C,)
    boxes : ndarray, shape (C, 4)
    intervals : int

    Returns
    -------
    center, radius, axis, half_angle : as `grid_bounds`
    """
    s = np.linspace(0.0, 1.0, intervals + 1)
    m = s.size
    u = boxes[:, 0, None, None] + (boxes[:, 1] - boxes[:, 0])[:, None, None] * s[None, :, None]
    v = boxes[:, 2, None, None] + (boxes[:, 3] - boxes[:, 2])[:, None, None] * s[None, None, :]
    u, v = np.broadcast_arrays(u, v)
    index = np.broadcast_to(patch[:, None, None], u.shape)
    P, N = surfaces.evaluate(index.ravel(), u.ravel(), v.ravel())
    unit, length = unit_vectors(N)
    shape = (len(patch), m, m)
    return grid_bounds(P.reshape(shape + (3,)), unit.reshape(shape + (3,)), length.reshape(shape))


class Pyramid:
    """Bounds of the cells (level, i, j) of a set of patches.

    Levels 0 .. depth are stored, sampled once per patch on a shared grid (levels below the root
    are bounded from it on first use; the root bound of a patch is kept with the patch, so a
    patch bounded before is not sampled again until a finer level is needed); deeper cells are
    sampled on demand on a 3 x 3 grid.

    Parameters
    ----------
    surfaces : SurfaceSet
    patches : ndarray of int, shape (Np,)
        Patches (indices into `surfaces`) to bound.
    depth : int
        Finest stored level (4**depth cells per patch).

    Attributes
    ----------
    center : ndarray, shape (Np, T, 3)
    radius : ndarray, shape (Np, T)
    axis : ndarray, shape (Np, T, 3)
    half_angle : ndarray, shape (Np, T)
        T = (4**(depth+1) - 1) / 3 cells per patch, level by level, row-major in (i, j).
    flat : ndarray of bool, shape (Np,)
        Patch lies in a plane: its normal cone is exact (half-angle 0).
    plane_point : ndarray, shape (Np, 3)
        A point of each patch (on its plane, for flat ones).
    """

    def __init__(self, surfaces, patches, depth=3):
        self.surfaces = surfaces
        self.depth = depth
        self.patches = np.asarray(patches, dtype=np.int64)
        self.slot_of = np.full(int(self.patches.max()) + 1, -1, dtype=np.int64)
        self.slot_of[self.patches] = np.arange(self.patches.size)
        self.level_offset = np.array([(4**ell - 1) // 3 for ell in range(depth + 2)])
        n_patch = self.patches.size
        total = int(self.level_offset[depth + 1])
        self.center = np.empty((n_patch, total, 3))
        self.radius = np.empty((n_patch, total))
        self.axis = np.empty((n_patch, total, 3))
        self.half_angle = np.empty((n_patch, total))
        self.flat = np.array(
            [surfaces.surfaces[p].geometry.plane is not None for p in self.patches], dtype=bool
        )
        self._sample()

    def _sample(self):
        """Bound the root cells: from the kept bounds of patches bounded before, by sampling the
        others on the grid (deeper levels on demand: a pair done by closed forms and one Gauss
        rule never needs them)."""
        m = 2**self.depth * SAMPLES + 1
        patches = [self.surfaces.surfaces[p] for p in self.patches]
        rows = [_ROOT_BOUNDS.get(patch, {}).get(m) for patch in patches]
        missing = [k for k, row in enumerate(rows) if row is None]
        self._grid = None
        if missing:
            grid = self._sample_grid(self.patches[missing])
            center, radius, axis, half = grid_bounds(*grid)
            # a point of each flat patch's plane (bounding-box centres need not lie on it): the
            # grid's middle sample, at the middle of the parameter box (m is odd)
            point = grid[0][:, m // 2, m // 2]
            fresh = np.concatenate([center, radius[:, None], axis, half[:, None], point], 1)
            for k, row in zip(missing, fresh):
                rows[k] = row.copy()
                _ROOT_BOUNDS.setdefault(patches[k], {})[m] = rows[k]
            if len(missing) == len(patches):
                self._grid = grid
        table = np.array(rows).reshape(len(patches), 11)
        self.center[:, 0] = table[:, 0:3]
        self.radius[:, 0] = table[:, 3]
        self.axis[:, 0] = table[:, 4:7]
        self.half_angle[:, 0] = np.where(self.flat, 0.0, table[:, 7])
        self.plane_point = table[:, 8:11].copy()
        self._levels = 1  # levels 0 .. _levels - 1 are bounded

    def _sample_grid(self, patches):
        """Samples of patches on the (m x m) parameter grid of the finest stored level.

        Returns
        -------
        P, unit, length : ndarray, shapes (K, m, m, 3), (K, m, m, 3), (K, m, m)
            Points, unit front normals and normal lengths (`grid_bounds`' input).
        """
        m = 2**self.depth * SAMPLES + 1
        boxes = self.surfaces.boxes[patches]
        s = np.linspace(0.0, 1.0, m)
        u = boxes[:, 0, None, None] + (boxes[:, 1] - boxes[:, 0])[:, None, None] * s[None, :, None]
        v = boxes[:, 2, None, None] + (boxes[:, 3] - boxes[:, 2])[:, None, None] * s[None, None, :]
        u, v = np.broadcast_arrays(u, v)
        index = np.broadcast_to(patches[:, None, None], u.shape)
        P, N = self.surfaces.evaluate(index.ravel(), u.ravel(), v.ravel())
        unit, length = unit_vectors(N.reshape(u.shape + (3,)))
        return P.reshape(u.shape + (3,)), unit, length

    def _bound_levels(self, count):
        """Bound the cells of levels up to count - 1 (at most depth) from the sample grid."""
        if self._levels >= min(count, self.depth + 1):
            return
        if self._grid is None:
            self._grid = self._sample_grid(self.patches)
        P, unit, length = self._grid
        n_patch, m = P.shape[0], P.shape[1]
        for ell in range(self._levels, min(count, self.depth + 1)):
            cells = 2**ell
            q = (m - 1) // cells
            if cells == 1:  # the root cell: the whole grid
                center, radius, axis, half = grid_bounds(P, unit, length)
            else:
                rows = np.arange(cells)[:, None] * q + np.arange(q + 1)[None, :]  # (cells, q+1)
                ii, jj = rows[:, None, :, None], rows[None, :, None, :]
                shape = (n_patch * cells * cells, q + 1, q + 1)
                center, radius, axis, half = grid_bounds(
                    P[:, ii, jj].reshape(shape + (3,)),
                    unit[:, ii, jj].reshape(shape + (3,)),
                    length[:, ii, jj].reshape(shape),
                )
            cell = slice(self.level_offset[ell], self.level_offset[ell + 1])
            self.center[:, cell] = center.reshape(n_patch, -1, 3)
            self.radius[:, cell] = radius.reshape(n_patch, -1)
            self.axis[:, cell] = axis.reshape(n_patch, -1, 3)
            self.half_angle[:, cell] = np.where(self.flat[:, None], 0.0, half.reshape(n_patch, -1))
            self._levels = ell + 1

    # ------------------------------------------------------------------ lookup
    def index(self, patch, level, i, j):
        """Flat indices (slot, cell) of the stored bound of square cell (level, i, j), level <= depth.

        Parameters
        ----------
        patch, level, i, j : ndarray of int, shape (K,)

        Returns
        -------
        slot, cell : ndarray of int, shape (K,)
        """
        level = np.asarray(level)
        return self.slot_of[patch], self.level_offset[level] + i * np.left_shift(1, level) + j

    def bounds(self, patch, lu, lv, i, j):
        """Bounds of cells: centre (K, 3), radius (K,), axis (K, 3), half-angle (K,), flat (K,).

        Square cells of the stored levels are looked up; other cells (deeper, or split more in
        one direction than the other) are sampled now on a 3 x 3 grid.
        """
        lu, lv = np.asarray(lu), np.asarray(lv)
        stored = (lu == lv) & (lu <= self.depth)
        if stored.any():
            self._bound_levels(int(lu[stored].max()) + 1)
        slot, cell = self.index(
            patch, np.where(stored, lu, 0), np.where(stored, i, 0), np.where(stored, j, 0)
        )
        center = self.center[slot, cell]
        radius = self.radius[slot, cell]
        axis = self.axis[slot, cell]
        half = self.half_angle[slot, cell]
        flat = self.flat[slot]
        other = np.flatnonzero(~stored)
        if other.size:
            boxes = self.surfaces.cell_boxes(patch[other], lu[other], lv[other], i[other], j[other])
            c, r, a, h = sample_cells(self.surfaces, patch[other], boxes, 2)
            # a flat patch keeps its exact normal (the root's axis)
            center[other], radius[other] = c, r
            axis[other] = np.where(flat[other, None], axis[other], a)
            half[other] = np.where(flat[other], 0.0, h)
        return center, radius, axis, half, flat


def facing_code(height, radius):
    """Sign of a linear function over a ball: HIDDEN if <= 0 throughout, FULL if > 0, else PARTIAL.

    Parameters
    ----------
    height : ndarray, shape (K,)
        Value at the ball's centre.
    radius : ndarray, shape (K,)
        Bound on the variation over the ball.
    """
    return np.where(height + radius <= 0.0, HIDDEN, np.where(height - radius > 0.0, FULL, PARTIAL))


def cone_code(axis, half_angle, direction, spread):
    """Sign of n . d for n in a cone and d in a cone of directions.

    HIDDEN if n . d <= 0 for every pair, FULL if > 0 for every pair, else PARTIAL.

    Parameters
    ----------
    axis : ndarray, shape (K, 3)
        Unit axis of the normal cone.
    half_angle : ndarray, shape (K,)
    direction : ndarray, shape (K, 3)
        Unit axis of the direction cone.
    spread : ndarray, shape (K,)
        Half-angle of the direction cone (pi when it is unbounded).
    """
    theta = _angle(axis, direction)
    slack = half_angle + spread
    return np.where(
        theta - slack >= 0.5 * np.pi, HIDDEN, np.where(theta + slack < 0.5 * np.pi, FULL, PARTIAL)
    )


def direction_cone(origin, center, radius):
    """Cone of directions from points near `origin` to a ball (center, radius).

    Returns
    -------
    direction : ndarray, shape (K, 3)
        Unit axis from origin to centre.
    spread : ndarray, shape (K,)
        Half-angle: asin(radius / distance), or pi when the origin is inside the ball.
    distance : ndarray, shape (K,)
    """
    direction, distance = unit_vectors(center - origin)
    ratio = np.divide(radius, distance, out=np.full_like(radius, 2.0), where=distance > 0)
    spread = np.where(ratio < 1.0, np.arcsin(np.minimum(ratio, 1.0)), np.pi)
    return direction, spread, distance


def sphere_patch_range(b, box):
    """Least and greatest values of p(u, v) . b over patches of the unit sphere, shapes (K,).

    p = (sin u cos v, sin u sin v, cos u) (`primitives.SphereGeometry`). A linear function on
    the sphere takes its extremes on a patch at the corners, inside an edge where the edge's
    circle turns most toward or away from b, or at +-b / |b| themselves.

    Parameters
    ----------
    b : ndarray, shape (K, 3)
    box : ndarray, shape (K, 4)
        (u0, u1, v0, v1) of each patch (radians, 0 <= u <= pi).
    """
    u0, u1, v0, v1 = box.T
    rho = np.hypot(b[:, 0], b[:, 1])
    bz = b[:, 2]
    phi = np.arctan2(b[:, 1], b[:, 0])
    su = np.sin([u0, u1])
    cu = np.cos([u0, u1])
    cv = np.cos([v0 - phi, v1 - phi])
    # g(u, v) = rho sin u cos(v - phi) + bz cos u at the four corners
    corners = rho * su[:, None] * cv[None] + bz * cu[:, None]
    least = corners.min((0, 1))
    most = corners.max((0, 1))

    def on(angle, lo, hi):
        """angle + 2 pi k in [lo, hi] for some k."""
        return (angle - lo) % (2.0 * np.pi) <= hi - lo

    # parallels u = const: extremes where cos(v - phi) = -1 or +1, if on the edge
    parallel = bz * cu
    least = np.where(on(phi + np.pi, v0, v1), np.minimum(least, (parallel - rho * su).min(0)), least)
    most = np.where(on(phi, v0, v1), np.maximum(most, (parallel + rho * su).max(0)), most)
    # meridians v = const: A sin u + bz cos u = |(A, bz)| cos(u - psi), extremes at psi (+ pi)
    A = rho * cv
    psi = np.arctan2(A, bz)
    size = np.hypot(A, bz)
    least = np.minimum(least, np.where(on(psi + np.pi, u0, u1), -size, np.inf).min(0))
    most = np.maximum(most, np.where(on(psi, u0, u1), size, -np.inf).max(0))
    # the extremes of the whole sphere, -+b / |b|: polar angles pi - theta_b and theta_b
    theta = np.arctan2(rho, bz)
    length = lengths(b)
    pole = rho == 0.0
    least = np.where(on(np.pi - theta, u0, u1) & (on(phi + np.pi, v0, v1) | pole), -length, least)
    most = np.where(on(theta, u0, u1) & (on(phi, v0, v1) | pole), length, most)
    return least, most


def cone_angles(x, target_center, target_radius, center, radius):
    """Half-angles of the cones of directions from x to a ball (alpha) and to the target's ball
    (beta), the angle between their axes (gamma), each shape (K,), and where x lies inside
    either ball (no conclusion, shape (K,) bool)."""
    to_target, to_ball = target_center - x, center - x
    dt, db = np.linalg.norm(to_target, axis=1), np.linalg.norm(to_ball, axis=1)
    beta = np.arcsin(np.clip(np.divide(target_radius, dt, out=np.ones_like(dt), where=dt > 0), 0.0, 1.0))
    alpha = np.arcsin(np.clip(np.divide(radius, db, out=np.ones_like(db), where=db > 0), 0.0, 1.0))
    cos = np.einsum("ki,ki->k", to_target, to_ball) / np.maximum(dt * db, 1e-300)
    gamma = np.arccos(np.clip(cos, -1.0, 1.0))
    return alpha, beta, gamma, (target_radius >= dt) | (radius >= db)


def cones_apart(x, target_center, target_radius, center, radius, beyond=False):
    """Whether the cone of directions from x to a ball (center, radius) misses the cone to the
    target's ball, shape (K,) bool (False where x is inside either ball: no conclusion), compared
    by cosines, cos gamma < cos(alpha + beta) (no arcsin or arccos; `cone_angles` gives the
    angles). With `beyond`, also where the ball lies wholly beyond the target's: then it can meet
    no segment from x to a point of the target's ball."""
    to_target, to_ball = target_center - x, center - x
    dt = np.sqrt(np.einsum("ki,ki->k", to_target, to_target))
    db = np.sqrt(np.einsum("ki,ki->k", to_ball, to_ball))
    outside = (dt > target_radius) & (db > radius)
    sin_b = np.divide(target_radius, dt, out=np.ones_like(dt), where=outside)
    sin_a = np.divide(radius, db, out=np.ones_like(db), where=outside)
    cos_sum = np.sqrt(1.0 - sin_a * sin_a) * np.sqrt(1.0 - sin_b * sin_b) - sin_a * sin_b
    cos_gamma = np.einsum("ki,ki->k", to_target, to_ball) / np.maximum(dt * db, 1e-300)
    apart = cos_gamma < cos_sum - 1e-9
    if beyond:
        apart |= db - radius > (dt + target_radius) * (1.0 + 1e-9)
    return outside & apart


def cannot_block(x, target_center, target_radius, center, radius):
    """Whether a ball (center, radius) can meet no segment from x to a point of the target's ball,
    shape (K,) bool (`cones_apart` with `beyond`)."""
    return cones_apart(x, target_center, target_radius, center, radius, beyond=True)
