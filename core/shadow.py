"""Occluded point-to-patch factors on flat targets: F(dA(x) -> the part of a flat patch that x sees).

A flat target T lies in a plane with an orthonormal frame (o, e1, e2, n_T); its points are
y = o + xi e1 + eta e2. For a point x in front of it (height h = (x - o) . n_T > 0) with unit
normal n, the point-to-patch factor of the visible part is

    F = integral over (T and H) minus S of  h n.(y - x) / (pi |y - x|^4)  dxi deta,

with H the half-plane above x's horizon (n.(y - x) >= 0) and S the union of the occluders'
shadows: the points y whose segment to x meets an occluder.

How it is integrated
--------------------
- **Along a line eta = const** the visible set is a union of intervals whose ends are known in
  closed form: the target's edges and x's horizon are linear in xi; a sphere's (or, through the
  affine map that makes it round, an ellipsoid's) shadow is bounded by the roots of three
  quadratics (its tangent cone from x, the sphere with diameter x c, the sphere itself: the
  segment's closest point to the centre is inside it, or at its end); a flat convex polygon's by
  the planes through x and its edges and by its own plane (linear); a flat disk sector's by the
  cones from x over its two circles (with a = x - c, m its normal and h = m.a, the segment x + t w
  crosses its plane at p with (m.w)(p - c) = a (m.w) - h w, linear in w, so |p - c| = r is
  quadratic), its own plane and the planes through x and its straight edges; a round cylinder
  patch's by four quadrics (y on the cylinder, the tangent planes from x, the cones from x over its
  two rims) and, for a partial patch, the planes through x and its straight edges. All candidate
  ends are sorted and each piece between two is classified at its midpoint by exact tests (the
  closest point of the segment to the centre; where the segment crosses a disk's plane; the roots
  of the segment's quadratic across a cylinder's axis, their heights and angles), so a superset of
  ends is harmless and no topology has to be built. A convex polygon's shadow on a line is one
  interval (the intersection of the half-lines where y is inside each edge plane and beyond its
  own plane), so many polygons (a mesh's pieces) are merged by sorting their +1 / -1 ends with the
  others and counting: a line costs O(P log P) for P polygons, not P tests a piece. The kernel
  along a line is a rational function of xi: each visible piece is integrated in closed form
  (`line_pieces`).
- **Across lines**, the line integral I(eta) is piecewise analytic. Its breaks (vertices of the
  target and of projected polygons, crossings of the horizon with the target's edges, tangencies
  of the quadrics' traces, crossings of the quadrics' and planes' traces with the target's straight
  edges, the foot of x; for disks and cylinders also their circles' and straight edges' crossings
  with the target's plane and their corners (and a cylinder's rim points touched by the tangent
  planes from x) seen from x) are computed in closed form, and each sub-interval is
  integrated by the Gauss-Kronrod 7-15 pair under the map eta = a + (b - a)(1 - cos pi t) / 2,
  which makes the square-root ends of chords smooth. Breaks not listed (crossings of two shadow
  boundaries) are found by bisection: a sub-interval is split until its two rules agree to its
  share of the tolerance (QUADPACK's local strategy), or until they agree to ROUNDING of a bound
  on the query's unoccluded factor (rounding-level slivers of a hidden target).

The approach is Nishita & Nakamae's (Proc. SIGGRAPH 1985: exact illumination by clipping the
source against the occluders' projections) turned around: the target is clipped against the
occluders one line at a time, which needs no polygon boolean operations and treats curved
(quadric) shadow boundaries like straight ones.
"""

import numpy as np

from .cones import cone_visible_factor, round_cone_visible_factor
from .quadrature import gauss_kronrod_15

MAX_LEVELS = 40  # bisections of one sub-interval at most
FLOOR = 1e-13  # absolute error floor of a point factor (no refinement below it)
PLANE_MARGIN = 1e-12  # relative distance from a polygon's plane below which rounding decides nothing
ROUNDING = 1e-15  # a sub-interval whose rules agree to this times its query's unoccluded factor is done
LINE_CHUNK = 20_000  # lines integrated at once (bounds the (lines, ends, occluders) temporaries)

# each sub-interval in eta: the 15-point Kronrod rule and its embedded 7-point Gauss rule, under the
# cosine map eta = a + (b - a)(1 - cos pi t) / 2 (square-root ends of chords become smooth)
_KRONROD, _GAUSS_W = gauss_kronrod_15()
_ETA_FRACTION = 0.5 * (1.0 - np.cos(np.pi * _KRONROD.points))
_SLOPE = 0.5 * np.pi * np.sin(np.pi * _KRONROD.points)
_ETA_WEIGHT = _KRONROD.weights * _SLOPE
_ETA_GAUSS = _GAUSS_W * _SLOPE
_POINTS = _KRONROD.size


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


# ---------------------------------------------------------------------------- inputs
def _take_rows(targets, index):
    """A copy of `targets` with the rows `index` of each of its per-query arrays."""
    out = object.__new__(type(targets))
    for name, value in vars(targets).items():
        setattr(out, name, value[index])
    return out


class FlatTargets:
    """Flat convex polygon targets, one per query, in their plane's frame.

    Parameters
    ----------
    corners : ndarray, shape (K, V, 3)
        Vertices of each convex polygon in order (either way round; repeated vertices allowed,
        e.g. a triangle as a quad with two equal corners).
    normal : ndarray, shape (K, 3)
        Unit front normal of each target.
    """

    def __init__(self, corners, normal):
        corners = np.asarray(corners, dtype=np.float64)
        normal = np.asarray(normal, dtype=np.float64)
        self.origin = corners.mean(1)
        # frame: e1 along the longest edge (any in-plane direction would do)
        edges = np.roll(corners, -1, axis=1) - corners
        longest = np.argmax(_dot(edges, edges), axis=1)
        e1 = edges[np.arange(len(corners)), longest]
        e1 = e1 - _dot(e1, normal)[:, None] * normal
        self.e1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
        self.e2 = np.cross(normal, self.e1)
        self.normal = normal
        rel = corners - self.origin[:, None]
        verts = np.stack([_dot(rel, self.e1[:, None]), _dot(rel, self.e2[:, None])], -1)
        # counter-clockwise about the normal (shoelace sign)
        area2 = np.sum(
            verts[..., 0] * np.roll(verts[..., 1], -1, 1) - np.roll(verts[..., 0], -1, 1) * verts[..., 1], 1
        )
        self.verts = np.where((area2 < 0)[:, None, None], verts[:, ::-1], verts)  # (K, V, 2)
        self.area = 0.5 * np.abs(area2)

    def __len__(self):
        return len(self.origin)

    def take(self, index):
        """The targets at `index`."""
        return _take_rows(self, index)

    def corners(self):
        """Vertices in space, counter-clockwise about the normal, shape (K, V, 3)."""
        return (
            self.origin[:, None]
            + self.verts[..., 0, None] * self.e1[:, None]
            + self.verts[..., 1, None] * self.e2[:, None]
        )

    def eta_range(self):
        """(lo, hi) of eta over each target, shape (K,) each."""
        return self.verts[..., 1].min(1), self.verts[..., 1].max(1)

    def edges(self):
        """Straight edges (xi, eta) = start + s direction, s in [0, 1]: shapes (K, V, 2) each."""
        return self.verts, np.roll(self.verts, -1, axis=1) - self.verts

    def chord(self, k, eta):
        """Where lines eta = const cross the targets: (lo, hi, ends, inside) with lo, hi (L,) the
        chord of the convex polygon (lo = hi where the line misses it), no further ends and no
        inside test (every point of the chord is inside)."""
        verts = self.verts[k]  # (L, V, 2)
        a, b = verts, np.roll(verts, -1, axis=1)
        d_eta = b[..., 1] - a[..., 1]
        frac = np.divide(eta[:, None] - a[..., 1], d_eta, out=np.full(d_eta.shape, np.nan), where=d_eta != 0)
        edge_xi = np.where((frac >= 0) & (frac <= 1), a[..., 0] + frac * (b[..., 0] - a[..., 0]), np.nan)
        none = np.all(np.isnan(edge_xi), axis=1)
        lo = np.where(none, 0.0, np.nanmin(np.where(none[:, None], 0.0, edge_xi), axis=1))
        hi = np.where(none, 0.0, np.nanmax(np.where(none[:, None], 0.0, edge_xi), axis=1))
        return lo, hi, np.zeros((len(k), 0)), None

    def eta_breaks(self, line):
        """eta of the vertices and of the crossings of a line alpha xi + beta eta + gamma = 0
        (each (K,)) with the edges, shape (K, 2V)."""
        alpha, beta, gamma = line
        a, b = self.verts, np.roll(self.verts, -1, axis=1)
        fa = alpha[:, None] * a[..., 0] + beta[:, None] * a[..., 1] + gamma[:, None]
        fb = alpha[:, None] * b[..., 0] + beta[:, None] * b[..., 1] + gamma[:, None]
        frac = np.divide(fa, fa - fb, out=np.full(fa.shape, np.nan), where=(fa - fb) != 0)
        cut = np.where((frac >= 0) & (frac <= 1), a[..., 1] + frac * (b[..., 1] - a[..., 1]), np.nan)
        return np.concatenate([self.verts[..., 1], cut], axis=1)


