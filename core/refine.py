"""The refinement oracle of hierarchical radiosity: link estimates, their error, and BF refinement.

BF refinement (Hanrahan, Salzman & Aupperle 1991, section 4.2): a link (r <- s) stays if the
light error it can make in the receiver, rho_r B_s times the uncertainty of its factor, is small;
otherwise the larger end (by bounding radius) is split and its children are linked instead. The
factor's uncertainty follows Holzschuch & Sillion 1998 ("An exhaustive error-bounding algorithm
for hierarchical radiosity", Computer Graphics Forum 17(4)): the link transports a constant
F(r -> s) V B_s where the exact transfer at a point x of r is F(x -> s) V(x, s) B_s(y), so the
error has three parts, each estimated here from samples rather than bounded analytically:

- factor shape: the link carries F(x -> s) over r as a quadratic in r's parameters, fitted (least
  squares) to the exact point-to-node factor (`transport.point_to_element`, exact contour
  integrals where the kind has them) at SAMPLE_ORDER^2 Gauss nodes of r and shifted so that its
  mean is the exact area average F(r -> s); its error is the largest residual at the nodes;
- visibility: a link whose shaft holds an occluder and whose sampled visibility is below 1 may
  be off by up to max_x F(x -> s) (the whole transfer);
- source variation: F V times the spread of B over s's children (B is constant per leaf);
- near links (bounding spheres that overlap: adjacent walls, contacts) have kernels that peak
  between the sample points, so they are split whatever the samples say, down to the leaves.

Error reference (`reference`): "receiver" compares with tol x the receiver's own radiosity (floored at
REFERENCE_FLOOR times the scene's area-mean B) times the link's share of the light the receiver
gathers (at least SHARE_FLOOR), so that the errors of all links into a receiver add up to about
tol of its radiosity and deep shadows are resolved to tol of their own light; "scene" compares
with tol x the scene's area-mean B (cheaper; dark receivers get an absolute error). The first
pass, before any solve, uses the ambient estimate of Cohen, Chen, Wallace & Greenberg 1988 ("A
progressive refinement approach to fast radiosity image generation", SIGGRAPH '88):
B ~ E + rho * (area-mean E) / (1 - area-mean rho).
"""

import numpy as np

from .bounds import FULL, HIDDEN, PARTIAL, lengths, unit_vectors
from .occluded import ExactShadows
from .transport import (
    CANDIDATE_BUDGET,
    ShaftTest,
    exact_pair_visibility,
    pair_form_factors,
    pair_visibility,
    point_to_element,
)

SAMPLE_ORDER = 4  # receiver sample points per parameter for the factor's quadratic (Gauss nodes)
REFERENCE_FLOOR = 1e-3  # receivers darker than this times the scene's mean B are held to it
SHARE_FLOOR = 0.25  # a link's error budget: tol x B_r x max(its share of r's light, this)
REFERENCES = ("receiver", "scene")


