"""Exact totals for sampled visibility in enclosures.

Visibility is sampled by rays (`visibility.pair_visibility`), so a partly blocked pair's factor
carries a sampling error, and in a closed scene the rows of F no longer sum to 1 exactly. This
module restores the row totals that can be known exactly.

Along a ray leaving a point x inside a closed, consistently oriented enclosure, the surfaces it
crosses alternate: it hits a front side first (what x sees), and every front side further on is
reached only after crossing a back side (leaving the solid in front of it). So, counting
crossings weighted by the projected solid angle,

    sum_j F(x -> j) - sum_k F(x -> back of k) = 1,    blocked(x) = sum_k F(x -> back of k),

where F are the exact unoccluded factors to front and back sides and blocked(x) is what occlusion
removes from x's row. Surfaces that do not occlude (`Scene.add(..., occluder=False)`) are
transparent to rays, so they take no part: rows, pairs and sums here run over occluders only.
Both sides are exact contour integrals. Where the first identity holds for an element (its
signed row sum is 1 to the tolerance), the element is enclosed, and the sampled blocked amounts of
its partly blocked pairs are scaled so that its blocked total is the exact one. The scaling is
symmetric (d_a d_b on pair a-b), so reciprocity A_a F_ab = A_b F_ba is kept, and fully blocked or
unblocked pairs are left as they are.

A two-sided object's elements come in twins (front and back of one sheet). Each sheet counts
once in the identity, oriented by its front, and its back is its twin: the signed sum runs over
front halves and one-sided elements. A row then also sees the back halves in its unoccluded sum,
so its blocked total is sum_k F(x -> back of one-sided k) + 2 sum_k F(x -> back half k). A
two-sided sheet's orientation is a choice, so the identity is also tried with every two-sided
sheet turned over (by its back half, whose back is the front half): a room of two-sided walls
whose normals face out of it (Blender's cube) is enclosed that way. One-sided sheets whose fronts
face out of the enclosure break the identity, and their rows are left alone.
Outside enclosures (open scenes, one-sided cards floating in a room: signed row sums other than
1) nothing changes.
"""

import numpy as np

from .bounds import FULL, HIDDEN, unit_vectors
from .transport import element_nodes, point_to_element

ENCLOSURE_SLACK = 4.0  # signed row sums within this times tol of 1 mark enclosed elements
MAX_SLACK = 0.02  # (and never further from 1 than this)
MAX_SCALE = 4.0  # rows needing their partial pairs' blocked amounts scaled by more are left alone
ITERATIONS = 200


def back_candidates(elements, a, k):
    """Whether the back side of element k can be seen from element a's front (bounds), shape (P,).

    Parameters
    ----------
    elements : Elements
    a, k : ndarray of int, shape (P,)
    """
    solver = elements.solver
    ia, ik = elements.index[a], elements.index[k]
    a_faces_k, k_faces_a = solver.visibility(ia, ik)
    # a's front toward k, and some of k turned away from a
    alive = (a_faces_k != HIDDEN) & (k_faces_a != FULL) & (a != k)
    # a convex solid's outside never sees its own inside, nor its inside its outside
    same_convex = (elements.geometry[a] == elements.geometry[k]) & elements.convex[a]
    alive &= ~(same_convex & (elements.outward[a] | ~elements.outward[k]))
    alive &= elements._plane_sees(a, k)
    # a flat k shows its back only to points behind its plane
    sel = np.flatnonzero(alive & elements.flat[k])
    if sel.size:
        axis = solver.axis[elements.index[k[sel]]]
        point = solver.plane_point[elements.index[k[sel]]]
        lowest, _ = elements.heights(a[sel], point, axis)
        slack = 1e-9 * (elements.radius[a[sel]] + elements.radius[k[sel]])
        alive[sel] = lowest < -slack
    return alive


