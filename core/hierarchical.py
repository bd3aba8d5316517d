"""Hierarchical radiosity for a scene: hierarchy, links and solves, kept for relights.

The runner of `Scene.solve(method="hierarchical")` (stages only; the maths is in `hierarchy`,
`links`, `refine` and `hsolve`):

1. build the patch hierarchy (once per geometry);
2. link the tree roots and refine (BF refinement, `refine`) against a first radiosity estimate;
3. solve (`hsolve`; the rows of enclosed leaves balanced to their exact totals, `hclosure`);
   re-check every link against the solved radiosity, refine those that fail, make exact the
   visibilities that need it, and solve again, until nothing changes (at most MAX_PASSES passes);
4. where the solved light varies over a patch by more than LIGHT_VARIATION of its radiosity
   (`light_levels`), give that patch sub-patches, graded SEAM_LEVELS more halvings toward the
   sides where another surface meets it and on the other surface's side of that seam
   (`hierarchy.seam_sides`: the light next to a seam varies over millimetres, where a wall's top
   under a ceiling lamp leaves its plane), and link and solve the refined tree again (once: a
   second build, like the contacts' in step 1; the first solve, which only has to find
   variations of LIGHT_VARIATION, links to the looser LIGHT_SURVEY_TOL);
5. results per user patch (its node of the hierarchy: a leaf, or the area mean of its
   sub-patches), and at points through the links of their leaf and its ancestors (`gatherer`,
   `hgather`).

A relight (new reflectances, emissions or light powers on the same geometry) re-solves on the
kept links and tree, re-checks the links (no kernel evaluation unless some link now fails) and
refines links only where the new light needs it; the sub-patches stay those of the first light.
"""

import time

import numpy as np

from . import coverage
from .hclosure import enclosed_leaves
from .hgather import LinkGather
from .hierarchy import (
    CONTACT_LEVELS,
    Hierarchy,
    contact_points,
    facing_patches,
    neighbour_patches,
    seam_sides,
    touching_patches,
)
from .hsolve import HierarchicalSystem
from .links import Links
from .refine import REFERENCE_FLOOR, LinkEstimator, Oracle, Refinement, ambient_estimate

MAX_PASSES = 4  # solve / re-check passes of one hierarchical solve
LIGHT_LEVELS = 0  # quadtree levels below a patch over which the light varies (off by default)
LIGHT_VARIATION = 0.05  # ... by more than this fraction of its radiosity
LIGHT_ORDER = 3  # Gauss points per parameter where a patch's arriving light is measured
LIGHT_SURVEY_TOL = 1e-2  # the first solve's tol, which only finds where the light varies
# halvings toward a seam below the light levels of a patch a seam bounds: against Cycles' probes
# 1 mm - 0.4 m from the seams of a lamp-lit box (tests/test_light_levels.py), 0: 17 % off at
# most, 2: 4.6 %, 3: 2.0 %, 4: 1.7 % (solve 2.2x that of 0), 6: 1.7 %
SEAM_LEVELS = 4


