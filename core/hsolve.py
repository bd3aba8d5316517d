"""The hierarchical radiosity solve: gather over links, push-pull, iterate to a residual bound.

One sweep (Hanrahan, Salzman & Aupperle 1991, section 4):

1. gather: every receiver node r collects H_r(x) = sum over its links F(x -> s) V B_s, a
   quadratic over r (`links.Links.shape`: higher-order links in the spirit of Zatz 1993 and
   Gortler, Schroeder, Cohen & Hanrahan 1993);
2. push: every node's H is added to all its descendants (light gathered by a node reaches
   every point of it; `hierarchy.Hierarchy.push_quadratic`), so a leaf holds the total it
   receives, H*_leaf(x);
3. leaves: B_leaf = E_leaf + rho_leaf mean(H*_leaf) (the area-weighted mean over the leaf of the
   quadratic: its coefficients dotted with the leaf's moments, `hierarchy.Hierarchy.mean`);
4. pull: inner nodes take the area-weighted mean of their children's B.

In an enclosure, a leaf's row from occluding sources (what it sees of them) must total its exact
signed sum (`hclosure`): the pushed row is scaled to it, so the links' shape and visibility errors
do not leak light (a white furnace gives B = E / (1 - rho) to the solve's bound).

Seen on leaves, a sweep is B' = E + rho P F R B with R (pull: averages, ||R||_inf = 1) and P
(push: sums over ancestors), so the per-element stopping bound of `solvers` carries over:
with s_i = rho_i sum over the links of i and its ancestors of F V (the pushed row sums),
q = max_i s_i < 1 and r = B' - B the residual of a sweep, |B'_i - B*_i| <= s_i ||r||_inf / (1 - q).
The solve stops when this is at most tol * max(B'_i, FLOOR * max B) for every leaf and channel,
or when ||r|| is down to ROUNDING * max B (double precision's rounding: the bound reached is
returned, as in `solvers`), max B being at least the largest emission or sky radiance (a closed
box under a sky has B = 0 exactly, and its sweeps settle at rounding values of either sign).
Where q >= 1 (a transparent emitter in contact with a wall lets a row sum pass 1) the bound uses
the observed contraction of the residual, max over the last sweeps of r_k / r_(k-1), instead of q
(an estimate, not a bound: info["fallback"] says so).

A node that another object partly covers (a floor under a box's footprint: `coverage`) has a
radiosity that is the mean over its free part. Links' visibilities hold only the free part, so
what a leaf gathers (its own links and its ancestors', pushed down) is its light over its whole
area with nothing on the covered part: divided by the leaf's free fraction f it is the mean over
the free part, and the pull weights children by their free areas, so a node's radiosity is the
mean over its free part too. The division comes after the push: an ancestor's link carries
light over the ancestor's whole area, which its quadratic spreads over free and covered leaves
alike (dividing by the ancestor's f made a free leaf below it 1/f too bright). An enclosed leaf's
row from occluding sources is balanced to its total over the free part (`hclosure`); any other
leaf's row from occluding sources is not taken above 1 by the division. Sources that do not
occlude (a lamp in front of a ceiling) are not counted in that cap, which otherwise kept patches
beside boxes in a closed room at the light over their whole area: up to 7 % dark.
"""

import numpy as np

from .coverage import gather_scale
from .solvers import (
    FLOOR,
    ROUNDING,
    SWEEP_BUDGET,
    ConvergenceError,
    CrossingSurfaceError,
    diverging,
    overfull,
)

MAX_ROW_CHANGE = 0.05  # an enclosed leaf's row further than this from its total is left as it is
# ... or this, for a leaf partly under another object (`coverage`): its sampled visibilities are
# means over the few sample nodes on its free part (a floor patch a fifth under a box in a closed
# room: its row 6.5 % over its total, every visibility a little high)
MAX_COVERED_ROW_CHANGE = 0.15
FREE_FLOOR = 1e-9  # added to free fractions in the pull's weights (a wholly covered node: areas)


