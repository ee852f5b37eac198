"""Which bricks a ray can reach: a compiled slab test of every ray against every brick's box.

A ray goes to a brick only if it meets the brick's box within its extent, so the test must
never say no to a ray that hits something inside: it runs in float64 on boxes padded by
``BOX_PADDING`` of their coordinates' size, far beyond the float32 rounding of a hit point
(a relative 2**-24) that could put a hit Embree reports just outside the exact box.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Boxes grow by this much of (1 + their largest |coordinate|) on every side.
BOX_PADDING = 2.0**-16


def padded_boxes(bounds: np.ndarray) -> np.ndarray:
    """(K, 2, 3) float64 ``bounds`` (low, high corners per brick) grown by ``BOX_PADDING``;
    an empty brick's box (low > high) stays empty."""
    bounds = np.asarray(bounds, np.float64).reshape(-1, 2, 3)
    finite = np.where(np.isfinite(bounds), np.abs(bounds), 0.0)
    pad = BOX_PADDING * (1.0 + finite.max(axis=(1, 2)))[:, None]
    out = bounds.copy()
    out[:, 0] -= pad
    out[:, 1] += pad
    return out


@njit(nogil=True, cache=True)
def boxes_reached(origins, directions, t_far, boxes):
    """(K, n) bool: whether ray i, ``origins[:, i] + t * directions[:, i]`` with t in
    [0, ``t_far[i]``] ((3, n) float32 each; ``t_far`` (n,) float64: inf for a ray that meets
    nothing else, 1 for a segment), meets box b of (K, 2, 3) float64 ``boxes``."""
    n = origins.shape[1]
    k = boxes.shape[0]
    reached = np.zeros((k, n), np.bool_)
    for i in range(n):
        o0 = np.float64(origins[0, i])
        o1 = np.float64(origins[1, i])
        o2 = np.float64(origins[2, i])
        d0 = np.float64(directions[0, i])
        d1 = np.float64(directions[1, i])
        d2 = np.float64(directions[2, i])
        for b in range(k):
            if boxes[b, 0, 0] > boxes[b, 1, 0]:  # an empty brick
                continue
            near = 0.0
            far = t_far[i]
            for axis in range(3):
                o = o0 if axis == 0 else (o1 if axis == 1 else o2)
                d = d0 if axis == 0 else (d1 if axis == 1 else d2)
                low = boxes[b, 0, axis]
                high = boxes[b, 1, axis]
                if d == 0.0:
                    if o < low or o > high:
                        far = -1.0
                        break
                    continue
                t0 = (low - o) / d
                t1 = (high - o) / d
                if t0 > t1:
                    t0, t1 = t1, t0
                near = max(near, t0)
                far = min(far, t1)
                if near > far:
                    break
            reached[b, i] = near <= far
    return reached


def rows_by_brick(reached: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(brick, (k,) int64 rays) for each brick of (K, n) bool ``reached`` that some ray
    reaches, in brick order."""
    out = []
    for brick, row in enumerate(reached):
        rows = np.flatnonzero(row)
        if len(rows):
            out.append((brick, rows))
    return out