class HierarchicalRadiosity:
    """A scene's hierarchy and links for one geometry, tolerance, occlusion mode and reference.

    Parameters
    ----------
    sides : sequence of (surface, object, grid, first_element)
        One tree per surface side (see `hierarchy.Hierarchy`).
    occluders : occlusion.Occluders or None
    occluder_object : ndarray of int, shape (O,)
    tol : float
    occlusion : False, "direct", "sampled" or "exact"
        As `Scene.solve`'s: links get rays first, then exact visibility where the solved light
        shows their error (`refine.Refinement`) among every link ("exact", which also starts
        shadowed links from exact V), the links with an emitting end ("direct"), or none
        ("sampled").
    reference : {"receiver", "scene"}
        What link errors are relative to (see `refine`).
    contact_levels : int or None
        Levels of sub-patches below the patches that touch another surface (`hierarchy`);
        None: CONTACT_LEVELS.
    light_levels : int or None
        Levels of sub-patches below the patches over which the first solve's light varies
        (`light_levels`); None: LIGHT_LEVELS.
    halves : sequence of int, optional
        Per side: `hclosure.ONE_SIDED`, or the FRONT_HALF or BACK_HALF of a two-sided surface
        (for the enclosure test; default all one-sided).
    """

    def __init__(
        self,
        sides,
        occluders,
        occluder_object,
        tol,
        occlusion,
        reference="receiver",
        contact_levels=None,
        light_levels=None,
        halves=None,
    ):
        start = time.perf_counter()
        self.sides = list(sides)
        self.halves = None if halves is None else np.asarray(halves, dtype=np.int64)
        self.occluders, self.occluder_object, self.occlusion = occluders, occluder_object, occlusion
        self.tol = tol
        self.reference = reference
        hierarchy = Hierarchy(self.sides)
        # patches that touch another surface get more levels (`hierarchy`): a second build
        levels = CONTACT_LEVELS if contact_levels is None else contact_levels
        facing = facing_patches(hierarchy) if levels else None
        refined = touching_patches(hierarchy, facing=facing) if levels else [None] * len(self.sides)
        self.patch_levels = [
            np.zeros(grid[0] * grid[1], np.int64) if mask is None else mask * levels
            for (_, _, grid, _), mask in zip(self.sides, refined)
        ]
        # ... and cells graded toward the contact points below those levels
        self.foci = contact_points(hierarchy, facing=facing) if levels else [None] * len(self.sides)
        if any(np.any(depth) for depth in self.patch_levels):
            hierarchy = Hierarchy(self.sides, self.patch_levels, foci=self.foci)
        self.light_depth = LIGHT_LEVELS if light_levels is None else light_levels
        self.light_refined = False  # whether `light_levels` has refined the tree
        self.light_added = 0  # patches it refined
        self._build(hierarchy)
        self.build_time = time.perf_counter() - start

    def _build(self, hierarchy, tol=None):
        """Take `hierarchy` and start from no links (what depends on the tree), linking to `tol`
        (default: the solve's)."""
        self.hierarchy = h = hierarchy
        self.link_tol = self.tol if tol is None else tol
        # each node's part that another object covers (a box's footprint: `coverage`): the links'
        # visibilities hold only the free part, whose mean the solve takes as the node's radiosity
        covered = coverage.Coverage(h.elements, self.occluders, self.occluder_object, h.elements.scale)
        self.free = covered.free
        self.estimator = LinkEstimator(
            h, self.occluders, self.occluder_object, self.link_tol, self.occlusion, covered
        )
        # the row totals of enclosed leaves (`hclosure`), once occlusion applies
        self.hides_sky = np.isin(h.object, self.occluder_object)  # occluders, even without occlusion
        self.occluding = self.hides_sky if self.occlusion else None
        self.sky_offset = None  # the last solve's (`solve`)
        self.enclosed = None
        self.links = Links()
        self.B = None  # node radiosities of the last solve
        self.emitting = None  # its nodes with an emitting part (`_emitting_nodes`)
        patch = h.patch_nodes
        self.node_of = np.full(int(h.element.max()) + 1, -1, dtype=np.int64)  # scene element -> node
        self.node_of[h.element[patch]] = patch
        # ancestors of every node, the node itself first (-1 past the root), shape (M, levels)
        up = [np.arange(len(h))]
        while np.any(up[-1] >= 0):
            last = up[-1]
            up.append(np.where(last >= 0, h.parent[np.maximum(last, 0)], -1))
        self.ancestors = np.stack(up[:-1], 1)
        self._link_keys = None

    def known_visibility(self, a, b):
        """Visibility of element pairs from the link that carries them (either direction), NaN
        where no link does, shape (K,).

        Parameters
        ----------
        a, b : ndarray of int, shape (K,)
            Scene elements (user patch sides).
        """
        h, links = self.hierarchy, self.links
        M = len(h)
        if self._link_keys is None or self._link_keys[0] != len(links):
            keys = np.concatenate([links.receiver * M + links.source, links.source * M + links.receiver])
            order = np.argsort(keys, kind="stable")
            self._link_keys = (len(links), keys[order], np.concatenate([links.V, links.V])[order])
        _, keys, values = self._link_keys
        V = np.full(np.shape(a), np.nan)
        if keys.size == 0:
            return V
        A, B = self.ancestors[self.node_of[a]], self.ancestors[self.node_of[b]]
        for i in range(A.shape[1]):
            for j in range(B.shape[1]):
                todo = np.flatnonzero(np.isnan(V) & (A[:, i] >= 0) & (B[:, j] >= 0))
                if todo.size == 0:
                    continue
                key = A[todo, i] * M + B[todo, j]
                at = np.minimum(np.searchsorted(keys, key), keys.size - 1)
                found = keys[at] == key
                V[todo[found]] = values[at[found]]
        return V

    def gatherer(self):
        """`radiosity_at` through the links of the last solve (`hgather.LinkGather`): the links carry
        B - L from surfaces that hide a sky of radiance L (the caller adds L)."""
        return LinkGather(
            self.hierarchy,
            self.links,
            self.estimator,
            self.B - self.sky_offset,
            self.node_of,
            self.ancestors,
            self.emitting,
        )

    def solve(self, rho_objects, E_elements, max_bounces, run, sky=None, direct=None):
        """Refine and solve for the element radiosities.

        Parameters
        ----------
        rho_objects : ndarray, shape (objects, 3)
            Reflectance of every scene object.
        E_elements : ndarray, shape (N, 3)
            Emission plus direct light of every scene element (user patch side).
        max_bounces : int or None
        run : the scene's runner (stages, blocks, counts, cancel)
        sky : ndarray, shape (3,), optional
            Radiance of a uniform sky (`hsolve.HierarchicalSystem`).
        direct : (emission (N, 3), irradiance) or None
            Each element's own emission, and a callable (x (K, 3), unit normals (K, 3), element
            (K,)) -> irradiance (K, 3) from the point, spot and sun lights at points of elements:
            sub-patches get the direct light at their own points (`sub_patch_light`), and it
            counts in where the light varies (`light_levels`). None: sub-patches take their
            patch's (as E_elements has it).

        Returns
        -------
        B : ndarray, shape (N, 3)
        stats : dict
            "links", "links_per_patch", "nodes", "levels", "link_bytes", "link_evaluations",
            "refine_rounds", "passes", "iterations", "residual", "error_bound", "contraction",
            "patches_refined_by_light".
        """
        if self.light_depth and not self.light_refined:
            self.light_refined = True
            # a survey at a looser tol finds where the light varies (by LIGHT_VARIATION: far
            # above tol), then the refined tree is linked at tol
            survey = max(self.tol, LIGHT_SURVEY_TOL)
            if survey != self.tol:
                self._build(self.hierarchy, survey)
            first, _ = self._solve(rho_objects, E_elements, max_bounces, run, sky, direct)
            with run.stage("links"):
                pairs = neighbour_patches(self.hierarchy)
                levels = self.light_levels(rho_objects, direct, pairs)
            self.light_added = sum(int(np.count_nonzero(a > b)) for a, b in zip(levels, self.patch_levels))
            seams = self.seams(levels, pairs)
            self.patch_levels = levels
            if self.light_added or survey != self.tol:
                refined = Hierarchy(self.sides, levels, seams=seams, graded=SEAM_LEVELS, foci=self.foci)
                self._build(refined if self.light_added else self.hierarchy, self.tol)
            out, stats = self._solve(rho_objects, E_elements, max_bounces, run, sky, direct, start=first)
        else:
            out, stats = self._solve(rho_objects, E_elements, max_bounces, run, sky, direct)
        stats["patches_refined_by_light"] = self.light_added
        return out, stats

    def light_levels(self, rho_objects, direct=None, pairs=None):
        """Each side's patch levels after the last solve: `light_depth` more (at least) for the
        user patches over which the light arriving through the links varies by more than
        LIGHT_VARIATION of the patch's radiosity, shape (nu * nv,) per side.

        Only patches with a neighbour (`pairs`, default `hierarchy.neighbour_patches`: another
        surface within two bounding radii that exchanges light with it) count.
        A patch's radiosity is one mean, and the light gathered at a point next to it
        (`radiosity_at`: a vertex where a wall meets the ceiling, a texel by a shadow edge) takes
        the patch's mean where the true radiosity is what the patch has right there; a wall
        lit at grazing angles by a lamp just under the ceiling varies by a factor of several
        over its top patch. Measured at LIGHT_ORDER^2 Gauss points of the patch (`hgather`):
        rho times the spread of the arriving light (through the links, plus the lights' direct
        irradiance / pi with `direct`, see `solve`) about its area mean.
        """
        h = self.hierarchy
        # only where another surface gathers from close by (`neighbour_patches`): elsewhere a
        # point's own light is gathered exactly, and what it sees is far off
        near = np.zeros(len(h), dtype=bool)
        near[np.concatenate(neighbour_patches(h) if pairs is None else pairs)] = True
        patch = h.patch_nodes
        scale = self.B[patch].sum(1)
        scale = np.maximum(scale, REFERENCE_FLOOR * np.average(scale, weights=h.area[patch]))
        scale, patch = scale[near[patch]], patch[near[patch]]
        levels = [depth.copy() for depth in self.patch_levels]
        if patch.size == 0:
            return levels
        q = LIGHT_ORDER**2
        gather = self.gatherer()
        X, N, weight = h.rule(patch, LIGHT_ORDER)
        arriving, _ = gather(
            X,
            N,
            np.repeat(h.element[patch], q),
            np.repeat(h.object[patch], q),
            np.repeat(h.elements.outward[patch], q),
        )
        if direct is not None:
            arriving = arriving + direct[1](X, N, np.repeat(h.element[patch], q)) / np.pi
        arriving = arriving.sum(1).reshape(-1, q)
        mean = (weight * arriving).sum(1) / np.maximum(weight.sum(1), 1e-300)
        rho = rho_objects[h.object[patch]].max(1)
        spread = rho * np.abs(arriving - mean[:, None]).max(1)
        varies = spread > LIGHT_VARIATION * scale
        first = np.array([first for (_, _, _, first) in self.sides])
        side = h.tree[patch[varies]]
        index = h.element[patch[varies]] - first[side]
        for t in np.unique(side):
            at = index[side == t]
            levels[t][at] = np.maximum(levels[t][at], self.light_depth)
        return levels

    def seams(self, levels, pairs=None):
        """Per side, the seam sides (`hierarchy.seam_sides`, neighbours `pairs`) at the patches
        the light refines (`levels` above the current ones) and at their neighbours across those
        seams, shape (nu * nv,) int, or None."""
        h = self.hierarchy
        patch = h.patch_nodes
        first = np.array([first for (_, _, _, first) in self.sides])
        index = h.element[patch] - first[h.tree[patch]]
        offset = np.concatenate([[0], np.cumsum([depth.size for depth in levels])])
        at = offset[h.tree[patch]] + index
        lit = np.concatenate(levels)[at] > np.concatenate(self.patch_levels)[at]
        out = [None] * len(self.sides)
        if not lit.any():
            return out
        marks = seam_sides(h, patch[lit], pairs=pairs)[patch]
        for t in np.unique(h.tree[patch[marks > 0]]):
            at = (h.tree[patch] == t) & (marks > 0)
            nu, nv = self.sides[t][2]
            out[t] = np.zeros(nu * nv, np.int64)
            out[t][index[at]] = marks[at]
        return out

    def sub_patch_light(self, E, rho, direct):
        """Emission plus rho / pi times the lights' irradiance averaged over each sub-patch's own
        LIGHT_ORDER^2 Gauss points (as `Scene` averages a patch's), into E (M, 3) in place."""
        h = self.hierarchy
        sub = np.flatnonzero((h.child_count == 0) & (h.element < 0))
        if sub.size == 0:
            return
        emission, irradiance = direct
        q = LIGHT_ORDER**2
        X, N, weight = h.rule(sub, LIGHT_ORDER)
        element = h.element[h.patch_node[sub]]
        value = irradiance(X, N, np.repeat(element, q)).reshape(sub.size, q, 3)
        mean = np.einsum("kq,kqc->kc", weight, value) / np.maximum(weight.sum(1), 1e-300)[:, None]
        E[sub] = emission[element] + rho[sub] * mean / np.pi

    def _exact_ends(self):
        """The nodes whose links may get an exact V (`refine.Refinement`), shape (M,) bool, or
        None for all: every node in the occlusion mode "exact", the nodes with an emitting part
        (`emitting`) in "direct" (where shadows are sharpest and carry the most light, as the
        all-pairs path takes its emitters' pairs), none in "sampled"."""
        if self.occlusion == "exact":
            return None
        if self.occlusion != "direct":
            return np.zeros(len(self.hierarchy), dtype=bool)
        return self.emitting

    def _emitting_nodes(self, E_elements, direct):
        """The nodes with an emitting part, shape (M,) bool."""
        h = self.hierarchy
        emission = E_elements if direct is None else direct[0]
        leaf = h.child_count == 0
        emits = np.zeros((len(h), 1))
        emits[leaf, 0] = emission[h.element[h.patch_node[leaf]]].max(1) > 0
        return h.pull(emits)[:, 0] > 0

    def _solve(self, rho_objects, E_elements, max_bounces, run, sky=None, direct=None, start=None):
        """`solve` on the current hierarchy (`start`: element radiosities to start from)."""
        h = self.hierarchy
        rho = rho_objects[h.object]
        leaf = h.child_count == 0
        E = np.zeros((len(h), 3))
        E[leaf] = E_elements[h.element[h.patch_node[leaf]]]
        if direct is not None:
            with run.stage("lights"):
                self.sub_patch_light(E, rho, direct)
            # direct light as a mean over the leaf's free part, as its links' light (`hsolve`)
            emission = direct[0][h.element[h.patch_node[leaf]]]
            E[leaf] = emission + coverage.gather_scale(self.free[leaf])[:, None] * (E[leaf] - emission)
        sky = np.zeros(3) if sky is None else np.asarray(sky, dtype=np.float64)
        self.sky_offset = self.hides_sky[:, None] * sky[None]
        oracle = Oracle(h, rho, E, self.link_tol, self.reference, self.sky_offset, self.free)
        self.emitting = self._emitting_nodes(E_elements, direct)
        refinement = Refinement(self.estimator, self.links, run, self._exact_ends())
        passes = 0
        info = {}
        with run.stage("links"):
            if len(self.links) == 0:
                r, s = refinement.root_pairs()
                refinement.refine(oracle, ambient_estimate(h, rho, E + rho * sky[None]), r, s)
            if self.occluding is not None and self.enclosed is None:
                self.enclosed = enclosed_leaves(h, self.estimator, self.occluding, self.link_tol, self.halves)
        B = self.B
        if B is None and start is not None:
            B = np.zeros((len(h), 3))
            below = h.patch_node >= 0
            B[below] = start[h.element[h.patch_node[below]]]
        while True:
            with run.stage("solve"):
                system = HierarchicalSystem(
                    h, self.links, rho, E, self.enclosed, self.occluding, (sky, self.sky_offset), self.free
                )
                try:
                    B, info = system.solve(self.link_tol, max_bounces, run.check, start=B)
                except ValueError as error:
                    refusal = system.refusal(error)
                    if refusal is error:
                        raise
                    raise refusal from error
            passes += 1
            if passes >= MAX_PASSES:
                break
            with run.stage("links"):
                updated = refinement.updated
                r, s = refinement.recheck(oracle, B)
                if r.size == 0 and refinement.updated == updated:
                    break
                refinement.refine(oracle, B, r, s)
        self.B = B
        out = np.zeros((len(E_elements), 3))
        patch = h.patch_nodes
        out[h.element[patch]] = B[patch]  # (a patch with sub-patches: their area mean)
        stats = dict(
            links=len(self.links),
            links_per_patch=len(self.links) / max(patch.size, 1),
            nodes=len(h),
            patches_refined=int(np.count_nonzero(h.child_count[patch])),
            sub_patches=int(np.count_nonzero(leaf & (h.element < 0))),
            levels=len(h.levels),
            link_bytes=self.links.nbytes(),
            link_evaluations=refinement.evaluated,
            refine_rounds=refinement.rounds,
            passes=passes,
            links_partial=int(np.count_nonzero(self.links.partial)),
            leaves_enclosed=int(np.count_nonzero(np.isfinite(self.enclosed)))
            if self.enclosed is not None
            else 0,
            leaves_balanced=system.balanced,
            hierarchy_build_seconds=self.build_time,
        )
        keys = ("iterations", "residual", "error_bound", "contraction", "fallback")
        stats.update({k: info[k] for k in keys})
        return out, stats
