"""Row totals of a hierarchy's enclosed leaves: the hierarchy's form of `closure`.

Inside a closed, consistently oriented enclosure of occluding surfaces, what a point sees of them
adds up to 1: the unoccluded factors to their fronts, less those to their backs, sum to 1, and
occlusion removes exactly the backs (`closure`, module docstring). A leaf whose area-averaged
signed sum over the surfaces (the trees' roots) is 1 to within ENCLOSURE_SLACK tol is enclosed,
and the row its links carry from occluding sources must total that sum. Each link's shape and sampled
visibility errors stay in that row otherwise (a white furnace shows them at once); the solve
scales an enclosed leaf's row from occluding sources to it (`hsolve.HierarchicalSystem`), as all
pairs balances an enclosed row's blocked total (`closure.balance_blocked`).
"""

import numpy as np

from .closure import ENCLOSURE_SLACK, MAX_SLACK, back_candidates
from .elements import Elements
from .transport import nudged, point_to_element

LEAF_BLOCK = 2048  # leaves whose signed sums are computed at once (bounded memory)
# the signed sums cost leaves x roots point factors: past this many trees (a mesh is one tree per
# flat piece until clusters exist) no leaf is balanced
MAX_ROOTS = 256


def enclosed_leaves(hierarchy, estimator, occluding, tol):
    """The row total of the leaves enclosed by the occluding surfaces, NaN elsewhere, shape (M,):
    the signed sum itself (1 to the slack; a leaf that sees a sliver of an opening keeps that
    sliver out of its total: rays through an opening cross no surface and count 0 in it).

    Parameters
    ----------
    hierarchy : hierarchy.Hierarchy
    estimator : refine.LinkEstimator
        Its `sample_points` give each leaf's Gauss points.
    occluding : ndarray of bool, shape (M,)
        Nodes on occluding surfaces.
    tol : float

    With more than MAX_ROOTS occluding trees nothing is marked (all NaN).
    """
    h = hierarchy
    e = h.elements
    leaves = np.flatnonzero((h.child_count == 0) & occluding)
    roots = h.roots[occluding[h.roots]]
    out = np.full(len(h), np.nan)
    if leaves.size == 0 or roots.size == 0 or roots.size > MAX_ROOTS:
        return out
    backs = Elements([e.surfaces[k].flipped() for k in roots], e.owner[roots])
    signed = np.concatenate(
        [
            _signed_sums(e, backs, estimator, leaves[start : start + LEAF_BLOCK], roots, tol)
            for start in range(0, leaves.size, LEAF_BLOCK)
        ]
    )
    slack = np.minimum(ENCLOSURE_SLACK * tol * np.abs(signed), MAX_SLACK) + 1e-12
    enclosed = np.abs(signed - 1.0) <= slack
    out[leaves[enclosed]] = signed[enclosed]
    return out


def _signed_sums(e, backs, estimator, leaves, roots, tol):
    """Area mean over each leaf of sum_k F(x -> front of root k) - F(x -> back of root k),
    shape (leaves.size,) (`backs[k]` is root k flipped)."""
    X, N, weight = estimator.sample_points(leaves)
    q = weight.shape[1]
    total = weight.sum(1)
    signed = np.zeros(leaves.size)
    for k, root in enumerate(roots):
        root_of = np.full(leaves.size, root)
        for side, alive in ((1.0, e.live(leaves, root_of)), (-1.0, back_candidates(e, leaves, root_of))):
            sel = np.flatnonzero(alive)
            if sel.size == 0:
                continue
            rows = (sel[:, None] * q + np.arange(q)[None]).ravel()
            x = nudged(e, X[rows], N[rows], np.full(rows.size, root))
            target, index = (e, np.full(rows.size, root)) if side > 0 else (backs, np.full(rows.size, k))
            F, _ = point_to_element(target, x, N[rows], index, tol, exact_polygons=False)
            signed[sel] += side * (weight[sel] * F.reshape(-1, q)).sum(1) / total[sel]
    return signed
