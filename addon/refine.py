"""A result mesh refined where the radiosity varies, coarse where it does not (numpy only).

Start from the user's triangles (the result mesh's loop triangles) with the radiance at their
vertices. Each pass evaluates the radiance at the midpoints of all edges still at least twice the
minimum edge length (once per edge: an edge kept keeps its ends, so its verdict stands), and
splits the edges whose midpoint value differs from the linear interpolation of its ends by more
than `tol` (relative to the local value, with a floor of `DARK_FLOOR` times the brightest value,
so the dark is not refined for noise), and every edge longer than `max_edge` (so that no shadow
hides between the first samples):

    |B(m) - (B(a) + B(b)) / 2| > tol * max(|B(a)|, |B(b)|, |B(m)|, floor)   (max over channels)

A triangle with one, two or three split edges is cut into two, three or four (red-green
refinement, Bank, Sherman & Weiser 1983; the split edge's midpoint is shared by both triangles
of the edge, so the mesh stays conforming: no T-junctions). Passes repeat until no edge splits,
or the vertex budget is reached. New vertices lie on the user's flat triangles (the twin renders
the same shape); their radiance is gathered on the core surface under them (`sampling`). Every
triangle keeps its root triangle and its corners' barycentric coordinates there, so UVs and
materials carry over exactly.
"""

from dataclasses import dataclass

import numpy as np

# below this fraction of the brightest value, differences count as absolute (no refining in the dark)
DARK_FLOOR = 1e-2
MAX_PASSES = 64

# children of a triangle (a, b, c) by its split edges, corners as pairs of local corners
# ((i, i) a corner, (i, j) the midpoint of edge i-j); edge k joins corners k and k + 1
_ONE = (((0, 0), (0, 1), (2, 2)), ((0, 1), (1, 1), (2, 2)))  # edge 0 split
_TWO = (((0, 1), (1, 1), (1, 2)), ((0, 0), (0, 1), (1, 2)), ((0, 0), (1, 2), (2, 2)))  # edges 0, 1
_THREE = (
    ((0, 0), (0, 1), (2, 0)),
    ((0, 1), (1, 1), (1, 2)),
    ((2, 0), (1, 2), (2, 2)),
    ((0, 1), (1, 2), (2, 0)),
)


@dataclass
class Refined:
    """A refined triangle mesh.

    Attributes
    ----------
    positions : ndarray, shape (V, 3)
        World positions.
    triangles : ndarray of int64, shape (T, 3)
    root : ndarray of int64, shape (T,)
        The user's triangle each triangle lies in.
    bary : ndarray, shape (T, 3, 3)
        Barycentric coordinates of each corner in its root triangle.
    values : ndarray, shape (V, C)
        Radiance at the vertices.
    passes : int
    budget_reached : bool
    """

    positions: np.ndarray
    triangles: np.ndarray
    root: np.ndarray
    bary: np.ndarray
    values: np.ndarray
    passes: int
    budget_reached: bool

    def corner_attribute(self, per_root_corner):
        """Interpolate a per-corner attribute of the root triangles (T0, 3, D) onto the corners
        of the refined triangles, shape (T, 3, D)."""
        return np.einsum("tcr,trd->tcd", self.bary, np.asarray(per_root_corner)[self.root])


