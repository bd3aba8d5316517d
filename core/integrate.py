"""Adaptive integration of a smooth-ish function over a parameter box (used for areas).

Each cell carries an n x n Gauss-Legendre value; a cell is accepted when its value agrees with
the sum over its four children (the children's sum is kept), otherwise the children are refined.
All cells of one level are evaluated in a single vectorised call.
"""

import numpy as np

from .quadrature import tensor_rule


def cell_nodes(boxes, n):
    """Gauss nodes and weights of many cells.

    Parameters
    ----------
    boxes : ndarray, shape (C, 4)
        Cells as (u0, u1, v0, v1).
    n : int
        Points per direction.

    Returns
    -------
    u, v, w : ndarray, shape (C, n * n)
        Nodes and weights (weights include the cell's parameter area).
    """
    s, t, w = tensor_rule(n)
    du = boxes[:, 1] - boxes[:, 0]
    dv = boxes[:, 3] - boxes[:, 2]
    u = boxes[:, :1] + du[:, None] * s
    v = boxes[:, 2:3] + dv[:, None] * t
    return u, v, (du * dv)[:, None] * w


def children(boxes):
    """Split each cell in four at its parameter midpoint.

    Parameters
    ----------
    boxes : ndarray, shape (C, 4)

    Returns
    -------
    ndarray, shape (4 * C, 4)
        Children of cell c at rows 4c .. 4c + 3.
    """
    u0, u1, v0, v1 = boxes.T
    um, vm = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    kids = np.stack(
        [
            np.stack([u0, um, v0, vm], -1),
            np.stack([um, u1, v0, vm], -1),
            np.stack([u0, um, vm, v1], -1),
            np.stack([um, u1, vm, v1], -1),
        ],
        axis=1,
    )
    return kids.reshape(-1, 4)


def integrate_box(f, box, rtol=1e-10, n=6, max_level=25, max_evaluations=4_000_000):
    """Integrate f(u, v) over a box to relative accuracy `rtol`.

    Parameters
    ----------
    f : callable
        f(u, v) with u, v of shape (K,) returning shape (K,).
    box : ((u0, u1), (v0, v1))
    rtol : float
        Target relative error of the result.
    max_evaluations : int
        Work budget: when the next refinement would pass it, the pending cells are accepted as
        they are and their differences stay in the error (memory and time stay bounded).

    Returns
    -------
    value, error : float
        The integral and a (pessimistic) estimate of its absolute error.
    evaluations : int
    """
    (u0, u1), (v0, v1) = box
    pending = np.array([[u0, u1, v0, v1]], dtype=np.float64)
    u, v, w = cell_nodes(pending, n)
    values = (f(u.ravel(), v.ravel()).reshape(u.shape) * w).sum(1)
    evaluations = u.size
    total_area = (u1 - u0) * (v1 - v0)
    accepted_value, accepted_error = 0.0, 0.0
    estimate = abs(values[0])
    for level in range(max_level):
        kids = children(pending)
        u, v, w = cell_nodes(kids, n)
        kid_values = (f(u.ravel(), v.ravel()).reshape(u.shape) * w).sum(1)
        evaluations += u.size
        sums = kid_values.reshape(-1, 4).sum(1)
        diff = np.abs(sums - values)
        estimate = max(estimate, abs(accepted_value + sums.sum()))
        cell_area = (pending[:, 1] - pending[:, 0]) * (pending[:, 3] - pending[:, 2])
        local = 0.5 * rtol * estimate * cell_area / total_area
        following = 4 * u.shape[1] * np.count_nonzero(diff > local)  # evaluations of the next level
        last = level == max_level - 1 or evaluations + following > max_evaluations
        done = (diff <= local) | last
        accepted_value += sums[done].sum()
        accepted_error += diff[done].sum()
        refine = np.repeat(~done, 4)
        pending, values = kids[refine], kid_values[refine]
        if pending.size == 0:
            break
    return accepted_value, accepted_error, evaluations
