"""F_vis(floor patch -> a square lamp above it) past spheres, by iterated integration with an
exact line-sphere test and a closed-form innermost integral; no code shared with core/.

Geometry: the floor z = 0 (front +z), a square lamp [lx - w, lx + w] x [ly - w, ly + w] in the
plane z = H facing down, a sphere (centre c, radius r) between the two planes (r < c_z, c_z + r < H).
For a floor point x and a lamp point q = (t, s, H), both cosines are H / |q - x|, so

    F_vis(x) = (H^2 / pi) int_s int_{t visible} dt / |q - x|^4.

- Innermost, t at fixed s: with u = t - x_1 and a^2 = H^2 + (s - x_2)^2,
  int du / (a^2 + u^2)^2 = u / (2 a^2 (a^2 + u^2)) + atan(u / a) / (2 a^3) (elementary; e.g.
  Gradshteyn & Ryzhik 2.172-2.173), over the lamp's t range minus the chords the spheres block
  (several spheres: the union of their chords, sorted by start, each taking off what lies beyond
  the ends of those before it).
  The segment x -> q meets the sphere iff (w . d)^2 > (|w|^2 - r^2) |d|^2 with w = c - x,
  d = q - x (the line's distance to c below r; the sphere lies between the planes, so the hit is
  on the segment, and with c_z > r only the forward nappe of the cone reaches z = H): a quadratic
  in u whose roots are the chord's ends.
- Middle, s: the integrand is analytic between the s where the chord's ends cross the lamp's
  edges t = lx +- w and where the chord closes (the cone's tangent lines): each is a root of a
  quadratic in s. The lamp's s range is cut there, and each piece is integrated by Gauss-Legendre
  in theta with s = a + (b - a)(1 - cos(pi theta)) / 2 (which absorbs the square-root ends where
  the chord closes). Where two spheres' chords overlap on a row, the union's end switches from
  one chord to the other at an s that is not a break point: there the Gauss rule converges only
  algebraically, so `point_factors` gives the difference of two orders as an error bar.
- Outer, x over the patch: composite Gauss-Legendre on cells x cells cells of order x order points.
  F_vis(x) is only C^1 across penumbra curves, so this converges algebraically: `patch_mean`
  doubles the cells per side until two rules agree to rtol, and returns the finer one's value
  with their difference as its error bar.
"""

import numpy as np


def _closed_form(u, a):
    """int_0^u du' / (a^2 + u'^2)^2, elementwise."""
    return u / (2.0 * a * a * (a * a + u * u)) + np.arctan(u / a) / (2.0 * a**3)


def _quadratic_roots(A, B, C):
    """Real roots of A z^2 + B z + C (A != 0), shape (..., 2); NaN where there are none."""
    disc = B * B - 4.0 * A * C
    root = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
    q = -0.5 * (B + np.copysign(root, B))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([q / A, np.where(q != 0.0, C / q, -B / (2.0 * A))], -1)


def _chord_coefficients(x, c, r, H, v):
    """Coefficients (A, B, C) of f(u) = A u^2 + B u + C, f > 0 where the segment from x to
    (x_1 + u, x_2 + v, H) meets the sphere; x (X, 3), v (X, K)."""
    w = c[None] - x
    kappa = (w * w).sum(1) - r * r
    beta = w[:, 1, None] * v + w[:, 2, None] * H
    A = (w[:, 0] ** 2 - kappa)[:, None] + 0.0 * v
    B = 2.0 * w[:, 0, None] * beta
    C = beta * beta - kappa[:, None] * (v * v + H * H)
    return A, B, C


def _spheres(sphere):
    """A list of (c (3,), r) from one sphere (c, r) or a sequence of them."""
    if len(sphere) == 2 and np.isscalar(sphere[1]):
        sphere = [sphere]
    return [(np.asarray(c, float), float(r)) for c, r in sphere]


