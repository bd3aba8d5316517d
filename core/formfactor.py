"""Form factors between parametric patches: the public entry points.

F(1 -> 2) = 1/A1 * integral over patch 1 of F(dA1 -> patch 2) dA1, where the inner
point-to-patch factor is exact for flat quads and adaptive elsewhere (`inner.PointToPatch`) and
the outer integral is adaptive over patch 1's parameters (`adaptive.integrate_cells`). Reciprocity
A1 F12 = A2 F21 lets the flat side of a pair be the inner one. Well-separated pairs that face each
other fully use one tensor Gauss rule whose order follows their distance-to-size ratio.
"""

import warnings
from collections import namedtuple

import numpy as np

from . import checks
from .adaptive import integrate_cells
from .bounds import FULL, HIDDEN, PARTIAL, Pyramid, cone_code, direction_cone, facing_code, lengths
from .inner import PointToPatch
from .integrate import cell_nodes
from .kernel import kernel
from .kinds import GENERIC, POLYGON
from .occluded import occluded_form_factor
from .quadrature import tensor_rule
from .surface import Surface, translated
from .surfaceset import SurfaceSet

FormFactorEstimate = namedtuple("FormFactorEstimate", "value error evaluations")
FormFactorEstimate.__doc__ = """Result of `form_factor_estimate`.

value : float
    F(src -> dst).
error : float
    Estimated absolute error of `value` (pessimistic).
evaluations : int
    Kernel evaluations spent (each edge term of an exact polygon integral counts as one).
"""


class AccuracyWarning(RuntimeWarning):
    """A form factor came back less accurate than its `tol`: its work budget ran out first.

    The value is still the best one reached and its error estimate says how good it is
    (`form_factor_estimate` returns both); the message names the pair, the tolerance and the
    achieved error. `warnings.simplefilter("error", AccuracyWarning)` turns it into an exception.
    """


OUTER_ORDER = 5
PYRAMID_DEPTH = 2
FAR_RATIO = 0.5  # pairs with (radius1 + radius2) / distance below this may use one Gauss rule
NODE_CHUNK = 4096  # outer nodes handed to the inner integral at once (bounds memory)
RECENTRE_RATIO = 16.0  # patches further than this many bounding-box diagonals from the origin are moved
HORIZON_LEVELS = 4  # source cells cut by their own horizon are split to this level sum at least
SMOOTH_ORDERS = (6, 10, 16, 25)  # outer Gauss orders tried on smooth pairs before the adaptive method
PAIR_BUDGET = 30_000_000  # kernel evaluations per nested pair before refinement stops (20-40 s here)
RUN_TARGET = 0.5  # an adaptive run's absolute target is RUN_TARGET * tol * (its scale of F)
# a pair's first scale of F where its coarse rule sees nothing: this fraction of its geometric
# magnitude (a run that finds F far below the scale runs again with F as its scale, `_nested_pairs`)
SCALE_FLOOR = 1e-3
# a generic patch whose normals turn by less than this (radians, half the cone) is the inner side of
# a pair with a more curved generic patch: seen from the other, its kernel is seldom cut by a
# silhouette (measured both ways on the generic pairs of `benchmarks.kind_pairs`: BENCHMARKS.md)
FLAT_INNER = 1.0
ZERO_ERROR = 1e-15  # absolute errors below this meet any tol (float64 noise of a sum of factors <= 1)


# ---------------------------------------------------------------------------- public API
def form_factor(src, dst, tol=1e-6, method="adaptive", order=None, occluders=None):
    """Diffuse form factor F(src -> dst) between two patches, optionally occluded by third bodies.

    A point pair counts only where both front sides face each other and, with `occluders`, where
    the segment between them meets no occluder.

    Parameters
    ----------
    src, dst : Surface
        Emitting and receiving patches (may be the same patch: its self factor).
    tol : float
        Relative accuracy of the result (default method).
    method : {"adaptive", "gauss"}
        "adaptive" (default): error-controlled. "gauss": the seed paper's fixed tensor
        Gauss-Legendre rule with `order` points per parameter (no error control).
    order : int, optional
        Points per parameter for method="gauss".
    occluders : sequence of Surface, optional
        Bodies that block light between the pair (the pair's own patches in it are ignored):
        whole spheres or ellipsoids, flat quads or triangles, circular disk patches and round
        cylinder patches (`occluded.SHAPES`). Shadows are exact (`shadow`), the result meets `tol`
        with an honest error estimate. One of src and dst must be a flat quad, triangle or circular
        disk patch, or the outside of a round sphere or sphere patch (`sphere_target`), for now;
        no occluder may reach inside such a sphere.

    Returns
    -------
    float

    Warns
    -----
    AccuracyWarning
        If the work budget (`PAIR_BUDGET` kernel evaluations, 20-40 s) ran out before the
        estimated error met tol * F: the value is the best reached, the message gives the error
        estimate (`form_factor_estimate` returns it). Nothing is raised, so that a scene still
        gets its best values; the same rule holds for `form_factors` and `form_factor_estimate`.
    """
    return form_factor_estimate(src, dst, tol, method, order, occluders).value


