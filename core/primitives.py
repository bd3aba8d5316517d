"""Analytic surfaces: sphere, bilinear quad, disk, cylinder (lateral surface)."""

import numpy as np

from . import checks
from .kinds import CYLINDER, DISK, GENERIC, POLYGON, SPHERE
from .surface import AffineGeometry, Geometry, Surface

TWO_PI = 2.0 * np.pi


def cos_range(a, b):
    """Range (lo, hi) of cos over [a, b] (rad)."""
    lo, hi = sorted((np.cos(a), np.cos(b)))
    if np.floor(b / TWO_PI) >= np.ceil(a / TWO_PI):  # a multiple of 2 pi inside: cos = 1
        hi = 1.0
    if np.floor((b - np.pi) / TWO_PI) >= np.ceil((a - np.pi) / TWO_PI):  # an odd multiple of pi: -1
        lo = -1.0
    return lo, hi


def sin_range(a, b):
    """Range (lo, hi) of sin over [a, b] (rad): sin x = cos(x - pi / 2)."""
    return cos_range(a - 0.5 * np.pi, b - 0.5 * np.pi)


def _product_range(x, y):
    """Interval product [x0, x1] * [y0, y1]."""
    products = [x[0] * y[0], x[0] * y[1], x[1] * y[0], x[1] * y[1]]
    return min(products), max(products)