def _s_breaks(x, c, r, H, T0, T1):
    """The s where one sphere's chord closes or an end crosses the lamp's edges, shape (X, 6)."""
    wv = c[None] - x
    kappa = (wv * wv).sum(1) - r * r
    # the chord closes (disc of f in u is 0):
    # disc(v) = B^2 - 4 A C with B = 2 w1 beta, A = w1^2 - kappa, C = beta^2 - kappa (v^2 + H^2)
    # = 4 [w1^2 beta^2 - (w1^2 - kappa)(beta^2 - kappa (v^2 + H^2))]
    # = 4 kappa [beta^2 + (w1^2 - kappa)(v^2 + H^2)], beta = w2 v + w3 H: a quadratic in v
    w1, w2, w3 = wv[:, 0], wv[:, 1], wv[:, 2]
    k1 = w1 * w1 - kappa
    closes = _quadratic_roots(w2 * w2 + k1, 2.0 * w2 * w3 * H, (w3 * w3 + k1) * H * H)
    # ... and a chord end crosses an edge t = T: f(T - x_1) = 0 as a quadratic in v:
    # (w1 u + w2 v + w3 H)^2 - kappa (u^2 + v^2 + H^2) = 0
    crossings = []
    for T in (T0, T1):
        u = T - x[:, 0]
        g = w1 * u + w3 * H
        crossings.append(_quadratic_roots(w2 * w2 - kappa, 2.0 * w2 * g, g * g - kappa * (u * u + H * H)))
    return np.concatenate([closes, *crossings], 1) + x[:, 1, None]


def _point_factors(x, lamp, spheres, order):
    lx, ly, w, H = lamp
    X = len(x)
    T0, T1, S0, S1 = lx - w, lx + w, ly - w, ly + w
    v_breaks = np.concatenate(
        [np.full((X, 0), np.nan)] + [_s_breaks(x, c, r, H, T0, T1) for c, r in spheres], 1
    )
    s_breaks = np.where(np.isfinite(v_breaks), np.clip(v_breaks, S0, S1), S0)
    edges = np.sort(np.concatenate([np.full((X, 1), S0), s_breaks, np.full((X, 1), S1)], 1), 1)
    # Gauss-Legendre in theta on [0, 1], s = a + (b - a)(1 - cos(pi theta)) / 2
    g, gw = np.polynomial.legendre.leggauss(order)
    theta, wt = 0.5 * (g + 1.0), 0.5 * gw
    a_, b_ = edges[:, :-1, None], edges[:, 1:, None]
    s = a_ + (b_ - a_) * 0.5 * (1.0 - np.cos(np.pi * theta))
    ds = (b_ - a_) * 0.5 * np.pi * np.sin(np.pi * theta) * wt
    s, ds = s.reshape(X, -1), ds.reshape(X, -1)
    v = s - x[:, 1, None]
    a = np.sqrt(H * H + v * v)
    u0, u1 = T0 - x[:, 0, None], T1 - x[:, 0, None]
    whole = _closed_form(u1, a) - _closed_form(u0, a)
    if not spheres:
        return H * H / np.pi * (whole * ds).sum(1)
    # each sphere's chord on the row, clipped to the lamp (empty: both ends at u0)
    los, his = [], []
    for c, r in spheres:
        A, B, C = _chord_coefficients(x, c, r, H, v)
        ends = np.sort(_quadratic_roots(A, B, C), -1)
        hit = np.isfinite(ends[..., 0])
        los.append(np.where(hit, np.clip(np.nan_to_num(ends[..., 0]), u0, u1), u0))
        his.append(np.where(hit, np.clip(np.nan_to_num(ends[..., 1]), u0, u1), u0))
    lo, hi = np.stack(los, -1), np.stack(his, -1)
    # the union of the chords: sorted by start, each takes off what lies beyond the ends before it
    order_ = np.argsort(lo, -1)
    lo, hi = np.take_along_axis(lo, order_, -1), np.take_along_axis(hi, order_, -1)
    first = np.broadcast_to(u0[..., None], lo[..., :1].shape)
    reached = np.maximum.accumulate(np.concatenate([first, hi[..., :-1]], -1), -1)
    start, stop = np.maximum(lo, reached), np.maximum(hi, reached)
    blocked = (_closed_form(stop, a[..., None]) - _closed_form(start, a[..., None])).sum(-1)
    return H * H / np.pi * ((whole - blocked) * ds).sum(1)


