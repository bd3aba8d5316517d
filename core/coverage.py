"""The part of each flat element that an occluder's face lying on it covers (contact footprints).

A box resting on a floor covers the floor under it: points there receive no light and send none.
The all-pairs solve keeps one radiosity per element, and a floor element that the box's footprint
cuts gets factors averaged over the whole element, visibility included. Its solved radiosity is
then the free part's light times its free fraction f, and what it sends on (its radiosity times
the factors toward it, whose visibility again holds only the free part) carries f twice: the
light it reflects is f times too small. In a 6 m room with three boxes on a 1/3 m floor grid that
made the ceiling 1.2 % and the walls 0.7 % darker than Cycles (BENCHMARKS.md, "Contact
footprints"). The solve therefore takes an element's radiosity to be the mean over its free part:
its gathered light (form factors, direct light, open sky) is divided by f (`gather_scale`).

Covered means: inside the element's polygon and inside a face of another occluding object that
lies in the element's plane (to COPLANAR of the scene's size), whichever way that face points. A
solid that sinks into the plane instead of resting on it is not found (its cross-section is not a
face); neither are curved occluders, whose contact with a plane is a point or a line.
"""

import numpy as np

from .bvh import BVH
from .occlusion import QUAD

COPLANAR = 1e-6  # of the scene's size: a face this close to an element's plane lies on it
MIN_FREE = 0.05  # free fractions below this are taken as this (a sliver's factors are not resolved)


def free_fractions(elements, occluders, occluder_object, scale):
    """Fraction of each element's area that no coplanar occluder face covers, shape (N,).

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
    N = len(elements)
    free = np.ones(N)
    if occluders is None:
        return free
    triangles, owner = _flat_faces(occluders, occluder_object)
    flat = np.flatnonzero(elements.straight)
    if triangles.size == 0 or flat.size == 0:
        return free
    polygon = elements.solver.inner.corners[elements.index[flat]]  # (K, 4, 3): a triangle repeats one
    normal, point = elements.solver.axis[elements.index[flat]], polygon[:, 0]
    pad = COPLANAR * scale
    query, face = BVH.from_primitives(triangles=triangles).box_candidates(
        polygon.min(1) - pad, polygon.max(1) + pad
    )
    # faces of other objects with all three corners on the element's plane
    height = np.einsum("kj,kij->ki", normal[query], triangles[face] - point[query][:, None])
    keep = np.all(np.abs(height) <= pad, axis=1) & (owner[face] != elements.owner[flat[query]])
    query, face = query[keep], face[keep]
    if query.size == 0:
        return free
    # both in 2D coordinates of the element's plane
    t1, t2 = _plane_basis(normal[query])
    origin = point[query][:, None]
    tri = _projected(triangles[face] - origin, t1, t2)
    quad = _projected(polygon[query] - origin, t1, t2)
    covered = np.bincount(query, _clipped_area(tri, quad), minlength=flat.size)
    own = np.abs(_shoelace(_projected(polygon - point[:, None], *_plane_basis(normal))))
    free[flat] = np.clip(1.0 - np.divide(covered, own, out=np.zeros_like(own), where=own > 0), 0.0, 1.0)
    return free


def gather_scale(free):
    """The factor that turns light gathered over a whole element into the mean over its free part,
    1 / max(free, MIN_FREE), shape (N,)."""
    return 1.0 / np.maximum(np.asarray(free, dtype=float), MIN_FREE)


def _flat_faces(occluders, occluder_object):
    """Triangles (T, 3, 3) of the occluders' flat faces (meshes' pieces, flat quads) and each
    one's scene object, shape (T,)."""
    from .mesh import PolygonMesh  # (core.mesh builds on core.bvh)

    triangles, owner = [], []
    for m, surface in enumerate(occluders.surfaces):
        if isinstance(surface, PolygonMesh):
            tri = surface.triangles()[0]
        elif occluders.kind[m] == QUAD and occluders.planar[m]:
            c = surface.geometry.box_corners(surface.domain)
            tri = np.stack([c[[0, 1, 2]], c[[0, 2, 3]]])
        else:
            continue
        triangles.append(np.asarray(tri, dtype=float))
        owner.append(np.full(len(tri), occluder_object[m], dtype=np.int64))
    if not triangles:
        return np.zeros((0, 3, 3)), np.zeros(0, dtype=np.int64)
    return np.concatenate(triangles), np.concatenate(owner)


def _plane_basis(normal):
    """Two unit vectors spanning the plane of each unit normal, shapes (K, 3)."""
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(normal, t1)


def _projected(points, t1, t2):
    """Points (K, n, 3) in the 2D coordinates (K, n, 2) of the planes spanned by t1, t2 (K, 3)."""
    return np.stack([np.einsum("kij,kj->ki", points, t1), np.einsum("kij,kj->ki", points, t2)], axis=-1)


def _shoelace(polygon):
    """Signed areas of polygons (K, n, 2) (repeated closing corners add nothing), shape (K,)."""
    x, y = polygon[..., 0], polygon[..., 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def _clipped_area(subject, clip):
    """Area of each subject polygon (K, n, 2) inside the convex polygon clip (K, m, 2), shape (K,).

    Sutherland & Hodgman 1974 (reentrant polygon clipping), one clip edge at a time for all K at
    once; a polygon is kept as MAX corners, the unused ones repeating its first corner.
    """
    K, n = subject.shape[:2]
    m = clip.shape[1]
    MAX = n + m  # each clip edge adds at most one corner to a convex subject
    poly = np.concatenate([subject, np.repeat(subject[:, :1], MAX - n, axis=1)], axis=1)
    count = np.full(K, n)
    orient = np.where(_shoelace(clip) >= 0.0, 1.0, -1.0)
    slots = np.arange(MAX)
    for e in range(m):
        a, b = clip[:, e], clip[:, (e + 1) % m]
        edge = b - a
        length = np.linalg.norm(edge, axis=1)
        if not np.any(length > 0):
            continue
        # signed distance of each corner from the edge's line, positive inside
        side = orient[:, None] * (
            edge[:, None, 0] * (poly[..., 1] - a[:, None, 1])
            - edge[:, None, 1] * (poly[..., 0] - a[:, None, 0])
        )
        side = np.where(length[:, None] > 0, side, 1.0)  # (a collapsed edge clips nothing)
        nxt = (slots[None] + 1) % np.maximum(count, 1)[:, None]
        rows = np.arange(K)[:, None]
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
        poly = points[np.arange(K)[:, None], order]
        first = np.where(count[:, None] > 0, poly[:, 0], 0.0)
        poly = np.where((slots[None] < count[:, None])[..., None], poly, first[:, None])
    return np.abs(_shoelace(poly))
