"""Multi-hit results finished in one compiled pass: the query's parts merged by ray, a ray's
hits at one point made one hit per surface crossing, each ray cut to its nearest ``capacity``,
and all put in trimesh's order (every ray's first hit, rays ascending, then every ray's second
hit, ...), with the hit points if asked.

One hit per crossing: a ray through an edge or a vertex hits every triangle there that
ray_triangle's float64 test accepts (``decided_hits``); those hits, at one point (equal float64
distances) on triangles meeting there (sharing a vertex position), are one crossing of the
surface, reported once, on the lowest triangle index among them. Faces in the same place
(coincident sheets: all three positions shared) are separate surfaces and each crossed. A ray
that only touches the surface at an edge or a vertex (a silhouette: the faces there turn one to
the ray and one away, so the ray stays on one side) meets the surface at that one point too, and
it is reported once, as a crossing is: the hits say where a ray meets the surface, as
``intersects_first`` does, not the parity of a point (``contains_points`` recasts every ray
that passes within float32 reach of an edge instead of counting it).

In NumPy these were a stable argsort by ray and its gathers, the point merging's passes, the
ranks, the cut and a counting sort by rank: about a tenth of an all-hits query on a small mesh.
Here: a counting sort by ray (stable, so each ray's hits keep their order), which also returns
rays traced in another order (``local_frame.ordered_local_rays``) to the given one — reading
the hits in traced order and *storing* each to its ray's next slot, where gathering them by ray
would *load* from scattered places, which stalls (measured 12-14 ms for 150k hits against
2-5) — then one walk over the rays in order, which merges, cuts and places each hit.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from embree_rt.compiled.pointers import prefetch
from embree_rt.compiled.work_split import chunk_count, chunk_span, parallel_region, threads_for
from embree_rt.trimesh_ray.hit_inputs import Hits

_EPS64 = np.finfo(np.float64).eps
_SAME_POINT_ULPS = 1e4
_AHEAD = 16
CHUNK = 4096  # rays per parallel iteration


class CrossingRule(NamedTuple):
    """What makes hits one crossing: ``canonical`` (triangles, 3) int64 corner position ids,
    ``planes`` (triangles, 6) float64 (first vertex, unit normal), the mesh's ``size`` and
    ``parallel_cos`` (the |cos| below which no hit was kept)."""

    canonical: np.ndarray
    planes: np.ndarray
    size: float
    parallel_cos: float


class Grouped(NamedTuple):
    """Hits grouped by ray: ``tris`` (k,) int64, ``distance`` (k,) float64."""

    tris: np.ndarray
    distance: np.ndarray


class HitPoints(NamedTuple):
    """The world rays ``origins``, ``directions`` (n, 3) float64 (unit) and whether to make
    hit points (``with_locations``)."""

    origins: np.ndarray
    directions: np.ndarray
    with_locations: bool


class Placed(NamedTuple):
    """The answer in trimesh's order: ``rays``, ``tris`` (m,) int64, ``locations`` (m, 3)
    float64 (0 rows without locations)."""

    rays: np.ndarray
    tris: np.ndarray
    locations: np.ndarray


class FinishScratch(NamedTuple):
    """Working arrays: per-ray ``starts`` (n + 1,), ``cursor`` and ``kept`` (n,) int64; the
    hits grouped by ray, ``grouped_tris`` (k,) int64 and ``grouped_distance`` (k,) float64."""

    starts: np.ndarray
    cursor: np.ndarray
    kept: np.ndarray
    grouped_tris: np.ndarray
    grouped_distance: np.ndarray


@njit(inline="always")
def _shared_positions(canonical, a, b):
    # how many of triangle a's corner positions are among b's (3: the same triangle's place)
    shared = 0
    for i in range(3):
        if (
            canonical[a, i] == canonical[b, 0]
            or canonical[a, i] == canonical[b, 1]
            or (canonical[a, i] == canonical[b, 2])
        ):
            shared += 1
    return shared


@njit(inline="always")
def _same_point(planes, directions, ray, tri_a, distance_a, tri_b, distance_b, size, parallel_cos):
    # Two hits of a ray are at one point if their float64 plane distances agree to within the
    # rounding of the planes' formula (a few ulps of the coordinates, over the |cos| of the
    # ray with each plane) and the width of ray_triangle's tol.zero band at an edge: 1e4 ulps
    # of the distance plus the mesh's size, over the smaller |cos|.
    gap = abs(distance_a - distance_b)
    scale = _SAME_POINT_ULPS * _EPS64 * (max(abs(distance_a), abs(distance_b)) + size)
    if gap > scale / parallel_cos:  # the loosest it can be: most pairs stop here
        return False
    smaller = 1.0
    for tri in (tri_a, tri_b):
        along = abs(
            planes[tri, 3] * directions[ray, 0]
            + planes[tri, 4] * directions[ray, 1]
            + planes[tri, 5] * directions[ray, 2]
        )
        smaller = min(smaller, max(along, parallel_cos))
    return gap <= scale / smaller


@njit(nogil=True, cache=True)
def _one_hit_per_crossing(tris, distance, canonical, crossing_tris, crossing_distance):
    """The hits of one ray at one point, ``tris``, ``distance`` (m,), as crossings of the
    surface: a hit joins a crossing holding a triangle it meets at an edge or a vertex (sharing
    a vertex position), unless the crossing already holds a triangle in the same place (all
    three positions shared: a coincident sheet, which is another crossing). Triangles are taken
    by ascending index, so each crossing is named by its lowest. Writes the crossings' triangles
    and distances into ``crossing_tris``, ``crossing_distance`` sorted by (distance, triangle)
    and returns how many."""
    m = tris.shape[0]
    order = np.argsort(tris)
    group = np.empty(m, np.int64)
    groups = 0
    for a in range(m):
        ta = tris[order[a]]
        chosen = -1
        for g in range(groups):
            joins, blocked = False, False
            for b in range(a):
                if group[b] != g:
                    continue
                shared = _shared_positions(canonical, ta, tris[order[b]])
                if shared == 3:
                    blocked = True
                    break
                joins = joins or shared > 0
            if joins and not blocked:
                chosen = g
                break
        if chosen < 0:
            chosen = groups
            groups += 1
            crossing_tris[chosen] = ta  # the crossing's lowest index
            crossing_distance[chosen] = distance[order[a]]
        group[a] = chosen
    for i in range(1, groups):  # by (distance, triangle), as every ray's hits
        f, d = crossing_tris[i], crossing_distance[i]
        j = i - 1
        while j >= 0 and (
            crossing_distance[j] > d or (crossing_distance[j] == d and crossing_tris[j] > f)
        ):
            crossing_tris[j + 1], crossing_distance[j + 1] = crossing_tris[j], crossing_distance[j]
            j -= 1
        crossing_tris[j + 1], crossing_distance[j + 1] = f, d
    return groups


@njit(nogil=True, cache=True)
def _merge_chunk(first_ray, stop_ray, starts, capacity, merge, directions, grouped, kept):
    # each ray's hits at one point made one hit per crossing (``_one_hit_per_crossing``, in
    # the run's place), then cut to `capacity`, in place; `kept` hits per ray (merge:
    # CrossingRule; grouped: Grouped, the hits grouped by ray)
    canonical, planes = merge.canonical, merge.planes
    size, parallel_cos = merge.size, merge.parallel_cos
    grouped_tris, grouped_distance = grouped.tris, grouped.distance
    for r in range(first_ray, stop_ray):
        first, stop = starts[r], starts[r + 1]
        out = first
        k = first
        while k < stop and out - first < capacity:
            j = k + 1
            while j < stop and _same_point(
                planes,
                directions,
                r,
                grouped_tris[j - 1],
                grouped_distance[j - 1],
                grouped_tris[j],
                grouped_distance[j],
                size,
                parallel_cos,
            ):
                j += 1
            if j - k == 1:
                grouped_tris[out] = grouped_tris[k]
                grouped_distance[out] = grouped_distance[k]
                out += 1
            else:  # rare: a ray through an edge, a vertex or coincident faces
                crossing_tris = np.empty(j - k, np.int64)
                crossing_distance = np.empty(j - k, np.float64)
                crossings = _one_hit_per_crossing(
                    grouped_tris[k:j].copy(),
                    grouped_distance[k:j].copy(),
                    canonical,
                    crossing_tris,
                    crossing_distance,
                )
                for i in range(min(crossings, capacity - (out - first))):
                    grouped_tris[out] = crossing_tris[i]
                    grouped_distance[out] = crossing_distance[i]
                    out += 1
            k = j
        kept[r] = out - first


@njit(nogil=True, cache=True)
def _place_chunk(first_ray, stop_ray, slots, starts, kept, grouped, points, out):
    # rays first_ray .. stop_ray; slots[d]: where this chunk's next hit of depth d goes.
    # points: HitPoints; out: Placed
    grouped_tris, grouped_distance = grouped.tris, grouped.distance
    origins, directions = points.origins, points.directions
    out_rays, out_tris, locations = out.rays, out.tris, out.locations
    with_locations = locations.shape[0] > 0
    for r in range(first_ray, stop_ray):
        first = starts[r]
        for d in range(kept[r]):
            slot = slots[d]
            slots[d] = slot + 1
            out_rays[slot] = r
            out_tris[slot] = grouped_tris[first + d]
            if with_locations:
                for axis in range(3):  # NumPy's origins[r] + directions[r] * distance, unfused
                    locations[slot, axis] = (
                        origins[r, axis] + directions[r, axis] * grouped_distance[first + d]
                    )


@njit(parallel=True, nogil=True, cache=True)
def _finish(parts, order, ray_count, capacity, merge, points, scratch):
    # parts: Hits; merge: CrossingRule; points: HitPoints; scratch: FinishScratch
    rays, tris, distance = parts.rays, parts.tris, parts.distance
    with_locations = points.with_locations
    starts, cursor, kept = scratch.starts, scratch.cursor, scratch.kept
    grouped = Grouped(scratch.grouped_tris, scratch.grouped_distance)
    grouped_tris, grouped_distance = grouped.tris, grouped.distance
    reordered = order.shape[0] > 0
    # 1. counting sort by ray; in traced order, the counters of each hit's ray are scattered:
    # fetched _AHEAD hits early, so that their loads overlap
    hits = rays.shape[0]
    starts[:] = 0
    for k in range(hits):
        if reordered and k + _AHEAD < hits:
            prefetch(starts.ctypes.data + 8 * (order[rays[k + _AHEAD]] + 1))
        ray = order[rays[k]] if reordered else rays[k]
        starts[ray + 1] += 1
    for r in range(ray_count):
        starts[r + 1] += starts[r]
    cursor[:] = starts[:-1]
    for k in range(hits):
        if reordered and k + _AHEAD < hits:
            prefetch(cursor.ctypes.data + 8 * order[rays[k + _AHEAD]])
        ray = order[rays[k]] if reordered else rays[k]
        slot = cursor[ray]
        cursor[ray] = slot + 1
        grouped_tris[slot] = tris[k]
        grouped_distance[slot] = distance[k]
    # 2. in parallel over chunks of rays: one hit per crossing and cut, in each ray's range
    n_chunks = chunk_count(ray_count, CHUNK)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, ray_count)
        _merge_chunk(first, stop, starts, capacity, merge, points.directions, grouped, kept)
    # 3. depth-major: rays with more than d hits, ascending, for each depth d; each chunk's
    # hits of depth d follow the earlier chunks' (a prefix sum over chunks, depth by depth), so
    # the placement is the serial one on any number of threads
    depth = 0
    for r in range(ray_count):
        depth = max(depth, kept[r])
    slots = np.zeros((n_chunks, depth + 1), np.int64)
    for c in range(n_chunks):
        first, stop = chunk_span(c, CHUNK, ray_count)
        for r in range(first, stop):
            for d in range(kept[r]):
                slots[c, d] += 1
    total = 0
    for d in range(depth):
        for c in range(n_chunks):
            count = slots[c, d]
            slots[c, d] = total
            total += count
    out_rays = np.empty(total, np.int64)
    out_tris = np.empty(total, np.int64)
    locations = np.empty((total if with_locations else 0, 3), np.float64)
    out = Placed(out_rays, out_tris, locations)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, ray_count)
        _place_chunk(first, stop, slots[c], starts, kept, grouped, points, out)
    return out


def finished_hits(
    rays: np.ndarray,
    tris: np.ndarray,
    distance: np.ndarray,
    order: np.ndarray | None,
    ray_count: int,
    capacity: int,
    canonical: np.ndarray,
    planes: np.ndarray,
    size: float,
    parallel_cos: float,
    origins: np.ndarray,
    directions: np.ndarray,
    with_locations: bool,
    scratch=None,
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The multi-hit query's final ``(rays, tris)`` (m,) int64 in trimesh's order and, with
    ``with_locations``, the hit points (m, 3) float64 (else None).

    ``rays``, ``tris`` (k,) int64, ``distance`` (k,) float64: hits in parts, each ray's hits
    contiguous in one part and sorted by (distance, triangle); with ``order`` (n,) int64, rays
    are positions in it (the hit's ray is ``order[rays[k]]``). ``ray_count``: n. ``capacity``:
    crossings kept a ray, its nearest. ``canonical`` (triangles, 3) int64 vertex-position ids
    of each triangle's corners and ``planes`` (triangles, 6) float64 (first vertex, unit
    normal): a ray's hits at one point (float64 distances equal to within 1e4 ulps of the
    distance plus ``size``, over the smaller |cos| of ray and plane, at least ``parallel_cos``,
    the |cos| below which no hit was kept) on triangles meeting at an edge or a vertex there
    are one crossing, named by its lowest triangle index (``_one_hit_per_crossing``; coincident
    faces stay apart). ``origins``, ``directions`` (n, 3) float64, directions unit: the points
    are ``origins[ray] + directions[ray] * distance``. ``scratch``: a function ``(name, size,
    dtype) -> (size,) array`` lending working space (or None for new arrays); ``threads``: how
    many to run on (the answer is
    the same for any).
    """
    if scratch is None:

        def scratch(name, size, dtype):
            return np.empty(size, dtype)

    k = len(rays)
    parts = Hits(
        np.ascontiguousarray(rays, np.int64),
        np.ascontiguousarray(tris, np.int64),
        np.ascontiguousarray(distance, np.float64),
    )
    merge = CrossingRule(
        np.ascontiguousarray(canonical, np.int64),
        np.ascontiguousarray(planes, np.float64),
        float(size),
        float(parallel_cos),
    )
    points = HitPoints(
        np.ascontiguousarray(origins, np.float64),
        np.ascontiguousarray(directions, np.float64),
        bool(with_locations),
    )
    work = FinishScratch(
        scratch("starts", ray_count + 1, np.int64),
        scratch("cursor", ray_count, np.int64),
        scratch("kept", ray_count, np.int64),
        scratch("grouped_tris", k, np.int64),
        scratch("grouped_distance", k, np.float64),
    )
    order = np.zeros(0, np.int64) if order is None else np.ascontiguousarray(order, np.int64)
    with parallel_region:
        numba.set_num_threads(threads_for(int(ray_count), threads))
        placed = _finish(parts, order, int(ray_count), max(1, int(capacity)), merge, points, work)
    return placed.rays, placed.tris, placed.locations if with_locations else None
