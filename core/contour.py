"""Exact point-to-patch form factors for sphere and disk patches by contour integration.

By Stokes' theorem (the same identity behind Lambert's polygon formula), the form factor from a
differential element (x1, unit normal n1) to a region D whose every point faces x1 and lies above
x1's horizon is a boundary integral:

    F(dA1 -> D) = -1/(2 pi) * contour integral over dD of  n1 . (r x dr) / |r|^2,   r = x - x1,

with dD run counter-clockwise about D's front normal (Sparrow 1963; Siegel & Howell, "Thermal
Radiation Heat Transfer", contour integration). For a sphere patch the visible part
D = patch & front-facing cap & above-horizon cap is an intersection of spherical caps, so dD is
made of circular arcs; for a disk patch (annulus sector) dD is made of arcs and straight segments.
Arcs are integrated in closed form (a rational function of cos t, sin t), segments by Lambert's
edge term. A point lying on a concave sphere patch also sees, near itself, a full horizon: that
adds 1 (the small loop around the point).
"""

import numpy as np

from .polygon import edge_terms
from .quadrature import gauss_legendre

TWO_PI = 2.0 * np.pi
CLOSED_FORM = 0.25  # arcs with lambda / A below this are integrated by Gauss-Legendre
ARC_GAUSS = 16
ARC_BLOCK = 256  # query rows whose arcs `_circle_arcs_integral` clips at once


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def arc_integral(x1, n1, center, e1, e2, radius, t0, t1):
    """Integral of n1 . (r x dr) / |r|^2 along the arc center + radius (cos t e1 + sin t e2), t0 -> t1,
    0 <= t1 - t0 <= 2 pi: arcs longer than pi in two halves (`_short_arc_integral`).

    Parameters
    ----------
    x1, n1 : ndarray, shape (M, 3)
        Points and unit normals.
    center, e1, e2 : ndarray, shape (M, 3)
        Circle centres and orthonormal in-plane axes.
    radius : ndarray, shape (M,)
    t0, t1 : ndarray, shape (M,)
        Arc ends.

    Returns
    -------
    ndarray, shape (M,)
    """
    long_ = np.flatnonzero(t1 - t0 > np.pi)
    if long_.size == 0:
        return _short_arc_integral(x1, n1, center, e1, e2, radius, t0, t1)
    mid = t1.copy()
    mid[long_] = 0.5 * (t0[long_] + t1[long_])
    out = _short_arc_integral(x1, n1, center, e1, e2, radius, t0, mid)
    out[long_] += _short_arc_integral(
        x1[long_], n1[long_], center[long_], e1[long_], e2[long_], radius[long_], mid[long_], t1[long_]
    )
    return out


def _short_arc_integral(x1, n1, center, e1, e2, radius, t0, t1):
    """`arc_integral` (same parameters and result) for arcs of at most pi: 0 <= t1 - t0 <= pi.

    Notes
    -----
    With d = center - x1 the integrand is (alpha + beta cos t + gamma sin t) / (A + B cos t + C sin t).
    Writing B cos t + C sin t = lam cos(tau), tau = t - psi, its antiderivative is
    (beta'/lam) tau + (alpha - beta' A/lam) J(tau) - (gamma'/lam) ln(A + lam cos tau),
    J = 2/sqrt(A^2 - lam^2) atan2(sqrt(A - lam) sin(tau/2), sqrt(A + lam) cos(tau/2)),
    continuous for tau in (-2 pi, 2 pi) (Gradshteyn & Ryzhik 2.553.3 and 2.558). Where lam is small
    against A the 1/lam form loses digits, and the smooth integrand is integrated by Gauss instead.
    """
    d = center - x1
    e3 = np.cross(e1, e2)
    alpha = radius**2 * _dot(n1, e3)
    beta = radius * _dot(n1, np.cross(d, e2))
    gamma = -radius * _dot(n1, np.cross(d, e1))
    d1, d2 = _dot(d, e1), _dot(d, e2)
    dd = _dot(d, d)
    d_perp = np.hypot(d1, d2)
    d_par2 = np.maximum(dd - d_perp**2, 0.0)
    A = dd + radius**2
    B, C = 2.0 * radius * d1, 2.0 * radius * d2
    lam = 2.0 * radius * d_perp
    result = np.zeros(x1.shape[0])

    closed = lam >= CLOSED_FORM * A
    k = np.flatnonzero(closed)
    if k.size:
        psi = np.arctan2(C[k], B[k])
        cp, sp = np.cos(psi), np.sin(psi)
        beta_p = beta[k] * cp + gamma[k] * sp
        gamma_p = -beta[k] * sp + gamma[k] * cp
        tau0 = np.mod(t0[k] - psi + np.pi, TWO_PI) - np.pi
        tau1 = tau0 + (t1[k] - t0[k])
        a_minus = (d_perp[k] - radius[k]) ** 2 + d_par2[k]  # A - lam, without cancellation
        a_plus = (d_perp[k] + radius[k]) ** 2 + d_par2[k]
        root_m, root_p = np.sqrt(a_minus), np.sqrt(a_plus)
        y = root_m / root_p
        on_circle = y == 0.0  # (x1 on the circle, off the arc: A = lam)

        def J(tau):
            """atan2(root_m sin(tau/2), root_p cos(tau/2)) / root_m, and its limit tan(tau/2)
            / root_p where x1 lies on the circle (a node of one patch on the rim of another)."""
            s, c = np.sin(0.5 * tau), np.cos(0.5 * tau)
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(
                    on_circle, s / c / root_p, np.arctan2(y * s, c) / np.where(on_circle, 1.0, root_m)
                )

        def log_r2(t):
            r = d[k] + radius[k, None] * (np.cos(t)[:, None] * e1[k] + np.sin(t)[:, None] * e2[k])
            return np.log(_dot(r, r))

        L = lam[k]
        result[k] = (
            beta_p / L * (tau1 - tau0)
            + (alpha[k] - beta_p * A[k] / L) * 2.0 / root_p * (J(tau1) - J(tau0))
            - gamma_p / L * (log_r2(t1[k]) - log_r2(t0[k]))
        )

    k = np.flatnonzero(~closed)
    if k.size:
        rule = gauss_legendre(ARC_GAUSS)
        span = t1[k] - t0[k]
        t = t0[k, None] + span[:, None] * rule.points
        c, s = np.cos(t), np.sin(t)
        f = (alpha[k, None] + beta[k, None] * c + gamma[k, None] * s) / (
            A[k, None] + B[k, None] * c + C[k, None] * s
        )
        result[k] = (f * rule.weights).sum(1) * span
    return result


