"""Global-adaptive cubature over dyadic parameter cells, for many independent integrals at once.

A cell (lu, lv, i, j) of a patch is the (i, j)-th of its 2^lu x 2^lv equal sub-boxes. Each
integral ("item") starts from its whole box. A *pending* cell holds its own rule value Q and the
values of its two halves in u (L, R) and in v (B, T): |Q - L - R| and |Q - B - T| estimate the
error left in each direction, so a cell is split in two along the direction where it matters
(refinement is anisotropic: a thin strip or an edge singularity refines across, not along).
An accepted cell contributes L + R + B + T - Q (the combination technique: both one-directional
corrections at once) with the error estimate |Q - L - R| + |Q - B - T|.
Every round, for each item whose estimated error is still above its tolerance, the cells with
the largest estimates (and cells flagged as unreliable) are split; the new halves' own halves
are evaluated. All cells of all items in a round go to the cell evaluator in one vectorised call.
"""

import numpy as np

# codes an evaluator may give instead of a bool `forced` (True means SPLIT_ANY)
SPLIT_NONE, SPLIT_ANY, SPLIT_U, SPLIT_V = 0, 1, 2, 3
CELL_CHUNK = 8192  # cells handed to the evaluator at once (bounds memory)


class CellBatch:
    """Cells to evaluate: item, lu, lv, i, j, each an int64 array of shape (K,)."""

    __slots__ = ("item", "lu", "lv", "i", "j")

    def __init__(self, item, lu, lv, i, j):
        self.item, self.lu, self.lv, self.i, self.j = item, lu, lv, i, j

    @property
    def level(self):
        """Depth of the cell (its finer direction)."""
        return np.maximum(self.lu, self.lv)

    def halves(self):
        """The two u-halves and the two v-halves of every cell: rows 4k .. 4k + 3 are L, R, B, T."""
        n = self.item.size
        rep = lambda a: np.repeat(a, 4)  # noqa: E731
        split_u = np.tile([True, True, False, False], n)
        second = np.tile([0, 1, 0, 1], n)
        lu, lv, i, j = rep(self.lu), rep(self.lv), rep(self.i), rep(self.j)
        return CellBatch(
            rep(self.item),
            lu + split_u,
            lv + ~split_u,
            np.where(split_u, 2 * i + second, i),
            np.where(split_u, j, 2 * j + second),
        )

    def take(self, sel):
        return CellBatch(self.item[sel], self.lu[sel], self.lv[sel], self.i[sel], self.j[sel])

    @staticmethod
    def concatenate(batches):
        return CellBatch(
            *(np.concatenate([getattr(b, name) for b in batches]) for name in CellBatch.__slots__)
        )

    @staticmethod
    def roots(items):
        zero = np.zeros(items.size, dtype=np.int64)
        return CellBatch(items.astype(np.int64), zero, zero.copy(), zero.copy(), zero.copy())


def _evaluate_one(evaluate, cells):
    """The evaluator's five results (a missing `final` is all False)."""
    out = evaluate(cells)
    final = out[4] if len(out) > 4 else np.zeros(cells.item.size, dtype=bool)
    return out[0], out[1], out[2], out[3], np.asarray(final, dtype=bool)


def _evaluate_chunked(evaluate, cells):
    """Call the evaluator on at most CELL_CHUNK cells at a time and join the results."""
    if cells.item.size <= CELL_CHUNK:
        return _evaluate_one(evaluate, cells)
    parts = [
        _evaluate_one(evaluate, cells.take(slice(start, start + CELL_CHUNK)))
        for start in range(0, cells.item.size, CELL_CHUNK)
    ]
    return (
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        np.concatenate([p[2] for p in parts]),
        sum(p[3] for p in parts),
        np.concatenate([p[4] for p in parts]),
    )