class SectorTargets:
    """Flat annular sectors (disk patches: r in [r0, r1], angle in [a0, a1]), one per query.

    Parameters
    ----------
    center, normal : ndarray, shape (K, 3)
        Disk centre and unit front normal.
    e1 : ndarray, shape (K, 3)
        Unit in-plane direction of angle 0.
    radii, angles : ndarray, shape (K, 2)
        (r0, r1) (m) and (a0, a1) (rad, a1 - a0 <= 2 pi) of each sector.
    """

    def __init__(self, center, normal, e1, radii, angles):
        self.origin = np.asarray(center, dtype=np.float64)
        self.normal = np.asarray(normal, dtype=np.float64)
        self.e1 = np.asarray(e1, dtype=np.float64)
        self.e2 = np.cross(self.normal, self.e1)
        self.radii = np.asarray(radii, dtype=np.float64)
        self.angles = np.asarray(angles, dtype=np.float64)
        self.area = (
            0.5 * (self.radii[:, 1] ** 2 - self.radii[:, 0] ** 2) * (self.angles[:, 1] - self.angles[:, 0])
        )

    def __len__(self):
        return len(self.origin)

    def take(self, index):
        """The targets at `index`."""
        return _take_rows(self, index)

    def eta_range(self):
        r1 = self.radii[:, 1]
        return -r1, r1

    def seen_round(self, x):
        """Whether each target is a whole disk and x (K, 3) lies on its axis (to 1e-12 of its
        distance), so that x sees it as a round cone, shape (K,) bool."""
        whole = (self.radii[:, 0] == 0.0) & (self.angles[:, 1] - self.angles[:, 0] >= 2.0 * np.pi)
        rel = x - self.origin
        height = np.einsum("ki,ki->k", rel, self.normal)
        off_axis = np.linalg.norm(rel - height[:, None] * self.normal, axis=1)
        return whole & (off_axis <= 1e-12 * np.linalg.norm(rel, axis=1))

    def edges(self):
        """The two straight edges (rays from r0 to r1 at the sector's angles): shapes (K, 2, 2)."""
        direction = np.stack([np.cos(self.angles), np.sin(self.angles)], -1)  # (K, 2, 2)
        r0, r1 = self.radii[:, :1, None], self.radii[:, 1:, None]
        return r0 * direction, (r1 - r0) * direction

    def _rays(self, k):
        a = self.angles[k]
        return np.cos(a), np.sin(a)  # (L, 2) each

    def chord(self, k, eta):
        """The outer circle's chord, the inner circle's and the two edge rays' crossings as
        further ends, and the inside test of the sector."""
        r0, r1 = self.radii[k, 0], self.radii[k, 1]
        e2 = eta * eta
        half = np.sqrt(np.maximum(r1 * r1 - e2, 0.0))
        inner = np.where(r0 * r0 > e2, np.sqrt(np.maximum(r0 * r0 - e2, 0.0)), np.nan)
        cos_a, sin_a = self._rays(k)
        along = np.divide(eta[:, None], sin_a, out=np.full(sin_a.shape, np.nan), where=sin_a != 0)
        ray = np.where(along >= 0, along * cos_a, np.nan)
        ends = np.concatenate([-inner[:, None], inner[:, None], ray], axis=1)
        a0, span = self.angles[k, 0], self.angles[k, 1] - self.angles[k, 0]

        def inside(mid):
            rr = mid * mid + e2[:, None]
            angle = np.mod(np.arctan2(eta[:, None], mid) - a0[:, None], 2.0 * np.pi)
            in_wedge = (angle <= span[:, None]) | (span[:, None] >= 2.0 * np.pi - 1e-12)
            return (rr >= (r0 * r0)[:, None]) & (rr <= (r1 * r1)[:, None]) & in_wedge

        return -half, half, ends, inside

    def eta_breaks(self, line):
        """eta of the circles' extremes, the sector's corners and the crossings of a line
        alpha xi + beta eta + gamma = 0 with both circles, shape (K, 12)."""
        alpha, beta, gamma = line
        r = self.radii  # (K, 2)
        corners = r[:, :, None] * np.sin(self.angles)[:, None, :]  # (K, 2, 2)
        # the line meets the circle of radius R at phi with R (alpha cos phi + beta sin phi) = -gamma
        norm = np.hypot(alpha, beta)[:, None]
        phi0 = np.arctan2(beta, alpha)[:, None]
        c = np.divide(-gamma[:, None], r * norm, out=np.full(r.shape, np.nan), where=r * norm > 0)
        spread = np.arccos(np.where(np.abs(c) <= 1, c, np.nan))
        cuts = np.concatenate([r * np.sin(phi0 + spread), r * np.sin(phi0 - spread)], axis=1)
        return np.concatenate([r, -r, corners.reshape(-1, 4), cuts], axis=1)


class Disks:
    """Flat disk occluders (circular disk patches: annular sectors r in [r0, r1], angle in
    [a0, a1]), padded per query.

    Parameters
    ----------
    center, normal, e1 : ndarray, shape (K, D, 3)
        Disk centre, unit normal and the unit in-plane direction of angle 0.
    radii, angles : ndarray, shape (K, D, 2)
        (r0, r1) (m) and (a0, a1) (rad, a1 - a0 <= 2 pi, measured from e1 toward normal x e1).
    valid : ndarray of bool, shape (K, D)
    """

    def __init__(self, center, normal, e1, radii, angles, valid):
        self.center = np.asarray(center, dtype=np.float64)
        self.normal = np.asarray(normal, dtype=np.float64)
        self.e1 = np.asarray(e1, dtype=np.float64)
        self.e2 = np.cross(self.normal, self.e1)
        self.radii = np.asarray(radii, dtype=np.float64)
        self.angles = np.asarray(angles, dtype=np.float64)
        self.valid = np.asarray(valid, dtype=bool)

    @classmethod
    def none(cls, K):
        return cls(*(np.zeros((K, 0, 3)),) * 3, *(np.zeros((K, 0, 2)),) * 2, np.zeros((K, 0), bool))

    def take(self, index):
        return _take_rows(self, index)

    def whole(self):
        """Which disks span every angle, shape (K, D) bool (no wedge edges)."""
        return self.angles[..., 1] - self.angles[..., 0] >= 2.0 * np.pi - 1e-12

    def live(self):
        """Which disks are valid, valid with a hole (r0 > 0), valid sectors (not whole): the
        boundaries each has, shapes (K, D) bool."""
        return self.valid, self.valid & (self.radii[..., 0] > 0.0), self.valid & ~self.whole()

    def wedge_normals(self):
        """In-plane unit normals of the two straight edges' lines through the centre, shape
        (K, D, 2, 3): n_a = normal x d_a with d_a = cos a e1 + sin a e2."""
        cos, sin = np.cos(self.angles)[..., None], np.sin(self.angles)[..., None]
        return cos * self.e2[..., None, :] - sin * self.e1[..., None, :]

    def corners(self):
        """The sectors' four corners c + r d_a, shape (K, D, 4, 3)."""
        d = (
            np.cos(self.angles)[..., None] * self.e1[..., None, :]
            + np.sin(self.angles)[..., None] * self.e2[..., None, :]
        )  # (K, D, 2, 3)
        r = self.radii[..., :, None, None]  # (K, D, 2, 1, 1)
        return (self.center[..., None, None, :] + r * d[..., None, :, :]).reshape(
            *self.center.shape[:2], 4, 3
        )


