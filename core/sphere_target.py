"""A whole sphere or a sphere patch as an exact shadow target: the flat disk spanning its silhouette.

Seen from a point x outside a sphere (centre c, radius r, d = |x - c|), the tangent cone from x
touches the sphere along a circle in the plane at r^2 / d from c toward x, of radius
r sqrt(1 - r^2 / d^2). A segment from x to a point y of the disk that circle bounds first crosses
the cap x sees, then runs inside the sphere. So an occluder that does not reach inside the sphere
blocks the segment x y exactly when it blocks the segment from x to the cap point on it, and

    F_vis(x -> the sphere's outside) = F_vis(x -> silhouette disk)

(a point factor depends only on the set of directions it covers: F = (1/pi) int cos(theta_x)
d omega). The disk is an annular sector of the shadow kernel (`shadow.SectorTargets`), so the
sphere's shadows past spheres, polygons, disks and cylinders are exact wherever those are.

A patch of the sphere (`SpherePatchTargets`) is the part of that disk whose directions first
meet the sphere inside the patch: the disk's chord along each line of the shadow kernel is cut
where the line crosses the cones from x over the patch's boundary circles (two of latitude, the
two great circles through its meridians; quadratics, as the disk occluders' cones in `shadow`),
and each piece is kept or dropped by where its midpoint's direction meets the sphere, so a
superset of ends is harmless. The same segments, so the same occluders, decide what is seen.

Occluders that reach inside the sphere (a floor it sinks into) break the argument: the segment
to the disk may meet them inside the sphere. Lower bounds of the distance from a point to each
occluder kind (below; `occluded.SHAPES` names them per kind) find those, conservatively.
"""

import numpy as np

from .kinds import SPHERE
from .shadow import SectorTargets, circle_crossings, conic_edge_crossings, conic_tangents, quadratic_roots

INSIDE = 1e-9  # an occluder reaches inside a sphere when nearer its centre than (1 - INSIDE) r
WINDOW_GRID = 9  # points per parameter that bound a patch's ball (`SpherePatchTargets.eta_range`)


def round_sphere(surface):
    """(center (3,), radius) of a whole round sphere whose front is its outside, else None."""
    geometry = surface.geometry
    if not geometry.whole_ellipsoid(surface.domain):
        return None
    sizes = np.linalg.svd(geometry.linear, compute_uv=False)
    if sizes.max() - sizes.min() > 1e-12 * sizes.max():
        return None
    center = np.asarray(geometry.offset, dtype=np.float64)
    if not _outward(surface, center):
        return None  # its inside
    return center, float(sizes.max())


def _outward(surface, center):
    """Whether the front of a patch of the sphere around `center` is its outside."""
    (u0, u1), (v0, v1) = surface.domain
    grid = np.linspace(0.25, 0.75, 3)
    points, normals = surface.evaluate(u0 + (u1 - u0) * grid[:, None], v0 + (v1 - v0) * grid[None, :])
    return np.einsum("abi,abi->", points - center, normals) > 0.0


def sphere_patch(surface):
    """(center (3,), radius, local (3, 3), box (4,)) of a round sphere patch that is not the whole
    sphere and whose front is its outside, else None: `local` maps offsets from the centre to
    `SphereGeometry`'s canonical sphere, box = (u0, u1, v0, v1) its angles there."""
    geometry = surface.geometry
    if geometry.exact_kind(surface.domain) != SPHERE or geometry.whole_ellipsoid(surface.domain):
        return None
    center = np.asarray(geometry.offset, dtype=np.float64)
    if not _outward(surface, center):
        return None  # its inside
    local = np.linalg.inv(geometry.linear)
    (u0, u1), (v0, v1) = surface.domain
    return center, float(geometry.similarity_scale), local, np.array([u0, u1, v0, v1], dtype=np.float64)


