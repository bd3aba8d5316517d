"""Ragged index ranges (`core.ragged`) against plain loops."""

import numpy as np

from core import ragged


def test_expand_matches_a_loop_over_ranges_with_empty_ones():
    start = np.array([5, 0, 9, 2])
    count = np.array([3, 0, 1, 2])
    owner, position = ragged.expand(start, count)
    expected = [(k, s + j) for k, (s, c) in enumerate(zip(start, count)) for j in range(c)]
    assert list(zip(owner.tolist(), position.tolist())) == expected
    assert ragged.local(count).tolist() == [0, 1, 2, 0, 0, 1]
    assert ragged.starts(count).tolist() == [0, 3, 3, 4]


def test_runs_of_finds_every_equal_key_and_nothing_for_missing_ones():
    keys = np.array([1, 1, 3, 4, 4, 4, 7])
    query, position = ragged.runs_of(keys, np.array([4, 2, 1, 7]))
    assert query.tolist() == [0, 0, 0, 2, 2, 3]
    assert position.tolist() == [3, 4, 5, 0, 1, 6]
    assert np.all(keys[position] == np.array([4, 2, 1, 7])[query])


def test_empty_input():
    owner, position = ragged.expand(np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert owner.size == position.size == 0
