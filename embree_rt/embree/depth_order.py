"""Multi-hit results put in trimesh's order in one compiled pass: every ray's first hit (rays
ascending), then every ray's second hit, and so on, with the hit points if asked. A counting
sort by rank in place of NumPy's stable argsort and the gathers after it (a tenth of an
all-hits query on a small mesh).

The hits may come from rays traced in another order (``local_frame.ordered_local_rays``): then
they are grouped by *position* in that order, and the same counting sort walks the rays in
their original order instead, so the output is exactly the one the given order would give."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def _depth_major(rays, tris, distance, ranks, origins, directions, locations, out_rays,
                 out_tris):  # fmt: skip
    starts = np.zeros(ranks.max() + 2, np.int64)
    for k in range(ranks.shape[0]):
        starts[ranks[k] + 1] += 1
    for depth in range(1, starts.shape[0]):
        starts[depth] += starts[depth - 1]
    with_locations = locations.shape[0] > 0
    for k in range(ranks.shape[0]):  # in input order within each rank: stable
        slot = starts[ranks[k]]
        starts[ranks[k]] += 1
        out_rays[slot] = rays[k]
        out_tris[slot] = tris[k]
        if with_locations:
            r = rays[k]
            for axis in range(3):  # NumPy's origins[r] + directions[r] * distance, unfused
                locations[slot, axis] = origins[r, axis] + directions[r, axis] * distance[k]


@njit(nogil=True, cache=True)
def _depth_major_reordered(positions, tris, distance, ranks, order, origins, directions,
                           locations, out_rays, out_tris):  # fmt: skip
    n = order.shape[0]
    first = np.zeros(n + 1, np.int64)  # hits of position p: first[p] .. first[p + 1]
    for k in range(positions.shape[0]):
        first[positions[k] + 1] += 1
    for p in range(n):
        first[p + 1] += first[p]
    starts = np.zeros(ranks.max() + 2, np.int64)
    for k in range(ranks.shape[0]):
        starts[ranks[k] + 1] += 1
    for depth in range(1, starts.shape[0]):
        starts[depth] += starts[depth - 1]
    inverse = np.empty(n, np.int64)
    for p in range(n):
        inverse[order[p]] = p
    with_locations = locations.shape[0] > 0
    for r in range(n):  # rays ascending, each ray's hits by rank: stable within each rank
        p = inverse[r]
        for k in range(first[p], first[p + 1]):
            slot = starts[ranks[k]]
            starts[ranks[k]] += 1
            out_rays[slot] = r
            out_tris[slot] = tris[k]
            if with_locations:
                for axis in range(3):  # as _depth_major's
                    locations[slot, axis] = origins[r, axis] + directions[r, axis] * distance[k]


def depth_major(
    rays: np.ndarray,
    tris: np.ndarray,
    distance: np.ndarray,
    ranks: np.ndarray,
    origins: np.ndarray,
    directions: np.ndarray,
    with_locations: bool,
    order: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Hits (k,) sorted by ray, with their ``ranks`` (k,) int64 (position within the ray),
    reordered by rank, then ray: ``(rays, tris)`` (k,) int64 and, with ``with_locations``, the
    points ``origins[ray] + directions[ray] * distance`` (k, 3) float64 (else None).
    ``distance`` (k,) float64; ``origins``, ``directions`` (n, 3) float64. With ``order`` (n,)
    int64, ``rays`` are positions in that order (hit of position p: ray ``order[p]``), sorted by
    position; the output is the same as for the hits given by ray."""
    count = len(rays)
    out_rays, out_tris = np.empty(count, np.int64), np.empty(count, np.int64)
    locations = np.empty((count if with_locations else 0, 3), np.float64)
    if count and order is not None:
        _depth_major_reordered(np.ascontiguousarray(rays, np.int64),
                               np.ascontiguousarray(tris, np.int64),
                               np.ascontiguousarray(distance, np.float64),
                               np.ascontiguousarray(ranks, np.int64),
                               np.ascontiguousarray(order, np.int64),
                               np.ascontiguousarray(origins, np.float64),
                               np.ascontiguousarray(directions, np.float64), locations, out_rays,
                               out_tris)  # fmt: skip
    elif count:
        _depth_major(np.ascontiguousarray(rays, np.int64), np.ascontiguousarray(tris, np.int64),
                     np.ascontiguousarray(distance, np.float64),
                     np.ascontiguousarray(ranks, np.int64),
                     np.ascontiguousarray(origins, np.float64),
                     np.ascontiguousarray(directions, np.float64), locations, out_rays,
                     out_tris)  # fmt: skip
    return out_rays, out_tris, locations if with_locations else None
