"""The part of each flat element that another object covers (contact footprints).

A box resting on a floor covers the floor under it: points there receive no light and send none.
The all-pairs solve keeps one radiosity per element, and a floor element that the box's footprint
cuts gets factors averaged over the whole element, visibility included. Its solved radiosity is
then the free part's light times its free fraction f, and what it sends on (its radiosity times
the factors toward it, whose visibility again holds only the free part) carries f twice: the
light it reflects is f times too small. In a 6 m room with three boxes on a 1/3 m floor grid that
made the ceiling 1.2 % and the walls 0.7 % darker than Cycles (BENCHMARKS.md, "Contact
footprints"). The solve therefore takes an element's radiosity to be the mean over its free part:
its gathered light (form factors, direct light, open sky) is divided by f (`gather_scale`).

That holds only if the factors' visibility gives the covered part nothing. A covering box lies in
no shaft between a floor patch and the ceiling above the box's far side, so shaft culling and a
few sample nodes let the covered part see through it: a patch a fifth under a box summed to 0.88
instead of 0.8, the row's cap at 1 then cut its lamp light by 10 %, and the floor of a 6 m room
with three boxes on 0.86 m patches received 1.75 % too little direct light against a ray-traced
count. So a covering occluder is a candidate of every pair of the element it covers
(`visibility.ShaftTest`), and sampled visibilities are taken over the free part's nodes times the
free part's share of the pair's factor (`visibility.free_share`, `Coverage.covers`).

Covered means: inside the element's polygon and
- inside a face of another occluding object that lies in the element's plane (to COPLANAR of the
  scene's size), whichever way that face points (the bottom of an open box on a floor); or
- inside a closed convex mesh of another object (`PolygonMesh.solid_hull`), resting on the plane
  or sunk into it: the element's polygon is clipped by the solid's face planes. Such a mesh's
  faces are not counted again as coplanar faces.
In either case the object must reach in front of the element: a box on a floor covers the
floor's front, not its back side (which may be the ceiling of a room below), and a zero-thickness
sheet lying on a plane covers neither side. Curved occluders touch a plane at points or lines, which
cover no area; a non-convex solid sunk into a plane leaves a cross-section that is no face of it,
which is not found.
"""

from typing import NamedTuple

import numpy as np

from . import ragged
from .bvh import BVH
from .contour import circle_frame
from .occlusion import QUAD

COPLANAR = 1e-6  # of the scene's size: a face this close to an element's plane lies on it
MIN_FREE = 0.05  # free fractions below this are taken as this (a sliver's factors are not resolved)


def free_fractions(elements, occluders, occluder_object, scale):
    """Fraction of each flat element's area that no other occluding object covers, shape (N,).

    Parameters
    ----------
    elements : elements.Elements
    occluders : occlusion.Occluders or None
    occluder_object : ndarray of int, shape (M,)
        Scene object of each occluder (faces of an element's own object never cover it).
    scale : float
        The scene's size (m).

    Returns
    -------
    ndarray, shape (N,)
        In [0, 1]; 1 for curved elements and where nothing lies on the element.
    """
    return Coverage(elements, occluders, occluder_object, scale).free