class Cylinders:
    """Round cylinder occluders (lateral surface patches: angle in [a0, a1] about the axis, axial
    distance from the base centre in [s0, s1]), padded per query.

    Parameters
    ----------
    center, axis, e1 : ndarray, shape (K, C, 3)
        Base centre, unit axis and the unit direction (perpendicular to it) of angle 0.
    radius : ndarray, shape (K, C)
    angles, heights : ndarray, shape (K, C, 2)
        (a0, a1) (rad, from e1 toward axis x e1) and (s0, s1) (m).
    valid : ndarray of bool, shape (K, C)
    """

    def __init__(self, center, axis, e1, radius, angles, heights, valid):
        self.center = np.asarray(center, dtype=np.float64)
        self.axis = np.asarray(axis, dtype=np.float64)
        self.e1 = np.asarray(e1, dtype=np.float64)
        self.e2 = np.cross(self.axis, self.e1)
        self.radius = np.asarray(radius, dtype=np.float64)
        self.angles = np.asarray(angles, dtype=np.float64)
        self.heights = np.asarray(heights, dtype=np.float64)
        self.valid = np.asarray(valid, dtype=bool)

    @classmethod
    def none(cls, K):
        z3, z2 = np.zeros((K, 0, 3)), np.zeros((K, 0, 2))
        return cls(z3, z3, z3, np.zeros((K, 0)), z2, z2, np.zeros((K, 0), bool))

    def take(self, index):
        return _take_rows(self, index)

    def sector(self):
        """Valid patches that do not go all the way round, shape (K, C) bool."""
        return self.valid & (self.angles[..., 1] - self.angles[..., 0] < 2.0 * np.pi - 1e-12)

    def directions(self, angles):
        """cos a e1 + sin a e2 for angles (K, C, J), shape (K, C, J, 3)."""
        return (
            np.cos(angles)[..., None] * self.e1[:, :, None] + np.sin(angles)[..., None] * self.e2[:, :, None]
        )


class Blockers:
    """Occluders of each query, padded: whole spheres/ellipsoids, flat convex polygons, flat
    disks and round cylinders.

    Parameters
    ----------
    sphere_linear, sphere_offset : ndarray, shape (K, S, 3, 3) and (K, S, 3)
        Each ellipsoid is {linear @ p + offset : |p| <= 1}; a sphere has linear = r I.
    sphere_valid : ndarray of bool, shape (K, S)
    polygons : ndarray, shape (K, P, W, 3)
        Vertices of convex flat polygons (repeated vertices allowed).
    polygon_valid : ndarray of bool, shape (K, P)
    sphere_inverse : ndarray, shape (K, S, 3, 3), optional
        The inverses of `sphere_linear`, when the caller has them (one inverse per occluder
        instead of one per query).
    disks : Disks, optional
        Disk occluders (none by default).
    cylinders : Cylinders, optional
        Cylinder occluders (none by default).
    polygon_edges : ndarray of bool, shape (K, P, W), optional
        The polygons' edges whose traces may bound the union of the shadows (default: all). Edges
        inside it (between two pieces of a mesh seen from one side) add no breaks across lines.
    """

    def __init__(
        self,
        sphere_linear,
        sphere_offset,
        sphere_valid,
        polygons,
        polygon_valid,
        sphere_inverse=None,
        disks=None,
        cylinders=None,
        polygon_edges=None,
    ):
        if sphere_inverse is None:
            sphere_inverse = np.linalg.inv(sphere_linear) if sphere_linear.size else sphere_linear
        self.sphere_inverse = sphere_inverse
        self.sphere_offset = sphere_offset
        self.sphere_valid = sphere_valid
        self.polygons = polygons
        self.polygon_valid = polygon_valid
        self.polygon_edges = (
            np.ones(polygons.shape[:3], dtype=bool) if polygon_edges is None else polygon_edges
        )
        self.disks = Disks.none(len(sphere_valid)) if disks is None else disks
        self.cylinders = Cylinders.none(len(sphere_valid)) if cylinders is None else cylinders

    @classmethod
    def none(cls, K):
        return cls(
            np.zeros((K, 0, 3, 3)),
            np.zeros((K, 0, 3)),
            np.zeros((K, 0), bool),
            np.zeros((K, 0, 3, 3)),
            np.zeros((K, 0), bool),
        )

    def take(self, index):
        out = object.__new__(Blockers)
        for name in (
            "sphere_inverse",
            "sphere_offset",
            "sphere_valid",
            "polygons",
            "polygon_valid",
            "polygon_edges",
        ):
            setattr(out, name, getattr(self, name)[index])
        out.disks = self.disks.take(index)
        out.cylinders = self.cylinders.take(index)
        return out

    def with_polygons(self, polygons, valid, edges):
        """The same occluders and more flat polygons per query: polygons (K, Q, 4, 3), valid
        (K, Q) and edges (K, Q, 4) appended to each query's (this one's polygons have 4
        vertices too)."""
        out = self.take(slice(None))
        out.polygons = np.concatenate([self.polygons, polygons], 1)
        out.polygon_valid = np.concatenate([self.polygon_valid, valid], 1)
        out.polygon_edges = np.concatenate([self.polygon_edges, edges], 1)
        return out

    def trimmed(self):
        """The same occluders with the polygon slots cut after the last one any query uses."""
        used = np.flatnonzero(self.polygon_valid.any(0))
        W = int(used[-1]) + 1 if used.size else 0
        out = self.take(slice(None))
        out.polygons, out.polygon_valid, out.polygon_edges = (
            self.polygons[:, :W],
            self.polygon_valid[:, :W],
            self.polygon_edges[:, :W],
        )
        return out


class _Query:
    """Per-query quantities shared by every line: x in the target's frame and the occluders'
    line coefficients (w(xi, eta) = y - x = g0 + eta g1 + xi e1)."""

    def __init__(self, x, n, targets, blockers):
        self.x, self.n, self.t, self.b = x, n, targets, blockers
        rel = x - targets.origin
        self.h = _dot(rel, targets.normal)
        self.xi_x = _dot(rel, targets.e1)
        self.eta_x = _dot(rel, targets.e2)
        self.g0 = -rel  # (o - x)
        # horizon n.(y - x) = alpha xi + beta eta + gamma
        self.alpha = _dot(n, targets.e1)
        self.beta = _dot(n, targets.e2)
        self.gamma = _dot(n, self.g0)
        # spheres in their unit frame: c = centre - x, m = |c|^2 - 1, quadrics Q(w) = w.M w + q.w + q0
        inv = blockers.sphere_inverse
        if inv.shape[1]:
            xl = np.einsum("ksij,ksj->ksi", inv, x[:, None] - blockers.sphere_offset)
            self.c = -xl
            self.m = _dot(xl, xl) - 1.0
            self.d = np.einsum("ksij,kj->ksi", inv, targets.e1)  # xi direction
            self.s0 = np.einsum("ksij,kj->ksi", inv, self.g0)
            self.s1 = np.einsum("ksij,kj->ksi", inv, targets.e2)
        # polygons: edge planes through x, N_k . w >= 0 inside (one sign for all k), own plane
        poly = blockers.polygons
        if poly.shape[1]:
            rel_p = poly - x[:, None, None]
            self.edge_normal = np.cross(rel_p, np.roll(rel_p, -1, axis=2))  # (K, P, W, 3)
            plane = np.cross(poly[:, :, 1] - poly[:, :, 0], poly[:, :, 2] - poly[:, :, 0])
            plane += np.cross(poly[:, :, 2] - poly[:, :, 0], poly[:, :, 3 % poly.shape[2]] - poly[:, :, 0])
            self.plane_normal = plane
            self.plane_x = hx = _dot(plane, x[:, None] - poly[:, :, 0])  # height of x over the plane
            # each polygon's shadow conditions along lines as half-lines a xi + b0 + eta b1 >= 0
            # (`_polygon_shadows`): edge planes with N's sign that of -h_x, then y beyond the plane
            side = -np.sign(hx)[..., None]
            N = self.edge_normal
            self.edge_a = side * _dot(N, targets.e1[:, None, None])  # (K, P, W)
            self.edge_b = (side * _dot(N, self.g0[:, None, None]), side * _dot(N, targets.e2[:, None, None]))
            self.cross_a = -hx * _dot(plane, targets.e1[:, None])  # (K, P)
            self.cross_b = (
                -hx * (hx + _dot(plane, self.g0[:, None])) - PLANE_MARGIN * hx * hx,
                -hx * _dot(plane, targets.e2[:, None]),
            )
            # no shadow: padding, and x in the polygon's plane (within PLANE_MARGIN of its size)
            area2 = _dot(plane, plane)  # (2 area)^2
            self.polygon_never = ~blockers.polygon_valid | (
                hx * hx <= PLANE_MARGIN**2 * area2 * np.sqrt(area2)
            )
        # disks: with a = x - c and m the disk's normal, the segment x + t w crosses the disk's plane
        # at p with (m.w)(p - c) = L w = a (m.w) - h_x w, linear in w (h_x = m.a: x's height)
        disks = blockers.disks
        if disks.valid.shape[1]:
            self.disk_a = x[:, None] - disks.center  # (K, D, 3)
            self.disk_hx = _dot(disks.normal, self.disk_a)
            self.disk_live = disks.live()
            self.disk_wedge = disks.wedge_normals()
            for name, v in (("g0", self.g0), ("e1", targets.e1), ("e2", targets.e2)):
                mv = _dot(disks.normal, v[:, None])  # (K, D)
                setattr(self, "disk_m" + name, mv)
                setattr(
                    self, "disk_L" + name, self.disk_a * mv[..., None] - self.disk_hx[..., None] * v[:, None]
                )
        # cylinders: with a = x - c and P the projection across the axis z, the segment x + t w meets
        # the round cylinder where t^2 |P w|^2 + 2 t Pa.Pw + |P a|^2 - R^2 = 0
        cylinders = blockers.cylinders
        if cylinders.valid.shape[1]:
            z = cylinders.axis
            self.cyl_a = x[:, None] - cylinders.center  # (K, C, 3)
            self.cyl_za = _dot(z, self.cyl_a)
            self.cyl_Pa = self.cyl_a - self.cyl_za[..., None] * z
            for name, v in (("g0", self.g0), ("e1", targets.e1), ("e2", targets.e2)):
                zv = _dot(z, v[:, None])  # (K, C)
                setattr(self, "cyl_z" + name, zv)
                setattr(self, "cyl_P" + name, v[:, None] - zv[..., None] * z)
            # each shadow boundary's trace in the target's plane: its conic's six coefficients, each
            # shape (K, C, forms)
            forms = [_conic_coefficients(form) for form in _cylinder_forms(self)]
            self.cyl_conics = tuple(np.stack(c, -1) for c in zip(*forms))
            # which forms bound a shadow: the surface's own trace only where the patch reaches the
            # target's plane (heights of its rims' centres, give or take R times the rims' tilt)
            n_t = targets.normal[:, None]
            rims = (
                _dot(cylinders.center - targets.origin[:, None], n_t)[..., None]
                + cylinders.heights * _dot(z, n_t)[..., None]
            )
            tilt = cylinders.radius * np.hypot(_dot(cylinders.e1, n_t), _dot(cylinders.e2, n_t))
            touch = (rims.min(-1) - tilt <= 0.0) & (rims.max(-1) + tilt >= 0.0)
            valid = cylinders.valid
            self.cyl_live = np.stack([valid & touch, valid, valid, valid], -1)  # (K, C, forms)
            self.cyl_sector = cylinders.sector()
            self.cyl_generators = _generator_planes(self)