def form_factor_estimate(src, dst, tol=1e-6, method="adaptive", order=None, occluders=None):
    """Like `form_factor`, also returning the error estimate and the kernel evaluations spent.

    Returns
    -------
    FormFactorEstimate
        (value, error, evaluations); with occluders, evaluations counts the lines integrated.
        error is the achieved estimate: above tol * value only when the budget ran out, which
        also warns (`AccuracyWarning`, as for `form_factor`). method="gauss" has no error
        control: error is NaN and nothing is checked.
    """
    _check_surface(src, "src")
    _check_surface(dst, "dst")
    occluders = _check_occluders(occluders)
    if not isinstance(method, str) or method not in ("adaptive", "gauss"):
        raise ValueError(f'method must be "adaptive" or "gauss", got {method!r}')
    if occluders:
        if method != "adaptive":
            raise ValueError('occluders need method="adaptive"')
        tol = checks.tolerance(tol)
        value, error, lines = occluded_form_factor(src, dst, occluders, tol)
        _check_accuracy(np.array([value]), np.array([error]), tol, "F(src -> dst)")
        return FormFactorEstimate(value, error, lines)
    if method == "gauss":
        if order is None:
            raise ValueError('method="gauss" needs order=n (points per parameter)')
        n = checks.count(order, "order", limit=checks.MAX_GAUSS_ORDER)
        return _fixed_gauss(src, dst, n)
    if order is not None:
        raise ValueError(f'order={order!r} is only used with method="gauss"')
    tol = checks.tolerance(tol)
    values, errors, evaluations = _solver_near_origin([src, dst]).pairs([0], [1], tol)
    _finite_result(values, f"F(src -> dst) at tol={tol!r}")
    _check_accuracy(values, errors, tol, "F(src -> dst)")
    return FormFactorEstimate(float(values[0]), float(errors[0]), int(evaluations))


def form_factors(sources, targets, tol=1e-6, occluders=None):
    """Matrix of form factors F[i, j] = F(sources[i] -> targets[j]).

    All pairs are integrated together (vectorised across pairs, in chunks that bound memory);
    each entry equals the single-pair `form_factor` result (within tol if the patches lie far
    from the origin for their size: they are then moved next to it first, see
    `_solver_near_origin`).

    Parameters
    ----------
    sources, targets : sequence of Surface
    tol : float
        Relative accuracy of every entry.
    occluders : sequence of Surface, optional
        As for `form_factor` (each pair ignores its own patches in the list).

    Returns
    -------
    ndarray, shape (len(sources), len(targets))

    Warns
    -----
    AccuracyWarning
        As for `form_factor`, once for all entries whose budget ran out (naming the worst).
    """
    sources, targets = _surface_list(sources, "sources"), _surface_list(targets, "targets")
    tol = checks.tolerance(tol)
    occluders = _check_occluders(occluders)
    if occluders:
        F = np.zeros((len(sources), len(targets)))
        E = np.zeros((len(sources), len(targets)))
        for i, src in enumerate(sources):  # (pairs one by one: each is vectorised inside)
            for j, dst in enumerate(targets):
                F[i, j], E[i, j], _ = occluded_form_factor(src, dst, occluders, tol)
        _check_accuracy(F.ravel(), E.ravel(), tol, "form_factors", len(targets))
        return F
    if not sources or not targets:
        return np.zeros((len(sources), len(targets)))
    solver = _solver_near_origin(sources + targets)
    i, j = np.meshgrid(np.arange(len(sources)), np.arange(len(targets)), indexing="ij")
    values, errors, _ = solver.pairs(i.ravel(), len(sources) + j.ravel(), tol)
    _finite_result(values, f"form_factors at tol={tol!r}")
    _check_accuracy(values, errors, tol, "form_factors", len(targets))
    return values.reshape(len(sources), len(targets))


