"""Recognise the vertex layout of Blender's UV sphere primitive in a mesh (numpy only).

Blender's `bpy.ops.mesh.primitive_uv_sphere_add` (bmesh `bmo_create_uvsphere_exec`,
source/blender/bmesh/operators/bmo_primitive.cc) builds a half-circle profile of rings + 1 points
at polar angles theta_r = pi r / rings in the +Y half of the YZ plane, extrudes it `segments`
times while rotating by -2 pi / segments about +Z, and welds the poles and the closing seam. So
with S = segments and R = rings (ring_count):

- N = S (R - 1) + 2 vertices: two poles at +-Z and, for r = 1 .. R - 1 and s = 0 .. S - 1, the
  point at polar angle theta_r = pi r / R and azimuth phi_s = pi / 2 - 2 pi s / S (radius 1);
- F = S R faces: 2 S pole triangles and S (R - 2) quads.

The vertex *order* is left to the weld (`remove_doubles`) and is not a fixed formula (for S = R = 3
the poles are vertices 1 and 2, for most sizes they are 0 and R), and geometry nodes' UV sphere
numbers its vertices differently again. So recognition here never trusts the order: it finds S, R
from the counts, the poles and two neighbouring ring-1 vertices from the pole triangles (a first
affine frame), every vertex's (ring, segment) from its position in that frame, requires that to
be a bijection onto the layout, and accepts only if one least-squares affine map takes the exact
layout onto all vertices to within a tight tolerance. The result gives each vertex its core
`Sphere` parameters (u = polar angle, v = azimuth) under that map.
"""

from dataclasses import dataclass

import numpy as np

# float32 rounding of Blender's coordinates, relative to their magnitude
FLOAT32_NOISE = 8.0 * np.finfo(np.float32).eps
# Blender rotates each extruded segment by the same float32 matrix, so segment s carries s times
# its rounding: measured drift ~1.5e-8 per segment (7.6e-6 at 500 segments, bpy 5.0.1)
PER_SEGMENT_DRIFT = 3e-8
# a sphere's map whose axes agree to this (relative) is a similarity: float32 coordinates and
# object matrices leave ~1e-7 in them, which would make every UV sphere an ellipsoid to the core
ROUND_AXES = 1e-5


@dataclass(frozen=True)
class SphereLayout:
    """A recognised UV sphere.

    Attributes
    ----------
    segments, rings : int
    local_from_unit : ndarray, shape (4, 4)
        Affine map taking the unit sphere (core.Sphere((0, 0, 0), 1)) onto the mesh vertices.
    u, v : ndarray, shape (N,)
        Parameters of each mesh vertex on that sphere: polar angle in [0, pi] and azimuth in
        [0, 2 pi); the poles get v = 0.
    residual : float
        Largest distance between a vertex and the mapped layout point, relative to the largest
        semi-axis.
    """

    segments: int
    rings: int
    local_from_unit: np.ndarray
    u: np.ndarray
    v: np.ndarray
    residual: float


def shape_from_counts(n_vertices, n_faces):
    """(segments, rings) if N = S (R - 1) + 2 and F = S R with S, R >= 3, else None."""
    segments = n_faces - (n_vertices - 2)
    if segments < 3 or n_faces % segments:
        return None
    rings = n_faces // segments
    if rings < 3 or segments * (rings - 1) + 2 != n_vertices:
        return None
    return segments, rings


def unit_layout(u, v):
    """Points of the unit sphere at polar angle u and azimuth v, shape u.shape + (3,)."""
    return np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], -1)


def recognise(positions, loop_total, corner_verts, rtol=1e-5):
    """The UV sphere layout of a mesh, or None.

    Parameters
    ----------
    positions : ndarray, shape (N, 3)
        Vertex positions (any frame; float32 data converted to float64 is fine).
    loop_total : ndarray of int, shape (F,)
        Corner count of each polygon.
    corner_verts : ndarray of int, shape (sum(loop_total),)
        Vertex of each polygon corner, polygon after polygon.
    rtol : float
        Accepted distance between a vertex and its layout point, relative to the largest
        semi-axis (plus float32 rounding and Blender's per-segment rotation drift).

    Returns
    -------
    SphereLayout or None
    """
    x = np.asarray(positions, dtype=np.float64)
    loop_total = np.asarray(loop_total)
    corner_verts = np.asarray(corner_verts)
    shape = shape_from_counts(len(x), len(loop_total))
    if shape is None or not np.all(np.isfinite(x)):
        return None
    S, R = shape
    triangles = _triangles(loop_total, corner_verts, S, R)
    if triangles is None:
        return None
    frame = _pole_frame(x, triangles, S, R)
    if frame is None:
        return None
    ring, segment = _rings_and_segments(x, frame, S, R)
    if ring is None:
        return None
    # exact layout points, then one affine fit onto all vertices
    u = np.pi * ring / R
    v = 2.0 * np.pi * segment / S
    X = unit_layout(u, v)
    design = np.column_stack([X, np.ones(len(X))])
    coef, *_ = np.linalg.lstsq(design, x, rcond=None)
    A, b = coef[:3].T, coef[3]
    sing = np.linalg.svd(A, compute_uv=False)
    if not sing[-1] > 1e-6 * sing[0]:
        return None
    residual = np.linalg.norm(design @ coef - x, axis=1).max()
    allowed = (rtol + PER_SEGMENT_DRIFT * S) * sing[0] + FLOAT32_NOISE * np.abs(x).max()
    if not residual <= allowed:
        return None
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = A, b
    return SphereLayout(S, R, matrix, u, v, float(residual / sing[0]))