class Coverage:
    """What other objects cover of each flat element (see the module docstring).

    Attributes
    ----------
    free : ndarray, shape (N,)
        Fraction of each element's area left free, in [0, 1] (1 for curved elements).
    element, occluder : ndarray of int, shape (C,)
        The (element, occluder) pairs with a covered area: segments from the covered part of
        the element start inside or on that occluder, which blocks them wherever they go, so it
        is a candidate occluder of every pair of that element (`visibility.ShaftTest`), even where
        it lies in no shaft between the element and the other end.
    """

    def __init__(self, elements, occluders, occluder_object, scale):
        N = len(elements)
        self.free = np.ones(N)
        self.element = self.occluder = np.zeros(0, dtype=np.int64)
        if occluders is None:
            return
        flat = np.flatnonzero(elements.straight)
        if flat.size == 0:
            return
        polygon = elements.solver.inner.corners[elements.index[flat]]  # (K, 4, 3): a triangle repeats one
        normal, point = elements.solver.axis[elements.index[flat]], polygon[:, 0]
        t1, t2 = circle_frame(normal)
        planes = _Planes(
            normal,
            point,
            t1,
            t2,
            _projected(polygon - point[:, None], t1, t2),
            polygon.min(1),
            polygon.max(1),
        )
        owner, pad = elements.owner[flat], COPLANAR * scale
        self._triangles, source = _flat_faces(occluders)
        parts = [
            _covered_by_faces(planes, owner, (self._triangles, source), occluder_object, occluders, pad),
            _covered_by_solids(planes, owner, occluders, occluder_object, pad),
        ]
        k, m, area, face = (np.concatenate(column) for column in zip(*parts))
        own = np.abs(_shoelace(planes.polygon))
        covered = np.bincount(k, area, minlength=flat.size)
        self.free[flat] = np.clip(
            1.0 - np.divide(covered, own, out=np.zeros_like(own), where=own > 0), 0.0, 1.0
        )
        hit = area > 0.0
        pairs = np.unique(flat[k[hit]] * len(occluder_object) + m[hit])
        self.element, self.occluder = pairs // len(occluder_object), pairs % len(occluder_object)
        # for `covers`: each covering (element, face triangle or solid), sorted by element
        order = np.argsort(flat[k[hit]], kind="stable")
        self._rows = flat[k[hit]][order]
        self._face = face[hit][order]  # (-1: a solid, m)
        self._occluder = m[hit][order]
        self._normal = elements.solver.axis[elements.index[self._rows]]
        self._hulls = occluders.solid_hull
        self._pad = pad

    def occluders_of(self, element):
        """(query (C,), occluder (C,)): the occluders covering part of each queried element (K,)."""
        query, row = ragged.runs_of(self.element, element)
        return query, self.occluder[row]

    def covers(self, x, element):
        """Whether points x (P, Q, 3) on elements (P,) lie in the elements' covered parts (inside
        a covering face, within `pad`, or inside a covering solid, within its slack), shape
        (P, Q) bool."""
        out = np.zeros(x.shape[:2], dtype=bool)
        if self.element.size == 0:
            return out
        p, row = ragged.runs_of(self._rows, element)
        face = self._face[row]
        on = np.flatnonzero(face >= 0)
        if on.size:
            tri = self._triangles[face[on]]  # (C, 3, 3)
            n = self._normal[row[on]]
            inside = np.ones((on.size, x.shape[1]), dtype=bool)
            for c in range(3):
                edge = tri[:, (c + 1) % 3] - tri[:, c]
                side = np.einsum("cqi,ci->cq", np.cross(edge[:, None], x[p[on]] - tri[:, None, c]), n)
                turn = np.einsum("ci,ci->c", np.cross(edge, tri[:, (c + 2) % 3] - tri[:, c]), n)
                inside &= side * np.sign(turn)[:, None] >= 0.0
            np.logical_or.at(out, p[on], inside)
        for m in np.unique(self._occluder[row[face < 0]]):
            sel = np.flatnonzero((face < 0) & (self._occluder[row] == m))
            normal, offset, slack = self._hulls[m]
            grow = (self._pad + slack) * np.abs(self._normal[row[sel]] @ normal.T)  # (C, P)
            height = np.einsum("cqi,hi->cqh", x[p[sel]], normal) - offset - grow[:, None]
            np.logical_or.at(out, p[sel], np.all(height <= 0.0, axis=-1))
        return out


