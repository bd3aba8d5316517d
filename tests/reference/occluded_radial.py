"""Deterministic reference for the occluded form factor from floor points to a disk lamp past spheres.

Shares no code with core/ (it imports numpy only). Geometry: the floor z = 0 (normal +z), a disk
lamp of radius R centred at c = (cx, cy, H) facing -z, black spheres (s, a) inside 0 <= z < H
(one may rest on the floor). F_vis(x) = int_{visible part of the disk} H^2 / (pi |y - x|^4) dA_y.

Point factor (disk_point_factor_exact). Polar coordinates on the lamp, y = c + r (cos phi,
sin phi, 0). For fixed phi the segment x -> y(r) meets a sphere iff y - x lies in the sphere's
tangent cone from x, (w.u)^2 >= (|u|^2 - a^2) |w|^2 with w = y - x, u = s - x: a quadratic
inequality in r whose solution is one interval (see _PointSet); the intervals are clipped to
[0, R] and merged, and the r-integral of r / (r^2 + 2 b r + q)^2 over each visible (or blocked)
interval is done in closed form. In phi the integrand is analytic except where the interval
structure changes: rays tangent to a shadow conic (square-root behaviour), conic crossings of
the rim r = R, crossings of two conics. All three are roots of degree-2 trigonometric
polynomials (the discriminant, the quadratic at r = R, a cone generator of one sphere on the
other's cone), found as the eigenvalues of the companion matrix of a quartic in z = e^{i phi},
real roots polished by Newton's method (the arguments of complex roots are kept as extra
breakpoints: they mark nearby complex singularities). On each piece: Gauss-Legendre rules
(nodes by Newton's method on the three-term recurrence) after algebraic end substitutions
(t = s^2 at a singular end, t = 3 s^2 - 2 s^3 with both) that make (t - t0)^(k/2) end behaviour
analytic, and, where the neighbouring breakpoint is nearer than the piece is long, the further
substitution x = p +- tau^2 with the pole p at that breakpoint (variable transformations for
endpoint and near-endpoint singularities: Davis & Rabinowitz, Methods of Numerical Integration,
2nd ed. 1984, ch. 2.12). The unoccluded factor has the closed form of a plane element parallel
to a disk, offset from its axis (Howell, A Catalog of Radiation Heat Transfer Configuration
Factors, section B, "plane element to parallel disk, offset from its axis"; the configuration
number was not checked here): F = (1 - X / Y) / 2, X = H^2 + rho^2 - R^2,
Y = sqrt((H^2 + rho^2 + R^2)^2 - 4 R^2 rho^2), rho the offset; it is checked against direct
integration in tests/test_reference_radial.py.
Per point, whichever is cheaper of (visible part over the pieces where something blocks, plus
the whole ray where nothing does) and (closed form minus the blocked part); points whose spheres
cannot reach the lamp's cone get the closed form.

Patch mean (floor_patch_factor_exact). F_vis is analytic on the floor except on curves where the
topology of the visible lamp region changes; F_vis behaves like dist^(3/2) (or smoother) across
them. They are, parametrised explicitly (see _singular_curves): each sphere's penumbra and umbra
boundary (its shadow conic tangent to the rim: the floor point of the line from a rim point y
through the contact of the plane that holds the rim tangent at y and touches the sphere); for two
spheres, the floor points of their common tangent lines lying in a common tangent plane (the
generators of the cones from the centres of similitude) that pass through the lamp, and of the
lines from a rim point tangent to both. The mean is an iterated integral, X outer, Y inner, each
split at these curves' crossings (inner: X(t) = X solved on monotone pieces of each curve by
bisection; outer: the curves' vertical tangents, their crossings of y0 and y1, arc ends), each
piece integrated as above.

Error estimate. Every level (phi, Y, X) is adaptive: each piece is integrated by two rules
(n1 < n2 points, the n2 result kept), pieces whose |Q_n2 - Q_n1| exceeds their share of the
tolerance are bisected, and the returned error is the sum of the accepted |Q_n2 - Q_n1| plus the
integral of the inner level's error bars (plus rounding bounds of the closed forms). As the rules
converge exponentially, |Q_n2 - Q_n1| bounds the error of Q_n2 by a wide margin; the tests check
that runs at loose tolerance differ from tight ones by less than their error estimates.
"""

import numpy as np

TWO_PI = 2.0 * np.pi


# ---------------------------------------------------------------------------- quadrature
_RULES = {}


def _gauss_legendre(n):
    """Gauss-Legendre nodes and weights on [-1, 1] by Newton's method on the three-term
    recurrence (numpy's leggauss loses ~1e-14 in its weights' moments from n ~ 30 on)."""
    x = np.cos(np.pi * (np.arange(1, n + 1) - 0.25) / (n + 0.5))
    for _ in range(100):
        p0, p1 = np.ones_like(x), x
        for k in range(2, n + 1):
            p0, p1 = p1, ((2 * k - 1) * x * p1 - (k - 1) * p0) / k
        dp = n * (x * p1 - p0) / (x * x - 1.0)
        step = p1 / dp
        x = x - step
        if np.abs(step).max() < 1e-16:
            break
    p0, p1 = np.ones_like(x), x
    for k in range(2, n + 1):
        p0, p1 = p1, ((2 * k - 1) * x * p1 - (k - 1) * p0) / k
    dp = n * (x * p1 - p0) / (x * x - 1.0)
    return x[::-1], (2.0 / ((1.0 - x * x) * dp * dp))[::-1]


def _rule(n):
    """n-point Gauss-Legendre rule on [0, 1]."""
    if n not in _RULES:
        x, w = _gauss_legendre(n)
        _RULES[n] = ((x + 1.0) / 2.0, w / 2.0)
    return _RULES[n]


