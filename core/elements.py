"""The patches of a radiosity scene as one indexed set, with the bounds that culling needs.

An element is one side of one patch: a surface split into nu x nv patches gives nu * nv front
elements, and as many back elements (the same patches `flipped`) when it is two-sided.
"""

import math
import threading

import numpy as np

from .bounds import HIDDEN
from .formfactor import FormFactorSolver
from .integrate import cell_nodes
from .kinds import POLYGON

BOX_SAMPLES = 9  # grid points per parameter when bounding a curved element by a box
PYRAMID_DEPTH = 1  # stored bound levels per element (elements are small; deeper ones on demand)
CELL_BALL_MARGIN = 0.05  # a curved cell's hull grows by this fraction of its sampled points' spread
BOX_PAD = 0.02  # curved elements' boxes grow by this fraction of their bounding radius


class Elements:
    """Elements with bounds, areas and the exact inner integrals of the form-factor core.

    Parameters
    ----------
    surfaces : sequence of Surface, length N
        One patch per element (front or back side as front).
    owner : ndarray of int, shape (N,)
        Scene object of each element.

    Attributes
    ----------
    solver : FormFactorSolver
        Bounding balls and normal cones (`center`, `radius`, `axis`, `half_angle`, `flat`,
        `plane_point`), areas and the point-to-patch integrals (`inner`).
    box_min, box_max : ndarray, shape (N, 3)
        Axis-aligned boxes containing each element.
    geometry : ndarray of int, shape (N,)
        Elements cut from one geometry share its number.
    convex : ndarray of bool, shape (N,)
        The geometry bounds a convex solid (sphere, ellipsoid, cylinder lateral surface).
    outward : ndarray of bool, shape (N,)
        The element's front is the convex solid's outside.
    turning : ndarray, shape (N,)
        Largest turning angle of a parameter line (see `parameter_order`).
    sealed : (centre (N, 3), linear (N, 3, 3), largest semi-axis (N,))
        For the inside of an ellipsoid whose whole inner side is among the elements
        (`Geometry.bounded_solid`: a whole sphere's back), the ellipsoid; NaN elsewhere. Such
        an element sees nothing outside it: its own shell is in the way (`exchange`).
    straight : ndarray of bool, shape (N,)
        Flat quads and triangles: parameter lines are straight.
    whole_body : ndarray of bool, shape (N,)
        The element is the whole outside of an ellipsoid (`Geometry.whole_ellipsoid`): a point
        sees it up to its silhouette, a smooth curve, so F(x -> it) has no kink from its own side
        (`transport.kinked_pairs`).
    """

    def __init__(self, surfaces, owner):
        self.surfaces = list(surfaces)
        self.owner = np.asarray(owner, dtype=np.int64)
        self.solver = FormFactorSolver(self.surfaces, pyramid_depth=PYRAMID_DEPTH)
        s = self.solver
        self.center, self.radius = s.center[s.slot], s.radius[s.slot]
        self.flat = s.flat[s.slot]
        self.area = s.area[s.slot]
        self.index = s.slot  # element -> row of the solver's SurfaceSet
        numbers = {}
        self.geometry = np.array([numbers.setdefault(id(x.geometry), len(numbers)) for x in self.surfaces])
        self.convex = np.array([bool(x.geometry.convex_outward) for x in self.surfaces])
        self.outward = np.array([not x.is_flipped for x in self.surfaces])
        self.straight = s.inner.kind[s.slot] == POLYGON  # flat quads and triangles
        self.box_min, self.box_max = self._boxes()
        self.sealed = self._sealed()
        self.whole_body = self.convex & self.outward
        for k in np.flatnonzero(self.whole_body):
            self.whole_body[k] = self.surfaces[k].geometry.whole_ellipsoid(self.surfaces[k].domain)
        self._nodes = {}
        self._nodes_lock = threading.Lock()

    def __len__(self):
        return len(self.surfaces)

    @property
    def scale(self):
        """The scene's size (m): the diagonal of the box around every element, a float."""
        return float(np.linalg.norm(self.box_max.max(0) - self.box_min.min(0)))

    def _boxes(self):
        """Boxes from a grid of samples, padded for curved elements (the grid cuts corners)."""
        m = BOX_SAMPLES
        boxes = self.solver.set.boxes[self.index]
        s = np.linspace(0.0, 1.0, m)
        u = boxes[:, :1, None] + (boxes[:, 1] - boxes[:, 0])[:, None, None] * s[None, :, None]
        v = boxes[:, 2:3, None] + (boxes[:, 3] - boxes[:, 2])[:, None, None] * s[None, None, :]
        u, v = np.broadcast_arrays(u, v)
        index = np.broadcast_to(self.index[:, None, None], u.shape)
        P, _ = self.solver.set.evaluate(index.ravel(), u.ravel(), v.ravel())
        grid = P.reshape(len(self), m, m, 3)
        self.turning = np.maximum(_turning(grid), _turning(grid.transpose(0, 2, 1, 3)))
        P = P.reshape(len(self), -1, 3)
        pad = np.where(self.flat, 1e-9, BOX_PAD) * self.radius
        return P.min(1) - pad[:, None], P.max(1) + pad[:, None]

    def orders(self, tol):
        """`parameter_order` of every element at this tolerance (cached), shape (N,)."""
        key = ("orders", float(tol))
        with self._nodes_lock:
            if key not in self._nodes:
                self._nodes[key] = parameter_order(self.turning, tol)
            return self._nodes[key]

    def nodes(self, splits, order):
        """Gauss nodes of every element (computed once per rule): splits x splits cells of
        order x order points.

        Returns
        -------
        x, normal : ndarray, shape (N, Q, 3)
            Points (m) and unnormalised front normals; Q = (splits * order)^2.
        w : ndarray, shape (N, Q)
            Parameter weights (times |normal| they integrate area).
        """
        key = (splits, order)
        with self._nodes_lock:
            if key not in self._nodes:
                self._nodes[key] = self._rule_nodes(splits, order)
            return self._nodes[key]

    def has_nodes(self, splits, order):
        """Whether `nodes(splits, order)` is already computed and kept."""
        with self._nodes_lock:
            return (splits, order) in self._nodes

    def nodes_of(self, index, splits, order):
        """`nodes` of some elements only (computed each call: for rules too fine to keep for all),
        shapes (P, Q, 3), (P, Q, 3) and (P, Q)."""
        return self._rule_nodes(splits, order, np.asarray(index, dtype=np.int64))

    def boxes_of(self, index):
        """Parameter boxes (u0, u1, v0, v1) of elements, shape (K, 4)."""
        return self.solver.set.boxes[self.index[np.asarray(index, dtype=np.int64)]]

    def cell_nodes(self, index, boxes, order):
        """Gauss nodes on parameter cells of elements (order x order points in each).

        Parameters
        ----------
        index : ndarray of int, shape (C,)
            The element of each cell.
        boxes : ndarray, shape (C, 4)
            Cells (u0, u1, v0, v1) inside their elements' boxes.

        Returns
        -------
        x, normal : ndarray, shape (C, order^2, 3)
            Points (m) and unnormalised front normals.
        w : ndarray, shape (C, order^2)
            Parameter weights (times |normal| they integrate area).
        """
        u, v, w = cell_nodes(np.asarray(boxes, dtype=np.float64), order)
        row = np.repeat(self.index[np.asarray(index, dtype=np.int64)], order * order)
        x, normal = self.solver.set.evaluate(row, u.ravel(), v.ravel())
        return x.reshape(u.shape + (3,)), normal.reshape(u.shape + (3,)), w

    def cell_hulls(self, index, boxes):
        """Points whose convex hull, grown by `margin`, holds each parameter cell of elements:
        its corners, edge midpoints and centre, shape (C, 9, 3), and margin, shape (C,).

        A flat quad's or triangle's cell has straight edges (a bilinear map is linear along
        parameter lines), so it is the hull of these points (margin 0); a curved cell's hull is
        grown by CELL_BALL_MARGIN times the points' spread for what bulges between them."""
        t = np.array([0.0, 0.5, 1.0])
        s, r = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
        index = np.asarray(index, dtype=np.int64)
        boxes = np.asarray(boxes, dtype=np.float64)
        u = boxes[:, :1] + (boxes[:, 1:2] - boxes[:, :1]) * s
        v = boxes[:, 2:3] + (boxes[:, 3:4] - boxes[:, 2:3]) * r
        row = np.repeat(self.index[index], s.size)
        x, _ = self.solver.set.evaluate(row, u.ravel(), v.ravel())
        x = x.reshape(len(boxes), s.size, 3)
        spread = np.linalg.norm(x - x.mean(1)[:, None], axis=-1).max(1)
        return x, np.where(self.straight[index], 0.0, CELL_BALL_MARGIN * spread)

    def grid_cells(self, index, splits):
        """The splits x splits parameter cells of each element, u-major, shape (K * splits^2, 4)."""
        boxes = self.boxes_of(index)
        s = np.arange(splits + 1) / splits
        u0 = boxes[:, :1] + (boxes[:, 1:2] - boxes[:, :1]) * s  # (K, splits + 1)
        v0 = boxes[:, 2:3] + (boxes[:, 3:4] - boxes[:, 2:3]) * s
        return np.stack(
            np.broadcast_arrays(u0[:, :-1, None], u0[:, 1:, None], v0[:, None, :-1], v0[:, None, 1:]), -1
        ).reshape(-1, 4)

    def _rule_nodes(self, splits, order, which=None):
        which = np.arange(len(self)) if which is None else which
        cells = self.grid_cells(which, splits)
        N = which.size
        x, normal, w = self.cell_nodes(np.repeat(which, splits * splits), cells, order)
        return x.reshape(N, -1, 3), normal.reshape(N, -1, 3), w.reshape(N, -1)

    def heights(self, index, point, axis):
        """Least and greatest heights of the elements' boxes over planes, shapes (K,).

        Over a box, (y - point) . axis is extreme at the corner picked by the signs of axis:
        centre height -+ sum_i |axis_i| half_i.

        Parameters
        ----------
        index : ndarray of int, shape (K,)
        point, axis : ndarray, shape (K, 3)
            A point on each plane (m) and its normal (unit).
        """
        lo, hi = self.box_min[index], self.box_max[index]
        middle = np.einsum("ki,ki->k", 0.5 * (lo + hi) - point, axis)
        reach = np.einsum("ki,ki->k", 0.5 * (hi - lo), np.abs(axis))
        return middle - reach, middle + reach

    def live(self, a, b):
        """Whether elements a and b can exchange light at all (bounds; both directions).

        A pair is dead when either side faces wholly away from the other (normal cones, and for
        flat elements the other's box against the plane), or both are parts of one convex solid
        seen from outside (or one from outside, one from inside), or they are coplanar.

        Parameters
        ----------
        a, b : ndarray of int, shape (P,)

        Returns
        -------
        ndarray of bool, shape (P,)
        """
        ia, ib = self.index[a], self.index[b]
        code1, code2 = self.solver.visibility(ia, ib)
        alive = (code1 != HIDDEN) & (code2 != HIDDEN)
        alive &= self._plane_sees(a, b) & self._plane_sees(b, a)
        same_convex = (self.geometry[a] == self.geometry[b]) & self.convex[a]
        alive &= ~(same_convex & (self.outward[a] | self.outward[b]))
        # an element sees itself only when it is curved and not the outside of a convex solid
        self_pair = a == b
        alive &= ~self_pair | (~self.flat[a] & ~(self.convex[a] & self.outward[a]))
        return alive

    def exchange(self, a, b):
        """`live` pairs that are not the inside of a whole sphere or ellipsoid and something
        outside it, shape (P,) bool. Those are live (they face each other, and their unoccluded
        factors count in an enclosure's identity: `closure`), but the shell between them blocks
        every segment: V = 0, so nothing that carries light needs them (links, contacts).
        """
        return self.live(a, b) & ~self.sealed_from(a, b) & ~self.sealed_from(b, a)

    def _sealed(self):
        """`sealed`: the inner sides of ellipsoids whose inner patches' parameter boxes add up to
        the whole natural domain (patches of a split tile it)."""
        center, linear = np.full((len(self), 3), np.nan), np.full((len(self), 3, 3), np.nan)
        inside = self.convex & ~self.outward
        for g in np.unique(self.geometry[inside]):
            members = np.flatnonzero(inside & (self.geometry == g))
            geometry = self.surfaces[members[0]].geometry
            solid = geometry.bounded_solid()
            if solid is None:
                continue
            (u0, u1), (v0, v1) = geometry.natural_domain
            covered = sum(
                (s1 - s0) * (t1 - t0) for (s0, s1), (t0, t1) in (self.surfaces[k].domain for k in members)
            )
            if covered >= (u1 - u0) * (v1 - v0) * (1.0 - 1e-9):
                center[members], linear[members] = solid
        outer = np.full(len(self), np.nan)
        found = np.isfinite(center[:, 0])
        outer[found] = np.linalg.norm(linear[found], ord=2, axis=(1, 2))
        return center, linear, outer

    def sealed_between(self, a, b, occluding):
        """Whether a closed occluding shell parts elements a and b (either order): one is the
        inside of a whole sphere or ellipsoid (`sealed_from`) that occludes (`occluding`, shape
        (N,) bool), the other lies outside it, so every segment between them is blocked, shape (P,)."""
        return (occluding[a] & self.sealed_from(a, b)) | (occluding[b] & self.sealed_from(b, a))

    def sealed_from(self, a, b):
        """True where a is the inside of a whole ellipsoid and b lies outside it (b's bounding
        ball outside the ellipsoid's, or b flat on a plane that does not cut it), shape (P,)."""
        result = np.zeros(a.size, dtype=bool)
        center, linear, outer = self.sealed
        sel = np.flatnonzero(np.isfinite(center[a, 0]) & (self.geometry[a] != self.geometry[b]))
        if sel.size == 0:
            return result
        C, L, bs, outer = center[a[sel]], linear[a[sel]], b[sel], outer[a[sel]]
        apart = np.linalg.norm(self.center[bs] - C, axis=1) >= outer + self.radius[bs]
        # a plane with unit normal n misses the inside of the ellipsoid when |n . (C - p)| >= |L^T n|
        n = self.solver.axis[self.index[bs]]
        height = np.abs(np.einsum("ki,ki->k", n, C - self.solver.plane_point[self.index[bs]]))
        reach = np.linalg.norm(np.einsum("kij,ki->kj", L, n), axis=1)
        result[sel] = apart | (self.flat[bs] & (height >= reach * (1.0 - 1e-9)))
        return result

    def _plane_sees(self, a, b):
        """False where a is flat and b's box lies wholly behind or in a's plane."""
        result = np.ones(a.size, dtype=bool)
        sel = np.flatnonzero(self.flat[a])
        if sel.size:
            axis = self.solver.axis[self.index[a[sel]]]
            point = self.solver.plane_point[self.index[a[sel]]]
            _, highest = self.heights(b[sel], point, axis)
            slack = 1e-9 * (self.radius[a[sel]] + self.radius[b[sel]])
            result[sel] = highest > slack
        return result


