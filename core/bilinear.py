"""Twisted (bilinear) quad occluders: their exact shadow seen from points that see no fold.

A quad patch is bilinear, P(u, v) = p00 + u a + v b + u v c with a = p10 - p00, b = p01 - p00 and
c = p11 - p10 - p01 + p00. Its normal P_u x P_v = (a + v c) x (b + u c) is linear in (u, v),

    n(u, v) = a x b + u (a x c) + v (c x b),

and for a point x the function g(u, v) = n(u, v) . (x - P(u, v)), whose sign says which side of
the tangent plane at P(u, v) the point lies on, is bilinear: expanding, every term of degree
two vanishes ((a x b) . a = (a x c) . a = (a x c) . c = (c x b) . b = (c x b) . c = 0) and the
three uv terms add up to det(a, b, c) uv. A bilinear function takes its extremes at the corners,
so **a point whose four corner values of g share one strict sign sees no fold** (no silhouette
inside the patch): the patch seen from x is then an immersed disk of constant orientation whose
boundary, four straight edges, projects to a quadrilateral; the winding number argument makes
that quadrilateral simple and the patch cover its inside exactly once. Split along the diagonal
that lies inside that quadrilateral (the one whose plane through x separates the other two
corners), the quad's two triangles cover the same directions from x. Both the patch and the
triangles lie in the tetrahedron of the four corners (a bilinear point is a convex combination
of them), so a segment from x to a point y outside that tetrahedron crosses the patch if and
only if it crosses the triangles: for such segments **the two triangles are the patch's exact
shadow** (`shadow.visible_factor` then integrates it like any polygon's).

A point that sees a fold (the patch's silhouette, whose shadow boundary is a conic: the trace
of the tangent cone from x to the hyperbolic paraboloid the patch lies on) or lies inside the
tetrahedron has no exact shadow here yet: `point_triangles` reports it and callers refuse the
query by name. (Splitting the patch until its pieces show no fold was tried: the pieces crossed by
the fold curve leave an error that falls only like 2^-depth, 22 triangles a point at depth 2
still left 10 % of the factor, and the outer integral then ran to its budget.)
"""

import numpy as np

from .kinds import POLYGON
from .primitives import QuadGeometry

SIGN_SLACK = 1e-12  # corner values of g within this of their largest count as zero (a fold)


def bilinear_corners(surface):
    """Corners p00, p10, p11, p01 (4, 3) of a twisted (not flat) quad patch, else None."""
    geometry = surface.geometry
    if not isinstance(geometry, QuadGeometry) or geometry.exact_kind(surface.domain) == POLYGON:
        return None
    return np.asarray(geometry.box_corners(surface.domain), dtype=np.float64)


def corner_normals(corners):
    """The bilinear normal P_u x P_v at p00, p10, p11, p01 of quads (R, 4, 3), shape (R, 4, 3):
    a x b, a x (b + c), (a + c) x (b + c), (a + c) x b."""
    p00, p10, p11, p01 = (corners[:, k] for k in range(4))
    a, b = p10 - p00, p01 - p00
    c = p11 - p10 - b
    return np.stack([np.cross(a, b), np.cross(a, b + c), np.cross(a + c, b + c), np.cross(a + c, b)], 1)


def fold_free(x, corners):
    """Whether points x (R, 3) see quads (R, 4, 3) without a fold, from outside their corners'
    tetrahedron, shape (R,): the quad's two `triangle_pairs` are then its exact shadow."""
    g = np.einsum("rci,rci->rc", corner_normals(corners), x[:, None] - corners)
    slack = SIGN_SLACK * np.abs(g).max(-1, keepdims=True)
    same = np.all(g > slack, -1) | np.all(g < -slack, -1)
    return same & ~inside_tetrahedron(x, corners)


def plane_side(corners, point, normal):
    """Which side of planes (point, normal, each (C, 3)) the tetrahedra of quads' corners (C, 4, 3)
    lie on, shape (C,) int: +1 strictly in front, -1 strictly behind, 0 where the plane meets them."""
    height = np.einsum("cki,ci->ck", corners - point[:, None], normal)
    return np.where(np.all(height > 0.0, 1), 1, np.where(np.all(height < 0.0, 1), -1, 0))


def _orient(p, q, r, s):
    """det(q - p, r - p, s - p) row by row."""
    return np.einsum("...i,...i->...", np.cross(q - p, r - p), s - p)


def inside_tetrahedron(x, corners):
    """Points x (R, 3) in or on the tetrahedron of quads' corners (R, 4, 3), shape (R,) bool
    (a flat quad's tetrahedron is flat: the points of its plane count)."""
    c = [corners[:, k] for k in range(4)]
    inside = np.ones(len(x), dtype=bool)
    for i, j, k, opposite in ((1, 2, 3, 0), (0, 3, 2, 1), (0, 1, 3, 2), (0, 2, 1, 3)):
        # on the side of face (i, j, k) where the fourth corner is, or on the face
        here, side = _orient(c[i], c[j], c[k], x), _orient(c[i], c[j], c[k], c[opposite])
        inside &= np.where(side != 0.0, here * np.sign(side) >= 0.0, here == 0.0)
    return inside


def triangle_pairs(x, corners):
    """Each quad's two triangles along the diagonal inside it as seen from its point.

    Parameters
    ----------
    x : ndarray, shape (R, 3)
    corners : ndarray, shape (R, 4, 3)

    Returns
    -------
    triangles : ndarray, shape (R, 2, 4, 3)
        Vertices, the first repeated last (`shadow.Blockers` polygons of four vertices).
    edges : ndarray of bool, shape (R, 2, 4)
        The edges that may bound the shadow: not the shared diagonal, nor the null last edge.
    """
    p00, p10, p11, p01 = (corners[:, k] for k in range(4))
    # the diagonal p00 - p11 lies inside when the plane through x and it separates p10 from p01
    inner = (_orient(x, p00, p11, p10) * _orient(x, p00, p11, p01) < 0.0)[:, None, None]
    first = np.where(inner, np.stack([p00, p10, p11, p00], 1), np.stack([p10, p11, p01, p10], 1))
    second = np.where(inner, np.stack([p00, p11, p01, p00], 1), np.stack([p10, p01, p00, p10], 1))
    edges = np.zeros((len(x), 2, 4), dtype=bool)
    edges[:, 0, :2] = True  # (the first's edge 2 and the second's edge 0 are the diagonal)
    edges[:, 1, 1:3] = True
    return np.stack([first, second], 1), edges


def point_triangles(x, quads):
    """Triangles that block exactly what twisted quads block, seen from each point.

    Parameters
    ----------
    x : ndarray, shape (K, 3)
    quads : ndarray, shape (B, 4, 3)
        The twisted quads' corners (p00, p10, p11, p01).

    Returns
    -------
    polygons : ndarray, shape (K, 2 B, 4, 3)
        Two triangles a quad (`triangle_pairs`), first vertex repeated.
    edges : ndarray of bool, shape (K, 2 B, 4)
        `shadow.Blockers.polygon_edges`.
    folded : ndarray of bool, shape (K,)
        Points that see a fold of some quad, or lie in its corners' tetrahedron: their
        triangles are not its shadow.
    """
    K, B = len(x), len(quads)
    point = np.repeat(np.arange(K), B)
    piece = np.tile(quads, (K, 1, 1))
    folded = np.bincount(point, ~fold_free(x[point], piece), minlength=K) > 0
    triangles, edges = triangle_pairs(x[point], piece)
    return triangles.reshape(K, 2 * B, 4, 3), edges.reshape(K, 2 * B, 4), folded
