"""Visibility of element pairs: which occluders may block them, and how much each pair sees past them.

- `ShaftTest`: the candidate occluders of an element pair (or of a point and an element), from the
  occluders' bounding volume hierarchy, planes and own surfaces;
- `blocked_rays`: segments against their pairs' candidates, kind by kind;
- `pair_visibility`: V as the kernel-weighted fraction of unblocked rays between Gauss samples of
  the two elements, refined where a pair is partly occluded; `free_share`, the share of a pair
  that no other object covers;
- `exact_pair_visibility`: V from exact shadows (`occluded.ExactShadows`), an outer rule over the
  source refined cell by cell where its rules disagree.
"""

import numpy as np

from . import ragged
from .bounds import cannot_block, lengths, unit_vectors
from .integrate import children
from .kernel import kernel
from .kinds import RAY_TEST_ORDER
from .transport import distinct, element_nodes, point_to_element, rule_order

TEST_BUDGET = 400_000  # ray-occluder tests per chunk
CANDIDATE_BUDGET = 2_000_000  # pair-occluder shaft tests per chunk


class ShaftTest:
    """Which occluders may block segments between two elements (or a point and an element).

    An occluder is a candidate for a pair only if its box meets the pair's common box, its
    bounding ball meets the capsule around the segment between the elements' centres, it is not
    a plane with both elements on one side, it is not the convex surface either element lies on
    (rays leaving a convex surface never meet it again: spheres, flat patches, meshes around a
    convex solid), and it is not a mesh around a convex room holding both ends (in front of every
    one of its planes: `mesh.PolygonMesh.front_hull`).

    The box and capsule tests are answered by the occluders' bounding volume hierarchy
    (`occlusion.Occluders.bvh`, `bvh.BVH.shaft_candidates`: O(log M) nodes per query instead of
    all M occluders); the plane and own-surface rules are then applied to the sparse
    (query, occluder) pairs it returns.

    An occluder that covers part of an element (a box resting on a floor patch: `coverage`) is a
    candidate of every pair of that element: segments from the covered part start inside it and
    are blocked whichever way they go, also toward elements that no shaft test would put it
    between. (Without it, a floor patch a fifth under a box saw the ceiling, the walls and a ball
    beside the box from under the box too: its visibilities added up to 0.88 instead of 0.8 and its
    radiosity, the mean over its free part, came out 10 % dark; in a 6 m room with three boxes on
    0.86 m floor patches the floor's direct light was 1.75 % short of a ray-traced reference.)

    Parameters
    ----------
    elements : Elements
    occluders : occlusion.Occluders
    occluder_object : ndarray of int, shape (M,)
        Scene object of each occluder.
    coverage : coverage.Coverage, optional
        What other objects cover of each element.
    """

    def __init__(self, elements, occluders, occluder_object, coverage=None):
        self.elements = elements
        self.occ = occluders
        self.object = np.asarray(occluder_object, dtype=np.int64)
        self.M = len(self.object)
        self.coverage = coverage
        self.planar = np.flatnonzero(occluders.planar) if self.M else np.zeros(0, dtype=np.int64)
        self.hull_meshes = [m for m in range(self.M) if occluders.hull[m] is not None]
        self.eps = 1e-9 * occluders.scale if self.M else 0.0

    def candidates(self, a, b):
        """Candidate occluders of element pairs, as a boolean matrix of shape (P, M)."""
        e = self.elements
        if self.M == 0:
            return np.zeros((a.size, 0), dtype=bool)
        lo = np.minimum(e.box_min[a], e.box_min[b])
        hi = np.maximum(e.box_max[a], e.box_max[b])
        radius = np.maximum(e.radius[a], e.radius[b])

        def heights(k, m):
            return self._element_heights(a[k], m), self._element_heights(b[k], m)

        def own(k, m):
            return self._own_pairs(e.owner[a[k]], e.outward[a[k]], m) | self._own_pairs(
                e.owner[b[k]], e.outward[b[k]], m
            )

        ends = (e.box_min[a], e.box_max[a], e.box_min[b], e.box_max[b])
        mask = self._mask(lo, hi, e.center[a], e.center[b], radius, heights, own, ends)
        for end in (a, b):
            k, m = self._covering(end)
            keep = ~own(k, m)
            mask[k[keep], m[keep]] = True
        return mask

    def _covering(self, element):
        """(query (C,), occluder (C,)): the occluders covering part of each queried element."""
        if self.coverage is None:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return self.coverage.occluders_of(element)

    def free_nodes(self, x, element):
        """Whether points x (P, Q, 3) on elements (P,) lie outside the elements' covered parts
        (`coverage.Coverage.covers`), shape (P, Q) bool."""
        if self.coverage is None:
            return np.ones(x.shape[:2], dtype=bool)
        return ~self.coverage.covers(x, element)

    def own(self, a, b):
        """(P, M): the occluder is the convex surface element a or b lies on, which segments between
        them leave outward and never meet again (a fact, not a culling rule)."""
        e = self.elements
        return self._own(e.owner[a], e.outward[a]) | self._own(e.owner[b], e.outward[b])

    def point_candidates(self, x, owner, outward, b, home=None):
        """Candidate occluders for segments from points x (on object `owner`) to elements b, (K, M).

        With `home` (K,), the element each point lies on, only the candidates of the element
        pairs (home, b) are tested (a segment from a point of home to one of b lies in their
        pair's shaft), once per distinct pair, instead of a descent of the hierarchy per point
        (a point outside its home's bounding ball is tested against every occluder). An occluder
        whose ball cannot meet the cone from x to b's ball (`bounds.cannot_block`) is dropped.
        """
        e = self.elements
        if self.M == 0:
            return np.zeros((len(x), 0), dtype=bool)
        within = None
        if home is not None:
            pairs, inverse = np.unique(home * len(e.center) + b, return_inverse=True)
            within = self.candidates(pairs // len(e.center), pairs % len(e.center))[inverse]
            within[lengths(x - e.center[home]) > e.radius[home] * (1.0 + 1e-9)] = True
        lo = np.minimum(x, e.box_min[b])
        hi = np.maximum(x, e.box_max[b])

        def heights(k, m):
            h = self._point_heights(x[k], m)
            return (h, h), self._element_heights(b[k], m)

        def dropped(k, m):
            # own surfaces; and the capsule holds the pair's segments as far from x as from b, but
            # they lie in the cone from x to b's ball, which a nearby occluder beside x often
            # misses (a floor point between balls resting on it: 8.8 candidate occluders per ray
            # of example 05's near field before this, 5.4 after)
            own_start = self._own_pairs(owner[k], outward[k], m)
            bvh = self.occ.bvh
            outside = cannot_block(x[k], e.center[b[k]], e.radius[b[k]], bvh.center[m], bvh.radius[m])
            return own_start | self._own_pairs(e.owner[b[k]], e.outward[b[k]], m) | outside

        ends = (x, x, e.box_min[b], e.box_max[b])
        mask = self._mask(lo, hi, x, e.center[b], e.radius[b], heights, dropped, ends, within)
        return mask

    def segment_candidates(self, p, q, radius, owner, outward):
        """Candidate occluders of segments from points p (on object `owner`, -1 for none) to
        balls (q, radius), shape (K, M)."""
        if self.M == 0:
            return np.zeros((len(p), 0), dtype=bool)
        lo = np.minimum(p, q - radius[:, None])
        hi = np.maximum(p, q + radius[:, None])

        def heights(k, m):
            hp, hq = self._point_heights(p[k], m), self._point_heights(q[k], m)
            return (hp, hp), (hq - radius[k], hq + radius[k])

        def own(k, m):
            return self._own_pairs(owner[k], outward[k], m)

        ends = (p, p, q - radius[:, None], q + radius[:, None])
        return self._mask(lo, hi, p, q, radius, heights, own, ends)

    def _mask(self, lo, hi, p, q, radius, heights, dropped, ends, within=None):
        """Dense (K, M) candidates: the BVH's box-and-capsule pairs (or those of `within`, a
        (K, M) superset, that pass the same test), less those `dropped` names (own surfaces, and
        for a point query occluders outside its cone) and planes with both ends on one side.

        heights(k, m) -> ((low, high) of end 1, (low, high) of end 2) over the planes of planar
        occluders m for queries k (arrays of shape (C,)); dropped(k, m) -> bool (C,); ends: boxes
        (lo1, hi1, lo2, hi2) holding the two ends, (K, 3) each, for the BVH's node-level plane test
        (coplanar groups of occluders, e.g. a wall of quads, are dropped at once).
        """
        K = lo.shape[0]
        if within is None:
            k, m = self.occ.bvh.shaft_candidates(lo, hi, p, q, radius, ends=ends, plane_eps=self.eps)
        else:
            k, m = np.nonzero(within)
            hit = self.occ.bvh.shaft_pairs(k, m, lo, hi, p, q, radius)
            k, m = k[hit], m[hit]
        keep = ~dropped(k, m)
        planar = np.flatnonzero(keep & self.occ.planar[m])
        if planar.size:
            (low1, high1), (low2, high2) = heights(k[planar], m[planar])
            above = (low1 >= -self.eps) & (low2 >= -self.eps)
            below = (high1 <= self.eps) & (high2 <= self.eps)
            keep[planar[above | below]] = False
        # a mesh around a convex room: both ends inside the room (in front of all its planes)
        for mesh in self.hull_meshes:
            sel = np.flatnonzero(keep & (m == mesh))
            if sel.size:
                normal, offset = self.occ.hull[mesh]
                inside = np.ones(sel.size, dtype=bool)
                for low, high in ((ends[0], ends[1]), (ends[2], ends[3])):
                    centre, half = 0.5 * (low[k[sel]] + high[k[sel]]), 0.5 * (high[k[sel]] - low[k[sel]])
                    least = centre @ normal.T - half @ np.abs(normal).T - offset[None]
                    inside &= least.min(1) >= -self.eps
                keep[sel[inside]] = False
        mask = np.zeros((K, self.M), dtype=bool)
        mask[k[keep], m[keep]] = True
        return mask

    def _element_heights(self, index, m):
        """Least and greatest heights of elements' boxes over the planes of occluders m, (C,) each."""
        normal = self.occ.plane_normal[m]
        return self.elements.heights(index, normal * self.occ.plane_offset[m][:, None], normal)

    def _point_heights(self, x, m):
        """Heights of points x (C, 3) over the planes of occluders m (C,)."""
        return np.einsum("ki,ki->k", x, self.occ.plane_normal[m]) - self.occ.plane_offset[m]

    def _own(self, owner, outward):
        """(K, M): the occluder is the convex surface the segment starts on, leaving it outward
        (or through its plane): such a segment never meets that surface again."""
        leaves = self.occ.planar[None] | outward[:, None]
        return self.occ.convex[None] & (self.object[None] == owner[:, None]) & leaves

    def _own_pairs(self, owner, outward, m):
        """`_own` for explicit (segment, occluder) pairs: owner, outward and m of shape (C,)."""
        leaves = self.occ.planar[m] | outward
        return self.occ.convex[m] & (self.object[m] == owner) & leaves


def blocked_rays(occluders, origins, ends, candidates, ray_pair):
    """Whether each segment is blocked by any candidate occluder of its pair.

    The candidates are tested kind by kind in `kinds.RAY_TEST_ORDER`, cheapest first, each only
    on the segments no earlier one blocked (the answer is the same; in the Cornell example a
    quarter of the segments sent to the NURBS shell's proxy were already blocked by a sphere or
    a wall).

    Parameters
    ----------
    origins, ends : ndarray, shape (R, 3)
    candidates : ndarray of bool, shape (P, M)
    ray_pair : ndarray of int, shape (R,)
        Pair (row of `candidates`) of each ray.

    Returns
    -------
    blocked : ndarray of bool, shape (R,)
    tests : int
        (segment, occluder) tests made.
    """
    blocked = np.zeros(len(origins), dtype=bool)
    pair_of_test, occluder = np.nonzero(candidates)
    if pair_of_test.size == 0:
        return blocked, 0
    # expand rays x candidate occluders of their pair
    per_pair = candidates.sum(1)
    ray, entry = ragged.expand(ragged.starts(per_pair)[ray_pair], per_pair[ray_pair])
    which = occluder[entry]
    phases = [np.isin(occluders.kind[which], kinds) for kinds in RAY_TEST_ORDER]
    phases[0] |= ~np.logical_or.reduce(phases)  # (a kind not listed: with the first)
    tests = 0
    for phase in phases:
        todo = np.flatnonzero(phase & ~blocked[ray])
        tests += todo.size
        for s in range(0, todo.size, TEST_BUDGET):
            part = todo[s : s + TEST_BUDGET]
            hit = occluders.blocked(origins[ray[part]], ends[ray[part]], which[part])
            blocked[ray[part[hit]]] = True
    return blocked, tests


# ---------------------------------------------------------------------------- visibility
EXACT_MAX_LEVEL = 7  # an exact pair visibility's outer cells are split at most this many times
SHADOW_EDGE_DECAY = 1.0 / 8.0  # ... a partly shadowed cell's difference: at least this of its parent's
DARK_PROOF_LEVEL = 3  # ... and a dark cell is split until proven dark down to this level
FREE_PROOF_LEVEL = 2  # ... and a cell that sees no shadow is split until proven clear down to this level
DARK_NOISE = 1e-12  # a cell seeing at most this fraction of its unoccluded light counts as dark


def exact_pairs(exact, shafts, a, b):
    """Which element pairs `exact_pair_visibility` can make exact, and how it orients them.

    Returns
    -------
    capable : ndarray of bool, shape (P,)
        The inner side an exact target and every occluder left in the shaft an exact kind
        (pairs with an empty shaft included: their V is 1).
    src, dst : ndarray of int, shape (P,)
        Outer and inner side (the inner one an exact target, a flat polygon preferred: the
        closed form of `cones`).
    candidates : ndarray of bool, shape (P, M)
        Occluders that may block a segment of the pair.
    """
    candidates = exact.clear(a, b, shafts.candidates(a, b))
    # (no views: pairs with a twisted quad in their shaft keep rays; their exact visibility cost
    # 3x the rays' time at tol 1e-3 and 130x at 1e-4 in a lamp-floor scene: BENCHMARKS.md)
    exact_a, exact_b = exact.exact(a, candidates), exact.exact(b, candidates)
    turn = exact_a & (~exact_b | (exact.polygon_target[a] & ~exact.polygon_target[b]))
    src, dst = np.where(turn, b, a), np.where(turn, a, b)
    capable = exact.exact(dst, candidates) | ~candidates.any(1)
    return capable, src, dst, candidates


def exact_pair_visibility(elements, exact, shafts, a, b, tol, absolute=None):
    """Visibility of element pairs from exact shadows where `exact` covers them, NaN elsewhere.

    V(a, b) = sum_k w_k F_vis(x_k -> b) / sum_k w_k F(x_k -> b) over an outer Gauss rule on a
    (the inner side b must be an exact target; pairs with only a exact are turned round, which
    reciprocity allows for V), refined cell by cell over a where a cell's rule and its four
    children's disagree (`_refined_visibility`).

    Parameters
    ----------
    exact : occluded.ExactShadows
    shafts : ShaftTest
    a, b : ndarray of int, shape (P,)
    tol : float or ndarray, shape (P,)
        Relative accuracy of each pair's V (of max(V, 1e-3)): cells are final where a rule and its
        children's agree to 3 tol times their share (the finer rule's error is about a third of
        their difference at second order).
    absolute : ndarray, shape (P,), optional
        Instead, the error allowed in each V (cells agree to 3 times it, by their share), never
        taken below half tol times V.

    Returns
    -------
    V : ndarray, shape (P,)
        NaN where the pair is not exact (a target or a candidate occluder not covered).
    lines : int
    """
    V = np.full(a.size, np.nan)
    capable, src, dst, candidates = exact_pairs(exact, shafts, a, b)
    V[~candidates.any(1)] = 1.0  # nothing in the shaft
    ok = np.flatnonzero(capable & candidates.any(1))
    lines = 0
    if ok.size == 0:
        return V, lines
    src, dst, candidates = src[ok], dst[ok], candidates[ok]
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), a.shape)[ok]
    allowed = None if absolute is None else np.asarray(absolute, dtype=np.float64)[ok]
    e = elements
    distance = lengths(e.center[src] - e.center[dst])
    ratio = e.radius[src] / np.maximum(distance - e.radius[dst], 1e-300)
    # each pair's outer rule order from its own distance-to-size ratio (far pairs: 2 x 2 points)
    order = np.clip(rule_order(np.minimum(ratio, 0.95), tol), 2, 4)
    result = np.full(ok.size, np.nan)
    for value in distinct(order):
        group = np.flatnonzero(order == value)
        result[group], count = _refined_visibility(
            e,
            exact,
            src[group],
            dst[group],
            candidates[group],
            tol[group],
            None if allowed is None else allowed[group],
            int(value),
        )
        lines += count
    V[ok] = np.clip(result, 0.0, 1.0)
    return V, lines