class _Planes(NamedTuple):
    """K flat elements in their planes: unit normals, origins (a corner), in-plane axes t1, t2
    (each (K, 3)), polygons in (t1, t2) coordinates (K, 4, 2) and boxes lo, hi (K, 3)."""

    normal: np.ndarray
    point: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    polygon: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def _covered_by_faces(planes, owner, faces, occluder_object, occluders, pad):
    """Areas of the elements (`_Planes`) inside faces of other objects (`owner`: each element's,
    (K,)) that lie in their planes to within `pad` (m), among `faces` (`_flat_faces`): (element
    (C,), occluder (C,), area (C,), face (C,)), one row per (element, face)."""
    none = (
        np.zeros(0, dtype=np.int64),
        np.zeros(0, dtype=np.int64),
        np.zeros(0),
        np.zeros(0, dtype=np.int64),
    )
    triangles, source = faces
    if triangles.size == 0:
        return none
    query, face = BVH.from_primitives(triangles=triangles).box_candidates(planes.lo - pad, planes.hi + pad)
    # faces of other objects with all three corners on the element's plane
    height = np.einsum("kj,kij->ki", planes.normal[query], triangles[face] - planes.point[query][:, None])
    keep = np.all(np.abs(height) <= pad, axis=1) & (occluder_object[source[face]] != owner[query])
    keep &= _in_front(planes, query, occluders, source[face], pad)
    query, face = query[keep], face[keep]
    if query.size == 0:
        return none
    tri = _projected(triangles[face] - planes.point[query][:, None], planes.t1[query], planes.t2[query])
    clip = _edge_halfplanes(planes.polygon[query])
    return query, source[face], _clipped_area(tri, *clip), face


def _covered_by_solids(planes, owner, occluders, occluder_object, pad):
    """Areas of the elements (`_Planes`) inside closed convex meshes of other objects (`owner`:
    each element's, (K,)), within their slack and `pad` (m): (element (C,), occluder (C,), area
    (C,), -1 (C,)), one row per (element, mesh)."""
    parts = [
        (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0, dtype=np.int64))
    ]
    for m, hull in enumerate(occluders.solid_hull):
        if hull is None:
            continue
        plane_normal, offset, slack = hull
        grow = pad + slack
        k = np.flatnonzero(
            np.all(
                (planes.lo <= occluders.box_max[m] + grow) & (planes.hi >= occluders.box_min[m] - grow),
                axis=1,
            )
            & (owner != occluder_object[m])
        )
        k = k[_in_front(planes, k, occluders, np.full(k.size, m), grow)]
        if k.size == 0:
            continue
        # n . (o + s t1 + t t2) <= d, in each element's (s, t); a face plane parallel to the
        # element's (a bottom on the floor) passes through it to within grow, the others are exact
        A = np.stack([planes.t1[k] @ plane_normal.T, planes.t2[k] @ plane_normal.T], axis=-1)  # (k, P, 2)
        b = offset[None] + grow * np.abs(planes.normal[k] @ plane_normal.T) - planes.point[k] @ plane_normal.T
        parts.append((k, np.full(k.size, m), _clipped_area(planes.polygon[k], A, b), np.full(k.size, -1)))
    return tuple(np.concatenate(column) for column in zip(*parts))


def gather_scale(free):
    """The factor that turns light gathered over a whole element into the mean over its free part,
    1 / max(free, MIN_FREE), shape (N,); 1 where nothing of the element is free (it gathers
    nothing but what quadrature lets through, which no factor should scale up)."""
    free = np.asarray(free, dtype=float)
    return np.where(free > 1e-9, 1.0 / np.maximum(free, MIN_FREE), 1.0)


def _in_front(planes, k, occluders, m, pad):
    """Whether occluder m (K,) reaches more than `pad` (m) in front of element k's plane (K,),
    shape (K,) bool: a box on a floor covers the floor's front, not its back (the ceiling of a
    room below); a face with nothing in front (a zero-thickness sheet on the plane) covers
    neither side."""
    lo, hi = occluders.box_min[m], occluders.box_max[m]
    n = planes.normal[k]
    reach = np.einsum("ki,ki->k", np.where(n > 0, hi, lo) - planes.point[k], n)
    return reach > pad