# ---------------------------------------------------------------------------- along lines
def _line_products(Q, k, eta):
    """Dot products of the sphere frames along lines, each (L, S): c.d, c.w0, d.d, d.w0, w0.w0,
    c.c, with w(xi) = w0 + xi d the segment from x to the line's point in the unit frame."""
    c, d = Q.c[k], Q.d[k]  # (L, S, 3)
    w0 = Q.s0[k] + eta[:, None, None] * Q.s1[k]
    cd, cw = _dot(c, d), _dot(c, w0)
    dd, dw, ww = _dot(d, d), _dot(d, w0), _dot(w0, w0)
    return cd, cw, dd, dw, ww, _dot(c, c)


def _quadric_terms(m, products):
    """Coefficients (A, B, C) of the three sphere quadrics along lines, each (L, S, 3):
    Q_i(w0 + xi d) = A xi^2 + B xi + C, from `_line_products` and m = |c|^2 - 1."""
    cd, cw, dd, dw, ww, cc = products
    # tangent cone: (w.c)^2 - m |w|^2 ; sphere on the diameter x-c: |w|^2 - w.c ; the sphere: |w - c|^2 - 1
    A = np.stack([cd * cd - m * dd, dd, dd], -1)
    B = np.stack([2.0 * (cw * cd - m * dw), 2.0 * dw - cd, 2.0 * (dw - cd)], -1)
    C = np.stack([cw * cw - m * ww, ww - cw, ww - 2.0 * cw + cc - 1.0], -1)
    return A, B, C


def quadratic_roots(A, B, C):
    """Real roots of A t^2 + B t + C (NaN where none), shape (..., 2); linear where A ~ 0."""
    scale = np.abs(A) + np.abs(B) + np.abs(C)
    disc = B * B - 4.0 * A * C
    sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
    # stable: q = -(B + sign(B) sq) / 2, roots q / A and C / q
    q = -0.5 * (B + np.where(B >= 0, 1.0, -1.0) * sq)
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = np.where(np.abs(A) > 1e-14 * scale, q / A, np.where(B != 0, -C / B, np.nan))
        r2 = np.where(q != 0, C / q, np.nan)
    return np.stack([r1, r2], -1)


def _safe_ratio(num, den):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den != 0, -num / np.where(den != 0, den, 1.0), np.nan)


def line_pieces(Q, k, eta):
    """The visible-part integral along lines eta = const, shape (L,).

    Parameters
    ----------
    Q : _Query
    k : ndarray of int, shape (L,)
        Query of each line.
    eta : ndarray, shape (L,)
    """
    t = Q.t
    L = len(k)
    lo, hi, target_ends, inside = t.chord(k, eta)
    # ---- candidate ends inside the chord: horizon, occluders
    horizon_c = Q.beta[k] * eta + Q.gamma[k]  # n.(y - x) = alpha xi + horizon_c
    alpha = Q.alpha[k]
    ends = [target_ends, _safe_ratio(horizon_c, alpha)[:, None]]
    S = Q.b.sphere_valid.shape[1]
    if S:
        products = _line_products(Q, k, eta)
        cd, cw, dd, dw, ww0, cc = products
        A, B, C = _quadric_terms(Q.m[k], products)
        live = Q.b.sphere_valid[k]  # (padding holds unit spheres: no ends of theirs)
        ends.append(np.where(live[..., None, None], quadratic_roots(A, B, C), np.nan).reshape(L, -1))
        ends.append(np.where(live, _safe_ratio(cw, cd), np.nan))  # w.c = 0
    P = Q.b.polygon_valid.shape[1]
    if P:
        shade_lo, shade_hi = _polygon_shadows(Q, k, eta, lo, hi)
    disks = Q.b.disks
    D = disks.valid.shape[1]
    if D:
        Lw0 = Q.disk_Lg0[k] + eta[:, None, None] * Q.disk_Le2[k]  # (L, D, 3)
        Le1 = Q.disk_Le1[k]
        mw0 = Q.disk_mg0[k] + eta[:, None] * Q.disk_me2[k]  # m.w = mw0 + xi me1, each (L, D)
        me1 = Q.disk_me1[k]
        hx = Q.disk_hx[k]
        uu, ue, ee = _dot(Lw0, Lw0), _dot(Lw0, Le1), _dot(Le1, Le1)  # |L w|^2 = uu + 2 xi ue + xi^2 ee
        rr = disks.radii[k] ** 2  # (L, D, 2)
        valid, inner, sector = (mask[k] for mask in Q.disk_live)
        # the cones over both circles: |L w|^2 = r^2 (m.w)^2
        roots = quadratic_roots(
            ee[..., None] - rr * (me1 * me1)[..., None],
            2.0 * (ue[..., None] - rr * (mw0 * me1)[..., None]),
            uu[..., None] - rr * (mw0 * mw0)[..., None],
        )  # (L, D, 2 circles, 2)
        ends.append(np.where(np.stack([inner, valid], -1)[..., None], roots, np.nan).reshape(L, -1))
        ends.append(np.where(valid, _safe_ratio(hx + mw0, me1), np.nan))  # y in the disk's plane
        wedge = Q.disk_wedge[k]  # (L, D, 2, 3): the straight edges' lines, (L w).n_a = 0
        wf0 = np.einsum("ldi,ldai->lda", Lw0, wedge)
        wf1 = np.einsum("ldi,ldai->lda", Le1, wedge)
        ends.append(np.where(sector[..., None], _safe_ratio(wf0, wf1), np.nan).reshape(L, -1))
    C = Q.b.cylinders.valid.shape[1]
    if C:
        cylinder_ends, cylinder_line = _cylinder_ends(Q, k, eta)
        ends.append(cylinder_ends)
    ends = np.concatenate(ends, axis=1)
    ends = np.where(np.isfinite(ends), np.clip(ends, lo[:, None], hi[:, None]), hi[:, None])
    ends = np.concatenate([lo[:, None], ends, hi[:, None]], axis=1)
    if P:
        # the polygons' shadows as +1 / -1 events: after sorting, their running sum counts the
        # shadows over each piece (a union of P intervals in one sort, not P tests a piece)
        shown = shade_hi > shade_lo
        events = np.concatenate([np.zeros(ends.shape, np.int32), shown, -shown.astype(np.int32)], axis=1)
        ends = np.concatenate([ends, shade_lo, shade_hi], axis=1)
        order = np.argsort(ends, axis=1, kind="stable")
        ends = np.take_along_axis(ends, order, axis=1)
        shaded = np.cumsum(np.take_along_axis(events, order, axis=1), axis=1)[:, :-1] > 0
    else:
        ends = np.sort(ends, axis=1)
    x0, x1 = ends[:, :-1], ends[:, 1:]
    mid = 0.5 * (x0 + x1)

    # ---- classify pieces at their midpoints (scalar forms of the exact segment tests)
    visible = (x1 > x0) & (alpha[:, None] * mid + horizon_c[:, None] > 0.0)
    if inside is not None:
        visible &= inside(mid)
    if S:
        valid = Q.b.sphere_valid[k]
        for j in range(S):  # (a small fixed axis: occluders of one query)
            m = mid
            wc = cw[:, j, None] + m * cd[:, j, None]
            wwm = ww0[:, j, None] + m * (2.0 * dw[:, j, None] + m * dd[:, j, None])
            tc = np.clip(np.divide(wc, wwm, out=np.zeros_like(wwm), where=wwm > 0), 0.0, 1.0)
            gap = tc * (tc * wwm - 2.0 * wc) + cc[:, j, None]  # |t w - c|^2
            visible &= ~((gap < 1.0) & valid[:, j, None])
    if P:
        visible &= ~shaded
    if D:
        valid = disks.valid[k]
        whole = disks.whole()[k]
        e1d, e2d = disks.e1[k], disks.e2[k]
        a0 = disks.angles[k, :, 0]
        span = disks.angles[k, :, 1] - a0
        for j in range(D):
            s = mw0[:, j, None] + mid * me1[:, j, None]  # m.w at the pieces' midpoints
            crosses = hx[:, j, None] * (hx[:, j, None] + s) < 0.0
            length = uu[:, j, None] + mid * (2.0 * ue[:, j, None] + mid * ee[:, j, None])  # |L w|^2
            ss = s * s
            within = (length <= rr[:, j, 1, None] * ss) & (length >= rr[:, j, 0, None] * ss)
            if not np.all(whole[:, j]):
                # the crossing's direction from the centre: sign(m.w) L w
                u = Lw0[:, j, None] + mid[..., None] * Le1[:, j, None]  # (L, R, 3)
                sign = np.where(s < 0.0, -1.0, 1.0)
                angle = np.arctan2(sign * _dot(u, e2d[:, j, None]), sign * _dot(u, e1d[:, j, None]))
                angle = np.mod(angle - a0[:, j, None], 2.0 * np.pi)
                within &= (angle <= span[:, j, None]) | whole[:, j, None]
            visible &= ~(within & crosses & valid[:, j, None])
    if C:
        visible &= ~_cylinder_blocked(Q, k, cylinder_line, mid)

    # ---- merge runs of visible pieces, then integrate each run in closed form
    padded = np.pad(visible, ((0, 0), (1, 1)))
    line, first = np.nonzero(padded[:, 1:-1] & ~padded[:, :-2])
    _, last = np.nonzero(padded[:, 1:-1] & ~padded[:, 2:])
    if line.size == 0:
        return np.zeros(L)
    r1, r2 = x0[line, first], x1[line, last]
    value = _kernel_integral(Q, k[line], eta[line], r1, r2)
    return np.bincount(line, weights=value, minlength=L)


