"""Segment visibility against exact surfaces: does the open segment a -> b cross an occluding patch?

Analytic shapes are intersected in closed form, vectorised over all segments at once:

- spheres and ellipsoids (`SphereGeometry`), disks (`DiskGeometry`) and cylinders
  (`CylinderGeometry`) in their local frame: an affine map x = L p + o keeps the segment
  parameter t, so the segment is mapped by L^-1 and met with the unit shape (a quadratic for the
  sphere and the cylinder, the plane z = 0 for the disk), then the hit's parameters are checked
  against the patch's domain (subpatches block only where they exist);
- flat quads and triangles (`QuadGeometry` with a plane): the plane hit and a convex-polygon
  inside test on the corners of the patch's parameter box.

A `core.PolygonMesh` is one occluder whose faces are the triangles of its own `bvh.BVH`
(`PolygonMesh.occlusion_bvh`, built once per mesh).

Anything else (NURBS, curved bilinear quads) is met as a proxy triangle mesh sampled on a
parameter grid (knot lines included), searched through a quadtree of tile boxes and
intersected by Moeller & Trumbore, "Fast, minimum storage ray/triangle intersection" (J. Graphics
Tools 2(1), 1997). The proxy's chord error (sampled at cell and edge midpoints) widens the
endpoint tolerance of those occluders.

The endpoints of a segment are usually points of patches, so crossings within `eps` (m) of
either endpoint are not counted; the front/back side of an occluder does not matter.
"""

import numpy as np

from .kinds import CYLINDER, DISK, GENERIC, MESH, NAMES, POLYGON, POLYGON_MESH, SPHERE
from .primitives import TWO_PI

QUAD = POLYGON  # a flat quad or triangle occluder
KIND_NAMES = NAMES

REL_EPS = 1e-9  # endpoint tolerance, relative to the scene size
GRAZE = 1e-7  # chords shorter than this (in units of the unit shape) are tangent touches, not crossings
ANGLE_TOL = 1e-10  # parameter-domain tolerance (rad): shared seams block from both sides
PROXY_TOL = 1e-4  # target proxy chord error, relative to the patch's bounding-box diagonal
PROXY_MIN, PROXY_MAX = 16, 128  # cells per direction of an automatic proxy grid
LEAF = 2  # proxy cells per leaf tile side (2 * LEAF**2 triangles per leaf)
BRANCH = 2  # tiles per side of a parent tile (a quadtree)
MAX_PAIRS = 32768  # (segment, tile) pairs expanded at once
TRI_BATCH = 1 << 17  # (segment, triangle) pairs tested at once: temporaries stay below ~50 MB
PAD32 = 4e-6  # proxy boxes grown by this of the largest coordinate for single-precision slab tests


# --------------------------------------------------------------------------- small helpers
def _affine_box(linear, offset, lo, hi):
    """World box (min, max) of the image of the local box [lo, hi] under x = linear @ p + offset."""
    center = linear @ (0.5 * (lo + hi)) + offset
    half = np.abs(linear) @ (0.5 * (hi - lo))
    return center - half, center + half


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _apply(matrix, x):
    """matrix (K, 3, 3) @ x (K, 3) row by row."""
    return np.einsum("kij,kj->ki", matrix, x)


def _inverse(D):
    """Componentwise 1 / D, with 1e200 for components below 1e-200 (a segment parallel to a slab).

    With the huge inverse the slab test stays right: the slab interval is all t (start inside
    the slab) or far outside [0, 1] (start outside); no inf or NaN arises for coordinates < 1e100.
    """
    return np.divide(1.0, D, out=np.full(D.shape, 1e200), where=np.abs(D) > 1e-200)


def _crosses_polytope(o, D, tolerance, normal, offset):
    """Whether segments o + t D, t in (0, 1), cross the surface of the convex polytope
    {x : normal . x <= offset}, shape (K,) bool; a crossing of a plane that either end lies
    within tolerance (m) of does not count (the ends lie on the surface there).

    Cyrus-Beck clipping (Cyrus & Beck, "Generalized two- and three-dimensional clipping",
    Computers & Graphics 3, 1978): the line is inside over [t_in, t_out], the largest entering
    and smallest leaving parameter over the planes; it crosses the surface at t_in and t_out.
    A line that only touches an edge or corner (t_in = t_out) does not cross it.

    Parameters
    ----------
    o, D : ndarray, shape (K, 3)
    tolerance : float
    normal : ndarray, shape (P, 3)
        Unit outward normals.
    offset : ndarray, shape (P,)
    """
    start = offset[None] - o @ normal.T  # (K, P) heights below each plane: >= 0 inside
    rate = D @ normal.T
    end = start - rate
    with np.errstate(divide="ignore", invalid="ignore"):
        t = start / rate
    t_enter = np.where(rate < 0.0, t, -np.inf)
    t_leave = np.where(rate > 0.0, t, np.inf)
    enter, leave = t_enter.argmax(1), t_leave.argmin(1)
    rows = np.arange(len(o))
    through = (t_enter[rows, enter] < t_leave[rows, leave]) & ~((rate == 0.0) & (start < 0.0)).any(1)
    crossed = np.zeros(len(o), dtype=bool)
    for plane, t_side in ((enter, t_enter), (leave, t_leave)):
        at = t_side[rows, plane]
        clear = (np.abs(start[rows, plane]) > tolerance) & (np.abs(end[rows, plane]) > tolerance)
        crossed |= (at > 0.0) & (at < 1.0) & clear
    return through & crossed


