"""Rays moved into a BVH's local frame in one compiled pass (the multi-hit query's first step):
what ``(p - shift) * scale`` rounded to float32, a cast and a row maximum cost as three NumPy
passes and their temporaries (about a tenth of an all-hits query on a small mesh)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def _local_rays(origins, directions, shift, scale, extent, local_origins, local_directions,
                magnitude):  # fmt: skip
    for i in range(origins.shape[0]):
        largest = extent
        for k in range(3):
            local = np.float32((origins[i, k] - shift[k]) * scale)
            local_origins[i, k] = local
            local_directions[i, k] = np.float32(directions[i, k])
            largest = max(largest, abs(np.float64(local)))
        magnitude[i] = largest


def local_rays(
    origins: np.ndarray, directions: np.ndarray, shift: np.ndarray, scale: float, extent: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``origins``, ``directions`` (n, 3) float64 in the frame ``(p - shift) * scale``:
    local origins and directions (n, 3) float32 (directions only rounded), and each ray's
    ``magnitude`` (n,) float64, the largest |coordinate| of its local origin or ``extent``."""
    n = len(origins)
    local_origins = np.empty((n, 3), np.float32)
    local_directions = np.empty((n, 3), np.float32)
    magnitude = np.empty(n, np.float64)
    if n:
        _local_rays(np.ascontiguousarray(origins, np.float64),
                    np.ascontiguousarray(directions, np.float64),
                    np.ascontiguousarray(shift, np.float64), float(scale), float(extent),
                    local_origins, local_directions, magnitude)  # fmt: skip
    return local_origins, local_directions, magnitude
