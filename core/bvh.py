"""One bounding volume hierarchy (BVH) for every occlusion query: segments, boxes and shafts.

The hierarchy is a binary tree over primitives given as arrays: axis-aligned boxes (M, 2, 3),
a kind per primitive and that kind's geometry (triangles, whole ellipsoids, flat convex quads;
anything else is tested by a caller's function). It is stored as flat numpy arrays in heap
order (node i has children 2 i + 1 and 2 i + 2, every leaf at the same depth) and built level by
level, all nodes of a level at once, by the median split along the longest axis of the node's
centroid box ("EqualCounts" of Pharr, Jakob & Humphreys, "Physically Based Rendering", 4th ed.,
section 7.3; the median-split hierarchy goes back to Kay & Kajiya, "Ray tracing complex scenes",
SIGGRAPH 1986). Median splits keep the tree balanced, so its shape depends on M only and
`refit` after moved primitives only recomputes the node boxes, bottom-up.

Queries are batched over all queries at once:

- `BVH.segments_blocked` runs one traversal stack per segment, all stacks popped together (one
  node per live segment per step, the nearer child on top, a segment leaves as soon as it is
  blocked), then the exact tests: Moeller & Trumbore, "Fast, minimum storage ray/triangle
  intersection" (J. Graphics Tools 2(1), 1997) for triangles, the stable quadratic for
  ellipsoids in their unit frame, and the plane hit plus inside-all-edges test for flat quads
  (the same tolerances as `core.occlusion.Occluders`);
- `BVH.box_candidates` and `BVH.shaft_candidates` descend level by level with a frontier of
  (query, node) pairs and return sparse (query, primitive) pairs: the primitives whose box meets
  the query box (and, for shafts, whose bounding ball meets the capsule around a segment), the
  test `core.visibility.ShaftTest` makes today against every occluder.

Each query records the nodes visited and the primitives tested in `BVH.stats`.

A segment p -> q is blocked by a primitive it crosses at p + t (q - p) with t in (0, 1) at a
distance > eps (m) from both endpoints (endpoints usually lie on surfaces); tangent touches of
ellipsoids (chords shorter than ~1e-7 of the unit shape) and segments in a triangle's or quad's
plane do not count, and shared triangle and quad edges block from both sides.
"""

import threading

import numpy as np

from . import ragged
from .kinds import MESH, POLYGON, SPHERE
from .occlusion import open_hit, segment_hits_flat_quad

TRIANGLE = MESH  # a triangle (of a mesh)
QUAD = POLYGON  # a flat convex quad
EXTERNAL = -1  # a primitive tested by the caller's `external` function
KINDS = {TRIANGLE: "triangle", SPHERE: "ellipsoid", QUAD: "quad", EXTERNAL: "external"}

LEAF_SIZE = 4  # most primitives per leaf
GRAZE = 1e-7  # ellipsoid chords shorter than this (unit-shape units) are tangent touches
BARY_TOL = 1e-9  # triangle barycentric slack: shared edges block from both sides
QUAD_TOL = 1e-12  # quad inside tolerance, relative to the scene size
PAD = 2e-9  # box padding of computed primitive boxes, relative to the primitive's size
FLAT_TOL = 1e-9  # quad corners off their plane by more than this (relative to the quad) are not flat
QUERY_CHUNK = 4096  # queries descended at once by the candidate queries
PAIR_BUDGET = 1 << 20  # (segment, primitive) pairs tested at once, (query, node) pairs descended at once
SEGMENT_CHUNK = 1 << 16  # segments traversed at once


# --------------------------------------------------------------------------- small helpers
def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _norm(v):
    """Euclidean lengths along the last axis, shape (...,)."""
    return np.sqrt(_dot(v, v))


def _inverse(D):
    """Componentwise 1 / D, with 1e200 where |D| < 1e-200 (a segment parallel to a slab).

    With the huge inverse the slab interval is all t (start inside the slab) or far outside
    [0, 1] (start outside), so no inf - inf or 0 * inf arises.
    """
    return np.divide(1.0, D, out=np.full(D.shape, 1e200), where=np.abs(D) > 1e-200)


def _slab(o, inv, lo, hi):
    """Slab test of the closed segment o + t D, t in [0, 1], against closed boxes [lo, hi].

    Parameters
    ----------
    o, inv : ndarray, shape (..., 3)
        Start (m) and `_inverse` of the direction (1/m), broadcast against the boxes.
    lo, hi : ndarray, shape (..., 3)

    Returns
    -------
    meet : ndarray of bool, shape (...)
    near : ndarray, shape (...)
        Entry parameter, in [0, 1] where meet.
    """
    near, far = 0.0, 1.0
    with np.errstate(over="ignore", invalid="ignore"):
        # (component by component: a reduction over an axis of 3 costs more than the arithmetic)
        for i in range(3):
            t1 = (lo[..., i] - o[..., i]) * inv[..., i]
            t2 = (hi[..., i] - o[..., i]) * inv[..., i]
            near = np.maximum(near, np.minimum(t1, t2))
            far = np.minimum(far, np.maximum(t1, t2))
    return near <= far, near


def _boxes_meet(lo1, hi1, lo2, hi2):
    """Whether closed boxes [lo1, hi1] and [lo2, hi2] (..., 3) meet, shape (...) bool."""
    meet = (lo1[..., 0] <= hi2[..., 0]) & (hi1[..., 0] >= lo2[..., 0])
    for i in (1, 2):
        meet &= (lo1[..., i] <= hi2[..., i]) & (hi1[..., i] >= lo2[..., i])
    return meet


def _capsule_gap(center, p, q):
    """Distance (m) from points `center` (..., 3) to the segments p -> q (..., 3)."""
    d = q - p
    dd = _dot(d, d)
    t = np.divide(_dot(center - p, d), dd, out=np.zeros(dd.shape), where=dd > 0.0)
    closest = p + np.clip(t, 0.0, 1.0)[..., None] * d
    diff = center - closest
    return np.sqrt(_dot(diff, diff))


