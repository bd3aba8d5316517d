"""Rational tensor-product B-spline (NURBS) surfaces, and Blender's rule for their knot vectors.

P(u, v) = sum_ij N_i(u) M_j(v) w_ij P_ij / sum_ij N_i(u) M_j(v) w_ij, with B-spline bases N (order
k_u = degree + 1 over knots_u) and M (order k_v over knots_v). Basis functions and their first
derivatives follow Piegl & Tiller, "The NURBS Book" (2nd ed., 1997), algorithms A2.1 (span),
A2.2 (basis functions) and A2.3 (derivatives); the surface and its rational derivatives follow
A3.5/A3.6 and A4.3/A4.4, evaluated on homogeneous points (w P, w) and finished by the quotient
rule. Everything is vectorised over the evaluation points; loops run over the degree only.
"""

import numpy as np

from . import checks
from .integrate import integrate_box
from .surface import Geometry, Surface


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


def basis_functions(knots, order, span, t):
    """The order nonzero basis functions at t and their first derivatives.

    Piegl & Tiller A2.2 (Cox-de Boor triangle) and A2.3 restricted to the first derivative:
    the quotients N_{r, p-1} / (knot difference) of the last stage give both
    N_{r,p} and N'_{r,p} = p (quotient_{r-1} - quotient_r). Denominators are knot differences
    that span a non-empty span, so they are positive.

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
    p = order - 1
    values = [np.ones_like(t)]
    for j in range(1, p + 1):
        # raise the degree from j - 1 to j; quotient r divides by knots[span+r+1] - knots[span+r+1-j]
        quotients = [values[r] / (knots[span + r + 1] - knots[span + r + 1 - j]) for r in range(j)]
        new = [np.zeros_like(t) for _ in range(j + 1)]
        for r, q in enumerate(quotients):
            new[r] += (knots[span + r + 1] - t) * q
            new[r + 1] += (t - knots[span + r + 1 - j]) * q
        if j == p:
            padded = [np.zeros_like(t)] + quotients + [np.zeros_like(t)]
            derivative = [p * (padded[r] - padded[r + 1]) for r in range(p + 1)]
        values = new
    return np.stack(values, -1), np.stack(derivative, -1)


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
        # homogeneous control points (w x, w y, w z, w)
        self._homogeneous = np.concatenate(
            [self.points * self.weights[..., None], self.weights[..., None]], -1
        )
        self.size = float(np.ptp(self.points.reshape(-1, 3), axis=0).max())
        for a in (self.points, self.weights, self.knots_u, self.knots_v, self._homogeneous):
            a.setflags(write=False)
        self._plane = self._find_plane()

    def derivatives(self, u, v):
        """Points and first derivatives (Piegl & Tiller A4.4 to first order).

        Parameters are clamped to `natural_domain`, as Blender's `basisNurb` does, so the
        rational denominator stays >= the smallest weight.

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
        # find the spans and the nonzero basis functions in each direction
        su = find_spans(*self._spans_u, u)
        sv = find_spans(*self._spans_v, v)
        Nu, dNu = basis_functions(self.knots_u, self.order_u, su, u)
        Nv, dNv = basis_functions(self.knots_v, self.order_v, sv, v)
        # sum the homogeneous control points row by row (A3.5): A, dA/du, dA/dv
        cols = sv[:, None] - (self.order_v - 1) + np.arange(self.order_v)
        A = np.zeros((u.size, 4))
        Au = np.zeros((u.size, 4))
        Av = np.zeros((u.size, 4))
        for a in range(self.order_u):
            rows = self._homogeneous[(su - (self.order_u - 1) + a)[:, None], cols]
            along = np.einsum("kb,kbc->kc", Nv, rows)
            A += Nu[:, a, None] * along
            Au += dNu[:, a, None] * along
            Av += Nu[:, a, None] * np.einsum("kb,kbc->kc", dNv, rows)
        # project: P = A / w and the quotient rule for the derivatives (A4.4, k = 1)
        w = A[:, 3:]
        P = A[:, :3] / w
        Pu = (Au[:, :3] - Au[:, 3:] * P) / w
        Pv = (Av[:, :3] - Av[:, 3:] * P) / w
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

    def knot_cells(self, box):
        """Split a parameter box at the distinct knots inside it.

        Returns
        -------
        list of ((u0, u1), (v0, v1))
            Cells on which the surface is one rational polynomial patch.
        """
        (u0, u1), (v0, v1) = box
        us = np.unique(np.concatenate([[u0, u1], self.knots_u[(self.knots_u > u0) & (self.knots_u < u1)]]))
        vs = np.unique(np.concatenate([[v0, v1], self.knots_v[(self.knots_v > v0) & (self.knots_v < v1)]]))
        return [((a, b), (c, d)) for a, b in zip(us[:-1], us[1:]) for c, d in zip(vs[:-1], vs[1:])]

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
    def plane(self):
        return self._plane

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
def _order(value, name):
    """An integer order (degree + 1) >= 2."""
    if isinstance(value, (bool, np.bool_)) or not np.isscalar(value) or int(value) != value:
        raise ValueError(f"{name} must be an integer (degree + 1), got {value!r}")
    if value < 2:
        raise ValueError(f"{name} must be at least 2 (degree >= 1), got {value!r}")
    return int(value)


def _knots(value, name, count, order):
    """A finite non-decreasing knot vector of length count + order with a non-empty domain."""
    knots = checks.finite_array(value, name, (count + order,))
    if np.any(np.diff(knots) < 0.0):
        raise ValueError(f"{name} must be non-decreasing, got {knots}")
    if not knots[order - 1] < knots[count]:
        raise ValueError(
            f"{name} gives a zero-length domain: knots[{order - 1}] = knots[{count}] = {knots[count]}"
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

    def area(self):
        """Surface area (m^2): adaptive quadrature on each knot cell, where P is smooth."""
        if self._area is None:

            def density(u, v):
                return np.linalg.norm(self.evaluate(u, v)[1], axis=-1)

            cells = self.geometry.knot_cells(self._box)
            self._area = float(sum(integrate_box(density, cell, rtol=1e-13)[0] for cell in cells))
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