def refine(surfaces, evaluate, tol, min_edge, max_edge=np.inf, max_vertices=2_000_000, progress=None):
    """Refine a result mesh.

    Parameters
    ----------
    surfaces : sampling.MeshSurfaces
        The user's mesh (world positions, triangles) and its core surfaces.
    evaluate : callable(triangle (K,), bary (K, 3)) -> ndarray (K, C)
        Radiance at points of the user's triangles (e.g. `sampling.gather` of `locate`).
    tol : float
        Relative tolerance of the linear interpolation along edges (> 0).
    min_edge : float
        Shortest edge (m) a split may make (> 0).
    max_edge : float
        Edges longer than this (m) are split whatever their error: the error test sees only
        what its midpoints sample, so a shadow smaller than an edge could fall between them.
    max_vertices : int
        Stop refining once the mesh has this many vertices.
    progress : callable(stage, fraction) or None

    Returns
    -------
    Refined

    Raises
    ------
    ValueError
        If tol or min_edge is not a positive finite number.
    """
    for name, value in (("tol", tol), ("min_edge", min_edge)):
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
            raise ValueError(f"refine: {name} must be a positive finite number, got {value!r}")
    tri0 = surfaces.triangles
    T0 = len(tri0)
    positions = surfaces.positions.copy()
    # vertex values: each vertex of the user's mesh evaluated from one triangle holding it
    corner_of = np.full(len(positions), -1, np.int64)
    corner_of[tri0.ravel()] = np.arange(tri0.size)
    used = np.flatnonzero(corner_of >= 0)
    eye = np.eye(3)
    first = evaluate(corner_of[used] // 3, eye[corner_of[used] % 3])
    values = np.zeros((len(positions), first.shape[1]))
    values[used] = first
    triangles = tri0.copy()
    root = np.arange(T0)
    bary = np.broadcast_to(eye, (T0, 3, 3)).copy()
    passes, budget = 0, False
    settled = np.zeros(0, np.int64)
    for passes in range(1, MAX_PASSES + 1):
        # unique edges of the current triangles, each with one triangle and local edge holding it
        a = triangles
        b = np.roll(triangles, -1, axis=1)
        pairs = np.sort(np.stack([a, b], -1).reshape(-1, 2), axis=1)
        edges, occurrence, inverse = np.unique(pairs, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.ravel()
        length = np.linalg.norm(positions[edges[:, 1]] - positions[edges[:, 0]], axis=1)
        # an edge checked and kept before keeps its ends, so its verdict stands: check it once
        key = edges[:, 0] * (1 << 32) + edges[:, 1]
        candidate = np.flatnonzero((length >= 2.0 * min_edge) & ~np.isin(key, settled))
        if candidate.size == 0:
            break
        if len(positions) + candidate.size > max_vertices:
            budget = True
            break
        # radiance at the candidates' midpoints, in the root triangle of one triangle holding each
        t, k = occurrence[candidate] // 3, occurrence[candidate] % 3
        mid_bary = 0.5 * (bary[t, k] + bary[t, (k + 1) % 3])
        mid = evaluate(root[t], mid_bary)
        ends = values[edges[candidate]]  # (n, 2, C)
        top = max(float(np.abs(values).max(initial=0.0)), float(np.abs(mid).max(initial=0.0)))
        floor = DARK_FLOOR * top
        scale = np.maximum(np.maximum(np.abs(ends).max(1), np.abs(mid)), floor).max(1)
        error = np.abs(mid - ends.mean(1)).max(1)
        bad = (error > tol * np.maximum(scale, 1e-300)) | (length[candidate] > max_edge)
        split = candidate[bad]
        settled = np.union1d(settled, key[candidate[~bad]])
        if split.size == 0:
            break
        # new vertices at the split edges' midpoints (flat: the twin keeps the user's shape)
        new_vertex = np.full(len(edges), -1, np.int64)
        new_vertex[split] = len(positions) + np.arange(split.size)
        keep = np.isin(candidate, split)
        positions = np.concatenate([positions, positions[edges[split]].mean(1)])
        values = np.concatenate([values, mid[keep]])
        triangles, root, bary = _split(triangles, root, bary, new_vertex[inverse].reshape(-1, 3))
        if progress is not None:
            progress("refine", passes / MAX_PASSES)
    return Refined(positions, triangles, root, bary, values, passes, budget)


def _split(triangles, root, bary, midpoint):
    """Cut triangles along their split edges (`midpoint` (T, 3): new vertex of edge k, or -1)."""
    flags = midpoint >= 0
    n = flags.sum(1)
    out = [(triangles[n == 0], root[n == 0], bary[n == 0])]
    for count, children in ((1, _ONE), (2, _TWO), (3, _THREE)):
        sel = np.flatnonzero(n == count)
        if sel.size == 0:
            continue
        # rotate so the split edges are 0 (one), 0 and 1 (two: the unsplit one is edge 2)
        if count == 1:
            r = np.argmax(flags[sel], axis=1)
        elif count == 2:
            r = (np.argmin(flags[sel], axis=1) + 1) % 3
        else:
            r = np.zeros(sel.size, np.int64)
        local = (r[:, None] + np.arange(3)) % 3  # (n, 3) original corner of rotated corner
        tv = np.take_along_axis(triangles[sel], local, 1)
        tm = np.take_along_axis(midpoint[sel], local, 1)  # edge k of the rotated triangle
        tb = np.take_along_axis(bary[sel], local[..., None], 1)
        for child in children:
            corners_v, corners_b = [], []
            for i, j in child:
                if i == j:
                    corners_v.append(tv[:, i])
                    corners_b.append(tb[:, i])
                else:
                    edge = i if (i + 1) % 3 == j else j  # edge index of the pair
                    corners_v.append(tm[:, edge])
                    corners_b.append(0.5 * (tb[:, i] + tb[:, j]))
            out.append((np.stack(corners_v, 1), root[sel], np.stack(corners_b, 1)))
    return tuple(np.concatenate(parts) for parts in zip(*out))
