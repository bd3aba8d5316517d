"""Points of a result mesh as core queries, and the radiance gathered there (numpy only).

This is the one place where a point of a Blender result mesh (a triangle of its loop
triangulation and barycentric coordinates in it) becomes what the core answers for: the item
(core surface handle) that covers it and its (u, v) on that surface. Lightmaps (`lightmap`) and
refined twins (`refine`) both ask through `MeshSurfaces.locate` and `gather`.

Each triangle is covered by the collected item that holds most of its corners (a quad piece
holds both triangles of its quad, a UV sphere or NURBS spline all of its own). A point's (u, v)
is found by Gauss-Newton projection of its world position onto that item's surface, started
from the corners' parameters interpolated across the triangle. Before interpolating, corner
parameters are made consistent: across a periodic seam (a sphere's azimuth 0 = 2 pi) they are
unwrapped to one side, and at a collapsed corner (a pole, where P does not depend on v) the free
parameter takes the mean of the other corners'.
"""

from dataclasses import dataclass

import numpy as np

from . import core

# Gauss-Newton steps of the projection (bilinear quads converge in 2-3, sphere patches in 4-5)
PROJECTION_STEPS = 8
# points per `radiosity_at` call; progress and cancel are polled between calls
GATHER_BLOCK = 4096


@dataclass
class Located:
    """Core queries for K mesh points.

    Attributes
    ----------
    item : ndarray of int64, shape (K,)
        Index into `Collected.surfaces` (and the session's surface handles).
    u, v : ndarray, shape (K,)
        Parameters on that item's surface.
    x : ndarray, shape (K, 3)
        World position of the mesh point.
    """

    item: np.ndarray
    u: np.ndarray
    v: np.ndarray
    x: np.ndarray