def circle_frame(axis):
    """Orthonormal e1, e2 with e1 x e2 = axis, for unit axes of shape (..., 3)."""
    helper = np.zeros_like(axis)
    pick = np.argmin(np.abs(axis), axis=-1)
    np.put_along_axis(helper, pick[..., None], 1.0, axis=-1)
    e1 = np.cross(helper, axis)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, np.cross(axis, e1)


def arc_ends(P, Q, S, active, trig=True):
    """Where P_j + Q_j cos t + S_j sin t > 0 for every active j on [0, 2 pi): the sorted ends of
    the pieces between roots, their cosines and sines, and which pieces hold.

    On circle t, constraint j holds on the arc (psi - h, psi + h) about psi = atan2(S, Q) with
    cos h = -P / sqrt(Q^2 + S^2) (everywhere when cos h <= -1, nowhere when >= 1). The pieces'
    violated counts follow from the count at t = 0+ by one step per root (-1 where an arc starts,
    +1 where it ends): the ends' order alone decides, so no piece is judged by a value that
    rounds to zero, and the ends' cosines and sines come from cos h and psi without trigonometry.

    Parameters
    ----------
    P, Q, S : ndarray, shape (..., J)
        One trigonometric constraint per j.
    active : ndarray of bool, shape (..., J)
    trig : bool
        Whether to return the ends' cos and sin (else None).

    Returns
    -------
    t, cos_t, sin_t : ndarray, shape (..., 2 J + 2)
        0, the 2 J roots sorted (2 pi for constraints without one), 2 pi; and their cos and sin.
    keep : ndarray of bool, shape (..., 2 J + 1)
        Piece [t_i, t_i+1] holds every active constraint.
    """
    W = np.sqrt(Q * Q + S * S)
    round_ = W > 0
    safe = np.where(round_, W, 1.0)
    ratio = np.where(round_, -P / safe, np.where(P > 0, -2.0, 2.0))  # cos h
    never = (active & (ratio >= 1.0)).any(-1)  # a constraint that holds nowhere on the circle
    crosses = active & (np.abs(ratio) < 1.0)
    ch = np.where(crosses, ratio, 1.0)
    sh = np.sqrt(1.0 - ch * ch)
    cp, sp = np.where(round_, Q / safe, 1.0), S / safe  # cos psi, sin psi
    psi, half = np.arctan2(sp, cp), np.arccos(ch)
    lo, hi = psi - half, psi + half  # in (-2 pi, pi) and (-pi, 2 pi)
    lo += TWO_PI * (lo < 0.0)
    hi += TWO_PI * (hi < 0.0)
    hi -= TWO_PI * (hi >= TWO_PI)
    # at t = 0+: the crossing constraints whose arc does not wrap past 0 are violated
    violated = (crosses & (lo <= hi)).sum(-1) + np.where(never, 2 * P.shape[-1] + 1, 0)
    two = np.concatenate([crosses, crosses], -1)
    angle = np.where(two, np.concatenate([lo, hi], -1), TWO_PI)
    step = np.where(two, np.concatenate([-np.ones(lo.shape), np.ones(hi.shape)], -1), 0.0)
    order = np.argsort(angle, -1)
    shape = P.shape[:-1] + (2 * P.shape[-1] + 2,)
    # the sort as flat indices, once (np.take_along_axis builds them again on every call)
    width = order.shape[-1]
    order = order + width * np.arange(order.size // max(width, 1)).reshape(order.shape[:-1] + (1,))

    def ends(values, first, last):
        out = np.empty(shape)
        out[..., 0], out[..., -1] = first, last
        out[..., 1:-1] = np.take(values, order)
        return out

    t, cos_t, sin_t = ends(angle, 0.0, TWO_PI), None, None
    if trig:
        cos_t = ends(np.concatenate([cp * ch + sp * sh, cp * ch - sp * sh], -1), 1.0, 1.0)
        sin_t = ends(np.concatenate([sp * ch - cp * sh, sp * ch + cp * sh], -1), 0.0, 0.0)
    count = np.empty(shape[:-1] + (shape[-1] - 1,))
    count[..., 0] = 0.0
    np.cumsum(np.take(step, order), -1, out=count[..., 1:])
    count += violated[..., None]
    return t, cos_t, sin_t, count < 0.5


def arc_pieces(P, Q, S, active):
    """Sub-arcs of [0, 2 pi) on which P_j + Q_j cos t + S_j sin t > 0 for every active j
    (`arc_ends`).

    Parameters
    ----------
    P, Q, S : ndarray, shape (..., J)
        One trigonometric constraint per j.
    active : ndarray of bool, shape (..., J)

    Returns
    -------
    start, end : ndarray, shape (..., 2 J + 1)
        Sub-arc ends (zero length where not kept), sorted.
    """
    t, _, _, keep = arc_ends(P, Q, S, active, trig=False)
    start = t[..., :-1]
    return start, np.where(keep, t[..., 1:], start)


def _circle_arcs_integral(x1, n1, a, b, active):
    """Sum over circles {a_k . y = b_k} on the unit sphere of the arcs bounding the caps' intersection.

    The region is the intersection of the caps a_k . y > b_k (active ones). Each circle is run
    with the cap on its left seen from outside the sphere (counter-clockwise about a_k).

    Parameters
    ----------
    x1, n1 : ndarray, shape (K, 3)
        Point and unit normal in unit-sphere coordinates.
    a : ndarray, shape (K, J, 3)
    b : ndarray, shape (K, J)
    active : ndarray of bool, shape (K, J)

    Returns
    -------
    total : ndarray, shape (K,)
    terms : int
        Arcs integrated.
    """
    # rows by their number of active circles (the clipping costs about J^2 per row), those
    # circles first, ARC_BLOCK rows at a time (the (K, J, 2 J + 2) temporaries stay in cache)
    total, terms = np.zeros(len(x1)), 0
    count = active.sum(1)
    order = np.argsort(~active, axis=1, kind="stable")
    a = np.take_along_axis(a, order[..., None], 1)
    b = np.take_along_axis(b, order, 1)
    for J in np.unique(count[count > 0]):
        rows = np.flatnonzero(count == J)
        for k in range(0, rows.size, ARC_BLOCK):
            r = rows[k : k + ARC_BLOCK]
            total[r], done = _circle_arcs_block(x1[r], n1[r], a[r, :J], b[r, :J])
            terms += done
    return total, terms


def _circle_arcs_block(x1, n1, a, b):
    """`_circle_arcs_integral` for rows whose caps are all active."""
    K, J, _ = a.shape
    norm = np.linalg.norm(a, axis=-1)
    safe = np.where(norm > 0, norm, 1.0)
    axis = a / safe[..., None]
    offset = b / safe
    is_circle = np.abs(offset) < 1.0
    center = offset[..., None] * axis
    radius = np.sqrt(np.maximum(1.0 - offset**2, 0.0))
    e1, e2 = circle_frame(axis)

    # constraint j along circle k: a_j . (center_k + radius_k (cos t e1_k + sin t e2_k)) - b_j
    P = np.einsum("kci,kji->kcj", center, a) - b[:, None, :]
    Q = radius[..., None] * np.einsum("kci,kji->kcj", e1, a)
    S = radius[..., None] * np.einsum("kci,kji->kcj", e2, a)
    others = np.broadcast_to(~np.eye(J, dtype=bool), (K, J, J))
    start, end = arc_pieces(P, Q, S, others)
    pieces = start.shape[-1]

    def spread(x):
        return np.broadcast_to(x[:, :, None], (K, J, pieces) + x.shape[2:]).reshape((-1,) + x.shape[2:])

    t0, t1 = start.ravel(), end.ravel()
    use = spread(is_circle) & (t1 > t0)
    idx = np.flatnonzero(use)
    total = np.zeros(K * J * pieces)
    if idx.size:
        X = np.repeat(x1, J * pieces, axis=0)[idx]
        N = np.repeat(n1, J * pieces, axis=0)[idx]
        c, u, w, r = spread(center)[idx], spread(e1)[idx], spread(e2)[idx], spread(radius)[idx]
        total[idx] = arc_integral(X, N, c, u, w, r, t0[idx], t1[idx])
    return total.reshape(K, -1).sum(1), idx.size


def sphere_patch(x1, n1, box, inward):
    """F(dA1 -> part of the unit sphere) for points in unit-sphere coordinates.

    A point that sees the whole patch (`_patch_within`) integrates its four edges; the others the
    boundary of the patch clipped by the point's horizon and by the sphere's visible cap.

    Parameters
    ----------
    x1 : ndarray, shape (K, 3)
        Points (in coordinates where the patch lies on the unit sphere at the origin).
    n1 : ndarray, shape (K, 3)
        Unit normals.
    box : ndarray, shape (K, 4)
        Patch (theta0, theta1, phi0, phi1): polar angle from +z, azimuth from +x; phi1 - phi0 <= pi
        or = 2 pi.
    inward : ndarray of bool, shape (K,)
        Front side is the inside of the sphere.

    Returns
    -------
    F : ndarray, shape (K,)
    terms : int
        Arc integrals computed.
    """
    F, terms = np.zeros(len(x1)), 0
    # the outside of a whole sphere wholly above the point's horizon (-n . x >= 1 with the centre
    # at the origin): F = cos(theta) / H^2 = -n . x / |x|^3 (Siegel & Howell, catalogue of
    # configuration factors: plane element to a sphere, the sphere wholly visible)
    th0, th1, ph0, ph1 = box.T
    height = -np.einsum("ki,ki->k", n1, x1)
    whole = (th0 <= 0.0) & (th1 >= np.pi) & (ph1 - ph0 >= 2.0 * np.pi) & ~inward & (height >= 1.0)
    F[whole] = height[whole] / np.linalg.norm(x1[whole], axis=1) ** 3
    above, facing = _patch_within(x1, n1, box, inward)
    above &= ~whole
    facing &= ~whole
    rows = np.flatnonzero(above & facing)
    if rows.size:
        F[rows], count = _whole_sphere_patch(x1[rows], n1[rows], box[rows], inward[rows])
        terms += count
    rows = np.flatnonzero(~(above & facing) & ~whole)
    if rows.size:
        F[rows], count = _clipped_sphere_patch(
            x1[rows], n1[rows], box[rows], inward[rows], above[rows], facing[rows]
        )
        terms += count
    return F, terms


def _patch_within(x1, n1, box, inward):
    """Whether the whole patch is above the point's horizon, and whether all of it faces the
    point: two shapes (K,) (a sufficient test, by the patch's bounding cap; False for patches
    wider than pi in azimuth).

    The patch lies within angle rho of its middle direction c: for |phi - phi_c| <= D,
    cos(angle) >= cos(theta_c) cos(theta) + sin(theta_c) sin(theta) cos(D), a sinusoid in theta
    whose least value on [theta0, theta1] is at an end. Over that cap the least of v . y is
    |v| cos(angle(v, c) + rho).
    """
    th0, th1, ph0, ph1 = box.T
    half = 0.5 * (ph1 - ph0)
    thc, phc = 0.5 * (th0 + th1), 0.5 * (ph0 + ph1)
    a, b = np.cos(thc), np.sin(thc) * np.cos(half)
    rho = np.arccos(
        np.clip(np.minimum(a * np.cos(th0) + b * np.sin(th0), a * np.cos(th1) + b * np.sin(th1)), -1, 1)
    )
    c = np.stack([np.sin(thc) * np.cos(phc), np.sin(thc) * np.sin(phc), np.cos(thc)], -1)

    def least(v):  # min over the cap of v . y
        size = np.linalg.norm(v, axis=-1)
        angle = np.arccos(np.clip(_dot(v, c) / np.maximum(size, 1e-300), -1.0, 1.0))
        return size * np.cos(np.minimum(angle + rho, np.pi))

    margin = 1e-9
    height = _dot(n1, x1)
    above = least(n1) > height + margin * (1.0 + np.abs(height))
    # the outside faces x where x . y > 1; the inside, from a point inside the sphere, everywhere
    facing = np.where(inward, _dot(x1, x1) < (1.0 - margin) ** 2, least(x1) > 1.0 + margin)
    narrow = half <= 0.5 * np.pi
    return narrow & above, narrow & facing


def _whole_sphere_patch(x1, n1, box, inward):
    """F for points that see the whole patch: the contour of its four edges, counter-clockwise
    seen from outside (theta, phi is a positive chart for the outward normal): the meridian
    phi0 from theta0 to theta1, the parallel theta1 from phi0 to phi1, then both back."""
    K = len(x1)
    th0, th1, ph0, ph1 = box.T
    z, one = np.zeros(K), np.ones(K)
    ez = np.stack([z, z, one], -1)
    ex, ey = np.stack([one, z, z], -1), np.stack([z, one, z], -1)
    meridian = [np.stack([np.cos(ph), np.sin(ph), z], -1) for ph in (ph0, ph1)]
    pieces = [  # (centre, e1, e2, radius, t0, t1, sign)
        (np.zeros((K, 3)), ez, meridian[0], one, th0, th1, 1.0),
        (np.cos(th1)[:, None] * ez, ex, ey, np.sin(th1), ph0, ph1, 1.0),
        (np.zeros((K, 3)), ez, meridian[1], one, th0, th1, -1.0),
        (np.cos(th0)[:, None] * ez, ex, ey, np.sin(th0), ph0, ph1, -1.0),
    ]
    columns = [np.concatenate(parts) for parts in zip(*[p[:6] for p in pieces])]
    arcs = arc_integral(np.tile(x1, (4, 1)), np.tile(n1, (4, 1)), *columns).reshape(4, K)
    total = np.einsum("pk,p->k", arcs, [p[6] for p in pieces])
    F = -np.where(inward, -1.0, 1.0) * total / TWO_PI
    return np.maximum(F, 0.0), 4 * K


def _clipped_sphere_patch(x1, n1, box, inward, above, facing):
    """F for any points: the patch's caps, the horizon and the visible cap intersected
    (`_circle_arcs_integral`); the horizon and the visible cap drop out where `_patch_within`
    (above, facing) says they hold the whole patch."""
    K = x1.shape[0]
    th0, th1, ph0, ph1 = box.T
    z = np.zeros(K)
    one = np.ones(K)
    # caps: theta >= th0, theta <= th1, phi >= ph0, phi <= ph1, horizon, front-facing
    a = np.stack(
        [
            np.stack([z, z, -one], -1),
            np.stack([z, z, one], -1),
            np.stack([-np.sin(ph0), np.cos(ph0), z], -1),
            np.stack([np.sin(ph1), -np.cos(ph1), z], -1),
            n1,
            np.where(inward[:, None], -x1, x1),
        ],
        1,
    )
    b = np.stack(
        [-np.cos(th0), np.cos(th1), z, z, _dot(n1, x1), np.where(inward, -1.0, 1.0)],
        1,
    )
    full_turn = ph1 - ph0 >= TWO_PI * (1 - 1e-12)
    active = np.stack([th0 > 0, th1 < np.pi, ~full_turn, ~full_turn, ~above, ~facing], 1)
    # caps that exclude the whole sphere leave nothing; caps that hold it all drop out
    norm = np.linalg.norm(a, axis=-1)
    empty = (active & (b >= norm * (1 - 1e-14))).any(1)
    active &= b > -norm * (1 - 1e-14)

    total, count = _circle_arcs_integral(x1, n1, a, b, active)
    F = -np.where(inward, -1.0, 1.0) * total / TWO_PI
    # a point on a concave patch sees a full horizon around itself
    on_patch = (
        inward
        & (np.abs(_dot(x1, x1) - 1.0) < 1e-10)
        & np.all((np.einsum("kji,ki->kj", a[:, :4], x1) >= b[:, :4]) | ~active[:, :4], 1)
    )
    F = F + np.where(on_patch & (_dot(n1, x1) < -1 + 1e-9), 1.0, 0.0)
    return np.where(empty, 0.0, np.maximum(F, 0.0)), count


def _segment_pieces(A, B, lines, line_active, circles, circle_sign, circle_active):
    """Pieces of segments A -> B (in the plane z = 0) on which every constraint holds.

    Constraints: lines[j] = (a_x, a_y, b): a . y > b; circles[j] = r: circle_sign * (|y|^2 - r^2) > 0.

    Parameters
    ----------
    A, B : ndarray, shape (M, 2)
    lines : ndarray, shape (M, Jl, 3)
    line_active : ndarray of bool, shape (M, Jl)
    circles : ndarray, shape (M, Jc)
    circle_sign : ndarray, shape (Jc,)
    circle_active : ndarray of bool, shape (M, Jc)

    Returns
    -------
    s0, s1 : ndarray, shape (M, Jl + 2 Jc + 1)
        Kept pieces as parameter ranges in [0, 1] (zero length where dropped).
    """
    D = B - A
    # linear constraints: P + Q s > 0
    P = np.einsum("mi,mji->mj", A, lines[..., :2]) - lines[..., 2]
    Q = np.einsum("mi,mji->mj", D, lines[..., :2])
    s_line = np.divide(-P, Q, out=np.full(P.shape, 2.0), where=(Q != 0) & line_active)
    # circle constraints: |A + s D|^2 - r^2 = a2 s^2 + a1 s + a0
    a2 = _dot(D, D)[:, None]
    a1 = 2.0 * _dot(A, D)[:, None]
    a0 = _dot(A, A)[:, None] - circles**2
    disc = a1**2 - 4.0 * a2 * a0
    ok = circle_active & (disc > 0) & (a2 > 0)
    root = np.sqrt(np.where(ok, disc, 0.0))
    denominator = np.where(ok, 2.0 * a2, 1.0)
    s_circle = np.concatenate(
        [np.where(ok, (-a1 - root) / denominator, 2.0), np.where(ok, (-a1 + root) / denominator, 2.0)], -1
    )
    cuts = np.concatenate([s_line, s_circle], -1)
    cuts = np.where((cuts > 0.0) & (cuts < 1.0), cuts, 1.0)
    cuts.sort(-1)
    start = np.concatenate([np.zeros((len(A), 1)), cuts], -1)
    end = np.concatenate([cuts, np.ones((len(A), 1))], -1)
    mid = 0.5 * (start + end)
    y = A[:, None, :] + mid[..., None] * D[:, None, :]
    line_ok = np.einsum("mpi,mji->mpj", y, lines[..., :2]) - lines[:, None, :, 2] > 0.0
    keep = np.all(line_ok | ~line_active[:, None, :], -1)
    r2 = _dot(y, y)[..., None]
    circle_ok = circle_sign * (r2 - circles[:, None, :] ** 2) > 0.0
    keep &= np.all(circle_ok | ~circle_active[:, None, :], -1)
    return start, np.where(keep, end, start)


def disk_patch(x1, n1, box, flipped):
    """F(dA1 -> annulus sector in the plane z = 0) for points in the disk's local coordinates.

    Parameters
    ----------
    x1 : ndarray, shape (K, 3)
        Points (local coordinates: the disk lies in z = 0, centred at the origin).
    n1 : ndarray, shape (K, 3)
        Unit normals.
    box : ndarray, shape (K, 4)
        (r0, r1, phi0, phi1), phi1 - phi0 <= pi or = 2 pi.
    flipped : ndarray of bool, shape (K,)
        Front side is -z.

    Returns
    -------
    F : ndarray, shape (K,)
    terms : int
        Arc and segment integrals computed.
    """
    K = x1.shape[0]
    r0, r1, ph0, ph1 = box.T
    front = np.where(flipped, -x1[:, 2], x1[:, 2]) > 1e-12 * (np.linalg.norm(x1, axis=-1) + r1)
    full_turn = ph1 - ph0 >= TWO_PI * (1 - 1e-12)
    z = np.zeros(K)
    # half-planes in the disk plane: phi >= phi0, phi <= phi1, above the horizon
    h = n1[:, :2]
    lines = np.stack(
        [
            np.stack([-np.sin(ph0), np.cos(ph0), z], -1),
            np.stack([np.sin(ph1), -np.cos(ph1), z], -1),
            np.stack([h[:, 0], h[:, 1], _dot(n1, x1)], -1),
        ],
        1,
    )
    h_norm = np.linalg.norm(h, axis=-1)
    horizon_cuts = h_norm > 1e-300
    # a horizon parallel to the disk: all of it is above (or below) the horizon
    above_all = ~horizon_cuts & (-_dot(n1, x1) > 0)
    line_active = np.stack([~full_turn, ~full_turn, horizon_cuts], 1)
    total = np.zeros(K)
    count = 0

    # arcs of the outer (+1, counter-clockwise) and inner (-1) circles
    for radius, sign, present in ((r1, 1.0, r1 > 0), (r0, -1.0, r0 > 0)):
        P = -lines[..., 2]
        Q = radius[:, None] * lines[..., 0]
        S = radius[:, None] * lines[..., 1]
        start, end = arc_pieces(P, Q, S, line_active)
        pieces = start.shape[-1]
        t0, t1 = start.ravel(), end.ravel()
        use = np.repeat(present & front, pieces) & (t1 > t0)
        idx = np.flatnonzero(use)
        if idx.size:
            rows = idx // pieces
            ez = np.zeros((idx.size, 3))
            ex, ey = ez.copy(), ez.copy()
            ex[:, 0] = 1.0
            ey[:, 1] = 1.0
            arcs = arc_integral(x1[rows], n1[rows], ez, ex, ey, radius[rows], t0[idx], t1[idx])
            total += sign * np.bincount(rows, arcs, K)
            count += idx.size

    # straight pieces: the radial edges (outward at phi0, inward at phi1) and the horizon chord
    c0, s0_, c1, s1_ = np.cos(ph0), np.sin(ph0), np.cos(ph1), np.sin(ph1)
    h_unit = h / np.where(horizon_cuts, h_norm, 1.0)[:, None]
    foot = (lines[:, 2, 2] / np.where(horizon_cuts, h_norm, 1.0))[:, None] * h_unit
    half = np.sqrt(np.maximum(r1**2 - _dot(foot, foot), 0.0))
    along = np.stack([h_unit[:, 1], -h_unit[:, 0]], -1)
    segments = [
        (np.stack([r0 * c0, r0 * s0_], -1), np.stack([r1 * c0, r1 * s0_], -1), ~full_turn, [1, 2]),
        (np.stack([r1 * c1, r1 * s1_], -1), np.stack([r0 * c1, r0 * s1_], -1), ~full_turn, [0, 2]),
        (foot - half[:, None] * along, foot + half[:, None] * along, horizon_cuts & (half > 0), [0, 1]),
    ]
    circles = np.stack([r0, r1], -1)
    circle_sign = np.array([1.0, -1.0])
    circle_active = np.stack([r0 > 0, r1 > 0], -1)
    for A, B, present, others in segments:
        idx = np.flatnonzero(present & front)
        if not idx.size:
            continue
        mask = np.zeros(3, dtype=bool)
        mask[others] = True
        s_start, s_end = _segment_pieces(
            A[idx], B[idx], lines[idx], line_active[idx] & mask, circles[idx], circle_sign, circle_active[idx]
        )
        D = (B - A)[idx]
        a3 = np.zeros((idx.size, s_start.shape[1], 3))
        b3 = np.zeros_like(a3)
        a3[..., :2] = A[idx, None] + s_start[..., None] * D[:, None]
        b3[..., :2] = A[idx, None] + s_end[..., None] * D[:, None]
        terms = edge_terms(x1[idx, None], n1[idx, None], a3, b3)
        total[idx] += np.where(s_end > s_start, terms, 0.0).sum(1)
        count += int((s_end > s_start).sum())

    # with the horizon parallel to the disk, either all of it is seen or none
    F = -np.where(flipped, -1.0, 1.0) * total / TWO_PI
    F = np.where(horizon_cuts | above_all, F, 0.0)
    return np.where(front, np.maximum(F, 0.0), 0.0), count


def _trig_roots(P, Q, S):
    """Roots in [0, 2 pi) of P + Q cos u + S sin u, shape (..., 2); 4 pi (out of range) where none."""
    W = np.sqrt(Q * Q + S * S)
    ratio = np.divide(-P, W, out=np.full(np.shape(P), 2.0), where=W > 0)
    crosses = np.abs(ratio) < 1.0
    psi = np.arctan2(S, Q)
    half = np.arccos(np.clip(ratio, -1.0, 1.0))
    roots = np.mod(np.stack([psi - half, psi + half], -1), TWO_PI)
    return np.where(crosses[..., None], roots, 2.0 * TWO_PI)


def planar_sweep(x1, n1, P0, P1, P2, A, B):
    """Angle swept about n1 by the curve x(u) = P0 + P1 cos u + P2 sin u, u from A to B, seen from x1.

    For a curve lying in x1's tangent plane, n1 . (r x dr) / |r|^2 = d(psi), the change of its
    polar angle about x1, so its contour integral is exactly this sweep. It is the principal
    angle of the end point (measured from the start point) plus a full turn for every crossing of
    the ray opposite to the start point, counted with its sense: crossings are roots of a
    trigonometric equation, so the sweep is exact however close the curve passes to x1.

    Parameters
    ----------
    x1, n1 : ndarray, shape (M, 3)
    P0, P1, P2 : ndarray, shape (M, 3)
    A, B : ndarray, shape (M,)
        0 <= B - A <= 2 pi.

    Returns
    -------
    ndarray, shape (M,)
    """

    def at(u):
        return P0 + np.cos(u)[:, None] * P1 + np.sin(u)[:, None] * P2 - x1

    start = at(A)
    f1 = start - _dot(start, n1)[:, None] * n1
    f1 /= np.maximum(np.linalg.norm(f1, axis=-1), 1e-300)[:, None]
    f2 = np.cross(n1, f1)
    end = at(B)
    sweep = np.arctan2(_dot(end, f2), _dot(end, f1))
    # crossings of the ray -f1: Y(u) = (x(u) - x1) . f2 = 0 with X(u) < 0
    Y0, Y1, Y2 = _dot(P0 - x1, f2), _dot(P1, f2), _dot(P2, f2)
    roots = _trig_roots(Y0, Y1, Y2)
    roots = np.where(roots < TWO_PI, A[:, None] + np.mod(roots - A[:, None], TWO_PI), np.inf)
    inside = (roots > A[:, None]) & (roots < B[:, None])
    u = np.where(inside, roots, A[:, None])
    X = _dot(P0 - x1, f1)[:, None] + np.cos(u) * _dot(P1, f1)[:, None] + np.sin(u) * _dot(P2, f1)[:, None]
    slope = -np.sin(u) * Y1[:, None] + np.cos(u) * Y2[:, None]
    turns = np.where(inside & (X < 0), np.where(slope < 0, 1.0, -1.0), 0.0).sum(-1)
    return sweep + TWO_PI * turns


def cylinder_patch(x1, n1, frame, box, orientation, inward):
    """F(dA1 -> patch of a circular cylinder) by contour integration over its visible part.

    The patch is x(u, v) = c + R (cos u e1 + sin u e2) + v w over box (u0, u1, v0, v1). Its part
    facing x1 is an interval of u (bounded by silhouette generators); x1's horizon cuts it along
    v = v*(u) (an ellipse, which lies in x1's tangent plane, so it contributes only the angle it
    sweeps: `planar_sweep`). Over each u-range
    where the bottom and top curves do not change, the boundary is: bottom (rim arc or horizon),
    right generator, top, left generator; shared generators cancel.

    Parameters
    ----------
    x1, n1 : ndarray, shape (K, 3)
        Points and unit normals (world).
    frame : ndarray, shape (K, 5, 3)
        c, e1, e2, w and (R, 0, 0) of each cylinder: e1, e2 orthonormal, w orthogonal to both.
    box : ndarray, shape (K, 4)
    orientation : ndarray, shape (K,)
        +1 if the front normal is dP/du x dP/dv, else -1.
    inward : ndarray of bool, shape (K,)
        Front side is the inside.

    Returns
    -------
    F : ndarray, shape (K,)
    terms : int
        Boundary pieces integrated (four per visible u-range).
    """
    K = x1.shape[0]
    c, e1, e2, w = frame[:, 0], frame[:, 1], frame[:, 2], frame[:, 3]
    R = frame[:, 4, 0]
    u0, u1, v0, v1 = box.T
    q = x1 - c
    q1, q2 = _dot(q, e1), _dot(q, e2)
    rho = np.hypot(q1, q2)
    # facing: outward r(u) . q > R, inward r(u) . q < R (always true from inside)
    facing_sign = np.where(inward, -1.0, 1.0)
    fP, fQ, fS = -facing_sign * R, facing_sign * q1, facing_sign * q2
    facing_active = ~(inward & (rho <= R * (1 + 1e-12)))
    nowhere = ~inward & (rho <= R)
    # horizon: a(u) + b v > 0 with a(u) = a0 + a1 cos u + a2 sin u
    a0, a1, a2 = -_dot(n1, q), R * _dot(n1, e1), R * _dot(n1, e2)
    b = _dot(n1, w)
    scale = np.linalg.norm(q, axis=-1) + R + np.linalg.norm(w, axis=-1) * (np.abs(v0) + np.abs(v1))
    level = np.abs(b) * (np.abs(v1 - v0) + 1.0) <= 1e-14 * scale
    touching = level & (a0 - np.hypot(a1, a2) >= -1e-12 * scale)  # horizon plane tangent along a generator
    b_safe = np.where(level, 1.0, b)

    # u breakpoints: patch ends, silhouette, horizon meeting the rims (or the horizon itself)
    roots = [
        np.where(facing_active[:, None], _trig_roots(fP, fQ, fS), 2 * TWO_PI),
        np.where((level & ~touching)[:, None], _trig_roots(a0, a1, a2), 2 * TWO_PI),
        np.where(~level[:, None], _trig_roots(a0 + b * v0, a1, a2), 2 * TWO_PI),
        np.where(~level[:, None], _trig_roots(a0 + b * v1, a1, a2), 2 * TWO_PI),
    ]
    cuts = np.concatenate(roots, -1)
    # bring roots into the patch's u-range (it may start anywhere in [0, 2 pi])
    cuts = np.where(cuts < TWO_PI, u0[:, None] + np.mod(cuts - u0[:, None], TWO_PI), 2 * TWO_PI)
    cuts = np.where(cuts < u1[:, None], cuts, u1[:, None])
    cuts = np.sort(np.concatenate([u0[:, None], cuts, u1[:, None]], -1), -1)
    ua, ub = cuts[:, :-1], cuts[:, 1:]
    um = 0.5 * (ua + ub)

    def horizon_v(u):
        return -(a0[:, None] + a1[:, None] * np.cos(u) + a2[:, None] * np.sin(u)) / b_safe[:, None]

    ok = (ub > ua) & ~nowhere[:, None]
    ok &= ~facing_active[:, None] | (fP[:, None] + fQ[:, None] * np.cos(um) + fS[:, None] * np.sin(um) > 0)
    horizon_mid = a0[:, None] + a1[:, None] * np.cos(um) + a2[:, None] * np.sin(um)
    ok &= ~(level & ~touching)[:, None] | (horizon_mid > 0)
    vm = horizon_v(um)
    rises = (~level & (b > 0))[:, None]
    falls = (~level & (b < 0))[:, None]
    bottom_horizon = rises & (vm > v0[:, None])
    top_horizon = falls & (vm < v1[:, None])
    lo_m = np.where(bottom_horizon, vm, v0[:, None])
    hi_m = np.where(top_horizon, vm, v1[:, None])
    ok &= hi_m > lo_m

    rows, cols = np.nonzero(ok)
    total = np.zeros(K)
    if rows.size:
        X, N = x1[rows], n1[rows]
        A, B = ua[rows, cols], ub[rows, cols]

        def point(u, v):
            return (
                c[rows]
                + R[rows, None] * (np.cos(u)[:, None] * e1[rows] + np.sin(u)[:, None] * e2[rows])
                + (v[:, None] * w[rows])
            )

        def ends(u):
            vh = -(a0[rows] + a1[rows] * np.cos(u) + a2[rows] * np.sin(u)) / b_safe[rows]
            lo = np.where(bottom_horizon[rows, cols], vh, v0[rows])
            hi = np.where(top_horizon[rows, cols], vh, v1[rows])
            return lo, hi

        lo_a, hi_a = ends(A)
        lo_b, hi_b = ends(B)
        # generators: up the right side, down the left side
        sides = edge_terms(
            X[:, None],
            N[:, None],
            np.stack([point(B, lo_b), point(A, hi_a)], 1),
            np.stack([point(B, hi_b), point(A, lo_a)], 1),
        ).sum(1)
        # rims: bottom run forwards, top backwards
        part = np.zeros(rows.size)
        for rim_v, is_horizon, sign in ((v0, bottom_horizon, 1.0), (v1, top_horizon, -1.0)):
            arc = ~is_horizon[rows, cols]
            k = np.flatnonzero(arc)
            if k.size:
                r = rows[k]
                center = c[r] + rim_v[r, None] * w[r]
                part[k] += sign * arc_integral(X[k], N[k], center, e1[r], e2[r], R[r], A[k], B[k])
            k = np.flatnonzero(~arc)
            if k.size:
                # the horizon curve x(u) = P0 + P1 cos u + P2 sin u lies in x1's tangent plane
                r = rows[k]
                P0 = c[r] - (a0[r] / b_safe[r])[:, None] * w[r]
                P1 = R[r, None] * e1[r] - (a1[r] / b_safe[r])[:, None] * w[r]
                P2 = R[r, None] * e2[r] - (a2[r] / b_safe[r])[:, None] * w[r]
                part[k] += sign * planar_sweep(X[k], N[k], P0, P1, P2, A[k], B[k])
        total = np.bincount(rows, sides + part, K)

    F = -orientation * total / TWO_PI
    # a point on a concave patch sees a full horizon around itself
    u_x = np.mod(np.arctan2(q2, q1) - u0, TWO_PI) + u0
    v_x = _dot(q, w) / _dot(w, w)
    on_patch = inward & touching & (np.abs(rho - R) <= 1e-10 * R) & (u_x <= u1) & (v_x >= v0) & (v_x <= v1)
    F = F + np.where(on_patch, 1.0, 0.0)
    return np.where(nowhere, 0.0, np.maximum(F, 0.0)), 4 * rows.size
