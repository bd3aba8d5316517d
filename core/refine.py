"""The refinement oracle of hierarchical radiosity: link estimates, their error, and BF refinement.

BF refinement (Hanrahan, Salzman & Aupperle 1991, section 4.2): a link (r <- s) stays if the
light error it can make in the receiver, rho_r B_s times the uncertainty of its factor, is small;
otherwise the larger end (by bounding radius) is split and its children are linked instead. The
factor's uncertainty follows Holzschuch & Sillion 1998 ("An exhaustive error-bounding algorithm
for hierarchical radiosity", Computer Graphics Forum 17(4)): the link transports a constant
F(r -> s) V B_s where the exact transfer at a point x of r is F(x -> s) V(x, s) B_s(y), so the
error has three parts, each estimated here from samples rather than bounded analytically:

- factor shape (only for receivers with children, which pass their light down: a receiver
  without children carries only its mean, the exact pair factor): the link carries F(x -> s) over
  r as a quadratic in r's parameters, fitted (least squares) to the exact point-to-node factor
  (`transport.point_to_element`) at SAMPLE_ORDER^2 Gauss nodes of r, times the point's own
  visibility of s for shadowed links (`pointgather.point_visibility`), with the exact area mean;
  its error is the largest residual at the nodes plus how far the nodes' rule is from that mean;
- visibility: a shadowed link's V may be off by its `v_error` (SAMPLED_VISIBILITY_ERROR for rays,
  measured up to 3.5e-2; the allowance asked of an exact V), times F; after a solve, the links
  whose errors could add up past half their receiver's allowance get exact V
  (`Oracle.visibility_allowance`, `Refinement._exact_visibility`), among the links that the
  occlusion mode lets have one (`Refinement.exact_ends`: all, or those with an emitting end);
- source variation: the link carries the source's mean B, and the error is the covariance of
  the kernel and B over s: at most F V times B's spread over s's children times the kernel's
  relative variation over s (`source_variation`, measured from s's Gauss nodes back to r only
  where it decides; 1 for shadowed links);
- factor: F comes from the exact pair kernels, but a kinked pair's fixed outer rule
  (`transport.kinked_pairs`: a horizon or silhouette may cross the pair) may be off by
  KINK_RULE_ERROR (measured on a ball's patches over floor cells: p95 7 %, slivers up to all of
  it), a near pair's first rule by NEAR_RULE_ERROR (`transport.rule_errors`); after a solve,
  the links whose factor errors could add up past half their receiver's allowance get F
  integrated again to their share (`transport.refined_pair_factors`,
  `Refinement._refined_factors`), as the all-pairs path does;
- near links (bounding spheres that overlap: adjacent walls, contacts) have kernels that peak
  between the sample points, so they are split whatever the samples say, down to the leaves.

Error reference (`reference`): "receiver" compares with tol x the receiver's own radiosity (floored at
REFERENCE_FLOOR times the scene's area-mean B) times the link's share of the light the receiver
gathers (at least SHARE_FLOOR), so that the errors of all links into a receiver add up to about
tol of its radiosity and deep shadows are resolved to tol of their own light (a sub-patch below
a user patch: of the larger of its own and its patch's radiosity); "scene" compares
with tol x the scene's area-mean B (cheaper; dark receivers get an absolute error). The first
pass, before any solve, uses the ambient estimate of Cohen, Chen, Wallace & Greenberg 1988 ("A
progressive refinement approach to fast radiosity image generation", SIGGRAPH '88):
B ~ E + rho * (area-mean E) / (1 - area-mean rho).
"""

import numpy as np

from .bounds import FULL, HIDDEN, PARTIAL, lengths
from .coverage import gather_scale
from .hierarchy import quadratic_basis, square_rule
from .occluded import ExactShadows
from .pointgather import nudged, point_visibility
from .transport import outer_first, pair_form_factors, point_to_element, refined_pair_factors, rule_errors
from .visibility import CANDIDATE_BUDGET, ShaftTest, exact_pair_visibility, pair_visibility

