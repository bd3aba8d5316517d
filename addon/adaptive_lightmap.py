"""Lightmap texels gathered where the radiance varies, interpolated where it provably does not.

Every texel's own gather (`Solution.radiosity_at`) is the exact answer, but it costs about a
millisecond; most of a lightmap is smooth. `sample` gathers on the corners of square cells of
`step` texels, and then, level by level, at each cell's centre and edge midpoints; a cell whose
five checks all lie within `tol` (relative, with a floor of `DARK_FLOOR` times the brightest
value, as in `refine`) of the bilinear interpolation of its corners is filled by that
interpolation, any other cell is split into four and checked again, down to single texels
(all gathered). This is adaptive sampling with a bilinear error test, the image-space analogue
of the refined twin (and of Whitted's adaptive supersampling, CACM 1980).

A cell is interpolated only if all its texels are covered and lie on one core surface: cells
that cross a UV chart's border, the image's border or an edge between surfaces (a crease, where
the radiance may jump) are gathered texel by texel. Features smaller than half a cell that fall
between all nine check points of a cell can be missed: `step` bounds that size (8 texels by
default; `step=1` gathers every texel).
"""

import numpy as np

DARK_FLOOR = 1e-2
STEP = 8
DEFAULT_TOL = 0.01


def sample(row, group, evaluate, tol, step=STEP):
    """Radiance at every covered texel of an (H, W) lightmap.

    Parameters
    ----------
    row : ndarray of int, shape (H, W)
        For each texel, the index of its sample point (into the arrays `evaluate` knows), -1 if
        it is not covered.
    group : ndarray of int, shape (K,)
        The surface of each sample point (cells interpolate over one surface only).
    evaluate : callable(points: ndarray of int (n,)) -> ndarray (n, C)
        Radiance at sample points.
    tol : float
        Relative tolerance of the interpolation (> 0).
    step : int
        Cell size in texels, a power of two (1: gather every texel).

    Returns
    -------
    values : ndarray, shape (K, C)
        Radiance at every sample point (gathered or interpolated).
    gathered : ndarray of bool, shape (K,)
        True where the value was gathered.

    Raises
    ------
    ValueError
        If tol is not positive or step is not a power of two.
    """
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"adaptive lightmap: tol must be a positive finite number, got {tol!r}")
    if step < 1 or step & (step - 1):
        raise ValueError(f"adaptive lightmap: step must be a power of two, got {step!r}")
    row = np.asarray(row, dtype=np.int64)
    group = np.asarray(group, dtype=np.int64)
    H, W = row.shape
    K = len(group)
    known = np.zeros(K, bool)
    values = None

    def need(points):
        """Gather the points not yet known."""
        nonlocal values
        points = np.unique(points[points >= 0])
        points = points[~known[points]]
        if points.size:
            got = evaluate(points)
            if values is None:
                values = np.zeros((K, got.shape[1]))
            values[points] = got
            known[points] = True

    # cells of `step` texels that lie inside the image, covered throughout by one surface
    ny, nx = (H - 1) // step, (W - 1) // step
    y0, x0 = np.meshgrid(np.arange(ny) * step, np.arange(nx) * step, indexing="ij")
    y0, x0 = y0.ravel(), x0.ravel()
    smooth = _uniform(row, group, y0, x0, step)
    # everything outside those cells is gathered texel by texel
    inside = _cell_mask(H, W, y0[smooth], x0[smooth], step)
    need(row[~inside])
    y0, x0 = y0[smooth], x0[smooth]
    size = step
    need(_points(row, y0, x0, size, corners=True))
    while size > 1 and y0.size:
        half = size // 2
        checks = _points(row, y0, x0, size, corners=False)  # (n, 5): centre and edge midpoints
        need(checks)
        corners = _points(row, y0, x0, size, corners=True)  # (n, 4): 00, 01, 10, 11 (y, x)
        c = values[corners]  # (n, 4, C)
        # bilinear interpolation at the five checks: centre, (0, h), (h, 0), (h, s), (s, h)
        lerp = np.stack(
            [
                c.mean(1),
                0.5 * (c[:, 0] + c[:, 1]),
                0.5 * (c[:, 0] + c[:, 2]),
                0.5 * (c[:, 1] + c[:, 3]),
                0.5 * (c[:, 2] + c[:, 3]),
            ],
            1,
        )
        got = values[checks]
        top = float(np.abs(values[known]).max(initial=0.0))
        scale = np.maximum(np.maximum(np.abs(c).max(1), np.abs(got).max(1)), DARK_FLOOR * top).max(1)
        error = np.abs(got - lerp).max(axis=(1, 2))
        ok = error <= tol * np.maximum(scale, 1e-300)
        _fill(values, known, row, y0[ok], x0[ok], size)
        # the others: four cells of half the size, whose corners are all known now
        y0, x0 = y0[~ok], x0[~ok]
        y0 = np.concatenate([y0, y0, y0 + half, y0 + half])
        x0 = np.concatenate([x0, x0 + half, x0, x0 + half])
        size = half
    if values is None:
        values = np.zeros((K, 3))
    return values, known


def _cell_mask(H, W, y0, x0, size):
    """Texels of the cells [y0, y0 + size] x [x0, x0 + size] (corners included), (H, W) bool."""
    mask = np.zeros((H, W), bool)
    d = np.arange(size + 1)
    mask[(y0[:, None, None] + d[None, :, None]), (x0[:, None, None] + d[None, None, :])] = True
    return mask


def _uniform(row, group, y0, x0, size):
    """True for cells whose (size + 1)^2 texels are all covered by one surface, shape (n,)."""
    d = np.arange(size + 1)
    rows = row[(y0[:, None, None] + d[None, :, None]), (x0[:, None, None] + d[None, None, :])]
    rows = rows.reshape(len(y0), -1)
    covered = np.all(rows >= 0, axis=1)
    g = group[np.maximum(rows, 0)]
    return covered & np.all(g == g[:, :1], axis=1)


def _points(row, y0, x0, size, corners):
    """Sample indices at a cell's corners (n, 4) or at its centre and edge midpoints (n, 5)."""
    h = size // 2
    if corners:
        offsets = ((0, 0), (0, size), (size, 0), (size, size))
    else:
        offsets = ((h, h), (0, h), (h, 0), (h, size), (size, h))
    return np.stack([row[y0 + dy, x0 + dx] for dy, dx in offsets], 1)


def _fill(values, known, row, y0, x0, size):
    """Bilinear interpolation of the corners over the cells' texels not yet known."""
    if y0.size == 0:
        return
    corners = values[_points(row, y0, x0, size, corners=True)]  # (n, 4, C)
    t = np.arange(size + 1) / size
    ty, tx = np.meshgrid(t, t, indexing="ij")
    w = np.stack([(1 - ty) * (1 - tx), (1 - ty) * tx, ty * (1 - tx), ty * tx], -1).reshape(-1, 4)
    d = np.arange(size + 1)
    rows = row[(y0[:, None, None] + d[None, :, None]), (x0[:, None, None] + d[None, None, :])].reshape(
        len(y0), -1
    )
    interpolated = np.einsum("pk,nkc->npc", w, corners)
    free = ~known[rows]
    values[rows[free]] = interpolated[free]