def _segment_box(o, inv, bmin, bmax):
    """Slab test: does the closed segment o + t D, t in [0, 1], meet the closed box [bmin, bmax]?

    Parameters
    ----------
    o, inv : sequence of 3 ndarrays (x, y, z components), each broadcastable to shape S
        Start (m) and `_inverse` of the direction D (1/m).
    bmin, bmax : sequence of 3 ndarrays, each broadcastable to shape S
        Box corners (m).

    Returns
    -------
    ndarray of bool, shape S
    """
    near, far = 0.0, 1.0
    with np.errstate(over="ignore"):
        for i in range(3):
            # the interval of t inside slab i, intersected with the running one
            t1 = (bmin[i] - o[i]) * inv[i]
            t2 = (bmax[i] - o[i]) * inv[i]
            near = np.maximum(near, np.minimum(t1, t2))
            far = np.minimum(far, np.maximum(t1, t2))
    return near <= far


def open_hit(t, length, eps):
    """t in (0, 1) at a distance > eps (m) from both endpoints of a segment of `length` (m)."""
    return (t * length > eps) & ((1.0 - t) * length > eps)


def segment_hits_flat_quad(o, D, length, eps, quad, row, inside_tol):
    """Segments o + t D, t in (0, 1), against flat convex quads: the plane n . x = d, then the hit
    inside all four edges (a collapsed edge passes), shape (K,).

    Parameters
    ----------
    o, D : ndarray, shape (K, 3)
    length, eps : ndarray, shape (K,)
        |D| and the endpoint tolerance (m).
    quad : dict
        "normal" (Q, 3), "offset" (Q,), "vertices", "edges" (Q, 4, 3), "edge_length" (Q, 4).
    row : ndarray of int, shape (K,)
        Quad of each segment.
    inside_tol : float
        Slack of the edge tests (m).
    """
    n = quad["normal"][row]
    denom = _dot(n, D)
    crossing = np.abs(denom) > 1e-14 * length
    t = np.divide(quad["offset"][row] - _dot(n, o), denom, out=np.zeros(o.shape[0]), where=crossing)
    X = o + t[:, None] * D
    V, E, L = quad["vertices"][row], quad["edges"][row], quad["edge_length"][row]
    # n . (edge x (X - start)) is the distance inside the edge times its length
    side = np.einsum("ki,kji->kj", n, np.cross(E, X[:, None] - V))
    inside = np.all(side >= -inside_tol * L, axis=1)
    return crossing & inside & open_hit(t, length, eps)


def _quadratic_roots(a, b, c, graze):
    """Roots of a t^2 + 2 b t + c = 0 that cut a chord longer than `graze` (unit-shape units).

    Stable form: q = -(b + sign(b) sqrt(b^2 - a c)), roots q / a and c / q. The chord between the
    roots is 2 sqrt(b^2 - a c) / sqrt(a) long in the unit frame, with rounding ~1e-8 for a
    tangent line, so shorter chords are tangent touches and are dropped.

    Returns
    -------
    ok : ndarray of bool
        Two separated real roots.
    t1, t2 : ndarray
        The roots (0 where not ok).
    """
    disc = b * b - a * c
    ok = (a > 0.0) & (disc > (0.5 * graze) ** 2 * a)
    root = np.sqrt(np.where(ok, disc, 0.0))
    q = -(b + np.copysign(root, b))
    t1 = np.divide(q, a, out=np.zeros_like(a), where=ok)
    t2 = np.divide(c, q, out=np.zeros_like(a), where=ok)
    return ok, t1, t2


# --------------------------------------------------------------------------- proxy mesh
def _breakpoints(lo, hi, knots, n):
    """n + 1 increasing parameters from lo to hi, with the knots inside (lo, hi) among them.

    Cells are shared among the knot spans in proportion to their length (at least one each);
    if that is impossible (more spans than cells) the grid is uniform.
    """
    inner = np.unique(knots[(knots > lo) & (knots < hi)])
    ends = np.concatenate([[lo], inner, [hi]])
    spans = np.diff(ends)
    if spans.size > n:
        return np.linspace(lo, hi, n + 1)
    counts = np.maximum(1, np.round(n * spans / (hi - lo)).astype(int))
    counts[np.argmax(spans)] += n - counts.sum()
    if counts.min() < 1:
        return np.linspace(lo, hi, n + 1)
    pieces = [np.linspace(a, b, c + 1)[:-1] for a, b, c in zip(ends[:-1], ends[1:], counts)]
    return np.concatenate(pieces + [[hi]])


def _round_up(n, step):
    return int(step * np.ceil(n / step))


