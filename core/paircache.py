"""The pair cache of a scene (`PairCache`): everything that depends only on surfaces and patch
grids (elements, occluders and their shafts, the live pairs) and the cached pair values, the
unoccluded G = A_a F(a -> b) and the visibilities V, with the stages that fill and refine them
(form factors, visibility, exact shadows, kinked pairs, row balances) and the system they make.
`Scene.solve` keeps one per patch grid, so `set_material` and `set_light` reuse it.
"""

from functools import partial

import numpy as np

from . import coverage, solvers
from .bounds import unit_vectors
from .closure import (
    ENCLOSURE_SLACK,
    MAX_SLACK,
    back_candidates,
    balance_blocked,
    row_sums,
    signed_sums_at_centres,
)
from .elements import Elements
from .mesh import PolygonMesh
from .occluded import ExactShadows
from .occlusion import Occluders
from .transport import element_nodes, outer_first, pair_form_factors, refined_pair_factors, rule_errors
from .visibility import (
    CANDIDATE_BUDGET,
    ShaftTest,
    blocked_rays,
    exact_pair_visibility,
    exact_pairs,
    free_share,
    pair_visibility,
)

CENTRE_MARGIN = 0.05  # rows whose centre's signed sum is further from 1 are not enclosed
CENTRE_TOL = 1e-3  # tolerance of those centre sums (their error is far below the margin)
PROXY_RESOLUTION = 32  # cells per parameter of the triangle proxy of a NURBS occluder
CONTACT_BOX = 1e-5  # a mesh vertex this close (of the scene's size) to another object may touch it


def ordered_pairs(i, j):
    """Ordered pairs represented by unordered pairs (i <= j)."""
    return int(2 * i.size - np.count_nonzero(i == j))


def _split(surface, grid):
    """The object's front patches: a mesh's pieces each split by its grid, in piece order."""
    if isinstance(surface, PolygonMesh):
        return [patch for piece, (nu, nv) in zip(surface.pieces(), grid) for patch in piece.split(nu, nv)]
    return surface.split(*grid)


