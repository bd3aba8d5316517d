"""Input checks shared by the public entry points: each failure names the argument and the problem.

A value of the wrong kind (a string, a bool, None where a number belongs) raises
`ArgumentTypeError`, which is both a TypeError (Python's convention) and a ValueError (the core's
promise: bad input raises ValueError). A value of the right kind but out of range raises
ValueError.

Limits that keep float64 arithmetic meaningful (module constants, stated in every message):

- MAX_COORDINATE = 1e30 m and MIN_LENGTH = 1e-30 m: the form-factor kernel multiplies up to six
  lengths ((n1 . e)(n2 . e) with unnormalised normals), so lengths within these bounds keep
  every product far inside float64's normal range (1e-308 ... 1e308) instead of overflowing to
  inf or underflowing to a silent zero.
- RESOLUTION = 1e-9: a surface must span at least this fraction of its distance from the
  origin. float64 places points to 1.1e-16 of their magnitude, so such a surface's points are
  placed to 1.1e-7 of its size, below the default tolerance 1e-6; smaller ones (a sphere of
  radius 1 at x = 1e300) are not representable and their form factors would be silently wrong.
- MIN_TOL = 1e-10: the smallest relative tolerance accepted. Below it the adaptive integrals
  chase rounding noise (measured: tol 1e-12 returns NaN for a sphere's inside, 1e-20 never
  returns).
- MAX_PATCHES = 1,000,000 patches per `split` (about 3 s and 1 GB of patch objects) and
  MAX_GAUSS_ORDER = 64 points per parameter for the fixed rule (64^4 = 1.7e7 kernel
  evaluations, a few seconds; 10^6 points asked for 7 TiB).
"""

import numbers

import numpy as np

MAX_COORDINATE = 1e30
MIN_LENGTH = 1e-30
RESOLUTION = 1e-9
MIN_TOL = 1e-10
MAX_PATCHES = 1_000_000
MAX_GAUSS_ORDER = 64


class ArgumentTypeError(TypeError, ValueError):
    """An argument of the wrong kind (a string, bool or None where a number belongs).

    Both a TypeError and a ValueError, so that callers catching either see it (as numpy's
    AxisError is both a ValueError and an IndexError).
    """