def integrate_cells(
    evaluate, n_items, tolerance, max_level=40, theta=0.25, max_rounds=600, max_evaluations=None, start=None
):
    """Integrate many items adaptively.

    Parameters
    ----------
    evaluate : callable
        evaluate(cells: CellBatch) -> (value, extra_error, forced, evaluations), with value and
        extra_error float arrays of shape (K,), forced a bool or int array of shape (K,) (the
        cell's value must not be trusted: split it whatever the error; the codes SPLIT_U and
        SPLIT_V also say in which direction, SPLIT_ANY leaves it to the error estimates),
        evaluations an int.
        `extra_error` is error the evaluator already knows of (e.g. of inner integrals).
        The evaluator may return a fifth result, `final` (bool, shape (K,)): the cell's value is
        exact up to its extra_error (e.g. a contour integral), so its halves are not evaluated
        when it becomes pending (they are taken as half its value each, its extra error split
        among them) and it is accepted as it is, never split (so an evaluator should call a cell
        final only when its extra_error is far below the item's tolerance).
    n_items : int
    tolerance : ndarray, shape (n_items,)
        Absolute error target of each item.
    max_level : int
        Cells this deep in either direction are accepted as they are.
    theta : float
        Cells whose error estimate is at least theta times the item's largest are split.
    max_rounds : int
        Refinement rounds at most.
    max_evaluations : int, optional
        Work budget: a round splits only as many cells (largest errors first) as the evaluations
        left pay for, at the average cost so far, and none once they are spent.
        Either limit ends the integration with the pending cells accepted as they are: the
        values are the best reached and the errors say what was reached (they may exceed the
        tolerances; callers compare).
    start : CellBatch, optional
        Cells to start from instead of each item's whole box: for each item, disjoint cells whose
        union is the part of its box that may contribute (an item without cells integrates to 0).
        A caller that knows splits the evaluator would force saves their rule values this way.

    Returns
    -------
    value, error : ndarray, shape (n_items,)
        Integrals and error estimates (per accepted cell: the sum of its two directional
        estimates, plus the evaluator's extra errors).
    evaluations : int
    """
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (n_items,))
    total = np.zeros(n_items)
    total_error = np.zeros(n_items)
    evaluations = 0
    evaluated = 0  # cells evaluated

    def evaluate_halves(cells, cell_value, cell_extra, cell_final):
        """Halves of pending cells: (value, extra, forced, final), each shape (K, 4)."""
        nonlocal evaluations
        nonlocal evaluated
        K = cells.item.size
        # a final cell's halves: half its value each way, its known error shared among them
        value = np.repeat(0.5 * cell_value[:, None], 4, 1)
        extra = np.repeat(0.25 * cell_extra[:, None], 4, 1)
        forced = np.zeros((K, 4), dtype=np.int8)
        final = np.repeat(cell_final[:, None], 4, 1)
        sel = np.flatnonzero(~cell_final)
        if sel.size:
            v, e, f, count, fin = _evaluate_chunked(evaluate, cells.take(sel).halves())
            value[sel], extra[sel] = v.reshape(-1, 4), e.reshape(-1, 4)
            forced[sel] = np.asarray(f, dtype=np.int8).reshape(-1, 4)
            final[sel] = fin.reshape(-1, 4)
            evaluations += count
            evaluated += 4 * sel.size
        return value, extra, forced, final

    pending = CellBatch.roots(np.arange(n_items)) if start is None else start
    value, root_extra, forced, count, final = _evaluate_chunked(evaluate, pending)
    forced = np.asarray(forced, dtype=np.int8)
    evaluations += count
    evaluated += pending.item.size
    half_value, half_extra, half_forced, half_final = evaluate_halves(pending, value, root_extra, final)

    for _ in range(max_rounds):
        if pending.item.size == 0:
            break
        if max_evaluations is not None and evaluations >= max_evaluations:
            break
        # directional error estimates; a cell is split along the worse direction
        error_u = np.abs(value - half_value[:, 0] - half_value[:, 1])
        error_v = np.abs(value - half_value[:, 2] - half_value[:, 3])
        along_u = error_u >= error_v
        # (final cells are never split: their halves were not evaluated)
        at_limit = (pending.level >= max_level) | final
        must_split = ((forced != SPLIT_NONE) | (half_forced != SPLIT_NONE).any(1)) & ~at_limit
        # forced cells with no error signal alternate directions (stay roughly isotropic);
        # a direction the evaluator names wins over both
        along_u = np.where(must_split & (error_u == error_v), pending.lu <= pending.lv, along_u)
        along_u = np.where(forced == SPLIT_U, True, np.where(forced == SPLIT_V, False, along_u))
        # a cell split only because some halves are forced splits so that those become pending
        halves_u = (half_forced[:, :2] != SPLIT_NONE).any(1)
        halves_v = (half_forced[:, 2:] != SPLIT_NONE).any(1)
        by_halves = (forced == SPLIT_NONE) & (halves_u != halves_v)
        along_u = np.where(by_halves, halves_u, along_u)
        pair = np.where(along_u[:, None], [0, 1], [2, 3])
        # combination of the two one-directional refinements (L + R) + (B + T) - Q corrects the
        # error in both directions at once; its error is bounded by the sum of the two estimates
        better = half_value.sum(1) - value
        cell_error = error_u + error_v + half_extra.sum(1)

        # per-item totals over accepted and pending cells
        item = pending.item
        item_error = total_error + np.bincount(item, cell_error, n_items)
        item_forced = np.bincount(item, must_split, n_items) > 0
        error_ok = item_error <= tolerance
        done_item = error_ok & ~item_forced

        # split the worst cells of unfinished items (and every forced cell)
        worst = np.zeros(n_items)
        np.maximum.at(worst, item, np.where(at_limit, 0.0, cell_error))
        worst_cell = (cell_error >= theta * worst[item]) & (cell_error > 0)
        split = ~done_item[item] & ~at_limit & (must_split | ~error_ok[item] & worst_cell)
        if max_evaluations is not None:
            # within the budget, split only as many cells as it pays for (largest errors first)
            per_cell = 4.0 * evaluations / max(evaluated, 1)
            allowed = max(1, int((max_evaluations - evaluations) / max(per_cell, 1e-300)))
            candidates = np.flatnonzero(split)
            if candidates.size > allowed:
                order = np.argsort(-cell_error[candidates], kind="stable")
                split[candidates[order[allowed:]]] = False
        # an unfinished item with nothing left to split accepts what it has
        stuck = ~done_item & (np.bincount(item, split, n_items) == 0)
        accept = done_item[item] | stuck[item]
        total += np.bincount(item[accept], better[accept], n_items)
        total_error += np.bincount(item[accept], cell_error[accept], n_items)

        # the two halves of each split cell become pending; their halves are evaluated
        keep = ~accept & ~split
        chosen = np.flatnonzero(split)
        halves = pending.take(chosen).halves()
        pick = (4 * np.arange(chosen.size)[:, None] + pair[chosen]).ravel()
        new_cells = halves.take(pick)
        new_value = half_value[chosen[:, None], pair[chosen]].ravel()
        new_forced = half_forced[chosen[:, None], pair[chosen]].ravel()
        new_extra = half_extra[chosen[:, None], pair[chosen]].ravel()
        new_final = half_final[chosen[:, None], pair[chosen]].ravel()
        if new_cells.item.size:
            new_half_value, new_half_extra, new_half_forced, new_half_final = evaluate_halves(
                new_cells, new_value, new_extra, new_final
            )
        else:
            new_half_value = new_half_extra = np.zeros((0, 4))
            new_half_forced = np.zeros((0, 4), dtype=np.int8)
            new_half_final = np.zeros((0, 4), dtype=bool)
        pending = CellBatch.concatenate([pending.take(keep), new_cells])
        value = np.concatenate([value[keep], new_value])
        forced = np.concatenate([forced[keep], new_forced])
        final = np.concatenate([final[keep], new_final])
        half_value = np.concatenate([half_value[keep], new_half_value])
        half_extra = np.concatenate([half_extra[keep], new_half_extra])
        half_forced = np.concatenate([half_forced[keep], new_half_forced])
        half_final = np.concatenate([half_final[keep], new_half_final])
    if pending.item.size:
        # round limit or budget reached: accept what is pending
        error_u = np.abs(value - half_value[:, 0] - half_value[:, 1])
        error_v = np.abs(value - half_value[:, 2] - half_value[:, 3])
        total += np.bincount(pending.item, half_value.sum(1) - value, n_items)
        total_error += np.bincount(pending.item, error_u + error_v + half_extra.sum(1), n_items)
    return total, total_error, evaluations