def _proxy_resolution(geometry, domain):
    """Cells per direction (nu, nv) for a chord error near PROXY_TOL times the patch size.

    Second differences on a 17 x 17 grid give h^2 |P_uu|, h^2 |P_vv| and h_u h_v |P_uv|; a
    chord over a cell of n-times smaller steps deviates by about |P_uu| h^2 / 8 (and the
    diagonal of a twisted cell by |P_uv| h_u h_v / 4), so n grows like the square root.
    """
    (u0, u1), (v0, v1) = domain
    s = np.linspace(0.0, 1.0, 17)
    u, v = np.meshgrid(u0 + (u1 - u0) * s, v0 + (v1 - v0) * s, indexing="ij")
    P = geometry.derivatives(u, v)[0]
    size = np.linalg.norm(P.reshape(-1, 3).max(0) - P.reshape(-1, 3).min(0))
    tol = PROXY_TOL * max(size, 1e-300)
    d2u = np.linalg.norm(P[2:] - 2 * P[1:-1] + P[:-2], axis=-1).max()
    d2v = np.linalg.norm(P[:, 2:] - 2 * P[:, 1:-1] + P[:, :-2], axis=-1).max()
    duv = np.linalg.norm(P[1:, 1:] - P[1:, :-1] - P[:-1, 1:] + P[:-1, :-1], axis=-1).max()
    twist = 16.0 * np.sqrt(duv / (4.0 * tol))
    nu = max(16.0 * np.sqrt(d2u / (8.0 * tol)), twist)
    nv = max(16.0 * np.sqrt(d2v / (8.0 * tol)), twist)
    return tuple(_round_up(np.clip(n, PROXY_MIN, PROXY_MAX), LEAF) for n in (nu, nv))


