"""Whole-column operations on ray arrays, which hold one ray per column: (3, n) vectors.

NumPy's 2-D fancy indexing (``target[:, columns] += values``) walks the index array once per
element with a generic iterator; three 1-D passes, one per row, are 3-4x faster (measured on
2^18 columns: 1.8 ms against 6.6 ms with half the columns chosen). The integrator's scatters go
through here.
"""

from __future__ import annotations

import numpy as np


def column_max(values: np.ndarray) -> np.ndarray:
    """(n,) largest entry of each column of a (3, n) array."""
    return np.maximum(np.maximum(values[0], values[1]), values[2])


def scatter(target: np.ndarray, columns: np.ndarray, values: np.ndarray) -> None:
    """``target[:, columns] = values`` in place: ``target`` (3, n), ``columns`` (k,) int indices,
    ``values`` (3, k) or (3, 1)."""
    for row, value in zip(target, values, strict=True):
        row[columns] = value


def scatter_add(target: np.ndarray, columns: np.ndarray, values: np.ndarray) -> None:
    """``target[:, columns] += values`` in place: ``target`` (3, n), ``columns`` (k,) distinct
    int indices, ``values`` (3, k) or (3, 1)."""
    for row, value in zip(target, values, strict=True):
        row[columns] += value