def _float_array(value, shape, name):
    """`value` as a finite float64 array of the given shape (None for any length there)."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, array.shape)):
        text = ", ".join("M" if s is None else str(s) for s in shape)
        raise ValueError(f"{name} must have shape ({text}), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return array


# --------------------------------------------------------------------------- primitive boxes
def triangle_boxes(triangles):
    """Padded boxes of triangles.

    Parameters
    ----------
    triangles : array_like, shape (T, 3, 3)
        Corners (m) of each triangle.

    Returns
    -------
    ndarray, shape (T, 2, 3)
        (min, max) corners (m), padded by PAD times the triangle's size so that hits accepted
        with the barycentric slack lie inside.
    """
    V = _float_array(triangles, (None, 3, 3), "triangles")
    return _padded(V.min(1), V.max(1))


def ellipsoid_boxes(linear, offset):
    """Padded boxes of the ellipsoids {linear @ p + offset : |p| = 1}.

    The half-extent along axis i is the length of row i of `linear`.

    Parameters
    ----------
    linear : array_like, shape (E, 3, 3)
    offset : array_like, shape (E, 3)
        Centres (m).

    Returns
    -------
    ndarray, shape (E, 2, 3)
    """
    L = _float_array(linear, (None, 3, 3), "ellipsoid linear maps")
    o = _float_array(offset, (L.shape[0], 3), "ellipsoid offsets")
    half = np.sqrt(_dot(L, L))
    return _padded(o - half, o + half)


def quad_boxes(quads):
    """Padded boxes of flat quads, corners (Q, 4, 3) in polygon order; returns (Q, 2, 3)."""
    V = _float_array(quads, (None, 4, 3), "quads")
    return _padded(V.min(1), V.max(1))


def _padded(lo, hi):
    """Boxes (K, 2, 3) from corners grown by PAD times their size (plus rounding of the coordinates)."""
    size = np.sqrt(_dot(hi - lo, hi - lo))
    pad = (PAD * size + 1e-15 * np.maximum(np.abs(lo).max(-1), np.abs(hi).max(-1)))[:, None]
    return np.stack([lo - pad, hi + pad], 1)


# --------------------------------------------------------------------------- the hierarchy
class BVH:
    """A bounding volume hierarchy over occluding primitives, with batched exact queries.

    Parameters
    ----------
    boxes : array_like, shape (M, 2, 3)
        (min, max) corners (m) of each primitive's box. It must hold every hit the exact test
        of the primitive accepts (see `triangle_boxes`, `ellipsoid_boxes`, `quad_boxes`).
    kind : array_like of int, shape (M,)
        TRIANGLE, SPHERE (a whole ellipsoid), QUAD (flat convex quad) or EXTERNAL.
    index : array_like of int, shape (M,)
        Row of each primitive in its kind's geometry array (ignored for EXTERNAL).
    triangles : array_like, shape (T, 3, 3), optional
    ellipsoids : (array_like, array_like), shapes (E, 3, 3) and (E, 3), optional
        Linear maps and offsets: the ellipsoid is {linear @ p + offset : |p| = 1}.
    quads : array_like, shape (Q, 4, 3), optional
        Corners in polygon order (p00, p10, p11, p01 of a `core.Quad`); flat and convex. A
        triangle may repeat a corner.
    object_id : array_like of int, shape (M,), optional
        Scene object of each primitive (for `exclude`); default: primitive m is object m.
    balls : (array_like, array_like), shapes (M, 3) and (M,), optional
        Bounding balls (centre, radius in m) for the shaft test; default: each box's ball.
    external : callable, optional
        external(p, q, primitive) -> bool array (K,), for segments p, q (K, 3) and primitive
        ids (K,) of EXTERNAL primitives (e.g. `core.occlusion.Occluders.blocked`, which applies
        its own endpoint tolerance). Required if any primitive is EXTERNAL.
    tolerance : array_like, shape (M,), optional
        Extra endpoint tolerance (m) per primitive, added to a query's eps (e.g. twice the chord
        error of a proxy triangle mesh); default 0.
    planes : (array_like, array_like, array_like), shapes (M, 3), (M,), (M,), optional
        Unit normal n, offset d (n . x = d) and a flag per primitive that lies in that plane:
        nodes whose primitives all lie in one plane let `shaft_candidates` drop them at once
        when both ends of a query lie on one side (see its `ends`).
    leaf_size : int, optional
        Most primitives per leaf.

    Attributes
    ----------
    M : int
        Number of primitives.
    depth : int
        Levels below the root; the leaves are the 2**depth nodes of the last level.
    node_box : ndarray, shape (N, 2, 3)
        Box of each node (N = 2**(depth + 1) - 1, heap order); empty leaves hold an inverted box.
    node_center, node_radius : ndarray, shapes (N, 3) and (N,)
        A ball holding the bounding balls of every primitive below the node.
    child : ndarray of int, shape (N, 2)
        Children of each node, -1 for leaves.
    start, count : ndarray of int, shape (N,)
        Primitives below node i are order[start[i] : start[i] + count[i]].
    order : ndarray of int, shape (M,)
        Primitive ids in tree order.
    scale : float
        Diagonal (m) of the box holding all primitives (1 for an empty scene).
    stats : dict
        Counters of the last query: "queries", "nodes" (nodes whose box was tested against a
        query) and "primitives" (exact primitive tests, or primitive box/ball tests).
    totals : dict
        The same counters summed over every query since construction (safe with threads).
    """

    def __init__(
        self,
        boxes,
        kind,
        index=None,
        *,
        triangles=None,
        ellipsoids=None,
        quads=None,
        object_id=None,
        balls=None,
        external=None,
        tolerance=None,
        planes=None,
        leaf_size=LEAF_SIZE,
    ):
        # check the primitives
        if isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer)) or leaf_size < 1:
            raise ValueError(f"leaf_size must be a positive integer, got {leaf_size!r}")
        self.leaf_size = int(leaf_size)
        boxes = _float_array(boxes, (None, 2, 3), "boxes")
        M = self.M = boxes.shape[0]
        if np.any(boxes[:, 0] > boxes[:, 1]):
            raise ValueError("boxes must have min <= max on every axis")
        self.kind = self._int_array(kind, M, "kind")
        unknown = set(np.unique(self.kind).tolist()) - set(KINDS)
        if unknown:
            raise ValueError(
                f"unknown primitive kinds {sorted(unknown)}: use TRIANGLE, SPHERE, QUAD or EXTERNAL"
                " (disks, cylinders and patches are EXTERNAL with a test function)"
            )
        self.index = np.zeros(M, dtype=np.int64) if index is None else self._int_array(index, M, "index")
        self.object_id = np.arange(M) if object_id is None else self._int_array(object_id, M, "object_id")
        if np.any(self.kind == EXTERNAL) and not callable(external):
            raise ValueError("EXTERNAL primitives need an `external` test function")
        self.external = external
        if tolerance is None:
            self.tolerance = np.zeros(M)
        else:
            self.tolerance = _float_array(tolerance, (M,), "tolerance")
            if np.any(self.tolerance < 0.0):
                raise ValueError("tolerance must be >= 0")
        self._set_geometry(triangles, ellipsoids, quads)
        self.boxes = boxes.copy()
        self.center, self.radius = self._checked_balls(balls, self.boxes)
        self.scale = self._scale()
        # build the tree, then its boxes and balls
        self._build()
        self._pack()
        self._refit_nodes()
        self._node_planes(planes)
        self.stats = dict(queries=0, nodes=0, primitives=0)
        self.totals = dict(queries=0, nodes=0, primitives=0)
        self._lock = threading.Lock()

    def _record(self, stats):
        """Keep `stats` as the last query's counters and add them to `totals`."""
        with self._lock:
            self.stats = stats
            for key, value in stats.items():
                self.totals[key] += value

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_primitives(
        cls, triangles=None, ellipsoids=None, quads=None, object_id=None, tolerance=None, leaf_size=LEAF_SIZE
    ):
        """A hierarchy over triangles, ellipsoids and quads, with boxes computed from them.

        Primitive ids run over the triangles first, then the ellipsoids, then the quads.

        Parameters
        ----------
        triangles : array_like, shape (T, 3, 3), optional
        ellipsoids : (array_like, array_like), shapes (E, 3, 3) and (E, 3), optional
        quads : array_like, shape (Q, 4, 3), optional
        object_id : array_like of int, shape (T + E + Q,), optional
        tolerance : array_like, shape (T + E + Q,), optional
        leaf_size : int, optional

        Returns
        -------
        BVH
        """
        parts = cls._computed_boxes(triangles, ellipsoids, quads)
        boxes = np.concatenate([b for _, b in parts]) if parts else np.zeros((0, 2, 3))
        kind = np.concatenate([np.full(len(b), k) for k, b in parts]) if parts else np.zeros(0, int)
        index = np.concatenate([np.arange(len(b)) for _, b in parts]) if parts else np.zeros(0, int)
        balls = None
        if ellipsoids is not None:
            # an ellipsoid's own ball (centre, largest singular value) where it is smaller
            center = 0.5 * (boxes[:, 0] + boxes[:, 1])
            radius = 0.5 * np.sqrt(_dot(boxes[:, 1] - boxes[:, 0], boxes[:, 1] - boxes[:, 0]))
            L, o = (np.asarray(x, dtype=np.float64) for x in ellipsoids)
            if L.size:
                own = np.linalg.norm(L, 2, axis=(1, 2)) * (1.0 + 1e-12)
                sel = np.flatnonzero(kind == SPHERE)
                smaller = own < radius[sel]
                center[sel[smaller]], radius[sel[smaller]] = o[smaller], own[smaller]
            balls = (center, radius)
        return cls(
            boxes,
            kind,
            index,
            triangles=triangles,
            ellipsoids=ellipsoids,
            quads=quads,
            object_id=object_id,
            balls=balls,
            tolerance=tolerance,
            leaf_size=leaf_size,
        )

    @staticmethod
    def _computed_boxes(triangles, ellipsoids, quads):
        parts = []
        if triangles is not None:
            parts.append((TRIANGLE, triangle_boxes(triangles)))
        if ellipsoids is not None:
            parts.append((SPHERE, ellipsoid_boxes(*ellipsoids)))
        if quads is not None:
            parts.append((QUAD, quad_boxes(quads)))
        return parts

    @staticmethod
    def _int_array(value, M, name):
        array = np.asarray(value)
        if array.shape != (M,) or not (np.issubdtype(array.dtype, np.integer) or array.size == 0):
            raise ValueError(
                f"{name} must be an integer array of shape ({M},), got {array.dtype} {array.shape}"
            )
        return array.astype(np.int64)

    def _set_geometry(self, triangles, ellipsoids, quads):
        """Check the geometry of each kind (nothing changes if it is bad), then store it."""
        for key, value in self._checked_geometry(triangles, ellipsoids, quads).items():
            setattr(self, key, value)

    def _checked_geometry(self, triangles, ellipsoids, quads):
        """Copies of the geometry arrays and the exact tests' data of each kind, as a dict."""
        # triangles: corner v0, edges e1, e2, normal e1 x e2 and |e1| |e2|
        T = np.zeros((0, 3, 3)) if triangles is None else _float_array(triangles, (None, 3, 3), "triangles")
        T = T.copy()
        e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
        tri = dict(
            v0=T[:, 0], e1=e1, e2=e2, normal=np.cross(e1, e2), scale=np.sqrt(_dot(e1, e1) * _dot(e2, e2))
        )
        # ellipsoids: inverse maps to the unit sphere
        if ellipsoids is None:
            L, o = np.zeros((0, 3, 3)), np.zeros((0, 3))
        else:
            if len(ellipsoids) != 2:
                raise ValueError("ellipsoids must be a pair (linear (E, 3, 3), offset (E, 3))")
            L = _float_array(ellipsoids[0], (None, 3, 3), "ellipsoid linear maps").copy()
            o = _float_array(ellipsoids[1], (L.shape[0], 3), "ellipsoid offsets").copy()
        if L.size:
            sv = np.linalg.svd(L, compute_uv=False)
            if np.any(sv[:, -1] <= 1e-12 * sv[:, 0]) or np.any(sv[:, 0] == 0.0):
                raise ValueError("ellipsoid linear maps must be invertible (a flat ellipsoid is a disk)")
        ell = dict(inverse=np.linalg.inv(L) if L.size else L, offset=o)
        # quads: unit normal, plane offset, edges; checked flat, convex and of positive area
        V = np.zeros((0, 4, 3)) if quads is None else _float_array(quads, (None, 4, 3), "quads").copy()
        normal = np.cross(V[:, 2] - V[:, 0], V[:, 3] - V[:, 1])
        area2 = np.sqrt(_dot(normal, normal))
        size = np.sqrt(_dot(V.max(1) - V.min(1), V.max(1) - V.min(1)))
        if np.any(area2 <= 1e-12 * size**2) or np.any(size == 0.0):
            raise ValueError("quads must have a positive area")
        unit = normal / np.where(area2 > 0.0, area2, 1.0)[:, None]
        offset = _dot(unit, V.mean(1))
        if np.any(np.abs(_dot(unit[:, None], V) - offset[:, None]) > FLAT_TOL * size[:, None]):
            raise ValueError("quads must be flat (corners on one plane); curved quads are EXTERNAL")
        edges = np.roll(V, -1, axis=1) - V
        turn = _dot(unit[:, None], np.cross(edges, np.roll(edges, -1, axis=1)))
        if np.any(turn < -1e-12 * size[:, None] ** 2):
            raise ValueError("quads must be convex, with corners in polygon order")
        quad = dict(vertices=V, edges=edges, edge_length=_norm(edges), normal=unit, offset=offset)
        # every primitive's row exists in its kind's arrays
        for code, rows in ((TRIANGLE, len(T)), (SPHERE, len(L)), (QUAD, len(V))):
            sel = self.index[self.kind == code]
            if sel.size and (sel.min() < 0 or sel.max() >= rows):
                raise ValueError(f"index of {KINDS[code]} primitives must be in 0 .. {rows - 1}")
        return dict(triangles=T, ellipsoids=(L, o), quads=V, _tri=tri, _ell=ell, _quad=quad)

    def _checked_balls(self, balls, boxes):
        """Bounding balls (centre (M, 3), radius (M,)): the given ones, checked, or the boxes' balls."""
        if balls is None:
            lo, hi = boxes[:, 0], boxes[:, 1]
            return 0.5 * (lo + hi), 0.5 * _norm(hi - lo)
        center = _float_array(balls[0], (self.M, 3), "ball centres").copy()
        radius = _float_array(balls[1], (self.M,), "ball radii").copy()
        if np.any(radius < 0.0):
            raise ValueError("ball radii must be >= 0")
        return center, radius

    def _scale(self):
        if self.M == 0:
            return 1.0
        scale = float(np.linalg.norm(self.boxes[:, 1].max(0) - self.boxes[:, 0].min(0)))
        return scale if scale > 0.0 else 1.0

    def _build(self):
        """Median splits along the longest axis of each node's centroid box, a level at a time."""
        M, leaf = self.M, self.leaf_size
        order = np.arange(M)
        c = 0.5 * (self.boxes[:, 0] + self.boxes[:, 1])  # centroids, kept in tree order
        start, count = np.zeros(1, dtype=np.int64), np.array([M], dtype=np.int64)
        starts, counts = [start], [count]
        while count.max() > leaf:
            # every range is non-empty here (sizes differ by at most one and the largest is > 1)
            rows = np.arange(start.size)
            low = np.minimum.reduceat(c, start)
            spread = np.maximum.reduceat(c, start) - low
            axis = np.argmax(spread, axis=1)
            node = np.repeat(rows, count)
            # sort within each node along its axis: one argsort of node + (position in [0, 1/2])
            # (node < 2**22 leaves ~30 bits for the position; stable: ties keep the previous order)
            width = np.where(spread[rows, axis] > 0.0, spread[rows, axis], 1.0)
            fraction = (c[np.arange(M), axis[node]] - low[rows, axis][node]) / width[node]
            perm = np.argsort(node + 0.5 * fraction, kind="stable")
            order, c = order[perm], c[perm]
            # children: the lower half (rounded down) and the rest
            half = count // 2
            start = np.stack([start, start + half], 1).ravel()
            count = np.stack([half, count - half], 1).ravel()
            starts.append(start)
            counts.append(count)
        self.order = order
        self.depth = len(starts) - 1
        self.start, self.count = np.concatenate(starts), np.concatenate(counts)
        N = self.start.size
        self.child = np.full((N, 2), -1, dtype=np.int64)
        internal = np.arange(N - (1 << self.depth))
        self.child[internal] = 2 * internal[:, None] + np.array([1, 2])

    def _pack(self):
        """Reorder each kind's test data into tree order (a leaf's rows are adjacent in memory).

        Primitive m's row in the reordered data is _row[m]; _tree holds kind, row, object and
        tolerance by position in tree order.
        """
        self._row = self.index.copy()
        for code, data in ((TRIANGLE, self._tri), (SPHERE, self._ell), (QUAD, self._quad)):
            prims = self.order[self.kind[self.order] == code]
            rows = self.index[prims]
            for key, value in data.items():
                data[key] = value[rows]
            self._row[prims] = np.arange(prims.size)
        # per-primitive data read by the traversal, by position in tree order
        self._tree = dict(
            kind=self.kind[self.order],
            row=self._row[self.order],
            object_id=self.object_id[self.order],
            tolerance=self.tolerance[self.order],
        )

    def _refit_nodes(self):
        """Node boxes and balls from the primitives', from the leaves up."""
        N, D = self.start.size, self.depth
        self.node_box = np.empty((N, 2, 3))
        self.node_box[:, 0], self.node_box[:, 1] = np.inf, -np.inf
        self.node_center = np.zeros((N, 3))
        self.node_radius = np.zeros(N)
        if self.M == 0:
            return
        leaves = np.arange((1 << D) - 1, N)
        full = leaves[self.count[leaves] > 0]
        box = self.boxes[self.order]
        at = self.start[full]
        self.node_box[full, 0] = np.minimum.reduceat(box[:, 0], at)
        self.node_box[full, 1] = np.maximum.reduceat(box[:, 1], at)
        # leaf balls: centred on the box, holding each primitive's ball
        self.node_center[full] = 0.5 * (self.node_box[full, 0] + self.node_box[full, 1])
        owner = np.repeat(full, self.count[full])
        reach = _norm(self.center[self.order] - self.node_center[owner])
        self.node_radius[full] = np.maximum.reduceat(reach + self.radius[self.order], at)
        for level in range(D - 1, -1, -1):
            nodes = np.arange((1 << level) - 1, (1 << (level + 1)) - 1)
            a, b = self.child[nodes, 0], self.child[nodes, 1]
            self.node_box[nodes, 0] = np.minimum(self.node_box[a, 0], self.node_box[b, 0])
            self.node_box[nodes, 1] = np.maximum(self.node_box[a, 1], self.node_box[b, 1])
            c = self.node_center[nodes] = 0.5 * (self.node_box[nodes, 0] + self.node_box[nodes, 1])
            reach = [
                np.where(self.count[k] > 0, _norm(self.node_center[k] - c) + self.node_radius[k], 0.0)
                for k in (a, b)
            ]
            self.node_radius[nodes] = np.maximum(*reach)
        # rounding slack: a node's ball holds its primitives' balls
        self.node_radius *= 1.0 + 1e-12
        self.node_radius += 1e-12 * self.scale

    def _node_planes(self, planes):
        """node_planar (N,), node_normal (N, 3), node_offset (N,): nodes whose primitives all lie
        in one plane (normals and offsets equal to 1e-12, up to sign), and that plane."""
        N = self.start.size
        self.node_planar = np.zeros(N, dtype=bool)
        self.node_normal = np.zeros((N, 3))
        self.node_offset = np.zeros(N)
        if planes is None or self.M == 0:
            return
        normal = _float_array(planes[0], (self.M, 3), "plane normals")
        offset = _float_array(planes[1], (self.M,), "plane offsets")
        flag = np.asarray(planes[2], dtype=bool).reshape(self.M)
        nodes = np.flatnonzero(self.count > 0)
        owner, position = ragged.expand(self.start[nodes], self.count[nodes])
        m = self.order[position]
        first = self.order[self.start[nodes]][owner]
        sign = np.where(_dot(normal[m], normal[first]) < 0.0, -1.0, 1.0)
        same = flag[m] & (_norm(sign[:, None] * normal[m] - normal[first]) <= 1e-12)
        same &= np.abs(sign * offset[m] - offset[first]) <= 1e-12 * self.scale
        at = ragged.starts(self.count[nodes])
        self.node_planar[nodes] = np.logical_and.reduceat(same, at)
        self.node_normal[nodes] = normal[self.order[self.start[nodes]]]
        self.node_offset[nodes] = offset[self.order[self.start[nodes]]]

    def refit(self, boxes=None, *, triangles=None, ellipsoids=None, quads=None, balls=None):
        """Update the primitives after they moved, keeping the tree's topology.

        Geometry arrays replace the old ones of their kind (same shapes). Boxes not given are
        recomputed from the new geometry of TRIANGLE, SPHERE and QUAD primitives (as in
        `from_primitives`); EXTERNAL primitives keep their boxes unless `boxes` is given. The
        queries stay exact after any move; only their speed depends on how far the primitives
        moved from where the tree was built (build a new BVH after large changes).

        Parameters
        ----------
        boxes : array_like, shape (M, 2, 3), optional
        triangles, ellipsoids, quads : as in `BVH`, optional
        balls : (array_like, array_like), optional
            New bounding balls; default: each new box's ball.
        """
        old = (self.triangles, self.ellipsoids, self.quads)
        new = [x if x is not None else o for x, o in zip((triangles, ellipsoids, quads), old)]
        shapes = [np.shape(old[0]), (np.shape(old[1][0]), np.shape(old[1][1])), np.shape(old[2])]
        given = [np.shape(new[0]), (np.shape(new[1][0]), np.shape(new[1][1])), np.shape(new[2])]
        if shapes != given:
            raise ValueError("refit keeps the number of primitives: geometry shapes must not change")
        # check everything first: a bad argument leaves the hierarchy as it was
        geometry = self._checked_geometry(*new)
        if boxes is not None:
            new_boxes = _float_array(boxes, (self.M, 2, 3), "boxes").copy()
            if np.any(new_boxes[:, 0] > new_boxes[:, 1]):
                raise ValueError("boxes must have min <= max on every axis")
        else:
            new_boxes = self.boxes.copy()
            for code, part in self._computed_boxes(triangles, ellipsoids, quads):
                sel = np.flatnonzero(self.kind == code)
                new_boxes[sel] = part[self.index[sel]]
        center, radius = self._checked_balls(balls, new_boxes)
        # then update the primitives and the node boxes
        for key, value in geometry.items():
            setattr(self, key, value)
        self.boxes, self.center, self.radius = new_boxes, center, radius
        self._pack()
        self.scale = self._scale()
        self._refit_nodes()
        self.node_planar[:] = False  # (moved primitives: their planes are not known any more)

    # ------------------------------------------------------------------ segment queries
    def _segments(self, p, q, eps, exclude):
        """Checked segment arrays: p, q (R, 3), eps (R,), exclude (R, 2)."""
        p = np.asarray(p, dtype=np.float64)
        p = _float_array(p.reshape(-1, 3) if p.ndim == 1 and p.size == 3 else p, (None, 3), "p")
        q = _float_array(q, p.shape, "q")
        R = p.shape[0]
        eps = np.asarray(eps, dtype=np.float64)
        if eps.ndim > 1 or (eps.ndim == 1 and eps.shape != (R,)):
            raise ValueError(f"eps must be a scalar or of shape ({R},), got {eps.shape}")
        if not np.all(np.isfinite(eps)) or np.any(eps < 0.0):
            raise ValueError("eps must be finite and >= 0")
        eps = np.broadcast_to(eps, (R,))
        return p, q, eps, self._exclusions(exclude, R)

    @staticmethod
    def _exclusions(exclude, R):
        """Excluded object ids as an integer array of shape (R, 2) (-1 for none)."""
        if exclude is None:
            return np.full((R, 2), -1, dtype=np.int64)
        array = np.asarray(exclude)
        if array.ndim == 1:
            array = np.stack([array, np.full(array.shape, -1)], 1) if array.size else array.reshape(0, 2)
        if array.shape != (R, 2) or not (np.issubdtype(array.dtype, np.integer) or array.size == 0):
            raise ValueError(
                f"exclude must be an integer array of shape ({R},) or ({R}, 2),"
                f" got {array.dtype} {array.shape}"
            )
        return array.astype(np.int64)

    @staticmethod
    def _kept(obj, excluded):
        """Primitives of objects obj (P,) that are none of the excluded ids (P, 2)."""
        return (obj != excluded[:, 0]) & (obj != excluded[:, 1])

    def segments_blocked(self, p, q, eps, exclude=None):
        """Whether each open segment p -> q crosses any primitive.

        Parameters
        ----------
        p, q : array_like, shape (R, 3)
            Endpoints (m); they may lie on primitives.
        eps : float or array_like, shape (R,)
            Endpoint tolerance (m): crossings within eps (plus the primitive's `tolerance`) of
            either end do not count.
        exclude : array_like of int, shape (R,) or (R, 2), optional
            One or two object ids per segment whose primitives are ignored: the convex surfaces
            the segment leaves (and arrives at), which it cannot cross again. Pass -1 (or an id
            no primitive has) for none, and never the id of a non-convex object.

        Returns
        -------
        ndarray of bool, shape (R,)

        Raises
        ------
        ValueError
            On shapes that do not match, NaN or inf coordinates, or a negative eps.
        """
        p, q, eps, exclude = self._segments(p, q, eps, exclude)
        R = p.shape[0]
        blocked = np.zeros(R, dtype=bool)
        stats = dict(queries=R, nodes=0, primitives=0)
        if self.M:
            for s in range(0, R, SEGMENT_CHUNK):
                part = slice(s, s + SEGMENT_CHUNK)
                blocked[part] = self._blocked_chunk(p[part], q[part], eps[part], exclude[part], stats)
        self._record(stats)
        return blocked

    def _blocked_chunk(self, p, q, eps, exclude, stats):
        """segments_blocked for up to SEGMENT_CHUNK segments (the stacks are (R, depth + 2))."""
        R = p.shape[0]
        blocked = np.zeros(R, dtype=bool)
        D = q - p
        length = np.sqrt(_dot(D, D))
        inv = _inverse(D)
        # one stack per segment, all popped together; the root's box first
        meet, _ = _slab(p, inv, self.node_box[0, 0], self.node_box[0, 1])
        stats["nodes"] += R
        stack = np.zeros((R, self.depth + 2), dtype=np.int64)
        top = np.where(meet & (length > 0.0), 1, 0)
        live = np.flatnonzero(top)
        nodes, tested = 0, 0
        # (flat indices and np.take below: fancy indexing of these small tables cost more than
        # the box tests themselves)
        width, flat_stack = stack.shape[1], stack.reshape(-1)
        while live.size:
            top[live] -= 1
            node = flat_stack[live * width + top[live]]
            leaf = self.child[node, 0] < 0
            # internal nodes: test both children's boxes, push the hit ones, the nearer on top
            k, n = live[~leaf], node[~leaf]
            if k.size:
                c = np.take(self.child, n, axis=0)
                box = np.take(self.node_box, c, axis=0)
                start, inverse = np.take(p, k, axis=0)[:, None], np.take(inv, k, axis=0)[:, None]
                hit, near = _slab(start, inverse, box[:, :, 0], box[:, :, 1])
                hit &= np.take(self.count, c) > 0
                nodes += 2 * k.size
                first = (near[:, 1] < near[:, 0]).astype(np.int64)  # index of the nearer child
                at = 2 * np.arange(k.size)
                hit, c = hit.reshape(-1), c.reshape(-1)
                for slot in (1 - first, first):
                    push = np.flatnonzero(hit[at + slot])
                    kk = k[push]
                    flat_stack[kk * width + top[kk]] = c[at[push] + slot[push]]
                    top[kk] += 1
            # leaves: exact tests of their primitives
            k, n = live[leaf], node[leaf]
            if k.size:
                owner, position = ragged.expand(self.start[n], self.count[n])
                seg = k[owner]
                tree = self._tree
                keep = self._kept(tree["object_id"][position], exclude[seg])
                seg, position = seg[keep], position[keep]
                tested += seg.size
                hit = self._exact(
                    np.take(p, seg, axis=0),
                    np.take(D, seg, axis=0),
                    length[seg],
                    eps[seg] + tree["tolerance"][position],
                    tree["kind"][position],
                    tree["row"][position],
                    self.order[position],
                )
                blocked[seg[hit]] = True
            live = live[(top[live] > 0) & ~blocked[live]]
        stats["nodes"] += nodes
        stats["primitives"] += tested
        return blocked

    def pair_blocked(self, p, q, primitive, eps):
        """Exact test of explicit (segment, primitive) pairs, without the tree.

        Parameters
        ----------
        p, q : array_like, shape (K, 3)
        primitive : array_like of int, shape (K,)
            Primitive id of each pair, in 0 .. M - 1.
        eps : float or array_like, shape (K,)

        Returns
        -------
        ndarray of bool, shape (K,)
            Whether segment k crosses primitive[k] (same rule as `segments_blocked`).
        """
        p, q, eps, _ = self._segments(p, q, eps, None)
        prim = np.broadcast_to(np.asarray(primitive), (p.shape[0],)) if np.ndim(primitive) == 0 else primitive
        prim = self._int_array(prim, p.shape[0], "primitive")
        if prim.size and (prim.min() < 0 or prim.max() >= self.M):
            raise ValueError(f"primitive ids must be in 0 .. {self.M - 1}")
        D = q - p
        return self._exact(
            p, D, np.sqrt(_dot(D, D)), eps + self.tolerance[prim], self.kind[prim], self._row[prim], prim
        )

    def _exact(self, o, D, length, eps, kind, row, prim):
        """Exact tests of (segment, primitive) pairs, one kind at a time, in batches.

        kind, row and prim (P,) are each pair's primitive kind, row in its kind's packed test
        data and primitive id (for the external test).
        """
        hit = np.zeros(prim.size, dtype=bool)
        tests = {TRIANGLE: self._triangle, SPHERE: self._ellipsoid, QUAD: self._flat_quad}
        for code, test in tests.items():
            idx = np.flatnonzero((kind == code) & (length > 0.0))
            for s in range(0, idx.size, PAIR_BUDGET):
                i = idx[s : s + PAIR_BUDGET]
                hit[i] = test(o[i], D[i], length[i], eps[i], row[i])
        idx = np.flatnonzero(kind == EXTERNAL)
        if idx.size:
            ends = o[idx] + D[idx]
            result = np.asarray(self.external(o[idx], ends, prim[idx]), dtype=bool)
            if result.shape != (idx.size,):
                raise ValueError(f"external test returned shape {result.shape}, expected ({idx.size},)")
            hit[idx] = result
        return hit

    def _triangle(self, o, D, length, eps, row):
        """Moeller & Trumbore (1997): with T = o - v0, N = e1 x e2, C = D x T and det = -D . N,
        barycentrics a = -e2 . C / det, b = e1 . C / det and t = T . N / det."""
        tri = self._tri
        N = np.take(tri["normal"], row, axis=0)
        T = o - np.take(tri["v0"], row, axis=0)
        C = np.cross(D, T)
        det = -_dot(D, N)
        # degenerate triangles and segments within ~1e-13 rad of the plane never block
        ok = np.abs(det) > 1e-13 * tri["scale"][row] * length
        inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
        a = -_dot(np.take(tri["e2"], row, axis=0), C) * inv
        b = _dot(np.take(tri["e1"], row, axis=0), C) * inv
        t = _dot(T, N) * inv
        ok &= (a >= -BARY_TOL) & (b >= -BARY_TOL) & (a + b <= 1.0 + BARY_TOL)
        return ok & open_hit(t, length, eps)

    def _ellipsoid(self, o, D, length, eps, row):
        """Unit sphere |p| = 1 after p = L^-1 (x - offset): a t^2 + 2 b t + c = 0.

        Stable roots q / a and c / q with q = -(b + sign(b) sqrt(b^2 - a c)); chords shorter
        than GRAZE in the unit frame (2 sqrt(b^2 - a c) / sqrt(a)) are tangent touches.
        """
        inverse = np.take(self._ell["inverse"], row, axis=0)
        ol = np.einsum("kij,kj->ki", inverse, o - np.take(self._ell["offset"], row, axis=0))
        dl = np.einsum("kij,kj->ki", inverse, D)
        a, b, c = _dot(dl, dl), _dot(ol, dl), _dot(ol, ol) - 1.0
        disc = b * b - a * c
        ok = (a > 0.0) & (disc > (0.5 * GRAZE) ** 2 * a)
        root = np.sqrt(np.where(ok, disc, 0.0))
        qq = -(b + np.copysign(root, b))
        t1 = np.divide(qq, a, out=np.zeros_like(a), where=ok)
        t2 = np.divide(c, qq, out=np.zeros_like(a), where=ok & (qq != 0.0))
        return ok & (open_hit(t1, length, eps) | open_hit(t2, length, eps))

    def _flat_quad(self, o, D, length, eps, row):
        return segment_hits_flat_quad(o, D, length, eps, self._quad, row, QUAD_TOL * self.scale)

    # ------------------------------------------------------------------ candidate queries
    def box_candidates(self, lo, hi):
        """Primitives whose box meets each query box (closed boxes).

        Parameters
        ----------
        lo, hi : array_like, shape (K, 3)
            Query boxes (m).

        Returns
        -------
        query, primitive : ndarray of int, shape (C,)
            The pairs, sorted by query and then primitive id.
        """
        lo = _float_array(lo, (None, 3), "lo")
        hi = _float_array(hi, lo.shape, "hi")

        def overlap(box, k):
            return _boxes_meet(box[:, 0], box[:, 1], np.take(lo, k, axis=0), np.take(hi, k, axis=0))

        return self._descend(
            lo.shape[0],
            lambda k, n: overlap(np.take(self.node_box, n, axis=0), k),
            lambda k, m: overlap(np.take(self.boxes, m, axis=0), k),
        )

    def shaft_candidates(self, lo, hi, p, q, radius, exclude=None, ends=None, plane_eps=0.0):
        """Primitives that may block segments between two balls: the ShaftTest box and capsule test.

        A primitive is a candidate of query k if its box meets the box [lo_k, hi_k] and its
        bounding ball meets the capsule of radius radius_k around the segment p_k -> q_k
        (the distance from the ball's centre to the segment is at most the sum of the radii).

        Parameters
        ----------
        lo, hi : array_like, shape (K, 3)
            Query boxes (m), e.g. the common box of two elements.
        p, q : array_like, shape (K, 3)
            Capsule axes (m), e.g. the elements' centres.
        radius : array_like, shape (K,)
            Capsule radii (m).
        exclude : array_like of int, shape (K,) or (K, 2), optional
            One or two object ids per query whose primitives are left out (-1 for none).
        ends : (lo1, hi1, lo2, hi2), each array_like of shape (K, 3), optional
            Boxes (m) holding each query's two ends: a node whose primitives lie in one plane
            (`planes`) is dropped when both boxes lie on one side of it, within plane_eps (m)
            (less a rounding margin): no segment between the ends crosses that plane. Its
            primitives would each be dropped by the same rule, so callers that apply it per
            primitive get the same pairs, sooner.
        plane_eps : float, optional

        Returns
        -------
        query, primitive : ndarray of int, shape (C,)
            The pairs, sorted by query and then primitive id.
        """
        lo = _float_array(lo, (None, 3), "lo")
        K = lo.shape[0]
        hi, p, q = (_float_array(x, (K, 3), name) for x, name in ((hi, "hi"), (p, "p"), (q, "q")))
        radius = _float_array(radius, (K,), "radius")
        if np.any(radius < 0.0):
            raise ValueError("radius must be >= 0")
        exclude = self._exclusions(exclude, K)

        def test(box, center, r, k):
            # (np.take and the components in turn: fancy indexing and reductions over an axis
            # of 3 cost more than the tests)
            meet = _boxes_meet(box[:, 0], box[:, 1], np.take(lo, k, axis=0), np.take(hi, k, axis=0))
            gap = _capsule_gap(center, np.take(p, k, axis=0), np.take(q, k, axis=0))
            return meet & (gap <= r + radius[k])

        sides = None
        if ends is not None and self.node_planar.any():
            boxes = [_float_array(x, (K, 3), "ends") for x in ends]
            # rounding margin of the node plane against its primitives' planes (1e-12 each)
            reach = np.max([np.abs(b).max(1) for b in boxes], axis=0)
            margin = 2e-12 * (reach + self.scale)
            sides = [(0.5 * (a + b), 0.5 * (b - a)) for a, b in (boxes[:2], boxes[2:])]

        def node_test(k, n):
            box, center = np.take(self.node_box, n, axis=0), np.take(self.node_center, n, axis=0)
            keep = test(box, center, self.node_radius[n], k)
            if sides is not None:
                sel = np.flatnonzero(keep & self.node_planar[n])
                if sel.size:
                    kk, nn = k[sel], n[sel]
                    normal, e = self.node_normal[nn], plane_eps - margin[kk]
                    heights = []
                    for middle, half in sides:
                        h = _dot(middle[kk], normal) - self.node_offset[nn]
                        r = _dot(half[kk], np.abs(normal))
                        heights.append((h - r, h + r))
                    (low1, high1), (low2, high2) = heights
                    one_side = ((low1 >= -e) & (low2 >= -e)) | ((high1 <= e) & (high2 <= e))
                    keep[sel[one_side]] = False
            return keep

        return self._descend(
            K,
            node_test,
            lambda k, m: (
                test(np.take(self.boxes, m, axis=0), np.take(self.center, m, axis=0), self.radius[m], k)
                & self._kept(self.object_id[m], exclude[k])
            ),
        )

    def shaft_pairs(self, k, m, lo, hi, p, q, radius):
        """`shaft_candidates`' box and capsule test for given (query k, primitive m) pairs, each
        shape (C,): bool (C,). For callers that already hold a superset of each query's
        candidates (a point's shaft lies in its element pair's), instead of a descent.

        lo, hi, p, q : ndarray, shape (K, 3); radius : ndarray, shape (K,) (as there)
        """
        box = np.take(self.boxes, m, axis=0)
        meet = _boxes_meet(box[:, 0], box[:, 1], np.take(lo, k, axis=0), np.take(hi, k, axis=0))
        gap = _capsule_gap(np.take(self.center, m, axis=0), np.take(p, k, axis=0), np.take(q, k, axis=0))
        return meet & (gap <= self.radius[m] + radius[k])

    def _descend(self, K, node_test, primitive_test):
        """Level-by-level descent of (query, node) pairs; (query, primitive) pairs that pass.

        node_test(k, n) and primitive_test(k, m) take query indices and node (primitive) ids of
        equal shape (P,) and return bool (P,); a node test must pass wherever a primitive below
        the node passes. A frontier larger than PAIR_BUDGET is split between its queries (a work
        stack), so that memory stays bounded when queries have many candidates.
        """
        stats = dict(queries=K, nodes=0, primitives=0)
        queries, primitives = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
        if self.M == 0 or K == 0:
            self._record(stats)
            return queries[0], primitives[0]
        work = [(0, np.arange(s, min(s + QUERY_CHUNK, K)), None) for s in range(0, K, QUERY_CHUNK)]
        while work:
            level, k, n = work.pop()
            n = np.zeros(k.size, dtype=np.int64) if n is None else n
            while k.size:
                # test this level's nodes, then expand the survivors to their children
                stats["nodes"] += k.size
                keep = node_test(k, n) & (self.count[n] > 0)
                k, n = k[keep], n[keep]
                if level == self.depth:
                    break
                k, n = np.repeat(k, 2), (2 * n[:, None] + np.array([1, 2])).ravel()
                level += 1
                if k.size > PAIR_BUDGET and k[0] != k[-1]:
                    # k is sorted: hand the queries from the median one on to the work stack
                    cut = np.searchsorted(k, k[k.size // 2])
                    cut = cut if cut > 0 else np.searchsorted(k, k[0], side="right")
                    work.append((level, k[cut:], n[cut:]))
                    k, n = k[:cut], n[:cut]
            if k.size == 0:
                continue
            owner, position = ragged.expand(self.start[n], self.count[n])
            k, m = k[owner], self.order[position]
            stats["primitives"] += k.size
            keep = primitive_test(k, m)
            queries.append(k[keep])
            primitives.append(m[keep])
        self._record(stats)
        k, m = np.concatenate(queries), np.concatenate(primitives)
        sort = np.lexsort((m, k))
        return k[sort], m[sort]