def _check_occluders(occluders):
    """The occluder list (empty for None); ValueError for anything but a sequence of surfaces."""
    if occluders is None:
        return []
    if isinstance(occluders, Surface):
        raise ValueError("occluders must be a sequence of surfaces, got a single surface: wrap it in a list")
    try:
        occluders = list(occluders)
    except TypeError as exc:
        raise ValueError(f"occluders must be a sequence of surfaces, got {occluders!r}") from exc
    for k, s in enumerate(occluders):
        _check_surface(s, f"occluders[{k}]")
    return occluders


def _solver_near_origin(surfaces):
    """A `FormFactorSolver` for `surfaces`, moved next to the origin first if they lie far from it
    for their size.

    Form factors do not change under a translation, but float64 rounds every evaluated point to
    its magnitude: two unit spheres at x = 1e8 are evaluated with 1e-8 noise, which an adaptive
    integral at tol 1e-9 chases forever. Moved so that their bounding box is centred on the
    origin (when its centre is more than RECENTRE_RATIO diagonals away), the points are exact to
    1e-16 of the patches' size; the move itself shifts each input coordinate by at most one
    rounding. Nearby patches are not touched (the bounds come from the solver already built).
    """
    solver = FormFactorSolver(surfaces)
    lo = (solver.center - solver.radius[:, None]).min(0)
    hi = (solver.center + solver.radius[:, None]).max(0)
    centre = 0.5 * (lo + hi)
    if np.linalg.norm(centre) > RECENTRE_RATIO * np.linalg.norm(hi - lo):
        solver = FormFactorSolver(translated(surfaces, -centre))
    return solver


def _finite_result(values, what):
    """Raise FloatingPointError rather than return a NaN or infinite form factor."""
    if not np.all(np.isfinite(values)):
        raise FloatingPointError(
            f"{what} came out {values[~np.isfinite(values)][0]!r} (rounding broke an integral)"
        )


def _check_accuracy(values, errors, tol, what, columns=None):
    """Warn (`AccuracyWarning`) if any error estimate exceeds tol * value (and ZERO_ERROR).

    Only a spent work budget leaves such an estimate; the message names the worst entry (as
    [i, j] of a `columns`-wide matrix when given), its value and achieved error.
    """
    short = np.flatnonzero((errors > tol * np.abs(values)) & (errors > ZERO_ERROR))
    if not short.size:
        return
    relative = errors[short] / np.maximum(np.abs(values[short]), ZERO_ERROR)
    k = short[np.argmax(relative)]
    where = what if columns is None else f"{what}[{k // columns}, {k % columns}]"
    more = f" ({short.size} entries short of tol; the worst is shown)" if short.size > 1 else ""
    warnings.warn(
        f"{where} = {values[k]!r} has an estimated error of {errors[k]:.3g} ({relative.max():.3g} "
        f"relative), above tol={tol!r}: its work budget ({PAIR_BUDGET:,} kernel evaluations per pair) or "
        f"refinement depth ran out first{more}",
        AccuracyWarning,
        stacklevel=3,
    )


def _surface_list(surfaces, name):
    """`surfaces` as a list, each checked by `_check_surface`."""
    if isinstance(surfaces, Surface) or not hasattr(surfaces, "__iter__"):
        raise checks.ArgumentTypeError(f"{name} must be a sequence of core surfaces, got {surfaces!r}")
    surfaces = list(surfaces)
    for k, s in enumerate(surfaces):
        _check_surface(s, f"{name}[{k}]")
    return surfaces


def _check_surface(surface, name):
    if not isinstance(surface, Surface):
        raise checks.ArgumentTypeError(
            f"{name} must be a core surface (Sphere, Quad, Disk, Cylinder, NurbsSurface), got {surface!r}"
        )