def _silhouette(x, center, radius):
    """Centre and unit normal (facing x) of the silhouette disks' planes, each (K, 3), and the
    disks' radii (K,) (0 for points on or inside their sphere)."""
    x = np.asarray(x, dtype=np.float64)
    center = np.asarray(center, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    K = len(x)
    to_x = x - center
    distance = np.linalg.norm(to_x, axis=1)
    normal = np.divide(
        to_x, distance[:, None], out=np.tile([0.0, 0.0, 1.0], (K, 1)), where=distance[:, None] > 0
    )
    ratio = np.divide(radius, distance, out=np.ones(K), where=distance > radius)
    rim = radius * np.sqrt(np.maximum(1.0 - ratio**2, 0.0))
    return center + (radius * ratio)[:, None] * normal, normal, rim


def silhouette_disks(x, center, radius):
    """The disk spanning the silhouette of a sphere seen from each point, as `SectorTargets`.

    Parameters
    ----------
    x, center : ndarray, shape (K, 3)
    radius : ndarray, shape (K,)

    Returns
    -------
    SectorTargets
        Whole disks facing x. A point on or inside its sphere gets a disk of radius 0: it sees
        none of the outside.
    """
    disk_center, normal, rim = _silhouette(x, center, radius)
    K = len(rim)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    radii = np.stack([np.zeros(K), rim], 1)
    angles = np.broadcast_to([0.0, 2.0 * np.pi], (K, 2))
    return SectorTargets(disk_center, normal, e1, radii, angles)


class SpherePatchTargets(SectorTargets):
    """Round sphere patches seen from outside, one per query, on their silhouette disks.

    Parameters
    ----------
    x : ndarray, shape (K, 3)
        The query points.
    center : ndarray, shape (K, 3)
    radius : ndarray, shape (K,)
    local : ndarray, shape (K, 3, 3)
        World offsets from the centre to the canonical sphere (`sphere_patch`).
    box : ndarray, shape (K, 4)
        (u0, u1, v0, v1) of each patch.
    """

    def __init__(self, x, center, radius, local, box):
        vars(self).update(vars(silhouette_disks(x, center, radius)))
        self.x, self.center, self.local, self.box = x, center, local, box
        self.radius2 = radius * radius
        # the map back, s Q for local = Q^T / s (a round sphere: Q orthogonal): s^2 local^T
        linear = self.radius2[:, None, None] * np.swapaxes(local, 1, 2)
        (u0, u1), (v0, v1) = box[:, :2].T, box[:, 2:].T
        ez, zero = np.array([0.0, 0.0, 1.0]), np.zeros(len(x))
        # boundary circles in the canonical sphere: latitudes u0, u1 (centre (0, 0, cos u), radius
        # sin u, basis ex, ey) and the great circles of the meridians v0, v1 (centre 0, basis ez and
        # (cos v, sin v, 0)); a whole turn in v has no meridian edges (radius 0: no ends)
        meridian = (v1 - v0 < 2.0 * np.pi - 1e-12).astype(float)
        centers, radii, first, second = [], [], [], []
        for u in (u0, u1):
            centers.append(np.cos(u)[:, None] * ez)
            radii.append(np.sin(u))
            first.append(np.broadcast_to([1.0, 0.0, 0.0], (len(x), 3)))
            second.append(np.broadcast_to([0.0, 1.0, 0.0], (len(x), 3)))
        for v in (v0, v1):
            centers.append(np.zeros((len(x), 3)))
            radii.append(meridian)
            first.append(np.broadcast_to(ez, (len(x), 3)))
            second.append(np.stack([np.cos(v), np.sin(v), zero], 1))
        scale = np.sqrt(self.radius2)[:, None]
        self.circle_center = center[:, None] + _mapped(linear, centers)
        self.circle_radius = scale * np.stack(radii, 1)
        self.circle_a = _mapped(linear, first) / scale[..., None]
        self.circle_b = _mapped(linear, second) / scale[..., None]
        self.circle_normal = np.cross(self.circle_a, self.circle_b)
        # the conics the cones from x over the circles leave on the disk's plane (`_cone_conics`),
        # and where I(eta) may kink: where the circles cross the silhouette (the disk's plane) and,
        # seen from x, the patch's corners and poles
        self.conic, self.plane = _cone_conics(self)
        self.rim_eta = circle_crossings(
            self, self.circle_center, self.circle_a, self.circle_b, self.circle_radius
        ).reshape(len(x), -1)
        corner_u = np.stack([u0, u0, u1, u1, zero, zero + np.pi], 1)
        corner_v = np.stack([v0, v1, v0, v1, v0, v0], 1)
        corners = center[:, None] + _mapped(linear, _canonical(corner_u, corner_v))
        # (only corners x sees can be kinks, and a pole only where the patch reaches it)
        seen = _dot(corners - center[:, None], (x - center)[:, None]) > self.radius2[:, None]
        seen[:, 4] &= u0 <= 0.0
        seen[:, 5] &= u1 >= np.pi
        self.kinks = np.where(seen[..., None], corners, np.nan)
        # the patch's bounding ball (its points on a WINDOW_GRID grid, widened by the radius times a
        # grid step: no point of the patch is farther from a node) seen from x: lines eta = const
        # outside that cone miss the patch (`eta_range`)
        s = np.linspace(0.0, 1.0, WINDOW_GRID)
        grid_u = u0[:, None, None] + (u1 - u0)[:, None, None] * s[None, :, None]
        grid_v = v0[:, None, None] + (v1 - v0)[:, None, None] * s[None, None, :]
        grid = center[:, None] + _mapped(linear, _canonical(grid_u, grid_v).reshape(len(x), -1, 3))
        middle = grid.mean(1)
        step = np.maximum(u1 - u0, v1 - v0) / (WINDOW_GRID - 1)
        reach = np.linalg.norm(grid - middle[:, None], axis=-1).max(1) + radius * step
        self.window = self._cone_window(middle, reach)

    def eta_range(self):
        lo, hi = super().eta_range()
        return np.maximum(lo, self.window[:, 0]), np.minimum(hi, self.window[:, 1])

    def _cone_window(self, center, reach):
        """(lo, hi) of eta, shape (K, 2), of the lines that cross the cone from x around the ball
        (center (K, 3), radius reach (K,)) on the disk's plane; (-inf, inf) where that cone is not
        wholly in front of the plane (its trace is then no ellipse) or x is in the ball."""
        axis = center - self.x
        distance = np.linalg.norm(axis, axis=1)
        sin = np.divide(reach, distance, out=np.full(len(reach), np.inf), where=distance > 0)
        axis = axis / np.maximum(distance, 1e-300)[:, None]
        # y = x + w on the cone: (w . a)^2 = cos^2 |w|^2, w = W + xi e1 + eta e2 (W = o - x)
        c2 = 1.0 - np.minimum(sin, 1.0) ** 2
        W = self.origin - self.x
        aW, a1, a2 = _dot(axis, W), _dot(axis, self.e1), _dot(axis, self.e2)
        conic = (
            a1 * a1 - c2,
            2.0 * (aW * a1 - c2 * _dot(W, self.e1)),
            2.0 * a1 * a2,
            aW * aW - c2 * _dot(W, W),
            2.0 * (aW * a2 - c2 * _dot(W, self.e2)),
            a2 * a2 - c2,
        )
        ends = np.sort(conic_tangents(conic), 1)
        bounded = (-_dot(axis, self.normal) > sin) & np.all(np.isfinite(ends), axis=1)
        return np.where(bounded[:, None], ends, [[-np.inf, np.inf]])

    def seen_round(self, x):
        return np.zeros(len(x), dtype=bool)

    def chord(self, k, eta):
        """The silhouette disk's chord, with the boundary cones' and planes' crossings as further
        ends and the patch's inside test (where the direction first meets the sphere)."""
        lo, hi, ends, in_disk = super().chord(k, eta)
        A, B0, B1, C0, C1, C2 = np.moveaxis(self.conic[k], -1, 0)  # (L, 4) each
        eta_ = eta[:, None]
        roots = quadratic_roots(A, B0 + B1 * eta_, C0 + (C1 + C2 * eta_) * eta_)  # (L, 4, 2)
        m0, m1, m2 = np.moveaxis(self.plane[k], -1, 0)
        flat = np.divide(-(m0 + m2 * eta_), m1, out=np.full(m1.shape, np.nan), where=m1 != 0)
        ends = np.concatenate([ends, roots.reshape(len(k), -1), flat], 1)
        x, local, box = self.x[k], self.local[k], self.box[k]
        rel = x - self.center[k]
        g = self.origin[k] + eta_ * self.e2[k] - x  # w = g + xi e1: from x to the line's point
        e1_ = self.e1[k]
        cc = _dot(rel, rel) - self.radius2[k]
        # the canonical sphere's p = (sin u cos v, sin u sin v, cos u) (`SphereGeometry`): u in
        # [u0, u1] is cos u1 <= p_z <= cos u0 (open at a pole, where rounding may pass 1)
        z_hi = np.where(box[:, 0] > 0.0, np.cos(box[:, 0]), np.inf)
        z_lo = np.where(box[:, 1] < np.pi, np.cos(box[:, 1]), -np.inf)
        v0, span = box[:, 2], box[:, 3] - box[:, 2]

        def inside(mid):
            out = in_disk(mid) & (mid > lo[:, None]) & (mid < hi[:, None])
            i, j = np.nonzero(out)
            w = g[i] + mid[i, j, None] * e1_[i]  # (P, 3)
            b, ww = _dot(w, rel[i]), _dot(w, w)
            t = np.divide(
                -b - np.sqrt(np.maximum(b * b - ww * cc[i], 0.0)), ww, out=np.zeros_like(ww), where=ww > 0
            )
            p = np.einsum("pij,pj->pi", local[i], rel[i] + t[:, None] * w)  # the first hit, canonical
            azimuth = np.mod(np.arctan2(p[:, 1], p[:, 0]) - v0[i], 2.0 * np.pi)
            seen = (
                (p[:, 2] <= z_hi[i])
                & (p[:, 2] >= z_lo[i])
                & ((azimuth <= span[i]) | (span[i] >= 2.0 * np.pi))
            )
            out[i, j] = seen
            return out

        return lo, hi, ends, inside

    def eta_breaks(self, line):
        """The disk's breaks, the tangencies of the lines eta = const with the boundary conics,
        the conics' crossings with a line alpha xi + beta eta + gamma = 0 (each (K,)), the
        circles' rim crossings and the corners seen from x."""
        K = len(self.x)
        conic = tuple(np.moveaxis(self.conic, -1, 0))  # (K, 4) each
        # the line as p + s q, (xi, eta) = p + s (-beta, alpha)
        alpha, beta, gamma = line
        norm2 = np.maximum(alpha * alpha + beta * beta, 1e-300)
        p = np.stack([-gamma * alpha / norm2, -gamma * beta / norm2], -1)[:, None]
        q = np.stack([-beta, alpha], -1)[:, None]
        crossing = conic_edge_crossings(conic, p, q, bounded=False)
        # the corners seen from x on the disk's plane
        to = self.kinks - self.x[:, None]
        h = _dot(self.x - self.origin, self.normal)[:, None]
        depth = -_dot(to, self.normal[:, None])
        s = np.divide(h, depth, out=np.full(depth.shape, np.nan), where=depth > 0)
        seen = self.x[:, None] + s[..., None] * to - self.origin[:, None]
        return np.concatenate(
            [
                super().eta_breaks(line),
                conic_tangents(conic).reshape(K, -1),
                crossing.reshape(K, -1),
                self.rim_eta,
                _dot(seen, self.e2[:, None]),
            ],
            1,
        )


def _cone_conics(t):
    """The cones from each query's point x over the patch's boundary circles on the disk's plane,
    A xi^2 + (B0 + B1 eta) xi + C0 + C1 eta + C2 eta^2 = 0 (`shadow`'s traces), coefficients
    (K, 4, 6), and the circles' planes there, m0 + m1 xi + m2 eta, (K, 4, 3) (for a point x in a
    circle's plane the cone is that plane).

    A point y = x + w of the plane is on the cone over the circle (centre q, unit normal m,
    radius r) when the line x y meets the circle: with a = x - q and hm = m.(q - x), where it
    meets the circle's plane is q + ((m.w) a + hm w) / (m.w), so |(m.w) a + hm w|^2 = r^2 (m.w)^2,
    quadratic in w = W + xi e1 + eta e2 (W = o - x)."""
    x, q, m, r2 = t.x[:, None], t.circle_center, t.circle_normal, t.circle_radius**2
    a = x - q
    hm = -_dot(m, a)
    W, e1, e2 = (v[:, None] for v in (t.origin - t.x, t.e1, t.e2))
    mW, m1, m2 = (_dot(m, v) for v in (W, e1, e2))
    VW, V1, V2 = (mv[..., None] * a + hm[..., None] * v for mv, v in ((mW, W), (m1, e1), (m2, e2)))
    conic = [
        _dot(V1, V1) - r2 * m1 * m1,
        2.0 * (_dot(VW, V1) - r2 * mW * m1),
        2.0 * (_dot(V1, V2) - r2 * m1 * m2),
        _dot(VW, VW) - r2 * mW * mW,
        2.0 * (_dot(VW, V2) - r2 * mW * m2),
        _dot(V2, V2) - r2 * m2 * m2,
    ]
    return np.stack(conic, -1), np.stack([mW, m1, m2], -1)


def _canonical(u, v):
    """`SphereGeometry`'s canonical points p = (sin u cos v, sin u sin v, cos u), shape S + (3,)
    for u, v broadcasting to shape S."""
    u, v = np.broadcast_arrays(u, v)
    return np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], -1)


