"""Lightmap texels of a triangle mesh's UV map: which triangle and where (numpy only).

A texel (x, y) of a W x H image has its centre at UV ((x + 0.5) / W, (y + 0.5) / H); row y = 0 is
the bottom of the image, as in Blender's `Image.pixels`. `rasterise` finds, for every texel, the
UV triangle it belongs to and the barycentric coordinates of its sample point:

- a texel whose centre lies inside a triangle samples at its centre;
- a texel whose centre lies outside every triangle but whose square still touches one (within
  half a diagonal, `EDGE_REACH` texels, of it) samples at the nearest point of the nearest
  triangle. These texels straddle a UV seam or a chart's border; bilinear filtering reads them,
  so they must carry the surface's own value (conservative rasterisation), not the background.

`dilate` then spreads the covered texels outwards by a few texels (the gutter), so that mipmaps
and filtering near chart borders never mix in an empty texel.
"""

import numpy as np

# half the diagonal of a texel: the farthest a touched texel's centre can lie from a triangle
EDGE_REACH = 0.5 * np.sqrt(2.0)
# candidate texels examined per chunk of triangles (bounds the memory of a rasterisation)
CHUNK_TEXELS = 1 << 22


def rasterise(uv, width, height):
    """Texels covered by (or touching) UV triangles.

    Parameters
    ----------
    uv : ndarray, shape (T, 3, 2)
        UV coordinates of each triangle's corners (the image spans [0, 1] x [0, 1]).
    width, height : int
        Image size in texels.

    Returns
    -------
    texel : ndarray of int64, shape (K,)
        Flat texel index y * width + x, each texel at most once.
    triangle : ndarray of int64, shape (K,)
        The triangle each texel samples.
    bary : ndarray, shape (K, 3)
        Barycentric coordinates of the sample point in that triangle (each >= 0, sum 1).
    inside : ndarray of bool, shape (K,)
        True if the texel's centre lies inside the triangle (False: an edge texel).

    Raises
    ------
    ValueError
        If `uv` is not of shape (T, 3, 2) or not finite, or the size is not positive.
    """
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 3 or uv.shape[1:] != (3, 2):
        raise ValueError(f"uv must have shape (T, 3, 2), got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise ValueError("uv coordinates must be finite")
    if int(width) < 1 or int(height) < 1:
        raise ValueError(f"image size must be positive, got {width} x {height}")
    width, height = int(width), int(height)
    # corners in texel units (texel centres at integers + 0.5); drop triangles of zero UV area
    q = uv * np.array([width, height], dtype=np.float64)
    area2 = _cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    keep = np.flatnonzero(np.abs(area2) > 1e-12)
    # each triangle's box of candidate texels, grown by the reach of edge texels
    low = np.floor(q[keep].min(1) - 0.5 - EDGE_REACH).astype(np.int64)
    high = np.ceil(q[keep].max(1) - 0.5 + EDGE_REACH).astype(np.int64)
    size = np.array([width, height])
    low = np.clip(low, 0, size - 1)
    high = np.clip(high, 0, size - 1)
    box = np.maximum(high - low + 1, 0)
    count = box[:, 0] * box[:, 1]
    count[(high < low).any(1)] = 0
    # chunks of triangles whose boxes hold at most CHUNK_TEXELS candidates (one at least)
    ends = np.cumsum(count)
    parts = []
    start = 0
    while start < keep.size:
        stop = max(int(np.searchsorted(ends, ends[start] - count[start] + CHUNK_TEXELS, "right")), start + 1)
        parts.append(_candidates(q, keep[start:stop], low[start:stop], box[start:stop], count[start:stop]))
        start = stop
    if not parts:
        empty = np.zeros(0, np.int64)
        return empty, empty, np.zeros((0, 3)), np.zeros(0, bool)
    texel, triangle, bary, distance = (np.concatenate(p) for p in zip(*parts))
    texel = texel[:, 1] * width + texel[:, 0]
    # one sample per texel: the nearest triangle (a centre inside one has distance 0)
    order = np.lexsort((distance, texel))
    texel, triangle, bary, distance = texel[order], triangle[order], bary[order], distance[order]
    first = np.ones(texel.size, bool)
    first[1:] = texel[1:] != texel[:-1]
    return texel[first], triangle[first], bary[first], distance[first] == 0.0


def _candidates(q, triangles, low, box, count):
    """The texels of the boxes of `triangles` within EDGE_REACH of them.

    Returns (texel xy (K, 2), triangle (K,), bary (K, 3), distance in texels (K,))."""
    owner = np.repeat(np.arange(triangles.size), count)
    local = np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count)
    xy = low[owner] + np.stack([local % box[owner, 0], local // box[owner, 0]], -1)
    p = xy + 0.5
    a, b, c = (q[triangles[owner], k] for k in range(3))
    area2 = _cross(b - a, c - a)
    # barycentric coordinates of the texel centres
    lb = _cross(p - a, c - a) / area2
    lc = _cross(b - a, p - a) / area2
    bary = np.stack([1.0 - lb - lc, lb, lc], -1)
    inside = np.all(bary >= 0.0, axis=1)
    # outside: the nearest point on the three edges (as barycentric coordinates)
    distance = np.zeros(owner.size)
    out = np.flatnonzero(~inside)
    if out.size:
        corners = (a[out], b[out], c[out])
        best = np.full(out.size, np.inf)
        nearest = np.zeros((out.size, 3))
        for k in range(3):  # the three edges (k, k + 1)
            s, e = corners[k], corners[(k + 1) % 3]
            d = e - s
            t = np.clip(np.einsum("ij,ij->i", p[out] - s, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
            gap = np.linalg.norm(p[out] - (s + t[:, None] * d), axis=1)
            better = gap < best
            best = np.where(better, gap, best)
            edge = np.zeros((out.size, 3))
            edge[:, k], edge[:, (k + 1) % 3] = 1.0 - t, t
            nearest[better] = edge[better]
        distance[out] = best
        bary[out] = nearest
    close = distance <= EDGE_REACH
    return xy[close], triangles[owner[close]], bary[close], distance[close]


def _cross(a, b):
    """z of the 2-D cross product, shape (...,)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def dilate(values, covered, passes=4):
    """Fill empty texels next to covered ones with the mean of their covered 8-neighbours.

    Parameters
    ----------
    values : ndarray, shape (H, W, C)
    covered : ndarray of bool, shape (H, W)
    passes : int
        Rings of texels added around the covered ones.

    Returns
    -------
    values : ndarray, shape (H, W, C)
        A copy; texels left empty keep their input value.
    covered : ndarray of bool, shape (H, W)
        Covered after dilation.
    """
    values = np.array(values, dtype=np.float64)
    covered = np.array(covered, dtype=bool)
    H, W = covered.shape
    for _ in range(passes):
        total = np.zeros_like(values)
        hits = np.zeros((H, W))
        padded_v = np.pad(values * covered[..., None], ((1, 1), (1, 1), (0, 0)))
        padded_c = np.pad(covered, 1).astype(np.float64)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx == 0 and dy == 0:
                    continue
                total += padded_v[1 + dy : 1 + dy + H, 1 + dx : 1 + dx + W]
                hits += padded_c[1 + dy : 1 + dy + H, 1 + dx : 1 + dx + W]
        grow = ~covered & (hits > 0)
        if not grow.any():
            break
        values[grow] = total[grow] / hits[grow, None]
        covered = covered | grow
    return values, covered