def _refined_visibility(e, exact, src, dst, candidates, tol, allowed, order):
    """`exact_pair_visibility`'s outer integral over the source, refined cell by cell.

    Each cell's rule (order x order points) is compared with the sum over its four children;
    a cell whose difference exceeds its share (by parameter area) of three times the pair's
    allowance is split, down to EXACT_MAX_LEVEL, so refinement goes where the visibility changes
    (a penumbra, the sliver a patch sees of an emitter), not over the whole pair. The allowance
    is `allowed` (absolute, in V) but never below half tol times V itself (the pair's own light
    to half tol: what a row whose first, sampled solve was dark needs), or without `allowed`
    tol relative to max(V, 1e-3). Returns (V (P,), lines).

    A cell that some of its points see partly shadowed may hold a shadow's edge between them,
    where a rule and its children's can agree by chance: its difference is taken as at least
    SHADOW_EDGE_DECAY times its parent's (its share of it), and the whole element is never
    final (a sphere's shadow on a 2.7 m floor patch agreed at the element's quarter cells,
    0.07 % off at tol 1e-4, 7.5 tol; BENCHMARKS.md "Shadow edges between a rule's points").
    """
    P = src.size
    pair = np.arange(P)
    boxes = e.boxes_of(src)
    level = np.zeros(P, dtype=np.int64)
    seen, total, lines = _cell_sums(e, exact, src, dst, candidates, tol, boxes, order)
    parent_difference = np.full(P, np.inf)  # (the element itself: none, never final if shadowed)
    done_seen, done_total = np.zeros(P), np.zeros(P)
    while pair.size:
        kids = children(boxes)
        kid_pair = np.repeat(pair, 4)
        s, t, count = _cell_sums(
            e, exact, src[kid_pair], dst[kid_pair], candidates[kid_pair], tol[kid_pair], kids, order
        )
        lines += count
        child_seen, child_total = s.reshape(-1, 4).sum(1), t.reshape(-1, 4).sum(1)
        # each pair's current estimate: finished cells and the children of the open ones
        pair_seen = done_seen + np.bincount(pair, child_seen, P)
        pair_total = done_total + np.bincount(pair, child_total, P)
        V = np.divide(pair_seen, pair_total, out=np.ones(P), where=pair_total > 0)
        if allowed is None:
            allow = tol * np.maximum(V, 1e-3)
        else:
            allow = np.maximum(allowed, 0.5 * tol * V)
        share = 3.0 * allow[pair] * pair_total[pair] * 0.25 ** level.astype(np.float64)
        difference = np.abs(child_seen - seen)
        # (rounding noise of the closed forms counts as unshadowed, as DARK_NOISE counts as dark)
        shadowed = (seen < (1.0 - DARK_NOISE) * total) | (child_seen < (1.0 - DARK_NOISE) * child_total)
        estimate = np.where(
            shadowed, np.maximum(difference, SHADOW_EDGE_DECAY * parent_difference), difference
        )
        final = (estimate <= share) | (level + 1 >= EXACT_MAX_LEVEL)
        # a cell whose rules see nothing may still hold a sliver of the target: where a sphere
        # could prove it (`ExactShadows.hides_cells`), it is dark only once one sphere hides the
        # whole target from it (refined down to DARK_PROOF_LEVEL until then)
        # (rounding noise of the closed forms, ~1e-16 of the cell's unoccluded light, counts as 0)
        noise = DARK_NOISE * child_total
        dark = np.flatnonzero(final & (seen <= noise) & (child_seen <= noise) & (level < DARK_PROOF_LEVEL))
        if dark.size:
            points, margin = e.cell_hulls(src[pair[dark]], boxes[dark])
            provable, hidden = exact.hides_cells(points, margin, dst[pair[dark]], candidates[pair[dark]])
            final[dark[provable & ~hidden]] = False
        # a cell whose rules see no shadow may still hold a small one between their points: it
        # is final only once no occluder can reach its segments (`ExactShadows.clears_cells`),
        # split down to FREE_PROOF_LEVEL until then
        unseen = np.flatnonzero(final & ~shadowed & (level < FREE_PROOF_LEVEL))
        if unseen.size:
            points, margin = e.cell_hulls(src[pair[unseen]], boxes[unseen])
            clear = exact.clears_cells(points, margin, dst[pair[unseen]], candidates[pair[unseen]])
            final[unseen[~clear]] = False
        done_seen += np.bincount(pair[final], child_seen[final], P)
        done_total += np.bincount(pair[final], child_total[final], P)
        open_kids = np.repeat(~final, 4)
        pair, boxes = kid_pair[open_kids], kids[open_kids]
        level = np.repeat(level + 1, 4)[open_kids]
        seen, total = s[open_kids], t[open_kids]
        parent_difference = np.repeat(0.25 * difference, 4)[open_kids]  # (a child's share)
    return np.divide(done_seen, done_total, out=np.ones(P), where=done_total > 0), lines


