"""Rational tensor-product B-spline (NURBS) surfaces, and Blender's rule for their knot vectors.

P(u, v) = sum_ij N_i(u) M_j(v) w_ij P_ij / sum_ij N_i(u) M_j(v) w_ij, with B-spline bases N (order
k_u = degree + 1 over knots_u) and M (order k_v over knots_v). Basis functions and their first
derivatives follow Piegl & Tiller, "The NURBS Book" (2nd ed., 1997), algorithms A2.1 (span),
A2.2 (basis functions) and A2.3 (derivatives); the surface and its rational derivatives follow
A3.5/A3.6 and A4.3/A4.4, evaluated on homogeneous points (w P, w) and finished by the quotient
rule. Everything is vectorised over the evaluation points; loops run over the degree only.

Precision anywhere: the surface is evaluated in a local frame (control points centred and
divided by the net's size, weights divided by the largest), and the basis is formed from
offsets inside a knot span, so rounding is relative to the surface itself whatever its
position, weights or span lengths. The area is integrated per knot span in the span's own
coordinates by bounded adaptive cubature (`NurbsGeometry.area`), with a work budget.
"""

import numpy as np

from . import checks
from .quadrature import gauss_legendre
from .quadric import exact_ellipsoid
from .surface import Geometry, Surface

AREA_RTOL = 1e-12  # target relative error of NurbsSurface.area
AREA_ACCEPT = 1e-9  # area() raises if the budget stops it above this relative error
AREA_BUDGET = 4_000_000  # surface evaluations one area may use
AREA_GAUSS = 8  # Gauss points per direction of an area cell
AREA_MAX_LEVEL = 60  # cells halved 60 times are below float64's resolution of their span
AREA_NOISE = 64.0  # rounding noise of a cell value, in eps times its sum of |dp/ds| |dp/dt|
CHUNK = 1 << 16  # points evaluated per vectorised call (bounds temporary memory)
MIN_DOMAIN = 1e-30  # narrowest natural domain (knot units): derivatives grow like 1 / width
_UNKNOWN = object()  # a lazily computed attribute not computed yet