class LinkEstimator:
    """Exact factor, visibility and factor variation of node pairs (the kernels of `transport`).

    Parameters
    ----------
    hierarchy : hierarchy.Hierarchy
    occluders : occlusion.Occluders or None
    occluder_object : ndarray of int, shape (O,)
        Scene object of each occluder.
    tol : float
    occlusion : False, "direct", "sampled" or "exact" ("direct" samples, as "sampled")
        As `Scene.solve`'s pair visibility: none, rays, or exact shadows where supported.
    """

    def __init__(self, hierarchy, occluders, occluder_object, tol, occlusion):
        self.hierarchy = hierarchy
        self.tol = tol
        self.occlusion = occlusion
        e = hierarchy.elements
        self.occluders = occluders
        self.shafts = (
            ShaftTest(e, occluders, occluder_object) if (occlusion and occluders is not None) else None
        )
        self.exact = (
            ExactShadows(e.surfaces, occluders.surfaces)
            if (occlusion == "exact" and occluders is not None)
            else None
        )
        self.evaluations = 0
        # Gauss nodes on [-1, 1]^2 and the least-squares map from values there to a quadratic
        t, w = np.polynomial.legendre.leggauss(SAMPLE_ORDER)
        tu, tv = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
        self.weights = np.outer(w, w).ravel()
        self.nodes = (tu, tv)
        self.basis = np.stack([np.ones_like(tu), tu, tv, tu * tu, tv * tv, tu * tv], 1)  # (q, 6)
        self.fit = np.linalg.pinv(self.basis)  # (6, q)

    def evaluate(self, r, s):
        """Sampled link columns (see `links.Links`) for receivers r and sources s, each shape (K,).

        F is the Gauss rule over the receiver's sample nodes, V = 1 and the class FULL: the
        oracle's first look. `visibility` and `exact_factors` complete the links it keeps.
        """
        e, tol = self.hierarchy.elements, self.tol
        # the point-to-source factor at Gauss nodes of the receiver (nudged off it, as a gather)
        box = e.solver.set.boxes[e.index[r]]  # (K, 4): u0, u1, v0, v1
        tu, tv = self.nodes
        u = 0.5 * (box[:, :1] + box[:, 1:2]) + 0.5 * (box[:, 1:2] - box[:, :1]) * tu[None]
        v = 0.5 * (box[:, 2:3] + box[:, 3:4]) + 0.5 * (box[:, 3:4] - box[:, 2:3]) * tv[None]
        q = tu.size
        X, normal = e.solver.set.evaluate(np.repeat(e.index[r], q), u.ravel(), v.ravel())
        N, _ = unit_vectors(normal)
        S = np.repeat(s, q)
        nudge = 1e-9 * (e.radius[S] + lengths(X - e.center[S]))
        Fx, count2 = point_to_element(e, X + nudge[:, None] * N, N, S, tol, exact_polygons=False)
        Fx = Fx.reshape(-1, q)
        self.evaluations += count2
        # the area-weighted Gauss rule over the receiver, and the least-squares quadratic with
        # that mean; its residual at the nodes is the error
        weight = self.weights[None] * lengths(normal).reshape(-1, q)
        F = (weight * Fx).sum(1) / np.maximum(weight.sum(1), 1e-300)
        shape = Fx @ self.fit.T
        shape[:, 0] += F - (shape[:, 0] + (shape[:, 3] + shape[:, 4]) / 3.0)
        residual = np.abs(Fx - shape @ self.basis.T).max(1)
        V = np.ones(r.size)
        visibility = np.full(r.size, FULL, dtype=np.int8)
        return dict(
            receiver=r,
            source=s,
            F=F,
            V=V,
            visibility=visibility,
            variation=residual,
            peak=Fx.max(1),
            shape=shape,
        )

    def exact_factors(self, columns):
        """The links' F from the exact pair kernels (`transport.pair_form_factors`), the quadratic's
        mean moved to it and the move added to its error (columns changed in place)."""
        e, r, s = self.hierarchy.elements, columns["receiver"], columns["source"]
        # outer rule over the end whose partner has an exact inner integral, else the smaller one
        exact = e.solver.exact_inner[e.solver.slot]
        outer_r = np.where(exact[r] != exact[s], exact[s], e.radius[r] <= e.radius[s])
        a, b = np.where(outer_r, r, s), np.where(outer_r, s, r)
        F_ab, count = pair_form_factors(e, a, b, self.tol)
        self.evaluations += count
        F = np.where(outer_r, F_ab, F_ab * e.area[s] / e.area[r])
        shift = F - columns["F"]
        columns["shape"][:, 0] += shift
        columns["variation"] += np.abs(shift)
        columns["F"] = F
        return columns

    def visibility(self, columns):
        """The links' V and visibility class (columns changed in place)."""
        if self.shafts is not None and columns["receiver"].size:
            r, s = columns["receiver"], columns["source"]
            columns["V"], columns["visibility"] = self._visibility(r, s, columns["F"], self.hierarchy.area)
        return columns

    def _visibility(self, r, s, F, area):
        """V and the visibility class of node pairs."""
        tol = self.tol
        chunk = max(256, CANDIDATE_BUDGET // max(self.shafts.M, 1))
        shadowed = np.concatenate(
            [
                self.shafts.candidates(r[k : k + chunk], s[k : k + chunk]).any(1)
                for k in range(0, r.size, chunk)
            ]
        )
        V = np.ones(r.size)
        todo = np.flatnonzero(shadowed)
        if self.exact is not None and todo.size:
            Vx, _ = exact_pair_visibility(
                self.hierarchy.elements, self.exact, self.shafts, r[todo], s[todo], tol
            )
            found = np.isfinite(Vx)
            V[todo[found]] = Vx[found]
            todo = todo[~found]
        if todo.size:
            weight = np.maximum(F[todo], F[todo] * area[r[todo]] / area[s[todo]])
            V[todo], _, _ = pair_visibility(
                self.hierarchy.elements, self.occluders, self.shafts, r[todo], s[todo], tol, weight
            )
        visibility = np.where(~shadowed | (V >= 1.0), FULL, np.where(V <= 0.0, HIDDEN, PARTIAL))
        # the first rays of a link between larger nodes (2 x 2 points each end) can miss an occluder
        # in its shaft, or miss a gap: such links count as partial (refined if their light shows)
        coarse = (self.hierarchy.child_count[r] > 0) | (self.hierarchy.child_count[s] > 0)
        visibility = np.where(shadowed & coarse, PARTIAL, visibility)
        return V, visibility.astype(np.int8)


class Oracle:
    """Which links carry too large an error (BF refinement), and which end to split.

    Parameters
    ----------
    hierarchy : hierarchy.Hierarchy
    rho : ndarray, shape (M, 3)
        Reflectance of every node.
    E : ndarray, shape (M, 3)
        Emission (with direct light) at the leaves (inner rows are ignored).
    tol : float
    reference : {"receiver", "scene"}
        What the error is relative to (see the module docstring).
    """

    def __init__(self, hierarchy, rho, E, tol, reference="receiver"):
        if reference not in REFERENCES:
            raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
        self.hierarchy = hierarchy
        self.rho = rho
        self.E = hierarchy.pull(E)
        self.tol = tol
        self.reference = reference

    def allowed(self, B):
        """tol times the reference radiosity of every node, shape (M, 3)."""
        h = self.hierarchy
        roots = h.roots
        mean = (h.area[roots, None] * B[roots]).sum(0) / max(h.area[roots].sum(), 1e-300)
        if self.reference == "scene":
            return np.broadcast_to(self.tol * mean, B.shape)
        return self.tol * np.maximum(B, REFERENCE_FLOOR * mean[None])

    def exceeds(self, r, s, columns, B, allowed, spread):
        """Links whose error estimate exceeds the allowance of their receiver, shape (K,) bool.

        Parameters
        ----------
        r, s : ndarray of int, shape (K,)
        columns : dict or links.Links
            "F", "V", "visibility", "variation", "peak" of the links.
        B, allowed, spread : ndarray, shape (M, 3)
            Node radiosities, `allowed(B)`, and each node's spread of B over its children.
        """
        get = columns.__getitem__ if isinstance(columns, dict) else lambda k: getattr(columns, k)
        e = self.hierarchy.elements
        near = lengths(e.center[r] - e.center[s]) <= e.radius[r] + e.radius[s]
        uncertain = np.where(get("visibility") != FULL, get("peak"), 0.0)
        factor_error = np.minimum(get("variation") + uncertain, np.maximum(get("peak"), get("F")))
        transfer = get("F") * get("V")
        light = self.rho[r] * B[s]
        error = light * factor_error[:, None] + self.rho[r] * transfer[:, None] * spread[s]
        if self.reference == "receiver":
            gathered = np.maximum(B[r] - self.E[r], 1e-300)
            share = np.clip(light * np.maximum(transfer, factor_error)[:, None] / gathered, SHARE_FLOOR, 1.0)
            return near | np.any(error > allowed[r] * share, axis=1)
        return near | np.any(error > allowed[r], axis=1)

    def split(self, r, s):
        """Which end of each link to split: 0 receiver, 1 source, -1 neither (both leaves)."""
        h = self.hierarchy
        radius = h.elements.radius
        r_ok, s_ok = h.child_count[r] > 0, h.child_count[s] > 0
        source = s_ok & (~r_ok | (radius[s] > radius[r]))
        return np.where(source, 1, np.where(r_ok, 0, -1))


def ambient_estimate(hierarchy, rho, E_leaf):
    """First radiosity estimate per node from the ambient term (Cohen et al. 1988), shape (M, 3).

    B ~ E + rho * A, A = (area-mean E) / (1 - area-mean rho), over the leaves.
    """
    leaf = hierarchy.child_count == 0
    area = hierarchy.area[leaf, None]
    total = area.sum()
    mean_E = (area * E_leaf[leaf]).sum(0) / total
    mean_rho = (area * rho[leaf]).sum(0) / total
    ambient = mean_E / np.maximum(1.0 - mean_rho, 1e-3)
    return hierarchy.pull(np.where(leaf[:, None], E_leaf + rho * ambient[None], 0.0))


class Refinement:
    """BF refinement of a link set: split links whose error exceeds tol until all are accepted.

    Parameters
    ----------
    estimator : LinkEstimator
    links : links.Links
        Accepted links (grown in place).
    run : object with `blocks(name, work, items)` and `count(**counts)`
        The scene's runner (threads, progress, cancel).
    """

    def __init__(self, estimator, links, run):
        self.estimator = estimator
        self.hierarchy = estimator.hierarchy
        self.links = links
        self.run = run
        self.evaluated = 0
        self.rounds = 0

    def root_pairs(self):
        """Pairs of tree roots that can exchange light (bounds), shapes (K,) and (K,)."""
        roots = self.hierarchy.roots
        r, s = np.meshgrid(roots, roots, indexing="ij")
        r, s = r.ravel(), s.ravel()
        alive = self.hierarchy.elements.live(r, s)
        return r[alive], s[alive]

    def recheck(self, oracle, B):
        """Remove accepted links that now exceed their allowance; return their children pairs."""
        links = self.links
        if len(links) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        allowed = oracle.allowed(B)
        spread = self.hierarchy.spread(B)
        bad = oracle.exceeds(links.receiver, links.source, links, B, allowed, spread)
        end = oracle.split(links.receiver, links.source)
        bad &= end >= 0
        rows = np.flatnonzero(bad)
        r, s, end = links.receiver[rows], links.source[rows], end[rows]
        links.remove(rows)
        return self._children(r, s, end)

    def refine(self, oracle, B, r, s):
        """Evaluate candidate links (r <- s), accept or split them until none is left."""
        allowed = oracle.allowed(B)
        spread = self.hierarchy.spread(B)
        estimator = self.estimator
        while r.size:
            self.rounds += 1
            self.evaluated += r.size
            # sampled factors first: links that fail on them are split without rays or exact F
            columns = self._map(lambda c: estimator.evaluate(c["receiver"], c["source"]), r, s)
            end = oracle.split(r, s)
            bad = oracle.exceeds(r, s, columns, B, allowed, spread) & (end >= 0)
            rest = np.flatnonzero(~bad)
            if rest.size:
                kept = self._map(estimator.visibility, **{k: v[rest] for k, v in columns.items()})
                again = oracle.exceeds(r[rest], s[rest], kept, B, allowed, spread) & (end[rest] >= 0)
                bad[rest[again]] = True
                ok = np.flatnonzero(~again)
                kept = self._map(estimator.exact_factors, **{k: v[ok] for k, v in kept.items()})
                keep = kept["F"] > 0
                self.links.append(**{k: v[keep] for k, v in kept.items()})
            r, s = self._children(r[bad], s[bad], end[bad])

    def _map(self, work, receiver, source, **columns):
        """work(columns) over blocks of links in the runner's threads, columns concatenated."""
        columns = dict(receiver=receiver, source=source, **columns)
        before = self.estimator.evaluations
        if receiver.size == 0:
            return work(columns)

        def block_work(block):
            return work({k: v[block] for k, v in columns.items()})

        parts = self.run.blocks("links", block_work, np.arange(receiver.size))
        self.run.count(evaluations=self.estimator.evaluations - before)
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def _children(self, r, s, end):
        """Candidate pairs after splitting the chosen end of each link (dead pairs dropped)."""
        h = self.hierarchy
        out_r, out_s = [], []
        for which, (keep, other) in ((0, (r, s)), (1, (s, r))):
            sel = np.flatnonzero(end == which)
            if sel.size == 0:
                continue
            position, child = h.children(keep[sel])
            partner = other[sel][position]
            cr, cs = (child, partner) if which == 0 else (partner, child)
            out_r.append(cr)
            out_s.append(cs)
        if not out_r:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        r, s = np.concatenate(out_r), np.concatenate(out_s)
        alive = h.elements.live(r, s)
        return r[alive], s[alive]