def _cell_sums(e, exact, src, dst, candidates, tol, boxes, order):
    """Visible and unoccluded sums of the outer rule over source cells, shapes (C,), (C,), and
    the lines spent: sum_k w_k F_vis(x_k -> dst) and sum_k w_k F(x_k -> dst)."""
    x, normal, w = e.cell_nodes(src, boxes, order)
    n1, length = unit_vectors(normal)
    weight = w * length
    C, q = x.shape[:2]
    if C == 0:
        return np.zeros(0), np.zeros(0), 0
    X, N = x.reshape(-1, 3), n1.reshape(-1, 3)
    target = np.repeat(dst, q)
    point_tol = np.repeat(tol, q)
    unoccluded, _ = point_to_element(e, X, N, target, point_tol.min())
    blocking = np.repeat(candidates, q, axis=0)
    visible, free, lines = exact.visible(X, N, target, blocking, point_tol)
    visible = np.where(free, unoccluded, visible)
    return (weight * visible.reshape(C, q)).sum(1), (weight * unoccluded.reshape(C, q)).sum(1), lines


def pair_visibility(elements, occluders, shafts, a, b, tol, weight=None):
    """Kernel-weighted unblocked fraction of element pairs, refined where partly occluded.

    Parameters
    ----------
    a, b : ndarray of int, shape (P,)
    shafts : ShaftTest
    weight : ndarray, shape (P,), optional
        The larger of F(a -> b) and F(b -> a): partly occluded pairs are refined only where
        weight * 0.1 exceeds tol (elsewhere the visibility error is below tol in B).

    Returns
    -------
    V : ndarray, shape (P,)
    counts : dict
        "rays" (segments cast), "tests" (segment-occluder tests), "shadowed" (pairs with an
        occluder in their shaft: the others cast no rays).
    free : ndarray of bool, shape (P,)
        Pairs with no candidate occluder in their shaft (nothing can block any segment between
        them: V = 1 exactly, also from any point of either element).
    """
    V = np.ones(a.size)
    free = np.ones(a.size, dtype=bool)
    counts = dict(rays=0, tests=0, shadowed=0)
    chunk = max(256, CANDIDATE_BUDGET // max(shafts.M, 1))
    orders = (2, 4) + ((8,) if tol < 1e-3 else ()) + ((16,) if tol < 1e-5 else ())
    for start in range(0, a.size, chunk):
        rows = np.arange(start, min(start + chunk, a.size))
        candidates = shafts.candidates(a[rows], b[rows])
        todo = np.flatnonzero(candidates.any(1))
        free[rows[todo]] = False
        counts["shadowed"] += todo.size
        for n in orders:
            if todo.size == 0:
                break
            width = max(1, int(candidates[todo].sum(1).max()))
            step = max(1, TEST_BUDGET // (n**4 * width))
            partial = []
            for s in range(0, todo.size, step):
                sel = todo[s : s + step]
                p = rows[sel]
                v, r, t = _visibility_rule(elements, occluders, shafts, a[p], b[p], candidates[sel], n)
                V[p] = v
                counts["rays"] += r
                counts["tests"] += t
                partial.append(sel[((v > 0.0) & (v < 1.0)) | np.isnan(v)])
            todo = np.concatenate(partial)
            if n == orders[0]:
                # a patch's view of itself is blocked only where it folds through itself, which the
                # first rule's few segments seldom cross: self pairs with a candidate (their own
                # surface, not convex) always take the next rule (a Blender NURBS Surface cyclic in u
                # and v passed its 2 x 2 rule unblocked and summed to 1.9)
                own = np.flatnonzero((a[rows] == b[rows]) & candidates.any(1))
                todo = np.union1d(todo, own)
            if weight is not None:
                todo = todo[0.1 * weight[rows[todo]] > tol]
    # (an end whose nodes all lie under its covering object even at the finest rule: its free
    # part, a sliver, is taken as unblocked; its share of the factor is small)
    return np.where(np.isnan(V), 1.0, V) * free_share(elements, shafts, a, b), counts, free


# nodes per parameter on a partly covered element for the kernel's means over its parts
# (`free_share`): as splits x order, 8 x 8
SHARE_SPLITS, SHARE_ORDER = 4, 2


def free_share(elements, shafts, a, b, first_only=False):
    """The share of the pairs' unoccluded factor that the free parts of elements a and b exchange
    (parts covered by another object, `coverage`, exchange nothing), shape (P,): per covered end
    f m_free / (f m_free + (1 - f) m_covered), with f its free fraction and m the kernel's means
    over its free and covered nodes (SHARE_SPLITS x SHARE_ORDER nodes per parameter, toward 2 x 2
    of the other end): f where the kernel is even, exactly 1 toward a covering box's own faces
    (the kernel is zero under it); 1 for pairs with no covered end. With `first_only`, a's share
    alone (what a point on a's free part reuses of the pair's visibility: `Scene` gathers).

    Pair visibilities are sampled over the free parts (`_visibility_rule`) and scaled by it: a
    box covering a fifth of a floor patch takes a fifth of what the patch sees, wherever the
    shaft tests put the box (even where a 2 x 2 rule has no node under it)."""
    share = np.ones(a.size)
    coverage = shafts.coverage
    if coverage is None or coverage.element.size == 0:
        return share
    for end, other in ((a, b),) if first_only else ((a, b), (b, a)):
        sel = np.flatnonzero(np.isin(end, coverage.element))
        if sel.size == 0:
            continue
        x, nx, wx = element_nodes(elements, end[sel], SHARE_SPLITS, SHARE_ORDER)
        y, ny, wy = element_nodes(elements, other[sel], 1, 2)
        K = (kernel(x[:, :, None], nx[:, :, None], y[:, None], ny[:, None]) * wy[:, None, :]).sum(2)
        free = shafts.free_nodes(x, end[sel])
        # the kernel's mean over each part from its nodes, weighted by the parts' exact areas (a
        # node count would put a footprint's edge at a node spacing: a fifth covered read as a
        # quarter on 8 x 8 nodes); a part without nodes takes the other's mean, but a free sliver
        # between the nodes takes all of a kernel that is zero on the covered nodes (the foot of
        # the covering box's own face: the pair's factor lies on the sliver)
        mean_free, mean_covered = (_part_mean(wx, K, part) for part in (free, ~free))
        mean_free = np.where(np.isnan(mean_free), np.where(mean_covered > 0, mean_covered, 1.0), mean_free)
        mean_covered = np.where(np.isnan(mean_covered), mean_free, mean_covered)
        f = coverage.free[end[sel]]
        whole = f * mean_free + (1.0 - f) * mean_covered
        share[sel] *= np.divide(f * mean_free, whole, out=f.copy(), where=whole > 0)
    return share


def _part_mean(w, K, part):
    """Mean of K (S, Q) over the nodes in `part` (S, Q) with weights w (S, Q), NaN where none."""
    total = np.where(part, w, 0.0).sum(1)
    return np.divide((np.where(part, w, 0.0) * K).sum(1), total, out=np.full(len(w), np.nan), where=total > 0)


def _visibility_rule(elements, occluders, shafts, a, b, candidates, n):
    """Kernel-weighted unblocked fraction of n x n nodes on each of the pairs' elements, over the
    nodes outside the elements' covered parts (`ShaftTest.free_nodes`), shape (P,); NaN where
    every node of an end is covered (a sliver beside a box: a finer rule may find its free part)."""
    xa, na, wa = element_nodes(elements, a, 1, n)
    xb, nb, wb = element_nodes(elements, b, 1, n)
    weight = kernel(xa[:, :, None], na[:, :, None], xb[:, None], nb[:, None])
    weight *= wa[:, :, None] * wb[:, None, :]
    free = shafts.free_nodes(xa, a)[:, :, None] & shafts.free_nodes(xb, b)[:, None, :]
    weight *= free
    P, q = a.size, xa.shape[1]
    origins = np.broadcast_to(xa[:, :, None], (P, q, q, 3)).reshape(-1, 3)
    ends = np.broadcast_to(xb[:, None], (P, q, q, 3)).reshape(-1, 3)
    ray_pair = np.repeat(np.arange(P), q * q)
    blocked, tests = blocked_rays(occluders, origins, ends, candidates, ray_pair)
    V = unblocked_fraction(weight.reshape(P, -1), blocked.reshape(P, -1))
    V[~free.reshape(P, -1).any(1)] = np.nan
    return V, P * q * q, tests


def unblocked_fraction(weight, blocked):
    """Kernel-weighted fraction of unblocked samples per row, shape (P,).

    Rows whose samples all have zero weight (they miss each other's fronts) get the plain
    fraction of unblocked samples.
    """
    total = weight.sum(1)
    fraction = 1.0 - blocked.mean(1)
    return np.divide(np.where(blocked, 0.0, weight).sum(1), total, out=fraction, where=total > 0)