class PairCache:
    """Everything that depends only on surfaces and patch grids: elements, occluders, live pairs,
    and the cached pair values G = A_a F(a -> b) (unoccluded) and visibilities V."""

    def __init__(self, objects, patches, key, rules, previous=None, pairs=True):
        self.key = key
        self.has_pairs = bool(pairs)
        self.link_visibility = None  # visibility of element pairs from hierarchical links
        self.rules = set(rules)
        surfaces, owner = [], []
        self.ranges = []  # per object: (first element, patches per side, two-sided)
        for k, (obj, grid) in enumerate(zip(objects, patches)):
            front = _split(obj.surface, grid)
            self.ranges.append((len(surfaces), len(front), obj.two_sided))
            pieces = front + ([p.flipped() for p in front] if obj.two_sided else [])
            surfaces += pieces
            owner += [k] * len(pieces)
        self.surfaces = [o.surface for o in objects]
        self.objects_grid = patches
        self.elements = Elements(surfaces, owner)
        # the other side of each element of a two-sided object (-1: one-sided), and whether an
        # element is the front half (`closure`: each sheet counts once, oriented by its front)
        self.twin = np.full(len(surfaces), -1, dtype=np.int64)
        self.front_half = np.ones(len(surfaces), dtype=bool)
        for start, count, two_sided in self.ranges:
            if two_sided:
                self.twin[start : start + count] = np.arange(start + count, start + 2 * count)
                self.twin[start + count : start + 2 * count] = np.arange(start, start + count)
                self.front_half[start + count : start + 2 * count] = False
        occluding = [k for k, o in enumerate(objects) if o.occluder]
        self.occluder_object = np.array(occluding, dtype=np.int64)
        self.occluding = np.isin(self.elements.owner, self.occluder_object)  # per element
        # NURBS proxies a little finer than the visibility sampling needs
        self.occluders = (
            Occluders([objects[k].surface for k in occluding], proxy_resolution=PROXY_RESOLUTION)
            if occluding
            else None
        )
        self.scale = self.elements.scale
        # what other objects cover of each flat element (a box's footprint on a floor: `coverage`)
        self.coverage = coverage.Coverage(self.elements, self.occluders, self.occluder_object, self.scale)
        self.shafts = (
            ShaftTest(self.elements, self.occluders, self.occluder_object, self.coverage)
            if occluding
            else None
        )
        self.exact_shadows = (
            ExactShadows(self.elements.surfaces, self.occluders.surfaces) if occluding else None
        )
        if pairs:
            self._live_pairs(rules)
        else:  # (the hierarchical path: no pair list)
            self.pair_i = self.pair_j = np.zeros(0, dtype=np.int64)
            self.live_ordered = 0
        self._pair_keys = None
        self._first_shares = None  # kept `_first_share` values, per pair and end
        self._matrix_key = None
        self._gather_scale = coverage.gather_scale(self.coverage.free)
        self.G = np.full(self.pair_i.size, np.nan)
        self.V_sampled = np.full(self.pair_i.size, np.nan)  # ray-sampled visibilities
        self.free = np.zeros(self.pair_i.size, dtype=bool)  # pairs with an empty shaft
        self.exact_tol = np.full(self.pair_i.size, np.inf)  # error allowed in an exact V (inf: sampled)
        self.exact_capable = np.zeros(self.pair_i.size, dtype=bool)  # (`visibility.exact_pairs`)
        self.rule_error = np.zeros(self.pair_i.size)  # of G's first rule (`transport.rule_errors`)
        self.G_kinked = np.full(self.pair_i.size, np.nan)  # pairs in doubt integrated again
        self.kink_tol = np.full(self.pair_i.size, np.nan)  # ... to this error (`refine_kinks`)
        self.kink_active = np.zeros(self.pair_i.size, dtype=bool)  # G_kinked in this solve
        self.V = self.V_sampled.copy()  # the same, balanced in enclosures (`closure`)
        self.exact_followers = None  # emitters whose pairs the "direct" mode makes exact (`compute`)
        self.shadow_mode = "sampled"  # the occlusion mode V_sampled was computed for (`Scene.solve`)
        self.back_total = np.full(len(self.elements), np.nan)  # sum_k F(a -> back of k)
        # signed sums at element centres (`closure`), two-sided sheets as they are and turned over
        self.centre_sum = np.full((2, len(self.elements)), np.nan)
        self._backs = None
        self._balance_key = None
        self.reused = 0
        if pairs and previous is not None and previous.rules == self.rules and previous.has_pairs:
            self._reuse(previous)

    def _reuse(self, previous):
        """Copy pair values of objects whose geometry did not change from the previous geometry.

        G = A_a F_ab depends on the two elements only; a visibility stays valid unless an
        occluder that changed (as it was, or as it is now) lies in the pair's shaft.
        """
        same = [k < len(previous.key) and previous.key[k] == self.key[k] for k in range(len(self.key))]
        # element map new -> old for unchanged objects (same split, so the same order)
        to_old = np.full(len(self.elements), -1, dtype=np.int64)
        for k, unchanged in enumerate(same):
            if unchanged:
                start, count, two = self.ranges[k]
                old_start = previous.ranges[k][0]
                n = count * (2 if two else 1)
                to_old[start : start + n] = np.arange(old_start, old_start + n)
        a, b = to_old[self.pair_i], to_old[self.pair_j]
        both = np.flatnonzero((a >= 0) & (b >= 0))
        if both.size == 0:
            return
        N_old = len(previous.elements)
        old_keys_sorted = previous.pair_i * N_old + previous.pair_j
        key = np.minimum(a[both], b[both]) * N_old + np.maximum(a[both], b[both])
        at = np.minimum(np.searchsorted(old_keys_sorted, key), old_keys_sorted.size - 1)
        found = old_keys_sorted[at] == key
        both, at = both[found], at[found]
        self.G[both] = previous.G[at]
        self.V_sampled[both] = previous.V_sampled[at]
        self.free[both] = previous.free[at]
        self.exact_tol[both] = previous.exact_tol[at]
        self.exact_capable[both] = previous.exact_capable[at]
        self.rule_error[both] = previous.rule_error[at]
        self.G_kinked[both] = previous.G_kinked[at]
        self.kink_tol[both] = previous.kink_tol[at]
        self.shadow_mode = previous.shadow_mode
        # visibilities whose shafts hold a changed occluder, old or new, are recomputed
        changed = [k for k, unchanged in enumerate(same) if not unchanged]
        for shafts, geometry in ((self.shafts, self), (previous.shafts, previous)):
            if shafts is None:
                continue
            columns = np.flatnonzero(np.isin(shafts.object, changed))
            if columns.size == 0:
                continue
            ii = self.pair_i[both] if geometry is self else previous.pair_i[at]
            jj = self.pair_j[both] if geometry is self else previous.pair_j[at]
            step = max(256, CANDIDATE_BUDGET // max(shafts.M, 1))
            for start in range(0, both.size, step):
                part = slice(start, start + step)
                hit = shafts.candidates(ii[part], jj[part])[:, columns].any(1)
                self.V_sampled[both[part][hit]] = np.nan
                self.free[both[part][hit]] = False
                self.exact_tol[both[part][hit]] = np.inf
        self.reused = int(both.size)

    def _live_pairs(self, rules):
        """Unordered pairs (i <= j) that may exchange light, chunked over rows."""
        N = len(self.elements)
        pi, pj = [], []
        step = max(1, 2_000_000 // N)
        for start in range(0, N, step):
            i = np.arange(start, min(start + step, N))
            ii, jj = np.meshgrid(i, np.arange(N), indexing="ij")
            keep = ii <= jj
            ii, jj = ii[keep], jj[keep]
            alive = self.elements.live(ii, jj) if "facing" in rules else np.ones(ii.size, dtype=bool)
            pi.append(ii[alive])
            pj.append(jj[alive])
        self.pair_i = np.concatenate(pi)
        self.pair_j = np.concatenate(pj)
        self.live_ordered = ordered_pairs(self.pair_i, self.pair_j)

    def matrix(self, need, rows, cols, occlusion):
        """Sparse (and, for small scenes, dense) F of the needed ordered pairs, cached for relights.

        F_ab = G / A_a (times visibility) for rows a and columns b that the solve needs.

        Returns
        -------
        r, c : ndarray of int, shape (P,)
        v : ndarray, shape (P,)
        dense : ndarray, shape (N, N), or None above `solvers.DENSE_MATRIX_LIMIT` elements
        """
        key = (need.tobytes(), rows.tobytes(), cols.tobytes(), occlusion)
        if self._matrix_key != key:
            i, j = self.pair_i[need], self.pair_j[need]
            G = self.gains()[need] * (self.V[need] if occlusion else 1.0)
            area = self.elements.area
            forward = rows[i] & cols[j]
            backward = rows[j] & cols[i] & (i != j)
            r = np.concatenate([i[forward], j[backward]])
            c = np.concatenate([j[forward], i[backward]])
            v = np.concatenate([G[forward] / area[i[forward]], G[backward] / area[j[backward]]])
            N = len(self.elements)
            # rows as means over each element's free part (`coverage`), never summing above 1
            # through that alone (a free fraction a little low, factors a little high); elements
            # that do not occlude (a lamp seen through, as Cycles' lights are) are no part of that sum
            total = np.bincount(r, v * self.occluding[c], N)[r]
            v = v * np.minimum(
                self.gather_scale(occlusion)[r], np.maximum(1.0, 1.0 / np.maximum(total, 1e-300))
            )
            dense = None
            if N <= solvers.DENSE_MATRIX_LIMIT:
                dense = np.zeros((N, N))
                dense[r, c] = v  # each ordered pair appears once
            self._matrix_key, self._matrix = key, (r, c, v, dense)
        return self._matrix

    def gather_scale(self, occlusion=True):
        """Per element, the factor that turns light gathered over the whole element into the
        mean over its part that no occluder face lying on it covers (`coverage`), shape (N,);
        1 without occlusion (the covered part then receives light like the rest)."""
        if not occlusion:
            return np.ones(len(self.elements))
        return self._gather_scale

    def covered(self, need, occlusion):
        """sum_j F_ij V_ij over the occluders' elements j, for every element i, shape (N,): the
        mean over i's free part (`coverage`).

        need : ndarray of bool, shape (P,)
            The pairs the solve computed (rows of elements without them get 0).
        """
        e, N = self.elements, len(self.elements)
        i, j = self.pair_i[need], self.pair_j[need]
        G = self.gains()[need] * (self.V[need] if occlusion else 1.0)
        G = np.nan_to_num(G, nan=0.0)
        occluding = self.occluding
        off = i != j
        total = np.bincount(i, np.where(occluding[j], G, 0.0), N)
        total += np.bincount(j[off], np.where(occluding[i[off]], G[off], 0.0), N)
        return total / e.area * self.gather_scale(occlusion)  # (over the free part: `coverage`)

    def known_visibility(self, a, b):
        """Cached visibility of element pairs (either order), NaN where not computed, shape (K,)."""
        if self.pair_i.size == 0:  # (the hierarchical path: the links' visibility, if solved)
            lookup = self.link_visibility
            return lookup(a, b) if lookup is not None else np.full(np.shape(a), np.nan)
        a, b = np.asarray(a), np.asarray(b)
        at, found = self._pair_index(a, b)
        # a pair's V holds the share of its factor that the free parts of partly covered ends
        # exchange (`visibility.free_share`); a gathered point on a's free part takes a's share off
        share = self._first_share(a, b, at, found) if self.shafts is not None else 1.0
        return np.where(found, np.minimum(self.V[at] / np.maximum(share, 1e-12), 1.0), np.nan)

    def _first_share(self, a, b, at, found):
        """`visibility.free_share(a, b, first_only=True)` of pairs (a, b) at `at` in the pair list
        where `found` (1 elsewhere), shape (K,). It depends on the geometry alone, and every point
        a gather reuses a pair's visibility for asks it again (a floor patch's vertices, each
        toward every patch it sees: 37 % of a mesh room's add-on run), so each pair's two values
        (a its first or its second element) are kept once computed."""
        P = self.pair_i.size
        if self._first_shares is None:
            self._first_shares = np.full(2 * P, np.nan)
        kept = self._first_shares
        out = np.ones(a.size)
        f = np.flatnonzero(found)
        slot = np.where(a[f] > b[f], P, 0) + at[f]  # (pairs are stored first element <= second)
        values = kept[slot]
        todo = np.flatnonzero(np.isnan(values))
        if todo.size:
            unique, first, inverse = np.unique(slot[todo], return_index=True, return_inverse=True)
            pick = f[todo[first]]
            kept[unique] = free_share(self.elements, self.shafts, a[pick], b[pick], first_only=True)
            values[todo] = kept[unique][inverse]
        out[f] = values
        return out

    def known_sealed(self, a, b):
        """Whether a closed occluding shell parts element pairs (either order): one is the inside
        of a whole sphere or ellipsoid and the other lies outside it (`Elements.sealed_between`),
        so every segment between them is blocked, shape (K,)."""
        return self.elements.sealed_between(a, b, self.occluding)

    def touching(self, handle, points):
        """Whether points (k, 3) of object `handle` may touch another occluding object, to
        CONTACT_BOX of the scene's size, shape (k,) bool: in its box, and for a mesh around a
        convex room (`PolygonMesh.front_hull`) near one of its planes, for a closed convex solid
        (`PolygonMesh.solid_hull`) in it or on it (a room's box holds everything in the room)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        out = np.zeros(len(points), dtype=bool)
        occ = self.occluders
        if occ is None:
            return out
        pad = CONTACT_BOX * self.scale
        for m in np.flatnonzero(self.occluder_object != handle):
            inside = np.flatnonzero(
                np.all((points >= occ.box_min[m] - pad) & (points <= occ.box_max[m] + pad), axis=1)
            )
            if occ.hull[m] is not None:
                normal, offset = occ.hull[m]
                inside = inside[np.abs(points[inside] @ normal.T - offset).min(1) <= pad]
            elif occ.solid_hull[m] is not None:
                normal, offset, slack = occ.solid_hull[m]
                inside = inside[(points[inside] @ normal.T - offset).max(1) <= pad + slack]
            out[inside] = True
        return out

    def known_free(self, a, b):
        """Whether element pairs (either order) had no candidate occluder in their shaft when
        their visibility was sampled, shape (K,) (False where unknown)."""
        if self.pair_i.size == 0:
            return np.zeros(np.shape(a), dtype=bool)
        at, found = self._pair_index(a, b)
        return found & self.free[at]

    def _pair_index(self, a, b):
        """Position of pairs (a, b) in the pair list and whether they are in it, shapes (K,)."""
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        N = len(self.elements)
        if self._pair_keys is None:
            self._pair_keys = self.pair_i * N + self.pair_j  # sorted: rows then columns
        key = lo * N + hi
        at = np.minimum(np.searchsorted(self._pair_keys, key), self._pair_keys.size - 1)
        return at, self._pair_keys[at] == key

    def gains(self):
        """A_a F_ab of every pair as this solve uses it: G, or G_kinked where `refine_kinks`
        took it, shape (P,)."""
        return np.where(self.kink_active, self.G_kinked, self.G)

    def nbytes(self):
        arrays = (self.pair_i, self.pair_j, self.G, self.G_kinked, self.V, self.V_sampled, self.free)
        return sum(a.nbytes for a in arrays)

    def compute(self, pairs, tol, occlusion, run, rules, rows, emitters=None):
        """Fill G (and V when occlusion is on) for the listed pairs where not cached, then balance
        the visibilities of enclosed elements among `rows` (bool, shape (N,)): the rows solved.

        occlusion : False, "direct", "exact" or "sampled" (see `Scene.solve`); visibilities of
        another mode are dropped.
        emitters : ndarray of bool, shape (N,), optional
            In "direct" mode, the elements whose pairs `refine_shadows` makes exact where their
            light needs it (in "exact" mode: every pair)."""
        self.exact_followers = emitters
        # a first solve on the fixed rules, as a fresh scene's (`refine_kinks` picks from it)
        if self.kink_active.any():
            self.kink_active[:] = False
            self._matrix_key = None
        if occlusion and occlusion != self.shadow_mode:
            self.V_sampled[:] = np.nan
            self.free[:] = False
            self.exact_tol[:] = np.inf
            self.V = self.V_sampled.copy()
            self._balance_key = None
            self.shadow_mode = occlusion
        self._fill(pairs, tol, occlusion, run, rules)
        if occlusion and self.shafts is not None:
            self._balance(tol, run, rules, rows)

    def refine_shadows(self, B, rho, tol, run, rules, rows, emitters=None):
        """Exact visibility (`visibility.exact_pair_visibility`) for the pairs whose sampled one
        could move a row's radiosity by more than its share of tol, given the solved B
        (`_picked_by_light`), among the pairs with an element of `emitters` (bool, shape (N,);
        None: all), then the balance of the rows solved (`rows`, as `compute`); returns how many
        pairs changed. Pairs already exact to the tolerance they need are kept (a relight adds
        only what its new light needs)."""
        if self.exact_shadows is None or self.shafts is None:
            return 0
        free = self.free
        if emitters is not None:
            free = free | ~(emitters[self.pair_i] | emitters[self.pair_j])
        skip = free | ~np.isfinite(self.V_sampled)
        pick, allowed = _picked_by_light(
            self.G, skip, self.pair_i, self.pair_j, self.elements.area, rho, B, tol, SAMPLED_VISIBILITY_ERROR
        )
        # (allowances rounded down to powers of 2, as `refine_kinks` does: a relight whose light
        # asks a pair a little tighter keeps its value, where a continuous allowance had it
        # integrated again: 1,646 of the 961-patch Cornell box's pairs after the lamp's colour
        # changed, 8.7 s of a 9.1 s relight, now 0.2 s; the first solve asks 1.44x tighter on
        # average for it, its exact shadows 1.2-1.5x the time)
        allowed = _power_of_two_below(allowed)
        need = allowed < self.exact_tol[pick]
        pick, allowed = pick[need], allowed[need]
        i, j = self.pair_i[pick], self.pair_j[pick]

        def work(block):
            shafts = self._shafts_for(rules)
            V, lines = exact_pair_visibility(
                self.elements, self.exact_shadows, shafts, i[block], j[block], tol, absolute=allowed[block]
            )
            run.count(shadow_lines=lines, pairs_exact=int(np.count_nonzero(np.isfinite(V))))
            return V

        with run.stage("exact shadows"):
            # (blocks of many pairs: the closed form's cost per call is large next to per pair)
            values = run.blocks("exact shadows", work, np.arange(pick.size), min_block=512)
        if pick.size == 0:
            return 0
        V = np.concatenate(values)
        found = np.isfinite(V)
        self.V_sampled[pick[found]] = V[found]
        self.exact_tol[pick[found]] = allowed[found]
        self._balance_key = None
        self._balance(tol, run, rules, rows)
        return int(found.sum())

    def _oriented(self, pairs):
        """(a, b) of pairs as `pair_form_factors` takes them (`transport.outer_first`)."""
        i, j = self.pair_i[pairs], self.pair_j[pairs]
        outer_i = outer_first(self.elements, i, j)
        return np.where(outer_i, i, j), np.where(outer_i, j, i)

    def refine_kinks(self, B, rho, tol, run, lamps):
        """Form factors of pairs in doubt (`transport.rule_errors`: a horizon may cross the
        pair, where a fixed outer rule may be off by KINK_RULE_ERROR; a near pair, whose first
        rule may stop early, NEAR_RULE_ERROR; counted as "pairs_kinked" and timed as "kinked
        form factors") whose error could move a
        row's radiosity by more than its share of tol, given the solved B (`_picked_by_light`),
        integrated again to the error each may have (`transport.refined_pair_factors`) into
        G_kinked, which the next solve takes for them (`gains`; `compute` goes back to G for the
        first solve). Returns how many pairs it takes (0: nothing changed)."""
        G, e = self.G, self.elements
        V = np.where(np.isfinite(self.V), self.V, 1.0)
        doubt = self.rule_error > 0
        kinked = np.flatnonzero(doubt & np.isfinite(G))
        # a rule whose points saw little of a lamp (an emitting element: direct light, where a
        # sliver of it shows most) may have missed most of it: the error of such a pair is taken
        # relative to the larger of G and UPPER_SHARE of the most any point of a can see of b's
        # ball (sin^2 of its half-angle)
        a, b = self._oriented(kinked)
        gap = np.linalg.norm(e.center[a] - e.center[b], axis=1) - e.radius[a]
        far = gap > e.radius[b]
        upper = np.ones(kinked.size)
        upper[far] = (e.radius[b[far]] / gap[far]) ** 2
        upper[~(lamps[a] | lamps[b])] = 0.0
        weight = np.zeros(G.size)
        weight[kinked] = np.maximum(G[kinked], UPPER_SHARE * e.area[a] * upper) * V[kinked]
        pick, allowed = _picked_by_light(
            weight, ~doubt, self.pair_i, self.pair_j, e.area, rho, B, tol, self.rule_error
        )
        # (allowances rounded down to powers of 2; a kept value integrated at least as tightly as
        # asked serves, its error being within the allowance, so a relight agrees with a fresh
        # solve of the relit scene within the allowances, not to rounding. A ball's colour
        # changed in 7 steps (`benchmarks.relight`) took 7-15 pairs again at every step, 25-50 ms
        # of a 120 ms relight; now 0-2 at four of the six steps after the first, 9-15 at two:
        # pairs first asked tighter than the first solve asked, and pairs newly picked; with
        # KINK_HEADROOM 0.5 the seven steps took 21, 0, 0, 1, 0, 6, 5 pairs instead of 99, 0, 0,
        # 2, 1, 15, 9, for a first solve's kinked stage within its noise)
        allowed = _power_of_two_below(allowed)
        stale = ~(self.kink_tol[pick] <= allowed)  # (inf: not integrated again yet)
        redo, redo_allowed = pick[stale], allowed[stale] * KINK_HEADROOM
        a, b = self._oriented(redo)
        # (relative error in G -> absolute in F)
        absolute = redo_allowed * weight[redo] / np.maximum(V[redo], 1e-300) / e.area[a]

        def work(block):
            F, count = refined_pair_factors(e, a[block], b[block], tol, absolute[block])
            run.count(evaluations=count, pairs_kinked=int(block.size))
            return F

        if redo.size:
            with run.stage("kinked form factors"):
                values = run.blocks("kinked form factors", work, np.arange(redo.size))
            self.G_kinked[redo] = np.concatenate(values) * e.area[a]
            self.kink_tol[redo] = redo_allowed
        active = np.zeros(self.kink_active.size, dtype=bool)
        active[pick] = True
        if np.array_equal(active, self.kink_active):
            return 0
        self.kink_active = active
        self._matrix_key = None
        return int(pick.size)

    def _fill(self, pairs, tol, occlusion, run, rules):
        e = self.elements
        todo = pairs[np.isnan(self.G[pairs])]
        run.count(pairs_cached=int(pairs.size - todo.size))
        if todo.size:
            a, b = self._oriented(todo)

            def work(block):
                F, count = pair_form_factors(e, a[block], b[block], tol)
                run.count(evaluations=count)
                return F, rule_errors(e, a[block], b[block], tol)

            with run.stage("form factors"):
                values = run.blocks("form factors", work, np.arange(todo.size))
                self.G[todo] = np.concatenate([F for F, _ in values]) * e.area[a]
                self.rule_error[todo] = np.concatenate([k for _, k in values])
                self.kink_tol[todo] = np.inf
        if not occlusion:
            return
        todo = pairs[np.isnan(self.V_sampled[pairs])]
        if self.shafts is None:
            self.V_sampled[todo] = self.V[todo] = 1.0
            self.free[todo] = True
            return
        i, j = self.pair_i[todo], self.pair_j[todo]
        # a closed occluding shell between a pair (a ball's inside and anything outside it)
        # blocks every segment: V = 0, exact (no rays, no exact pass, no kinked refinement)
        sealed = self.known_sealed(i, j)
        if sealed.any():
            self.V_sampled[todo[sealed]] = 0.0
            self.free[todo[sealed]] = False
            self.exact_tol[todo[sealed]] = 0.0
            todo, i, j = todo[~sealed], i[~sealed], j[~sealed]

        # pairs whose form factor is too small for a visibility error to show are not refined
        weight = np.nan_to_num(self.G[todo] / np.minimum(e.area[i], e.area[j]), nan=1.0)

        # with exact shadows to follow (`refine_shadows`), rays only find the partly blocked pairs
        # and a first radiosity: no finer than at tol 1e-3, where SAMPLED_VISIBILITY_ERROR holds
        # (which kinds the exact pass covers is asked only of the pairs its mode would take)
        ask = np.flatnonzero(self._mode_follows(todo))
        for sel in np.array_split(ask, max(1, ask.size // 65536)) if ask.size else ():
            capable, _, _, _ = exact_pairs(self.exact_shadows, self._shafts_for(rules), i[sel], j[sel])
            self.exact_capable[todo[sel]] = capable
        follows = self._exact_follows(todo)

        def visibility(block, ray_tol):
            V, counts, free = pair_visibility(
                e, self.occluders, self._shafts_for(rules), i[block], j[block], ray_tol, weight[block]
            )
            run.count(rays=counts["rays"], ray_tests=counts["tests"], pairs_shadow_tested=counts["shadowed"])
            return V, free

        with run.stage("visibility"):
            for group, ray_tol in ((follows, max(tol, 1e-3)), (~follows, tol)):
                sel = np.flatnonzero(group)
                values = run.blocks("visibility", partial(visibility, ray_tol=ray_tol), sel)
                if sel.size:
                    self.V_sampled[todo[sel]] = np.concatenate([v for v, _ in values])
                    self.free[todo[sel]] = np.concatenate([f for _, f in values])
        run.count(pairs_shadow_tested=0, pairs_visibility=int(todo.size))
        run.stats["pairs_culled_shaft"] = run.stats["pairs_visibility"] - run.stats["pairs_shadow_tested"]

    def _mode_follows(self, pairs):
        """Which pairs (indices, shape (P,)) the occlusion mode hands to the exact pass
        (`refine_shadows`): every pair in "exact" mode, those with an emitter in "direct" mode,
        none without exact shadows; shape (P,)."""
        none = np.zeros(np.size(pairs), dtype=bool)
        if self.exact_shadows is None or self.shadow_mode not in ("exact", "direct"):
            return none
        if self.shadow_mode == "exact":
            return ~none
        emitting = self.exact_followers
        return none if emitting is None else emitting[self.pair_i[pairs]] | emitting[self.pair_j[pairs]]

    def _exact_follows(self, pairs):
        """Which pairs (indices, shape (P,)) get exact visibility where their light needs it: those
        of `_mode_follows` whose kinds `exact_pair_visibility` covers (`exact_capable`)."""
        return self._mode_follows(pairs) & self.exact_capable[pairs]

    def _balance(self, tol, run, rules, rows):
        """Visibilities with exact blocked totals in the rows of enclosed elements (`closure`).

        Pairs whose visibility the exact pass controls (`_exact_follows`: made exact wherever a
        sampled V's error could show in B) are neither rescaled nor a reason to balance a row."""
        e, N = self.elements, len(self.elements)
        i, j = self.pair_i, self.pair_j
        done = np.isfinite(self.G) & np.isfinite(self.V_sampled)
        follows = self._exact_follows(np.arange(i.size)) & done
        # solved rows with something sampled blocked need all their pairs (also those culled by
        # material)
        blocked = row_sums(np.where(done & ~follows, self.G * (1.0 - self.V_sampled), 0.0), i, j, N)
        grow = rows & (blocked > 0)
        extra = np.flatnonzero(~done & (grow[i] | grow[j]))
        if extra.size:
            self._fill(extra, tol, True, run, rules)
            done = np.isfinite(self.G) & np.isfinite(self.V_sampled)
        key = (rows.tobytes(), done.tobytes(), float(tol))
        if key == self._balance_key:  # nothing new since the last balance (a relight)
            return
        self._balance_key = key
        self.V = np.where(done, self.V_sampled, np.nan)
        self._matrix_key = None
        # only occluders count (the others are transparent): their pairs and rows
        occluding = self.occluding
        counted = done & occluding[i] & occluding[j]
        G = np.where(counted, self.G, 0.0)
        V = np.where(done, self.V_sampled, 1.0)
        # candidates: rows with every pair known, something blocked, and an unoccluded sum at
        # least the element's free fraction (1 unless another object covers part of it: `coverage`)
        complete = row_sums((~done).astype(float), i, j, N) == 0
        S = row_sums(G, i, j, N) / e.area
        blocked = row_sums(G * (1.0 - V), i, j, N)
        near_one = S >= self.coverage.free - np.minimum(ENCLOSURE_SLACK * tol * S, MAX_SLACK)
        maybe = np.flatnonzero(rows & occluding & complete & (blocked > 0) & near_one)
        run.stats["rows_enclosed"] = run.stats["rows_balanced"] = 0
        if maybe.size == 0:
            return
        # enclosed: the signed row sum over sheets (fronts minus backs) is 1; the elements'
        # centres rule most out. A sheet is a one-sided element or the front half of a two-sided
        # one, whose back is its twin (an element already); one-sided sheets need flipped copies.
        # A two-sided sheet's orientation is a choice (Cycles renders both sides alike), so the
        # test runs both ways: two-sided sheets by their front halves, and turned over (by their
        # back halves), and a room of two-sided walls whose normals face out is enclosed too
        one_sided = occluding & (self.twin < 0)
        ways = [occluding & self.front_half]
        if np.any(occluding & (self.twin >= 0)):
            ways.append(occluding & (~self.front_half | (self.twin < 0)))
        if self._backs is None and one_sided.any():
            self._backs = Elements([s.flipped() for s in e.surfaces], e.owner)
        # (without one-sided sheets the exact test below costs nothing: no pre-filter)
        if one_sided.any():
            near = np.zeros(maybe.size, dtype=bool)
            for way, sheet in enumerate(ways):
                cache = self.centre_sum[way]
                todo = maybe[np.isnan(cache[maybe])]
                if todo.size:
                    with run.stage("form factors"):
                        # a pre-filter against CENTRE_MARGIN: CENTRE_TOL is ample (the exact test follows)
                        def centre_work(block, sheet=sheet):
                            return signed_sums_at_centres(e, self._backs, block, sheet, self.twin, CENTRE_TOL)

                        sums = run.blocks("form factors", centre_work, todo, min_block=16)
                        cache[todo] = np.concatenate(sums) if sums else []
                # (a partly covered element's centre may lie under the covering object: 0 there)
                partly = self.coverage.free[maybe] < 1.0
                near |= (np.abs(cache[maybe] - 1.0) <= CENTRE_MARGIN) | (
                    partly & (np.abs(cache[maybe]) <= CENTRE_MARGIN)
                )
            maybe = maybe[near]
        # what occlusion removes: the backs of one-sided sheets, and twice the other halves of the
        # two-sided sheets seen (S counts them once; the identity takes them off once more)
        backs = self._back_totals(maybe, one_sided, tol, run) if one_sided.any() else np.zeros(maybe.size)
        target = np.full(N, np.nan)
        enclosed = np.zeros(maybe.size, dtype=bool)
        # an element partly covered by another object (`coverage`) sees the enclosure from its
        # free part only: its signed row sum is its free fraction f (a segment from under a box
        # crosses the box's back, then a wall), and its visibilities add up to f, not 1
        free = self.coverage.free[maybe]
        for sheet in ways:
            other = occluding & (self.twin >= 0) & ~sheet
            seen = np.bincount(i, G * other[j], N) + np.bincount(j, np.where(i != j, G, 0.0) * other[i], N)
            T = backs + 2.0 * seen[maybe] / e.area[maybe]
            slack = np.minimum(ENCLOSURE_SLACK * tol * (S[maybe] + T), MAX_SLACK) + 1e-12
            way = (np.abs(S[maybe] - T - free) <= slack) & ~enclosed
            target[maybe[way]] = T[way] * e.area[maybe[way]]
            enclosed |= way
        with run.stage("visibility"):
            balanced, count = balance_blocked(G, V, i, j, target, fixed=follows)
        self.V = np.where(done, np.where(counted, balanced, V), np.nan)
        run.stats["rows_enclosed"] = int(enclosed.sum())
        run.stats["rows_balanced"] = count

    def _back_totals(self, rows, occluding, tol, run):
        """sum_k F(a -> back side of k) over k where `occluding` (bool, shape (N,): the same
        mask on every call of a geometry), for elements a = rows (cached), shape (rows.size,)."""
        e, N = self.elements, len(self.elements)
        cache = self.back_total
        todo = rows[np.isnan(cache[rows])]
        if todo.size:
            step = max(1, 2_000_000 // N)

            def work(block):
                total = np.zeros(block.size)
                for start in range(0, block.size, step):
                    part = block[start : start + step]
                    local = np.repeat(np.arange(part.size), N)
                    a, k = part[local], np.tile(np.arange(N), part.size)
                    keep = np.flatnonzero(occluding[k] & back_candidates(e, a, k))
                    F, count = pair_form_factors(e, a[keep], k[keep], tol, targets=self._backs)
                    run.count(evaluations=count, back_pairs=keep.size)
                    total[start : start + part.size] = np.bincount(local[keep], F, part.size)
                return total

            with run.stage("form factors"):
                cache[todo] = np.concatenate(run.blocks("back factors", work, todo, min_block=8))
        return cache[rows]

    def _shafts_for(self, rules):
        return self.shafts if "shaft" in rules else _AllCandidates(self.shafts)

    def light_factors(self, light, occlusion, run, tol, order=3):
        """Patch-average irradiance per unit light power, shape (N,): order x order Gauss points
        on splits x splits cells of each element, the cells halved until two successive rules
        agree within tol of the finer one (a lamp close to a patch: a 3 x 3 rule over a 0.5 m
        patch 0.15 m under a point lamp is 16 % off) or LIGHT_MAX_SPLITS is reached."""
        e = self.elements

        def rule(block, splits):
            # (the finer rules, asked for the elements that need them, are not kept)
            nodes = element_nodes(e, block, 1, order) if splits == 1 else e.nodes_of(block, splits, order)
            x, normal, w = nodes
            n, length = unit_vectors(normal)
            K, q = block.size, x.shape[1]
            X, Nn = x.reshape(-1, 3), n.reshape(-1, 3)
            value = light.unshadowed(X, Nn)
            if occlusion and self.shafts is not None:
                value = value * self.light_visibility(light, X, Nn, np.repeat(block, q), value > 0, run)
            weight = (w * length).reshape(K, q)
            total = weight.sum(1)
            return np.divide((weight * value.reshape(K, q)).sum(1), total, out=np.zeros(K), where=total > 0)

        def work(block):
            value = rule(block, 1)
            todo, splits = np.arange(block.size), 1
            while todo.size and splits < LIGHT_MAX_SPLITS:
                splits *= 2
                # (in chunks of at most LIGHT_POINTS points: their shadow rays' memory)
                step = max(1, LIGHT_POINTS // (splits * order) ** 2)
                finer = np.concatenate(
                    [rule(block[todo[k : k + step]], splits) for k in range(0, todo.size, step)]
                )
                done = np.abs(finer - value[todo]) <= tol * np.abs(finer)
                value[todo] = finer
                todo = todo[~done]
            return value

        with run.stage("lights"):
            return np.concatenate(run.blocks("lights", work, np.arange(len(e))))

    def light_visibility(self, light, x, n, element, lit, run, owner=None, outward=None):
        """Unshadowed share of a light's irradiance at points x (normals n, (K, 3)), shape (K,):
        its shadow rays' weighted free fraction (`lights`) where `lit`, else 1.

        element : ndarray of int, shape (K,), or None
            Element holding each point; or None with `owner` and `outward` given per point.
        """
        V = np.ones(len(x))
        sel = np.flatnonzero(lit)
        if sel.size == 0:
            return V
        targets, weights, centre, radius, probes = light.targets(x[sel], n[sel], self.scale)
        if owner is None:
            owner = self.elements.owner[element[sel]]
            outward = self.elements.outward[element[sel]]
        else:
            owner, outward = owner[sel], outward[sel]
        cand = self.shafts.segment_candidates(x[sel], centre, radius, owner, outward)

        def blocked(rows, ends):
            """Whether the rays from points `rows` (of sel) to `ends` (R, S, 3) are blocked, (R, S)."""
            s = ends.shape[1]
            origins = np.repeat(x[sel[rows]], s, axis=0)
            hit, tests = blocked_rays(self.occluders, origins, ends.reshape(-1, 3), cand, np.repeat(rows, s))
            run.count(rays=origins.shape[0], ray_tests=tests)
            return hit.reshape(-1, s)

        # an extended light: probe rays first, all rays where the probes disagree (a penumbra)
        rows = np.arange(sel.size)
        if probes is not None:
            hit = blocked(rows, probes)
            V[sel] = np.where(hit.all(1), 0.0, 1.0)
            rows = np.flatnonzero(hit.any(1) & ~hit.all(1))
        if rows.size:
            V[sel[rows]] = 1.0 - (weights[rows] * blocked(rows, targets[rows])).sum(1)
        return V


LIGHT_MAX_SPLITS = 8  # cells per side of a patch's finest rule for the lights' irradiance
LIGHT_POINTS = 32768  # points of the finer rules evaluated at once
UPPER_SHARE = 0.01  # a lamp pair's rule may miss this share of its upper bound (`refine_kinks`)
# a pair integrated again is integrated this times tighter than its allowance asks, so a relight
# whose light asks at most that much tighter reuses it (`refine_kinks`)
KINK_HEADROOM = 0.5
SAMPLED_VISIBILITY_ERROR = 0.05  # absolute error of a sampled visibility assumed by `_picked_by_light`
ROW_FLOOR = 1e-5  # rows darker than this times the mean radiosity are held to it (`_picked_by_light`)


def _power_of_two_below(allowed):
    """Each allowance (P,) rounded down to a power of 2 (`refine_shadows`, `refine_kinks`: a relight
    that asks a pair a little tighter then keeps the pair's value)."""
    return 2.0 ** np.floor(np.log2(allowed))


def _picked_by_light(G, skip, pair_i, pair_j, area, rho, B, tol, bound):
    """Which pairs need a value better than a first one for every row's radiosity to meet tol,
    and the error allowed in each: (pick, allowed), shapes (K,) int and (K,).

    The first value of a pair may be off by `bound` times its G: a sampled visibility by
    SAMPLED_VISIBILITY_ERROR (absolute in V, measured: up to 3.5e-2 on the partly blocked pairs
    of a sphere on a floor under a disk lamp, median 5e-3), a kinked pair's fixed rule by
    KINK_RULE_ERROR (relative). That moves row i's radiosity by rho_i F_ij B_j times `bound`:
    light-driven, with the solved B. In each row
    the pairs of smallest error keep their sampled visibility while their errors add up to half
    the row's allowance (tol B_i, B_i floored at ROW_FLOOR times the mean); the others are
    exact (in either of their two rows), with the other half shared as for independent errors
    (each pair's error allowed in its light is half the allowance over sqrt(count); measured: the
    patches come out 10-20x inside tol, see BENCHMARKS.md "Exact shadows per patch").

    Parameters
    ----------
    G : ndarray, shape (P,)
        A_i F_ij (times a visibility) of each unordered pair (NaN: not computed).
    skip : ndarray of bool, shape (P,)
        Pairs whose value is known to be good enough (e.g. an empty shaft: V exact).
    rho, B : ndarray, shape (N, 3)
    bound : float or ndarray, shape (P,)
        The first values' error relative to G (so `allowed` is in the same units).
    """
    N = len(area)
    known = np.flatnonzero(np.isfinite(G) & ~skip)
    if known.size == 0:
        return known, np.zeros(0)
    i, j = pair_i[known], pair_j[known]
    bound = np.broadcast_to(bound, G.shape)[known]
    mean = np.abs(B).mean(0)
    reference = np.maximum(np.abs(B), ROW_FLOOR * mean[None] + 1e-300)
    exact = np.zeros(known.size, dtype=bool)
    roles = []
    for row, other in ((i, j), (j, i)):
        light = G[known] / area[row] * (rho[row] * np.abs(B[other]) / reference[row]).max(1)
        error = bound * light
        order = np.lexsort((error, row))
        cumulative = np.cumsum(error[order])
        start = np.searchsorted(row[order], row[order], side="left")
        within = cumulative - (cumulative[start] - error[order][start]) <= 0.5 * tol
        exact[order[~within]] = True
        roles.append((row, light))
    pick = np.flatnonzero(exact)
    allowed = np.full(pick.size, np.inf)
    for row, light in roles:
        count = np.bincount(row[pick], minlength=N)[row[pick]]
        weight = np.sqrt(count) * light[pick]
        share = np.divide(0.5 * tol, weight, out=np.full(pick.size, np.inf), where=weight > 0)
        allowed = np.minimum(allowed, share)
    # (no tighter than 1e-3 tol, nor looser than the first values' bound)
    return known[pick], np.clip(allowed, 1e-3 * tol, bound[pick])


class _AllCandidates:
    """A shaft test that keeps every occluder but the convex surface a segment leaves (to measure
    what shaft culling saves)."""

    def __init__(self, shafts):
        self.inner = shafts
        self.M = shafts.M
        self.coverage = shafts.coverage

    def candidates(self, a, b):
        return ~self.inner.own(a, b)

    def free_nodes(self, x, element):
        return self.inner.free_nodes(x, element)