SAMPLE_ORDER = 4  # receiver sample points per parameter for the factor's quadratic (Gauss nodes)
REFERENCE_FLOOR = 1e-3  # receivers darker than this times the scene's mean B are held to it
SHARE_FLOOR = 0.25  # a link's error budget: tol x B_r x max(its share of r's light, this)
REFERENCES = ("receiver", "scene")
SAMPLED_VISIBILITY_ERROR = 0.05  # absolute error assumed of a pair's sampled V (as `scene` assumes)
MIN_VISIBILITY_ALLOWANCE = 1e-4  # the tightest absolute error asked of an exact V
MIN_FACTOR_ALLOWANCE = 1e-4  # the tightest relative error asked of a kinked pair's F


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
    coverage : coverage.Coverage, optional
        What other objects cover of each node: covering occluders block every link of the node
        they cover, and sampled visibilities count its free part only (`visibility.ShaftTest`).
    """

    def __init__(self, hierarchy, occluders, occluder_object, tol, occlusion, coverage=None):
        self.hierarchy = hierarchy
        self.tol = tol
        self.occlusion = occlusion
        e = hierarchy.elements
        self.occluders = occluders
        self.shafts = (
            ShaftTest(e, occluders, occluder_object, coverage)
            if (occlusion and occluders is not None)
            else None
        )
        # exact shadows for the points of shadowed links (and whole pairs in "exact" mode)
        self.shadows = ExactShadows(e.surfaces, occluders.surfaces) if self.shafts is not None else None
        self.exact_pairs = occlusion == "exact" and self.shadows is not None
        self.evaluations = 0
        # Gauss nodes on [-1, 1]^2 and the least-squares map from values there to a quadratic
        tu, tv, self.weights = square_rule(SAMPLE_ORDER)
        self.basis = quadratic_basis(tu, tv)  # (q, 6)
        self.fit = np.linalg.pinv(self.basis)  # (6, q)

    def sample_points(self, nodes):
        """SAMPLE_ORDER^2 Gauss points of each node (on its surface), their unit normals and area
        weights: shapes (K * q, 3), (K * q, 3) and (K, q)."""
        return self.hierarchy.rule(nodes, SAMPLE_ORDER)

    def _point_factors(self, X, N, targets):
        """F(x -> target) at points (K * q,) on their surface (`pointgather.nudged` off it)."""
        e = self.hierarchy.elements
        F, count = point_to_element(e, nudged(e, X, N, targets), N, targets, self.tol, exact_polygons=False)
        self.evaluations += count
        return F

    def _fit(self, nodes, values, weight, mean=None):
        """Quadratic over each node (least squares at its Gauss points) with the given area mean
        (the Gauss rule's by default): (mean (K,), coefficients (K, 6), max residual (K,))."""
        rule = (weight * values).sum(1) / np.maximum(weight.sum(1), 1e-300)
        mean = rule if mean is None else mean
        shape = values @ self.fit.T
        shape[:, 0] += mean - np.einsum("kc,kc->k", shape, self.hierarchy.moments[nodes])
        return rule, shape, np.abs(values - shape @ self.basis.T).max(1)

    def evaluate(self, r, s):
        """Sampled link columns (see `links.Links`) for receivers r and sources s, each shape (K,).

        V = 1 and the class FULL: the oracle's first look. A receiver without children gets the
        exact pair factor as a constant (column "exact" True); one with children the quadratic
        fitted to F(x -> s) at its Gauss points, whose rule gives F until `exact_factors`; the
        column "samples" (K, q) holds those values for `visibility`. `visibility` and
        `exact_factors` complete the links the oracle keeps.
        """
        K, q = r.size, self.weights.size
        F, peak, residual = np.zeros(K), np.zeros(K), np.zeros(K)
        shape, samples = np.zeros((K, 6)), np.zeros((K, q))
        # a receiver without children carries only its mean: the exact pair factor, as a constant
        leaf = self.hierarchy.child_count[r] == 0
        at = np.flatnonzero(leaf)
        f_error = np.zeros(K)
        if at.size:
            F[at], f_error[at] = self._pair_factors(r[at], s[at])
            peak[at] = shape[at, 0] = F[at]
        # one with children passes its light down: the point factor's quadratic over it
        at = np.flatnonzero(~leaf)
        if at.size:
            X, N, weight = self.sample_points(r[at])
            Fx = self._point_factors(X, N, np.repeat(s[at], q))
            samples[at] = Fx.reshape(-1, q)
            F[at], shape[at], residual[at] = self._fit(r[at], samples[at], weight)
            peak[at] = samples[at].max(1)
        # how much the kernel varies over the source: not yet known (NaN, counted as 1) for
        # sources with children (`source_variation`), none for leaves (constant by the model)
        source_variation = np.where(self.hierarchy.child_count[s] > 0, np.nan, 0.0)
        return dict(
            receiver=r,
            source=s,
            F=F,
            V=np.ones(r.size),
            visibility=np.full(r.size, FULL, dtype=np.int8),
            variation=residual,
            source_variation=source_variation,
            peak=peak,
            shape=shape,
            samples=samples,
            exact=leaf,
            v_error=np.zeros(K),
            f_error=f_error,
        )

    def source_variation(self, columns):
        """The links' "source_variation": max |F(y -> r) - mean| / mean over the source's Gauss
        points y (at most 1), where F(y -> r) is the point factor from the source back to the
        receiver (columns changed in place)."""
        r, s = columns["receiver"], columns["source"]
        q = self.weights.size
        Y, M, weight = self.sample_points(s)
        Fy = self._point_factors(Y, M, np.repeat(r, q))
        Fy = Fy.reshape(-1, q)
        mean = (weight * Fy).sum(1) / np.maximum(weight.sum(1), 1e-300)
        spread = np.abs(Fy - mean[:, None]).max(1)
        columns["source_variation"] = np.minimum(
            np.divide(spread, mean, out=np.ones(r.size), where=mean > 0), 1.0
        )
        return columns

    def exact_visibility(self, columns, allowance):
        """Exact V (`visibility.exact_pair_visibility`, to the absolute `allowance` (K,)) for the
        shadowed links whose kinds allow it; their v_error becomes the allowance and column
        "exact_v" (K,) marks them (columns changed in place). The quadratic is F(x) V(x) / V, so it
        stays: V times it now has mean F V."""
        r, s = columns["receiver"], columns["source"]
        V, _ = exact_pair_visibility(
            self.hierarchy.elements, self.shadows, self.shafts, r, s, self.tol, absolute=allowance
        )
        found = np.isfinite(V)
        columns["V"] = np.where(found, V, columns["V"])
        columns["v_error"] = np.where(found, allowance, columns["v_error"])
        columns["visibility"] = np.where(
            found, np.where(V <= 0.0, HIDDEN, PARTIAL), columns["visibility"]
        ).astype(np.int8)
        columns["exact_v"] = found
        return columns

    def _oriented(self, r, s):
        """(a, b, whether a is r) of pairs (r, s) as `pair_form_factors` takes them."""
        outer_r = outer_first(self.hierarchy.elements, r, s)
        return np.where(outer_r, r, s), np.where(outer_r, s, r), outer_r

    def _pair_factors(self, r, s):
        """F(r -> s) from the exact pair kernels (`transport.pair_form_factors`) and the relative
        error it may have (`transport.rule_errors`: kinked and near pairs), shapes (K,) and (K,)."""
        e = self.hierarchy.elements
        a, b, outer_r = self._oriented(r, s)
        F_ab, count = pair_form_factors(e, a, b, self.tol)
        self.evaluations += count
        f_error = rule_errors(e, a, b, self.tol)
        return np.where(outer_r, F_ab, F_ab * e.area[s] / e.area[r]), f_error

    def refined_factors(self, columns, allowance):
        """F of kinked links integrated again to the relative error `allowance` (K,)
        (`transport.refined_pair_factors`); f_error becomes the allowance (columns "F" and
        "f_error" changed in place)."""
        e = self.hierarchy.elements
        r, s = columns["receiver"], columns["source"]
        a, b, outer_r = self._oriented(r, s)
        F_ab = np.where(outer_r, columns["F"], columns["F"] * e.area[r] / e.area[s])
        got, count = refined_pair_factors(e, a, b, self.tol, allowance * F_ab)
        self.evaluations += count
        columns["F"] = np.where(outer_r, got, got * e.area[s] / e.area[r])
        columns["f_error"] = np.asarray(allowance, dtype=np.float64)
        return columns

    def exact_factors(self, columns):
        """The links' F from the exact pair kernels where not yet exact (receivers with children),
        the quadratic's mean moved to it and the move added to its error (columns changed in
        place)."""
        todo = np.flatnonzero(~columns["exact"])
        if todo.size:
            F, columns["f_error"][todo] = self._pair_factors(
                columns["receiver"][todo], columns["source"][todo]
            )
            self.move_factors(columns, todo, F)
            columns["exact"][todo] = True
        return columns

    def move_factors(self, columns, rows, F):
        """Links `rows` take the factors F (rows.size,): the quadratic's mean moves with F, and
        for receivers with children (which pass the quadratic down) the move is added to its
        error (columns changed in place)."""
        shift = F - columns["F"][rows]
        columns["shape"][rows, 0] += shift
        inner = self.hierarchy.child_count[columns["receiver"][rows]] > 0
        columns["variation"][rows] += np.where(inner, np.abs(shift), 0.0)
        columns["F"][rows] = F

    def pair_visibility(self, columns):
        """The links' V, visibility class and v_error (columns changed in place).

        V is the pair's (exact in "exact" mode, else rays, as the all-pairs path); column
        "shadowed" marks the links with a candidate occluder in their shaft.
        """
        r, s = columns["receiver"], columns["source"]
        columns["shadowed"] = np.zeros(r.size, dtype=bool)
        if self.shafts is None or r.size == 0:
            return columns
        e = self.hierarchy.elements
        chunk = max(256, CANDIDATE_BUDGET // max(self.shafts.M, 1))
        shadowed = np.concatenate(
            [
                self.shafts.candidates(r[k : k + chunk], s[k : k + chunk]).any(1)
                for k in range(0, r.size, chunk)
            ]
        )
        V = np.ones(r.size)
        todo = np.flatnonzero(shadowed)
        if self.exact_pairs and todo.size:
            Vx, _ = exact_pair_visibility(e, self.shadows, self.shafts, r[todo], s[todo], self.tol)
            found = np.isfinite(Vx)
            V[todo[found]] = Vx[found]
            todo = todo[~found]
        if todo.size:
            F = columns["F"]
            h = self.hierarchy
            weight = np.maximum(F[todo], F[todo] * h.area[r[todo]] / h.area[s[todo]])
            V[todo], _, _ = pair_visibility(
                e, self.occluders, self.shafts, r[todo], s[todo], self.tol, weight
            )
        columns["V"] = V
        columns["shadowed"] = shadowed
        columns["visibility"] = np.where(~shadowed, FULL, np.where(V <= 0.0, HIDDEN, PARTIAL)).astype(np.int8)
        columns["v_error"] = np.zeros(r.size)
        columns["v_error"][todo] = SAMPLED_VISIBILITY_ERROR  # (the rays' V)
        return columns

    def visible_shapes(self, columns):
        """For shadowed links (`pair_visibility`) into receivers with children, the quadratic of
        the visible point factor F(x -> s) V(x, s) over the receiver (columns changed in place).

        A receiver with children passes its light down to them, so how the shadow falls across it
        matters: the visible factor at its Gauss points (exact shadows where the kinds allow,
        else rays) is fitted with mean F V; the fit's residual, plus how far the points' own mean
        is from F V (a shadow the points resolve badly), is the link's factor error.
        """
        r, s, V = columns["receiver"], columns["source"], columns["V"]
        h, e = self.hierarchy, self.hierarchy.elements
        sel = np.flatnonzero(columns["shadowed"] & (h.child_count[r] > 0))
        if sel.size:
            q = self.weights.size
            X, N, weight = self.sample_points(r[sel])
            Fx = columns["samples"][sel]
            S = np.repeat(s[sel], q)
            R = np.repeat(r[sel], q)
            Vx, _ = point_visibility(
                e,
                self.occluders,
                self.shafts,
                self.shadows,
                X,
                N,
                dict(owner=e.owner[R], outward=e.outward[R]),
                S,
                Fx.ravel(),
                self.tol,
                # (sphere-patch sources keep rays, as element pairs do, emitting or not: their exact
                # lines cost ~10x a whole sphere's; with them the Cornell hierarchy at 250 patches
                # took 2.3x its time)
                exact_allowed=~self.shadows.patch_target[S],
            )
            seen = Fx * Vx.reshape(-1, q)
            transfer = columns["F"][sel] * V[sel]
            rule, shape, residual = self._fit(r[sel], seen, weight, mean=transfer)
            columns["shape"][sel] = np.divide(
                shape, V[sel, None], out=columns["shape"][sel], where=V[sel, None] > 0
            )
            columns["variation"][sel] = residual + np.abs(rule - transfer)
        return columns


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
    sky_offset : ndarray, shape (M, 3), optional
        Under a sky of radiance L, L at nodes of surfaces that hide it: a link then carries
        B_s - L (`hsolve`), and its error is judged on that.
    free : ndarray, shape (M,), optional
        Each node's free fraction f (`coverage`): the solve divides what a node's links gather by
        f (`hsolve`), so their errors are allowed f times tol.
    """

    def __init__(self, hierarchy, rho, E, tol, reference="receiver", sky_offset=None, free=None):
        if reference not in REFERENCES:
            raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
        self.hierarchy = hierarchy
        self.rho = rho
        self.E = hierarchy.pull(E)
        self.tol = tol
        self.reference = reference
        self.sky_offset = np.zeros_like(rho) if sky_offset is None else sky_offset
        self.free = np.ones(len(hierarchy)) if free is None else 1.0 / gather_scale(free)

    def carried(self, B, s):
        """What links from sources s carry per unit F V: |B_s - sky offset|, shape (K, 3)."""
        return np.abs(B[s] - self.sky_offset[s])

    def allowed(self, B):
        """tol times the reference radiosity of every node (times its free fraction), shape (M, 3)."""
        h = self.hierarchy
        roots = h.roots
        mean = (h.area[roots, None] * B[roots]).sum(0) / max(h.area[roots].sum(), 1e-300)
        if self.reference == "scene":
            return self.tol * self.free[:, None] * mean[None]
        # a sub-patch (below a user patch that touches another surface) is held to tol of its
        # patch's radiosity when that is the larger: the user's tol is per patch, and a dark
        # sub-patch at a contact held to its own would draw fine links from the whole scene
        reference = B.copy()
        below = np.flatnonzero((h.patch_node >= 0) & (h.element < 0))
        reference[below] = np.maximum(B[below], B[h.patch_node[below]])
        return self.tol * self.free[:, None] * np.maximum(reference, REFERENCE_FLOOR * mean[None])

    def exceeds(self, r, s, columns, B, allowed, spread, pending=None):
        """Links whose error estimate exceeds the allowance of their receiver, shape (K,) bool.

        Parameters
        ----------
        r, s : ndarray of int, shape (K,)
        columns : dict
            "F", "V", "visibility", "v_error", "variation", "source_variation" and "peak" of the
            links (`links.Links.FIELDS`).
        B, allowed, spread : ndarray, shape (M, 3)
            Node radiosities, `allowed(B)`, and each node's spread of B over its children.
        pending : ndarray of bool, shape (K,), optional
            Links whose factor shape over the receiver is still to be fitted
            (`LinkEstimator.visible_shapes`): judged on the rest of their error, their shape error
            taken as 0 in the error and as its largest value, max(peak, F), in their share of the
            receiver's light, so that a pending link that exceeds here exceeds whatever its shape
            turns out to be (and is split without fitting it).
        """
        get = columns.__getitem__
        h = self.hierarchy
        near = self.near(r, s)
        # a receiver's error is in its mean; the shape of the factor over it matters only when it
        # has children to pass its light down to
        largest = np.where(h.child_count[r] > 0, np.maximum(get("peak"), get("F")), 0.0)
        shape_error = np.minimum(get("variation"), largest)
        shared = shape_error  # (the shape error that counts in the link's share)
        if pending is not None:
            shape_error, shared = np.where(pending, 0.0, shape_error), np.where(pending, largest, shape_error)
        # the source's radiosity varies over it while the link carries its mean: the error is the
        # covariance of the kernel and B over the source, at most F V times B's spread times the
        # kernel's relative variation over it (any shadow: up to all of it)
        variation = np.nan_to_num(get("source_variation"), nan=1.0)
        relative = np.where(get("visibility") == FULL, variation, 1.0)
        transfer = get("F") * get("V")
        light = self.rho[r] * self.carried(B, s)
        # a shadowed pair's V may be off by its v_error (rays: SAMPLED_VISIBILITY_ERROR); a
        # larger node is split while that could show, and between leaves `Refinement` makes V
        # exact where it must
        sampled = get("v_error") * get("F")
        error = light * (shape_error + sampled)[:, None]
        error += self.rho[r] * (transfer * relative)[:, None] * spread[s]
        if self.reference == "receiver":
            gathered = np.maximum(B[r] - self.E[r], 1e-300)
            share = np.clip(
                light * np.maximum(transfer, shared + sampled)[:, None] / gathered, SHARE_FLOOR, 1.0
            )
            return near | np.any(error > allowed[r] * share, axis=1)
        return near | np.any(error > allowed[r], axis=1)

    def near(self, r, s):
        """Links whose ends' bounding spheres overlap (adjacent walls, contacts): their kernels
        peak between any sample points, so they are split whatever the samples say (`exceeds`),
        shape (K,) bool."""
        e = self.hierarchy.elements
        return lengths(e.center[r] - e.center[s]) <= e.radius[r] + e.radius[s]

    def visibility_allowance(self, r, s, columns, B, allowed):
        """The absolute error each link's V may have, shape (K,) (inf: as it is).

        The V errors of a receiver's links add up: its links are taken in order of the error
        they may bring (v_error x the light they carry unoccluded, over tol x B_r), the smallest
        first, and left as they are while those add up to at most half of tol x B_r; each of the
        others may err by the other half over the square root of their number (independent
        errors), as `paircache._picked_by_light` does for rows of pairs.
        """
        light = self.rho[r] * self.carried(B, s) * columns["F"][:, None]
        return _shared_allowance(r, light, columns["v_error"], allowed)

    def factor_allowance(self, r, s, columns, B, allowed):
        """The relative error each link's F may have, shape (K,) (inf: as it is): the f_error
        of a receiver's links shared out as `visibility_allowance` shares V errors (a budget of
        its own: the two kinds of error are independent)."""
        light = self.rho[r] * self.carried(B, s) * (columns["F"] * columns["V"])[:, None]
        return _shared_allowance(r, light, columns["f_error"], allowed)

    def split(self, r, s):
        """Which end of each link to split: 0 receiver, 1 source, -1 neither (both leaves)."""
        h = self.hierarchy
        radius = h.elements.radius
        r_ok, s_ok = h.child_count[r] > 0, h.child_count[s] > 0
        source = s_ok & (~r_ok | (radius[s] > radius[r]))
        return np.where(source, 1, np.where(r_ok, 0, -1))


def _shared_allowance(r, light, error, allowed):
    """Error each link may have in the units of `error` (K,), given the light (K, C) it brings
    per unit of that error into its receiver r (K,) and the receivers' `allowed` (M, C): a
    receiver's links of smallest risk keep theirs while the risks add up to half its allowance,
    the others share the other half as independent errors. Shape (K,), inf: as it is."""
    if r.size == 0:
        return np.zeros(0)
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(light > 0, allowed[r] / light, np.inf).min(axis=1)  # error = all of tol B_r
    risk = np.where(np.isfinite(room), error / room, 0.0)
    order = np.lexsort((risk, r))
    ranked, receiver = risk[order], r[order]
    total = np.cumsum(ranked)
    first = np.flatnonzero(np.r_[True, receiver[1:] != receiver[:-1]])
    size = np.diff(np.r_[first, receiver.size])
    within = total - np.repeat(total[first] - ranked[first], size)
    picked = within > 0.5
    count = np.repeat(np.add.reduceat(picked.astype(np.int64), first), size)
    allowance = np.full(r.size, np.inf)
    allowance[order] = np.where(picked, 0.5 * room[order] / np.sqrt(np.maximum(count, 1)), np.inf)
    return allowance


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
    exact_ends : ndarray of bool, shape (M,), optional
        The nodes whose links may get an exact V (`recheck`): a link qualifies when either end
        is one. None: every node (the occlusion mode "exact"; "direct" takes the emitters' nodes,
        as the all-pairs path makes its emitters' pairs exact).
    """

    def __init__(self, estimator, links, run, exact_ends=None):
        self.estimator = estimator
        self.exact_ends = exact_ends
        self.hierarchy = estimator.hierarchy
        self.links = links
        self.run = run
        self.evaluated = 0
        self.rounds = 0
        self.updated = 0  # links whose V was made exact (a change the solve must see)

    def root_pairs(self):
        """Pairs of tree roots that can exchange light (bounds), shapes (K,) and (K,)."""
        roots = self.hierarchy.roots
        r, s = np.meshgrid(roots, roots, indexing="ij")
        r, s = r.ravel(), s.ravel()
        alive = self.hierarchy.elements.exchange(r, s)
        return r[alive], s[alive]

    def recheck(self, oracle, B):
        """Remove accepted links that now exceed their allowance, make exact the kept links' V
        that now need it (counted in `updated`); return the removed links' children pairs."""
        links = self.links
        if len(links) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        allowed = oracle.allowed(B)
        spread = self.hierarchy.spread(B)
        columns = {name: getattr(links, name) for name in links.FIELDS}
        end = oracle.split(links.receiver, links.source)
        bad = oracle.exceeds(links.receiver, links.source, columns, B, allowed, spread) & (end >= 0)
        bad = self._settle_sources(oracle, columns, bad, B, allowed, spread)
        links.source_variation = columns["source_variation"]
        rows = np.flatnonzero(bad)
        r, s, end = links.receiver[rows], links.source[rows], end[rows]
        links.remove(rows)
        # the links kept whose V must now be exact (or exact to a tighter allowance)
        columns = self._exact_visibility(
            oracle, {name: getattr(links, name) for name in links.FIELDS}, B, allowed
        )
        columns = self._refined_factors(oracle, columns, B, allowed)
        for name in links.FIELDS:
            setattr(links, name, columns[name])
        return self._children(r, s, end)

    def refine(self, oracle, B, r, s):
        """Evaluate candidate links (r <- s), accept or split them until none is left."""
        allowed = oracle.allowed(B)
        spread = self.hierarchy.spread(B)
        estimator = self.estimator
        while r.size:
            self.rounds += 1
            end = oracle.split(r, s)
            # near links with an end to split are split unseen (`Oracle.exceeds` would split them)
            forced = oracle.near(r, s) & (end >= 0)
            unseen = (r[forced], s[forced], end[forced])
            r, s, end = r[~forced], s[~forced], end[~forced]
            self.evaluated += r.size
            # sampled factors first: links that fail on them are split without rays or exact F
            columns = self._map(lambda c: estimator.evaluate(c["receiver"], c["source"]), r, s)
            bad = oracle.exceeds(r, s, columns, B, allowed, spread) & (end >= 0)
            bad = self._settle_sources(oracle, columns, bad, B, allowed, spread)
            rest = np.flatnonzero(~bad)
            if rest.size:
                kept = self._map(estimator.pair_visibility, **{k: v[rest] for k, v in columns.items()})
                # links that fail whatever the shadow's shape over their receiver are split
                # without fitting it (the visible factor at points: exact shadows, the dearest part)
                pending = kept["shadowed"] & (self.hierarchy.child_count[r[rest]] > 0)
                hopeless = oracle.exceeds(r[rest], s[rest], kept, B, allowed, spread, pending)
                hopeless &= pending & (end[rest] >= 0)
                bad[rest[hopeless]] = True
                rest, kept = rest[~hopeless], {k: v[~hopeless] for k, v in kept.items()}
            if rest.size:
                kept = self._map(estimator.visible_shapes, **kept)
                again = oracle.exceeds(r[rest], s[rest], kept, B, allowed, spread) & (end[rest] >= 0)
                bad[rest[again]] = True
                ok = np.flatnonzero(~again)
                kept = self._map(estimator.exact_factors, **{k: v[ok] for k, v in kept.items()})
                # (exact V waits for `recheck`, after a solve: the B it must be exact for)
                keep = kept["F"] > 0
                self.links.append(**{k: v[keep] for k, v in kept.items()})
            r, s = self._children(*(np.concatenate([a, b[bad]]) for a, b in zip(unseen, (r, s, end))))

    def _exact_visibility(self, oracle, columns, B, allowed):
        """Exact V for the shadowed links whose V error could exceed twice its allowance (see
        `Oracle.visibility_allowance`; at least MIN_VISIBILITY_ALLOWANCE), columns updated.

        V is symmetric (the kernel-weighted unblocked fraction of the pair), so a link and its
        reverse share one computation, to the tighter of their allowances."""
        if self.estimator.shadows is None:
            return columns
        r, s = columns["receiver"], columns["source"]
        allowance = oracle.visibility_allowance(r, s, columns, B, allowed)
        allowance = np.clip(allowance, MIN_VISIBILITY_ALLOWANCE, SAMPLED_VISIBILITY_ERROR)
        # (a V within twice its allowance stays: the sampled error is a worst case, and an exact V
        # is not recomputed for a small change of B)
        wanted = (columns["visibility"] != FULL) & (columns["v_error"] > 2.0 * allowance)
        if self.exact_ends is not None:
            wanted &= self.exact_ends[r] | self.exact_ends[s]
        sel = np.flatnonzero(wanted)
        self.updated += sel.size
        if sel.size == 0:
            return columns
        got, inverse, _ = self._per_pair(columns, sel, allowance[sel], self.estimator.exact_visibility)
        found = got["exact_v"][inverse]
        at = sel[found]
        for name in ("V", "v_error", "visibility"):
            columns[name][at] = got[name][inverse[found]]
        return columns

    def _refined_factors(self, oracle, columns, B, allowed):
        """F integrated again for the kinked links whose factor error could exceed twice its
        allowance (`Oracle.factor_allowance`, at least MIN_FACTOR_ALLOWANCE), columns updated
        (counted in `updated`). A link and its reverse share one integration, to the tighter
        of their allowances."""
        r, s = columns["receiver"], columns["source"]
        allowance = oracle.factor_allowance(r, s, columns, B, allowed)
        allowance = np.clip(allowance, MIN_FACTOR_ALLOWANCE, columns["f_error"])
        sel = np.flatnonzero(columns["f_error"] > 2.0 * allowance)
        self.updated += sel.size
        if sel.size == 0:
            return columns
        got, inverse, receiver = self._per_pair(columns, sel, allowance[sel], self.estimator.refined_factors)
        # each link takes its pair's F, seen from its own receiver
        e = self.hierarchy.elements
        same = r[sel] == receiver
        F_pair = got["F"][inverse]
        F = np.where(same, F_pair, F_pair * e.area[s[sel]] / e.area[r[sel]])
        self.estimator.move_factors(columns, sel, F)
        columns["f_error"][sel] = got["f_error"][inverse]
        return columns

    def _per_pair(self, columns, sel, allowance, work):
        """work(columns, allowance) once per unordered pair among the links `sel` (a link and its
        reverse share it), to the tighter of their `allowance` (sel.size,), in the runner's
        threads. Returns (the pairs' columns, each selected link's pair row (sel.size,), the
        receiver each pair was computed for (sel.size,))."""
        r, s = columns["receiver"][sel], columns["source"][sel]
        pair = np.minimum(r, s) * len(self.hierarchy) + np.maximum(r, s)
        _, first, inverse = np.unique(pair, return_index=True, return_inverse=True)
        tightest = np.full(first.size, np.inf)
        np.minimum.at(tightest, inverse, allowance)
        part = {k: v[sel[first]] for k, v in columns.items()}
        got = self._map(lambda c: work(c, c["allowance"]), allowance=tightest, **part)
        return got, inverse, part["receiver"][inverse]

    def _settle_sources(self, oracle, columns, bad, B, allowed, spread):
        """`bad` after measuring the source variation of the failing links that would pass with a
        uniform source and have not measured it (NaN: counted as 1); columns updated in place."""
        unknown = np.flatnonzero(bad & np.isnan(columns["source_variation"]))
        if unknown.size == 0:
            return bad
        trial = {k: v[unknown] for k, v in columns.items()}
        trial["source_variation"] = np.zeros(unknown.size)
        r, s = columns["receiver"], columns["source"]
        sel = unknown[~oracle.exceeds(r[unknown], s[unknown], trial, B, allowed, spread)]
        if sel.size:
            got = self._map(self.estimator.source_variation, **{k: v[sel] for k, v in columns.items()})
            columns["source_variation"][sel] = got["source_variation"]
            bad = bad.copy()
            bad[sel] = oracle.exceeds(r[sel], s[sel], got, B, allowed, spread)
        return bad

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
        alive = h.elements.exchange(r, s)
        return r[alive], s[alive]
