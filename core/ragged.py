"""Ragged index ranges: runs of consecutive indices of different lengths, laid out flat.

Many stages hold variable-length lists as one flat array plus a start and a count per list
(a node's primitives in the BVH, a face's corners, a sorted array's run of equal keys). Visiting
every entry of many lists at once means expanding those ranges without a Python loop: for
ranges [start_k, start_k + count_k), the flat arrays

    owner    = 0 ... 0, 1 ... 1, ...          (k repeated count_k times)
    position = start_0, start_0 + 1, ..., start_1, start_1 + 1, ...

(`expand`), from which each list's entries are gathered at once.
"""

import numpy as np


def starts(count):
    """Where each of the ranges of `count` (K,) entries laid end to end starts, shape (K,)."""
    count = np.asarray(count, dtype=np.int64)
    return np.cumsum(count) - count


def local(count):
    """Each entry's place within its range, for ranges of `count` (K,) entries laid end to end:
    0 .. count_0 - 1, 0 .. count_1 - 1, ...; shape (sum(count),)."""
    count = np.asarray(count, dtype=np.int64)
    return np.arange(int(count.sum())) - np.repeat(starts(count), count)


def expand(start, count):
    """The ranges [start, start + count) (each (K,)), concatenated.

    Returns
    -------
    owner : ndarray of int, shape (sum(count),)
        Which range each entry comes from.
    position : ndarray of int, shape (sum(count),)
        The entry's index.
    """
    count = np.asarray(count, dtype=np.int64)
    owner = np.repeat(np.arange(count.size), count)
    return owner, np.asarray(start, dtype=np.int64)[owner] + local(count)


def runs_of(keys, queries):
    """Every position of the sorted array `keys` that holds each query (K,): (query (C,),
    position (C,)), the queries' runs of equal keys in order."""
    first = np.searchsorted(keys, queries, side="left")
    count = np.searchsorted(keys, queries, side="right") - first
    return expand(first, count)
