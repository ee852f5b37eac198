"""Row-by-row column scatters against NumPy's own 2-D fancy indexing."""

from __future__ import annotations

import numpy as np
import pytest

from embree_rt.columns import column_max, scatter, scatter_add


@pytest.mark.parametrize("chosen", [0, 1, 7, 500])
def test_scatter_and_scatter_add_match_fancy_indexing(chosen: int) -> None:
    rng = np.random.default_rng(chosen)
    target = rng.random((3, 1000)).astype(np.float32)
    columns = np.sort(rng.choice(1000, chosen, replace=False))
    values = rng.random((3, chosen)).astype(np.float32)

    expected = target.copy()
    expected[:, columns] = values
    written = target.copy()
    scatter(written, columns, values)
    np.testing.assert_array_equal(written, expected)

    expected = target.copy()
    expected[:, columns] += values
    added = target.copy()
    scatter_add(added, columns, values)
    np.testing.assert_array_equal(added, expected)
    # Columns not chosen are untouched.
    untouched = np.setdiff1d(np.arange(1000), columns)
    np.testing.assert_array_equal(added[:, untouched], target[:, untouched])


def test_scatter_add_broadcasts_one_value_per_row() -> None:
    target = np.zeros((3, 5), np.float32)
    scatter_add(target, np.array([1, 3]), np.array([[1.0], [2.0], [3.0]], np.float32))
    np.testing.assert_array_equal(target[:, [1, 3]], [[1, 1], [2, 2], [3, 3]])
    assert target[:, [0, 2, 4]].sum() == 0


def test_column_max_is_the_largest_entry_of_each_column() -> None:
    values = np.random.default_rng(3).normal(size=(3, 200)).astype(np.float32)
    np.testing.assert_array_equal(column_max(values), values.max(axis=0))
