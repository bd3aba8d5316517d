"""Row totals of a hierarchy's enclosed leaves: the hierarchy's form of `closure`.

Inside a closed, consistently oriented enclosure of occluding surfaces, what a point sees of them
adds up to 1: the unoccluded factors to their fronts, less those to their backs, sum to 1, and
occlusion removes exactly the backs (`closure`, module docstring). A leaf whose area-averaged
signed sum over the surfaces (the trees' roots) is 1 to within ENCLOSURE_SLACK tol is enclosed,
and the row its links carry from occluding sources must total that sum. Each link's shape and sampled
visibility errors stay in that row otherwise (a white furnace shows them at once); the solve
scales an enclosed leaf's row from occluding sources to it (`hsolve.HierarchicalSystem`), as all
pairs balances an enclosed row's blocked total (`closure.balance_blocked`).

The signed sums cost leaves x roots point factors, and under a sky most leaves (a floor between
objects, their upper sides) see too little of the scene to be enclosed. So the sums are a branch
and bound: each root's factor is bounded first (seen from a point, a root inside a ball of radius
rho at distance d covers at most the cap of half-angle alpha, sin alpha = rho / d, whose factor
is at most its solid angle over pi, 2 (1 - cos alpha), times the largest cosine over it; a flat
root at most its whole plane, (1 + cos phi) / 2 with phi the angle between the point's normal and
the way to the plane), the roots are taken largest bound first, and a leaf leaves the sum once
what it has so far plus the bounds still to come cannot reach 1 - MAX_SLACK (the backs only
subtract).

A two-sided surface is two trees (its front and its back half, `Scene`): each sheet counts once
in the identity, by its front half, whose back is the back half; counting both halves would add
each sheet's front and take it off again as the other half's back (every sum 0: nothing was ever
enclosed in a room of two-sided walls). A two-sided sheet's orientation is a choice (Cycles
renders both sides alike), so a room of two-sided walls whose normals face out (Blender's cube)
is enclosed too: the sum is taken both ways, the two-sided sheets as they are and turned over,
and a leaf is enclosed when either comes to 1.

A leaf partly under another object (a floor under a box's footprint: `coverage`) sees the
enclosure from its free part only (from under a box a segment crosses the box's back, then a
wall: 0), and its radiosity is the mean over that part (`hsolve`): the sum is its mean over the
Gauss points on the free part, and the row it balances is the one taken over the free part.
"""

import numpy as np

from .bounds import lengths
from .closure import ENCLOSURE_SLACK, MAX_SLACK, back_candidates
from .elements import Elements
from .pointgather import nudged
from .transport import point_to_element

LEAF_BLOCK = 2048  # leaves whose signed sums are computed at once (bounded memory)
# the signed sums cost leaves x roots point factors: past this many trees (a mesh is one tree per
# flat piece until clusters exist) no leaf is balanced
MAX_ROOTS = 256
REACH_MARGIN = 1e-6  # of the bound on a leaf's signed sum (its points are nudged off the surface)


ONE_SIDED, FRONT_HALF, BACK_HALF = 0, 1, 2  # what a tree is of its surface (`enclosed_leaves`)


