"""F(dA1 -> whole ellipsoid) by a contour integral around the part of it that a point sees.

Either side may be the front: from a point outside, the directions that reach the outside of
the near wall above the point's horizon are those that reach the inside of the far wall.

From a point strictly inside, every direction above the horizon meets the (convex) ellipsoid
once, on its inside: F = 1 when the inside is the front and 0 when it is the back (the enclosure
rule: a surface element inside a closed convex surface sees only it, Siegel & Howell, "Thermal
Radiation Heat Transfer", the configuration-factor algebra of enclosures). From a point on the
ellipsoid (to ON_SURFACE), the directions that enter it are the half-space inside its tangent
plane, so the point sees the inside through the lune between that half-space and its own
horizon: F = (1 + n1 . m) / 2 with m the inward unit normal (the element-to-tilted-plane factor
of the same catalogue; 1 for a patch of the inside itself, 0 for one of the outside), and 0 for
an outward front.

For a point x1 with unit normal n1 and a surface S that x1 sees whole and front side on, without
any part hiding another, F(dA1 -> S) depends only on S's boundary (Stokes' theorem; Sparrow's
contour method):

    F = 1/(2 pi) |contour integral of n1 . (R x dR) / |R|^2|,   R = y - x1, y on the boundary.

The part of a convex body that x1 sees front side on, above its horizon, is bounded by (a) the
curve where the tangent cone from x1 touches the body and (b) the body's cut by x1's tangent
plane. For an ellipsoid E = {c + L p : |p| = 1} both are planar ellipses, the images under L of
two circles on the unit sphere in local coordinates p = L^-1 (y - c):

- the contact circle {|p| = 1, p . q = 1}, q = L^-1 (x1 - c) (tangency is affine invariant: the
  polar plane of q);
- the horizon circle {|p| = 1, m . p = k}, m = L^T n1, k = n1 . (x1 - c).

The visible region is bounded by the arc of the contact circle above the horizon and the arc of
the horizon circle that faces x1 (p . q >= 1); both arcs end where the circles cross. Each arc is
integrated by Gauss-Legendre rules of doubling order until two successive orders agree to the
point's tolerance; the integrand is analytic along the arcs (x1 is off the ellipsoid), so the
rules converge geometrically at a rate set by x1's distance to the ellipsoid for its size.

Reference: E. M. Sparrow, "A new and simpler formulation for radiative angle factors", J. Heat
Transfer 85 (1963) 81-88 (contour integral form of the point-to-surface factor).
"""

import numpy as np

from .bounds import lengths
from .quadrature import gauss_legendre

ORDERS = (16, 32, 64, 128, 256)  # Gauss points per arc, tried in turn
ON_SURFACE = 1e-9  # |q|^2 within this of 1: the point is on the ellipsoid (the lune); below:
# inside (F = 1 or 0); above: outside (the contour)


def _circle_frame(axis):
    """Two unit vectors completing the unit `axis` (K, 3) to a right-handed frame, each (K, 3)."""
    helper = np.zeros_like(axis)
    helper[np.arange(len(axis)), np.argmin(np.abs(axis), axis=1)] = 1.0
    e1 = np.cross(helper, axis)
    e1 /= lengths(e1)[:, None]
    return e1, np.cross(axis, e1)


def _arc_integral(x1, n1, center, linear, middle, radius, e1, e2, t0, t1, n):
    """Integral of n1 . (R x dR) / |R|^2 along the arcs p(t) = middle + radius (e1 cos t + e2 sin t),
    t from t0 to t1, mapped to the world by y = center + linear p; n-point Gauss-Legendre, (K,)."""
    rule = gauss_legendre(n)
    t = t0[:, None] + (t1 - t0)[:, None] * rule.points  # (K, n)
    cos, sin = np.cos(t)[..., None], np.sin(t)[..., None]
    p = middle[:, None] + radius[:, None, None] * (e1[:, None] * cos + e2[:, None] * sin)
    dp = radius[:, None, None] * (e2[:, None] * cos - e1[:, None] * sin)
    R = np.einsum("kij,knj->kni", linear, p) + (center - x1)[:, None]
    dR = np.einsum("kij,knj->kni", linear, dp)
    f = np.einsum("ki,kni->kn", n1, np.cross(R, dR)) / np.einsum("kni,kni->kn", R, R)
    return (f @ rule.weights) * (t1 - t0)


