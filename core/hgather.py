"""Gathering at points through the hierarchy: `radiosity_at` at a cost that grows with the links
of one leaf, not with the number of patches.

A point x of leaf l receives what the links into l and into l's ancestors carry (the push of
`hsolve`, point by point): sum over those links of F(x -> s) V(x, s) B_s, with the point factor
F(x -> s) exact (`transport.point_to_element`, the kernel the links were built from) instead of
the link's quadratic (sources close to the point replaced by their children, down to leaves),
and V(x, s) = 1 for links with nothing in their shaft, else the point's own
visibility of s (`pointgather.point_visibility`: exact shadows where the kinds allow, rays
elsewhere). The source's radiosity is its area mean B_s, whose error against the true
distribution over s the refinement oracle bounds for the receiver (`refine`).
"""

import numpy as np

from . import ragged
from .bounds import FULL, lengths
from .pointgather import nudged, point_visibility
from .transport import point_to_element

NEAR_RATIO = 0.5  # sources larger than this times their distance from a point are split for it
PAIR_BUDGET = 200_000  # (point, link source) pairs gathered at once


class LinkGather:
    """The light arriving at points of a hierarchy's leaves from its links.

    Parameters
    ----------
    hierarchy : hierarchy.Hierarchy
    links : links.Links
    estimator : refine.LinkEstimator
        The link kernels' context: occluders, shafts, exact shadows and tol.
    B : ndarray, shape (M, 3)
        Node radiosities of the solve to gather from.
    node_of : ndarray of int, shape (N,)
        The node of every scene element (a user patch: a leaf, or the root of its sub-patches).
    ancestors : ndarray of int, shape (M, levels)
        Each node and its ancestors (-1 past the root).
    emitting : ndarray of bool, shape (M,)
        Nodes with an emitting part: sphere-patch sources get exact shadows only if they emit
        (as the all-pairs gather's exact shadows go toward emitters: a patch's lines cost ~10x a
        whole sphere's closed form).
    """

    def __init__(self, hierarchy, links, estimator, B, node_of, ancestors, emitting):
        self.hierarchy = hierarchy
        self.estimator = estimator
        self.B = np.array(B, dtype=np.float64, copy=True)
        self.node_of = node_of
        self.ancestors = ancestors
        shadows = estimator.shadows
        self.exact_source = emitting | (~shadows.patch_target if shadows is not None else True)
        # links by receiver (CSR): links into node m are rows start[m] .. start[m + 1] - 1
        order = np.argsort(links.receiver, kind="stable")
        self.source = links.source[order]
        self.full = links.visibility[order] == FULL
        self.start = np.searchsorted(links.receiver[order], np.arange(len(hierarchy) + 1))

    def _near_leaves(self, x, p, s, full):
        """Sources seen from near by their point (the source's bounding radius above NEAR_RATIO
        times its distance) replaced by their children, down to leaves: the link was judged for
        the receiver's mean, and close to a point the kernel varies over the source more than
        over the receiver. Returns the points, sources and FULL flags (a child of an empty shaft
        is in an empty shaft)."""
        h = self.hierarchy
        e = h.elements
        while True:
            split = (h.child_count[s] > 0) & (e.radius[s] > NEAR_RATIO * lengths(x[p] - e.center[s]))
            if not split.any():
                return p, s, full
            position, child = h.children(s[split])
            p = np.concatenate([p[~split], p[split][position]])
            full = np.concatenate([full[~split], full[split][position]])
            s = np.concatenate([s[~split], child])

    def __call__(self, x, n, home, owner, outward):
        """Arriving radiance sum_links F(x -> s) V(x, s) B_s at points, shape (K, 3).

        Parameters
        ----------
        x, n : ndarray, shape (K, 3)
            Points on their leaves and unit normals.
        home : ndarray of int, shape (K,)
            Scene element holding each point.
        owner : ndarray of int, shape (K,)
            Scene object of each point.
        outward : ndarray of bool, shape (K,)

        Returns
        -------
        arriving : ndarray, shape (K, 3)
        counts : dict
            "evaluations", "rays", "lines", "pairs".
        """
        # points in chunks of at most PAIR_BUDGET (point, link) pairs: memory stays bounded
        # the leaf holding each point (below its patch where the patch has sub-patches)
        nodes = self.ancestors[self.hierarchy.descend(self.node_of[home], x)]  # (K, levels)
        valid = nodes >= 0
        safe = np.where(valid, nodes, 0)
        per_point = np.where(valid, self.start[safe + 1] - self.start[safe], 0).sum(1)
        ends = np.searchsorted(
            np.cumsum(per_point), np.arange(1, 1 + per_point.sum() // PAIR_BUDGET) * PAIR_BUDGET
        )
        bounds = np.unique(np.r_[0, np.minimum(ends + 1, len(x)), len(x)])
        arriving = np.zeros((len(x), 3))
        counts = dict(evaluations=0, rays=0, lines=0, pairs=0)
        for a, b in zip(bounds[:-1], bounds[1:]):
            part = slice(a, b)
            arriving[part], c = self._gather(x[part], n[part], nodes[part], owner[part], outward[part])
            for key in counts:
                counts[key] += c[key]
        return arriving, counts

    def _gather(self, x, n, nodes, owner, outward):
        """`__call__` for points whose leaf and ancestors are `nodes` (K, levels)."""
        e, est = self.hierarchy.elements, self.estimator
        point = np.repeat(np.arange(len(x))[:, None], nodes.shape[1], 1)[nodes >= 0]
        node = nodes[nodes >= 0]
        count = self.start[node + 1] - self.start[node]
        p = np.repeat(point, count)
        _, row = ragged.expand(self.start[node], count)
        p, s, full = self._near_leaves(x, p, self.source[row], self.full[row])
        F, evaluations = point_to_element(e, nudged(e, x[p], n[p], s), n[p], s, est.tol, exact_polygons=False)
        counts = dict(evaluations=evaluations, rays=0, lines=0, pairs=p.size)
        shadowed = np.flatnonzero(~full & (F > 0))
        if shadowed.size:
            q = p[shadowed]
            V, c = point_visibility(
                e,
                est.occluders,
                est.shafts,
                est.shadows,
                x[q],
                n[q],
                dict(owner=owner[q], outward=outward[q]),
                s[shadowed],
                F[shadowed],
                est.tol,
                exact_allowed=self.exact_source[s[shadowed]],
            )
            F[shadowed] *= V
            counts["rays"], counts["lines"] = c["rays"], c["lines"]
        arriving = np.stack([np.bincount(p, F * self.B[s, c], minlength=len(x)) for c in range(3)], 1)
        return arriving, counts
