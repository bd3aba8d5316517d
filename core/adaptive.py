"""Global-adaptive cubature over dyadic parameter cells, for many independent integrals at once.

Each integral ("item") starts from its whole parameter box (cell level 0). A *pending* cell holds
its own rule value and the values of its four children; their difference is the error estimate
of the cell, and the children's sum is its (better) value. Every round, for each item whose
estimated error is still above its tolerance, the cells with the largest estimates (and cells
flagged as unreliable) are replaced by their children, whose children are evaluated in turn. All
cells of all items in a round go to the cell evaluator in one vectorised call.
"""

import numpy as np


class CellBatch:
    """Cells to evaluate: item, level, i, j, each an int64 array of shape (K,)."""

    __slots__ = ("item", "level", "i", "j")

    def __init__(self, item, level, i, j):
        self.item, self.level, self.i, self.j = item, level, i, j

    def children(self):
        """The four children of every cell, child c of cell k at row 4k + c."""
        rep = lambda a: np.repeat(a, 4)  # noqa: E731
        di = np.tile([0, 1, 0, 1], self.item.size)
        dj = np.tile([0, 0, 1, 1], self.item.size)
        return CellBatch(rep(self.item), rep(self.level) + 1, 2 * rep(self.i) + di, 2 * rep(self.j) + dj)

    def take(self, sel):
        return CellBatch(self.item[sel], self.level[sel], self.i[sel], self.j[sel])

    @staticmethod
    def roots(items):
        zero = np.zeros(items.size, dtype=np.int64)
        return CellBatch(items.astype(np.int64), zero, zero.copy(), zero.copy())


CELL_CHUNK = 8192  # cells handed to the evaluator at once (bounds memory)


def _evaluate_chunked(evaluate, cells):
    """Call the evaluator on at most CELL_CHUNK cells at a time and join the results."""
    if cells.item.size <= CELL_CHUNK:
        return evaluate(cells)
    parts = [
        evaluate(cells.take(slice(start, start + CELL_CHUNK)))
        for start in range(0, cells.item.size, CELL_CHUNK)
    ]
    return (
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        np.concatenate([p[2] for p in parts]),
        sum(p[3] for p in parts),
    )


def integrate_cells(evaluate, n_items, tolerance, max_level=40, theta=0.25, max_rounds=400):
    """Integrate many items adaptively.

    Parameters
    ----------
    evaluate : callable
        evaluate(cells: CellBatch) -> (value, extra_error, forced, evaluations), with value and
        extra_error float arrays of shape (K,), forced a bool array of shape (K,) (the cell's value
        must not be trusted: refine it whatever the error), evaluations an int.
        `extra_error` is error the evaluator already knows of (e.g. of inner integrals).
    n_items : int
    tolerance : ndarray, shape (n_items,)
        Absolute error target of each item.
    max_level : int
        Cells at this level are accepted as they are.
    theta : float
        Cells whose error estimate is at least theta times the item's largest are refined.

    Returns
    -------
    value, error : ndarray, shape (n_items,)
        Integrals and error estimates (sum of |parent - children| over accepted cells plus the
        evaluator's extra errors).
    evaluations : int
    """
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (n_items,))
    total = np.zeros(n_items)
    total_error = np.zeros(n_items)
    evaluations = 0

    def evaluate_with_children(cells):
        nonlocal evaluations
        kids = cells.children()
        value, extra, forced, count = _evaluate_chunked(evaluate, kids)
        evaluations += count
        return value.reshape(-1, 4), extra.reshape(-1, 4), forced.reshape(-1, 4)

    pending = CellBatch.roots(np.arange(n_items))
    value, extra, forced, count = _evaluate_chunked(evaluate, pending)
    evaluations += count
    kid_value, kid_extra, kid_forced = evaluate_with_children(pending)

    for _ in range(max_rounds):
        if pending.item.size == 0:
            break
        kid_sum = kid_value.sum(1)
        diff = np.abs(value - kid_sum)
        cell_error = diff + kid_extra.sum(1)
        at_limit = pending.level >= max_level
        must_split = (forced | kid_forced.any(1)) & ~at_limit

        # per-item totals over accepted and pending cells
        item = pending.item
        item_error = total_error + np.bincount(item, cell_error, n_items)
        item_forced = np.bincount(item, must_split, n_items) > 0
        error_ok = item_error <= tolerance
        done_item = error_ok & ~item_forced

        # refine the worst cells of unfinished items (and every forced cell)
        worst = np.zeros(n_items)
        np.maximum.at(worst, item, np.where(at_limit, 0.0, cell_error))
        worst_cell = (cell_error >= theta * worst[item]) & (cell_error > 0)
        refine = ~done_item[item] & ~at_limit & (must_split | ~error_ok[item] & worst_cell)
        # an unfinished item with nothing left to refine accepts what it has
        stuck = ~done_item & (np.bincount(item, refine, n_items) == 0)
        accept = done_item[item] | stuck[item]

        total += np.bincount(item[accept], kid_sum[accept], n_items)
        total_error += np.bincount(item[accept], cell_error[accept], n_items)

        keep = ~accept & ~refine
        split = pending.take(refine)
        new_cells = split.children()
        new_value = kid_value[refine].ravel()
        new_forced = kid_forced[refine].ravel()
        if new_cells.item.size:
            new_kid_value, new_kid_extra, new_kid_forced = evaluate_with_children(new_cells)
        else:
            new_kid_value = new_kid_extra = np.zeros((0, 4))
            new_kid_forced = np.zeros((0, 4), dtype=bool)
        kept = pending.take(keep)
        pending = CellBatch(
            np.concatenate([kept.item, new_cells.item]),
            np.concatenate([kept.level, new_cells.level]),
            np.concatenate([kept.i, new_cells.i]),
            np.concatenate([kept.j, new_cells.j]),
        )
        value = np.concatenate([value[keep], new_value])
        forced = np.concatenate([forced[keep], new_forced])
        kid_value = np.concatenate([kid_value[keep], new_kid_value])
        kid_extra = np.concatenate([kid_extra[keep], new_kid_extra])
        kid_forced = np.concatenate([kid_forced[keep], new_kid_forced])
    else:
        # round limit reached: accept what is pending
        kid_sum = kid_value.sum(1)
        total += np.bincount(pending.item, kid_sum, n_items)
        total_error += np.bincount(pending.item, np.abs(value - kid_sum) + kid_extra.sum(1), n_items)
    return total, total_error, evaluations
