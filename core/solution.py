"""The result of a radiosity solve (`Solution`): radiosities per patch and vertex, and gathered at
any point of a surface (`Solution.radiosity_at`), with relights that reuse the solved factors.
"""

import time

import numpy as np

from . import checks, nearfield, ragged
from .bounds import unit_vectors
from .elements import piece_patches
from .gathered import GatherFactors
from .mesh import PolygonMesh
from .pointgather import gather
from .runner import Run

CONTACT_INSET = 2e-6  # gathered points move this times their coordinates' size off a border
MAX_INSET = 1e-3  # (at most this fraction of the parameter range)


class Solution:
    """Result of `Scene.solve`.

    Attributes
    ----------
    stats : dict
        "times" (seconds per stage: elements, lights, form factors, visibility, solve, gather),
        "evaluations" (kernel evaluations), "rays", "ray_tests", pair counts per culling rule
        ("pairs_total", "pairs_culled_facing", "pairs_culled_rows_columns", "pairs_culled_shaft",
        "pairs_shadow_tested", "pairs_cached"), "back_pairs" (pairs whose back-side factor was
        computed), "rows_enclosed" and "rows_balanced" (rows whose blocked total was made exact, see
        `closure`), "pairs_exact" (pairs given exact visibility), "pairs_kinked" (pairs across a
        horizon integrated again, `PairCache.refine_kinks`), "bvh_nodes" and "bvh_primitives"
        (nodes visited and primitives tested in the occluders' hierarchies, `bvh.BVH`), "solver",
        "iterations", "residual", "error_bound" and "fallback" (see `solvers.solve`),
        "memory_bytes" (cached pair data and matrix), "peak_rss_bytes", "threads".
    """

    def __init__(self, scene, geometry, B, occlusion, tol, stats, threads=None, matrix=None):
        self._geometry = geometry
        self._threads = threads
        self._matrix = matrix if matrix is not None else (np.zeros(0, int), np.zeros(0, int), np.zeros(0))
        self._B = B
        self._occlusion = occlusion
        self.exact_shadows = True  # radiosity_at: exact shadows where supported (False: sampled rays)
        self.links_gather = None  # radiosity_at through a hierarchy's links (`hgather`), if solved so
        self.near_field = True  # radiosity_at: near elements resolved by a final gather (`nearfield`)
        self._near = None  # the near field, built on first use (`_near_field`)
        self._tol = tol
        self.stats = stats
        # materials and lights as solved (later edits of the scene do not change this result)
        self._rho, self._E, self._lights, self._sky = scene.materials()
        # what every gather needs: elements that carry light, and the emitting ones
        self._carries = np.flatnonzero(np.any(B != 0, axis=1))
        self._emitters = (np.array(self._E).max(1) > 0)[geometry.elements.owner]
        if np.any(self._sky > 0):
            # under a sky every occluder element counts, as the sky it hides (see `radiosity_at`)
            occluding = geometry.occluding
            self._carries = np.flatnonzero(np.any(B != 0, axis=1) | occluding)
            self._gathered = B - occluding[:, None] * self._sky[None]
        else:
            self._gathered = B

    def surface(self, handle):
        """The surface (or PolygonMesh) that `handle` was solved with."""
        return self._geometry.surfaces[checks.handle(handle, len(self._geometry.ranges), "surface")]

    def form_factor_matrix(self):
        """The solved system's form factors with visibility, dense, shape (N, N).

        Element order: surfaces in the order added, each one's front patches (u-major), then
        its back patches if two-sided. Rows skipped by culling (black, non-emitting patches)
        and pairs culled as facing away are zero.
        """
        r, c, v = self._matrix
        N = len(self._B)
        F = np.zeros((N, N))
        np.add.at(F, (r, c), v)
        return F

    def element_areas(self):
        """Areas (m^2) of the elements in `form_factor_matrix` order, shape (N,)."""
        return self._geometry.elements.area.copy()

    def _elements_of(self, handle, side):
        handle = checks.handle(handle, len(self._geometry.ranges), "surface")
        start, count, two_sided = self._geometry.ranges[handle]
        if side not in ("front", "back"):
            raise ValueError(f'side must be "front" or "back", got {side!r}')
        if side == "back":
            if not two_sided:
                raise ValueError(f"surface {handle} is one-sided: it has no back results")
            start += count
        return np.arange(start, start + count)

    def radiosity(self, handle, side="front"):
        """Per-patch radiosity, shape (nu * nv, 3); patch i * nv + j is parameter cell (i, j).

        For a `PolygonMesh`: per face, shape (F, 3), in the mesh's face order: the area-weighted
        mean over the face's patches. A skipped face (no area) gets the mean of its corners'
        `vertex_radiosity`.
        """
        elements = self._elements_of(handle, side)
        mesh = self._geometry.surfaces[handle]
        if not isinstance(mesh, PolygonMesh):
            return self._B[elements].copy()
        area = self._geometry.elements.area[elements]
        face = self._element_face(handle)
        weight = np.bincount(face, area, minlength=mesh.face_count)
        B = np.stack([np.bincount(face, area * self._B[elements, c], mesh.face_count) for c in range(3)], 1)
        B = np.divide(B, weight[:, None], out=np.zeros_like(B), where=weight[:, None] > 0)
        if mesh.skipped.size:
            vertex = self.vertex_radiosity(handle, side)
            for f in mesh.skipped:
                B[f] = vertex[mesh.corners_of(f)].mean(0)
        return B

    def _element_face(self, handle):
        """Face of each front element of mesh `handle`, shape (patches,)."""
        mesh = self._geometry.surfaces[handle]
        return np.repeat(mesh.piece_face, piece_patches(self._geometry.objects_grid[handle]))

    def _piece_cells(self, handle):
        """Grid (P, 2) of each piece of mesh `handle` and its first patch's offset, shape (P,)."""
        grid = np.asarray(self._geometry.objects_grid[handle], dtype=np.int64).reshape(-1, 2)
        count = grid[:, 0] * grid[:, 1]
        return grid, ragged.starts(count)

    def vertex_radiosity(self, handle, side="front"):
        """Per-vertex radiosity of a `PolygonMesh`, shape (V, 3).

        The rule: B(v) = sum_e A_e B_e / sum_e A_e over the patches e that hold vertex v as a
        corner (the corner cells of the faces around v; the limit of the piecewise constant
        solution from each face, weighted by area). Vertices of no face get zero.

        Raises
        ------
        ValueError
            If the surface is not a mesh.
        """
        elements = self._elements_of(handle, side)
        mesh = self._geometry.surfaces[handle]
        if not isinstance(mesh, PolygonMesh):
            raise ValueError(f"surface {handle} is not a PolygonMesh: vertex_radiosity needs a mesh")
        grid, offset = self._piece_cells(handle)
        nu, nv = grid[:, :1], grid[:, 1:]
        # corner cells (i, j) of p00, p10, p11, p01 (a triangle's p01 repeats p00: left out)
        cells = np.concatenate([0 * nu, (nu - 1) * nv, nu * nv - 1, nv - 1], axis=1)
        P = len(mesh.piece_face)
        element = offset[:, None] + cells
        vertex = mesh.piece_vertices
        keep = np.ones((P, 4), dtype=bool)
        keep[:, 3] = vertex[:, 3] != vertex[:, 0]
        element, vertex = elements[element[keep]], vertex[keep]
        area = self._geometry.elements.area[element]
        V = len(mesh.vertices)
        weight = np.bincount(vertex, area, minlength=V)
        B = np.stack([np.bincount(vertex, area * self._B[element, c], V) for c in range(3)], 1)
        return np.divide(B, weight[:, None], out=np.zeros_like(B), where=weight[:, None] > 0)

    def radiosity_at(self, handle, u, v, side="front"):
        """Radiosity at parameter points, gathered from every patch (with occlusion), shape (k, 3).

        B(x) = E + rho * (sum_j F(x -> j) V(x, j) B_j + direct irradiance / pi): smooth inside
        patches and right at shadow edges and contacts, not an interpolation of patch values.

        For a `PolygonMesh`, a point is addressed by its face: u holds face indices, shape (k,),
        and v the points (m), shape (k, 3), on those faces (projected onto the face's piece
        nearest to them); a point on a face's edge or corner gets the limit from inside that
        face (so a mesh vertex has one value per face around it).
        Under a sky of radiance L the gathered sum is L + sum_j F(x -> j) V(x, j) (B_j - L) with
        the sky taken off the occluders' B_j: what each of them hides of the sky.
        """
        return self._gather(handle, u, v, side, keep=False)[0]

    def gather_factors(self, handle, u, v, side="front"):
        """`radiosity_at`'s factors at parameter points, kept for relighting (`gathered`).

        The gather runs toward every element that may carry light in a relight (those with a
        nonzero reflectance or emission, and under a sky every occluder), so it costs somewhat
        more than `radiosity_at`; `radiosity_from` then re-applies it to any later solution of
        the same geometry.

        Returns
        -------
        gathered.GatherFactors
        """
        return self._gather(handle, u, v, side, keep=True)[1]

    def radiosity_from(self, factors):
        """Radiosity at the points of kept `factors` (`gather_factors`, possibly of an earlier
        solution of the same geometry) with this solution's radiosities, materials, lights and
        sky: one matrix product, shape (K, 3). A merged point (`GatherFactors.merged`) gets the
        weighted sum of the radiosities of the points it stands for.

        Raises
        ------
        ValueError
            If the factors belong to another geometry, lights were added or removed, or an
            element outside the factors' targets now carries light.
        """
        if not isinstance(factors, GatherFactors):
            raise checks.ArgumentTypeError(f"radiosity_from needs GatherFactors, got {factors!r}")
        if factors.geometry is not self._geometry:
            raise ValueError("these gather factors belong to another geometry: gather again")
        if factors.direct.shape[1] != len(self._lights):
            raise ValueError(
                f"the gather factors know {factors.direct.shape[1]} lights, the solution has "
                f"{len(self._lights)}: gather again"
            )
        if np.any(self._gathered[~factors.targets] != 0):
            raise ValueError(
                "elements the factors left out now carry light (a black surface lit): gather again"
            )
        w = factors.weight[:, None]  # 1, or the total weight of the points a merged one sums
        arriving = factors.product(self._gathered) + w * self._sky[None]
        near = factors.near
        if near is not None:  # the near field's nodes solved again (`nearfield`)
            nodes = near.system.nodes
            rho = np.array(self._rho)[nodes.handle]
            start = self._B[near.system.node_element]
            base = self.radiosity_from(nodes)
            threads = self._threads or 1
            arriving += near.arriving(base, rho, self._sky, self._tol, start, len(factors), threads)
        if self._lights:
            power = np.array([p for _, p in self._lights])  # (lights, 3)
            arriving += factors.direct @ power / np.pi
        h = factors.handle
        return w * np.array(self._E)[h] + np.array(self._rho)[h] * arriving

    def _gather(self, handle, u, v, side, keep):
        """(radiosity (k, 3), GatherFactors or None) at parameter points (see `radiosity_at`)."""
        elements_of = self._elements_of(handle, side)
        geometry = self._geometry
        surface = geometry.surfaces[handle]
        if isinstance(surface, PolygonMesh):
            x, n, home, aside = self._mesh_points(handle, elements_of, u, v, side)
            # a vertex's corners on coplanar faces (the inside of a flat grid) are one point of
            # the same plane, so one gather serves them all; but a vertex touching another
            # object may have corners on both sides of it (a floor vertex on the edge of a box
            # resting there: corners under the box and beside it, each moved into its face).
            # Its corners are gathered one by one, each also moved the same small step along
            # its face's two axes and their diagonals both ways (a face may span both sides: a
            # merged floor, `PolygonMesh.merge_coplanar`), and it takes the brightest: the limit on its
            # visible side, what a render shows beside the box (Cycles' vertex bake averages the
            # corners: about half of it there)
            vertex = np.reshape(v, (-1, 3))
            first, group = _coincident(vertex, n)
            touching = geometry.touching(handle, vertex[first])[group]
            key = group * (len(geometry.elements) + 1) + np.where(touching, home + 1, 0)
            _, reps = np.unique(key, return_index=True)
            k = x.shape[0]
            moved, way = np.nonzero(touching[reps, None] & np.isfinite(aside[reps, :, 0]))
            source = reps[moved]
            reps = np.concatenate([reps, k + np.arange(source.size)])
            group = np.concatenate([group, group[source]])
            x = np.concatenate([x, aside[source, way]])
            n = np.concatenate([n, n[source]])
            home = np.concatenate([home, home[source]])
            B, factors = self._gather_points(handle, elements_of, x[reps], n[reps], home[reps], keep)
            order = np.lexsort((-B.sum(1), group[reps]))  # (each group's brightest first)
            ordered = group[reps][order]
            lead = np.r_[True, ordered[1:] != ordered[:-1]]
            brightest = np.zeros(first.size, dtype=np.int64)
            brightest[ordered[lead]] = order[lead]
            pick = brightest[group[:k]]
            return B[pick], (factors.take(pick) if factors is not None else None)
        u = np.atleast_1d(checks.finite_array(u, "radiosity_at u")).ravel()
        v = np.atleast_1d(checks.finite_array(v, "radiosity_at v")).ravel()
        if u.shape != v.shape:
            raise ValueError(f"u and v must have the same length, got {u.size} and {v.size}")
        (u0, u1), (v0, v1) = surface.domain
        slack_u, slack_v = 1e-9 * (u1 - u0), 1e-9 * (v1 - v0)
        if np.any((u < u0 - slack_u) | (u > u1 + slack_u) | (v < v0 - slack_v) | (v > v1 + slack_v)):
            raise ValueError(f"(u, v) outside the surface's domain {surface.domain}")
        u, v = np.clip(u, u0, u1), np.clip(v, v0, v1)
        if side == "back":
            surface = surface.flipped()
        # the limit from inside the surface: a point on its border would lie in the plane of
        # a neighbour that meets it at an edge (where that neighbour's cosine vanishes), or, with
        # coordinates rounded to float32 as Blender stores them, just behind a surface it touches
        # (a wall standing on a floor: the floor would hide the light); so the point moves
        # into the domain by about CONTACT_INSET of its coordinates' size (points further in
        # stay where they are)
        x, _ = surface.evaluate(u, v)
        centre, _ = surface.evaluate(np.full(1, 0.5 * (u0 + u1)), np.full(1, 0.5 * (v0 + v1)))
        reach = np.linalg.norm(x - centre, axis=-1)
        size = np.linalg.norm(x, axis=-1) + reach
        inset = np.clip(CONTACT_INSET * size / np.maximum(reach, 1e-300), 1e-7, MAX_INSET)
        u = np.clip(u, u0 + inset * (u1 - u0), u1 - inset * (u1 - u0))
        v = np.clip(v, v0 + inset * (v1 - v0), v1 - inset * (v1 - v0))
        x, n = _points_and_normals(surface, u, v)
        # the element holding each point (u-major cells of the patch grid)
        nu, nv = geometry.objects_grid[handle]
        cu = np.clip(((u - u0) / (u1 - u0) * nu).astype(np.int64), 0, nu - 1)
        cv = np.clip(((v - v0) / (v1 - v0) * nv).astype(np.int64), 0, nv - 1)
        home = elements_of[cu * nv + cv]
        return self._gather_points(handle, elements_of, x, n, home, keep)

    def _mesh_points(self, handle, elements_of, faces, points, side):
        """Points on mesh faces: inset points x (k, 3), unit normals (k, 3), home elements (k,),
        and the points moved by the inset's step along the face's two axes and its diagonals
        both ways instead, shape (k, 8, 3) (NaN where that leaves the face)."""
        mesh = self._geometry.surfaces[handle]
        e = self._geometry.elements
        f = np.atleast_1d(np.asarray(faces))
        if f.ndim != 1 or not (np.issubdtype(f.dtype, np.integer) or f.size == 0):
            raise checks.ArgumentTypeError(f"radiosity_at on a mesh: u must be face indices (k,), got {f!r}")
        x = checks.finite_array(points, "radiosity_at points").reshape(-1, 3) if f.size else np.zeros((0, 3))
        if x.shape[0] != f.size:
            raise ValueError(
                f"radiosity_at on a mesh: {f.size} faces but {x.shape[0]} points (v must be (k, 3))"
            )
        if f.size and (f.min() < 0 or f.max() >= mesh.face_count):
            raise ValueError(f"radiosity_at: face indices must be in 0 .. {mesh.face_count - 1}")
        bad = np.intersect1d(f, mesh.skipped)
        if bad.size:
            raise ValueError(f"radiosity_at: faces {bad.tolist()} of the mesh were skipped (no area)")
        # candidate pieces of each point's face; the one nearest the point (by its centroid and
        # a point-in-piece test) holds it
        query, piece = ragged.runs_of(mesh.piece_face, f)
        C = mesh.piece_corners[piece]
        centroid = C.mean(1)
        normal = np.cross(C[:, 2] - C[:, 0], C[:, 3] - C[:, 1])
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        X = x[query]
        side_dist, length = _edge_sides(C, normal, X)
        outside = np.where(length > 0, -side_dist / np.where(length > 0, length, 1.0), 0.0).max(1)
        score = np.maximum(outside, 0.0) + 1e-12 * np.linalg.norm(X - centroid, axis=1)
        best = np.full(f.size, np.inf)
        np.minimum.at(best, query, score)
        chosen = np.full(f.size, -1)
        row = np.full(f.size, -1)  # (each point's chosen candidate: faces come in any order)
        hit = np.flatnonzero(score <= best[query])
        chosen[query[hit]], row[query[hit]] = piece[hit], hit
        # a point off its face (beyond rounding) is a wrong address, not a point to project
        corners = mesh.piece_corners[chosen]
        size = np.linalg.norm(corners.max(1) - corners.min(1), axis=1)
        height = np.abs(np.einsum("ki,ki->k", x - corners.mean(1), normal[row]))
        off = np.flatnonzero((np.maximum(best, height) > 1e-6 * size) if f.size else np.zeros(0, bool))
        if off.size:
            k = int(off[0])
            raise ValueError(
                f"radiosity_at: point {k} {x[k].tolist()} is not on face {int(f[k])} of the mesh"
                f" ({off.size} point(s) off their faces by more than 1e-6 of the face size)"
            )
        # project onto the piece's plane and inset toward its centroid (the limit from inside)
        c = corners.mean(1)
        nrm = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)[:, None]
        x = x - np.einsum("ki,ki->k", x - c, nrm)[:, None] * nrm
        # inset toward the centroid as parametric points are (see `_gather`: float32 contacts)
        reach = np.linalg.norm(x - c, axis=-1)
        size = np.linalg.norm(x, axis=-1) + reach
        inset = np.clip(CONTACT_INSET * size / np.maximum(reach, 1e-300), 1e-7, MAX_INSET)
        step = np.maximum(2.0 * inset * reach, 2.0 * CONTACT_INSET * size)  # (a point at the centroid too)
        axis = corners[:, 1] - corners[:, 0]
        axis /= np.maximum(np.linalg.norm(axis, axis=1), 1e-300)[:, None]
        other = np.cross(nrm, axis)
        axes = np.stack([axis, other, (axis + other) / np.sqrt(2.0), (axis - other) / np.sqrt(2.0)], 1)
        aside = x[:, None] + step[:, None, None] * np.concatenate([axes, -axes], 1)  # (k, 8, 3)
        within, length = _edge_sides(corners[:, None], nrm[:, None], aside)
        aside[~np.all((within > 0.0) | (length == 0.0), axis=-1)] = np.nan
        x = x + 2.0 * inset[:, None] * (c - x)
        if side == "back":
            nrm = -nrm
        # the home element: the patch of the chosen piece with the nearest centre
        grid, offset = self._piece_cells(handle)
        owner, cell = ragged.expand(offset[chosen], grid[chosen, 0] * grid[chosen, 1])
        candidates = elements_of[cell]
        distance = np.linalg.norm(e.center[candidates] - x[owner], axis=-1)
        best = np.full(f.size, np.inf)
        np.minimum.at(best, owner, distance)
        home = np.zeros(f.size, dtype=np.int64)
        home[owner[distance <= best[owner]]] = candidates[distance <= best[owner]]
        return x, nrm, home, aside

    def _gather_points(self, handle, elements_of, x, n, home, keep):
        """(B (k, 3), GatherFactors or None) at points x (k, 3) with unit normals n on surface
        `handle`, homes (k,): see `radiosity_at` and `gather_factors`. With `near_field`, the
        elements near a point are resolved by the near-field final gather (its first build
        counts in the gather's time, and on its own as "near field")."""
        start = time.perf_counter()
        links = self.links_gather is not None and not keep
        near = self.near_field and not links
        arriving, triplets, direct, targets, counts = self._arriving(
            elements_of[0], x, n, home, keep, keep or near
        )
        near_terms = None
        # (the near field is built on the first gather with a point that may couple to cells)
        if near and triplets[0].size:
            reach = nearfield.near_pairs(self._geometry.elements, x, *triplets, nearfield.COUPLE_RATIO)
            if reach.any():
                field = self._near_field()
                arriving, triplets, near_terms = field.resolve(x, n, arriving, triplets, reach, keep)
                self.stats.update(field.stats)
        B = self._E[handle][None] + self._rho[handle][None] * arriving
        factors = None
        if keep:
            factors = GatherFactors(
                np.full(len(x), int(handle)), *triplets, direct, targets, self._geometry, near=near_terms
            )
        times = self.stats["times"]
        times["gather"] = times.get("gather", 0.0) + time.perf_counter() - start
        self.stats["gather_points"] = self.stats.get("gather_points", 0) + len(x)
        self.stats["gather_rays"] = self.stats.get("gather_rays", 0) + counts["rays"]
        self.stats["gather_evaluations"] = self.stats.get("gather_evaluations", 0) + counts["evaluations"]
        self.stats["gather_shadow_lines"] = self.stats.get("gather_shadow_lines", 0) + counts["lines"]
        return B, factors

    def _arriving(self, first, x, n, home, keep, factors):
        """The light arriving at points x (k, 3) with unit normals n of the surface side of
        element `first` (homes (k,)), all of it (elements, sky, point, spot and sun lights).

        Returns (arriving (k, 3), (point, element, F V) triplets (empty unless `factors`),
        direct (k, lights) irradiance per unit power, the elements gathered from (N,) bool,
        counts)."""
        geometry = self._geometry
        e = geometry.elements
        query = dict(
            owner=int(e.owner[first]),
            geometry=int(e.geometry[first]),
            outward=bool(e.outward[first]),
        )
        shafts = geometry.shafts if self._occlusion else None
        run = Run(None, None, self._threads)
        targets = np.flatnonzero(self._relight_targets()) if keep else self._carries

        def work(block):
            if self.links_gather is not None and not keep:
                owner = np.full(len(block), query["owner"])
                outward = np.full(len(block), query["outward"])
                arriving, counts = self.links_gather(x[block], n[block], home[block], owner, outward)
                return arriving, dict(counts, tests=0)
            return gather(
                e,
                geometry.occluders,
                shafts,
                x[block],
                n[block],
                query,
                self._gathered,
                targets,
                self._tol,
                home[block],
                geometry,
                self._emitters,
                geometry.exact_shadows if self._occlusion and self.exact_shadows else None,
                keep=factors,
            )

        parts = run.blocks("gather", work, np.arange(len(x)), min_block=32) if len(x) else []
        arriving = np.concatenate([p[0] for p in parts]) if parts else np.zeros((0, 3))
        arriving = arriving + self._sky[None]
        keys = ("evaluations", "rays", "tests", "pairs", "lines")
        counts = {key: sum(p[1][key] for p in parts) for key in keys}
        triplets = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        if factors and parts:
            starts = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])  # blocks keep their order
            triplets = (
                np.concatenate([p[2][0] + s for p, s in zip(parts, starts)]),
                np.concatenate([p[2][1] for p in parts]),
                np.concatenate([p[2][2] for p in parts]),
            )
        # point, spot and sun lights
        direct = np.zeros((len(x), len(self._lights)))
        for index, (light, power) in enumerate(self._lights):
            value = light.unshadowed(x, n)
            if self._occlusion and geometry.shafts is not None:
                owner = np.full(len(x), query["owner"])
                outward = np.full(len(x), query["outward"])
                run = Run(None, None, 1)
                value = value * geometry.light_visibility(light, x, n, None, value > 0, run, owner, outward)
                counts["rays"] += run.stats["rays"]
            direct[:, index] = value
            arriving += value[:, None] * power[None] / np.pi
        flag = np.zeros(len(e), dtype=bool)
        flag[targets] = True
        return arriving, triplets, direct, flag, counts

    def _relight_targets(self):
        """Elements that may carry light after a relight, shape (N,) bool: those that carry it
        now, those with a nonzero reflectance or emission and, under a sky, every occluder."""
        geometry = self._geometry
        owner = geometry.elements.owner
        may = (np.array(self._rho).max(1) > 0)[owner] | (np.array(self._E).max(1) > 0)[owner]
        if np.any(self._sky > 0):
            may |= geometry.occluding
        may[self._carries] = True
        return may

    def _sides(self, element):
        """The surface sides that elements (Q,) lie on: (first element of the side, rows of
        `element` on it) for each side met."""
        geometry = self._geometry
        out = []
        for h in np.unique(geometry.elements.owner[element]):
            lo, size, two_sided = geometry.ranges[h]
            for side in (lo, lo + size)[: 1 + two_sided]:  # front, then a two-sided one's back
                on = np.flatnonzero((element >= side) & (element < side + size))
                if on.size:
                    out.append((side, on))
        return out

    def _near_field(self):
        """The near-field final gather of this solution (`nearfield.NearField`), built on first
        use (its nodes gather as `gather_factors` does, so it serves a relight too)."""
        if self._near is None:
            start = time.perf_counter()
            geometry = self._geometry
            self._near = nearfield.NearField(
                geometry.elements,
                self._B,
                self._gathered,
                self._node_arriving,
                self._node_radiosity,
                self._node_factors,
                geometry.occluding,
                self._sky,
                self._tol,
                self._threads or 1,
            )
            times = self.stats["times"]
            times["near field"] = times.get("near field", 0.0) + time.perf_counter() - start
        return self._near

    def _node_arriving(self, y, n, element):
        """The near field's gather at its nodes (`nearfield.NearField`'s `arrive`)."""
        arriving = np.zeros((len(y), 3))
        direct = np.zeros((len(y), len(self._lights)))
        triplets = []
        for first, on in self._sides(element):
            got = self._arriving(first, y[on], n[on], element[on], True, True)
            arriving[on], (k, j, F), direct[on] = got[:3]
            triplets.append((on[k], j, F))
        return arriving, tuple(np.concatenate(t) for t in zip(*triplets)), direct

    def _node_radiosity(self, element, arriving):
        """E + rho arriving at points of elements, and their rho, each shape (Q, 3)."""
        owner = self._geometry.elements.owner[element]
        rho = np.array(self._rho)[owner]
        return np.array(self._E)[owner] + rho * arriving, rho

    def _node_factors(self, element, triplets, direct):
        """GatherFactors of the near field's nodes on elements (Q,) (`nearfield.NearField`)."""
        owner = self._geometry.elements.owner[element]
        order = np.argsort(triplets[0], kind="stable")
        rows, cols, values = (t[order] for t in triplets)
        return GatherFactors(owner, rows, cols, values, direct, self._relight_targets(), self._geometry)