def _polygon_shadows(Q, k, eta, lo, hi):
    """Each polygon's shadow on lines eta = const as an interval [start, end] of xi inside the
    chord [lo, hi], each shape (L, P) (end <= start: no shadow).

    The segment x -> y (y = x + w) meets a flat convex polygon where w lies inside the planes
    through x and its edges (N_e . w of one sign: that of -h_x, x's height over the polygon's
    plane against the normal its vertex order gives) and y lies beyond its plane
    (h_x (h_x + n.w) < 0). Along a line each condition is a half-line of xi (w is linear in xi), so
    the shadow is the intersection of W + 1 half-lines: one interval.

    Rounding: y must lie beyond the plane by more than PLANE_MARGIN of x's distance from it (a
    target in the polygon's own plane, such as a patch of a mesh piece that is also an occluder,
    is not shadowed by rounding noise), and a polygon whose plane passes within PLANE_MARGIN of its
    size from x casts no shadow (x on the piece it lies on).
    """
    a = Q.edge_a[k]  # (L, P, W)
    b = Q.edge_b[0][k] + eta[:, None, None] * Q.edge_b[1][k]
    ca = Q.cross_a[k]  # (L, P)
    cb = Q.cross_b[0][k] + eta[:, None] * Q.cross_b[1][k]
    with np.errstate(divide="ignore", invalid="ignore"):
        root, cross = -b / a, -cb / ca
    start = np.maximum(np.where(a > 0.0, root, -np.inf).max(-1), np.where(ca > 0.0, cross, -np.inf))
    end = np.minimum(np.where(a < 0.0, root, np.inf).min(-1), np.where(ca < 0.0, cross, np.inf))
    # (zero-length edges have a = b = 0: no condition)
    never = np.any((a == 0.0) & (b < 0.0), -1) | ((ca == 0.0) & (cb <= 0.0)) | Q.polygon_never[k]
    start = np.clip(start, lo[:, None], hi[:, None])
    end = np.where(never, start, np.clip(end, lo[:, None], hi[:, None]))
    return start, end


def _kernel_integral(Q, k, eta, xi1, xi2):
    """Closed-form integral of h (c0 + alpha s) / (pi (D + s^2)^2) over xi in [xi1, xi2], s = xi - xi_x,
    D = h^2 + (eta - eta_x)^2 (the squared distance from x to the line), shape (J,).

    With psi = atan2(sqrt D, s) for s >= 0:  integral ds / (D + s^2)^2 =
    [(delta - sin delta) + 2 sin delta sin^2(Sigma / 2)] / (2 D^1.5), delta = psi1 - psi2,
    Sigma = psi1 + psi2 (no cancellation far from x), and integral s ds / (D + s^2)^2 =
    (s2 - s1)(s2 + s1) / (2 (D + s1^2)(D + s2^2)). Pieces at s < 0 are mirrored (the first
    integrand is even, the second odd).
    """
    h = Q.h[k]
    D = h * h + (eta - Q.eta_x[k]) ** 2
    root = np.sqrt(D)
    s1, s2 = xi1 - Q.xi_x[k], xi2 - Q.xi_x[k]
    # the part at s >= 0 and the mirrored part at s <= 0
    p1, p2 = np.maximum(s1, 0.0), np.maximum(s2, 0.0)
    m1, m2 = np.maximum(-s2, 0.0), np.maximum(-s1, 0.0)
    K0 = _even_part(p1, p2, D, root) + _even_part(m1, m2, D, root)
    K1 = _odd_part(p1, p2, D) - _odd_part(m1, m2, D)
    c0 = Q.alpha[k] * Q.xi_x[k] + Q.beta[k] * eta + Q.gamma[k]
    return h / np.pi * (c0 * K0 + Q.alpha[k] * K1)


def _even_part(s1, s2, D, root):
    """integral_{s1}^{s2} ds / (D + s^2)^2 for 0 <= s1 <= s2."""
    delta = np.arctan2(root * (s2 - s1), D + s1 * s2)  # psi1 - psi2
    total = np.arctan2(root, s1) + np.arctan2(root, s2)
    d2 = delta * delta
    series = delta * d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0))
    delta_minus_sin = np.where(delta < 1e-2, series, delta - np.sin(delta))
    return (delta_minus_sin + 2.0 * np.sin(delta) * np.sin(0.5 * total) ** 2) / (2.0 * D * root)


def _odd_part(s1, s2, D):
    """integral_{s1}^{s2} s ds / (D + s^2)^2 for 0 <= s1 <= s2."""
    return (s2 - s1) * (s2 + s1) / (2.0 * (D + s1 * s1) * (D + s2 * s2))


# ---------------------------------------------------------------------------- across lines
def conic_tangents(conic):
    """eta of the lines eta = const tangent to the traces A xi^2 + (B0 + B1 eta) xi + C0 + C1 eta
    + C2 eta^2 = 0 (`conic` = (A, B0, B1, C0, C1, C2), each shape S), shape S + (2,), NaN for
    none: where the discriminant in xi, itself quadratic in eta, vanishes."""
    A, B0, B1, C0, C1, C2 = conic
    return quadratic_roots(B1 * B1 - 4 * A * C2, 2 * B0 * B1 - 4 * A * C1, B0 * B0 - 4 * A * C0)