class HierarchicalSystem:
    """B = E + rho (push F gather pull) B on a hierarchy's leaves.

    Under a uniform sky of radiance L a leaf gathers L + sum_links F V (B_s - L) over sources on
    surfaces that hide the sky (what they hide of it; the others let it through), as the pairs
    path's L (1 - sum_j F_ij V_ij) + sum_j F_ij V_ij B_j does.

    Parameters
    ----------
    hierarchy : hierarchy.Hierarchy
    links : links.Links
    rho : ndarray, shape (M, 3)
        Reflectance of every node (its surface's).
    E : ndarray, shape (M, 3)
        Emission (with direct light) of every leaf (inner rows are ignored).
    enclosed : ndarray, shape (M,), optional
        The total the row from occluding sources must have, NaN where unknown (`hclosure`): it is
        scaled to it (when within MAX_ROW_CHANGE of it, MAX_COVERED_ROW_CHANGE for a covered leaf).
    occluding : ndarray of bool, shape (M,), optional
        Nodes on occluding surfaces (with `enclosed`).
    sky : (ndarray (3,), ndarray (M, 3)), optional
        The sky's radiance L and its offset per node (L on surfaces that hide the sky, else 0).
    free : ndarray, shape (M,), optional
        Each node's free fraction (`coverage.Coverage.free`); default 1.
    """

    def __init__(self, hierarchy, links, rho, E, enclosed=None, occluding=None, sky=None, free=None):
        self.hierarchy = hierarchy
        self.links = links
        self.sky, self.sky_offset = (np.zeros(3), 0.0) if sky is None else sky
        self.rho = np.asarray(rho, dtype=np.float64)
        self.leaf = hierarchy.child_count == 0
        h, size = hierarchy, len(hierarchy)
        self.weight, self.scale_gathered = None, np.ones(size)
        covered = free is not None and np.any(free < 1.0)
        if covered:
            self.weight = h.area * (free + FREE_FLOOR)
            self.scale_gathered = gather_scale(free)
        self.E = h.pull(np.where(self.leaf[:, None], E, 0.0), self.weight)
        self.scale = None  # per leaf, for the row from occluding sources
        fits = np.zeros(size, dtype=bool)
        if enclosed is not None and np.any(np.isfinite(enclosed)):
            self.mask = occluding[links.source]
            rows = self._pushed(links.row_sums(size, self.mask))[:, 0]
            target = np.nan_to_num(enclosed, nan=-1.0)
            change = (
                MAX_ROW_CHANGE
                if free is None
                else np.where(free < 1.0, MAX_COVERED_ROW_CHANGE, MAX_ROW_CHANGE)
            )
            fits = (target > 0) & (np.abs(rows - target) <= change) & (rows > 0)
            self.scale = np.where(fits, target / np.where(fits, rows, 1.0), 1.0)[:, None]
        self.balanced = int(np.count_nonzero(fits & self.leaf))
        if covered:
            # rows not balanced to their total are capped at 1 (the cap counts occluding sources
            # only: a lamp that does not occlude adds its factor on top of the ceiling's behind it)
            counted = None if occluding is None else occluding[links.source]
            raw = h.mean(h.push_quadratic(links.row_sums(size, counted)))[:, 0]
            cap = np.maximum(1.0, 1.0 / np.maximum(raw, 1e-300))
            self.scale_gathered = np.where(fits, self.scale_gathered, np.minimum(self.scale_gathered, cap))
        # s_i per leaf and channel: pushed row sums of F V (balanced) times rho
        self.row_sum = np.where(self.leaf, np.abs(self._rows()[:, 0]), 0.0)
        self.s = self.rho * self.row_sum[:, None]
        self.q = float(self.s.max()) if self.s.size else 0.0

    def refusal(self, error):
        """The error a failed `solve` raises: a CrossingSurfaceError (handles: the hierarchy's
        object indices) if some leaves' rows sum above 1 + OVERFULL_ROW, the likely cause (no
        patch sees more than its whole view), else `error` itself."""
        handles, row_sums = overfull(self.hierarchy.object, self.row_sum)
        return CrossingSurfaceError(str(error), handles, row_sums) if handles else error

    def _pushed(self, coef):
        """Gathered quadratics per node (M, 6, C) pushed down and averaged over every node, each
        node's mean then taken over its free part, shape (M, C)."""
        h = self.hierarchy
        return self.scale_gathered[:, None] * h.mean(h.push_quadratic(coef))

    def _rows(self):
        """Pushed row sums of F V per node (balanced rows scaled), shape (M, 1)."""
        size = len(self.hierarchy)
        if self.scale is None:
            return self._pushed(self.links.row_sums(size))
        inside = self._pushed(self.links.row_sums(size, self.mask))
        return self.scale * inside + self._pushed(self.links.row_sums(size, ~self.mask))

    def sweep(self, B):
        """One gather, push and pull from node radiosities B, shape (M, 3) -> (M, 3)."""
        size = len(self.hierarchy)
        B = B - self.sky_offset  # what links carry under a sky (B itself without one)
        if self.scale is None:
            H = self._pushed(self.links.gather(B, size))
        else:
            H = self.scale * self._pushed(self.links.gather(B, size, self.mask))
            H += self._pushed(self.links.gather(B, size, ~self.mask))
        leaf_B = np.where(self.leaf[:, None], self.E + self.rho * (H + self.sky[None]), 0.0)
        return self.hierarchy.pull(leaf_B, self.weight)

    def solve(self, tol, max_bounces=None, cancel=None, start=None):
        """Jacobi sweeps from B = E (or `start`), stopped by the per-element bound.

        Parameters
        ----------
        tol : float
        max_bounces : int or None
            At most this many sweeps (bounces of light) from B = E; None: until converged.
        cancel : callable() or None
            Called between sweeps (it raises to stop).
        start : ndarray, shape (M, 3), optional
            A first iterate (a previous solution; used only when max_bounces is None).

        Returns
        -------
        B : ndarray, shape (M, 3)
            Node radiosities (leaves and their area averages).
        info : dict
            "iterations", "residual" (last sweep's max |B' - B| over max B), "error_bound" (the
            largest bound on |B_i - B*_i| over max(B_i, FLOOR max B)), "contraction" (q).
        """
        B = self.E.copy() if (start is None or max_bounces is not None) else np.array(start, dtype=float)
        budget = SWEEP_BUDGET if max_bounces is None else max_bounces
        observed = self.q >= 1.0
        kappa = 1.0 / (1.0 - self.q) if not observed else np.inf
        s = np.minimum(self.s, 1.0) if observed else self.s
        iterations, bound, residual, previous, ratios, rounded = 0, np.inf, 0.0, None, [], False
        light = max(float(np.abs(self.E).max(initial=0.0)), float(np.abs(self.sky).max(initial=0.0)))
        history = []  # each sweep's residual
        while iterations < budget:
            if cancel is not None:
                cancel()
            new = self.sweep(B)
            iterations += 1
            r = float(np.abs(new - B)[self.leaf].max(initial=0.0))
            # (the scale of what the scene receives, if larger: under a sky a closed box's exact
            # radiosity is 0, and its sweeps settle at rounding values of either sign)
            top = max(float(new[self.leaf].max(initial=0.0)), light)
            B = new
            history.append(r)
            how = diverging(history, top, limited=max_bounces is not None)
            if how:
                raise ValueError(
                    f"the hierarchical radiosity solve diverges ({how}; contraction {self.q:.6g})"
                )
            residual = r / top if top > 0 else 0.0
            if observed:
                if previous is not None and previous > 0:
                    ratios = (ratios + [r / previous])[-3:]
                contraction = max(ratios) if len(ratios) == 3 else 1.0
                kappa = 1.0 / (1.0 - contraction) if contraction < 1.0 else np.inf
                previous = r
            allowed = np.maximum(new, FLOOR * top)[self.leaf]
            # (a leaf that gathers nothing, s = 0, or a sweep that changed nothing, r = 0, has no
            # error left, also while the observed contraction is not known yet: kappa = inf)
            with np.errstate(invalid="ignore"):
                err = np.where((s[self.leaf] > 0) & (r > 0), s[self.leaf] * kappa * r, 0.0)
            with np.errstate(invalid="ignore", divide="ignore"):
                bound = float(np.where(err > 0, err / allowed, 0.0).max(initial=0.0))
            # (a residual at double precision's rounding is as small as sweeps get: stop there,
            # with the bound it gives, as `solvers` does)
            rounded = r <= ROUNDING * top
            if bound <= tol or rounded:
                break
        if max_bounces is None and bound > tol and not rounded:
            raise ConvergenceError(
                f"hierarchical solve reached an error bound of {bound:.3g} > tol {tol:g} "
                f"in {iterations} sweeps",
                residual,
                tol,
                iterations,
            )
        fallback = "observed contraction" if observed else None
        return B, dict(
            iterations=iterations, residual=residual, error_bound=bound, contraction=self.q, fallback=fallback
        )