def orthonormal_frame(axis):
    """Right-handed orthonormal columns (e1, e2, axis) for a unit `axis`.

    e1 is perpendicular to `axis` and to the coordinate axis least aligned with it, so the
    frame is a deterministic function of `axis`.

    Returns
    -------
    ndarray, shape (3, 3)
        Columns e1, e2, axis.
    """
    helper = np.zeros(3)
    helper[np.argmin(np.abs(axis))] = 1.0
    e1 = np.cross(helper, axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    return np.column_stack([e1, e2, axis])


# --------------------------------------------------------------------------- sphere
class SphereGeometry(AffineGeometry):
    """Unit sphere p = (sin u cos v, sin u sin v, cos u) mapped by an affine transform."""

    natural_domain = ((0.0, np.pi), (0.0, TWO_PI))
    kind = SPHERE

    def exact_kind(self, box):
        return SPHERE if self.similarity_scale is not None else GENERIC

    def whole_ellipsoid(self, box):
        return tuple(map(tuple, box)) == self.natural_domain

    def bounded_solid(self):
        return self.offset, self.linear

    def unit_box(self, box):
        # p = (sin u cos v, sin u sin v, cos u) with u in [0, pi]: sin u >= 0, cos u decreasing
        (u0, u1), (v0, v1) = box
        su = sin_range(u0, u1)
        ranges = [_product_range(su, cos_range(v0, v1)), _product_range(su, sin_range(v0, v1))]
        ranges.append((np.cos(u1), np.cos(u0)))
        return tuple(np.array(ranges).T)

    @staticmethod
    def local_jet(u, v):
        su, cu, sv, cv = np.sin(u), np.cos(u), np.sin(v), np.cos(v)
        jet = np.empty(np.shape(u) + (3, 3))
        jet[..., 0, 0] = su * cv
        jet[..., 0, 1] = su * sv
        jet[..., 0, 2] = cu
        jet[..., 1, 0] = cu * cv
        jet[..., 1, 1] = cu * sv
        jet[..., 1, 2] = -su
        jet[..., 2, 0] = -jet[..., 0, 1]
        jet[..., 2, 1] = jet[..., 0, 0]
        jet[..., 2, 2] = 0.0
        return jet

    def exact_area(self, box):
        s = self.similarity_scale
        if s is None:
            return None
        (u0, u1), (v0, v1) = box
        # cos u0 - cos u1 = 2 sin((u0 + u1) / 2) sin((u1 - u0) / 2): no cancellation on thin bands
        return s * s * 2.0 * np.sin(0.5 * (u0 + u1)) * np.sin(0.5 * (u1 - u0)) * (v1 - v0)

    @property
    def convex_outward(self):
        return True


class Sphere(Surface):
    """Sphere: u = polar angle from +Z in [0, pi], v = azimuth from +X in [0, 2 pi]; front = outside.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre (m).
    radius : float
        Radius (m), > 0.

    Raises
    ------
    ValueError
        If the centre is not a finite 3-vector within `checks.MAX_COORDINATE` of the origin, or
        the radius is not positive, not between `checks.MIN_LENGTH` and `checks.MAX_COORDINATE`,
        or below `checks.RESOLUTION` times the centre's distance from the origin. Strings, bools
        and None raise `checks.ArgumentTypeError` (a TypeError and a ValueError).
    """

    def __init__(self, center, radius):
        c = checks.point(center, "sphere center")
        r = checks.length(radius, "sphere radius", np.linalg.norm(c))
        self._init(SphereGeometry(r * np.eye(3), c))

    @property
    def center(self):
        """Centre, shape (3,) (of the ellipsoid, after a non-uniform transform)."""
        return self.geometry.offset

    @property
    def radius(self):
        """Radius, or None if a non-uniform transform made this an ellipsoid."""
        return self.geometry.similarity_scale


# --------------------------------------------------------------------------- quad
class QuadGeometry(Geometry):
    """Bilinear patch through corners p00, p10, p11, p01 over (u, v) in [0, 1]^2."""

    def __init__(self, corners, handedness=1):
        self.corners = np.array(corners, dtype=np.float64)
        self.corners.setflags(write=False)
        self.handedness = handedness
        p00, p10, p11, p01 = self.corners
        size = max(np.linalg.norm(p11 - p00), np.linalg.norm(p01 - p10))
        normal = np.cross(p11 - p00, p01 - p10)
        self.size = size
        self._plane = None
        self._valid_whole = False  # (set once validate_box passed on the whole domain)
        length = np.linalg.norm(normal)
        if length > 0.0:
            unit = normal / length
            heights = (self.corners - self.corners.mean(0)) @ unit
            if np.abs(heights).max() <= 1e-10 * size:
                self._plane = (self.corners.mean(0), unit)

    @property
    def kind(self):
        return POLYGON if self._plane is not None else GENERIC

    def exact_kind(self, box):
        return self.kind

    def hull_points(self, box):
        return self.box_corners(box)  # (a bilinear patch lies in the hull of its corners)

    def derivatives(self, u, v):
        u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
        return self._bilinear(self.corners, u[..., None], v[..., None])

    @staticmethod
    def _bilinear(c, u, v):
        """c: corners (..., 4, 3) broadcast against u, v of shape (..., 1)."""
        p00, p10, p11, p01 = c[..., 0, :], c[..., 1, :], c[..., 2, :], c[..., 3, :]
        P = (1 - u) * (1 - v) * p00 + u * (1 - v) * p10 + u * v * p11 + (1 - u) * v * p01
        Pu = (1 - v) * (p10 - p00) + v * (p11 - p01)
        Pv = (1 - u) * (p01 - p00) + u * (p11 - p10)
        return P, Pu, Pv

    @staticmethod
    def flat_patches(patches):
        """Indices of the patches that lie on a flat QuadGeometry (quads and triangles), a list."""
        return [k for k, p in enumerate(patches) if p.geometry.exact_kind(p.domain) == POLYGON]

    @classmethod
    def patch_frames(cls, patches):
        """Corners and centre normals of many flat quad patches at once.

        Parameters
        ----------
        patches : sequence of Surface
            Patches on QuadGeometry.

        Returns
        -------
        corners : ndarray, shape (K, 4, 3)
            p00, p10, p11, p01 of each patch's box (as `box_corners`).
        normal : ndarray, shape (K, 3)
            dP/du x dP/dv at the box centre (times the patch's orientation: its front).
        """
        C = np.stack([p.geometry.corners for p in patches])[:, None]  # (K, 1, 4, 3)
        box = np.array([p.domain for p in patches], dtype=np.float64)  # (K, 2, 2)
        u = np.concatenate([box[:, 0][:, [0, 1, 1, 0]], box[:, 0].mean(1, keepdims=True)], 1)
        v = np.concatenate([box[:, 1][:, [0, 0, 1, 1]], box[:, 1].mean(1, keepdims=True)], 1)
        P, Pu, Pv = cls._bilinear(C, u[..., None], v[..., None])  # (K, 5, 3)
        sign = np.array([p.orientation for p in patches], dtype=np.float64)
        return P[:, :4], sign[:, None] * np.cross(Pu[:, 4], Pv[:, 4])

    @classmethod
    def stack(cls, geometries):
        """Coefficients (p00, p10 - p00, p01 - p00, p11 - p10 - p01 + p00) of every quad, (G, 4, 3):
        P = a + u b + v c + u v d."""
        c = np.stack([g.corners for g in geometries])
        p00, p10, p11, p01 = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
        return np.stack([p00, p10 - p00, p01 - p00, p11 - p10 - p01 + p00], 1)

    @classmethod
    def stacked_derivatives(cls, stack, index, u, v):
        coefficients = stack[0, None] if len(stack) == 1 else stack[index]  # (one gather)
        a, b, c, d = (coefficients[:, k] for k in range(4))
        u, v = u[:, None], v[:, None]
        Pu = b + v * d
        return a + u * Pu + v * c, Pu, c + u * d

    def transformed(self, linear, offset):
        hand = self.handedness * (1 if np.linalg.det(linear) > 0 else -1)
        return QuadGeometry(self.corners @ linear.T + offset, hand)

    def box_corners(self, box):
        """Corners of the sub-quad over `box`, shape (4, 3), in the order p00, p10, p11, p01."""
        (u0, u1), (v0, v1) = box
        P, _, _ = self.derivatives(np.array([u0, u1, u1, u0]), np.array([v0, v0, v1, v1]))
        return P

    @property
    def plane(self):
        return self._plane

    def exact_area(self, box):
        if self._plane is None:
            return None
        c00, c10, c11, c01 = self.box_corners(box)
        return 0.5 * np.linalg.norm(np.cross(c11 - c00, c01 - c10))

    def validate_box(self, box):
        """Raise ValueError if the patch over `box` folds over itself or has no area.

        The normal dP/du x dP/dv of a bilinear patch is affine in (u, v) (the u v term of P
        cancels in the cross product), so it vanishes on a point or a line; the patch folds
        over itself (its normal changes side) exactly when that zero set meets the open box. A
        zero on the border is a collapsed edge (a triangle), which is allowed. Twisted quads
        whose corner normals differ by more than 90 degrees are valid when the zero set misses
        the box.
        """
        (u0, u1), (v0, v1) = box
        if self._plane is not None and self._valid_whole and 0 <= u0 < u1 <= 1 and 0 <= v0 < v1 <= 1:
            return  # (a part of a valid flat convex quad is one: no fold, some area)
        _, Pu, Pv = self.derivatives(np.array([u0, u1, u1, u0]), np.array([v0, v0, v1, v1]))
        normals = np.cross(Pu, Pv)
        largest = np.linalg.norm(normals, axis=1).max()
        if largest > 0.0 and _vanishes_inside(*(normals / largest)):
            raise ValueError(
                "degenerate quad: it folds over itself (corners out of order or non-convex), "
                "so its normal changes side"
            )
        scale = max(self.size, np.abs(self.corners).max() * 1e-300)
        if not np.linalg.norm(normals.sum(0)) > 1e-12 * scale * scale * (u1 - u0) * (v1 - v0):
            raise ValueError("degenerate quad: its corners are collinear or coincide, so it has no area")
        self._valid_whole = self._valid_whole or box == ((0.0, 1.0), (0.0, 1.0))


def _vanishes_inside(n00, n10, n11, n01, eps=1e-9):
    """Whether n(s, t) = n00 + s (n10 - n00) + t (n01 - n00) is zero somewhere in (0, 1)^2.

    Parameters
    ----------
    n00, n10, n11, n01 : ndarray, shape (3,)
        Corner values of an affine 3-vector field, scaled so that the largest has length 1
        (n11 = n10 + n01 - n00 for an affine field; it is not needed).
    eps : float
        Lengths below eps count as zero; parameters within eps of the border count as on it.

    Returns
    -------
    bool
    """
    A, B = n10 - n00, n01 - n00
    AA, AB, BB = A @ A, A @ B, B @ B
    det = AA * BB - AB * AB
    if det > 1e-12 * AA * BB:
        # rank 2: the least-squares point (normal equations, closed form) is the only candidate
        s = (AB * (B @ n00) - BB * (A @ n00)) / det
        t = (AB * (A @ n00) - AA * (B @ n00)) / det
        residual = np.linalg.norm(n00 + s * A + t * B)
        return bool(residual <= eps and eps < s < 1.0 - eps and eps < t < 1.0 - eps)
    # rank <= 1: n = n00 + lam e along one direction e, lam = alpha s + beta t
    e = A if AA >= BB else B
    ee = e @ e
    if not ee > 0.0:
        return False  # a constant normal (a parallelogram)
    alpha, beta = (A @ e) / ee, (B @ e) / ee
    lam = -(n00 @ e) / ee
    if np.linalg.norm(n00 + lam * e) > eps:
        return False
    values = (0.0, alpha, beta, alpha + beta)
    lo, hi = min(values), max(values)
    margin = eps * (hi - lo)
    return bool(lo + margin < lam < hi - margin)


class Quad(Surface):
    """Bilinear patch; u runs p00 -> p10, v runs p00 -> p01; front = side of (p10-p00) x (p01-p00).

    Flat when the four corners are coplanar (a convex quadrilateral), a true bilinear surface
    otherwise. A triangle is a quad with p01 = p00 (one collapsed edge).

    Parameters
    ----------
    p00, p10, p11, p01 : array_like, shape (3,)
        Corners (m), in order around the quad.

    Raises
    ------
    ValueError
        If a corner is not a finite 3-vector within `checks.MAX_COORDINATE`, the quad's size is
        beyond what float64 resolves at its position (`checks.resolvable`), it has no area, or
        it folds over itself (its normal vanishes inside; a saddle whose corner normals differ
        by more than 90 degrees is valid).
    """

    def __init__(self, p00, p10, p11, p01):
        corners = np.stack(
            [
                checks.point(p, name)
                for p, name in zip(
                    (p00, p10, p11, p01),
                    ("quad corner p00", "quad corner p10", "quad corner p11", "quad corner p01"),
                )
            ]
        )
        size = max(np.linalg.norm(corners[2] - corners[0]), np.linalg.norm(corners[3] - corners[1]))
        if size > 0.0:  # (all corners equal: the no-area check below says so)
            checks.resolvable(size, np.linalg.norm(corners, axis=1).max(), "quad size (its longer diagonal)")
        geometry = QuadGeometry(corners)
        self._init(geometry)
        geometry.validate_box(self._box)

    @property
    def corners(self):
        """Corners of this (sub-)patch, shape (4, 3): p00, p10, p11, p01."""
        return self.geometry.box_corners(self._box)


# --------------------------------------------------------------------------- disk
class DiskGeometry(AffineGeometry):
    """Flat disk p = (u cos v, u sin v, 0), u in [0, radius], mapped by an affine transform."""

    def __init__(self, linear, offset, radius):
        super().__init__(linear, offset)
        self.natural_domain = ((0.0, float(radius)), (0.0, TWO_PI))

    kind = DISK

    def exact_kind(self, box):
        return DISK if self.similarity_scale is not None else GENERIC

    def unit_box(self, box):
        # p = (u cos v, u sin v, 0) with u >= 0
        (u0, u1), (v0, v1) = box
        ranges = [_product_range((u0, u1), cos_range(v0, v1)), _product_range((u0, u1), sin_range(v0, v1))]
        return tuple(np.array(ranges + [(0.0, 0.0)]).T)

    @staticmethod
    def local_jet(u, v):
        sv, cv = np.sin(v), np.cos(v)
        jet = np.empty(np.shape(u) + (3, 3))
        jet[..., 0, 0] = u * cv
        jet[..., 0, 1] = u * sv
        jet[..., 1, 0] = cv
        jet[..., 1, 1] = sv
        jet[..., 2, 0] = -jet[..., 0, 1]
        jet[..., 2, 1] = jet[..., 0, 0]
        jet[..., :, 2] = 0.0
        return jet

    @property
    def plane(self):
        normal = np.cross(self.linear[:, 0], self.linear[:, 1])
        return self.offset, normal / np.linalg.norm(normal)

    def exact_area(self, box):
        s = self.similarity_scale
        if s is None:
            return None
        (u0, u1), (v0, v1) = box
        return s * s * 0.5 * (u1 - u0) * (u1 + u0) * (v1 - v0)


class Disk(Surface):
    """Flat disk: u = distance from the centre in [0, radius], v = angle in [0, 2 pi].

    The angle v is measured from the unit vector e1 perpendicular to the normal and to the
    coordinate axis least aligned with it (see `orthonormal_frame`). Front = the normal's side;
    an annulus is `Disk(...).subpatch(u=(r_inner, radius))`.

    Parameters
    ----------
    center : array_like, shape (3,)
    normal : array_like, shape (3,)
        Non-zero; its length is ignored.
    radius : float
        > 0 (m).

    Raises
    ------
    ValueError
        As for `Sphere`; a zero direction is refused, and any other length (1e-300 ... 1e300)
        is normalised without overflow.
    """

    def __init__(self, center, normal, radius):
        c = checks.point(center, "disk center")
        n = checks.direction(normal, "disk normal")
        r = checks.length(radius, "disk radius", np.linalg.norm(c))
        self._init(DiskGeometry(orthonormal_frame(n), c, r))

    @property
    def center(self):
        return self.geometry.offset


# --------------------------------------------------------------------------- cylinder
class CylinderGeometry(AffineGeometry):
    """Unit cylinder p = (cos u, sin u, v), v in [0, height], mapped by an affine transform."""

    def __init__(self, linear, offset, height):
        super().__init__(linear, offset)
        self.natural_domain = ((0.0, TWO_PI), (0.0, float(height)))

    kind = CYLINDER

    def exact_kind(self, box):
        return CYLINDER if self.exact_area(box) is not None else GENERIC

    def unit_box(self, box):
        # p = (cos u, sin u, v)
        (u0, u1), (v0, v1) = box
        return tuple(np.array([cos_range(u0, u1), sin_range(u0, u1), (v0, v1)]).T)

    @staticmethod
    def local_jet(u, v):
        su, cu = np.sin(u), np.cos(u)
        jet = np.zeros(np.shape(u) + (3, 3))
        jet[..., 0, 0] = cu
        jet[..., 0, 1] = su
        jet[..., 0, 2] = v
        jet[..., 1, 0] = -su
        jet[..., 1, 1] = cu
        jet[..., 2, 2] = 1.0
        return jet

    def exact_area(self, box):
        a, b, c = self.linear.T
        ra, rb = np.linalg.norm(a), np.linalg.norm(b)
        tol = 1e-12 * max(ra, rb, np.linalg.norm(c))
        circular = (
            abs(ra - rb) <= tol
            and abs(a @ b) <= tol * ra
            and abs(a @ c) <= tol * ra
            and abs(b @ c) <= tol * rb
        )
        if not circular:
            return None
        (u0, u1), (v0, v1) = box
        return ra * np.linalg.norm(c) * (u1 - u0) * (v1 - v0)

    @property
    def convex_outward(self):
        return True


class Cylinder(Surface):
    """Lateral surface of a cylinder: u = angle in [0, 2 pi], v = distance along the axis in [0, height].

    The angle u is measured from e1 as for `Disk`. Front = outside.

    Parameters
    ----------
    base_center : array_like, shape (3,)
    axis : array_like, shape (3,)
        Non-zero; its length is ignored.
    radius, height : float
        > 0 (m).

    Raises
    ------
    ValueError
        As for `Sphere`; a zero direction is refused, and any other length (1e-300 ... 1e300)
        is normalised without overflow.
    """

    def __init__(self, base_center, axis, radius, height):
        c = checks.point(base_center, "cylinder base_center")
        a = checks.direction(axis, "cylinder axis")
        position = np.linalg.norm(c)
        r = checks.length(radius, "cylinder radius", position)
        h = checks.length(height, "cylinder height", position)
        frame = orthonormal_frame(a)
        linear = np.column_stack([r * frame[:, 0], r * frame[:, 1], frame[:, 2]])
        self._init(CylinderGeometry(linear, c, h))