# ---------------------------------------------------------------------------- the seed's method
def _fixed_gauss(src, dst, n):
    """The seed paper's rule: n-point Gauss-Legendre in each of the four parameters.

    F = sum_ij w_i w_j K(x_i, x_j) / sum_i w_i |n1(x_i)|, the area of src taken with the same
    rule (as in the paper), and both facing tests applied.
    """
    u1, v1, w1 = cell_nodes(np.array([np.ravel(src.domain)]), n)
    u2, v2, w2 = cell_nodes(np.array([np.ravel(dst.domain)]), n)
    x1, n1 = src.evaluate(u1[0], v1[0])
    x2, n2 = dst.evaluate(u2[0], v2[0])
    total = 0.0
    rows = max(1, 2_000_000 // x2.shape[0])
    for start in range(0, x1.shape[0], rows):
        part = slice(start, start + rows)
        k = kernel(x1[part, None], n1[part, None], x2[None], n2[None])
        total += (w1[0, part, None] * k * w2[0][None]).sum()
    area = (w1[0] * np.linalg.norm(n1, axis=-1)).sum()
    return FormFactorEstimate(float(total / area), float("nan"), n**4 + n**2)


# ---------------------------------------------------------------------------- the adaptive method
class FormFactorSolver:
    """Form factors among a fixed set of patches, for any list of (source, target) pairs.

    Parameters
    ----------
    surfaces : sequence of Surface
        The patches; pairs refer to them by index. Repeated objects are evaluated once.
    pyramid_depth : int
        Finest level of stored cell bounds (deeper cells are bounded on demand).
    """

    def __init__(self, surfaces, pyramid_depth=PYRAMID_DEPTH):
        unique = {}
        self.slot = np.array([unique.setdefault(id(s), len(unique)) for s in surfaces], dtype=np.int64)
        first = {}
        for s in surfaces:
            first.setdefault(id(s), s)
        self.set = SurfaceSet(list(first.values()))
        self.pyramid = Pyramid(self.set, np.arange(len(self.set)), pyramid_depth)
        self.plane_point = self.pyramid.plane_point
        self.inner = PointToPatch(self.set, self.pyramid)
        # flat quads: half the cross product of the diagonals (exact), from their corners at once
        c = self.inner.corners
        flat_area = 0.5 * lengths(np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1]))
        polygon = self.inner.kind == POLYGON
        self.area = np.array(
            [flat_area[k] if polygon[k] else s.area() for k, s in enumerate(self.set.surfaces)]
        )
        zero = np.zeros(len(self.set), dtype=np.int64)
        (self.center, self.radius, self.axis, self.half_angle, self.flat) = self.pyramid.bounds(
            np.arange(len(self.set)), zero, zero, zero, zero
        )
        # patches with an exact inner integral make the better inner side of a pair; whole
        # ellipsoids (a contour integral for points outside them) come next
        self.exact_inner = self.inner.kind != GENERIC
        self.fast_inner = self.exact_inner | self.inner.whole_ellipsoid
        self.closed = np.array([s.geometry.whole_ellipsoid(s.domain) for s in self.set.surfaces], dtype=bool)
        # for `_never_facing`: which patches share a geometry, and which are outward parts of
        # a convex body
        self.geometry_slot = self.set.group * len(self.set) + self.set.local
        self.convex_outward = np.array(
            [s.geometry.convex_outward and not s.is_flipped for s in self.set.surfaces], dtype=bool
        )

    # ------------------------------------------------------------------ pairs
    def pairs(self, source, target, tol):
        """F(source[k] -> target[k]) for index arrays into the constructor's list.

        Returns
        -------
        values, errors : ndarray, shape (P,)
        evaluations : int
        """
        a = self.slot[np.asarray(source, dtype=np.int64)]
        b = self.slot[np.asarray(target, dtype=np.int64)]
        values = np.zeros(a.size)
        errors = np.zeros(a.size)
        code1, code2 = self.visibility(a, b)
        live = (code1 != HIDDEN) & (code2 != HIDDEN) & ~self._never_facing(a, b)
        evaluations = 0

        # the flat side (exact inner integral) is the inner one; F(a->b) = F(b->a) A_b / A_a
        swap = live & self._swap(a, b, code1, code2)
        outer = np.where(swap, b, a)
        inner = np.where(swap, a, b)
        reciprocity = np.where(swap, self.area[b] / self.area[a], 1.0)

        # well-separated pairs that face each other fully: one tensor Gauss rule
        distance = np.linalg.norm(self.center[a] - self.center[b], axis=-1)
        ratio = np.divide(
            self.radius[a] + self.radius[b], distance, out=np.full(a.size, np.inf), where=distance > 0
        )
        far = live & (code1 == FULL) & (code2 == FULL) & (ratio < FAR_RATIO)
        sel = np.flatnonzero(far)
        if sel.size:
            v, e, ok, count = self._far_pairs(outer[sel], inner[sel], ratio[sel], tol)
            values[sel], errors[sel] = v, e
            far[sel] = ok
            evaluations += count

        # pairs whose outer integrand is smooth (an exact inner integral, no horizon or silhouette
        # crossing the inner patch): one outer Gauss rule of increasing order
        code_outer = np.where(swap, code2, code1)
        code_inner = np.where(swap, code1, code2)
        smooth = (
            live
            & ~far
            & self.fast_inner[inner]
            & (code_outer == FULL)
            & ((code_inner == FULL) | self.closed[inner])
        )
        sel = np.flatnonzero(smooth)
        if sel.size:
            v, e, ok, count = self._smooth_pairs(outer[sel], inner[sel], tol)
            values[sel], errors[sel] = v, e
            smooth[sel] = ok
            evaluations += count

        sel = np.flatnonzero(live & ~far & ~smooth)
        if sel.size:
            v, e, count = self._nested_pairs(outer[sel], inner[sel], tol)
            values[sel], errors[sel] = v, e
            evaluations += count
        # (adaptive sums replace a cell's value by its children's: rounding may leave -1e-19)
        return np.maximum(values, 0.0) * reciprocity, errors * reciprocity, evaluations

    def visibility(self, a, b):
        """Codes (HIDDEN, PARTIAL, FULL) for 'a faces b' and 'b faces a' over whole patches."""
        code1 = self._faces(a, b)
        code2 = self._faces(b, a)
        return code1, code2

    def _faces(self, a, b):
        """Whether n_a . (x_b - x_a) > 0 for all (FULL), no (HIDDEN) or some (PARTIAL) point pairs."""
        direction, spread, distance = direction_cone(
            self.center[a], self.center[b], self.radius[a] + self.radius[b]
        )
        code = cone_code(self.axis[a], self.half_angle[a], direction, spread)
        # a flat patch: the sign of n_a . (x_b - c_a) over b's bounding ball decides exactly
        height = np.einsum("ki,ki->k", self.axis[a], self.center[b] - self.plane_point[a])
        flat_code = facing_code(height, self.radius[b] + 1e-12 * (distance + self.radius[b]))
        return np.where(self.flat[a], flat_code, code)

    def _never_facing(self, a, b):
        """Pairs that provably exchange nothing: outward parts of one convex body, coplanar flats."""
        same = self.geometry_slot[a] == self.geometry_slot[b]
        convex_outward = self.convex_outward[a] & self.convex_outward[b]
        # two flat patches in one plane: every cosine is zero
        both_flat = self.flat[a] & self.flat[b]
        if not both_flat.any():
            return same & convex_outward
        parallel = lengths(np.cross(self.axis[a], self.axis[b])) <= 1e-12
        offset = np.abs(np.einsum("ki,ki->k", self.axis[a], self.plane_point[b] - self.plane_point[a]))
        size = self.radius[a] + self.radius[b] + lengths(self.center[a])
        coplanar = both_flat & parallel & (offset <= 1e-12 * size)
        return (same & convex_outward) | coplanar

    def _swap(self, a, b, code1, code2):
        """Whether to integrate F(b -> a) (outer over b, inner over a) and use reciprocity.

        The inner side should have an exact inner integral (or, failing that, be a whole
        ellipsoid: a contour integral, `ellipsoid.whole_ellipsoid`). When both are exact, the outer integrand
        should be smooth: it is when the outer side's horizon never cuts the inner patch and the
        inner patch is either wholly facing it or closed (a whole sphere: its silhouette never
        meets a patch border). Otherwise a flat polygon is the preferred inner side. When neither
        side is exact nor a whole ellipsoid, a nearly flat patch (normals within FLAT_INNER of its
        axis) is the inner side of a pair with a more curved one.
        """
        exact_a, exact_b = self.exact_inner[a], self.exact_inner[b]
        fast_a, fast_b = self.fast_inner[a], self.fast_inner[b]
        polygon_a = self.inner.kind[a] == POLYGON
        polygon_b = self.inner.kind[b] == POLYGON
        smooth_outer_a = (code1 == FULL) & ((code2 == FULL) | self.closed[b])
        smooth_outer_b = (code2 == FULL) & ((code1 == FULL) | self.closed[a])
        prefer_b = np.where(smooth_outer_a != smooth_outer_b, smooth_outer_b, polygon_a & ~polygon_b)
        # neither exact: a whole ellipsoid (contour inner integral) is the better inner side; with
        # neither fast either, a nearly flat patch (a silhouette seldom crosses it)
        neither = ~exact_a & ~exact_b & ~fast_a & ~fast_b
        flat_a, flat_b = self.half_angle[a] < FLAT_INNER, self.half_angle[b] < FLAT_INNER
        better_a = (exact_a & ~exact_b) | (~exact_a & ~exact_b & fast_a & ~fast_b)
        better_a |= neither & flat_a & ~flat_b
        return np.where(exact_a & exact_b, prefer_b, better_a)

    # ------------------------------------------------------------------ far pairs
    def _far_pairs(self, a, b, ratio, tol):
        """One tensor Gauss rule per pair, order from the distance-to-size ratio.

        The error of an n-point rule falls roughly like ratio^(2n); the rule with n + 1 points is
        accepted when it agrees with the n-point one to within tol/2.

        Returns
        -------
        values, errors : ndarray, shape (P,)
        ok : ndarray of bool, shape (P,)
            Whether the estimate met the tolerance (the rest need the adaptive method).
        evaluations : int
        """
        n = np.clip(np.ceil(np.log(0.1 * tol) / (2.0 * np.log(np.maximum(ratio, 1e-3)))), 2, 8).astype(int)
        values = np.zeros(a.size)
        errors = np.zeros(a.size)
        evaluations = 0
        for order in np.unique(n):
            sel = np.flatnonzero(n == order)
            coarse, count1 = self._tensor_gauss(a[sel], b[sel], order)
            fine, count2 = self._tensor_gauss(a[sel], b[sel], order + 1)
            values[sel], errors[sel] = fine, np.abs(fine - coarse)
            evaluations += count1 + count2
        return values, errors, errors <= 0.5 * tol * np.abs(values), evaluations

    def _tensor_gauss(self, a, b, n):
        """F(a -> b) by an n-point Gauss rule per parameter on both patches, shape (P,)."""
        s, t, w = tensor_rule(n)
        q = s.size
        box_a, box_b = self.set.boxes[a], self.set.boxes[b]
        ua = box_a[:, :1] + (box_a[:, 1] - box_a[:, 0])[:, None] * s
        va = box_a[:, 2:3] + (box_a[:, 3] - box_a[:, 2])[:, None] * t
        ub = box_b[:, :1] + (box_b[:, 1] - box_b[:, 0])[:, None] * s
        vb = box_b[:, 2:3] + (box_b[:, 3] - box_b[:, 2])[:, None] * t
        xa, na = self.set.evaluate(np.repeat(a, q), ua.ravel(), va.ravel())
        xb, nb = self.set.evaluate(np.repeat(b, q), ub.ravel(), vb.ravel())
        xa, na = xa.reshape(-1, q, 1, 3), na.reshape(-1, q, 1, 3)
        xb, nb = xb.reshape(-1, 1, q, 3), nb.reshape(-1, 1, q, 3)
        k = kernel(xa, na, xb, nb)
        jac = (
            (box_a[:, 1] - box_a[:, 0])
            * (box_a[:, 3] - box_a[:, 2])
            * (box_b[:, 1] - box_b[:, 0])
            * (box_b[:, 3] - box_b[:, 2])
        )
        return np.einsum("pij,i,j->p", k, w, w) * jac / self.area[a], a.size * q * q

    # ------------------------------------------------------------------ smooth pairs
    def _smooth_pairs(self, a, b, tol):
        """Outer Gauss rules of increasing order over a, with b's exact inner integral.

        For pairs whose integrand F(dA_a -> b) is smooth over a (`pairs` selects them: b has an
        exact inner integral, every cell of a faces b, and b wholly faces a or is a closed
        sphere) the error of an n-point rule per parameter falls geometrically with n. The
        orders SMOOTH_ORDERS are tried in turn; a pair is accepted at the first order whose
        value differs from the previous order's by at most tol/2 of it (plus the inner
        integrals' own errors), the difference being its error estimate (as `_far_pairs`).

        Returns
        -------
        values, errors : ndarray, shape (P,)
        ok : ndarray of bool, shape (P,)
            Whether the pair met tol (the rest need the adaptive method).
        evaluations : int
        """
        # absolute targets of inner integrals that are not closed forms (far points): from a
        # geometric magnitude first, then from the previous order's value
        floor = 1e-6 * self._magnitude(a, b)
        tolerance = 0.1 * tol * floor
        evaluations = 0
        values = np.zeros(a.size)
        errors = np.full(a.size, np.inf)
        ok = np.zeros(a.size, dtype=bool)
        previous = None
        todo = np.arange(a.size)
        for n in SMOOTH_ORDERS:
            value, inner_error, count = self._outer_gauss(a[todo], b[todo], n, tolerance[todo])
            evaluations += count
            tolerance[todo] = 0.1 * tol * np.maximum(np.abs(value), floor[todo])
            if previous is not None:
                error = np.abs(value - previous) + inner_error
                done = error <= 0.5 * tol * np.abs(value)
                values[todo], errors[todo] = value, error
                ok[todo[done]] = True
                todo, value = todo[~done], value[~done]
                if not todo.size:
                    break
            previous = value
        return values, errors, ok, evaluations

    def _outer_gauss(self, a, b, n, tolerance):
        """F(a -> b) by an n-point Gauss rule per parameter over a and the inner integral over b.

        Returns
        -------
        values, errors : ndarray, shape (P,)
            Values and the inner integrals' error (weighted like the values).
        evaluations : int
        """
        s, t, w = tensor_rule(n)
        q = s.size
        box = self.set.boxes[a]
        du, dv = box[:, 1] - box[:, 0], box[:, 3] - box[:, 2]
        u = box[:, :1] + du[:, None] * s
        v = box[:, 2:3] + dv[:, None] * t
        x, normal = self.set.evaluate(np.repeat(a, q), u.ravel(), v.ravel())
        density = lengths(normal)
        unit = normal / np.where(density > 0, density, 1.0)[:, None]
        targets = np.repeat(b, q)
        node_tolerance = np.repeat(tolerance, q)
        f = np.zeros(targets.size)
        f_error = np.zeros(targets.size)
        evaluations = 0
        for start in range(0, targets.size, NODE_CHUNK):
            part = slice(start, start + NODE_CHUNK)
            f[part], f_error[part], count = self.inner(
                x[part], unit[part], targets[part], node_tolerance[part]
            )
            evaluations += count
        weight = (density * np.tile(w, a.size)).reshape(-1, q) * (du * dv / self.area[a])[:, None]
        return (weight * f.reshape(-1, q)).sum(1), (weight * f_error.reshape(-1, q)).sum(1), evaluations

    # ------------------------------------------------------------------ nested adaptive pairs
    def _nested_pairs(self, a, b, tol):
        """Adaptive outer integral over a of the inner factor F(dA1 -> b).

        The absolute targets scale with a first estimate of each F; a pair whose result is far
        below that estimate is run again with the result as its scale.

        Work is bounded: the runs of a pair stop refining once together they have spent about
        PAIR_BUDGET kernel evaluations per pair (and each inner integral has its own per-point
        budget). A pair that hits the budget returns its best value with the error estimate it
        reached, which is then above tol * value: the public entries warn (`AccuracyWarning`).
        Only a run that met its own target is run again with a finer scale (one that ran out of
        budget would only run out again, at twice the cost).
        """
        scale, evaluations = self._scale(a, b)
        budget = PAIR_BUDGET * a.size
        values, errors, count = self._nested_run(a, b, tol, scale, budget - evaluations)
        evaluations += count
        # results below 1e-9 of the first estimate's floor are rounding noise of an exact zero
        # (a patch touching the other's plane from behind), not worth a finer scale
        floor = 1e-9 * scale
        for _ in range(2):
            met_target = errors <= RUN_TARGET * tol * scale
            again = (values > floor) & (errors > tol * values) & met_target
            if not again.any() or evaluations >= budget:
                break
            sel = np.flatnonzero(again)
            scale = scale.copy()
            scale[sel] = np.minimum(scale[sel], values[sel]) * 0.25
            v, e, count = self._nested_run(a[sel], b[sel], tol, scale[sel], budget - evaluations)
            values[sel], errors[sel] = v, e
            evaluations += count
        return values, errors, evaluations

    def _scale(self, a, b):
        """A first estimate of F(a -> b) to scale the error targets (4-point rules, clipped)."""
        coarse, evaluations = self._tensor_gauss(a, b, 4)
        # a geometric magnitude keeps targets finite where the coarse rule sees nothing
        return np.maximum(coarse, SCALE_FLOOR * self._magnitude(a, b)), evaluations

    def _magnitude(self, a, b):
        """A geometric magnitude of F(a -> b): b's area over pi d^2 (clipped to 1), shape (P,)."""
        distance = np.linalg.norm(self.center[a] - self.center[b], axis=-1) + self.radius[a] + self.radius[b]
        return np.minimum(1.0, self.area[b] / (np.pi * distance**2))

    def _nested_run(self, a, b, tol, scale, budget):
        """One adaptive run to the absolute target RUN_TARGET * tol * scale per pair, within
        `budget` kernel evaluations for all pairs together; (values, errors, evaluations)."""
        node_tolerance = 0.25 * tol * scale
        rule_s, rule_t, rule_w = tensor_rule(OUTER_ORDER)
        q = rule_s.size
        spent = 0  # kernel evaluations so far: the inner integrals share what is left

        def evaluate(cells):
            nonlocal spent
            pa, pb = a[cells.item], b[cells.item]
            box = self.set.cell_boxes(pa, cells.lu, cells.lv, cells.i, cells.j)
            center, radius, axis, half, flat = self.pyramid.bounds(pa, cells.lu, cells.lv, cells.i, cells.j)
            # cull cells of a that cannot face b (or that b cannot face)
            direction, spread, distance = direction_cone(center, self.center[pb], radius + self.radius[pb])
            code1 = cone_code(axis, half, direction, spread)
            code2 = cone_code(self.axis[pb], self.half_angle[pb], -direction, spread)
            height = np.einsum("ki,ki->k", self.axis[pb], center - self.plane_point[pb])
            code2 = np.where(self.flat[pb], facing_code(height, radius + 1e-12 * (distance + radius)), code2)
            hidden = (code1 == HIDDEN) | (code2 == HIDDEN)
            value = np.zeros(len(pa))
            extra = np.zeros(len(pa))
            sel = np.flatnonzero(~hidden)
            evaluations = 0
            if sel.size:
                u = box[sel, :1] + (box[sel, 1] - box[sel, 0])[:, None] * rule_s
                v = box[sel, 2:3] + (box[sel, 3] - box[sel, 2])[:, None] * rule_t
                w = ((box[sel, 1] - box[sel, 0]) * (box[sel, 3] - box[sel, 2]))[:, None] * rule_w
                x1, n1 = self.set.evaluate(np.repeat(pa[sel], q), u.ravel(), v.ravel())
                density = lengths(n1)
                unit = n1 / np.where(density > 0, density, 1.0)[:, None]
                targets = np.repeat(pb[sel], q)
                tolerance = np.repeat(node_tolerance[cells.item[sel]], q)
                f = np.zeros(len(targets))
                f_error = np.zeros(len(targets))
                for start in range(0, len(targets), NODE_CHUNK):
                    part = slice(start, start + NODE_CHUNK)
                    f[part], f_error[part], count = self.inner(
                        x1[part], unit[part], targets[part], tolerance[part], max(budget - spent, 0)
                    )
                    evaluations += count
                    spent += count
                weight = w.ravel() * density
                value[sel] = (weight * f).reshape(-1, q).sum(1)
                extra[sel] = (weight * f_error).reshape(-1, q).sum(1)
            # a source cell cut by its own horizon may hide a thin visible sliver: look closer
            # (unless b's hull is on or above every tangent plane of the cell)
            forced = (code1 == PARTIAL) & ~hidden & (cells.lu + cells.lv < HORIZON_LEVELS)
            sel = np.flatnonzero(forced)
            if sel.size:
                bounds = (center[sel], radius[sel], axis[sel], half[sel], flat[sel])
                forced[sel[self.inner.hull_above(*bounds, pb[sel])]] = False
            return value, extra, forced, evaluations

        total, error, evaluations = integrate_cells(
            evaluate, a.size, RUN_TARGET * tol * scale * self.area[a], max_evaluations=max(budget, 1)
        )
        return total / self.area[a], error / self.area[a], evaluations