def _mapped(linear, points):
    """Canonical points (a list of (K, 3) or an array (K, C, 3)) mapped by each query's linear
    map (K, 3, 3), shape (K, C, 3)."""
    return np.einsum("kij,kcj->kci", linear, np.stack(points, 1) if isinstance(points, list) else points)


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def silhouette_planes(x, center, radius):
    """(point, unit normal) of the silhouette disks' planes, each shape (K, 3): segments from x to
    the disk lie on x's side of it (as `silhouette_disks`)."""
    disk_center, normal, _ = _silhouette(x, center, radius)
    return disk_center, normal


# ---------------------------------------------------------------------------- distances
def polygon_distance(p, corners):
    """Distance from points p (C, 3) to flat convex quads or triangles `corners` (C, 4, 3)
    (a triangle repeats a corner), shape (C,)."""
    normal = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    edge = np.roll(corners, -1, axis=1) - corners  # (C, 4, 3)
    to_p = p[:, None] - corners
    side = np.einsum("cei,ci->ce", np.cross(edge, to_p), normal)
    height = np.abs(np.einsum("ci,ci->c", p - corners[:, 0], normal))
    t = np.clip(
        np.einsum("cei,cei->ce", to_p, edge) / np.maximum(np.einsum("cei,cei->ce", edge, edge), 1e-300), 0, 1
    )
    to_edge = np.linalg.norm(to_p - t[..., None] * edge, axis=-1).min(1)
    return np.where(np.all(side >= 0.0, 1), height, to_edge)