def _flat_faces(occluders):
    """Triangles (T, 3, 3) of the occluders' flat faces (meshes' pieces, flat quads) other than
    closed convex meshes', and each one's occluder, shape (T,)."""
    from .mesh import PolygonMesh  # (core.mesh builds on core.bvh)

    triangles, owner = [], []
    for m, surface in enumerate(occluders.surfaces):
        if occluders.solid_hull[m] is not None:
            continue  # (`_covered_by_solids`)
        if isinstance(surface, PolygonMesh):
            tri = surface.triangles()[0]
        elif occluders.kind[m] == QUAD and occluders.planar[m]:
            c = surface.geometry.box_corners(surface.domain)
            tri = np.stack([c[[0, 1, 2]], c[[0, 2, 3]]])
        else:
            continue
        triangles.append(np.asarray(tri, dtype=float))
        owner.append(np.full(len(tri), m, dtype=np.int64))
    if not triangles:
        return np.zeros((0, 3, 3)), np.zeros(0, dtype=np.int64)
    return np.concatenate(triangles), np.concatenate(owner)


def _projected(points, t1, t2):
    """Points (K, n, 3) in the 2D coordinates (K, n, 2) of the planes spanned by t1, t2 (K, 3)."""
    return np.stack([np.einsum("kij,kj->ki", points, t1), np.einsum("kij,kj->ki", points, t2)], axis=-1)


def _shoelace(polygon):
    """Signed areas of polygons (K, n, 2) (repeated closing corners add nothing), shape (K,)."""
    x, y = polygon[..., 0], polygon[..., 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def _edge_halfplanes(clip):
    """The convex polygons clip (K, m, 2) as half-planes A p <= b inside them: A (K, m, 2), b (K, m)
    (a collapsed edge gives 0 <= 0, which clips nothing)."""
    edge = np.roll(clip, -1, axis=1) - clip
    orient = np.where(_shoelace(clip) >= 0.0, 1.0, -1.0)[:, None]
    # inside a counter-clockwise polygon: cross(edge, p - a) >= 0, i.e. (e_y, -e_x) . p <= (e_y, -e_x) . a
    A = orient[..., None] * np.stack([edge[..., 1], -edge[..., 0]], axis=-1)
    return A, np.einsum("kmi,kmi->km", A, clip)


def _clipped_area(subject, A, b):
    """Area of each subject polygon (K, n, 2) inside the half-planes A p <= b (A (K, H, 2), b
    (K, H)), shape (K,).

    Sutherland & Hodgman, "Reentrant polygon clipping", CACM 17(1), 1974: one half-plane at a
    time for all K at once. Subjects are convex (triangles, elements' quads): each half-plane adds
    at most one corner, so a polygon is kept as n + H corners, the unused ones repeating its first
    corner. (`cones.clip_below` clips by one plane and doubles the corner slots; over the up to
    4 + P half-planes here those would grow as 2^H, hence the compaction after each.)
    """
    K, n = subject.shape[:2]
    H = A.shape[1]
    MAX = n + H
    poly = np.concatenate([subject, np.repeat(subject[:, :1], MAX - n, axis=1)], axis=1)
    count = np.full(K, n)
    slots = np.arange(MAX)
    rows = np.arange(K)[:, None]
    for h in range(H):
        # signed distance of each corner inside the half-plane (>= 0: kept)
        side = b[:, h, None] - np.einsum("kmi,ki->km", poly, A[:, h])
        nxt = (slots[None] + 1) % np.maximum(count, 1)[:, None]
        side_next, poly_next = side[rows, nxt], poly[rows, nxt]
        live = slots[None] < count[:, None]
        inside, inside_next = side >= 0.0, side_next >= 0.0
        t = np.divide(side, side - side_next, out=np.zeros_like(side), where=side != side_next)
        cross = poly + t[..., None] * (poly_next - poly)
        # each corner emits itself if inside, then the crossing if the edge to the next crosses
        keep = np.stack([live & inside, live & (inside != inside_next)], axis=2).reshape(K, 2 * MAX)
        points = np.stack([poly, cross], axis=2).reshape(K, 2 * MAX, 2)
        order = np.argsort(~keep, axis=1, kind="stable")[:, :MAX]
        count = np.minimum(keep.sum(1), MAX)
        poly = points[rows, order]
        first = np.where(count[:, None] > 0, poly[:, 0], 0.0)
        poly = np.where((slots[None] < count[:, None])[..., None], poly, first[:, None])
    return np.abs(_shoelace(poly))