def _triangles(loop_total, corner_verts, S, R):
    """The mesh's triangles, shape (2 S, 3), if it has the layout's 2 S triangles and S (R - 2) quads."""
    if np.count_nonzero(loop_total == 3) != 2 * S or np.count_nonzero(loop_total == 4) != S * (R - 2):
        return None
    return corner_verts[np.repeat(loop_total == 3, loop_total)].reshape(-1, 3)


def _pole_frame(x, triangles, S, R):
    """A first guess (A, c) of the affine map, from the poles and two ring-1 vertices.

    The poles are the two vertices in S triangles each (other vertices lie in at most 2). With
    centre c = (north + south) / 2 and a3 = north - c, a ring-1 vertex is
    c + cos(t) a3 + sin(t) (cos(phi) a1 + sin(phi) a2), t = pi / R. Taking one ring-1 vertex as
    phi = 0 and a neighbour in a pole triangle as phi = 2 pi / S gives a1 and a2.
    """
    count = np.bincount(triangles.ravel(), minlength=len(x))
    poles = np.flatnonzero(count == S)
    if poles.size != 2:
        return None
    north, south = poles
    fan = triangles[np.any(triangles == north, axis=1)]
    first = fan[0][fan[0] != north][0]
    neighbours = np.unique(fan[np.any(fan == first, axis=1)])
    second = neighbours[(neighbours != north) & (neighbours != first)][0]
    c = 0.5 * (x[north] + x[south])
    a3 = x[north] - c
    t, step = np.pi / R, 2.0 * np.pi / S
    a1 = (x[first] - c - np.cos(t) * a3) / np.sin(t)
    a2 = ((x[second] - c - np.cos(t) * a3) / np.sin(t) - np.cos(step) * a1) / np.sin(step)
    A = np.column_stack([a1, a2, a3])
    if not abs(np.linalg.det(A)) > 1e-9 * np.linalg.norm(A) ** 3:
        return None
    return A, c, (int(north), int(south))


def _rings_and_segments(x, frame, S, R):
    """(ring, segment) of every vertex under the first-guess frame, or (None, None).

    Each non-pole vertex must round to a distinct (ring, segment) with 1 <= ring <= R - 1.
    """
    A, c, (north, south) = frame
    p = np.linalg.solve(A, (x - c).T).T
    theta = np.arctan2(np.hypot(p[:, 0], p[:, 1]), p[:, 2])
    phi = np.mod(np.arctan2(p[:, 1], p[:, 0]), 2.0 * np.pi)
    ring = np.rint(theta * R / np.pi).astype(np.int64)
    segment = np.mod(np.rint(phi * S / (2.0 * np.pi)).astype(np.int64), S)
    ring[north], ring[south] = 0, R
    segment[[north, south]] = 0
    others = np.ones(len(x), bool)
    others[[north, south]] = False
    inner = ring[others]
    if inner.min() < 1 or inner.max() > R - 1:
        return None, None
    if np.unique(inner * S + segment[others]).size != len(x) - 2:
        return None, None
    return ring, segment


def nearest_similarity(affine, rtol=ROUND_AXES):
    """`affine` (4, 4) with its linear part made the nearest similarity when its singular values
    agree to `rtol` (relative), else unchanged.

    The nearest orthogonal map to L = U S V^T is U V^T (the polar decomposition); it is scaled by
    the mean singular value. A UV sphere read from float32 vertices and matrices is a sphere to
    about 1e-7, and the core takes only an exact similarity of its unit sphere as a sphere (exact
    sphere kernels, closed-form shadows); anything less is an ellipsoid, integrated generically.
    """
    linear = np.asarray(affine, dtype=np.float64)[:3, :3]
    U, s, Vt = np.linalg.svd(linear)
    if s[0] - s[2] > rtol * s[0]:
        return affine
    out = np.array(affine, dtype=np.float64)
    out[:3, :3] = s.mean() * (U @ Vt)
    return out