def enclosed_leaves(hierarchy, estimator, occluding, tol, halves=None):
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
    halves : ndarray of int, shape (trees,), optional
        Per tree: ONE_SIDED, or the FRONT_HALF or BACK_HALF of a two-sided surface (default: all
        one-sided).

    With more than MAX_ROOTS occluding sheets nothing is marked (all NaN).
    """
    h = hierarchy
    e = h.elements
    leaves = np.flatnonzero((h.child_count == 0) & occluding)
    roots = h.roots[occluding[h.roots]]
    half = np.full(roots.size, ONE_SIDED) if halves is None else np.asarray(halves)[h.tree[roots]]
    # each sheet once: a two-sided surface by its front half (the back half is its back)
    roots, two_sided = roots[half != BACK_HALF], half[half != BACK_HALF] == FRONT_HALF
    out = np.full(len(h), np.nan)
    if leaves.size == 0 or roots.size == 0 or roots.size > MAX_ROOTS:
        return out
    backs = Elements([e.surfaces[k].flipped() for k in roots], e.owner[roots])
    signed = np.concatenate(
        [
            _signed_sums(e, backs, estimator, leaves[start : start + LEAF_BLOCK], roots, tol, two_sided)
            for start in range(0, leaves.size, LEAF_BLOCK)
        ]
    )
    slack = np.minimum(ENCLOSURE_SLACK * tol * np.abs(signed), MAX_SLACK) + 1e-12
    enclosed = np.abs(signed - 1.0) <= slack  # (False where NaN: a leaf left out early)
    out[leaves[enclosed]] = signed[enclosed]
    return out


def front_bounds(e, leaves, roots, X, N, weight, tol, live):
    """Upper bounds of each leaf's area mean of F(x -> front of root k) as `_signed_sums` computes
    it (a Gauss rule over the leaf, point factors to tol), shape (leaves.size, roots.size): the
    caps of the roots' bounding balls, and a flat root's whole plane (0 where `live`, shape
    (leaves.size, roots.size), says they cannot exchange light at all)."""
    q = weight.shape[1]
    total = np.maximum(weight.sum(1), 1e-300)
    out = np.zeros((leaves.size, roots.size))
    for k, root in enumerate(roots):
        alive = np.repeat(live[:, k], q)
        to = e.center[root] - X[alive]
        d = lengths(to)
        sin_alpha = np.clip(e.radius[root] / np.maximum(d, 1e-300), 0.0, 1.0)
        alpha = np.arcsin(sin_alpha)
        theta = np.arccos(np.clip(np.einsum("ki,ki->k", to, N[alive]) / np.maximum(d, 1e-300), -1.0, 1.0))
        cap = 2.0 * (1.0 - np.sqrt(1.0 - sin_alpha**2)) * np.cos(np.maximum(theta - alpha, 0.0))
        cap = np.where(sin_alpha >= 1.0, 1.0, np.clip(cap, 0.0, 1.0))
        if e.flat[root]:  # a flat root lies in its plane: (1 + cos) / 2 toward that whole plane
            axis = e.solver.axis[e.index[root]]
            axis = axis / np.linalg.norm(axis)
            side = np.sign((X[alive] - e.solver.plane_point[e.index[root]]) @ axis)
            cap = np.minimum(cap, 0.5 * (1.0 - side * (N[alive] @ axis)))
        point = np.zeros(X.shape[0])
        point[alive] = cap
        out[:, k] = (weight * point.reshape(-1, q)).sum(1) / total
    return out * (1.0 + tol) + REACH_MARGIN


def _signed_sums(e, backs, estimator, leaves, roots, tol, two_sided=None):
    """Area mean over each leaf of sum_k F(x -> front of root k) - F(x -> back of root k),
    shape (leaves.size,) (`backs[k]` is root k flipped); NaN for the leaves left out once that
    sum cannot come within MAX_SLACK of 1 (branch and bound: the roots are taken in order of their
    largest bounds, and a leaf whose sum so far plus the bounds of the roots still to come stays
    below 1 - MAX_SLACK is dropped; the backs only subtract).

    `two_sided` (shape (roots.size,), default none) marks sheets whose orientation is a choice:
    the sum is also taken with them turned over (their backs minus their fronts), and each leaf
    gets whichever of the two is nearer 1."""
    two_sided = np.zeros(roots.size, dtype=bool) if two_sided is None else np.asarray(two_sided, dtype=bool)
    X, N, weight = estimator.sample_points(leaves)
    q = weight.shape[1]
    if estimator.shafts is not None:
        # over the free part of a leaf that another object covers (`coverage`): the mean there
        # is 1 (from under a box a segment crosses the box's back, then a wall: 0)
        weight = weight * estimator.shafts.free_nodes(X.reshape(-1, q, 3), leaves)
    total = weight.sum(1)
    live = np.stack([e.live(leaves, np.full(leaves.size, root)) for root in roots], 1)
    seen_back = np.stack([back_candidates(e, leaves, np.full(leaves.size, root)) for root in roots], 1)
    # a turned-over sheet's front is its back: its bound must hold where either side is seen
    # (the caps and a plane's (1 + cos) / 2 do not depend on the side)
    bound = front_bounds(e, leaves, roots, X, N, weight, tol, live | (seen_back & two_sided[None]))
    rest = bound.sum(1)
    signed = np.zeros((2, leaves.size))  # the two-sided sheets as they are, and turned over
    going = total > 0.0
    for k in np.argsort(-bound.sum(0), kind="stable"):
        root = roots[k]
        going &= signed.max(0) + rest >= 1.0 - MAX_SLACK
        rest -= bound[:, k]
        turned = -1.0 if two_sided[k] else 1.0
        for side, alive in ((1.0, live[:, k]), (-1.0, seen_back[:, k])):
            sel = np.flatnonzero(alive & going)
            if sel.size == 0:
                continue
            rows = (sel[:, None] * q + np.arange(q)[None]).ravel()
            x = nudged(e, X[rows], N[rows], np.full(rows.size, root))
            target, index = (e, np.full(rows.size, root)) if side > 0 else (backs, np.full(rows.size, k))
            F, _ = point_to_element(target, x, N[rows], index, tol, exact_polygons=False)
            mean = (weight[sel] * F.reshape(-1, q)).sum(1) / total[sel]
            signed[0, sel] += side * mean
            signed[1, sel] += turned * side * mean
    nearer = np.where(np.abs(signed[1] - 1.0) < np.abs(signed[0] - 1.0), signed[1], signed[0])
    return np.where(going, nearer, np.nan)