def conic_edge_crossings(conic, start, direction, bounded=True):
    """eta where the traces A xi^2 + (B0 + B1 eta) xi + C0 + C1 eta + C2 eta^2 = 0 cross the
    target's straight edges (a shadow boundary meeting an edge: a kink of I(eta)), NaN for none.

    Parameters
    ----------
    conic : tuple of ndarray, each shape (K, S)
    start, direction : ndarray, shape (K, E, 2)
        Edges (xi, eta) = start + s direction, s in [0, 1].
    bounded : bool, optional
        False: whole lines (any s).

    Returns
    -------
    ndarray, shape (K, S, E, 2)
    """
    A, B0, B1, C0, C1, C2 = (c[..., None] for c in conic)
    px, py = start[:, None, :, 0], start[:, None, :, 1]
    dx, dy = direction[:, None, :, 0], direction[:, None, :, 1]
    s2 = A * dx * dx + B1 * dy * dx + C2 * dy * dy
    s1 = 2.0 * A * px * dx + B0 * dx + B1 * (py * dx + dy * px) + C1 * dy + 2.0 * C2 * py * dy
    s0 = A * px * px + (B0 + B1 * py) * px + C0 + C1 * py + C2 * py * py
    s = quadratic_roots(s2, s1, s0)
    if bounded:
        s = np.where((s >= 0.0) & (s <= 1.0), s, np.nan)
    return py[..., None] + s * dy[..., None]


def _line_edge_crossings(line, start, direction):
    """eta where the lines alpha xi + beta eta + gamma = 0 (each (K, L)) cross the target's
    straight edges, NaN for none: shape (K, L, E)."""
    alpha, beta, gamma = (c[..., None] for c in line)
    px, py = start[:, None, :, 0], start[:, None, :, 1]
    dx, dy = direction[:, None, :, 0], direction[:, None, :, 1]
    across = alpha * dx + beta * dy
    s = np.divide(
        -(alpha * px + beta * py + gamma), across, out=np.full(across.shape, np.nan), where=across != 0
    )
    return np.where((s >= 0.0) & (s <= 1.0), py + s * dy, np.nan)


def _eta_breaks(Q):
    """Candidate breaks of I(eta) per query, shape (K, E) (NaN for none)."""
    t = Q.t
    K = len(t)
    breaks = [Q.eta_x[:, None], t.eta_breaks((Q.alpha, Q.beta, Q.gamma))]
    if Q.b.sphere_valid.shape[1]:
        # tangencies of each quadric's trace: the discriminant of A xi^2 + B xi + C in eta
        c, m, d = Q.c, Q.m, Q.d
        g0, g1 = Q.s0, Q.s1
        M = [  # w.M w + q.w + q0 for the three quadrics
            (lambda u, v: _dot(u, c) * _dot(v, c) - m * _dot(u, v), 0.0 * c, 0.0 * m),
            (lambda u, v: _dot(u, v), -c, 0.0 * m),
            (lambda u, v: _dot(u, v), -2.0 * c, _dot(c, c) - 1.0),
        ]
        for form, q, q0 in M:
            A = form(d, d)
            B0, B1 = 2.0 * form(g0, d) + _dot(q, d), 2.0 * form(g1, d)
            C0 = form(g0, g0) + _dot(q, g0) + q0
            C1, C2 = 2.0 * form(g0, g1) + _dot(q, g1), form(g1, g1)
            roots = conic_tangents((A, B0, B1, C0, C1, C2))
            live = Q.b.sphere_valid[..., None, None]  # (padding holds unit spheres: no breaks)
            breaks.append(np.where(live[..., 0], roots, np.nan).reshape(K, -1))
            crossings = conic_edge_crossings((A, B0, B1, C0, C1, C2), *t.edges())
            breaks.append(np.where(live, crossings, np.nan).reshape(K, -1))
    if Q.b.polygon_valid.shape[1]:
        poly = Q.b.polygons
        hp = _dot(poly - t.origin[:, None, None], t.normal[:, None, None])  # (K, P, W)
        h = Q.h[:, None, None]
        # projections of the vertices between x's level and the plane
        scale = np.divide(h, h - hp, out=np.full(hp.shape, np.nan), where=(h - hp) > 0)
        proj = Q.x[:, None, None] + (poly - Q.x[:, None, None]) * scale[..., None]
        eta = _dot(proj - t.origin[:, None, None], t.e2[:, None, None])
        edges = Q.b.polygon_edges & Q.b.polygon_valid[..., None]  # (K, P, W): edge w joins corners w, w + 1
        corners = edges | np.roll(edges, 1, axis=2)
        breaks.append(np.where((hp >= 0) & corners, eta, np.nan).reshape(K, -1))
        # where the polygon's edges cross the target's plane
        hn = np.roll(hp, -1, axis=2)
        frac = np.divide(hp, hp - hn, out=np.full(hp.shape, np.nan), where=hp * hn < 0)
        cut = poly + frac[..., None] * (np.roll(poly, -1, axis=2) - poly)
        breaks.append(_dot(cut - t.origin[:, None, None], t.e2[:, None, None]).reshape(K, -1))
        # where the traces of the edge planes through x and of the polygon's own plane (where the
        # polygon reaches through the target's plane: elsewhere its cone alone bounds its shadow)
        # cross the target's edges
        straddles = (hp.min(-1) < 0.0) & (hp.max(-1) > 0.0) & Q.b.polygon_valid
        live = np.concatenate([edges, straddles[..., None]], 2)
        N = np.concatenate([Q.edge_normal, Q.plane_normal[:, :, None]], 2)
        N = np.where(live[..., None], N, 0.0).reshape(K, -1, 3)
        g0 = np.concatenate([np.zeros(Q.edge_normal.shape[:3]), Q.plane_x[:, :, None]], 2).reshape(
            K, -1
        ) + _dot(N, Q.g0[:, None])
        line = (_dot(N, t.e1[:, None]), _dot(N, t.e2[:, None]), g0)
        breaks.append(_line_edge_crossings(line, *t.edges()).reshape(K, -1))
    if Q.b.disks.valid.shape[1]:
        breaks.extend(_disk_breaks(Q))
    if Q.b.cylinders.valid.shape[1]:
        breaks.extend(_cylinder_breaks(Q))
    return np.concatenate(breaks, axis=1)


def _in_frame(t, points):
    """The target's origin, normal and e2 shaped to broadcast against `points` (K, ..., 3)."""
    shape = (len(t),) + (1,) * (points.ndim - 2) + (3,)
    return t.origin.reshape(shape), t.normal.reshape(shape), t.e2.reshape(shape)


def _seen_eta(Q, points):
    """eta of `points` (K, ..., 3) projected from x onto the target's plane, shape (K, ...): NaN
    for points behind the plane or not below x."""
    origin, normal, e2 = _in_frame(Q.t, points)
    hp = _dot(points - origin, normal)
    h = Q.h.reshape((-1,) + (1,) * (hp.ndim - 1))
    scale = np.divide(h, h - hp, out=np.full(hp.shape, np.nan), where=(h - hp) > 0)
    x = Q.x.reshape((-1,) + (1,) * (hp.ndim - 1) + (3,))
    return np.where(hp >= 0, _dot(x + (points - x) * scale[..., None] - origin, e2), np.nan)


def circle_crossings(t, center, e1, e2, radius):
    """eta where circles center + r (cos phi e1 + sin phi e2) (each (K, ..., 3), radius (K, ...))
    cross the target's plane, shape (K, ..., 2), NaN where they do not: at height
    hc + r (H1 cos phi + H2 sin phi) = 0."""
    origin, normal, e2_t = _in_frame(t, center)
    hc = _dot(center - origin, normal)
    H1, H2 = _dot(e1, normal), _dot(e2, normal)
    rho, phi0 = np.hypot(H1, H2), np.arctan2(H2, H1)
    c = np.divide(-hc, radius * rho, out=np.full(hc.shape, np.nan), where=radius * rho > 0)
    spread = np.arccos(np.where(np.abs(c) <= 1.0, c, np.nan))
    eta = []
    for phi in (phi0 + spread, phi0 - spread):
        point = center + radius[..., None] * (np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2)
        eta.append(_dot(point - origin, e2_t))
    return np.stack(eta, -1)


def _ray_crossings(t, foot, direction):
    """eta where the lines foot + s direction (broadcast, (K, ..., 3)) cross the target's plane,
    shape (K, ...), NaN where parallel to it."""
    foot, direction = np.broadcast_arrays(foot, direction)
    origin, normal, e2 = _in_frame(t, foot)
    across = _dot(direction, normal)
    along = np.divide(
        -_dot(foot - origin, normal), across, out=np.full(across.shape, np.nan), where=across != 0
    )
    return _dot(foot + along[..., None] * direction - origin, e2)