def _turning(grid):
    """Largest angle (radians) through which a parameter line of each element turns, shape (N,).

    Lines are the rows of `grid`, shape (N, m, m, 3) (a full disk's circles: 2 pi).
    """
    step = np.diff(grid, axis=2)
    length = np.linalg.norm(step, axis=-1)
    unit = np.divide(step, length[..., None], out=np.zeros_like(step), where=length[..., None] > 0)
    cos = np.clip(np.einsum("nlki,nlki->nlk", unit[:, :, 1:], unit[:, :, :-1]), -1.0, 1.0)
    turning = np.where((length[:, :, 1:] > 0) & (length[:, :, :-1] > 0), np.arccos(cos), 0.0).sum(-1)
    return turning.max(1)


def parameter_order(turning, tol):
    """Fewest Gauss points per parameter that a parametrisation turning through `turning` needs.

    Along such a line the integrand is trigonometric in the parameter, like exp(i t tau / 2) on
    [-1, 1]; the n-point Gauss rule's error for it is about (tau / 4)^(2n) / (2n)!, kept below
    tol / 4. Shape of `turning`.
    """
    n = np.ones(np.shape(turning), dtype=np.int64)
    x = np.asarray(turning, dtype=np.float64) / 4.0
    for k in range(1, 16):
        error = x ** (2 * k) / math.factorial(2 * k)
        n = np.where((n == k) & (error > 0.25 * tol), k + 1, n)
    return n


def piece_patches(grid):
    """Patches per piece of a patch grid ((nu, nv), or one row per mesh piece), shape (P,)."""
    g = np.asarray(grid, dtype=np.int64).reshape(-1, 2)
    return g[:, 0] * g[:, 1]