class MeshSurfaces:
    """A result mesh's triangles and the collected items that cover them.

    Parameters
    ----------
    positions : ndarray, shape (V, 3)
        World positions of the result mesh's vertices (the mesh the items' `vertices` index).
    triangles : ndarray of int, shape (T, 3)
        Vertex indices of its loop triangles.
    surfaces : list of SurfaceItem
        All collected items (`Collected.surfaces`).
    target : str
        The result target's name; only its items cover the mesh.

    Raises
    ------
    ValueError
        If no item of `target` covers any of the triangles.
    """

    def __init__(self, positions, triangles, surfaces, target):
        self.positions = np.asarray(positions, dtype=np.float64)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.surfaces = [item.surface for item in surfaces]
        n_vertices = len(self.positions)
        # (item, vertex, u, v) rows of the target's items, sorted by key item * V + vertex
        mine = [k for k, item in enumerate(surfaces) if item.target == target]
        rows_item = np.concatenate([np.full(len(surfaces[k].vertices), k) for k in mine] or [np.zeros(0)])
        rows_item = rows_item.astype(np.int64)
        rows_vertex = np.concatenate([surfaces[k].vertices for k in mine] or [np.zeros(0)]).astype(np.int64)
        rows_params = np.concatenate([surfaces[k].params for k in mine] or [np.zeros((0, 2))])
        key = rows_item * n_vertices + rows_vertex
        order = np.argsort(key, kind="stable")
        self._key, self._params = key[order], rows_params[order]
        self._n_vertices = n_vertices
        self.item = self._cover(rows_item, rows_vertex)
        if len(self.triangles) and np.all(self.item < 0):
            raise ValueError(f"{target!r}: no collected surface covers its mesh")
        self._periodic = {}

    def _cover(self, rows_item, rows_vertex):
        """The item holding most corners of each triangle, shape (T,) (-1: none)."""
        T = len(self.triangles)
        if T == 0 or rows_item.size == 0:
            return np.full(T, -1, np.int64)
        # every (triangle, item) incidence through a shared corner vertex
        by_vertex = np.argsort(rows_vertex, kind="stable")
        sorted_vertex = rows_vertex[by_vertex]
        corners = self.triangles.ravel()
        first = np.searchsorted(sorted_vertex, corners, "left")
        count = np.searchsorted(sorted_vertex, corners, "right") - first
        triangle = np.repeat(np.arange(corners.size) // 3, count)
        offset = np.arange(triangle.size) - np.repeat(np.cumsum(count) - count, count)
        item = rows_item[by_vertex[np.repeat(first, count) + offset]]
        n_items = int(rows_item.max()) + 1
        pair, hits = np.unique(triangle * n_items + item, return_counts=True)
        triangle, item = pair // n_items, pair % n_items
        # most hits per triangle (ties: the lower item index)
        order = np.lexsort((item, -hits, triangle))
        triangle, item = triangle[order], item[order]
        best = np.ones(triangle.size, bool)
        best[1:] = triangle[1:] != triangle[:-1]
        out = np.full(T, -1, np.int64)
        out[triangle[best]] = item[best]
        return out

    def points(self, triangle, bary):
        """World positions of barycentric points, shape (K, 3)."""
        corners = self.positions[self.triangles[triangle]]
        return np.einsum("kc,kcj->kj", bary, corners)

    def locate(self, triangle, bary):
        """Core queries for points given by triangle and barycentric coordinates.

        Parameters
        ----------
        triangle : ndarray of int, shape (K,)
        bary : ndarray, shape (K, 3)

        Returns
        -------
        Located
            Points on uncovered triangles get item -1 (and u = v = 0).
        """
        triangle = np.asarray(triangle, dtype=np.int64)
        bary = np.asarray(bary, dtype=np.float64)
        x = self.points(triangle, bary)
        item = self.item[triangle]
        u = np.zeros(len(triangle))
        v = np.zeros(len(triangle))
        order = np.argsort(item, kind="stable")
        bounds = np.flatnonzero(np.diff(item[order])) + 1
        for group in np.split(order, bounds):  # one pass per covering item
            k = int(item[group[0]]) if group.size else -1
            if k < 0:
                continue
            if isinstance(self.surfaces[k], core.PolygonMesh):
                # a mesh point is addressed by its face (u) and its world position (`x`)
                u[group] = self._mesh_face(k, triangle[group])
                continue
            guess = self._guess(k, triangle[group], bary[group])
            u[group], v[group] = project(self.surfaces[k], x[group], guess, self._is_periodic(k))
        return Located(item, u, v, x)

    def _mesh_face(self, k, triangle):
        """The face of item k's PolygonMesh that each triangle lies in, shape (K,): the face
        whose corner samples hold the most of the triangle's corners (all three for a loop
        triangle of that face)."""
        unique, back = np.unique(triangle, return_inverse=True)
        corners = self.triangles[unique].ravel()  # (3n,)
        key = k * self._n_vertices + corners
        first = np.searchsorted(self._key, key, "left")
        count = np.searchsorted(self._key, key, "right") - first
        owner = np.repeat(np.arange(corners.size) // 3, count)
        row = np.repeat(first, count) + np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)
        face = self._params[row, 0].astype(np.int64)
        faces = int(face.max()) + 1 if face.size else 1
        pair, hits = np.unique(owner * faces + face, return_counts=True)
        owner, face = pair // faces, pair % faces
        order = np.lexsort((face, -hits, owner))
        owner, face = owner[order], face[order]
        best = np.ones(owner.size, bool)
        best[1:] = owner[1:] != owner[:-1]
        chosen = np.zeros(len(unique), np.int64)
        chosen[owner[best]] = face[best]
        return chosen[back].astype(np.float64)

    def _is_periodic(self, k):
        """(periodic in u, periodic in v) of item k's surface: P equal at both ends of its domain."""
        if k not in self._periodic:
            surface = self.surfaces[k]
            (u0, u1), (v0, v1) = surface.domain
            s = np.linspace(0.1, 0.9, 5)
            P = surface.derivatives
            size = np.ptp(P(u0 + s * (u1 - u0), v0 + s[:, None] * (v1 - v0))[0].reshape(-1, 3), axis=0).max()
            gap_u = np.abs(P(u0, v0 + s * (v1 - v0))[0] - P(u1, v0 + s * (v1 - v0))[0]).max()
            gap_v = np.abs(P(u0 + s * (u1 - u0), v0)[0] - P(u0 + s * (u1 - u0), v1)[0]).max()
            self._periodic[k] = (bool(gap_u <= 1e-9 * size), bool(gap_v <= 1e-9 * size))
        return self._periodic[k]

    def _guess(self, k, triangle, bary):
        """Initial (u, v) of points of item k: consistent corner parameters interpolated, (K, 2)."""
        unique, back = np.unique(triangle, return_inverse=True)
        corners = self.triangles[unique]  # (n, 3)
        key = k * self._n_vertices + corners
        where = np.clip(np.searchsorted(self._key, key), 0, max(len(self._key) - 1, 0))
        known = self._key[where] == key
        params = np.where(known[..., None], self._params[where], np.nan)
        surface = self.surfaces[k]
        periodic = self._is_periodic(k)
        # corners where moving in u (or v) does not move the point: that parameter is free
        _, Pu, Pv = surface.derivatives(np.nan_to_num(params[..., 0]), np.nan_to_num(params[..., 1]))
        scale = np.maximum(np.linalg.norm(Pu, axis=-1), np.linalg.norm(Pv, axis=-1)).max(initial=0.0)
        collapsed = (np.linalg.norm(Pu, axis=-1) <= 1e-9 * scale, np.linalg.norm(Pv, axis=-1) <= 1e-9 * scale)
        for axis in (0, 1):
            (a, b) = surface.domain[axis]
            value = params[..., axis]
            fixed = known & ~collapsed[axis]
            if periodic[axis]:
                # unwrap onto the side of the first well-defined corner
                ref_index = np.argmax(fixed, axis=1)
                ref = value[np.arange(len(value)), ref_index][:, None]
                period = b - a
                value = np.where(fixed, value + period * np.round((ref - value) / period), value)
            # free or unknown corners take the mean of the well-defined ones (or the domain centre)
            n_fixed = fixed.sum(1, keepdims=True)
            mean = np.where(fixed, value, 0.0).sum(1, keepdims=True) / np.maximum(n_fixed, 1)
            mean = np.where(n_fixed > 0, mean, 0.5 * (a + b))
            params[..., axis] = np.where(fixed, value, mean)
        return np.einsum("kc,kcj->kj", bary, params[back])


def project(surface, x, guess, periodic=(False, False), steps=PROJECTION_STEPS):
    """Parameters of the points of `surface` nearest to `x` (Gauss-Newton, started at `guess`).

    Minimises |P(u, v) - x|^2 with the normal equations of J = [dP/du, dP/dv]; a singular J (a
    pole) is regularised. Each step stays in the domain: wrapped in a periodic direction, clipped
    otherwise.

    Parameters
    ----------
    surface : core.Surface
    x : ndarray, shape (K, 3)
    guess : ndarray, shape (K, 2)
    periodic : (bool, bool)

    Returns
    -------
    u, v : ndarray, shape (K,)
    """
    (u0, u1), (v0, v1) = surface.domain
    u, v = _into(guess[:, 0], u0, u1, periodic[0]), _into(guess[:, 1], v0, v1, periodic[1])
    for _ in range(steps):
        du, dv = core.surface.nearest_step(x, *surface.derivatives(u, v))
        # no step longer than a quarter of the domain (far guesses stay on their side)
        du = np.clip(du, -0.25 * (u1 - u0), 0.25 * (u1 - u0))
        dv = np.clip(dv, -0.25 * (v1 - v0), 0.25 * (v1 - v0))
        u, v = _into(u + du, u0, u1, periodic[0]), _into(v + dv, v0, v1, periodic[1])
    return u, v


def _into(t, a, b, periodic):
    return a + np.mod(t - a, b - a) if periodic else np.clip(t, a, b)


def gather(
    sol, handles, located, side="front", progress=None, cancel=None, stage="gather", block=GATHER_BLOCK
):
    """Radiance (W / (m^2 sr)) at located points: `Solution.radiosity_at`, item by item in blocks.

    Parameters
    ----------
    sol : core Solution
    handles : list
        Core handle of each item of `Collected.surfaces`.
    located : Located
    side : {"front", "back"}
    progress : callable(stage, fraction) or None
        Called between blocks.
    cancel : callable() -> bool or None
        Polled between blocks; True raises core.Cancelled.

    Returns
    -------
    ndarray, shape (K, 3)
        Zero for points of no item.
    """
    out = np.zeros((len(located.item), 3))
    order = np.argsort(located.item, kind="stable")
    order = order[located.item[order] >= 0]
    bounds = np.flatnonzero(np.diff(located.item[order])) + 1
    done, total = 0, max(order.size, 1)
    _report(progress, cancel, stage, 0.0)
    for group in np.split(order, bounds) if order.size else []:
        handle = handles[int(located.item[group[0]])]
        for start in range(0, group.size, block):
            part = group[start : start + block]
            if isinstance(sol.surface(handle), core.PolygonMesh):
                faces = located.u[part].astype(np.int64)
                out[part] = sol.radiosity_at(handle, faces, located.x[part], side=side)
            else:
                out[part] = sol.radiosity_at(handle, located.u[part], located.v[part], side=side)
            done += part.size
            _report(progress, cancel, stage, done / total)
    return out


def _report(progress, cancel, stage, fraction):
    if progress is not None:
        progress(stage, fraction)
    if cancel is not None and cancel():
        raise core.Cancelled(f"radiosity {stage} cancelled")
