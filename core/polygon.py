"""Exact form factor from a differential area to a flat polygon, clipped at its tangent plane.

Lambert's contour integral: for a polygon wholly in front of the element dA1 (normal n1),

    F(dA1 -> P) = 1/(2 pi) * sum over edges (a -> b) of  angle(ra, rb) * n1 . (ra x rb) / |ra x rb|

with ra = a - x1, rb = b - x1 (Sparrow 1963; Siegel & Howell, "Thermal Radiation Heat Transfer",
contour integration of configuration factors; Baum, Rushmeier & Winget 1989 use it for radiosity).
Where the element's tangent plane cuts the polygon, only the part in front counts: the polygon is
clipped to it (for a convex polygon, one exit and one entry point joined by a chord).
"""

import numpy as np

from .bounds import lengths


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
    ra = a - x1
    rb = b - x1
    c = np.cross(ra, rb)
    sine = lengths(c)
    cosine = np.einsum("kei,kei->ke", ra, rb)
    angle = np.arctan2(sine, cosine)
    scale = lengths(ra) * lengths(rb)
    ok = sine > 1e-300 + 1e-15 * scale
    projected = np.einsum("kei,kei->ke", c, np.broadcast_to(n1, c.shape))
    return np.where(ok, angle * np.divide(projected, sine, out=np.zeros_like(sine), where=ok), 0.0)


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
    # only points in front of the polygon's plane see its front side
    offset = np.einsum("ki,ki->k", x1 - vertices[:, 0], front)
    size = lengths(vertices - vertices[:, :1]).max(-1)
    scale = size + lengths(x1 - vertices[:, 0])
    in_front = offset > 1e-12 * scale

    # heights of the vertices over the point's tangent plane
    h = np.einsum("kvi,ki->kv", vertices - x1[:, None], n1)
    a, b = vertices, np.roll(vertices, -1, axis=1)
    ha, hb = h, np.roll(h, -1, axis=1)
    inside_a, inside_b = ha >= 0.0, hb >= 0.0
    crossing = inside_a != inside_b
    t = np.divide(ha, ha - hb, out=np.zeros_like(ha), where=crossing)
    cut = a + t[..., None] * (b - a)
    # clip each edge to the front half-space: keep, drop, or shorten at the cut point
    start = np.where((inside_a | ~crossing)[..., None], a, cut)
    end = np.where((inside_b | ~crossing)[..., None], b, cut)
    kept = inside_a | inside_b
    terms = np.where(kept, edge_terms(x1[:, None], n1[:, None], start, end), 0.0)
    total = terms.sum(-1)

    # the chord along the horizon closes the clipped polygon: from the exit cut to the entry cut
    exits = crossing & inside_a
    entries = crossing & inside_b
    has_chord = exits.any(-1) & entries.any(-1)
    rows = np.arange(K)
    exit_point = cut[rows, np.argmax(exits, -1)]
    entry_point = cut[rows, np.argmax(entries, -1)]
    chord = edge_terms(x1[:, None], n1[:, None], exit_point[:, None], entry_point[:, None])[:, 0]
    total += np.where(has_chord, chord, 0.0)

    # orientation: vertices run counter-clockwise about `front`, seen from the front side
    F = np.where(in_front & kept.any(-1), -total / (2.0 * np.pi), 0.0)
    return np.maximum(F, 0.0), K * (V + 1)