def _map(rows, s, w):
    """Nodes and weights of the rule (s, w) on [0, 1] mapped to each row [a, b] (rows: a, b,
    pole p, singular-end flags sa, sb).

    At a singular end the row is entered through t = s^2 (t = 3 s^2 - 2 s^3 with both ends
    singular), so that an end behaviour (x - a)^(k/2) becomes analytic in s. With a pole p
    (p <= a or p >= b; NaN for none), x = p + tau^2 or p - tau^2 with tau linear in t: a square
    root singularity at p, just outside the row, is then harmless too.
    """
    a, b, p, sa, sb = rows
    sa, sb = sa[:, None], sb[:, None]
    T = np.where(sa, np.where(sb, s * s * (3.0 - 2.0 * s), s * s), np.where(sb, s * (2.0 - s), s))
    dT = np.where(sa, np.where(sb, 6.0 * s * (1.0 - s), 2.0 * s), np.where(sb, 2.0 * (1.0 - s), 1.0))
    pole = ~np.isnan(p)
    pp = np.where(pole, p, a)
    left = (pp <= a)[:, None]
    ta = np.sqrt(np.abs(a - pp))[:, None]
    tb = np.sqrt(np.abs(b - pp))[:, None]
    dt = tb - ta
    tau_minus_ta = dt * T
    shift = tau_minus_ta * (2.0 * ta + tau_minus_ta)  # tau^2 - ta^2, free of the size of p
    x_pole = np.where(left, a[:, None] + shift, a[:, None] - shift)
    jac_pole = 2.0 * (ta + tau_minus_ta) * np.abs(dt)
    h = (b - a)[:, None]
    x = np.where(pole[:, None], x_pole, a[:, None] + h * T)
    jac = np.where(pole[:, None], jac_pole, h)
    return x, w * jac * dT


def _adaptive(owner, rows, func, tolerance, n_owner, n1, n2, max_rounds=60):
    """Integrals over rows (a, b, p, sa, sb; see _map) summed per owner: (value, error), arrays
    of length n_owner.

    func(owner_of_rows, x) -> (f, e): integrand values and their own error bars at nodes x of
    shape (rows, n). Each row is integrated by the n1- and n2-point rules; the n2 result is kept
    and |Q2 - Q1| is its error estimate. A row is accepted when that estimate is within its share
    (b - a) / (owner's total length) of the owner's tolerance(value) (value: the sum of the first
    round's results) or is explained by the integrand's own error bars; else it is bisected (the
    halves keep the pole; the new end is regular). The returned error is the sum of the accepted
    |Q2 - Q1| plus the n2-rule integral of the integrand's error bars.
    """
    value = np.zeros(n_owner)
    error = np.zeros(n_owner)
    a, b, p, sa, sb = rows
    keep = b > a
    owner, a, b, p, sa, sb = owner[keep], a[keep], b[keep], p[keep], sa[keep], sb[keep]
    length = np.bincount(owner, b - a, n_owner)
    s1, w1 = _rule(n1)
    s2, w2 = _rule(n2)
    tol = None
    for round_ in range(max_rounds):
        if len(owner) == 0:
            break
        x1, v1 = _map((a, b, p, sa, sb), s1, w1)
        x2, v2 = _map((a, b, p, sa, sb), s2, w2)
        f, e = func(owner, np.concatenate([x1, x2], axis=1))
        q1 = np.einsum("rn,rn->r", f[:, :n1], v1)
        q2 = np.einsum("rn,rn->r", f[:, n1:], v2)
        inner = np.einsum("rn,rn->r", e[:, n1:], v2)
        diff = np.abs(q2 - q1)
        if tol is None:
            tol = tolerance(np.bincount(owner, q2, n_owner))
        h = b - a
        ok = (
            (diff <= tol[owner] * h / length[owner])
            | (diff <= 2.0 * inner)  # explained by the integrand's own error bars
            | (h <= 1e-13 * length[owner])
            | (round_ == max_rounds - 1)
        )
        value += np.bincount(owner[ok], q2[ok], n_owner)
        error += np.bincount(owner[ok], diff[ok] + inner[ok], n_owner)
        bad = ~ok
        mid = 0.5 * (a[bad] + b[bad])
        no = np.zeros(len(mid), bool)
        owner, p = np.tile(owner[bad], 2), np.tile(p[bad], 2)
        a, b = np.concatenate([a[bad], mid]), np.concatenate([mid, b[bad]])
        sa, sb = np.concatenate([sa[bad], no]), np.concatenate([no, sb[bad]])
    return value, error


def _pieces(bp, before, after, count=None, ends_singular=False):
    """(owner, rows) for _adaptive from sorted breakpoints bp (K, m) whose first and last valid
    entries (the first count[k], default all) are the ends of owner k's range, the others
    singular points of the integrand; `before` / `after` (K,) are the nearest singular points
    outside the range (or -inf / inf). The range's own ends count as singular with
    ends_singular or where a singular point lies on them.

    A piece whose neighbouring singular point on one side is nearer than its length gets its
    pole there (see _map); a piece with near neighbours on both sides is split at its middle, a
    pole for each half; a piece with none has no pole.
    """
    K, m = bp.shape
    count = np.full(K, m) if count is None else np.asarray(count)
    col = np.arange(m - 1)[None, :]
    valid = col < (count - 1)[:, None]
    lo, hi = bp[:, :-1], bp[:, 1:]
    prev = np.concatenate([before[:, None], bp[:, :-2]], axis=1)
    nxt = np.concatenate([bp[:, 2:], np.zeros((K, 1))], axis=1)
    last = col + 2 >= count[:, None]
    nxt = np.where(last, after[:, None], nxt)
    sing_lo = (col > 0) | ends_singular | (before[:, None] >= lo)
    sing_hi = ~last | ends_singular | (after[:, None] <= hi)
    length = hi - lo
    near_l = (lo - prev) < length
    near_r = (nxt - hi) < length
    both = near_l & near_r
    mid = lo + 0.5 * length
    # first rows: the whole piece, or its left half
    b1 = np.where(both, mid, hi)
    p1 = np.where(near_l, prev, np.where(near_r, nxt, np.nan))
    sb1 = np.where(both, False, sing_hi)
    owner = np.broadcast_to(np.arange(K)[:, None], lo.shape)
    take = valid & both  # second rows: the right half
    rows = (
        np.concatenate([lo[valid], mid[take]]),
        np.concatenate([b1[valid], hi[take]]),
        np.concatenate([p1[valid], nxt[take]]),
        np.concatenate([sing_lo[valid], np.zeros(take.sum(), bool)]),
        np.concatenate([sb1[valid], sing_hi[take]]),
    )
    return np.concatenate([owner[valid], owner[take]]), rows


