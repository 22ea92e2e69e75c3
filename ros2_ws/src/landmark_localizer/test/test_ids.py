"""The class-id table answers as np.isin and np.setdiff1d do."""
from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st
import numpy as np

from landmark_localizer.ids import IdTable

ids = st.lists(st.integers(0, 49), max_size=30).map(lambda v: np.array(v, np.int64))


def test_by_hand_and_the_table_is_left_clear() -> None:
    table = IdTable(6)
    assert table.member(np.array([5, 0, 2, 5]), np.array([5, 2])).tolist() == \
        [True, False, True, True]
    assert table.member(np.array([1, 2]), np.zeros(0, np.int64)).tolist() == [False, False]
    assert table.member(np.zeros(0, np.int64), np.array([1])).size == 0
    assert table.difference(np.array([4, 1, 4, 3]), [3]).tolist() == [1, 4]
    assert not table._table.any()   # scratch: nothing left set for the next call


@given(ids, ids)
def test_the_same_answers_as_numpy(values: np.ndarray, members: np.ndarray) -> None:
    table = IdTable(50)
    assert np.array_equal(table.member(values, members), np.isin(values, members))
    assert np.array_equal(table.difference(values, members), np.setdiff1d(values, members))
    assert not table._table.any()
