"""Exact form factor from a differential area to a flat polygon, clipped at its tangent plane.

Lambert's contour integral: for a polygon wholly in front of the element dA1 (normal n1),

    F(dA1 -> P) = 1/(2 pi) * sum over edges (a -> b) of  angle(ra, rb) * n1 . (ra x rb) / |ra x rb|

with ra = a - x1, rb = b - x1 (Sparrow 1963; Siegel & Howell, "Thermal Radiation Heat Transfer",
contour integration of configuration factors; Baum, Rushmeier & Winget 1989 use it for radiosity).
Where the element's tangent plane cuts the polygon, only the part in front counts: the polygon is
clipped to it (for a convex polygon, one exit and one entry point joined by a chord).
"""

import numpy as np


def _terms(a, b, n):
    """angle(a, b) * n . (a x b) / |a x b| from components; zero for degenerate edges.

    a, b, n : tuples of three broadcastable ndarrays (x, y, z components)."""
    ax, ay, az = a
    bx, by, bz = b
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    sine = np.sqrt(cx * cx + cy * cy + cz * cz)
    cosine = ax * bx + ay * by + az * bz
    scale = np.sqrt((ax * ax + ay * ay + az * az) * (bx * bx + by * by + bz * bz))
    ok = sine > 1e-300 + 1e-15 * scale
    projected = cx * n[0] + cy * n[1] + cz * n[2]
    return np.where(ok, np.arctan2(sine, cosine) * projected / np.where(ok, sine, 1.0), 0.0)


def _components(v):
    return v[..., 0], v[..., 1], v[..., 2]


def edge_terms(x1, n1, a, b):
    """angle(ra, rb) * n1 . (ra x rb) / |ra x rb| for edges a -> b; zero for degenerate edges.

    Parameters
    ----------
    x1, n1 : ndarray, shape (K, 1, 3)
        Points and unit normals.
    a, b : ndarray, shape (K, E, 3)
        Edge end points.

    Returns
    -------
    ndarray, shape (K, E)
    """
    return _terms(_components(a - x1), _components(b - x1), _components(n1))


def point_to_polygon(x1, n1, vertices, front):
    """Form factor F(dA1 -> convex polygon), counting only the polygon's part above dA1's horizon.

    Parameters
    ----------
    x1 : ndarray, shape (K, 3)
        Points (m).
    n1 : ndarray, shape (K, 3)
        Unit normals at the points.
    vertices : ndarray, shape (K, V, 3)
        Convex polygon of each point, vertices in order; its front normal is `front`.
    front : ndarray, shape (K, 3)
        Unit front normal of each polygon (the side that emits and receives).

    Returns
    -------
    F : ndarray, shape (K,)
        Zero where the point is not strictly in front of the polygon's plane (coplanar pairs give
        exactly zero).
    evaluations : int
        Number of edge terms computed (K * (V + 1)).
    """
    K, V, _ = vertices.shape
    rel = vertices - x1[:, None]  # (vertices seen from the point)
    n = tuple(n1[:, k, None] for k in range(3))
    # only points in front of the polygon's plane see its front side
    offset = -np.einsum("ki,ki->k", rel[:, 0], front)
    spread = vertices - vertices[:, :1]
    size = np.sqrt(np.einsum("kvi,kvi->kv", spread, spread).max(-1))
    scale = size + np.sqrt(np.einsum("ki,ki->k", rel[:, 0], rel[:, 0]))
    in_front = offset > 1e-12 * scale

    # heights of the vertices over the point's tangent plane
    h = rel[..., 0] * n[0] + rel[..., 1] * n[1] + rel[..., 2] * n[2]
    inside = h >= 0.0
    whole = inside.all(-1)
    total = np.zeros(K)

    # polygons wholly above the horizon: the plain contour
    rows = np.flatnonzero(whole & in_front)
    if rows.size:
        a = rel[rows]
        b = np.roll(a, -1, axis=1)
        nr = tuple(c[rows] for c in n)
        total[rows] = _terms(_components(a), _components(b), nr).sum(-1)

    # polygons cut by the horizon: clip each edge to the front half-space (keep, drop, or
    # shorten at the cut point), then close the clipped polygon with the chord along the horizon
    rows = np.flatnonzero(~whole & inside.any(-1) & in_front)
    if rows.size:
        a = rel[rows]
        b = np.roll(a, -1, axis=1)
        ha = h[rows]
        hb = np.roll(ha, -1, axis=1)
        inside_a, inside_b = ha >= 0.0, hb >= 0.0
        crossing = inside_a != inside_b
        t = np.divide(ha, ha - hb, out=np.zeros_like(ha), where=crossing)
        cut = a + t[..., None] * (b - a)
        start = np.where((inside_a | ~crossing)[..., None], a, cut)
        end = np.where((inside_b | ~crossing)[..., None], b, cut)
        nr = tuple(c[rows] for c in n)
        terms = _terms(_components(start), _components(end), nr)
        clipped = np.where(inside_a | inside_b, terms, 0.0).sum(-1)
        # the chord runs from the exit cut to the entry cut
        exits = crossing & inside_a
        entries = crossing & inside_b
        has_chord = exits.any(-1) & entries.any(-1)
        r = np.arange(rows.size)
        exit_point = cut[r, np.argmax(exits, -1)]
        entry_point = cut[r, np.argmax(entries, -1)]
        chord = _terms(_components(exit_point), _components(entry_point), tuple(c[:, 0] for c in nr))
        total[rows] = clipped + np.where(has_chord, chord, 0.0)

    # orientation: vertices run counter-clockwise about `front`, seen from the front side
    return np.maximum(-total / (2.0 * np.pi), 0.0), K * (V + 1)