def point_factors(x, lamp, sphere, order=48, error=False):
    """F_vis(x -> lamp) past spheres for floor points x (X, 3) with z = 0, shape (X,).
    lamp = (lx, ly, w, H), sphere = (c (3,), r) or a sequence of them. With error=True, also the
    difference from the rule of twice the order (X,) (overlapping chords: see the module)."""
    lx, ly, w, H = lamp
    spheres = _spheres(sphere)
    for c, r in spheres:
        if not (r < c[2] and c[2] + r < H):
            raise ValueError("the spheres must lie between the floor and the lamp's plane")
    x = np.asarray(x, float)
    F = _point_factors(x, lamp, spheres, order)
    if not error:
        return F
    return F, np.abs(_point_factors(x, lamp, spheres, 2 * order) - F)


def _patch_rule(x0, x1, y0, y1, cells, order):
    g, gw = np.polynomial.legendre.leggauss(order)
    t, wt = 0.5 * (g + 1.0), 0.5 * gw
    ex, ey = np.linspace(x0, x1, cells + 1), np.linspace(y0, y1, cells + 1)
    px = (ex[:-1, None] + np.diff(ex)[:, None] * t[None]).ravel()
    py = (ey[:-1, None] + np.diff(ey)[:, None] * t[None]).ravel()
    wx = (np.diff(ex)[:, None] * wt[None]).ravel()
    wy = (np.diff(ey)[:, None] * wt[None]).ravel()
    X, Y = np.meshgrid(px, py, indexing="ij")
    points = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    return points, np.outer(wx, wy).ravel() / ((x1 - x0) * (y1 - y0))


def _shadowing(x0, x1, y0, y1, lamp, spheres):
    """The spheres whose shadow may reach the patch: the shadow of a sphere's bounding box lies
    in the box of its corners' central projections from the lamp's corners onto z = 0 (affine in
    the lamp point, projective with the box wholly below the lamp: extremes at the corners)."""
    lx, ly, w, H = lamp
    q = np.array([(lx + i * w, ly + j * w, H) for i in (-1, 1) for j in (-1, 1)])
    kept = []
    for c, r in spheres:
        p = c + r * np.array([(i, j, k) for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        scale = H / (H - p[None, :, 2])
        image = q[:, None, :2] + (p[None, :, :2] - q[:, None, :2]) * scale[..., None]
        lo, hi = image.reshape(-1, 2).min(0), image.reshape(-1, 2).max(0)
        if lo[0] <= x1 and hi[0] >= x0 and lo[1] <= y1 and hi[1] >= y0:
            kept.append((c, r))
    return kept


def patch_mean(x0, x1, y0, y1, lamp, sphere, rtol=1e-6, order=6, max_cells=64, chunk=4096, s_order=48):
    """Mean of F_vis over the floor patch [x0, x1] x [y0, y1]: (value, error bar). Cells per side
    double from 2 until two rules differ by at most rtol of the value (or max_cells); the value is
    the finer rule's and the bar their difference (with several spheres, plus the final rule's
    mean `point_factors` error bar)."""
    sphere = _shadowing(x0, x1, y0, y1, lamp, _spheres(sphere))
    several = len(sphere) > 1
    chunk = chunk if not several else max(1, chunk // (4 * len(sphere)))
    previous, cells = None, 2
    while True:
        points, weights = _patch_rule(x0, x1, y0, y1, cells, order)
        value = 0.0
        for k in range(0, len(points), chunk):
            value += (
                weights[k : k + chunk] * point_factors(points[k : k + chunk], lamp, sphere, s_order)
            ).sum()
        if previous is not None:
            bar = abs(value - previous)
            if bar <= rtol * abs(value) or cells >= max_cells:
                break
        previous, cells = value, 2 * cells
    if several:
        for k in range(0, len(points), chunk):
            _, error = point_factors(points[k : k + chunk], lamp, sphere, s_order, error=True)
            bar += (weights[k : k + chunk] * error).sum()
    return value, bar
