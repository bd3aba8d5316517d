"""Gathering light at points: F(x -> j) V(x, j) B_j summed over the elements j.

The factors are the exact point-to-element ones (`transport.point_to_element`); V comes from
exact shadows, rays, or the element pair's own V, whichever the point's share of the light needs
(`gather`).
"""

import numpy as np

from .bounds import lengths
from .kernel import kernel
from .transport import element_nodes, point_to_element
from .visibility import CANDIDATE_BUDGET, blocked_rays, unblocked_fraction

RAY_SHARE = 10.0  # gathered pairs carrying this times tol of a point's light get their own rays
MAX_RAY_SHARE = 1e-2  # (and at most this share)
EXACT_GATHER_MAX_TOL = 0.05  # loosest relative tol of a gathered pair's exact shadow


def gather(
    elements,
    occluders,
    shafts,
    x,
    n,
    query,
    B,
    targets,
    tol,
    home=None,
    known=None,
    emitters=None,
    exact=None,
    keep=False,
):
    """sum_j F(x -> j) V(x, j) B_j at points: the light arriving at x from all elements.

    Rays are cast for the pairs that carry at least RAY_SHARE * tol (at most MAX_RAY_SHARE) of
    the light arriving at their point (emitters, lit neighbours: where shadows show) and for
    those whose element pair (home element of x, j) is partly blocked; the dim rest reuses that
    pair's visibility from the solve when it is known, and pairs whose shaft was empty need none.

    Parameters
    ----------
    x, n : ndarray, shape (K, 3)
        Points (m) and unit front normals.
    query : dict
        The points' surface: "owner" (object), "geometry" (element geometry number), "outward".
    B : ndarray, shape (N, 3)
        Element radiosities.
    targets : ndarray of int
        Elements that carry light (B != 0).
    home : ndarray of int, shape (K,), optional
        Element containing each point.
    known : object, optional
        What the solve knows of element pairs: `known_visibility(home, j)` -> V (NaN where
        unknown), `known_free(home, j)` -> bool (nothing in the pair's shaft: a point of
        `home` sees j unblocked) and `known_sealed(home, j)` -> bool (a closed occluding shell
        between them: the pair is skipped).
    emitters : ndarray of bool, shape (N,), optional
        Emitting elements: always traced (their shadows are the sharpest).
    exact : occluded.ExactShadows, optional
        Traced pairs whose target and candidate occluders it covers get their exact visible
        factor instead of rays.

    keep : bool
        Also return the factors F(x -> j) V(x, j) (`gathered`).

    Returns
    -------
    arriving : ndarray, shape (K, 3)
    counts : dict
        "evaluations", "rays", "tests", "pairs", "lines" (of exact shadows, `shadow`).
    factors : (points (P,), elements (P,), F V (P,)), only with `keep`
    """
    e = elements
    arriving = np.zeros((len(x), 3))
    counts = dict(evaluations=0, rays=0, tests=0, pairs=0, lines=0)
    kept = []
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    if targets.size == 0 or len(x) == 0:
        return (arriving, counts, empty) if keep else (arriving, counts)
    M = shafts.M if shafts is not None else 0
    chunk = max(1, min(200_000, CANDIDATE_BUDGET // max(M, 1)) // targets.size)
    for s in range(0, len(x), chunk):
        part = slice(s, s + chunk)
        k, j = _facing_pairs(e, x[part], n[part], query, targets)
        k_global = k + s
        if known is not None and home is not None and k.size:
            # (a point inside a closed occluding shell sees nothing outside it, nor a point
            # outside it the shell's inside)
            open_ = ~known.known_sealed(home[k_global], j)
            k, j, k_global = k[open_], j[open_], k_global[open_]
        if k.size == 0:
            continue
        F, ev = _point_factors(e, x[k_global], n[k_global], j, tol)
        counts["evaluations"] += ev
        counts["pairs"] += k.size
        if shafts is not None and shafts.M:
            traced = _gather_visibility(
                e,
                occluders,
                shafts,
                x,
                n,
                query,
                B,
                tol,
                home,
                known,
                emitters,
                k_global,
                j,
                F,
                counts,
                exact,
            )
            F = F * traced
        if keep:
            kept.append((k_global, j, F))
        for channel in range(3):
            arriving[:, channel] += np.bincount(k_global, weights=F * B[j, channel], minlength=len(x))
    if not keep:
        return arriving, counts
    if not kept:
        return arriving, counts, empty
    return arriving, counts, tuple(np.concatenate(part) for part in zip(*kept))


def _gather_visibility(
    e, occluders, shafts, x, n, query, B, tol, home, known, emitters, k, j, F, counts, exact
):
    """V for the (point, element) pairs k, j: exact or rays where they matter, the pair's V elsewhere."""
    V = np.ones(k.size)
    # (B may be net of a sky: `Solution.radiosity_at`; the channels' largest by components, which
    # costs a third of a reduction over an axis of 3)
    light = np.abs(np.take(B, j, axis=0))
    share = F * np.maximum(np.maximum(light[:, 0], light[:, 1]), light[:, 2])
    total = np.bincount(k, weights=share, minlength=len(x))
    rays = share >= min(RAY_SHARE * tol, MAX_RAY_SHARE) * total[k]
    if emitters is not None:
        rays |= emitters[j]
    if known is not None and home is not None:
        # a point inside its home's bounding ball lies in every shaft of the home's pairs, so a
        # pair with an empty shaft leaves the point's segments free (V = 1, no rays)
        inside = lengths(x[k] - e.center[home[k]]) <= e.radius[home[k]] * (1.0 + 1e-9)
        free = inside & known.known_free(home[k], j)
        rays &= ~free
        reuse = np.flatnonzero(~rays & ~free)
        V[reuse] = known.known_visibility(home[k[reuse]], j[reuse])
        # an element pair whose shaft held an occluder says little about one point of its element,
        # whatever its sampled V: a point under a box resting on the floor sees none of what its
        # floor patch sees, even of a patch it barely covers (V = 1), and a point just outside the
        # box sees what a patch mostly under it does not (V = 0). Rays there, the largest shares
        # first, until what is left of the point's reused light adds up to at most tol of it (each
        # reused pair's V is off by at most 1: its share bounds it)
        rays[reuse[_beyond_budget(k[reuse], share[reuse], tol * total)]] = True
        rays[reuse[np.isnan(V[reuse])]] = True
    sel = np.flatnonzero(rays)
    if sel.size:
        p, q = k[sel], j[sel]
        # exact shadows where target and occluders allow, for emitters only: direct light has the
        # sharpest shadows; indirect pairs keep rays (exact for them costs ~10x more lines than it
        # improves); a pair carrying the share f of the point's light needs tol / f of its value
        fraction = share[sel] / np.maximum(total[p], 1e-300)
        local = np.clip(tol / np.maximum(fraction, 1e-12), tol, EXACT_GATHER_MAX_TOL)
        V[sel], c = point_visibility(
            e,
            occluders,
            shafts,
            exact,
            x[p],
            n[p],
            dict(
                owner=np.full(sel.size, query["owner"]),
                outward=np.full(sel.size, query["outward"]),
                home=home[p] if home is not None else None,
            ),
            q,
            F[sel],
            tol,
            exact_tol=local,
            exact_allowed=emitters[q] if emitters is not None else None,
        )
        for key in ("rays", "tests", "lines"):
            counts[key] += c[key]
    return V


def _beyond_budget(point, share, budget):
    """Which of the items (point (P,), share (P,)) fall outside each point's budget (shape (Q,))
    when its smallest shares are kept first: keeping the rest would add up past the budget,
    shape (P,) bool."""
    order = np.lexsort((share, point))
    point, ordered = point[order], share[order]
    running = np.cumsum(ordered)
    first = np.searchsorted(point, point)  # (sorted by point: its first item)
    before = np.where(first > 0, running[first - 1], 0.0)
    out = np.zeros(point.size, dtype=bool)
    out[order] = running - before > budget[point]
    return out


def nudged(elements, x, n, j):
    """Points x moved off their surface along their unit normals n by 1e-9 of element j's size
    plus distance, shape (K, 3): the edge terms of the contour integrals stay finite at points on
    a border (every point factor of a gather is taken there)."""
    return x + (1e-9 * (elements.radius[j] + lengths(x - elements.center[j])))[:, None] * n


def point_visibility(
    elements, occluders, shafts, exact, x, n, start, j, F, tol, exact_tol=None, exact_allowed=None
):
    """V(x, j): the fraction of F(x -> j) that points x see past the occluders, shape (K,).

    Exact visible factors (`occluded.ExactShadows.visible`, at the points `nudged` as F is) where
    the target and every candidate occluder allow, rays (`_point_visibility`: 2 x 2 per target,
    refined where partial) elsewhere.

    Parameters
    ----------
    exact : occluded.ExactShadows or None
    x, n : ndarray, shape (K, 3)
        Points on their surface and unit normals.
    start : dict of ndarray, shape (K,) each
        Where the points lie: "owner", the scene object (its own convex surface cannot block
        them), "outward", whether on the outside of a convex surface, and optionally "home",
        the element (its pairs' shafts then hold the candidates: `ShaftTest.point_candidates`).
    j : ndarray of int, shape (K,)
        Target elements.
    F : ndarray, shape (K,)
        The unoccluded F(x -> j) (the exact visible factor is divided by it).
    tol : float
    exact_tol : ndarray, shape (K,), optional
        Tolerance of each exact query (default tol).
    exact_allowed : ndarray of bool, shape (K,), optional
        The queries that may take exact shadows (default all).

    Returns
    -------
    V : ndarray, shape (K,)
    counts : dict
        "rays", "tests", "lines".
    """
    V = np.ones(len(x))
    counts = dict(rays=0, tests=0, lines=0)
    if shafts is None or shafts.M == 0 or len(x) == 0:
        return V, counts
    candidates = shafts.point_candidates(x, start["owner"], start["outward"], j, start.get("home"))
    todo = candidates.any(1)
    if exact is not None:
        may = todo if exact_allowed is None else todo & exact_allowed
        use = np.flatnonzero(may & exact.exact(j, candidates, x))
        if use.size:
            local = tol if exact_tol is None else exact_tol[use]
            p = nudged(elements, x[use], n[use], j[use])
            visible, free, lines = exact.visible(p, n[use], j[use], candidates[use], local)
            ratio = np.divide(visible, F[use], out=np.zeros(use.size), where=F[use] > 0)
            V[use] = np.where(free, 1.0, ratio)
            counts["lines"] += lines
            todo[use] = False
    sel = np.flatnonzero(todo)
    if sel.size:
        V[sel], counts["rays"], counts["tests"] = _point_visibility(
            elements, occluders, x[sel], n[sel], j[sel], candidates[sel], tol, shafts
        )
    return V, counts


def _facing_pairs(e, x, n, query, targets):
    """(point, element) pairs that can exchange light: both face each other by bounds."""
    c, r = e.center[targets], e.radius[targets]
    toward = c[None] - x[:, None]  # (K, T, 3)
    distance = lengths(toward)
    ok = np.einsum("kti,ki->kt", toward, n) + r[None] > 0.0
    # the element's front must face the point: exactly by its plane for flat elements, by its
    # normal cone and the cone of directions to the point for curved ones
    axis = e.solver.axis[e.index[targets]]
    flat = e.flat[targets]
    columns = np.flatnonzero(flat)
    if columns.size:
        point = e.solver.plane_point[e.index[targets[columns]]]
        height = np.einsum("kti,ti->kt", x[:, None] - point[None], axis[columns])
        ok[:, columns] &= height > 1e-9 * (r[None, columns] + distance[:, columns])
    columns = np.flatnonzero(~flat)
    if columns.size:
        half = e.solver.half_angle[e.index[targets[columns]]]
        d = distance[:, columns]
        safe = np.where(d > 0, d, 1.0)
        cos_angle = np.einsum("kti,ti->kt", -toward[:, columns], axis[columns]) / safe
        ratio = np.divide(r[None, columns], d, out=np.ones_like(d), where=d > 0)
        spread = np.arcsin(np.clip(ratio, 0, 1))
        angle = np.arccos(np.clip(cos_angle, -1.0, 1.0))
        ok[:, columns] &= angle - spread - half[None] < 0.5 * np.pi
    same = (e.geometry[targets] == query["geometry"]) & e.convex[targets]
    ok &= ~(same & (query["outward"] | e.outward[targets]))[None]
    k, t = np.nonzero(ok)
    return k, targets[t]


def _point_factors(e, x, n, j, tol):
    """F(x -> j), points nudged off their surface by 1e-9 of the element size (edge terms)."""
    return point_to_element(e, nudged(e, x, n, j), n, j, tol, exact_polygons=False)


def _point_visibility(e, occluders, x, n, j, candidates, tol, shafts=None):
    """Kernel-weighted unblocked fraction of point-to-element pairs: 2 x 2 rays, refined if partial.
    Nodes on a target's covered part (`ShaftTest.free_nodes`) count as blocked: that part sends
    nothing (a pair's visibility holds the same share, `free_share`)."""
    V = np.ones(len(x))
    rays = tests = 0
    todo = np.flatnonzero(candidates.any(1))
    for m in (2, 4) + ((8,) if tol < 1e-3 else ()) + ((16,) if tol < 1e-5 else ()):
        if todo.size == 0:
            break
        y, normal, w = element_nodes(e, j[todo], 1, m)
        weight = kernel(x[todo, None], n[todo, None], y, normal) * w
        q = y.shape[1]
        origins = np.repeat(x[todo], q, axis=0)
        ray_pair = np.repeat(np.arange(todo.size), q)
        blocked, t = blocked_rays(occluders, origins, y.reshape(-1, 3), candidates[todo], ray_pair)
        blocked = blocked.reshape(-1, q)
        if shafts is not None:
            blocked |= ~shafts.free_nodes(y, j[todo])
        v = unblocked_fraction(weight, blocked)
        V[todo] = v
        rays += todo.size * q
        tests += t
        todo = todo[(v > 0.0) & (v < 1.0)]
    return V, rays, tests
