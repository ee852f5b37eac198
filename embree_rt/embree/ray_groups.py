"""Hits regrouped by ray in one compiled counting sort: the multi-hit query's merge of its
parts (rays settled in the compiled pass, rays decided in float64) and, when the rays were
traced in another order (``local_frame.ordered_local_rays``), their return to the given order.

A counting sort by ray is stable, so it is NumPy's stable argsort by ray and the gathers after
it, in two passes: per-ray counts, then each hit written to its ray's next slot. Read in
position order, the hits of rays traced in a coherent order are written to scattered places
(stores, which do not stall the loop), where gathering them back by ray would read scattered
places (loads, which do: measured 12-14 ms for 150k hits, against 2 ms for this pass).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def _group_by_ray(rays, tris, distance, order, ray_count, out_rays, out_tris, out_distance):
    reordered = order.shape[0] > 0
    starts = np.zeros(ray_count + 1, np.int64)
    for k in range(rays.shape[0]):
        ray = order[rays[k]] if reordered else rays[k]
        starts[ray + 1] += 1
    for r in range(ray_count):
        starts[r + 1] += starts[r]
    for k in range(rays.shape[0]):
        ray = order[rays[k]] if reordered else rays[k]
        slot = starts[ray]
        starts[ray] = slot + 1
        out_rays[slot] = ray
        out_tris[slot] = tris[k]
        out_distance[slot] = distance[k]


def group_by_ray(
    rays: np.ndarray,
    tris: np.ndarray,
    distance: np.ndarray,
    ray_count: int,
    order: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hits ``rays``, ``tris`` (k,) int64, ``distance`` (k,) float64 stably sorted by ray:
    ``(rays, tris, distance)``, each ray's hits in their given order. With ``order`` (n,)
    int64, ``rays`` are positions in it (the hit's ray is ``order[rays[k]]``) and the output
    holds the rays themselves. ``ray_count``: rays are below it."""
    count = len(rays)
    out = (np.empty(count, np.int64), np.empty(count, np.int64), np.empty(count, np.float64))
    if count:
        _group_by_ray(np.ascontiguousarray(rays, np.int64), np.ascontiguousarray(tris, np.int64),
                      np.ascontiguousarray(distance, np.float64),
                      np.zeros(0, np.int64) if order is None else np.ascontiguousarray(order,
                                                                                       np.int64),
                      int(ray_count), *out)  # fmt: skip
    return out