class _Proxy:
    """Triangle mesh of a patch over its domain with a box tree of tiles.

    Parameters
    ----------
    surface : Surface
    resolution : int, (int, int) or None
        Cells per direction (rounded up to a multiple of LEAF), or None for `_proxy_resolution`.

    Attributes
    ----------
    chord_error : float
        Largest distance (m) between the true surface and the proxy at cell centres and edge
        midpoints (an estimate of the proxy's distance to the surface).
    box_min, box_max : ndarray, shape (3,)
        Box of the proxy vertices.
    """

    def __init__(self, surface, resolution=None):
        geometry = surface.geometry
        (u0, u1), (v0, v1) = domain = surface.domain
        if resolution is None:
            nu, nv = _proxy_resolution(geometry, domain)
        else:
            nu, nv = (resolution, resolution) if np.isscalar(resolution) else resolution
            nu, nv = _round_up(max(int(nu), 1), LEAF), _round_up(max(int(nv), 1), LEAF)
        knots_u, knots_v = geometry.breaks
        us = _breakpoints(u0, u1, knots_u, nu)
        vs = _breakpoints(v0, v1, knots_v, nv)
        # vertices, and the proxy's offset from the surface at cell centres (from both diagonals)
        # and edge midpoints: its component along the unit normal there (a tangential part is
        # only a shift of parameters), or its length where the normal vanishes (poles)
        P = geometry.derivatives(*np.meshgrid(us, vs, indexing="ij"))[0]
        um, vm = 0.5 * (us[1:] + us[:-1]), 0.5 * (vs[1:] + vs[:-1])
        P00, P10, P11, P01 = P[:-1, :-1], P[1:, :-1], P[1:, 1:], P[:-1, 1:]
        checks = [
            (um, vm, [0.5 * (P00 + P11), 0.5 * (P10 + P01)]),
            (um, vs, [0.5 * (P[1:] + P[:-1])]),
            (us, vm, [0.5 * (P[:, 1:] + P[:, :-1])]),
        ]
        errors = []
        for pu, pv, chords in checks:
            Q, Qu, Qv = geometry.derivatives(*np.meshgrid(pu, pv, indexing="ij"))
            n = np.cross(Qu, Qv)
            n_len = np.linalg.norm(n, axis=-1, keepdims=True)
            valid = n_len > 1e-8 * n_len.max()
            unit = np.divide(n, n_len, out=np.zeros_like(n), where=valid)
            for chord in chords:
                offset = Q - chord
                along = np.abs(np.einsum("...i,...i->...", offset, unit))
                errors.append(np.where(valid[..., 0], along, np.linalg.norm(offset, axis=-1)).max())
        self.chord_error = float(max(errors))
        self.resolution = (nu, nv)
        flat = P.reshape(-1, 3)
        self.box_min, self.box_max = flat.min(0), flat.max(0)
        size = np.linalg.norm(self.box_max - self.box_min)
        pad = 1e-12 * (size + np.abs(flat).max())
        # triangles (P00, P10, P11) and (P00, P11, P01) of each cell, grouped LEAF x LEAF per leaf
        tri = np.stack([np.stack([P00, P10, P11], -2), np.stack([P00, P11, P01], -2)], 2)
        a, b = nu // LEAF, nv // LEAF
        tri = tri.reshape(a, LEAF, b, LEAF, 2, 3, 3).transpose(0, 2, 1, 3, 4, 5, 6).reshape(a * b, -1, 3, 3)
        # per leaf, shape (leaves, 3, triangles): corner v0, edges e1, e2 and normal e1 x e2
        v0, e1, e2 = tri[:, :, 0], tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0]
        self.tri_scale = np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1)
        self.v0, self.e1, self.e2, self.normal = (
            np.ascontiguousarray(x.transpose(0, 2, 1)) for x in (v0, e1, e2, np.cross(e1, e2))
        )
        # per leaf, the slab along its mean normal that holds its triangles: a segment with both
        # ends on one side of it, beyond rounding, meets none of them
        mean = np.cross(e1, e2).sum(1)
        self.leaf_normal = mean / np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-300)
        heights = np.einsum("lci,li->lc", tri.reshape(a * b, -1, 3), self.leaf_normal)
        slack = 1e-9 * (size + np.abs(flat).max())
        self.leaf_low, self.leaf_high = heights.min(1) - slack, heights.max(1) + slack
        # level 0: leaf boxes; each level above groups BRANCH x BRANCH tiles, up to one root
        corners = tri.reshape(a * b, -1, 3)
        boxes = [(corners.min(1) - pad, corners.max(1) + pad)]
        self.children = [None]
        grid = (a, b)
        while grid != (1, 1):
            ga, gb = grid
            pa, pb = -(-ga // BRANCH), -(-gb // BRANCH)
            # child (BRANCH I + di, BRANCH J + dj) of parent (I, J), -1 outside the grid
            ci = BRANCH * np.arange(pa)[:, None, None, None] + np.arange(BRANCH)[None, None, :, None]
            cj = BRANCH * np.arange(pb)[None, :, None, None] + np.arange(BRANCH)[None, None, None, :]
            ci, cj = np.broadcast_arrays(ci, cj)
            child = np.where((ci < ga) & (cj < gb), ci * gb + cj, -1).reshape(pa * pb, -1)
            lo, hi = boxes[-1]
            safe = np.maximum(child, 0)
            big = np.abs(lo).max() + np.abs(hi).max() + 1.0
            lo_p = np.where((child >= 0)[..., None], lo[safe], big).min(1)
            hi_p = np.where((child >= 0)[..., None], hi[safe], -big).max(1)
            boxes.append((lo_p, hi_p))
            self.children.append(child)
            grid = (pa, pb)
        # per level, component-major boxes (3, tiles) for the slab test, relative to the proxy's
        # centre (`blocked` tests them in single precision)
        self.origin = 0.5 * (self.box_min + self.box_max)
        self.size = float(size)
        self.boxes = [
            (np.ascontiguousarray((lo - self.origin).T), np.ascontiguousarray((hi - self.origin).T))
            for lo, hi in boxes
        ]

    def blocked(self, o, D, length, eps):
        """Segments o + t D crossing the proxy at t in (0, 1), > eps (m) from both ends.

        Parameters
        ----------
        o, D : ndarray, shape (K, 3)
            Starts (m) and directions (m).
        length, eps : ndarray, shape (K,)
            |D| (m) and the endpoint tolerance (m).

        Returns
        -------
        ndarray of bool, shape (K,)
        """
        hit = np.zeros(o.shape[0], dtype=bool)
        if o.shape[0] == 0:
            return hit
        # The hierarchy's box tests run in single precision, relative to the proxy's centre,
        # on boxes grown by PAD32 of the largest coordinate: rounding moves a slab's crossing by
        # well under that (a few 2^-24 of the coordinates), so no segment that meets a box is
        # dropped; the triangles are tested in double precision. (Scenes beyond 1e30 or within
        # 1e-30, near the ends of single precision's range, keep double.)
        start = o - self.origin
        reach = max(self.size, float(np.abs(start).max()), float(np.abs(D).max()))
        real = np.float32 if 1e-30 < reach < 1e30 else np.float64
        pad = PAD32 * reach if real is np.float32 else 0.0
        oT = np.ascontiguousarray(start.T, dtype=real)
        del start  # (a copy of every segment's start: only the single-precision one is kept)
        inv = _inverse(D)
        if real is np.float32:
            # (a slab within 1e-30 of parallel: its interval stays all t or none, as the boxes
            # are grown by far more than 1e-30)
            np.clip(inv, -1e30, 1e30, out=inv)
        invT = np.ascontiguousarray(inv.T, dtype=real)
        del inv
        boxes = [((lo - pad).astype(real), (hi + pad).astype(real)) for lo, hi in self.boxes]
        top = len(boxes) - 1
        seg = np.flatnonzero(_segment_box(oT, invT, boxes[top][0][:, 0], boxes[top][1][:, 0]))
        stack = [(top, seg, np.zeros(seg.size, dtype=np.int64))]
        while stack:
            level, seg, node = stack.pop()
            keep = ~hit[seg]
            seg, node = seg[keep], node[keep]
            if seg.size == 0:
                continue
            if seg.size > MAX_PAIRS:
                stack.extend(
                    (level, seg[i : i + MAX_PAIRS], node[i : i + MAX_PAIRS])
                    for i in range(0, seg.size, MAX_PAIRS)
                )
                continue
            if level == 0:
                normal = np.take(self.leaf_normal, node, axis=0)
                first, direction = np.take(o, seg, axis=0), np.take(D, seg, axis=0)
                h0 = _dot(first, normal)
                h1 = h0 + _dot(direction, normal)
                low, high = self.leaf_low[node], self.leaf_high[node]
                across = np.flatnonzero(~(((h0 < low) & (h1 < low)) | ((h0 > high) & (h1 > high))))
                seg, node = seg[across], node[across]
                self._triangles(first[across], direction[across], length[seg], eps[seg], node, seg, hit)
                continue
            # expand every (segment, tile) pair to the tile's children and keep those the segment meets
            # (np.take: a third of the time of fancy indexing on these small tables)
            child = np.take(self.children[level], node, axis=0)  # (P, BRANCH^2), -1 outside the grid
            lo, hi = boxes[level - 1]
            safe = np.maximum(child, 0)
            seg_o, seg_inv = np.take(oT, seg, axis=1)[..., None], np.take(invT, seg, axis=1)[..., None]
            box_lo, box_hi = np.take(lo, safe, axis=1), np.take(hi, safe, axis=1)
            meet = _segment_box(seg_o, seg_inv, box_lo, box_hi) & (child >= 0)
            row, col = np.nonzero(meet)
            stack.append((level - 1, seg[row], child[row, col]))
        return hit

    def _triangles(self, o, D, length, eps, leaf, seg, hit):
        """Moeller-Trumbore on every triangle of the (segment, leaf) pairs; sets hit[seg] in place.

        With T = o - v0, N = e1 x e2 and C = D x T: det = -D . N, barycentrics
        a = -e2 . C / det, b = e1 . C / det, and t = T . N / det (the scalar triple products of
        Moeller & Trumbore rearranged so that one cross product per pair is left).
        """
        step = max(1, TRI_BATCH // self.v0.shape[2])
        for i in range(0, leaf.size, step):
            f = leaf[i : i + step]
            d, lng = D[i : i + step, :, None], length[i : i + step, None]
            # (P, 3, T) each
            v0, e1, e2, N = (np.take(x, f, axis=0) for x in (self.v0, self.e1, self.e2, self.normal))
            T = o[i : i + step, :, None] - v0
            C0 = d[:, 1] * T[:, 2] - d[:, 2] * T[:, 1]
            C1 = d[:, 2] * T[:, 0] - d[:, 0] * T[:, 2]
            C2 = d[:, 0] * T[:, 1] - d[:, 1] * T[:, 0]
            det = -(d[:, 0] * N[:, 0] + d[:, 1] * N[:, 1] + d[:, 2] * N[:, 2])
            # skip degenerate triangles (poles) and segments within ~1e-13 rad of their plane
            ok = np.abs(det) > 1e-13 * self.tri_scale[f] * lng
            inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
            a = -(e2[:, 0] * C0 + e2[:, 1] * C1 + e2[:, 2] * C2) * inv
            b = (e1[:, 0] * C0 + e1[:, 1] * C1 + e1[:, 2] * C2) * inv
            t = (T[:, 0] * N[:, 0] + T[:, 1] * N[:, 1] + T[:, 2] * N[:, 2]) * inv
            tol = 1e-9  # barycentric slack: shared triangle edges block from both sides
            ok &= (a >= -tol) & (b >= -tol) & (a + b <= 1.0 + tol)
            ok &= open_hit(t, lng, eps[i : i + step, None])
            hit[seg[i : i + step][ok.any(1)]] = True


# --------------------------------------------------------------------------- occluders
class Occluders:
    """Ray (segment) occlusion against a list of core surfaces.

    Surfaces may be `Sphere`, `Quad`, `Disk`, `Cylinder`, `NurbsSurface`, and any of them after
    `subpatch`, `flipped`, `transformed` (4 x 4) or `split`, and `PolygonMesh`es (their
    triangles through the mesh's BVH). Spheres (ellipsoids), disks,
    cylinders and flat quads are intersected exactly; NURBS and curved quads through a proxy
    triangle mesh (see the module docstring).

    Parameters
    ----------
    surfaces : sequence of Surface, length M
        Occluder m is surfaces[m].
    proxy_resolution : int, (int, int) or None, optional
        Proxy grid cells per direction for mesh occluders (rounded up to a multiple of 2); None
        chooses 16..128 per direction from the patch's curvature (chord error ~1e-4 of its size).
    rel_eps : float, optional
        Endpoint tolerance relative to `scale`.

    Attributes
    ----------
    surfaces : list of Surface, length M
    kind : ndarray of int, shape (M,)
        SPHERE, QUAD (flat quad or triangle), DISK, CYLINDER, MESH (a proxy) or POLYGON_MESH
        (see KIND_NAMES).
    center : ndarray, shape (M, 3)
    radius : ndarray, shape (M,)
        A ball (m) holding the whole surface.
    box_min, box_max : ndarray, shape (M, 3)
        An axis-aligned box (m) holding the whole surface.
    planar : ndarray of bool, shape (M,)
    plane_normal : ndarray, shape (M, 3)
        Unit normal n of planar surfaces (zero for curved ones).
    plane_offset : ndarray, shape (M,)
        d with n . x = d on the plane (m); 0 for curved ones.
    convex : ndarray of bool, shape (M,)
        Part of the boundary of a convex solid (sphere or ellipsoid patch, disk, flat quad or
        NURBS, cylinder lateral surface): it never occludes two points lying on itself.
    scale : float
        Scene size (m): diagonal of the box holding all occluders.
    chord_error : ndarray, shape (M,)
        Proxy chord error (m) of mesh occluders, 0 for analytic ones.
    eps : ndarray, shape (M,)
        Endpoint tolerance (m): rel_eps * scale, plus 2 * chord_error for mesh occluders.
    bvh : bvh.BVH
        Hierarchy over the occluders' boxes and bounding balls (EXTERNAL primitives tested by
        `blocked`): `visibility.ShaftTest` asks it for each pair's candidate occluders.
    """

    def __init__(self, surfaces, proxy_resolution=None, rel_eps=REL_EPS):
        self.surfaces = list(surfaces)
        M = len(self.surfaces)
        self.kind = np.empty(M, dtype=np.int64)
        self.box_min = np.zeros((M, 3))
        self.box_max = np.zeros((M, 3))
        self.center = np.zeros((M, 3))
        self.radius = np.zeros(M)
        self.planar = np.zeros(M, dtype=bool)
        self.plane_normal = np.zeros((M, 3))
        self.plane_offset = np.zeros(M)
        self.convex = np.zeros(M, dtype=bool)
        # meshes bounding a convex region from outside (`PolygonMesh.front_hull`): their planes
        self.hull = [None] * M
        # meshes that are closed convex solids (`PolygonMesh.solid_hull`): their face planes
        self.solid_hull = [None] * M
        self.chord_error = np.zeros(M)
        self._slot = np.zeros(M, dtype=np.int64)
        self._meshes = []
        affine = {SPHERE: [], DISK: [], CYLINDER: []}
        quads = []
        self._polygon_meshes = []
        from .mesh import PolygonMesh  # (core.mesh builds on core.bvh, which builds on this module)

        for m, surface in enumerate(self.surfaces):
            if isinstance(surface, PolygonMesh):
                self._add_polygon_mesh(m, surface)
                continue
            geometry = surface.geometry
            kind = MESH if geometry.kind == GENERIC else geometry.kind
            self.kind[m] = kind
            if kind in affine:
                self._slot[m] = len(affine[kind])
                affine[kind].append(surface)
                lo, hi = _affine_box(geometry.linear, geometry.offset, *geometry.unit_box(surface.domain))
                if kind == SPHERE:
                    # the whole ellipsoid's box: half-extent |row i of linear| along axis i
                    half = np.linalg.norm(geometry.linear, axis=1)
                    lo = np.maximum(lo, geometry.offset - half)
                    hi = np.minimum(hi, geometry.offset + half)
                self.convex[m] = True
            elif kind == QUAD:
                self._slot[m] = len(quads)
                corners = geometry.box_corners(surface.domain)
                quads.append(corners)
                lo, hi = corners.min(0), corners.max(0)
                self.convex[m] = True
            else:
                self._slot[m] = len(self._meshes)
                proxy = _Proxy(surface, proxy_resolution)
                self._meshes.append(proxy)
                self.chord_error[m] = proxy.chord_error
                grow = 2.0 * proxy.chord_error
                lo, hi = proxy.box_min - grow, proxy.box_max + grow
                hull = geometry.hull_points(surface.domain)
                if hull is not None:
                    lo, hi = np.maximum(lo, hull.min(0)), np.minimum(hi, hull.max(0))
                # (a NURBS net that is a whole ellipsoid is convex too: without this its own
                # patches' pairs kept it as a candidate occluder, and an exact shadow then took
                # their points, on its surface, as inside it: a room with a NURBS ball 15 % off)
                self.convex[m] = geometry.plane is not None or geometry.whole_ellipsoid(surface.domain)
            pad = 1e-12 * (np.abs(lo).max() + np.abs(hi).max())
            self.box_min[m], self.box_max[m] = lo - pad, hi + pad
            self.center[m] = 0.5 * (lo + hi)
            self.radius[m] = 0.5 * np.linalg.norm(hi - lo) + pad
            if kind == SPHERE:
                # the ellipsoid's own ball (centre o, largest singular value) if it is smaller
                r = np.linalg.norm(geometry.linear, 2) * (1.0 + 1e-12)
                if r < self.radius[m]:
                    self.center[m], self.radius[m] = geometry.offset, r
            plane = geometry.plane
            if plane is not None:
                self.planar[m] = True
                self.plane_normal[m] = plane[1]
                self.plane_offset[m] = plane[1] @ plane[0]
        if M:
            self.scale = float(np.linalg.norm(self.box_max.max(0) - self.box_min.min(0)))
        else:
            self.scale = 1.0
        self.scale = self.scale if self.scale > 0.0 else 1.0
        self.eps = rel_eps * self.scale + 2.0 * self.chord_error
        self._tol = 1e-12 * self.scale  # inside tests of flat quads (m)
        self._pack_affine(affine)
        self._pack_quads(quads)
        # one hierarchy over the occluders' boxes and balls for every shaft query
        # (imported here: core.bvh builds on this module's exact tests)
        from .bvh import BVH, EXTERNAL

        boxes = np.stack([self.box_min, self.box_max], 1)
        self.bvh = BVH(
            boxes,
            np.full(M, EXTERNAL),
            balls=(self.center, self.radius),
            external=self.blocked,
            planes=(self.plane_normal, self.plane_offset, self.planar),
        )

    def bvh_totals(self):
        """BVH counters summed over the shaft hierarchy and the meshes' triangle hierarchies:
        {"nodes": nodes visited, "primitives": primitives tested}."""
        trees = [self.bvh] + self._polygon_meshes
        return {key: sum(t.totals[key] for t in trees) for key in ("nodes", "primitives")}

    def _add_polygon_mesh(self, m, mesh):
        """Box, ball and plane of a PolygonMesh occluder m; its triangles stay in its own BVH."""
        self.kind[m] = POLYGON_MESH
        self._slot[m] = len(self._polygon_meshes)
        self._polygon_meshes.append(mesh.occlusion_bvh())
        flat = mesh.piece_corners.reshape(-1, 3)
        lo, hi = flat.min(0), flat.max(0)
        pad = 1e-9 * np.linalg.norm(hi - lo) + 1e-12 * (np.abs(lo).max() + np.abs(hi).max())
        self.box_min[m], self.box_max[m] = lo - pad, hi + pad
        self.center[m] = 0.5 * (lo + hi)
        self.radius[m] = 0.5 * np.linalg.norm(hi - lo) + pad
        self.hull[m] = mesh.front_hull
        self.solid_hull[m] = mesh.solid_hull
        # a convex solid: segments leaving its front never meet it again (`visibility.ShaftTest`)
        self.convex[m] = mesh.convex_solid
        plane = mesh.planar
        if plane is not None:
            # one plane: no segment between two of its points crosses it
            self.planar[m] = self.convex[m] = True
            self.plane_normal[m] = plane[1]
            self.plane_offset[m] = plane[1] @ plane[0]

    def _pack_affine(self, affine):
        """Stacked inverse maps, offsets, domains and natural sizes of the affine shapes."""
        self._affine = {}
        for kind, surfaces in affine.items():
            if not surfaces:
                continue
            self._affine[kind] = dict(
                inverse=np.stack([np.linalg.inv(s.geometry.linear) for s in surfaces]),
                offset=np.stack([s.geometry.offset for s in surfaces]),
                domain=np.array([s.domain for s in surfaces]).reshape(-1, 4),
                size=np.array([np.abs(s.geometry.natural_domain).max() for s in surfaces]),
            )

    def _pack_quads(self, quads):
        """Corners, polygon normals (unit, counterclockwise order) and plane offsets of flat quads."""
        if not quads:
            return
        V = np.stack(quads)  # (Q, 4, 3): p00, p10, p11, p01 of each patch's box
        normal = np.cross(V[:, 2] - V[:, 0], V[:, 3] - V[:, 1])
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        edges = np.roll(V, -1, axis=1) - V
        self._quad = dict(
            vertices=V,
            edges=edges,
            edge_length=np.linalg.norm(edges, axis=-1),
            normal=normal,
            offset=np.einsum("qi,qi->q", normal, V.mean(1)),
        )

    # ------------------------------------------------------------------ queries
    def blocked(self, origins, ends, occluder):
        """Whether each open segment crosses its occluder.

        Parameters
        ----------
        origins, ends : array_like, shape (K, 3)
            Segment endpoints (m); they may lie on surfaces.
        occluder : array_like of int, shape (K,) (or a scalar)
            Occluder index of each segment, in 0 .. M - 1.

        Returns
        -------
        ndarray of bool, shape (K,)
            True if segment k meets surfaces[occluder[k]] at o + t (e - o) with t in (0, 1) at
            a distance > eps[occluder[k]] (m) from both endpoints. Tangent touches (chords
            shorter than ~1e-7 of a sphere's or cylinder's radius) do not count.
        """
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        D = np.asarray(ends, dtype=np.float64).reshape(-1, 3) - o
        K = o.shape[0]
        occ = np.broadcast_to(np.asarray(occluder, dtype=np.int64), (K,))
        result = np.zeros(K, dtype=bool)
        if K == 0:
            return result
        length = np.sqrt(_dot(D, D))
        # cull by the occluders' boxes, then intersect exactly, one kind at a time
        # (component-major copies and np.take: strided views and fancy row indexing cost more
        # than the slab test)
        oT, invT = np.ascontiguousarray(o.T), np.ascontiguousarray(_inverse(D).T)
        lo, hi = (np.take(x, occ, axis=0).T for x in (self.box_min, self.box_max))
        candidate = _segment_box(oT, invT, lo, hi) & (length > 0.0)
        kind = self.kind[occ]
        tests = {SPHERE: self._sphere, QUAD: self._flat_quad, DISK: self._disk, CYLINDER: self._cylinder}
        for code, test in tests.items():
            idx = np.flatnonzero(candidate & (kind == code))
            if idx.size:
                m = occ[idx]
                start, direction = np.take(o, idx, axis=0), np.take(D, idx, axis=0)
                result[idx] = test(start, direction, length[idx], self.eps[m], self._slot[m])
        idx = np.flatnonzero(candidate & (kind == POLYGON_MESH))
        for m in np.unique(occ[idx]):
            sel = idx[occ[idx] == m]
            if self.solid_hull[m] is not None:
                normal, offset, slack = self.solid_hull[m]
                result[sel] = _crosses_polytope(o[sel], D[sel], self.eps[m] + slack, normal, offset)
                continue
            bvh = self._polygon_meshes[self._slot[m]]
            result[sel] = bvh.segments_blocked(o[sel], o[sel] + D[sel], self.eps[m])
        idx = np.flatnonzero(candidate & (kind == MESH))
        if idx.size:
            # one batch per mesh occluder
            for m in np.flatnonzero(np.bincount(occ[idx])):
                sel = idx[occ[idx] == m]
                proxy = self._meshes[self._slot[m]]
                result[sel] = proxy.blocked(o[sel], D[sel], length[sel], np.full(sel.size, self.eps[m]))
        return result

    def any_blocked(self, origins, ends, candidates):
        """Whether each segment is blocked by any of the candidate occluders.

        Parameters
        ----------
        origins, ends : array_like, shape (K, 3)
        candidates : array_like of int, shape (C,)

        Returns
        -------
        ndarray of bool, shape (K,)
        """
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        e = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
        result = np.zeros(o.shape[0], dtype=bool)
        for m in np.asarray(candidates, dtype=np.int64).ravel():
            # only segments not yet blocked are tested again
            open_ = np.flatnonzero(~result)
            if open_.size == 0:
                break
            result[open_] = self.blocked(o[open_], e[open_], np.full(open_.size, m))
        return result

    # ------------------------------------------------------------------ exact tests
    def _local(self, kind, o, D, slot):
        """Segment in the unit shape's frame: p = L^-1 (x - offset); t is unchanged."""
        data = self._affine[kind]
        inverse, offset, domain = (
            np.take(data[key], slot, axis=0) for key in ("inverse", "offset", "domain")
        )
        return _apply(inverse, o - offset), _apply(inverse, D), domain

    def _sphere(self, o, D, length, eps, slot):
        """Unit sphere |p| = 1: (o + t d)^2 = 1, i.e. a t^2 + 2 b t + c = 0; hits inside the domain."""
        ol, dl, dom = self._local(SPHERE, o, D, slot)
        ok, t1, t2 = _quadratic_roots(_dot(dl, dl), _dot(ol, dl), _dot(ol, ol) - 1.0, GRAZE)
        hit = np.zeros(o.shape[0], dtype=bool)
        # (a whole sphere holds every hit: the angles are taken for patches only)
        whole = (dom[:, 0] <= 0.0) & (dom[:, 1] >= np.pi) & (dom[:, 3] - dom[:, 2] >= TWO_PI - ANGLE_TOL)
        for t in (t1, t2):
            good = ok & open_hit(t, length, eps)
            part = np.flatnonzero(good & ~whole)
            if part.size:
                p = ol[part] + t[part, None] * dl[part]
                # u = polar angle from +z, v = azimuth; at a pole every azimuth belongs to the patch
                rho = np.hypot(p[:, 0], p[:, 1])
                u = np.arctan2(rho, p[:, 2])
                v = np.arctan2(p[:, 1], p[:, 0])
                d = dom[part]
                inside = (u >= d[:, 0] - ANGLE_TOL) & (u <= d[:, 1] + ANGLE_TOL)
                good[part] = inside & ((rho <= 1e-12) | self._arcs(v, d[:, 2], d[:, 3]))
            hit |= good
        return hit

    def _cylinder(self, o, D, length, eps, slot):
        """Unit cylinder x^2 + y^2 = 1: a quadratic in t; hits with angle and height in the domain."""
        ol, dl, dom = self._local(CYLINDER, o, D, slot)
        a = dl[:, 0] ** 2 + dl[:, 1] ** 2
        b = ol[:, 0] * dl[:, 0] + ol[:, 1] * dl[:, 1]
        c = ol[:, 0] ** 2 + ol[:, 1] ** 2 - 1.0
        # segments (almost) along the axis never cross the lateral surface
        along = a <= 1e-24 * _dot(dl, dl)
        ok, t1, t2 = _quadratic_roots(np.where(along, 0.0, a), b, c, GRAZE)
        tol = 1e-12 * self._affine[CYLINDER]["size"][slot]
        hit = np.zeros(o.shape[0], dtype=bool)
        for t in (t1, t2):
            p = ol + t[:, None] * dl
            good = ok & open_hit(t, length, eps)
            good &= (p[:, 2] >= dom[:, 2] - tol) & (p[:, 2] <= dom[:, 3] + tol)
            good &= self._arcs(np.arctan2(p[:, 1], p[:, 0]), dom[:, 0], dom[:, 1])
            hit |= good
        return hit

    def _disk(self, o, D, length, eps, slot):
        """Plane z = 0 of the unit-frame disk; hit radius and angle in the domain."""
        ol, dl, dom = self._local(DISK, o, D, slot)
        crossing = np.abs(dl[:, 2]) > 1e-14 * np.linalg.norm(dl, axis=1)
        t = np.divide(-ol[:, 2], dl[:, 2], out=np.zeros(o.shape[0]), where=crossing)
        p = ol + t[:, None] * dl
        r = np.hypot(p[:, 0], p[:, 1])
        tol = 1e-12 * self._affine[DISK]["size"][slot]
        good = crossing & open_hit(t, length, eps)
        good &= (r >= dom[:, 0] - tol) & (r <= dom[:, 1] + tol)
        # at the centre every angle belongs to a patch that reaches it
        good &= (r <= tol) | self._arcs(np.arctan2(p[:, 1], p[:, 0]), dom[:, 2], dom[:, 3])
        return good

    def _flat_quad(self, o, D, length, eps, slot):
        return segment_hits_flat_quad(o, D, length, eps, self._quad, slot, self._tol)

    @staticmethod
    def _arcs(angle, a, b):
        """Per-segment arc test: angle in [a, b] modulo 2 pi (arrays of shape (K,))."""
        full = b - a >= TWO_PI - ANGLE_TOL
        inside = np.mod(angle - a + ANGLE_TOL, TWO_PI) <= b - a + 2.0 * ANGLE_TOL
        return full | inside
