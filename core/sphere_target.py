"""A whole sphere as an exact shadow target: the flat disk spanning its silhouette.

Seen from a point x outside a sphere (centre c, radius r, d = |x - c|), the tangent cone from x
touches the sphere along a circle in the plane at r^2 / d from c toward x, of radius
r sqrt(1 - r^2 / d^2). A segment from x to a point y of the disk that circle bounds first crosses
the cap x sees, then runs inside the sphere. So an occluder that does not reach inside the sphere
blocks the segment x y exactly when it blocks the segment from x to the cap point on it, and

    F_vis(x -> the sphere's outside) = F_vis(x -> silhouette disk)

(a point factor depends only on the set of directions it covers: F = (1/pi) int cos(theta_x)
d omega). The disk is an annular sector of the shadow kernel (`shadow.SectorTargets`), so the
sphere's shadows past spheres, polygons, disks and cylinders are exact wherever those are.

Occluders that reach inside the sphere (a floor it sinks into) break the argument: the segment
to the disk may meet them inside the sphere. Lower bounds of the distance from a point to each
occluder kind (below; `occluded.SHAPES` names them per kind) find those, conservatively.
"""

import numpy as np

from .shadow import SectorTargets

INSIDE = 1e-9  # an occluder reaches inside a sphere when nearer its centre than (1 - INSIDE) r


def round_sphere(surface):
    """(center (3,), radius) of a whole round sphere whose front is its outside, else None."""
    geometry = surface.geometry
    if not geometry.whole_ellipsoid(surface.domain):
        return None
    sizes = np.linalg.svd(geometry.linear, compute_uv=False)
    if sizes.max() - sizes.min() > 1e-12 * sizes.max():
        return None
    center = np.asarray(geometry.offset, dtype=np.float64)
    (u0, u1), (v0, v1) = surface.domain
    grid = np.linspace(0.25, 0.75, 3)
    points, normals = surface.evaluate(u0 + (u1 - u0) * grid[:, None], v0 + (v1 - v0) * grid[None, :])
    if np.einsum("abi,abi->", points - center, normals) <= 0.0:
        return None  # its inside
    return center, float(sizes.max())


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