def _edge_sides(corners, normal, points):
    """normal . (edge x (point - edge start)) for the four edges of pieces `corners` (..., 4, 3)
    (counter-clockwise about `normal` (..., 3)): the point's distance inside each edge's line
    times the edge's length, shape (..., 4), and the edges' lengths (..., 4) (0: a triangle's
    repeated corner)."""
    edges = np.roll(corners, -1, axis=-2) - corners
    side = np.einsum("...i,...ji->...j", normal, np.cross(edges, points[..., None, :] - corners))
    return side, np.linalg.norm(edges, axis=-1)


def _coincident(points, normals):
    """Queries at the same point with the same unit normal (to 1e-9): the first of each group
    (U,) and each query's group (k,)."""
    if len(points) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    key = np.column_stack([np.asarray(points, dtype=float), np.round(normals * 1e9)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return first, inverse.ravel()


def _points_and_normals(surface, u, v):
    """Points and unit front normals; where the normal vanishes (a pole), the limit from inside."""
    x, normal = surface.evaluate(u, v)
    n, length = unit_vectors(normal)
    bad = np.flatnonzero(length <= 1e-12 * np.max(length, initial=0.0))
    if bad.size:
        (u0, u1), (v0, v1) = surface.domain
        cu, cv = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
        for eps in (1e-7, 1e-5, 1e-3):
            _, nn = surface.evaluate(u[bad] + eps * (cu - u[bad]), v[bad] + eps * (cv - v[bad]))
            unit_n, ln = unit_vectors(nn)
            n[bad] = np.where((ln > 0)[:, None], unit_n, n[bad])
    return x, n
