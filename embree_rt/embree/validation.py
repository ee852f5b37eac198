"""Checks that keep bad arrays from ever reaching Embree: each error names the argument and row."""

from __future__ import annotations

import numpy as np

from embree_rt.transforms import as_affine


def _first_bad_row(bad: np.ndarray) -> int:
    return int(np.flatnonzero(bad)[0])


def as_points(values: np.ndarray, name: str, count: int | None = None) -> np.ndarray:
    """``values`` as an (n, 3) float32 array of finite numbers (any strides: a transposed view
    of a (3, n) array passes without a copy)."""
    array = np.asarray(values)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (n, 3), got {array.shape}")
    if count is not None and len(array) != count:
        raise ValueError(f"{name}: expected {count} rows, got {len(array)}")
    if array.dtype.kind not in "fiu":
        raise ValueError(f"{name}: expected numbers, got dtype {array.dtype}")
    array = np.asarray(array, dtype=np.float32)
    if not np.isfinite(array).all():
        row = _first_bad_row(~np.isfinite(array).all(axis=1))
        raise ValueError(f"{name}: row {row} is not finite: {array[row].tolist()}")
    return array


def as_positive(values: np.ndarray, name: str, count: int) -> np.ndarray:
    """``values`` as a (count,) float32 array of finite positive numbers."""
    array = np.asarray(values)
    if array.ndim != 1 or len(array) != count:
        raise ValueError(f"{name}: expected shape ({count},), got {array.shape}")
    if array.dtype.kind not in "fiu":
        raise ValueError(f"{name}: expected numbers, got dtype {array.dtype}")
    array = np.ascontiguousarray(array, dtype=np.float32)
    bad = ~(np.isfinite(array) & (array > 0))
    if bad.any():
        row = _first_bad_row(bad)
        raise ValueError(f"{name}: row {row} must be finite and > 0, got {array[row]}")
    return array


def as_indices(values: np.ndarray, name: str, count: int) -> np.ndarray:
    """``values`` as a (k,) int64 array of indices in ``[0, count)``."""
    array = np.asarray(values)
    if array.ndim != 1 or (len(array) and array.dtype.kind not in "iu"):
        raise ValueError(f"{name}: expected (k,) integer indices, got {array.shape} {array.dtype}")
    array = array.astype(np.int64, copy=False)
    if len(array) and (array.min() < 0 or array.max() >= count):
        row = _first_bad_row((array < 0) | (array >= count))
        raise ValueError(f"{name}: row {row} is {array[row]}, outside [0, {count})")
    return array


def as_segment_starts(values: np.ndarray, name: str, vertex_count: int) -> np.ndarray:
    """``values`` as a (k,) uint32 array of segment starts: vertex i begins a segment that
    ends at vertex i + 1, so each start lies in ``[0, vertex_count - 1)``."""
    array = np.asarray(values)
    if array.ndim != 1 or (len(array) and array.dtype.kind not in "iu"):
        raise ValueError(f"{name}: expected (k,) integer indices, got {array.shape} {array.dtype}")
    bad = (array < 0) | (array >= vertex_count - 1)
    if bad.any():
        row = _first_bad_row(bad)
        raise ValueError(
            f"{name}: row {row} is {array[row]}: a segment from vertex i to i + 1 starts in "
            f"[0, {vertex_count - 1})"
        )
    return np.ascontiguousarray(array, dtype=np.uint32)


def as_triangle_indices(values: np.ndarray, name: str, vertex_count: int) -> np.ndarray:
    """``values`` as a (k, 3) uint32 array of vertex indices in ``[0, vertex_count)``."""
    array = np.asarray(values)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (k, 3), got {array.shape}")
    if len(array) and array.dtype.kind not in "iu":
        raise ValueError(f"{name}: expected integer indices, got dtype {array.dtype}")
    bad = ((array < 0) | (array >= vertex_count)).any(axis=1)
    if bad.any():
        row = _first_bad_row(bad)
        raise ValueError(
            f"{name}: row {row} indexes a vertex outside [0, {vertex_count}): {array[row].tolist()}"
        )
    return np.ascontiguousarray(array, dtype=np.uint32)


def as_transform(values: np.ndarray, name: str) -> np.ndarray:
    """``values`` as a (4, 4) float64 invertible affine matrix (last row 0, 0, 0, 1), by the rule
    every placement in embree_rt follows (``embree_rt.transforms``)."""
    return as_affine(values, name)


def as_ray_bounds(
    tnear: float | np.ndarray, tfar: float | np.ndarray, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """``tnear``, ``tfar`` broadcast to (count,) float32 arrays with 0 <= tnear, NaN-free."""
    arrays = []
    for name, value in (("tnear", tnear), ("tfar", tfar)):
        array = np.asarray(value, dtype=np.float32)
        if array.ndim == 0:
            array = np.full(count, array, np.float32)
        elif array.shape != (count,):
            raise ValueError(f"{name}: expected a scalar or shape ({count},), got {array.shape}")
        if np.isnan(array).any():  # one reduction on the common, clean path
            raise ValueError(f"{name}: row {_first_bad_row(np.isnan(array))} is NaN")
        arrays.append(np.ascontiguousarray(array))
    near, far = arrays
    if (near < 0).any():
        raise ValueError(f"tnear: row {_first_bad_row(near < 0)} is negative")
    return near, far