def finite_array(value, name, shape=None):
    """Return `value` as a float64 array, raising if it is not real, finite or of the right shape.

    Parameters
    ----------
    value : array_like
        Any real (float or int) array. Strings (even numeric ones), bools and complex numbers
        are refused: they are never a coordinate by intent.
    name : str
        Name used in the error message.
    shape : tuple of int or None, optional
        Required shape; -1 entries match any length.

    Raises
    ------
    ArgumentTypeError
        If `value` is not made of real numbers.
    ValueError
        If it has the wrong shape or holds NaN or infinite values.
    """
    what = "a real number" if shape == () else "a real number array"
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nesting
        raise ArgumentTypeError(f"{name} must be {what}, got {value!r}") from exc
    if raw.dtype.kind == "O" and any(
        x is None or isinstance(x, (str, bytes, bool, np.bool_)) for x in raw.flat
    ):
        raise ArgumentTypeError(f"{name} must be {what}, not None, strings or bools: got {value!r}")
    if raw.dtype.kind not in "iufO":
        raise ArgumentTypeError(f"{name} must be {what}, got {value!r} (of type {raw.dtype})")
    try:
        array = np.asarray(raw, dtype=np.float64)
    except OverflowError as exc:
        raise ValueError(f"{name} contains values too large for float64: {value!r}") from exc
    except (TypeError, ValueError) as exc:
        raise ArgumentTypeError(f"{name} must be {what}, got {value!r}") from exc
    if shape is not None:
        ok = array.ndim == len(shape) and all(want in (-1, got) for want, got in zip(shape, array.shape))
        if not ok:
            wanted = "(" + ", ".join("any" if s == -1 else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have shape {wanted}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or infinite values: {value!r}")
    return array


def scalar(value, name):
    """A finite real number as float."""
    return float(finite_array(value, name, ()))


def ndim(value, name):
    """np.ndim(value), raising ArgumentTypeError (not numpy's message) for ragged nesting."""
    try:
        return np.ndim(value)
    except (TypeError, ValueError) as exc:
        raise ArgumentTypeError(
            f"{name} must be a number or a flat sequence of numbers, got {value!r}"
        ) from exc


def rgb(value, name):
    """A finite, non-negative scalar or RGB triple as float64, shape (3,)."""
    array = finite_array([value] * 3 if ndim(value, name) == 0 else value, name, (3,))
    if np.any(array < 0):
        raise ValueError(f"{name} must be >= 0, got {array.tolist()}")
    return array


def point(value, name):
    """A finite 3-vector within MAX_COORDINATE of the origin, as float64, shape (3,)."""
    array = finite_array(value, name, (3,))
    coordinates(array, name)
    return array


def coordinates(array, name):
    """Raise ValueError if any coordinate of `array` exceeds MAX_COORDINATE in magnitude."""
    largest = float(np.abs(array).max(initial=0.0))
    if largest > MAX_COORDINATE:
        raise ValueError(
            f"{name} has a coordinate of magnitude {largest:.3g}: beyond {MAX_COORDINATE:.0e} m, "
            "float64 products of lengths in the form factors overflow (move or scale the scene)"
        )


def positive(value, name):
    """A finite scalar > 0 as float."""
    number = scalar(value, name)
    if not number > 0.0:
        raise ValueError(f"{name} must be positive, got {number!r}")
    return number


def non_negative(value, name):
    """A finite scalar >= 0 as float."""
    number = scalar(value, name)
    if not number >= 0.0:
        raise ValueError(f"{name} must be finite and >= 0, got {number!r}")
    return number


def length(value, name, position=0.0):
    """A size (m) of a surface at distance `position` from the origin, as float.

    Raises
    ------
    ValueError
        If it is not positive, exceeds MAX_COORDINATE, is below MIN_LENGTH, or is below
        RESOLUTION times `position` (float64 could not tell the surface's points apart).
    """
    size = positive(value, name)
    resolvable(size, position, name)
    return size


def resolvable(size, position, name):
    """Raise ValueError if a surface `size` (m) across, `position` (m) from the origin, is beyond
    what float64 represents meaningfully (see the module's limits)."""
    if size > MAX_COORDINATE:
        raise ValueError(f"{name} is {size:.3g} m: beyond {MAX_COORDINATE:.0e} m float64 products overflow")
    if size < MIN_LENGTH:
        raise ValueError(
            f"{name} is {size:.3g} m: below {MIN_LENGTH:.0e} m float64 products of lengths underflow "
            "(scale the scene up)"
        )
    if size < RESOLUTION * position:
        raise ValueError(
            f"{name} is {size:.3g} m at {position:.3g} m from the origin: below {RESOLUTION:.0e} of its "
            "distance float64 cannot place its points apart (move the scene's origin closer)"
        )


def direction(value, name):
    """A finite non-zero 3-vector, normalised to unit length, shape (3,).

    The vector is divided by its largest component before its length is taken, so lengths
    from 1e-300 to 1e300 normalise without overflow or underflow.
    """
    vector = finite_array(value, name, (3,))
    largest = np.abs(vector).max()
    if not largest > 0.0:
        raise ValueError(f"{name} must be a non-zero vector, got {value!r}")
    vector = vector / largest
    return vector / np.linalg.norm(vector)


def tolerance(value, name="tol"):
    """A relative tolerance in [MIN_TOL, 1)."""
    tol = scalar(value, name)
    if not MIN_TOL <= tol < 1.0:
        raise ValueError(
            f"{name} must be in [{MIN_TOL:.0e}, 1), got {tol!r} (smaller tolerances are below what "
            "float64 rounding lets the integrals reach)"
        )
    return tol


def affine(matrix):
    """Split a 4x4 (or 3x4) affine matrix into its linear part and offset.

    Returns
    -------
    linear : ndarray, shape (3, 3)
    offset : ndarray, shape (3,)

    Raises
    ------
    ValueError
        If the matrix is not finite, not affine (bottom row other than 0, 0, 0, 1), singular,
        or has entries beyond MAX_COORDINATE.
    """
    m = finite_array(matrix, "transform matrix")
    if m.shape == (4, 4):
        if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-12):
            raise ValueError(
                f"transform matrix must be affine (bottom row 0, 0, 0, 1), got bottom row {m[3]}"
            )
    elif m.shape != (3, 4):
        raise ValueError(f"transform matrix must have shape (4, 4) or (3, 4), got {m.shape}")
    coordinates(m, "transform matrix")
    linear, offset = m[:3, :3].copy(), m[:3, 3].copy()
    scale = np.abs(linear).max()
    if not scale > 0.0 or abs(np.linalg.det(linear / scale)) < 1e-12:
        raise ValueError("transform matrix is singular: it would flatten the surface")
    return linear, offset


def interval(value, name, limits):
    """A parameter sub-range (a, b) with limits[0] <= a < b <= limits[1].

    The width b - a must be at least RESOLUTION times max(|a|, |b|): a narrower range (one ulp)
    holds no float64 parameter values inside it.
    """
    pair = finite_array(value, name, (2,))
    a, b = float(pair[0]), float(pair[1])
    lo, hi = limits
    slack = 1e-12 * max(1.0, abs(lo), abs(hi))
    if not a < b:
        raise ValueError(f"{name} range must be increasing with positive length, got ({a}, {b})")
    if a < lo - slack or b > hi + slack:
        raise ValueError(f"{name} range ({a}, {b}) lies outside the surface's range ({lo}, {hi})")
    a, b = max(a, lo), min(b, hi)
    if not b - a >= RESOLUTION * max(abs(a), abs(b)):
        raise ValueError(
            f"{name} range ({a!r}, {b!r}) is {b - a:.3g} wide: narrower than {RESOLUTION:.0e} of its "
            "values, too narrow for float64 to hold parameters inside it"
        )
    return a, b


def count(value, name, minimum=1, limit=None):
    """An integer >= `minimum` (and <= `limit` if given), as int.

    Integral floats (2.0) are accepted; bools, strings, NaN, inf and fractions are not.
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ArgumentTypeError(f"{name} must be an integer, got {value!r}")
    integral = isinstance(value, numbers.Integral) or (np.isfinite(value) and int(value) == value)
    if not integral or value < minimum:
        kind = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        raise ValueError(f"{name} must be {kind}, got {value!r}")
    if limit is not None and value > limit:
        raise ValueError(f"{name} must be at most {limit:,}, got {value!r}")
    return int(value)


def flag(value, name):
    """A bool (Python's or numpy's) as bool; anything else, even 0 or "False", is refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise ArgumentTypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def handle(value, size, what):
    """An index into a list of `size` items (a handle returned by `Scene.add` or a light's)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ArgumentTypeError(f"{what} handle must be an int returned when it was added, got {value!r}")
    if not 0 <= value < size:
        raise ValueError(f"no {what} with handle {value!r} (the scene has {size})")
    return int(value)