# --------------------------------------------------------------------------- Blender's knots
def blender_knots(count, order, endpoint=False, bezier=False, cyclic=False):
    """The knot vector Blender builds for one direction of a NURBS spline.

    Our own statement of the rule in `calcknots` (source/blender/blenkernel/intern/curve.cc,
    called by `BKE_nurb_knot_calc_u/v`; the rule of Blender 5.0, checked against the
    tessellation of bpy 5.0.1 in tests/test_nurbs_blender.py), with knots counted from 0 in
    steps of 1:

    - every interior knot value is repeated `m` times: m = order - 1 for Bezier, else 1;
    - the first value 0 is repeated `order` times with `endpoint`, else min(2, m) times for
      Bezier, else once;
    - not cyclic: `count + order` knots; with `endpoint` the last value is repeated `order`
      times (an incomplete last group merges into it);
    - cyclic: `count + 2 order - 1` knots for the `count + order - 1` control points P_0 ..
      P_{count-1}, P_0 .. P_{order-2} (Blender wraps the points, see `wrap_cyclic`). The first
      `count` knots follow the rules above (with `endpoint` the head is one 0 followed by
      `order - 1` copies of 1) and the last `2 order - 1` knots repeat the spacing of the first
      ones, shifted to continue after them.

    Parameters
    ----------
    count : int
        Number of control points in this direction (before cyclic wrapping).
    order : int
        Degree + 1, with 2 <= order <= count.

    Returns
    -------
    ndarray, shape (count + order,) or (count + 2 order - 1,) if cyclic
    """
    repeat = order - 1 if bezier else 1
    total = count + order + (order - 1 if cyclic else 0)
    tail = 2 * order - 1 if cyclic else (order if endpoint else 0)
    # head: the multiplicity of the first value; with endpoint and cyclic a lone 0 comes first
    head = order - (1 if cyclic else 0) if endpoint else (min(2, repeat) if bezier else 1)
    lone = 1 if endpoint and cyclic else 0
    # the first total - tail knots: the lone 0, `head` copies of the next value, then groups
    ranks = np.arange(total - tail - lone)
    groups = np.where(ranks < head, 0, (ranks - head) // repeat + 1)
    knots = np.concatenate([np.zeros(lone), lone + groups]).astype(np.float64)
    # the value after the last complete group carries on into the tail
    done = total - tail - lone
    current = lone + (0 if done < head else (done - head) // repeat + 1)
    out = np.empty(total)
    out[: total - tail] = knots
    for i in range(tail):
        out[total - tail + i] = current + out[i] - out[0]
    return out


def wrap_cyclic(points, order, axis):
    """Append the first `order - 1` control points along `axis` (Blender's cyclic splines).

    Blender evaluates a cyclic spline of n points as an open spline of n + order - 1 points
    (`BKE_nurb_makeFaces`, `basisNurb` called with pnts + order - 1 and index i wrapped to
    i - n), over the parameter range [knots[order - 1], knots[n + order - 1]].
    """
    head = np.take(points, np.arange(order - 1), axis=axis)
    return np.concatenate([points, head], axis=axis)


# --------------------------------------------------------------------------- B-spline basis
def nonempty_spans(knots, order, count):
    """Spans [knots[i], knots[i+1]) of positive length inside the natural domain.

    Returns
    -------
    spans : ndarray of int, shape (S,)
        Span indices i with order - 1 <= i <= count - 1 and knots[i] < knots[i + 1].
    starts : ndarray, shape (S,)
        knots[spans], increasing.
    """
    p = order - 1
    spans = p + np.flatnonzero(knots[p:count] < knots[p + 1 : count + 1])
    return spans, knots[spans]


def find_spans(spans, starts, t):
    """The knot span holding each parameter (Piegl & Tiller A2.1, by binary search).

    The last span is closed, so t = knots[count] (the end of the domain) uses it.

    Parameters
    ----------
    spans, starts : from `nonempty_spans`
    t : ndarray, shape (K,)

    Returns
    -------
    ndarray of int, shape (K,)
    """
    index = np.searchsorted(starts, t, side="right") - 1
    return spans[np.clip(index, 0, spans.size - 1)]


def span_basis(knots, order, span, offset, width=None):
    """The order nonzero basis functions at t = knots[span] + offset, and width * dN/dt.

    Piegl & Tiller A2.2 (Cox-de Boor triangle) and A2.3 restricted to the first derivative:
    the quotients N_{r, p-1} / (knot difference) of the last stage give both N_{r,p} and
    N'_{r,p} = p (quotient_{r-1} - quotient_r). Every distance t - knots[k] is formed as
    (knots[span] - knots[k]) + offset, so a parameter inside a span as short as 1e-300 keeps
    its full relative precision; the quotients are multiplied by `width` / (knot difference)
    <= 1 (every denominator covers the non-empty span), so nothing overflows however short
    the span is.

    Parameters
    ----------
    knots : ndarray, shape (L,)
    order : int
        Degree p + 1 >= 2.
    span : ndarray of int, shape (K,)
        Non-empty span index of each point (see `find_spans`).
    offset : ndarray, shape (K,)
        t - knots[span], in [0, knots[span + 1] - knots[span]].
    width : ndarray, shape (K,), optional
        The length the derivative is measured in; default the span's length h, which gives
        h dN/dt, bounded by p.

    Returns
    -------
    N, dN : ndarray, shape (K, order)
        Values of N_{span - p + r, p}, r = 0 .. p, and `width` times their t-derivatives.
    """
    p = order - 1
    base = knots[span]
    width = knots[span + 1] - base if width is None else width
    values = [np.ones_like(offset)]
    derivative = [np.zeros_like(offset)]
    for j in range(1, p + 1):
        # raise the degree from j - 1 to j; quotient r divides by knots[span+r+1] - knots[span+r+1-j]
        right = [knots[span + r + 1] - base for r in range(j)]
        left = [base - knots[span + r + 1 - j] for r in range(j)]
        scaled = [values[r] / (right[r] + left[r]) for r in range(j)]
        new = [np.zeros_like(offset) for _ in range(j + 1)]
        for r, q in enumerate(scaled):
            new[r] += (right[r] - offset) * q
            new[r + 1] += (left[r] + offset) * q
        if j == p:
            padded = [np.zeros_like(offset)] + [q * width for q in scaled] + [np.zeros_like(offset)]
            derivative = [p * (padded[r] - padded[r + 1]) for r in range(p + 1)]
        values = new
    return np.stack(values, -1), np.stack(derivative, -1)


def basis_functions(knots, order, span, t):
    """The order nonzero basis functions at t and their first derivatives.

    `span_basis` at offset t - knots[span], with the derivative in units of t.

    Parameters
    ----------
    knots : ndarray, shape (L,)
    order : int
        Degree p + 1 >= 2.
    span : ndarray of int, shape (K,)
        Non-empty span index of each t (see `find_spans`).
    t : ndarray, shape (K,)

    Returns
    -------
    N, dN : ndarray, shape (K, order)
        Values and t-derivatives of N_{span - p + r, p}, r = 0 .. p.
    """
    N, scaled = span_basis(knots, order, span, t - knots[span])
    return N, scaled / (knots[span + 1] - knots[span])[:, None]


# --------------------------------------------------------------------------- geometry
class NurbsGeometry(Geometry):
    """A NURBS surface with validated float64 data (see `NurbsSurface` for the meaning).

    Parameters
    ----------
    points : ndarray, shape (nu, nv, 3)
    weights : ndarray, shape (nu, nv)
    order_u, order_v : int
    knots_u, knots_v : ndarray, shapes (nu + order_u,), (nv + order_v,)
    handedness : {+1, -1}
    """

    def __init__(self, points, weights, order_u, order_v, knots_u, knots_v, handedness=1):
        self.points = np.array(points, dtype=np.float64)
        self.weights = np.array(weights, dtype=np.float64)
        self.order_u, self.order_v = int(order_u), int(order_v)
        self.knots_u = np.array(knots_u, dtype=np.float64)
        self.knots_v = np.array(knots_v, dtype=np.float64)
        self.handedness = handedness
        nu, nv = self.weights.shape
        self.natural_domain = (
            (float(self.knots_u[self.order_u - 1]), float(self.knots_u[nu])),
            (float(self.knots_v[self.order_v - 1]), float(self.knots_v[nv])),
        )
        self._spans_u = nonempty_spans(self.knots_u, self.order_u, nu)
        self._spans_v = nonempty_spans(self.knots_v, self.order_v, nv)
        # local frame: x = origin + scale * p with the control net centred in a unit box, so
        # rounding is relative to the surface's own size wherever it sits
        flat = self.points.reshape(-1, 3)
        lo, hi = flat.min(0), flat.max(0)
        self.size = float((hi - lo).max())
        self.origin = 0.5 * (lo + hi)
        self.scale = self.size if self.size > 0.0 else 1.0
        local = (self.points - self.origin) / self.scale
        # homogeneous local control points (w p, w), weights divided by the largest (P is unchanged)
        w = self.weights / self.weights.max()
        self._homogeneous = np.concatenate([local * w[..., None], w[..., None]], -1)
        for a in (self.points, self.weights, self.knots_u, self.knots_v, self.origin, self._homogeneous):
            a.setflags(write=False)
        self._plane = self._find_plane()
        self._ellipsoid = _UNKNOWN  # `quadric.exact_ellipsoid` (an Ellipsoid or None), on first use

    def local_derivatives(self, su, offset_u, width_u, sv, offset_v, width_v):
        """Local-frame points and derivatives on given knot spans (Piegl & Tiller A3.5, A4.4).

        The point with u = knots_u[su] + offset_u, v = knots_v[sv] + offset_v, in the frame
        p = (x - origin) / scale, with derivatives along s = (u - u_start) / width_u and
        t = (v - v_start) / width_v: dp/ds = width_u dp/du. Values stay of the order of one
        for any translation, weights and span lengths (see `span_basis`).

        Parameters
        ----------
        su, sv : ndarray of int, shape (K,)
            Non-empty span indices (into `knots_u`, `knots_v`).
        offset_u, offset_v : ndarray, shape (K,)
            Parameter minus the span's first knot.
        width_u, width_v : ndarray, shape (K,)
            Lengths the derivatives are measured in.

        Returns
        -------
        p, ps, pt : ndarray, shape (K, 3)
        """
        Nu, dNu = span_basis(self.knots_u, self.order_u, su, offset_u, width_u)
        Nv, dNv = span_basis(self.knots_v, self.order_v, sv, offset_v, width_v)
        # sum the homogeneous control points row by row (A3.5): A, dA/ds, dA/dt
        cols = sv[:, None] - (self.order_v - 1) + np.arange(self.order_v)
        A = np.zeros((su.size, 4))
        As = np.zeros((su.size, 4))
        At = np.zeros((su.size, 4))
        for a in range(self.order_u):
            rows = self._homogeneous[(su - (self.order_u - 1) + a)[:, None], cols]
            along = np.einsum("kb,kbc->kc", Nv, rows)
            A += Nu[:, a, None] * along
            As += dNu[:, a, None] * along
            At += Nu[:, a, None] * np.einsum("kb,kbc->kc", dNv, rows)
        # project: p = A / w and the quotient rule for the derivatives (A4.4, k = 1)
        w = A[:, 3:]
        p = A[:, :3] / w
        return p, (As[:, :3] - As[:, 3:] * p) / w, (At[:, :3] - At[:, 3:] * p) / w

    def derivatives(self, u, v):
        """Points and first derivatives (Piegl & Tiller A4.4 to first order).

        Parameters are clamped to `natural_domain`, as Blender's `basisNurb` does, so the
        rational denominator stays >= the smallest weight. Evaluated in the local frame
        (`local_derivatives`) and mapped back, so the derivatives keep their relative precision
        far from the origin.

        Parameters
        ----------
        u, v : array_like, broadcastable to shape S

        Returns
        -------
        P, Pu, Pv : ndarray, shape S + (3,)
        """
        u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
        shape = u.shape
        (u0, u1), (v0, v1) = self.natural_domain
        u = np.clip(u.ravel(), u0, u1)
        v = np.clip(v.ravel(), v0, v1)
        # find the spans; derivatives per span length, then per unit parameter
        su = find_spans(*self._spans_u, u)
        sv = find_spans(*self._spans_v, v)
        hu = self.knots_u[su + 1] - self.knots_u[su]
        hv = self.knots_v[sv + 1] - self.knots_v[sv]
        p, ps, pt = self.local_derivatives(su, u - self.knots_u[su], hu, sv, v - self.knots_v[sv], hv)
        P = self.origin + self.scale * p
        Pu = ps * (self.scale / hu)[:, None]
        Pv = pt * (self.scale / hv)[:, None]
        return P.reshape(shape + (3,)), Pu.reshape(shape + (3,)), Pv.reshape(shape + (3,))

    def transformed(self, linear, offset):
        """The image under x -> linear @ x + offset (NURBS are affine invariant)."""
        hand = self.handedness * (1 if np.linalg.det(linear) > 0 else -1)
        return NurbsGeometry(
            self.points @ np.asarray(linear).T + offset,
            self.weights,
            self.order_u,
            self.order_v,
            self.knots_u,
            self.knots_v,
            hand,
        )

    def span_cells(self, box):
        """The pieces of a parameter box inside single knot spans, where P is one rational patch.

        Returns
        -------
        cells : ndarray, shape (C, 6)
            Rows (span_u, offset_u, width_u, span_v, offset_v, width_v): the piece covers
            u in knots_u[span_u] + offset_u + [0, width_u], and likewise in v. Spans of zero
            length never appear; a piece of a span as short as 1e-300 keeps its exact width.
        """
        axes = []
        for (lo, hi), knots, (spans, first) in zip(
            box, (self.knots_u, self.knots_v), (self._spans_u, self._spans_v)
        ):
            last = knots[spans + 1]
            keep = (last > lo) & (first < hi)
            spans, first, last = spans[keep], first[keep], last[keep]
            start, end = np.maximum(first, lo), np.minimum(last, hi)
            # a whole span keeps the exact difference of its knots as width
            width = np.where((start == first) & (end == last), last - first, end - start)
            axes.append(np.stack([spans, start - first, width], -1)[width > 0.0])
        cu, cv = axes
        return np.concatenate([np.repeat(cu, len(cv), 0), np.tile(cv, (len(cu), 1))], -1)

    def area(self, box, rtol=None, max_evaluations=None):
        """Area over a parameter box by bounded adaptive Gauss cubature in the local frame.

        The integrand |dp/ds x dp/dt| is integrated over each piece of the box inside one
        knot span (`span_cells`), in that piece's own coordinates (s, t) in [0, 1]^2, so short
        spans, translations and weights change no tolerance. Each cell carries an n x n
        Gauss-Legendre value (n = `AREA_GAUSS`) and is compared with both of its halvings; the
        halves that differ more from it are kept (so refinement follows thin layers along a
        knot line, which large weights make, at the cost of a line rather than a plane: the
        direction choice of Genz & Malik, J. Comput. Appl. Math. 6 (1980) 295, by a
        difference instead of a fourth difference). A cell is accepted when the difference is
        within its share of `rtol`, or within the rounding noise of float64 (where no
        refinement could tell the two apart); all cells of one level are evaluated in one
        vectorised pass, in chunks of `CHUNK` points, and the loop stops before the work
        budget or `AREA_MAX_LEVEL` halvings.

        Parameters
        ----------
        box : ((u0, u1), (v0, v1))
        rtol : float, optional
            Target relative error, default `AREA_RTOL`.
        max_evaluations : int, optional
            Work budget in surface evaluations, default `AREA_BUDGET`; refinement stops
            before exceeding it.

        Returns
        -------
        value, error : float
            Area (m^2) and an estimate of its absolute error: the sum over accepted cells of
            |parent - halves| plus that of the cells still pending when the budget ran out
            (inf if it ran out before any comparison). Once the halves resolve the integrand
            (a relative estimate below about 1e-6) it is pessimistic, as the halves' value is
            returned; a large estimate only says the budget was too small, its value may be
            exceeded by the true error.
        evaluations : int
        """
        rtol = AREA_RTOL if rtol is None else float(rtol)
        max_evaluations = AREA_BUDGET if max_evaluations is None else int(max_evaluations)
        cells = self.span_cells(box)
        # each knot cell gets an equal share of the tolerance, halved with each split
        share = np.full(len(cells), 1.0 / max(len(cells), 1))
        values, _ = self._cell_rule(cells)
        evaluations = values.size * AREA_GAUSS**2
        # until a first comparison the error is unknown
        accepted, error, pending_error = 0.0, 0.0, np.inf
        for level in range(AREA_MAX_LEVEL + 1):
            if cells.size == 0:
                break
            if level == AREA_MAX_LEVEL or evaluations + 4 * len(cells) * AREA_GAUSS**2 > max_evaluations:
                # out of budget: keep the pending values with their parents' differences as error
                accepted += values.sum()
                error += pending_error
                break
            # both ways of halving every cell: along u (rows 0, 1) and along v (rows 2, 3)
            halves = _halves(cells)
            half_values, half_magnitudes = self._cell_rule(halves)
            evaluations += half_values.size * AREA_GAUSS**2
            pairs = half_values.reshape(-1, 2, 2).sum(2)
            diffs = np.abs(pairs - values[:, None])
            # split where the parent differs most from its halves; keep those halves' value
            along = np.argmax(diffs, 1)
            rows = np.arange(len(cells))
            sums, diff = pairs[rows, along], diffs[rows, along]
            total = accepted + sums.sum()
            noise = AREA_NOISE * np.finfo(float).eps * half_magnitudes.reshape(-1, 4).sum(1)
            done = (diff <= 0.5 * rtol * (sums + total * share)) | (diff <= noise)
            accepted += sums[done].sum()
            error += diff[done].sum()
            pending_error = diff[~done].sum()
            # the kept halves of the cells still pending become the next cells
            keep = (4 * rows + 2 * along)[~done]
            kept = np.stack([keep, keep + 1], 1).ravel()
            cells, values, share = halves[kept], half_values[kept], np.repeat(share[~done] / 2, 2)
        return self.scale**2 * accepted, self.scale**2 * error, evaluations

    def cell_derivatives(self, cells, s, t):
        """Local-frame points and derivatives on the tensor grid s x t of each cell.

        The same quantities as `local_derivatives`, for grid node (i, j) of cell c at
        u = knots_u[span_u] + offset_u + width_u s_i (likewise v), with derivatives along the
        cell's own coordinates (dp/ds = width_u dp/du). Each cell lies in one knot span, so its
        order_u x order_v control points are gathered once and the basis is evaluated once per
        grid line (the tensor-product form of Piegl & Tiller A3.5).

        Parameters
        ----------
        cells : ndarray, shape (C, 6)
            Rows as in `span_cells`.
        s, t : ndarray, shapes (n,) and (m,)
            Nodes in [0, 1].

        Returns
        -------
        p, ps, pt : ndarray, shape (C, n, m, 3)
        """
        C, n, m = len(cells), s.size, t.size
        su = cells[:, 0].astype(np.int64)
        sv = cells[:, 3].astype(np.int64)
        # basis along each grid line: shapes (C, n, order_u) and (C, m, order_v)
        offset_u = (cells[:, 1:2] + cells[:, 2:3] * s).ravel()
        offset_v = (cells[:, 4:5] + cells[:, 5:6] * t).ravel()
        Nu, dNu = span_basis(
            self.knots_u, self.order_u, np.repeat(su, n), offset_u, np.repeat(cells[:, 2], n)
        )
        Nv, dNv = span_basis(
            self.knots_v, self.order_v, np.repeat(sv, m), offset_v, np.repeat(cells[:, 5], m)
        )
        Nu, dNu = Nu.reshape(C, n, -1), dNu.reshape(C, n, -1)
        Nv, dNv = Nv.reshape(C, m, -1), dNv.reshape(C, m, -1)
        # the cell's homogeneous control points, shape (C, order_u, order_v, 4)
        rows = su[:, None] - (self.order_u - 1) + np.arange(self.order_u)
        cols = sv[:, None] - (self.order_v - 1) + np.arange(self.order_v)
        block = self._homogeneous[rows[:, :, None], cols[:, None, :]]
        # contract v, then u: A, dA/ds, dA/dt, shape (C, n, m, 4)
        T = np.einsum("cjb,cabk->cajk", Nv, block)
        dT = np.einsum("cjb,cabk->cajk", dNv, block)
        A = np.einsum("cia,cajk->cijk", Nu, T)
        As = np.einsum("cia,cajk->cijk", dNu, T)
        At = np.einsum("cia,cajk->cijk", Nu, dT)
        # project (A4.4, k = 1)
        w = A[..., 3:]
        p = A[..., :3] / w
        return p, (As[..., :3] - As[..., 3:] * p) / w, (At[..., :3] - At[..., 3:] * p) / w

    def _cell_rule(self, cells):
        """n x n Gauss values of |dp/ds x dp/dt| and of |dp/ds| |dp/dt| over cells, shape (C,) each."""
        rule = gauss_legendre(AREA_GAUSS)
        x, w = rule.points, rule.weights
        values = np.empty(len(cells))
        magnitudes = np.empty(len(cells))
        step = max(1, CHUNK // x.size**2)
        for first in range(0, len(cells), step):
            block = cells[first : first + step]
            _, ps, pt = self.cell_derivatives(block, x, x)
            normal = np.cross(ps, pt)
            density = np.sqrt(np.einsum("cijk,cijk->cij", normal, normal))
            size = np.sqrt(np.einsum("cijk,cijk->cij", ps, ps) * np.einsum("cijk,cijk->cij", pt, pt))
            values[first : first + step] = np.einsum("cij,i,j->c", density, w, w)
            magnitudes[first : first + step] = np.einsum("cij,i,j->c", size, w, w)
        return values, magnitudes

    def _sample_normals(self, box, n=8):
        """dP/du x dP/dv on an n x n grid of cell midpoints of `box`, shape (n * n, 3)."""
        (u0, u1), (v0, v1) = box
        s = (np.arange(n) + 0.5) / n
        u, v = np.meshgrid(u0 + (u1 - u0) * s, v0 + (v1 - v0) * s, indexing="ij")
        _, Pu, Pv = self.derivatives(u.ravel(), v.ravel())
        return np.cross(Pu, Pv)

    def _find_plane(self):
        """(centroid, unit normal along dP/du x dP/dv) if all control points are coplanar."""
        flat = self.points.reshape(-1, 3)
        centroid = flat.mean(0)
        if not self.size > 0.0:
            return None
        _, sing, vt = np.linalg.svd(flat - centroid)
        normal = vt[-1]
        if sing[1] <= 1e-10 * self.size or np.abs((flat - centroid) @ normal).max() > 1e-10 * self.size:
            return None
        if self._sample_normals(self.natural_domain).sum(0) @ normal < 0.0:
            normal = -normal
        return centroid, normal

    @property
    def breaks(self):
        """Interior knot values in u and in v (the basis is only piecewise polynomial)."""
        (u0, u1), (v0, v1) = self.natural_domain
        u = np.unique(self.knots_u)
        v = np.unique(self.knots_v)
        return u[(u > u0) & (u < u1)], v[(v > v0) & (v < v1)]

    @property
    def plane(self):
        return self._plane

    def span_indices(self):
        """Indices of the non-empty knot spans inside the natural domain, along u and along v."""
        return self._spans_u[0], self._spans_v[0]

    def exact_ellipsoid(self):
        """The `quadric.Ellipsoid` this net is over its natural domain (covered once), or None."""
        if self._ellipsoid is _UNKNOWN:
            self._ellipsoid = exact_ellipsoid(self)
        return self._ellipsoid

    def whole_ellipsoid(self, box):
        return tuple(map(tuple, box)) == self.natural_domain and self.exact_ellipsoid() is not None

    def bounded_solid(self):
        ellipsoid = self.exact_ellipsoid()
        return None if ellipsoid is None else (ellipsoid.center, ellipsoid.linear)

    @property
    def linear(self):
        """L of the whole ellipsoid {offset + L t : |t| = 1} (only for nets that are one)."""
        return self.exact_ellipsoid().linear

    @property
    def offset(self):
        """Centre of the whole ellipsoid (only for nets that are one)."""
        return self.exact_ellipsoid().center

    @property
    def convex_outward(self):
        ellipsoid = self.exact_ellipsoid()
        return ellipsoid is not None and ellipsoid.outward == (self.handedness > 0)

    def hull_points(self, box):
        return self.points.reshape(-1, 3)  # (positive weights: the hull of the control net)

    def validate_box(self, box):
        """Raise ValueError if the surface has (numerically) zero area over `box`."""
        (u0, u1), (v0, v1) = box
        (U0, U1), (V0, V1) = self.natural_domain
        density = np.linalg.norm(self._sample_normals(box), axis=-1).mean()
        share = (u1 - u0) * (v1 - v0) / ((U1 - U0) * (V1 - V0))
        if not density * (u1 - u0) * (v1 - v0) > 1e-12 * self.size**2 * share:
            raise ValueError(
                "degenerate NURBS patch: its control points are coincident or collinear over "
                f"u in ({u0}, {u1}), v in ({v0}, {v1}), so it has no area"
            )


# --------------------------------------------------------------------------- surface
def _halves(cells):
    """Both ways of halving each `span_cells` row.

    Returns
    -------
    ndarray, shape (4 C, 6)
        For row c: rows 4c, 4c + 1 are its halves along u, rows 4c + 2, 4c + 3 along v.
    """
    su, ou, wu, sv, ov, wv = cells.T
    hu, hv = 0.5 * wu, 0.5 * wv
    halves = np.stack(
        [
            np.stack([su, ou, hu, sv, ov, wv], -1),
            np.stack([su, ou + hu, hu, sv, ov, wv], -1),
            np.stack([su, ou, wu, sv, ov, hv], -1),
            np.stack([su, ou, wu, sv, ov + hv, hv], -1),
        ],
        axis=1,
    )
    return halves.reshape(-1, 6)


def _order(value, name):
    """An integer order (degree + 1) >= 2 (bools, strings, NaN, inf and fractions refused)."""
    order = checks.count(value, f"{name} (degree + 1)", minimum=1)
    if order < 2:
        raise ValueError(f"{name} must be at least 2 (degree >= 1), got {value!r}")
    return order


def _knots(value, name, count, order):
    """A finite non-decreasing knot vector of length count + order with a non-empty domain."""
    knots = checks.finite_array(value, name, (count + order,))
    if np.any(np.diff(knots) < 0.0):
        raise ValueError(f"{name} must be non-decreasing, got {knots}")
    if not knots[order - 1] < knots[count]:
        raise ValueError(
            f"{name} gives a zero-length domain: knots[{order - 1}] = knots[{count}] = {knots[count]}"
        )
    # derivatives scale like 1 / width: below MIN_DOMAIN their squares leave float64's range
    # (the surface does not depend on the knots' scale, so the remedy is a rescaled vector)
    width = knots[count] - knots[order - 1]
    magnitude = max(abs(knots[order - 1]), abs(knots[count]))
    if width < MIN_DOMAIN or width < checks.RESOLUTION * magnitude:
        raise ValueError(
            f"{name} gives a domain ({knots[order - 1]!r}, {knots[count]!r}) of width {width:.3g}: below "
            f"{MIN_DOMAIN:.0e} or {checks.RESOLUTION:.0e} of its values float64 derivatives overflow or "
            "parameters collapse (scale or shift the knot vector: the surface does not change)"
        )
    return knots


class NurbsSurface(Surface):
    """A rational tensor-product B-spline surface; front = side of dP/du x dP/dv.

    Parameters
    ----------
    points : array_like, shape (nu, nv, 3)
        Control points (m); index i runs along u, j along v.
    weights : array_like, shape (nu, nv)
        Positive weights.
    order_u, order_v : int
        Degree + 1, at least 2, with nu >= order_u and nv >= order_v.
    knots_u, knots_v : array_like, shapes (nu + order_u,), (nv + order_v,)
        Non-decreasing. The natural domain is u in [knots_u[order_u - 1], knots_u[nu]] and
        v likewise; it must have positive length.

    Raises
    ------
    ValueError
        Naming the problem: non-finite values, wrong shapes, weights <= 0, order < 2, too few
        points for the order, wrong knot count, decreasing knots, zero-length domain, or a
        surface with no area.
    """

    def __init__(self, points, weights, order_u, order_v, knots_u, knots_v):
        P = checks.finite_array(points, "NURBS points", (-1, -1, 3))
        nu, nv = P.shape[:2]
        W = checks.finite_array(weights, "NURBS weights", (nu, nv))
        if not np.all(W > 0.0):
            raise ValueError(f"NURBS weights must all be positive, got minimum {W.min()!r}")
        ku, kv = _order(order_u, "order_u"), _order(order_v, "order_v")
        for count, order, axis in ((nu, ku, "u"), (nv, kv, "v")):
            if count < order:
                raise ValueError(f"too few NURBS points along {axis} for order_{axis} = {order}: got {count}")
        Tu = _knots(knots_u, "knots_u", nu, ku)
        Tv = _knots(knots_v, "knots_v", nv, kv)
        geometry = NurbsGeometry(P, W, ku, kv, Tu, Tv)
        self._init(geometry)
        geometry.validate_box(self._box)

    @classmethod
    def from_blender(
        cls,
        points,
        order_u,
        order_v,
        point_count_u,
        point_count_v,
        use_endpoint_u=False,
        use_endpoint_v=False,
        use_bezier_u=False,
        use_bezier_v=False,
        use_cyclic_u=False,
        use_cyclic_v=False,
    ):
        """The surface Blender draws for one 'NURBS' spline of a 'SURFACE' object.

        Knots follow `blender_knots`; cyclic directions wrap the first order - 1 rows of points
        (`wrap_cyclic`). Like Blender's `BKE_nurb_order_clamp_u/v` (run by the RNA update when
        an order is set), an order larger than the point count is lowered to the point count
        (and never below 2); the returned surface therefore has order min(order, count).

        Parameters
        ----------
        points : array_like, shape (point_count_u * point_count_v, 4)
            `Spline.points[...].co` in Blender's storage order (u fastest) in the object's local
            coordinates; the 4th coordinate is the weight.
        order_u, order_v, point_count_u, point_count_v : int
        use_endpoint_u, ..., use_cyclic_v : bool
            The spline's flags.

        Raises
        ------
        ValueError
            If the data would not make a surface in Blender either (fewer than 2 points in a
            direction, or too few points for its Bezier option), or as for `NurbsSurface`.
        """
        nu, nv = (int(point_count_u), int(point_count_v))
        co = checks.finite_array(points, "Blender spline points", (nu * nv, 4))
        grid = co.reshape(nv, nu, 4).transpose(1, 0, 2)
        flags = {
            "u": (nu, order_u, use_endpoint_u, use_bezier_u, use_cyclic_u),
            "v": (nv, order_v, use_endpoint_v, use_bezier_v, use_cyclic_v),
        }
        orders, knots = [], []
        for axis, (count, order, endpoint, bezier, cyclic) in flags.items():
            if count < 2:
                raise ValueError(f"a Blender NURBS surface needs at least 2 points along {axis}, got {count}")
            order = max(2, min(_order(order, f"order_{axis}"), count))
            _check_blender_bezier(axis, count, order, endpoint, bezier, cyclic)
            orders.append(order)
            knots.append(blender_knots(count, order, endpoint, bezier, cyclic))
            if cyclic:
                grid = wrap_cyclic(grid, order, 0 if axis == "u" else 1)
        return cls(grid[..., :3], grid[..., 3], orders[0], orders[1], knots[0], knots[1])

    @property
    def points(self):
        """Control points, shape (nu, nv, 3)."""
        return self.geometry.points

    @property
    def weights(self):
        """Weights, shape (nu, nv)."""
        return self.geometry.weights

    def area_estimate(self, rtol=None, max_evaluations=None):
        """Area with its error estimate and cost: see `NurbsGeometry.area`.

        Returns
        -------
        value, error : float
            m^2.
        evaluations : int
        """
        return self.geometry.area(self._box, rtol, max_evaluations)

    def area(self):
        """Surface area (m^2), to about 1e-12 relative (`AREA_RTOL`) where float64 allows.

        Computed once by `area_estimate` within `AREA_BUDGET` evaluations and cached.

        Raises
        ------
        ValueError
            If the budget ran out before the estimated relative error fell below
            `AREA_ACCEPT`; the message gives the value and error reached.
        """
        if self._area is None:
            value, error, evaluations = self.area_estimate()
            if not error <= AREA_ACCEPT * value:
                raise ValueError(
                    f"NURBS area did not converge: {value!r} m^2 with estimated error {error:.3g} "
                    f"after {evaluations} evaluations (budget {AREA_BUDGET}); the surface is too "
                    "irregular for its knot spans"
                )
            self._area = float(value)
        return self._area


def _check_blender_bezier(axis, count, order, endpoint, bezier, cyclic):
    """Blender's extra point-count rule for the Bezier option (`nurb_check_valid`, curve.cc)."""
    if not bezier:
        return
    if cyclic and count % (order - 1):
        needed = order - 1 - count % (order - 1)
    elif not cyclic and not endpoint and count <= order:
        needed = order + 1 - count
    else:
        return
    raise ValueError(f"Blender's Bezier option along {axis} needs {needed} more point row(s)")
