"""Mesh polygons as bilinear quad pieces (numpy only).

A piece is four corner vertices (p00, p10, p11, p01) in the order of `core.Quad`: a quad polygon
is one piece, a triangle is a piece with p01 = p00, and an n-gon is fan-split from its first
corner into quads (0, i, i + 1, i + 2) and, for odd n, one last triangle (0, n - 2, n - 1).
Polygons whose fan pieces are unusable (concave or folded) fall back to Blender's own loop
triangles, see `triangle_pieces`.

Corner parameters: p00 -> (u, v) = (0, 0), p10 -> (1, 0), p11 -> (1, 1), p01 -> (0, 1).
"""

import numpy as np

CORNER_U = np.array([0.0, 1.0, 1.0, 0.0])
CORNER_V = np.array([0.0, 0.0, 1.0, 1.0])
# quads flatter than this (relative to their size) are snapped onto their best-fit plane
PLANAR_RTOL = 1e-6


def fan_pieces(loop_start, loop_total, corner_verts):
    """Split every polygon into quad/triangle pieces.

    Parameters
    ----------
    loop_start, loop_total : ndarray of int, shape (F,)
    corner_verts : ndarray of int, shape (L,)

    Returns
    -------
    vertex : ndarray of int64, shape (K, 4)
        Mesh vertex at p00, p10, p11, p01; triangles repeat p00 as p01.
    polygon : ndarray of int64, shape (K,)
    """
    loop_start = np.asarray(loop_start, np.int64)
    loop_total = np.asarray(loop_total, np.int64)
    count = np.maximum((loop_total - 1) // 2, 0)
    polygon = np.repeat(np.arange(len(loop_total)), count)
    # piece j of its polygon: local corners 0, 2j + 1, 2j + 2 and 2j + 3 (0 past the end)
    first = np.cumsum(count) - count
    j = np.arange(polygon.size) - np.repeat(first, count)
    n = loop_total[polygon]
    local = np.stack([np.zeros_like(j), 2 * j + 1, 2 * j + 2, 2 * j + 3], -1)
    local[:, 3] = np.where(local[:, 3] < n, local[:, 3], 0)
    vertex = np.asarray(corner_verts, np.int64)[loop_start[polygon, None] + local]
    return vertex, polygon


def polygon_normals(points, loop_start, loop_total, corner_verts):
    """Newell normals (twice the vector area) of all polygons, shape (F, 3).

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Vertex positions (any frame).
    """
    loop_start = np.asarray(loop_start, np.int64)
    loop_total = np.asarray(loop_total, np.int64)
    corner_verts = np.asarray(corner_verts, np.int64)
    polygon = np.repeat(np.arange(len(loop_total)), loop_total)
    local = np.arange(corner_verts.size) - loop_start[polygon]
    following = loop_start[polygon] + (local + 1) % loop_total[polygon]
    cross = np.cross(points[corner_verts], points[corner_verts[following]])
    normals = np.zeros((len(loop_total), 3))
    np.add.at(normals, polygon, cross)
    return normals


def folded(corners, polygon, normals):
    """Polygons whose fan pieces do not all face the polygon's own normal (concave n-gons).

    Parameters
    ----------
    corners : ndarray, shape (K, 4, 3)
    polygon : ndarray of int, shape (K,)
    normals : ndarray, shape (F, 3)
        From `polygon_normals`.

    Returns
    -------
    ndarray of int
        Sorted polygon indices.
    """
    piece = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    return np.unique(polygon[np.einsum("kj,kj->k", piece, normals[polygon]) <= 0.0])


def triangle_pieces(triangle_vertices, triangle_polygon, keep):
    """Pieces from Blender's loop triangles of the polygons in `keep`.

    Parameters
    ----------
    triangle_vertices : ndarray of int, shape (T, 3)
    triangle_polygon : ndarray of int, shape (T,)
    keep : ndarray of int
        Polygon indices to take.

    Returns
    -------
    vertex : ndarray of int64, shape (K, 4)
    polygon : ndarray of int64, shape (K,)
    """
    mask = np.isin(triangle_polygon, keep)
    tri = np.asarray(triangle_vertices, np.int64)[mask]
    return np.column_stack([tri, tri[:, 0]]), np.asarray(triangle_polygon, np.int64)[mask]


def is_triangle(vertex):
    """True for pieces whose p01 repeats p00, shape (K,)."""
    return vertex[:, 3] == vertex[:, 0]


def snap_planar(corners, rtol=PLANAR_RTOL):
    """Project nearly planar quads onto their best-fit plane; keep others bilinear.

    The plane goes through the corners' mean with the normal of the cross product of the
    diagonals (the direction of the quad's mean normal). A quad is snapped when its corners lie
    within rtol * (longest diagonal) of that plane, which absorbs float32 noise.

    Parameters
    ----------
    corners : ndarray, shape (K, 4, 3)

    Returns
    -------
    ndarray, shape (K, 4, 3)
    """
    corners = np.array(corners, dtype=np.float64)
    centre = corners.mean(1, keepdims=True)
    normal = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    unit = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0.0)
    height = np.einsum("kcj,kj->kc", corners - centre, unit)
    diagonals = np.stack([corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1]], 1)
    size = np.linalg.norm(diagonals, axis=2).max(1)
    snap = (np.abs(height).max(1) <= rtol * size) & (length[:, 0] > 0.0)
    corners[snap] -= height[snap, :, None] * unit[snap, None, :]
    return corners


def vertex_average(values, vertex, n_vertices):
    """Average per-corner samples onto mesh vertices.

    Parameters
    ----------
    values : ndarray, shape (K, C)
        One sample per (piece corner) entry.
    vertex : ndarray of int, shape (K,)
        Mesh vertex of each sample.
    n_vertices : int

    Returns
    -------
    mean : ndarray, shape (n_vertices, C)
        Zero where a vertex has no sample.
    count : ndarray of int, shape (n_vertices,)
    """
    total = np.zeros((n_vertices, values.shape[1]))
    np.add.at(total, vertex, values)
    count = np.bincount(vertex, minlength=n_vertices)
    return total / np.maximum(count, 1)[:, None], count
