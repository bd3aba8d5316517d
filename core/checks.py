"""Input checks shared by the public entry points: each failure is a ValueError naming the problem."""

import numpy as np


def finite_array(value, name, shape=None):
    """Return `value` as a float64 array, raising ValueError if it is not finite or mis-shaped.

    Parameters
    ----------
    value : array_like
        Any real (float or int) array.
    name : str
        Name used in the error message.
    shape : tuple of int or None, optional
        Required shape; -1 entries match any length.
    """
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number array, got {value!r}") from exc
    if shape is not None:
        ok = array.ndim == len(shape) and all(want in (-1, got) for want, got in zip(shape, array.shape))
        if not ok:
            wanted = "(" + ", ".join("any" if s == -1 else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have shape {wanted}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or infinite values: {value!r}")
    return array


def rgb(value, name):
    """A finite, non-negative scalar or RGB triple as float64, shape (3,)."""
    array = finite_array([value] * 3 if np.ndim(value) == 0 else value, name, (3,))
    if np.any(array < 0):
        raise ValueError(f"{name} must be >= 0, got {array.tolist()}")
    return array


def point(value, name):
    """A finite 3-vector as float64, shape (3,)."""
    return finite_array(value, name, (3,))


def positive(value, name):
    """A finite scalar > 0 as float."""
    array = finite_array(value, name, ())
    if not array > 0.0:
        raise ValueError(f"{name} must be positive, got {float(array)!r}")
    return float(array)


def direction(value, name):
    """A finite non-zero 3-vector, normalised to unit length, shape (3,)."""
    vector = point(value, name)
    length = np.linalg.norm(vector)
    if not length > 0.0:
        raise ValueError(f"{name} must be a non-zero vector, got {value!r}")
    return vector / length


def tolerance(value, name="tol"):
    """A relative tolerance in (0, 1)."""
    tol = finite_array(value, name, ())
    if not 0.0 < tol < 1.0:
        raise ValueError(f"{name} must be in (0, 1), got {float(tol)!r}")
    return float(tol)


def affine(matrix):
    """Split a 4x4 (or 3x4) affine matrix into its linear part and offset.

    Returns
    -------
    linear : ndarray, shape (3, 3)
    offset : ndarray, shape (3,)

    Raises
    ------
    ValueError
        If the matrix is not finite, not affine (bottom row other than 0, 0, 0, 1) or singular.
    """
    m = finite_array(matrix, "transform matrix")
    if m.shape == (4, 4):
        if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-12):
            raise ValueError(
                f"transform matrix must be affine (bottom row 0, 0, 0, 1), got bottom row {m[3]}"
            )
    elif m.shape != (3, 4):
        raise ValueError(f"transform matrix must have shape (4, 4) or (3, 4), got {m.shape}")
    linear, offset = m[:3, :3].copy(), m[:3, 3].copy()
    scale = np.abs(linear).max()
    if not scale > 0.0 or abs(np.linalg.det(linear / scale)) < 1e-12:
        raise ValueError("transform matrix is singular: it would flatten the surface")
    return linear, offset


def interval(value, name, limits):
    """A parameter sub-range (a, b) with limits[0] <= a < b <= limits[1]."""
    pair = finite_array(value, name, (2,))
    a, b = float(pair[0]), float(pair[1])
    lo, hi = limits
    slack = 1e-12 * max(1.0, abs(lo), abs(hi))
    if not a < b:
        raise ValueError(f"{name} range must be increasing with positive length, got ({a}, {b})")
    if a < lo - slack or b > hi + slack:
        raise ValueError(f"{name} range ({a}, {b}) lies outside the surface's range ({lo}, {hi})")
    return max(a, lo), min(b, hi)


def count(value, name):
    """A positive integer."""
    if isinstance(value, (bool, np.bool_)) or int(value) != value or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)
