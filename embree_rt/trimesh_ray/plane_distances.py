"""Float64 distances along rays to their hit triangles' planes, gathered in one compiled pass.

The multi-hit query reports each hit's distance as trimesh's ``planes_lines`` computes it, from
the ray's float64 origin and the triangle's float64 plane; with NumPy that is five gathers of
(k, 3) rows from per-triangle tables (megabytes on big meshes) and three temporaries, which cost
a quarter of a multi-hit query. Here each hit reads its rows once. Serial: it is a small
share of a query, and a serial kernel needs no threading layer (callable from any thread).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(inline="always", error_model="numpy")
def plane_distance(planes, origins, directions, r, f):
    """(distance, |cos|) float64 of ray ``r`` to triangle ``f``'s plane (see ``plane_distances``);
    the one copy of this arithmetic, which ``settled_hits`` also runs."""
    toward = (
        (planes[f, 0] - origins[r, 0]) * planes[f, 3]
        + (planes[f, 1] - origins[r, 1]) * planes[f, 4]
        + (planes[f, 2] - origins[r, 2]) * planes[f, 5]
    )
    along = (
        directions[r, 0] * planes[f, 3]
        + directions[r, 1] * planes[f, 4]
        + directions[r, 2] * planes[f, 5]
    )
    return toward / along, abs(along)  # ±inf or nan along the plane, as NumPy gives


@njit(inline="always")
def insert_by_distance(out_distance, out_tris, start, stop, distance, triangle):
    """Insert the hit (``distance``, ``triangle``) into the run ``out_*[start:stop]``, kept
    sorted by distance then triangle (a ray's few hits: insertion is the cheapest sort; float64
    may order what float32 tied). The run grows to ``stop + 1``."""
    m = stop
    while m > start and (
        out_distance[m - 1] > distance
        or (out_distance[m - 1] == distance and out_tris[m - 1] > triangle)
    ):
        out_distance[m] = out_distance[m - 1]
        out_tris[m] = out_tris[m - 1]
        m -= 1
    out_distance[m] = distance
    out_tris[m] = triangle


@njit(nogil=True, cache=True, error_model="numpy")
def _plane_distances(planes, origins, directions, rays, tris, distance, cos):
    for k in range(rays.shape[0]):
        distance[k], cos[k] = plane_distance(planes, origins, directions, rays[k], tris[k])


def plane_distances(
    planes: np.ndarray,
    origins: np.ndarray,
    directions: np.ndarray,
    rays: np.ndarray,
    tris: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Distance along ray ``rays[k]`` to the plane of triangle ``tris[k]``, and |cos| of the
    angle between that ray and the plane's normal: ``(distance, cos)`` (k,) float64.

    ``planes`` (triangles, 6) float64: a vertex of each triangle, then its unit normal, one
    C-contiguous row a triangle (a view of two (k, 3) halves of such rows, numba's 'A'
    layout, indexed 2.5x slower in the settling pass); ``origins``, ``directions`` (n, 3)
    float64 (unit directions); ``rays``, ``tris`` (k,) int64.
    """
    count = len(rays)
    distance = np.empty(count, np.float64)
    cos = np.empty(count, np.float64)
    if count:
        _plane_distances(
            np.ascontiguousarray(planes, np.float64),
            np.ascontiguousarray(origins, np.float64),
            np.ascontiguousarray(directions, np.float64),
            np.ascontiguousarray(rays, np.int64),
            np.ascontiguousarray(tris, np.int64),
            distance,
            cos,
        )
    return distance, cos