# ---------------------------------------------------------------------------- trigonometric roots
_FIVE = TWO_PI * np.arange(5) / 5


def _trig_coefficients(g):
    """Coefficients (a0, a1, b1, a2, b2) of a0 + a1 cos + b1 sin + a2 cos 2t + b2 sin 2t from its
    values at the five angles 2 pi m / 5 (last axis), each of shape g.shape[:-1]."""
    c1, s1, c2, s2 = np.cos(_FIVE), np.sin(_FIVE), np.cos(2 * _FIVE), np.sin(2 * _FIVE)
    return g.mean(-1), 0.4 * g @ c1, 0.4 * g @ s1, 0.4 * g @ c2, 0.4 * g @ s2


def _trig_roots(coef):
    """The four angles of the roots z of z^2 g(z) (z = e^{it}) of a degree-2 trigonometric
    polynomial, shape (..., 4): the real roots of g (|z| = 1), polished by Newton's method, and
    the real parts of its complex roots (harmless extra breakpoints that also mark where the
    integrand has a nearby complex singularity)."""
    a0, a1, b1, a2, b2 = coef
    scale = np.maximum.reduce([np.abs(a0), np.abs(a1), np.abs(b1), np.abs(a2), np.abs(b2)])
    scale = np.where(scale > 0, scale, 1.0)
    c4 = 0.5 * (a2 - 1j * b2)
    small = np.abs(c4) < 1e-13 * scale
    c4 = np.where(small, 1e-13 * scale, c4)  # degree drop: two roots move to 0 and infinity
    c3, c2, c1, c0 = 0.5 * (a1 - 1j * b1), a0 + 0j, 0.5 * (a1 + 1j * b1), 0.5 * (a2 + 1j * b2)
    shape = a0.shape
    comp = np.zeros(shape + (4, 4), complex)
    comp[..., 0, 0] = -c3 / c4
    comp[..., 0, 1] = -c2 / c4
    comp[..., 0, 2] = -c1 / c4
    comp[..., 0, 3] = -c0 / c4
    comp[..., 1, 0] = comp[..., 2, 1] = comp[..., 3, 2] = 1.0
    z = np.linalg.eigvals(comp)
    t = np.angle(z)
    near = np.abs(np.abs(z) - 1.0) < 0.05
    cf = [c[..., None] for c in (a0, a1, b1, a2, b2)]
    for _ in range(6):
        g = cf[0] + cf[1] * np.cos(t) + cf[2] * np.sin(t) + cf[3] * np.cos(2 * t) + cf[4] * np.sin(2 * t)
        dg = -cf[1] * np.sin(t) + cf[2] * np.cos(t) - 2 * cf[3] * np.sin(2 * t) + 2 * cf[4] * np.cos(2 * t)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = g / dg
        step = np.where(near & np.isfinite(step) & (np.abs(step) < 0.02), step, 0.0)
        t = t - step
    return t