def signed_sums_at_centres(elements, backs, rows, sheets, twin, tol, budget=2_000_000):
    """sum_k F(x -> k) - sum_k F(x -> back of k) over sheets k, at the centre x of each row
    element (its one-point Gauss node), shape (rows.size,).

    An enclosed element is enclosed at every point, so a centre whose signed sum is far from 1
    rules its element out at the cost of one point instead of a whole outer rule. A pre-filter:
    far flat targets take a low-order Gauss rule instead of their exact contour (to `tol`).

    Parameters
    ----------
    elements : Elements
    backs : Elements or None
        The same elements flipped (`backs[k]` is the back of `elements[k]`); needed only for
        sheets without a twin.
    rows : ndarray of int, shape (R,)
    sheets : ndarray of bool, shape (N,)
        Elements that take part, each sheet of surface once (occluders; one side of two-sided
        objects).
    twin : ndarray of int, shape (N,)
        The element that is the back of each element (the other side of a two-sided object), or
        -1 where the back is `backs[k]`.
    """
    N = len(elements)
    x, normal, _ = element_nodes(elements, rows, 1, 1)
    n, _ = unit_vectors(normal[:, 0])
    x = x[:, 0] + 1e-9 * elements.radius[rows, None] * n  # (just off the surface, as in the gather)
    out = np.zeros(rows.size)
    step = max(1, budget // N)
    for start in range(0, rows.size, step):
        part = np.arange(start, min(start + step, rows.size))
        local = np.repeat(part, N)
        a, k = rows[local], np.tile(np.arange(N), part.size)
        front = np.flatnonzero(sheets[k] & elements.live(a, k))
        F, _ = point_to_element(
            elements, x[local[front]], n[local[front]], k[front], tol, exact_polygons=False
        )
        out += np.bincount(local[front], F, rows.size)
        # backs that are twins: elements themselves
        paired = np.flatnonzero(sheets[k] & (twin[k] >= 0))
        paired = paired[elements.live(a[paired], twin[k[paired]])]
        B, _ = point_to_element(
            elements, x[local[paired]], n[local[paired]], twin[k[paired]], tol, exact_polygons=False
        )
        out -= np.bincount(local[paired], B, rows.size)
        # the other backs: flipped copies
        single = np.flatnonzero(sheets[k] & (twin[k] < 0))
        if single.size:
            single = single[back_candidates(elements, a[single], k[single])]
            B, _ = point_to_element(
                backs, x[local[single]], n[local[single]], k[single], tol, exact_polygons=False
            )
            out -= np.bincount(local[single], B, rows.size)
    return out


def row_sums(values, i, j, N):
    """Row sums of a symmetric matrix stored as unordered pairs (i <= j), shape (N,)."""
    off = i != j
    return np.bincount(i, values, N) + np.bincount(j[off], values[off], N)


def balance_blocked(G, V, i, j, target, fixed=None):
    """Visibilities whose blocked amounts meet exact row totals where those are known.

    Parameters
    ----------
    G : ndarray, shape (P,)
        A_i F_ij of unordered pairs (i <= j), unoccluded.
    V : ndarray, shape (P,)
        Sampled visibilities.
    i, j : ndarray of int, shape (P,)
    target : ndarray, shape (N,)
        Exact blocked total of each element's row, sum_j A_i F_ij (1 - V_ij); NaN where unknown.
    fixed : ndarray of bool, shape (P,), optional
        Pairs whose V is kept as given (exact ones): they count in the totals, are not rescaled.

    Returns
    -------
    V : ndarray, shape (P,)
        Balanced visibilities (partly blocked pairs of rows with a target rescaled).
    rows : int
        Rows whose totals now match their targets.
    """
    N = target.size
    known = np.isfinite(target)
    blocked = G * (1.0 - V)
    partial = (V > 0.0) & (V < 1.0) & (G > 0.0) & (known[i] | known[j])
    if fixed is not None:
        partial &= ~fixed
    fixed = row_sums(np.where(partial, 0.0, blocked), i, j, N)
    b, pi, pj = blocked[partial], i[partial], j[partial]
    want = np.where(known, target - fixed, np.nan)
    have = row_sums(b, pi, pj, N)
    # rows that can be balanced: a positive remainder within reach of their partial pairs
    ratio = np.divide(want, have, out=np.full(N, np.nan), where=known & (have > 0))
    free = (ratio > 1.0 / MAX_SCALE**2) & (ratio < MAX_SCALE**2)
    if not free.any():
        return V, 0
    d = np.ones(N)
    for _ in range(ITERATIONS):
        r = row_sums(b * d[pi] * d[pj], pi, pj, N)
        step = np.sqrt(np.divide(want, r, out=np.ones(N), where=free & (r > 0)))
        d = np.where(free, np.clip(d * step, 1.0 / MAX_SCALE, MAX_SCALE), 1.0)
        if np.abs(step[free] - 1.0).max() < 1e-13:
            break
    out = V.copy()
    scaled = b * d[pi] * d[pj]
    out[partial] = np.clip(1.0 - scaled / G[partial], 0.0, 1.0)
    return out, int(free.sum())