def _disk_breaks(Q):
    """Candidate breaks of I(eta) from disk occluders, a list of arrays (K, *)."""
    t, disks = Q.t, Q.b.disks
    K = len(t)
    L = {"g0": Q.disk_Lg0, "e1": Q.disk_Le1, "e2": Q.disk_Le2}
    m = {"g0": Q.disk_mg0, "e1": Q.disk_me1, "e2": Q.disk_me2}
    valid, inner, sector = Q.disk_live
    breaks = []

    def add(values, mask):  # values (K, D, ...): NaN where the disk has no such break
        breaks.append(
            np.where(mask.reshape(mask.shape + (1,) * (values.ndim - 2)), values, np.nan).reshape(K, -1)
        )

    for r, live in ((disks.radii[..., 0], inner), (disks.radii[..., 1], valid)):
        # the cone over the circle of radius r: w.M w with w.M v = (L w).(L v) - r^2 (m.w)(m.v)
        def form(u, v, r=r):
            return _dot(L[u], L[v]) - r * r * m[u] * m[v]

        A = form("e1", "e1")
        B0, B1 = 2.0 * form("g0", "e1"), 2.0 * form("e2", "e1")
        C0, C1, C2 = form("g0", "g0"), 2.0 * form("g0", "e2"), form("e2", "e2")
        add(conic_tangents((A, B0, B1, C0, C1, C2)), live)
        add(conic_edge_crossings((A, B0, B1, C0, C1, C2), *t.edges()), live)
    # traces of the disk's plane and of its straight edges' planes through x on the target's edges
    wedge = Q.disk_wedge  # (K, D, 2, 3)
    lines = [((m["e1"], m["e2"], Q.disk_hx + m["g0"]), valid)]
    for a in range(2):
        n_a = wedge[:, :, a]
        lines.append((tuple(_dot(L[name], n_a) for name in ("e1", "e2", "g0")), sector))
    for line, live in lines:
        add(_line_edge_crossings(line, *t.edges()), live)
    # where the circles and the straight edges cross the target's plane, and the sectors' corners
    # seen from x
    for r, live in ((disks.radii[..., 0], inner), (disks.radii[..., 1], valid)):
        add(circle_crossings(t, disks.center, disks.e1, disks.e2, r), live)
    add(_ray_crossings(t, disks.center[:, :, None], np.cross(wedge, disks.normal[:, :, None])), sector)
    add(_seen_eta(Q, disks.corners()), sector)
    return breaks


def _cylinder_forms(Q):
    """The quadrics in w = y - x whose zero sets bound a cylinder's shadow, as (quad, lin, c0) with
    Q(w) = quad(w, w) + lin(w) + c0 (quad(u, v) and lin(v) take the names "g0", "e1", "e2" of the
    precomputed vectors), each over (K, C): y on the cylinder, the tangent planes from x, the cones
    from x over its two rims."""
    cylinders = Q.b.cylinders
    R2 = cylinders.radius**2
    Pa, za, axis = Q.cyl_Pa, Q.cyl_za, cylinders.axis
    P = {name: getattr(Q, "cyl_P" + name) for name in ("g0", "e1", "e2")}
    z = {name: getattr(Q, "cyl_z" + name) for name in ("g0", "e1", "e2")}
    gap = _dot(Pa, Pa) - R2
    zero = 0.0 * gap

    def none(v):
        return zero

    forms = [
        (lambda u, v: _dot(P[u], P[v]), lambda v: 2.0 * _dot(Pa, P[v]), gap),  # |P (a + w)|^2 = R^2
        (lambda u, v: _dot(Pa, P[u]) * _dot(Pa, P[v]) - gap * _dot(P[u], P[v]), none, zero),  # double root
    ]
    for end in (0, 1):
        # the rim at axial distance s, as for disks: |L w|^2 = R^2 (z.w)^2, L w = a_s (z.w) - h_s w with
        # a_s = a - s z and h_s = z.a - s
        h = za - cylinders.heights[..., end]
        a_s = Pa + h[..., None] * axis

        def L(u, a_s=a_s, h=h):
            return a_s * z[u][..., None] - h[..., None] * (P[u] + z[u][..., None] * axis)

        forms.append((lambda u, v, L=L: _dot(L(u), L(v)) - R2 * z[u] * z[v], none, zero))
    return forms


def _conic_coefficients(form):
    """(A, B0, B1, C0, C1, C2) of a form's trace A xi^2 + (B0 + B1 eta) xi + C0 + C1 eta + C2 eta^2
    in the target's plane (w = g0 + eta e2 + xi e1)."""
    quad, lin, c0 = form
    return (
        quad("e1", "e1"),
        2.0 * quad("g0", "e1") + lin("e1"),
        2.0 * quad("e2", "e1"),
        quad("g0", "g0") + lin("g0") + c0,
        2.0 * quad("g0", "e2") + lin("e2"),
        quad("e2", "e2"),
    )


def _generator_planes(Q):
    """Normals of the planes through x and a cylinder patch's two straight edges (its generators at
    angles a0 and a1), shape (K, C, 2, 3)."""
    cylinders = Q.b.cylinders
    d = cylinders.directions(cylinders.angles)  # (K, C, 2, 3)
    foot = cylinders.radius[..., None, None] * d - Q.cyl_a[:, :, None]  # a generator's foot - x
    return np.cross(foot, cylinders.axis[:, :, None])


def _cylinder_ends(Q, k, eta):
    """Candidate ends along lines from cylinder occluders, shape (L, *), and the lines'
    per-cylinder quantities for `_cylinder_blocked`."""
    L = len(k)
    sector = Q.cyl_sector[k]
    e = eta[:, None, None]
    A, B0, B1, C0, C1, C2 = (c[k] for c in Q.cyl_conics)  # (L, C, forms)
    roots = quadratic_roots(A, B0 + B1 * e, C0 + C1 * e + C2 * e * e)  # (L, C, forms, 2)
    ends = [np.where(Q.cyl_live[k][..., None], roots, np.nan).reshape(L, -1)]
    normal = Q.cyl_generators[k]  # (L, C, 2, 3)
    w0 = Q.g0[k] + eta[:, None] * Q.t.e2[k]
    f0 = np.einsum("lcai,li->lca", normal, w0)
    f1 = np.einsum("lcai,li->lca", normal, Q.t.e1[k])
    ends.append(np.where(sector[..., None], _safe_ratio(f0, f1), np.nan).reshape(L, -1))
    # along a line, w = w0 + xi e1: |P w|^2 = q0 + 2 xi q1 + xi^2 q2, Pa.Pw = p0 + xi p1, z.w = z0 + xi z1
    Pw0 = Q.cyl_Pg0[k] + eta[:, None, None] * Q.cyl_Pe2[k]
    Pe1, Pa = Q.cyl_Pe1[k], Q.cyl_Pa[k]
    line = dict(
        q0=_dot(Pw0, Pw0),
        q1=_dot(Pw0, Pe1),
        q2=_dot(Pe1, Pe1),
        p0=_dot(Pa, Pw0),
        p1=_dot(Pa, Pe1),
        z0=Q.cyl_zg0[k] + eta[:, None] * Q.cyl_ze2[k],
        z1=Q.cyl_ze1[k],
        Pw0=Pw0,
        Pe1=Pe1,
    )
    return np.concatenate(ends, axis=1), line


def _cylinder_blocked(Q, k, line, mid):
    """Whether the segments from x to the lines' points at `mid` (L, R) meet a cylinder patch: a
    root t in (0, 1) of t^2 |Pw|^2 + 2 t Pa.Pw + |Pa|^2 - R^2 whose point lies within the patch's
    heights and angles, shape (L, R) bool."""
    cylinders = Q.b.cylinders
    blocked = np.zeros(mid.shape, dtype=bool)
    valid, sector = cylinders.valid[k], Q.cyl_sector[k]
    gap = _dot(Q.cyl_Pa[k], Q.cyl_Pa[k]) - cylinders.radius[k] ** 2  # (L, C)
    for j in range(valid.shape[1]):  # (a small fixed axis: occluders of one query)

        def at(name):
            return line[name][:, j, None]

        A = at("q0") + mid * (2.0 * at("q1") + mid * at("q2"))
        B = 2.0 * (at("p0") + mid * at("p1"))
        roots = quadratic_roots(A, B, gap[:, j, None] + 0.0 * A)  # (L, R, 2)
        s = Q.cyl_za[k, j][:, None, None] + roots * (at("z0") + mid * at("z1"))[..., None]
        lo, hi = cylinders.heights[k, j, 0][:, None, None], cylinders.heights[k, j, 1][:, None, None]
        hit = (roots > 0.0) & (roots < 1.0) & (s >= lo) & (s <= hi)
        if np.any(sector[:, j]):
            Pw = line["Pw0"][:, j, None] + mid[..., None] * line["Pe1"][:, j, None]  # (L, R, 3)
            p = Q.cyl_Pa[k, j][:, None, None] + roots[..., None] * Pw[..., None, :]  # (L, R, 2, 3)
            e1, e2 = cylinders.e1[k, j][:, None, None], cylinders.e2[k, j][:, None, None]
            a0 = cylinders.angles[k, j, 0][:, None, None]
            span = (cylinders.angles[k, j, 1] - cylinders.angles[k, j, 0])[:, None, None]
            angle = np.mod(np.arctan2(_dot(p, e2), _dot(p, e1)) - a0, 2.0 * np.pi)
            hit &= (angle <= span) | ~sector[:, j, None, None]
        blocked |= np.any(hit, -1) & valid[:, j, None]
    return blocked