# ---------------------------------------------------------------------------- point factor
def unoccluded_factor(points, lamp_center, lamp_radius):
    """F(dA(x) -> disk) without occluders for floor points x (K, 3): the parallel offset
    element-to-disk form factor (Howell's catalogue, B-13), 0.5 (1 - X / Y) with
    X = H^2 + rho^2 - R^2, Y = sqrt((H^2 + rho^2 + R^2)^2 - 4 R^2 rho^2), written without the
    cancellation of 1 - X / Y: Y^2 - X^2 = 4 R^2 H^2 and Y^2 = (H^2 + (rho - R)^2)(H^2 + (rho + R)^2)."""
    points = np.asarray(points, float).reshape(-1, 3)
    c = np.asarray(lamp_center, float)
    H, R = c[2] - points[:, 2], float(lamp_radius)
    rho = np.hypot(points[:, 0] - c[0], points[:, 1] - c[1])
    X = H * H + rho * rho - R * R
    Y = np.sqrt((H * H + (rho - R) ** 2) * (H * H + (rho + R) ** 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(X > 0, 2.0 * R * R * H * H / (Y * (Y + np.abs(X))), (Y - X) / (2.0 * Y))


def _interval_integral(r1, r2, b, D):
    """int_{r1}^{r2} r dr / (r^2 + 2 b r + q)^2 with D = q - b^2 > 0, in a form free of the
    cancellation of G(r2) - G(r1) (G the antiderivative below) when r2 - r1 is small:
    G(r) = -1/(2Q) - b [t / (2 D Q) + atan(t / sqrt D) / (2 D^1.5)], t = r + b, Q = t^2 + D;
    and a bound on its rounding error (its two terms still cancel when |b| >> r)."""
    t1, t2 = r1 + b, r2 + b
    Q1, Q2 = t1 * t1 + D, t2 * t2 + D
    delta = r2 - r1
    sD = np.sqrt(D)
    first = delta / (Q1 * Q2) * (0.5 * (t1 + t2) - b * (D - t1 * t2) / (2.0 * D))
    second = b / (2.0 * D * sD) * np.arctan2(delta * sD, D + t1 * t2)
    return first - second, 1e-15 * (np.abs(first) + np.abs(second))


class _PointSet:
    """Per-point quantities of F_vis(x) for floor points x (K, 3), z = 0.

    Lamp ray at angle phi: y(r) = c + r e, e = (cos phi, sin phi, 0), w = y - x = w0 + r e with
    w0 = (d, H), d = c_xy - x_xy; |w|^2 = r^2 + 2 b r + q0, b = d.e, q0 = |d|^2 + H^2, and
    D = q0 - b^2 = H^2 + eps^2, eps = d1 sin phi - d2 cos phi. For a sphere (s, a), u = s - x,
    k = |u|^2 - a^2: the segment x -> y(r) meets it iff f(r) = (w.u)^2 - k |w|^2 >= 0, a quadratic
    A r^2 + 2 B r + C with A = (e.u)^2 - k <= 0, B = (w0.u)(e.u) - k b, C = (w0.u)^2 - k q0
    (C does not depend on phi: its sign says whether the lamp centre is in the sphere's shadow).
    Its discriminant is B^2 - A C = k (a^2 D - g^2), g = H (u2 cos phi - u1 sin phi) + eps u3
    (g / sqrt D is the distance of s from the plane through x and the ray): the form used, which
    loses far less to cancellation near a tangent ray.
    """

    def __init__(self, points, center, radius, spheres):
        points = np.asarray(points, float).reshape(-1, 3)
        self.center = np.asarray(center, float)
        self.R = float(radius)
        self.H = float(self.center[2])
        self.x = points[:, :2]
        self.d = self.center[:2] - self.x
        self.q0 = np.einsum("ki,ki->k", self.d, self.d) + self.H**2
        self.spheres = [(np.asarray(s, float), float(a)) for s, a in spheres]
        self.u, self.k, self.p0, self.relevant = [], [], [], []
        self.inside = np.zeros(len(points), bool)  # x on (or inside) a sphere: no light
        lamp = np.column_stack([self.d, np.full(len(points), self.H)])
        lamp_dist = np.sqrt(self.q0)
        lamp_angle = np.arcsin(np.minimum(self.R / lamp_dist, 1.0))
        for s, a in self.spheres:
            u = s[None, :] - np.column_stack([self.x, np.zeros(len(points))])
            k = np.einsum("ki,ki->k", u, u) - a * a
            self.inside |= k <= 0
            self.u.append(u)
            self.k.append(np.where(k > 0, k, 1.0))
            self.p0.append(self.d[:, 0] * u[:, 0] + self.d[:, 1] * u[:, 1] + self.H * u[:, 2])
            # can the sphere's tangent cone from x meet the cone of the lamp's bounding ball?
            L = np.linalg.norm(u, axis=1)
            cos = np.einsum("ki,ki->k", u, lamp) / (L * lamp_dist)
            gap = np.arccos(np.clip(cos, -1.0, 1.0)) - np.arcsin(np.minimum(a / L, 1.0)) - lamp_angle
            self.relevant.append((gap < 1e-6) & (k > 0))

    def quadratic(self, i, owner, cos, sin):
        """A, B, C of f(r) along the ray at angle phi, arrays broadcast with cos, sin."""
        u = self.u[i][owner]
        k = self.k[i][owner][..., None]
        p0 = self.p0[i][owner][..., None]
        d = self.d[owner]
        p1 = cos * u[..., 0:1] + sin * u[..., 1:2]
        b = cos * d[..., 0:1] + sin * d[..., 1:2]
        return p1 * p1 - k, p0 * p1 - k * b, p0 * p0 - k * self.q0[owner][..., None]

    def intervals(self, owner, cos, sin, eps):
        """Blocked r-intervals [lo, hi] within [0, R] of each sphere (lo = hi = R where empty),
        each (S, rows, n), and the rounding error bars of lo and hi."""
        R, H = self.R, self.H
        D = eps * eps + H * H
        los, his, dlos, dhis = [], [], [], []
        for i, (_, a) in enumerate(self.spheres):
            u = self.u[i][owner]
            k = self.k[i][owner][:, None]
            A, B, C = self.quadratic(i, owner, cos, sin)
            A = np.minimum(A, -1e-30 * k)  # A <= 0 in exact arithmetic
            g = H * (u[:, 1:2] * cos - u[:, 0:1] * sin) + eps * u[:, 2:3]
            aD = a * np.sqrt(D)
            disc = k * (aD - np.abs(g)) * (aD + np.abs(g))
            sq = np.sqrt(np.maximum(disc, 0.0))
            noise = 8e-16 * k * aD * aD
            dsq = np.minimum(noise / (2.0 * np.maximum(sq, 1e-300)), np.sqrt(noise))
            qq = -(B + np.copysign(sq, B))
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                ra, rb = qq / A, C / qq
                dra, drb = dsq / np.abs(A), np.abs(rb / qq) * dsq
            swap = ra > rb
            lo, hi = np.where(swap, rb, ra), np.where(swap, ra, rb)
            dlo, dhi = np.where(swap, drb, dra), np.where(swap, dra, drb)
            empty = ~(disc > 0) | ~(hi > 0) | ~(lo < R) | ~self.relevant[i][owner][:, None]
            dlos.append(np.where(empty | (lo <= 0), 0.0, dlo))
            dhis.append(np.where(empty | (hi >= R), 0.0, dhi))
            los.append(np.where(empty, R, np.clip(lo, 0.0, R)))
            his.append(np.where(empty, R, np.clip(hi, 0.0, R)))
        return np.array(los), np.array(his), np.array(dlos), np.array(dhis)

    def ray(self, owner, phi, blocked):
        """H^2/pi times the r-integral over the blocked (or, blocked=False, the visible) part of
        the lamp ray at angles phi (rows, n), and its rounding error bar."""
        cos, sin = np.cos(phi), np.sin(phi)
        d = self.d[owner]
        b = cos * d[:, 0:1] + sin * d[:, 1:2]
        eps = sin * d[:, 0:1] - cos * d[:, 1:2]
        D = eps * eps + self.H**2
        R = self.R
        out = np.zeros_like(phi)
        err = np.zeros_like(phi)
        reach = np.zeros_like(phi)
        if self.spheres:
            lo, hi, dlo, dhi = self.intervals(owner, cos, sin, eps)
            order = np.argsort(lo, axis=0)
            lo, hi = np.take_along_axis(lo, order, 0), np.take_along_axis(hi, order, 0)
            for j in range(len(lo)):
                if blocked:
                    start = np.maximum(reach, lo[j])
                    value, rounding = _interval_integral(start, np.maximum(start, hi[j]), b, D)
                else:
                    value, rounding = _interval_integral(reach, np.maximum(reach, lo[j]), b, D)
                out += value
                err += rounding
                reach = np.maximum(reach, hi[j])
            for r, dr in ((lo, dlo), (hi, dhi)):
                t = r + b[None]
                err += (dr * r / (t * t + D[None]) ** 2).sum(0)
        if not blocked:
            value, rounding = _interval_integral(reach, np.full_like(phi, R), b, D)
            out += value
            err += rounding
        scale = self.H**2 / np.pi
        out *= scale
        err *= scale
        if not blocked:
            out[self.inside[owner]] = 0.0
        return out, err

    def breakpoints(self):
        """Angles (K, m) where the blocked r-set is not analytic in phi: tangent rays of each
        shadow conic, its crossings with the rim, crossings of two conics; mod 2 pi, sorted."""
        K = len(self.x)
        cos, sin = np.cos(_FIVE)[None, :], np.sin(_FIVE)[None, :]
        angles = [np.zeros((K, 1))]
        for i in range(len(self.spheres)):
            owner = np.nonzero(self.relevant[i])[0]
            A, B, C = self.quadratic(i, owner, cos, sin)
            for g in (B * B - A * C, A * self.R**2 + 2 * B * self.R + C):
                out = np.zeros((K, 4))
                out[owner] = _trig_roots(_trig_coefficients(g))
                angles.append(out)
        for i in range(len(self.spheres)):
            for j in range(i + 1, len(self.spheres)):
                owner = np.nonzero(self.relevant[i] & self.relevant[j])[0]
                out = np.zeros((K, 4))
                out[owner] = self._pair_angles(i, j, owner)
                angles.append(out)
        angles = np.mod(np.concatenate(angles, axis=1), TWO_PI)
        return np.sort(angles, axis=1)

    def _pair_angles(self, i, j, owner):
        """Angles of the (up to 4) points where the shadow conics of spheres i and j cross: the
        generators v(t) of i's tangent cone on j's, (v.u_j)^2 = k_j, a trigonometric quadratic."""
        u = self.u[i][owner]
        L = np.linalg.norm(u, axis=1)
        axis = u / L[:, None]
        ref = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        p = np.cross(axis, ref)
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        q = np.cross(axis, p)
        ca = np.sqrt(self.k[i][owner]) / L
        sa = self.spheres[i][1] / L

        def generator(t):
            return ca[:, None, None] * axis[:, None, :] + sa[:, None, None] * (
                np.cos(t)[..., None] * p[:, None, :] + np.sin(t)[..., None] * q[:, None, :]
            )

        v = generator(np.broadcast_to(_FIVE, (len(L), 5)))
        g = np.einsum("kmi,ki->km", v, self.u[j][owner]) ** 2 - self.k[j][owner][:, None]
        t = _trig_roots(_trig_coefficients(g))
        v = generator(t)
        ok = v[..., 2] > 1e-12
        vz = np.where(ok, v[..., 2], 1.0)
        y = self.x[owner][:, None, :] + self.H * v[..., :2] / vz[..., None]
        ang = np.arctan2(y[..., 1] - self.center[1], y[..., 0] - self.center[0])
        return np.where(ok, ang, 0.0)


_N_PHI = (16, 24)
_CHUNK = 1024  # rows per block of ray evaluations


def _point_factors(points, center, radius, spheres, rtol, atol, integrate_all=False):
    """(F, error) at floor points (K, 3).

    Spheres whose tangent cone from x cannot meet the lamp are dropped for that point; where none
    is left, F is the closed-form unoccluded factor. Elsewhere the ray's blocked set is the same
    kind on a whole piece between breakpoints: empty, all of [0, R], or partial (told at the
    piece's middle), and F is the cheaper of two exact sums: F = (visible part over the partial
    pieces) + (whole ray over the empty ones), or F = (unoccluded factor) - (blocked part over
    the partial and the full pieces); the second only where it has fewer rows, as its
    subtraction costs ~1e-16 of the unoccluded factor. With integrate_all, the visible part is
    integrated over all pieces (no closed form, no skipping: a check of the machinery).
    """
    points = np.asarray(points, float).reshape(-1, 3)
    K = len(points)
    ps = _PointSet(points, center, radius, spheres)
    full = unoccluded_factor(points, center, radius)
    value, error = full.copy(), 1e-15 * full  # the closed form's rounding
    active = np.ones(K, bool) if integrate_all else np.any(ps.relevant, axis=0) & ~ps.inside
    value[ps.inside], error[ps.inside] = 0.0, 0.0
    if not active.any():
        return value, error
    ps = _PointSet(points[active], center, radius, spheres)
    full = full[active]
    Ka = len(full)
    bp = ps.breakpoints()
    bp = np.concatenate([bp, bp[:, :1] + TWO_PI], axis=1)
    owner, rows = _pieces(bp, bp[:, -2] - TWO_PI, bp[:, 1] + TWO_PI, ends_singular=True)
    complement = np.zeros(Ka, bool)
    if not integrate_all:
        a, b = rows[0], rows[1]
        mid = 0.5 * (a + b)[:, None]
        eps = np.sin(mid) * ps.d[owner, :1] - np.cos(mid) * ps.d[owner, 1:]
        lo, hi, _, _ = ps.intervals(owner, np.cos(mid), np.sin(mid), eps)
        lo, hi = lo[..., 0], hi[..., 0]
        order = np.argsort(lo, axis=0)
        lo, hi = np.take_along_axis(lo, order, 0), np.take_along_axis(hi, order, 0)
        gap, reach = np.zeros(len(owner)), np.zeros(len(owner))
        for j in range(len(lo)):
            gap += np.maximum(lo[j] - reach, 0.0)
            reach = np.maximum(reach, hi[j])
        gap += ps.R - reach
        kind = np.where((hi > lo).any(axis=0), np.where(gap > 0, 1, 2), 0)  # empty, partial, full
        n_none = np.bincount(owner, kind == 0, Ka)
        n_full = np.bincount(owner, kind == 2, Ka)
        complement = n_full <= n_none
        keep = np.where(complement[owner], kind > 0, kind < 2)
        owner, rows = owner[keep], tuple(r[keep] for r in rows)

    def func(own, phi):
        f, e = np.empty_like(phi), np.empty_like(phi)
        for blocked in (False, True):
            sel = np.nonzero(complement[own] == blocked)[0]
            for chunk in np.array_split(sel, max(1, -(-len(sel) // _CHUNK))):  # cache-sized blocks
                if len(chunk):
                    f[chunk], e[chunk] = ps.ray(own[chunk], phi[chunk], blocked)
        return f, e

    def tolerance(first):
        return np.maximum(rtol * np.abs(np.where(complement, full - first, first)), atol)

    v, e = _adaptive(owner, rows, func, tolerance, Ka, *_N_PHI)
    value[active] = np.where(complement, np.maximum(full - v, 0.0), v)
    error[active] = e + np.where(complement, 1e-15 * full, 0.0)
    return value, error


def disk_point_factor_exact(
    points, lamp_center, lamp_radius, spheres, rtol=1e-12, atol=1e-16, integrate_all=False
):
    """F_vis(x) for floor points x (K, 3) (z = 0, normal +z) to the disk lamp (centre, radius,
    facing -z) past spheres [((sx, sy, sz), a), ...]: (F, error estimate), each shape (K,), the
    estimate kept within max(rtol F, atol). A point on a sphere (a resting sphere's contact
    point) gets F = 0. integrate_all: integrate the visible part over all of the lamp, without
    the closed-form unoccluded factor (a check of the integration)."""
    return _point_factors(points, lamp_center, lamp_radius, spheres, rtol, atol, integrate_all)


# ---------------------------------------------------------------------------- singular curves on the floor
def _floor_hit(origin, direction):
    """Floor (z = 0) points of the lines origin + t direction: (X, Y)."""
    t = -origin[..., 2] / direction[..., 2]
    return origin[..., 0] + t * direction[..., 0], origin[..., 1] + t * direction[..., 1]


def _penumbra_curve(center, radius, sphere, sign):
    """Floor points x where sphere's shadow conic on the lamp plane is tangent to the rim, as a
    function of the rim angle psi of the contact: the plane through the rim tangent line at y(psi)
    tangent to the sphere (two such planes: sign) touches it at T; x is where the line y T meets
    the floor. The outer (penumbra) and inner (umbra) boundaries of the sphere's shadow."""
    c, R = center, radius
    s, a = sphere

    def curve(psi):
        cos, sin = np.cos(psi), np.sin(psi)
        y = np.stack([c[0] + R * cos, c[1] + R * sin, np.full_like(psi, c[2])], axis=-1)
        g1 = (s[0] - y[..., 0]) * cos + (s[1] - y[..., 1]) * sin
        g2 = s[2] - c[2]
        beta = np.arctan2(g2, g1) + sign * np.arccos(np.clip(a / np.hypot(g1, g2), -1.0, 1.0))
        n = np.stack([np.cos(beta) * cos, np.cos(beta) * sin, np.sin(beta)], axis=-1)
        T = s - a * n
        return _floor_hit(y, T - y)

    return curve


def _cone_line_curve(center, radius, sphere_i, sphere_j, internal):
    """Lines tangent to both spheres inside a common tangent plane: the generators of the cone
    from the external (internal) centre of similitude, tangent to both, parametrised by the
    angle t around the cone (a cylinder for equal external radii). Where such a line passes
    through the lamp (|y - c| <= R), its floor point x is where the two shadow conics seen from
    x touch inside the lamp. Returns curve(t) -> (X, Y) and the lamp-distance margin(t)."""
    (si, ai), (sj, aj) = sphere_i, sphere_j
    c, R = center, radius
    cylinder = (not internal) and abs(ai - aj) <= 1e-12 * max(ai, aj)
    if cylinder:
        axis = (sj - si) / np.linalg.norm(sj - si)
    else:
        apex = (aj * si + ai * sj) / (ai + aj) if internal else (aj * si - ai * sj) / (aj - ai)
        axis = si - apex
        dist = np.linalg.norm(axis)
        axis = axis / dist
        sa = ai / dist
        ca = np.sqrt(max(1.0 - sa * sa, 0.0))
    ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = np.cross(axis, ref)
    p /= np.linalg.norm(p)
    q = np.cross(axis, p)

    def line(t):
        ring = np.cos(t)[..., None] * p + np.sin(t)[..., None] * q
        if cylinder:
            return si + ai * ring, np.broadcast_to(axis, ring.shape)
        return np.broadcast_to(apex, ring.shape), ca * axis + sa * ring

    def curve(t):
        origin, direction = line(t)
        with np.errstate(divide="ignore", invalid="ignore"):
            return _floor_hit(origin, direction)

    def margin(t):
        origin, direction = line(t)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (c[2] - origin[..., 2]) / direction[..., 2]
            y = origin + s[..., None] * direction
            out = R - np.hypot(y[..., 0] - c[0], y[..., 1] - c[1])
        return np.where(np.isfinite(out), out, -1.0)

    return curve, margin


def _rim_line_curve(center, radius, sphere_i, sphere_j, sign):
    """Lines from a rim point y(psi) tangent to both spheres (two, sign, where they exist): their
    floor points x are where the two shadow conics seen from x cross on the rim. Returns
    curve(psi) -> (X, Y) and the existence margin mu^2(psi)."""
    (si, ai), (sj, aj) = sphere_i, sphere_j
    c, R = center, radius

    def parts(psi):
        y = np.stack([c[0] + R * np.cos(psi), c[1] + R * np.sin(psi), np.full_like(psi, c[2])], -1)
        ui, uj = si - y, sj - y
        li, lj = np.linalg.norm(ui, axis=-1), np.linalg.norm(uj, axis=-1)
        ui, uj = ui / li[..., None], uj / lj[..., None]
        ci, cj = np.sqrt(1.0 - (ai / li) ** 2), np.sqrt(1.0 - (aj / lj) ** 2)
        g = np.einsum("...i,...i->...", ui, uj)
        l1 = (ci - g * cj) / (1.0 - g * g)
        l2 = (cj - g * ci) / (1.0 - g * g)
        mu2 = 1.0 - (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * g)
        n = np.cross(ui, uj)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return y, l1[..., None] * ui + l2[..., None] * uj, n, mu2

    def curve(psi):
        y, base, n, mu2 = parts(psi)
        v = base + sign * np.sqrt(np.maximum(mu2, 0.0))[..., None] * n
        return _floor_hit(y, v)

    def margin(psi):
        return parts(psi)[3]

    return curve, margin


class _Curve:
    """A parametric floor curve (X(t), Y(t)) on [lo, hi] (periodic or an arc), with its
    monotone pieces in X and in Y, for solving X(t) = level or Y(t) = level."""

    def __init__(self, func, lo, hi, periodic, samples=2048):
        self.func, self.lo, self.hi, self.periodic = func, lo, hi, periodic
        if periodic:
            t = lo + (hi - lo) * np.arange(samples) / samples
        else:
            t = np.linspace(lo, hi, samples)
        values = func(t)
        self.extrema, self.segments = [], []
        for k in range(2):
            ext_t = self._extrema(t, values[k], k)
            self.extrema.append(ext_t)
            if periodic:
                if len(ext_t) == 0:
                    seg = np.array([[lo, hi]])
                else:
                    seg = np.column_stack([ext_t, np.append(ext_t[1:], ext_t[0] + (hi - lo))])
            else:
                edges = np.concatenate([[lo], ext_t, [hi]])
                seg = np.column_stack([edges[:-1], edges[1:]])
            self.segments.append(seg)

    def _extrema(self, t, v, k):
        """Parameters of the local extrema of coordinate k: sign changes of the sampled
        differences, refined by golden-section search on the bracketing pair of samples."""
        if self.periodic:
            dv = np.roll(v, -1) - v
            turn = np.nonzero(np.sign(dv) != np.sign(np.roll(dv, 1)))[0]
            step = t[1] - t[0]
            left, right = t[turn] - step, t[turn] + step
        else:
            dv = np.diff(v)
            turn = np.nonzero(np.sign(dv[1:]) != np.sign(dv[:-1]))[0] + 1
            left, right = t[turn - 1], t[turn + 1]
        if len(turn) == 0:
            return np.zeros(0)
        sense = np.where(np.sign(dv[turn - 1]) > 0, -1.0, 1.0)  # minimise sense * v
        ratio = (np.sqrt(5.0) - 1.0) / 2.0
        a, b = left, right
        for _ in range(80):
            m1, m2 = b - ratio * (b - a), a + ratio * (b - a)
            f1, f2 = sense * self.func(m1)[k], sense * self.func(m2)[k]
            lower = f1 < f2
            b = np.where(lower, m2, b)
            a = np.where(lower, a, m1)
        ext = 0.5 * (a + b)
        if self.periodic:
            ext = self.lo + np.mod(ext - self.lo, self.hi - self.lo)
        return np.sort(ext)

    def extreme_points(self, k):
        """(X, Y) at the extrema of coordinate k (e.g. k = 0: where the curve is vertical)."""
        return self.func(self.extrema[k])

    def ends(self):
        """(X, Y) of the arc's two ends (none for a closed curve)."""
        if self.periodic:
            return np.zeros(0), np.zeros(0)
        return self.func(np.array([self.lo, self.hi]))

    def solve(self, k, levels):
        """All t with coordinate k equal to one of levels (L,): (level index, other coordinate)."""
        seg = self.segments[k]
        va, vb = self.func(seg[:, 0])[k], self.func(seg[:, 1])[k]
        low, high = np.minimum(va, vb), np.maximum(va, vb)
        idx, s = np.nonzero((levels[:, None] >= low[None]) & (levels[:, None] <= high[None]))
        if len(idx) == 0:
            return idx, np.zeros(0)
        level = levels[idx]
        a, b = seg[s, 0].copy(), seg[s, 1].copy()
        rising = vb[s] > va[s]
        for _ in range(64):
            m = 0.5 * (a + b)
            above = (self.func(m)[k] > level) == rising
            b = np.where(above, m, b)
            a = np.where(above, a, m)
        return idx, self.func(0.5 * (a + b))[1 - k]


def _arcs(margin, lo, hi, samples=4096):
    """The sub-intervals of [lo, hi) (periodic) where margin(t) >= 0, ends refined by
    bisection: a list of (a, b, closed) with closed True when margin >= 0 everywhere."""
    t = lo + (hi - lo) * np.arange(samples) / samples
    ok = margin(t) >= 0
    if ok.all():
        return [(lo, hi, True)]
    if not ok.any():
        return []
    change = np.nonzero(ok != np.roll(ok, -1))[0]  # between sample i and i + 1
    step = (hi - lo) / samples
    a, b = t[change], t[change] + step
    inside_first = ok[change]
    for _ in range(64):
        m = 0.5 * (a + b)
        same = (margin(m) >= 0) == inside_first
        a = np.where(same, m, a)
        b = np.where(same, b, m)
    cut = np.where(inside_first, a, b)  # stay on the valid side
    starts = cut[~inside_first]
    stops = cut[inside_first]
    out = []
    for s in starts:
        later = stops[stops > s]
        e = later.min() if len(later) else stops.min() + (hi - lo)
        out.append((s, e, False))
    return out


def _singular_curves(center, radius, spheres):
    """Floor curves across which F_vis(x) is not analytic: each sphere's umbra and penumbra
    boundary; for two spheres, where their shadow conics touch inside the lamp or cross on its
    rim."""
    curves = []
    for sphere in spheres:
        for sign in (1.0, -1.0):
            curves.append(_Curve(_penumbra_curve(center, radius, sphere, sign), 0.0, TWO_PI, True))
    for i in range(len(spheres)):
        for j in range(i + 1, len(spheres)):
            pairs = [
                _cone_line_curve(center, radius, spheres[i], spheres[j], internal)
                for internal in (False, True)
            ]
            pairs += [_rim_line_curve(center, radius, spheres[i], spheres[j], sign) for sign in (1.0, -1.0)]
            for curve, margin in pairs:
                for a, b, closed in _arcs(margin, 0.0, TWO_PI):
                    curves.append(_Curve(curve, a, b, closed))
    return curves


# ---------------------------------------------------------------------------- patch means
_N_Y = (10, 14)
_N_X = (10, 14)


def _assemble(owner, values, lo, hi):
    """Per-owner sorted breakpoints from loose (owner, value) pairs: bp (K, m) = [lo, the values
    strictly inside (lo, hi), hi, hi, ...], its valid counts, and the nearest values outside the
    range on either side (before <= lo, after >= hi; -inf / inf when none)."""
    K = len(lo)
    before = np.full(K, -np.inf)
    after = np.full(K, np.inf)
    below, above = values <= lo[owner], values >= hi[owner]
    np.maximum.at(before, owner[below], values[below])
    np.minimum.at(after, owner[above], values[above])
    inside = ~below & ~above
    owner, values = owner[inside], values[inside]
    order = np.lexsort((values, owner))
    owner, values = owner[order], values[order]
    count = np.bincount(owner, minlength=K)
    m = int(count.max()) if K and len(owner) else 0
    bp = np.repeat(hi[:, None], m + 2, axis=1)
    bp[:, 0] = lo
    start = np.cumsum(count) - count
    bp[owner, 1 + np.arange(len(owner)) - start[owner]] = values
    return bp, count + 2, before, after


class _Floor:
    """Patch means of F_vis over axis-aligned floor rectangles by iterated integration, X outer,
    Y inner, each split at the singular curves' crossings (see module docstring)."""

    def __init__(self, center, radius, spheres, rtol, atol):
        self.center = np.asarray(center, float)
        self.R = float(radius)
        self.spheres = [(np.asarray(s, float), float(a)) for s, a in spheres]
        self.curves = _singular_curves(self.center, self.R, self.spheres)
        self.rtol, self.atol = rtol, atol
        self.points = 0  # point factors evaluated (a cost statistic)

    def x_breakpoints(self, x0, x1, y0, y1):
        """Per patch: where G(X) = int F dY is not analytic (the curves' vertical tangents within
        [y0, y1], their crossings of y0 and y1, arc ends), for _pieces."""
        owners, values = [np.zeros(0, int)], [np.zeros(0)]
        for curve in self.curves:
            for X, Y in (curve.extreme_points(0), curve.ends()):
                hit = (Y[None, :] >= y0[:, None]) & (Y[None, :] <= y1[:, None])
                o, e = np.nonzero(hit)
                owners.append(o)
                values.append(X[e])
            for edge in (y0, y1):
                o, X = curve.solve(1, edge)
                owners.append(o)
                values.append(X)
        return _assemble(np.concatenate(owners), np.concatenate(values), x0, x1)

    def y_breakpoints(self, X, y0, y1):
        """Per line X: where it crosses the singular curves, for _pieces."""
        owners, values = [np.zeros(0, int)], [np.zeros(0)]
        for curve in self.curves:
            o, Y = curve.solve(0, X)
            owners.append(o)
            values.append(Y)
        return _assemble(np.concatenate(owners), np.concatenate(values), y0, y1)

    def f_values(self, X, Y):
        """F_vis and its error bar at floor points (X, Y) (same shapes)."""
        pts = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
        self.points += len(pts)
        F, e = _point_factors(pts, self.center, self.R, self.spheres, self.rtol_f, self.atol_f)
        return F.reshape(X.shape), e.reshape(X.shape)

    def g_values(self, X, y0, y1):
        """int_{y0}^{y1} F_vis(X, Y) dY and its error bar, for X, y0, y1 of the same shape."""
        shape = X.shape
        X, y0, y1 = X.ravel(), y0.ravel(), y1.ravel()
        bp, count, before, after = self.y_breakpoints(X, y0, y1)
        owner, rows = _pieces(bp, before, after, count)
        span = y1 - y0

        def func(own, Y):
            return self.f_values(np.broadcast_to(X[own][:, None], Y.shape), Y)

        def tolerance(first):
            return np.maximum(self.rtol_g * np.abs(first), self.atol_g * span)

        G, e = _adaptive(owner, rows, func, tolerance, len(X), *_N_Y)
        return G.reshape(shape), e.reshape(shape)

    def means(self, x0, x1, y0, y1):
        """(mean, error) per patch. Tolerance max(rtol |mean|, atol): half for the X level, a
        fifth for the Y level (relative to each G(X) >= 0), 1e-2 for the point factors."""
        x0, x1, y0, y1 = (np.atleast_1d(np.asarray(v, float)) for v in (x0, x1, y0, y1))
        area = (x1 - x0) * (y1 - y0)
        self.rtol_f = min(1e-12, 1e-2 * self.rtol)
        self.atol_f = 1e-2 * self.atol
        self.rtol_g, self.atol_g = 0.2 * self.rtol, 0.2 * self.atol
        bp, count, before, after = self.x_breakpoints(x0, x1, y0, y1)
        owner, rows = _pieces(bp, before, after, count)

        def func(own, X):
            return self.g_values(
                X, np.broadcast_to(y0[own][:, None], X.shape), np.broadcast_to(y1[own][:, None], X.shape)
            )

        def tolerance(first):
            return np.maximum(0.5 * self.rtol * np.abs(first), 0.5 * self.atol * area)

        value, error = _adaptive(owner, rows, func, tolerance, len(x0), *_N_X)
        error += 1e-14 * np.abs(value)  # rounding of the sums over ~1e5 terms
        return value / area, error / area


def floor_patch_factor_exact(x0, x1, y0, y1, lamp_center, lamp_radius, spheres, rtol=1e-9, atol=1e-13):
    """Area mean of F_vis over the floor rectangle [x0, x1] x [y0, y1]: the quantity of
    occluded_mc.disk_pair_factor(source, lamp_center, lamp_radius, spheres)[0] for the
    parallelogram source ((x0, y0, 0), (x1 - x0, 0, 0), (0, y1 - y0, 0)). Returns (mean, error
    estimate); the estimate is kept within max(rtol mean, atol). Arrays of patches (equal
    shapes) give arrays, computed together."""
    floor = _Floor(lamp_center, lamp_radius, spheres, rtol, atol)
    mean, err = floor.means(x0, x1, y0, y1)
    if np.ndim(x0) == 0:
        return float(mean[0]), float(err[0])
    return mean, err


def floor_reference_exact(half, m, lamp_center, lamp_radius, spheres, rho, E, rtol=1e-9):
    """rho E x (patch mean of F_vis) for the m x m patches of the floor [-half, half]^2, patch
    i * m + j spanning [e_i, e_(i+1)] in x and [e_j, e_(j+1)] in y (the layout of
    benchmarks/shadow_patches.floor_reference): (values, error estimates), shape (m * m,)."""
    edges = np.linspace(-half, half, m + 1)
    i, j = np.divmod(np.arange(m * m), m)
    mean, err = floor_patch_factor_exact(
        edges[i], edges[i + 1], edges[j], edges[j + 1], lamp_center, lamp_radius, spheres, rtol
    )
    return rho * E * mean, rho * E * err