def disk_distance(p, center, normal, radius):
    """Distance from points p (C, 3) to whole disks (center, unit normal (C, 3), radius (C,)):
    a disk patch's distance is at least this."""
    d = p - center
    height = np.einsum("ci,ci->c", d, normal)
    radial = np.linalg.norm(d - height[:, None] * normal, axis=1)
    return np.hypot(height, np.maximum(radial - radius, 0.0))


def band_distance(p, center, axis, radius, heights):
    """Distance from points p (C, 3) to whole cylinder bands (base centre, unit axis (C, 3),
    radius (C,), axial span (C, 2)): a cylinder patch's distance is at least this."""
    d = p - center
    s = np.einsum("ci,ci->c", d, axis)
    radial = np.linalg.norm(d - s[:, None] * axis, axis=1)
    beyond = s - np.clip(s, heights[:, 0], heights[:, 1])
    return np.hypot(beyond, radial - radius)


def ellipsoid_distance(p, linear, offset):
    """Distance from points p (C, 3) to whole ellipsoids {offset + L t : |t| = 1} (linear L
    (C, 3, 3), offset (C, 3)), shape (C,); 0 for points inside.

    With L = U S V^T and y = U^T (p - offset), the nearest point is s_i^2 y_i / (t + s_i^2) for the
    root t >= 0 of sum_i (s_i y_i / (t + s_i^2))^2 = 1, which decreases in t (Eberly, "Distance from
    a point to an ellipse, an ellipsoid, or a hyperellipsoid", Geometric Tools, 2013); bisection.
    """
    U, s, _ = np.linalg.svd(linear)
    y = np.einsum("cji,cj->ci", U, p - offset)
    inside = np.einsum("ci,ci->c", y / s, y / s) <= 1.0
    s2 = s**2
    lo = np.zeros(len(p))
    hi = np.maximum(np.linalg.norm(y, axis=1) * s.max(1), 1e-300)  # f(hi) <= 0
    for _ in range(80):
        t = 0.5 * (lo + hi)
        f = np.einsum("ci,ci->c", s * y / (t[:, None] + s2), s * y / (t[:, None] + s2)) - 1.0
        lo, hi = np.where(f > 0, t, lo), np.where(f > 0, hi, t)
    nearest = s2 * y / (0.5 * (lo + hi)[:, None] + s2)
    return np.where(inside, 0.0, np.linalg.norm(y - nearest, axis=1))