def whole_ellipsoid(x1, n1, center, linear, local_from_world, inward, tolerance):
    """F(dA1 -> a whole ellipsoid, either side its front) at points off it.

    Parameters
    ----------
    x1, n1 : ndarray, shape (K, 3)
        Points (m) and unit front normals.
    center : ndarray, shape (K, 3)
        Ellipsoid centres c (m).
    linear, local_from_world : ndarray, shape (K, 3, 3)
        L (the ellipsoid is c + L p, |p| = 1) and its inverse.
    inward : ndarray of bool, shape (K,)
        Whether the ellipsoid's front is its inside (matters only for points inside it).
    tolerance : ndarray, shape (K,)
        Absolute error allowed for each value.

    Returns
    -------
    F, error : ndarray, shape (K,)
        Values and error estimates (the difference of the last two orders).
    done : ndarray of bool, shape (K,)
        Points handled: inside the ellipsoid or on it, or outside it and converged by the last
        order. The others (not converged) have meaningless values (the caller integrates them
        another way).
    evaluations : int
        Contour nodes evaluated.
    """
    K = len(x1)
    F = np.zeros(K)
    error = np.zeros(K)
    offset = x1 - center
    q = np.einsum("kij,kj->ki", local_from_world, offset)
    qq = np.einsum("ki,ki->k", q, q)
    done = qq > 1.0 + ON_SURFACE
    inside = qq < 1.0 - ON_SURFACE
    F[inside] = np.where(inward[inside], 1.0, 0.0)
    on = ~done & ~inside
    # the inward normal there: minus the gradient of |L^-1 (y - c)|^2, along L^-T q
    m = -np.einsum("kji,kj->ki", local_from_world[on], q[on])
    m /= lengths(m)[:, None]
    F[on] = np.where(inward[on], 0.5 * (1.0 + np.einsum("ki,ki->k", n1[on], m)), 0.0)
    inside |= on
    # contact circle: centre q / |q|^2, radius sqrt(1 - 1/|q|^2), in the plane normal to q
    safe_qq = np.where(done, qq, 2.0)
    q_unit = q / np.sqrt(safe_qq)[:, None]
    c_mid = q / safe_qq[:, None]
    c_rad = np.sqrt(1.0 - 1.0 / safe_qq)
    c1, c2 = _circle_frame(q_unit)
    # horizon in local coordinates: above it where m . p > k
    m = np.einsum("kji,kj->ki", linear, n1)
    k = np.einsum("ki,ki->k", n1, offset)
    alpha = np.einsum("ki,ki->k", m, c_mid) - k
    a_cos, a_sin = c_rad * np.einsum("ki,ki->k", m, c1), c_rad * np.einsum("ki,ki->k", m, c2)
    beta = np.hypot(a_cos, a_sin)
    phi = np.arctan2(a_sin, a_cos)

    # wholly below the horizon: F = 0 exactly; wholly above: the whole contact circle
    below = done & (alpha + beta <= 0.0)
    whole = done & ~below & (alpha - beta >= 0.0)
    cut = done & ~below & ~whole
    # contact arc above the horizon: alpha + beta cos(t - phi) >= 0
    tau = np.where(whole, np.pi, np.arccos(np.clip(-alpha / np.where(beta > 0, beta, 1.0), -1.0, 1.0)))
    t0, t1 = phi - tau, phi + tau
    # horizon circle: centre (k / |m|^2) m, radius sqrt(1 - k^2 / |m|^2), normal m; its arc
    # facing the point (p . q >= 1) runs between the same two crossings
    mm = np.einsum("ki,ki->k", m, m)
    m_unit = m / np.sqrt(mm)[:, None]
    h_mid = (k / mm)[:, None] * m
    h_rad = np.sqrt(np.clip(1.0 - k * k / mm, 0.0, None))
    h1, h2 = _circle_frame(m_unit)
    gamma = np.einsum("ki,ki->k", h_mid, q) - 1.0
    b_cos, b_sin = h_rad * np.einsum("ki,ki->k", h1, q), h_rad * np.einsum("ki,ki->k", h2, q)
    delta = np.hypot(b_cos, b_sin)
    psi = np.arctan2(b_sin, b_cos)
    omega = np.arccos(np.clip(-gamma / np.where(delta > 0, delta, 1.0), -1.0, 1.0))
    # orient the horizon arc to run from the contact arc's end back to its start
    end = h_mid + h_rad[:, None] * (h1 * np.cos(psi + omega)[:, None] + h2 * np.sin(psi + omega)[:, None])
    start_contact = c_mid + c_rad[:, None] * (c1 * np.cos(t0)[:, None] + c2 * np.sin(t0)[:, None])
    forward = lengths(end - start_contact) <= lengths(
        h_mid
        + h_rad[:, None] * (h1 * np.cos(psi - omega)[:, None] + h2 * np.sin(psi - omega)[:, None])
        - start_contact
    )
    s0 = np.where(forward, psi - omega, psi + omega)
    s1 = np.where(forward, psi + omega, psi - omega)

    evaluations = 0
    todo = np.flatnonzero(whole | cut)
    previous = None
    for n in ORDERS:
        sel = todo
        value = _arc_integral(
            x1[sel],
            n1[sel],
            center[sel],
            linear[sel],
            c_mid[sel],
            c_rad[sel],
            c1[sel],
            c2[sel],
            t0[sel],
            t1[sel],
            n,
        )
        evaluations += n * sel.size
        part = cut[sel]
        if part.any():
            c = sel[part]
            value[part] += _arc_integral(
                x1[c], n1[c], center[c], linear[c], h_mid[c], h_rad[c], h1[c], h2[c], s0[c], s1[c], n
            )
            evaluations += n * c.size
        value = np.abs(value) / (2.0 * np.pi)
        if previous is not None:
            difference = np.abs(value - previous)
            ok = difference <= tolerance[sel]
            F[sel[ok]], error[sel[ok]] = value[ok], difference[ok]
            todo, value = sel[~ok], value[~ok]
            if not todo.size:
                break
        previous = value
    done &= ~np.isin(np.arange(K), todo)
    return F, error, done | inside, evaluations