def _cylinder_breaks(Q):
    """Candidate breaks of I(eta) from cylinder occluders, a list of arrays (K, *)."""
    t, cylinders = Q.t, Q.b.cylinders
    K = len(t)
    valid, sector = cylinders.valid, Q.cyl_sector
    breaks = []

    def add(values, mask):  # values (K, C, ...): NaN where the cylinder has no such break
        shape = mask.shape + (1,) * (values.ndim - 2)
        breaks.append(np.where(mask.reshape(shape), values, np.nan).reshape(K, -1))

    for f in range(Q.cyl_conics[0].shape[-1]):
        A, B0, B1, C0, C1, C2 = (c[..., f] for c in Q.cyl_conics)
        live = Q.cyl_live[..., f]
        add(conic_tangents((A, B0, B1, C0, C1, C2)), live)
        add(conic_edge_crossings((A, B0, B1, C0, C1, C2), *t.edges()), live)
    normal = Q.cyl_generators  # (K, C, 2, 3)
    for a in range(2):
        n_a = normal[:, :, a]
        line = (_dot(n_a, t.e1[:, None]), _dot(n_a, t.e2[:, None]), _dot(n_a, Q.g0[:, None]))
        add(_line_edge_crossings(line, *t.edges()), sector)
    # rim points projected from x: the patch's corners, and where the tangent planes from x touch
    # the rims (the corners of the shadow's outline)
    R = cylinders.radius
    Pa = Q.cyl_Pa
    across = np.sqrt(np.maximum(_dot(Pa, Pa), 1e-300))
    towards = np.arctan2(_dot(Pa, cylinders.e2), _dot(Pa, cylinders.e1))
    touch = np.arccos(np.clip(R / across, -1.0, 1.0))
    angles = np.concatenate([cylinders.angles, np.stack([towards + touch, towards - touch], -1)], -1)
    d = cylinders.directions(angles)  # (K, C, 4, 3)
    rims = (
        cylinders.center[:, :, None] + cylinders.heights[..., None] * cylinders.axis[:, :, None]
    )  # (K, C, 2, 3)
    points = rims[:, :, :, None] + R[..., None, None, None] * d[:, :, None]  # (K, C, 2, 4, 3)
    eta = _seen_eta(Q, points)
    add(eta[..., :2], sector)
    add(eta[..., 2:], valid)
    # where the rims and the generators cross the target's plane
    radius = np.broadcast_to(R[..., None], rims.shape[:-1])
    add(circle_crossings(t, rims, cylinders.e1[:, :, None], cylinders.e2[:, :, None], radius), valid)
    foot = cylinders.center[:, :, None] + R[..., None, None] * cylinders.directions(cylinders.angles)
    add(_ray_crossings(t, foot, cylinders.axis[:, :, None]), sector)
    return breaks


def _lines(Q, k, a, b):
    """Kronrod and Gauss rules (cosine map) of I(eta) over [a, b] per interval, each shape (J,)."""
    eta = a[:, None] + (b - a)[:, None] * _ETA_FRACTION[None]
    kk = np.repeat(k, _POINTS)
    values = np.empty(eta.size)
    flat = eta.ravel()
    for s in range(0, flat.size, LINE_CHUNK):
        part = slice(s, s + LINE_CHUNK)
        values[part] = line_pieces(Q, kk[part], flat[part])
    values = values.reshape(-1, _POINTS)
    return values @ _ETA_WEIGHT * (b - a), values @ _ETA_GAUSS * (b - a)


def visible_factor(x, n, targets, blockers, tol):
    """F(dA(x) -> visible part of a flat target) for many queries, with an error estimate.

    Parameters
    ----------
    x, n : ndarray, shape (K, 3)
        Points (m) and unit normals.
    targets : FlatTargets or SectorTargets
        One target per query (len K).
    blockers : Blockers
        The occluders of each query.
    tol : float or ndarray, shape (K,)
        Relative accuracy of each factor (absolute floor FLOOR).

    Returns
    -------
    F : ndarray, shape (K,)
    error : ndarray, shape (K,)
        Estimated absolute error (sum over sub-intervals of |Kronrod - Gauss|, pessimistic:
        it is the error of the 7-point rule, while the 15-point value is returned).
    lines : int
        Lines integrated (each costs one sort of its candidate ends).
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    K = len(x)
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), (K,))
    F, error = np.zeros(K), np.zeros(K)
    rest = np.arange(K)
    if isinstance(targets, FlatTargets):
        # sphere and polygon occluders on x's side of the plane: closed form (`cones`), no lines
        F, closed = cone_visible_factor(x, n, targets.corners(), targets.normal, blockers)
        rest = np.flatnonzero(~closed)
    else:
        # a whole disk seen from its axis (a sphere target's silhouette disk) is a round cone
        round_ = np.flatnonzero(targets.seen_round(x))
        if round_.size:
            r = targets.take(round_)
            value, closed = round_cone_visible_factor(
                x[round_], n[round_], r.origin, r.normal, r.radii[:, 1], blockers.take(round_)
            )
            F[round_] = value
            rest = np.setdiff1d(rest, round_[closed])
    lines = 0
    # queries grouped by their polygon count (within a factor of 4): a line's cost grows with its
    # query's polygon slots, and padding every query to the fullest one's would waste it
    count = blockers.polygon_valid[rest].sum(1)
    group = np.ceil(0.5 * np.log2(np.maximum(count, 1)))
    for value in np.unique(group):
        part = rest[group == value]
        F[part], error[part], spent = _line_integrals(
            x[part], n[part], targets.take(part), blockers.take(part).trimmed(), tol[part]
        )
        lines += spent
    return F, error, lines


def _line_integrals(x, n, targets, blockers, tol):
    """`visible_factor` by the integrals along lines eta = const (the module's docstring)."""
    K = len(x)
    F = np.zeros(K)
    error = np.zeros(K)
    Q = _Query(x, n, targets, blockers)
    front = Q.h > 0.0
    eta_lo, eta_hi = targets.eta_range()
    breaks = _eta_breaks(Q)
    breaks = np.where(np.isfinite(breaks), np.clip(breaks, eta_lo[:, None], eta_hi[:, None]), eta_hi[:, None])
    breaks = np.sort(np.concatenate([eta_lo[:, None], breaks, eta_hi[:, None]], 1), 1)
    k, j = np.nonzero((breaks[:, 1:] > breaks[:, :-1]) & front[:, None])
    a, b = breaks[k, j], breaks[k, j + 1]
    width = np.maximum(eta_hi - eta_lo, 1e-300)
    # a bound on each query's unoccluded factor (kernel <= 1 / (pi h^2)): the scale of rounding noise
    # in its line integrals, which slivers of a hidden target are made of
    h2 = np.pi * Q.h * Q.h
    bound = np.minimum(1.0, np.divide(targets.area, h2, out=np.ones(len(h2)), where=h2 > targets.area))
    lines = 0
    scale = None
    for _level in range(MAX_LEVELS):
        if k.size == 0:
            break
        value, gauss = _lines(Q, k, a, b)
        lines += value.size * _POINTS
        diff = np.abs(value - gauss)
        if scale is None:  # each query's scale: its first estimate
            scale = np.bincount(k, weights=np.abs(value), minlength=K)
        allowed = np.maximum(np.maximum(tol[k] * scale[k], FLOOR) * (b - a) / width[k], ROUNDING * bound[k])
        done = (diff <= allowed) | (_level == MAX_LEVELS - 1)
        F += np.bincount(k[done], weights=value[done], minlength=K)
        error += np.bincount(k[done], weights=diff[done], minlength=K)
        todo = ~done
        mid = 0.5 * (a + b)
        k = np.concatenate([k[todo], k[todo]])
        a, b = np.concatenate([a[todo], mid[todo]]), np.concatenate([mid[todo], b[todo]])
    return np.maximum(F, 0.0), error, int(lines)
