"""The compiled passes of the exact-hit pipeline (``exact_hits``), one section a stage, all
reading their grouped inputs by name (the named tuples first):

- float64 distances to the hit triangles' planes, which every stage takes its distances from;
- **screen**: Embree's nearest hit of each ray, screened for float32 doubt;
- **settle**: rays whose every recorded hit is clear of edges and grazing, finished at once;
- **decide**: the other rays' doubtful hits decided in float64 as ``ray_triangle`` decides;
- **finish**: the parts merged by ray, one hit per crossing, in trimesh's order;
- the parity of each ray's crossings, for ``contains_points``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from embree_rt.compiled.morton import radix_order
from embree_rt.compiled.pointers import prefetch
from embree_rt.compiled.work_split import (
    chunk_count,
    chunk_scratch,
    chunk_span,
    over_chunks,
    parallel_region,
    threads_for,
)
from embree_rt.embree import BVH, multihit
from embree_rt.embree.kernels import (
    CHUNK,
    SCRATCH_WORDS,
    NearestHits,
    Query,
    Rays,
    intersect_chunk,
)
from embree_rt.embree.multihit import HitBuffers
from embree_rt.trimesh_ray.local_frame import (
    Fans,
    MeshTables,
    box,
    entry_key,
    frame,
    local_coordinate,
    refuse_rays,
)

# -- what the passes read ---------------------------------------------------------------------
# What the float64 passes over Embree's recorded hits (``settled_hits``, ``decided_hits``) read,
# as named tuples the compiled kernels take whole: the rays, the mesh's tables and the
# tolerances of trimesh's rules.


class WorldRays(NamedTuple):
    """n rays in float64: ``origins``, ``directions`` (n, 3) float64 world rays (unit
    directions); ``magnitude`` (n,) float64 the largest local coordinate of each ray
    (``local_frame.local_rays``); ``near`` (n,) float64 the world distance hits must lie
    beyond (``inclusive``: at or beyond)."""

    origins: np.ndarray
    directions: np.ndarray
    magnitude: np.ndarray
    near: np.ndarray
    inclusive: bool


class Hits(NamedTuple):
    """Hits as columns: ``rays``, ``tris`` (k,) int64 and ``distance`` (k,) float64."""

    rays: np.ndarray
    tris: np.ndarray
    distance: np.ndarray


class Tolerances(NamedTuple):
    """trimesh's rules as numbers: ``band_scale`` the edge band per unit of magnitude / altitude
    (a hit nearer its triangle's edge, barycentric, is decided in float64); ``graze`` (float32)
    the |cos| at or below which a hit is too; ``parallel_cos`` the |cos| at or below which a
    ray misses a triangle's plane; ``zero`` ray_triangle's barycentric tolerance."""

    band_scale: float
    graze: np.float32
    parallel_cos: float
    zero: float


def world_rays(
    origins: np.ndarray,
    directions: np.ndarray,
    magnitude: np.ndarray,
    near: np.ndarray,
    inclusive: bool,
) -> WorldRays:
    """``WorldRays`` of the arrays given, as the kernels take them (C-contiguous float64)."""
    return WorldRays(
        np.ascontiguousarray(origins, np.float64),
        np.ascontiguousarray(directions, np.float64),
        np.ascontiguousarray(magnitude, np.float64),
        np.ascontiguousarray(near, np.float64),
        bool(inclusive),
    )


def tolerances(band_scale: float, graze: float, parallel_cos: float, zero: float) -> Tolerances:
    """``Tolerances`` with the kernels' types (graze compared in float32, as Embree's cos)."""
    return Tolerances(float(band_scale), np.float32(graze), float(parallel_cos), float(zero))


# -- plane distances --------------------------------------------------------------------------
# Float64 distances along rays to their hit triangles' planes, gathered in one compiled pass.
#
# The multi-hit query reports each hit's distance as trimesh's ``planes_lines`` computes it, from
# the ray's float64 origin and the triangle's float64 plane; with NumPy that is five gathers of
# (k, 3) rows from per-triangle tables (megabytes on big meshes) and three temporaries, which cost
# a quarter of a multi-hit query. Here each hit reads its rows once. Serial: it is a small
# share of a query, and a serial kernel needs no threading layer (callable from any thread).


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


# -- screen -----------------------------------------------------------------------------------
# Nearest hits of float64 rays, each screened for whether Embree's float32 answer may be wrong.
#
# One compiled pass on all cores: each ray is moved into the BVH's local frame (shifted, scaled,
# rounded to float32 once, its direction made unit), traced with Embree's nearest-hit query, and
# its hit *screened*: it is suspect if it lies within a float32-scaled band of its triangle's edge
# (barycentric), meets the triangle at a grazing angle, or lies at the ray's origin. Callers trust
# the clear hits as they are and decide the suspect ones again (in float64, against the triangles
# around them). Doing the frame change, the query and the screening in one pass spares the
# NumPy temporaries of each step, which cost more than the query itself for small meshes.
#
# Given the mesh's box, the rays are traced in the order of where they enter it
# (``local_frame.entry_key``): the frame pass also keys each ray, a radix sort orders the keys, a
# gather pass copies the local rays into that order, the trace and screening run over them, and a
# last pass puts the answers back in the caller's order.
#
# The band: Embree's float32 barycentrics err by a few ulps of the largest coordinate involved
# (``magnitude``: the ray's origin's or the mesh's) over the triangle's smallest altitude, so a hit
# is suspect when ``min(u, v, 1 - u - v) <= band_ulps * eps32 * magnitude / altitude[prim]``.
# That table is read only for hits that fail the same test with the mesh's smallest positive
# altitude (a wider band): most hits pass it, and the table (one float64 per triangle, megabytes
# on big meshes) is then never touched, which is where the pass spent most of its time.

_EPS32 = np.float64(np.finfo(np.float32).eps)
# trimesh.util.unitize leaves vectors no longer than this as they are
_UNIT_THRESHOLD = 1e-12


class Near(NamedTuple):
    """Where each ray's hits start to count: ``world`` (n,) float64 world distances, or empty
    for ``ulps`` float32 ulps of each ray's magnitude; Embree looks from half of it, and a hit
    within ``factor`` times it is suspect."""

    world: np.ndarray
    ulps: float
    factor: float


class Staged(NamedTuple):
    """The frame pass's output: ``rays`` (n, 6) float32 local origin and unit direction,
    ``limits`` (n, 2) float64 Embree's tnear and the screening's origin limit (local), and
    ``keys`` (n,) uint32 tracing-order keys (0 rows: the given order)."""

    rays: np.ndarray
    limits: np.ndarray
    keys: np.ndarray


class Screen(NamedTuple):
    """What makes a hit suspect: ``altitude`` (primitives,) float64 smallest local altitude of
    each triangle (0: degenerate, always suspect) and ``floor_altitude`` its smallest value; a
    barycentric distance from an edge within ``band_ulps`` float32 ulps of the magnitude (the
    largest of the ray's local origin coordinates and the mesh's, ``extent``) over the
    altitude; |cos| <= ``graze``."""

    altitude: np.ndarray
    floor_altitude: float
    band_ulps: float
    graze: float
    extent: float


@njit(nogil=True, cache=True)
def _frame_chunk(first, stop, origins, directions, frame, near_rule, box, staged, bad):
    # the local frame (local_frame.local_coordinate) and trimesh.util.unitize's unit direction
    # into `staged` (Staged)
    shift, scale, extent = frame.shift, frame.scale, frame.extent
    near_world, near_ulps, near_factor = near_rule.world, near_rule.ulps, near_rule.factor
    rays, limits, keys = staged.rays, staged.limits, staged.keys
    given = near_world.shape[0] > 0
    for i in range(first, stop):
        magnitude = extent
        finite = True
        for k in range(3):
            local = local_coordinate(origins[i, k], shift[k], scale)
            rays[i, k] = local
            finite = finite and math.isfinite(local)
            magnitude = max(magnitude, abs(np.float64(local)))
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        reciprocal = 1.0 / norm if norm > _UNIT_THRESHOLD else 1.0
        rays[i, 3] = np.float32(dx * reciprocal)
        rays[i, 4] = np.float32(dy * reciprocal)
        rays[i, 5] = np.float32(dz * reciprocal)
        near = near_world[i] * scale if given else near_ulps * _EPS32 * magnitude
        # Embree from a little short of tnear: which hits count as at the origin is decided
        # in float64 by the caller for the suspect ones
        limits[i, 0] = np.float32(near * 0.5)
        limits[i, 1] = near_factor * near
        if not (finite and math.isfinite(norm) and math.isfinite(near)):
            bad[0] = True
            for k in range(6):  # a harmless ray: the caller raises
                rays[i, k] = 0.0
        if keys.shape[0]:
            keys[i] = entry_key(origins[i], directions[i], box.lower, box.upper, box.cells_per_unit)


@njit(nogil=True, cache=True)
def _gather_screened_chunk(first, stop, order, rays, limits, ordered_rays, ordered_limits):
    # ray order[j] to position j. A pass of its own, over rows the frame pass has just written:
    # read from the trace loop, between Embree calls (which evict them), or straight from the
    # caller's float64 arrays, these scattered reads cost more than the order saved.
    for j in range(first, stop):
        i = order[j]
        for k in range(6):
            ordered_rays[j, k] = rays[i, k]
        ordered_limits[j, 0] = limits[i, 0]
        ordered_limits[j, 1] = limits[i, 1]


@njit(nogil=True, cache=True)
def _trace_chunk(query, words, first, stop, rays, limits, screen, hits, suspect):
    # local rays first .. stop of `rays` (kernels.Rays; tnear and tfar written here from
    # limits (n, 2) float64), their nearest hits into `hits` (kernels.NearestHits)
    origins, directions, tnear, tfar = rays.origins, rays.directions, rays.tnear, rays.tfar
    altitude, floor_altitude = screen.altitude, screen.floor_altitude
    band_ulps, graze, extent = screen.band_ulps, screen.graze, screen.extent
    t, normal, u, v, prim = hits.t, hits.normal, hits.u, hits.v, hits.prim
    for i in range(first, stop):
        tnear[i] = np.float32(limits[i, 0])
        tfar[i] = np.inf
    intersect_chunk(words, first, stop, query, rays, hits, None)
    floor_band_scale = band_ulps * _EPS32 / floor_altitude if floor_altitude > 0 else np.inf
    for i in range(first, stop):
        p = prim[i]
        if p < 0:
            suspect[i] = False
            continue
        gx, gy, gz = np.float64(normal[i, 0]), np.float64(normal[i, 1]), np.float64(normal[i, 2])
        dx = np.float64(directions[i, 0])
        dy = np.float64(directions[i, 1])
        dz = np.float64(directions[i, 2])
        norms = math.sqrt((gx * gx + gy * gy + gz * gz) * (dx * dx + dy * dy + dz * dz))
        cos = abs(gx * dx + gy * dy + gz * dz) / norms if norms > 0 else 0.0
        ui, vi = np.float64(u[i]), np.float64(v[i])
        edge = min(ui, vi, 1.0 - ui - vi)
        magnitude = extent
        for k in range(3):
            magnitude = max(magnitude, abs(np.float64(origins[i, k])))
        near_edge = edge <= floor_band_scale * magnitude
        if near_edge:  # only now read this triangle's own altitude
            own = altitude[p]
            near_edge = own <= 0 or edge <= band_ulps * _EPS32 * magnitude / own
        suspect[i] = near_edge or cos <= graze or t[i] <= limits[i, 1]


@njit(nogil=True, cache=True)
def _scatter_screened_chunk(first, stop, order, ordered_prim, ordered_suspect, prim, suspect):
    for j in range(first, stop):
        prim[order[j]] = ordered_prim[j]
        suspect[order[j]] = ordered_suspect[j]


@njit(parallel=True, nogil=True, cache=True)
def _screened(
    query, origins, directions, frame, reorder, box, near_rule, screen, prim, suspect, bad
):
    n = origins.shape[0]
    n_chunks = chunk_count(n, CHUNK)
    rays = np.empty((n, 6), np.float32)
    limits = np.empty((n, 2), np.float64)
    keys = np.empty(n if reorder else 0, np.uint32)
    staged = Staged(rays, limits, keys)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        _frame_chunk(first, stop, origins, directions, frame, near_rule, box, staged, bad)
    if reorder:
        order = radix_order(keys)
        ordered_rays = np.empty((n, 6), np.float32)
        ordered_limits = np.empty((n, 2), np.float64)
        for c in prange(n_chunks):
            first, stop = chunk_span(c, CHUNK, n)
            _gather_screened_chunk(first, stop, order, rays, limits, ordered_rays, ordered_limits)
    else:
        order = np.arange(0)
        ordered_rays, ordered_limits = rays, limits
    local = Rays(
        ordered_rays[:, :3], ordered_rays[:, 3:], np.empty(n, np.float32), np.empty(n, np.float32)
    )
    ordered_prim = np.empty(n, np.int32) if reorder else prim
    ordered_suspect = np.empty(n, np.bool_) if reorder else suspect
    hits = NearestHits(
        np.empty(n, np.float32),
        np.empty((n, 3), np.float32),
        np.empty(n, np.float32),
        np.empty(n, np.float32),
        ordered_prim,
        np.empty(n, np.int32),
        np.empty(n, np.int32),
    )
    scratch = chunk_scratch(n, CHUNK, SCRATCH_WORDS)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        _trace_chunk(
            query, scratch[c], first, stop, local, ordered_limits, screen, hits, ordered_suspect
        )
    if reorder:
        for c in prange(n_chunks):
            first, stop = chunk_span(c, CHUNK, n)
            _scatter_screened_chunk(
                first, stop, order, ordered_prim, ordered_suspect, prim, suspect
            )


def screened_nearest(
    bvh: BVH,
    origins: np.ndarray,
    directions: np.ndarray,
    *,
    shift: np.ndarray,
    scale: float,
    extent: float,
    bounds: np.ndarray | None,
    near: np.ndarray | None,
    near_ulps: float,
    altitude: np.ndarray,
    floor_altitude: float,
    band_ulps: float,
    graze: float,
    near_factor: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of each ray and whether it is suspect (see the module docstring).

    ``bvh``: a committed BVH of one triangle geometry, no instances; ``origins``,
    ``directions`` (n, 3) float64 world rays (directions need not be unit);
    ``shift`` (3,) float64 and ``scale``: the local frame is ``(p - shift) * scale`` in float64,
    rounded to float32; ``extent``: the mesh's largest local coordinate; ``bounds``: (2, 3)
    float64 world box (the mesh's) to trace the rays in the order of where they enter it
    (``local_frame.entry_key``; the answers are the same, see below), or None for the given order;
    ``near`` (n,) float64 world distances, or None for ``near_ulps`` float32 ulps of each ray's
    magnitude: Embree looks from half of it, and a hit within ``near_factor`` times it is
    suspect; ``altitude``
    (primitives,) float64 smallest altitude of each triangle in the local frame (0 for a
    degenerate one: always suspect), ``floor_altitude`` its smallest value (so 0 when any
    triangle is degenerate); ``graze``: hits at |cos| <= it are suspect.

    Returns ``prim`` (n,) int32 (-1 for a miss, never suspect) and ``suspect`` (n,) bool;
    raises ValueError, naming the first bad row, when a ray is not finite in the BVH's frame.

    Reordering cannot change an answer: every ray is traced on its own (``lanes`` 1: one
    ``rtcIntersect1`` call, whose result is a function of that ray's fields and the committed,
    immutable BVH alone), and the frame change and screening of ray i read only row i. So with
    ``bounds`` or without, each ray goes through the same arithmetic on the same bits.
    """
    scene = bvh.committed_scene()
    n = len(origins)
    prim = np.empty(n, np.int32)
    suspect = np.empty(n, bool)
    bad = np.zeros(1, bool)
    near_rule = Near(
        np.zeros(0) if near is None else np.ascontiguousarray(near, np.float64),
        float(near_ulps),
        float(near_factor),
    )
    screen = Screen(
        np.ascontiguousarray(altitude, np.float64),
        float(floor_altitude),
        float(band_ulps),
        float(graze),
        float(extent),
    )
    with parallel_region:
        if n:
            numba.set_num_threads(threads_for(n, bvh.threads))
            _screened(
                Query(scene, 0, bvh.lanes),
                np.ascontiguousarray(origins, np.float64),
                np.ascontiguousarray(directions, np.float64),
                frame(shift, scale, extent),
                bounds is not None,
                box(np.zeros((2, 3)) if bounds is None else bounds),
                near_rule,
                screen,
                prim,
                suspect,
                bad,
            )
    if bad[0]:
        refuse_rays(origins, directions, shift, scale, near)
    return prim, suspect


# -- settle -----------------------------------------------------------------------------------
# The multi-hit query's common case in one compiled pass: rays whose every hit is clear of
# edges and grazing angles, turned from ``multihit.all_hits``' buffers into final hits.
#
# For such a ray Embree's float32 answer needs no second look: each hit's distance is taken in
# float64 from the ray's origin to the triangle's plane (``plane_distances.plane_distance``, as
# trimesh computes it), hits at the origin or along a face are dropped, and the rest are sorted by
# (distance, triangle). A ray with a hit within ``band_scale * magnitude / altitude`` (barycentric)
# of an edge, at |cos| <= ``graze``, or that overflowed its buffer (when a retrace with more room
# follows) is *messy*: left to the caller's float64 path. Compiled because in NumPy this pass
# takes a dozen passes and gathers over every hit, more than the traversal itself on small
# meshes.
#
# In parallel over chunks of rays, with an output layout that does not depend on the thread
# count: each chunk writes its hits into its own range of a scratch array (sized by the hits the
# traversal found in the chunk, an upper bound), then the kept counts' prefix sum places each
# chunk's hits in the output, chunk after chunk. So the result is the serial pass's, bit for bit,
# on any number of threads (the arithmetic of a hit reads only its own ray and triangle).

SETTLE_CHUNK = 512  # rays per parallel iteration
_SETTLE_AHEAD = 8  # rays whose triangles' rows are fetched ahead (4: 4.7 ms, 8: 4.0, 16: 8-12)


@njit(nogil=True, cache=True, error_model="numpy")
def _settle_chunk(first, stop, k, hits, retrace_more, rays, mesh, tolerances, messy, out):
    # rays first .. stop, their kept hits written from index k of `out` (rays, tris, distance)
    # on; returns the index past them
    prim, u, v, cos = hits.prim, hits.u, hits.v, hits.cos
    count, more = hits.count, hits.more
    origins, directions, magnitude = rays.origins, rays.directions, rays.magnitude
    near, inclusive = rays.near, rays.inclusive
    planes, altitude, floor_altitude = mesh.planes, mesh.altitude, mesh.floor_altitude
    band_scale, graze, parallel_cos = (
        tolerances.band_scale,
        tolerances.graze,
        tolerances.parallel_cos,
    )
    out_rays, out_tris, out_distance = out.rays, out.tris, out.distance
    one = np.float32(1.0)
    floor_scale = band_scale / floor_altitude if floor_altitude > 0 else np.inf
    rows = planes.ctypes.data
    for i in range(first, stop):
        # The triangles' rows are scattered over tables of tens of MB on a big mesh: their
        # loads, one after the other, left this pass waiting on memory. Started _SETTLE_AHEAD rays
        # early they overlap (the distances on the icosphere's hits: 10.4 -> 4.0 ms).
        if i + _SETTLE_AHEAD < stop:
            for j in range(count[i + _SETTLE_AHEAD]):
                p = prim[i + _SETTLE_AHEAD, j]
                prefetch(rows + 48 * p)  # a row's 48 bytes may cross a line
                prefetch(rows + 48 * p + 40)
        found = count[i]
        bad = retrace_more and more[i]
        for j in range(found):
            if bad:
                break
            p = prim[i, j]
            # float32, as the NumPy screening of the same buffers computes it
            edge = min(min(u[i, j], v[i, j]), one - u[i, j] - v[i, j])
            bad = cos[i, j] <= graze
            # the triangle's own altitude (a cache miss on a big mesh) only for hits inside the
            # mesh-wide band, which is at least as wide: the same answer
            if not bad and edge <= floor_scale * magnitude[i]:
                own = altitude[p]
                bad = own <= 0 or edge <= band_scale * magnitude[i] / own
        messy[i] = bad
        if bad:
            continue
        start = k
        for j in range(found):
            p = prim[i, j]
            distance, along = plane_distance(planes, origins, directions, i, p)
            ahead = distance >= near[i] if inclusive else distance > near[i]
            if not (ahead and along > parallel_cos):
                continue
            insert_by_distance(out_distance, out_tris, start, k, distance, p)
            out_rays[k] = i
            k += 1
    return k


@njit(nogil=True, cache=True)
def _copy_chunk(source, stop, target, kept, ray_offset, out):
    for k in range(source, stop):
        out.rays[target] = kept.rays[k] + ray_offset
        out.tris[target] = kept.tris[k]
        out.distance[target] = kept.distance[k]
        target += 1


@njit(parallel=True, nogil=True, cache=True)
def _settle(hits, retrace_more, rays, mesh, tolerances, messy, scratch, ray_offset, out):
    count = hits.count
    n = count.shape[0]
    n_chunks = chunk_count(n, SETTLE_CHUNK)
    starts = np.zeros(n_chunks + 1, np.int64)  # each chunk's scratch range: hits found
    for i in range(n):
        starts[i // SETTLE_CHUNK + 1] += count[i]
    for c in range(n_chunks):
        starts[c + 1] += starts[c]
    ends = np.empty(n_chunks, np.int64)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, SETTLE_CHUNK, n)
        ends[c] = _settle_chunk(
            first,
            stop,
            starts[c],
            hits,
            retrace_more,
            rays,
            mesh,
            tolerances,
            messy,
            scratch,
        )
    places = np.zeros(n_chunks + 1, np.int64)  # each chunk's place in the output
    for c in range(n_chunks):
        places[c + 1] = places[c] + ends[c] - starts[c]
    for c in prange(n_chunks):
        _copy_chunk(starts[c], ends[c], places[c], scratch, ray_offset, out)
    return places[n_chunks]


def _new_hits(size: int) -> Hits:
    return Hits(np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size))


def settled_hits(
    hits: HitBuffers,
    retrace_more: bool,
    rays: WorldRays,
    mesh: MeshTables,
    tolerances: Tolerances,
    threads: int = 1,
    scratch: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ray_offset: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Final hits of the clear rays of one ``all_hits`` block, and which rays are messy.

    ``hits``: ``all_hits``' ``HitBuffers`` for n rays; ``retrace_more``: rays with ``more`` set
    are messy (the caller traces them again with more room); ``rays``: the n rays
    (``world_rays``); ``mesh``: the mesh's tables (a triangle of altitude 0 is
    degenerate: always messy); ``tolerances``: ``band_scale``, ``graze`` (the messy |cos|) and
    ``parallel_cos`` (the dropping |cos|) are read. ``scratch``, ``out``: (int64, int64,
    float64) arrays of at least as many items as ``hits`` holds, or None for new ones.

    Returns ``rays`` (k,) int64 (``ray_offset`` + 0 .. n - 1, ascending), ``tris`` (k,)
    int64, ``distance`` (k,) float64 sorted by (distance, triangle) within each ray, and
    ``messy`` (n,) bool.
    """
    n = len(hits.count)
    messy = np.zeros(n, bool)
    if not n:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), messy
    total = int(hits.count.sum())
    scratch = Hits(*scratch) if scratch is not None else _new_hits(total)
    out = Hits(*out) if out is not None else _new_hits(total)
    with parallel_region:
        numba.set_num_threads(threads_for(n, threads))
        kept = _settle(
            hits,
            bool(retrace_more),
            rays,
            mesh,
            tolerances,
            messy,
            scratch,
            int(ray_offset),
            out,
        )
    return out.rays[:kept], out.tris[:kept], out.distance[:kept], messy


# -- decide -----------------------------------------------------------------------------------
# The multi-hit query's rays that the compiled settling pass leaves (``settled_hits``: a hit
# within float32 reach of an edge, or grazing), decided in float64 in one compiled pass.
#
# For each such ray, as ``trimesh.ray.ray_triangle`` decides: every hit near an edge or grazing
# (*suspect*) is replaced by the triangles around it, those sharing a vertex position with it
# (``fans``), each tested in float64 with ray_triangle's formulas (``planes_lines``' distance,
# then ``points_to_barycentric``'s Cramer's rule within ``zero``); the ray's other hits stand as
# Embree found them. The union, each triangle once, keeps what lies ahead of the origin and is
# not met along its plane, sorted by (distance, triangle). Rays with no suspect hit (whose
# buffers overflowed and were traced again) go through the same pass, with nothing to test.
#
# Compiled because in NumPy this takes a dozen passes with gathers, uniques and sorts over
# every candidate pair (about 10 µs a ray, a tenth of an all-hits query on the 1.3M-triangle
# icosphere). Such rays
# are 1-2% of a batch, but each reads a few dozen scattered table rows (fetched ahead, see
# ``pointers.prefetch``): in parallel over chunks of rays, each writing its own ranges, so the
# output is the same on any number of threads.

DECIDE_CHUNK = 16  # rays per parallel iteration


class Chosen(NamedTuple):
    """The rays decided: ``rows`` (m,) int64 in the hit buffers, ``positions`` (m,) int64 in
    the world rays."""

    rows: np.ndarray
    positions: np.ndarray


class DecideWork(NamedTuple):
    """Each ray's range of candidates (``bound`` (m + 1,) int64), the candidates (int64) and
    whether each is ``tested`` in float64 (else Embree's hit stands), the kept hits' ``tris``
    (int64) and ``distance`` (float64), and how many each ray ``kept`` (m,) int64."""

    bound: np.ndarray
    candidates: np.ndarray
    tested: np.ndarray
    tris: np.ndarray
    distance: np.ndarray
    kept: np.ndarray


@njit(inline="always")
def _is_suspect(u, v, cos, edge_band_scale, altitude, graze):
    # as settled_hits screens: float32 distance from an edge against a float64 band
    edge = min(min(u, v), np.float32(1.0) - u - v)
    return edge <= edge_band_scale / altitude or cos <= graze


@njit(inline="always", error_model="numpy")
def _barycentric_hit(triangles, f, px, py, pz, zero):
    """ray_triangle's test of point p against triangle f: trimesh.triangles.points_to_barycentric
    (Cramer's rule; its row dot products summed as (x + y) + z, as trimesh's ``diagonal_dot``
    sums them) within ``zero`` of the triangle."""
    ax, ay, az = triangles[f, 0, 0], triangles[f, 0, 1], triangles[f, 0, 2]
    e0x, e0y, e0z = triangles[f, 1, 0] - ax, triangles[f, 1, 1] - ay, triangles[f, 1, 2] - az
    e1x, e1y, e1z = triangles[f, 2, 0] - ax, triangles[f, 2, 1] - ay, triangles[f, 2, 2] - az
    wx, wy, wz = px - ax, py - ay, pz - az
    dot00 = (e0x * e0x + e0y * e0y) + e0z * e0z
    dot01 = (e0x * e1x + e0y * e1y) + e0z * e1z
    dot02 = (e0x * wx + e0y * wy) + e0z * wz
    dot11 = (e1x * e1x + e1y * e1y) + e1z * e1z
    dot12 = (e1x * wx + e1y * wy) + e1z * wz
    inverse_denominator = 1.0 / (dot00 * dot11 - dot01 * dot01)
    b2 = (dot00 * dot12 - dot01 * dot02) * inverse_denominator
    b1 = (dot11 * dot02 - dot01 * dot12) * inverse_denominator
    b0 = 1 - b1 - b2
    low, high = -zero, 1 + zero
    return (b0 > low and b1 > low and b2 > low) and (b0 < high and b1 < high and b2 < high)


@njit(nogil=True, cache=True, error_model="numpy")
def _bounds_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, totals):
    rows, positions = chosen.rows, chosen.positions
    prim, u, v, cos, count = hits.prim, hits.u, hits.v, hits.cos, hits.count
    magnitude = rays.magnitude
    altitude = mesh.altitude
    band_scale, graze = tolerances.band_scale, tolerances.graze
    canonical, fan_starts = fans.canonical, fans.starts
    for a in range(first, stop):  # candidates of each ray, at most
        r, q = rows[a], positions[a]
        total = 0
        for j in range(count[r]):
            p = prim[r, j]
            total += 1
            if _is_suspect(
                u[r, j], v[r, j], cos[r, j], band_scale * magnitude[q], altitude[p], graze
            ):
                for c in range(3):
                    corner = canonical[p, c]
                    total += fan_starts[corner + 1] - fan_starts[corner]
        totals[a] = total


@njit(nogil=True, cache=True, error_model="numpy")
def _decide_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, work):
    # rays first .. stop; ray a's candidates and hits in bound[a] .. bound[a + 1] of `work`'s
    # arrays, kept[a] hits
    rows, positions = chosen.rows, chosen.positions
    prim, u, v, cos, count = hits.prim, hits.u, hits.v, hits.cos, hits.count
    origins, directions, magnitude = rays.origins, rays.directions, rays.magnitude
    near, inclusive = rays.near, rays.inclusive
    planes, triangles, altitude = mesh.planes, mesh.triangles, mesh.altitude
    band_scale, graze = tolerances.band_scale, tolerances.graze
    parallel_cos, zero = tolerances.parallel_cos, tolerances.zero
    canonical, fan_starts, fan_faces = fans.canonical, fans.starts, fans.faces
    bound, candidates, tested = work.bound, work.candidates, work.tested
    out_tris, out_distance, kept = work.tris, work.distance, work.kept
    for a in range(first, stop):
        r, q = rows[a], positions[a]
        stop_a = bound[a]
        for j in range(count[r]):
            p = prim[r, j]
            if _is_suspect(
                u[r, j], v[r, j], cos[r, j], band_scale * magnitude[q], altitude[p], graze
            ):
                for c in range(3):
                    corner = canonical[p, c]
                    for s in range(fan_starts[corner], fan_starts[corner + 1]):
                        candidates[stop_a] = fan_faces[s]
                        tested[stop_a] = True
                        stop_a += 1
            else:
                candidates[stop_a] = p
                tested[stop_a] = False
                stop_a += 1
        # the candidates' rows (scattered over tables of tens of MB on a big mesh) fetched now,
        # to arrive while they are sorted
        for i in range(bound[a], stop_a):
            f = candidates[i]
            prefetch(planes.ctypes.data + 48 * f)
            prefetch(planes.ctypes.data + 48 * f + 40)
            if tested[i]:
                prefetch(triangles.ctypes.data + triangles.strides[0] * f)
                prefetch(triangles.ctypes.data + triangles.strides[0] * f + 64)
        # by (triangle, tested): a triangle's first entry says whether Embree's hit stands
        for i in range(bound[a] + 1, stop_a):
            f, flag = candidates[i], tested[i]
            j = i - 1
            while j >= bound[a] and (
                candidates[j] > f or (candidates[j] == f and tested[j] and not flag)
            ):
                candidates[j + 1], tested[j + 1] = candidates[j], tested[j]
                j -= 1
            candidates[j + 1], tested[j + 1] = f, flag
        start = k = bound[a]
        for i in range(bound[a], stop_a):
            f = candidates[i]
            if i > bound[a] and candidates[i - 1] == f:
                continue
            distance, along = plane_distance(planes, origins, directions, q, f)
            if not along > parallel_cos:
                continue
            if tested[i] and not _barycentric_hit(
                triangles,
                f,
                origins[q, 0] + directions[q, 0] * distance,
                origins[q, 1] + directions[q, 1] * distance,
                origins[q, 2] + directions[q, 2] * distance,
                zero,
            ):
                continue
            if not (distance >= near[q] if inclusive else distance > near[q]):
                continue
            insert_by_distance(out_distance, out_tris, start, k, distance, f)
            k += 1
        kept[a] = k - start


@njit(nogil=True, cache=True)
def _gather_decided_chunk(first, stop, positions, work, places, out):
    bound, tris, distance, kept = work.bound, work.tris, work.distance, work.kept
    for a in range(first, stop):
        for i in range(kept[a]):
            out.rays[places[a] + i] = positions[a]
            out.tris[places[a] + i] = tris[bound[a] + i]
            out.distance[places[a] + i] = distance[bound[a] + i]


@njit(inline="always")
def _offsets(counts):
    """(m + 1,) int64 starts of m consecutive ranges of ``counts`` (m,) int64 entries."""
    offsets = np.zeros(counts.shape[0] + 1, np.int64)
    for a in range(counts.shape[0]):
        offsets[a + 1] = offsets[a] + counts[a]
    return offsets


@njit(parallel=True, nogil=True, cache=True, error_model="numpy")
def _decide(rows, positions, hits, rays, mesh, tolerances, fans):
    # in parallel over chunks of rays, each in its own ranges (a prefix sum of bounds, then of
    # kept hits): the same output on any number of threads
    m = rows.shape[0]
    n_chunks = chunk_count(m, DECIDE_CHUNK)
    chosen = Chosen(rows, positions)
    totals = np.empty(m, np.int64)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, DECIDE_CHUNK, m)
        _bounds_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, totals)
    bound = _offsets(totals)
    kept = np.empty(m, np.int64)
    # each ray's range of candidates, then candidates, tested (decided in float64, else
    # Embree's hit stands), tris, distance, and how many of its hits each ray keeps
    work = DecideWork(
        bound,
        np.empty(bound[m], np.int64),
        np.empty(bound[m], np.bool_),
        np.empty(bound[m], np.int64),
        np.empty(bound[m], np.float64),
        kept,
    )
    for c in prange(n_chunks):
        first, stop = chunk_span(c, DECIDE_CHUNK, m)
        _decide_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, work)
    places = _offsets(kept)
    out = Hits(
        np.empty(places[m], np.int64),
        np.empty(places[m], np.int64),
        np.empty(places[m], np.float64),
    )
    for c in prange(n_chunks):
        first, stop = chunk_span(c, DECIDE_CHUNK, m)
        _gather_decided_chunk(first, stop, positions, work, places, out)
    return out


def decided_hits(
    rows: np.ndarray,
    positions: np.ndarray,
    hits: HitBuffers,
    rays: WorldRays,
    mesh: MeshTables,
    tolerances: Tolerances,
    fans: Fans,
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Final hits of the rays in rows ``rows`` (m,) int64 of ``multihit.all_hits``' buffers
    ``hits``, decided as the module docstring says.

    ``positions`` (m,) int64: each ray's index into ``rays`` (``world_rays``);
    ``mesh``: the mesh's tables; ``tolerances``: ``band_scale`` and ``graze`` (which hits are
    suspect), ``parallel_cos`` (|cos| at or below which a ray misses a triangle's plane) and
    ``zero`` (ray_triangle's barycentric tolerance); ``fans``: (canonical faces (triangles,
    3), starts, faces) CSR of the faces around each vertex position; ``threads``: how many to
    run on (the answer is the same for any).

    Returns ``rays`` (k,) int64 (positions, in the order of ``positions``), ``tris`` (k,) int64
    and ``distance`` (k,) float64, sorted by (distance, triangle) within each ray.
    """
    if not len(rows):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    with parallel_region:
        numba.set_num_threads(threads_for(len(rows) * 16, threads))
        return _decide(
            np.ascontiguousarray(rows, np.int64),
            np.ascontiguousarray(positions, np.int64),
            HitBuffers(*hits[:7]),
            rays,
            mesh,
            tolerances,
            Fans(*fans),
        )


# -- finish -----------------------------------------------------------------------------------
# Multi-hit results finished in one compiled pass: the query's parts merged by ray, a ray's
# hits at one point made one hit per surface crossing, each ray cut to its nearest ``capacity``,
# and all put in trimesh's order (every ray's first hit, rays ascending, then every ray's second
# hit, ...), with the hit points if asked.
#
# One hit per crossing: a ray through an edge or a vertex hits every triangle there that
# ray_triangle's float64 test accepts (``decided_hits``); those hits, at one point (equal float64
# distances) on triangles meeting there (sharing a vertex position), are one crossing of the
# surface, reported once, on the lowest triangle index among them. Faces in the same place
# (coincident sheets: all three positions shared) are separate surfaces and each crossed. A ray
# that only touches the surface at an edge or a vertex (a silhouette: the faces there turn one to
# the ray and one away, so the ray stays on one side) meets the surface at that one point too, and
# it is reported once, as a crossing is: the hits say where a ray meets the surface, as
# ``intersects_first`` does, not the parity of a point (``contains_points`` recasts every ray
# that passes within float32 reach of an edge instead of counting it).
#
# Compiled because in NumPy this takes a stable argsort by ray and its gathers, the point
# merging's passes, the ranks, the cut and a counting sort by rank: about a tenth of an
# all-hits query on a small mesh.
# Here: a counting sort by ray (stable, so each ray's hits keep their order), which also returns
# rays traced in another order (``local_frame.ordered_local_rays``) to the given one — reading
# the hits in traced order and *storing* each to its ray's next slot, where gathering them by ray
# would *load* from scattered places, which stalls (measured 12-14 ms for 150k hits against
# 2-5) — then one walk over the rays in order, which merges, cuts and places each hit.

_EPS64 = np.finfo(np.float64).eps
_SAME_POINT_ULPS = 1e4
_FINISH_AHEAD = 16
FINISH_CHUNK = 4096  # rays per parallel iteration


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
    # fetched _FINISH_AHEAD hits early, so that their loads overlap
    hits = rays.shape[0]
    starts[:] = 0
    for k in range(hits):
        if reordered and k + _FINISH_AHEAD < hits:
            prefetch(starts.ctypes.data + 8 * (order[rays[k + _FINISH_AHEAD]] + 1))
        ray = order[rays[k]] if reordered else rays[k]
        starts[ray + 1] += 1
    for r in range(ray_count):
        starts[r + 1] += starts[r]
    cursor[:] = starts[:-1]
    for k in range(hits):
        if reordered and k + _FINISH_AHEAD < hits:
            prefetch(cursor.ctypes.data + 8 * order[rays[k + _FINISH_AHEAD]])
        ray = order[rays[k]] if reordered else rays[k]
        slot = cursor[ray]
        cursor[ray] = slot + 1
        grouped_tris[slot] = tris[k]
        grouped_distance[slot] = distance[k]
    # 2. in parallel over chunks of rays: one hit per crossing and cut, in each ray's range
    n_chunks = chunk_count(ray_count, FINISH_CHUNK)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, FINISH_CHUNK, ray_count)
        _merge_chunk(first, stop, starts, capacity, merge, points.directions, grouped, kept)
    # 3. depth-major: rays with more than d hits, ascending, for each depth d; each chunk's
    # hits of depth d follow the earlier chunks' (a prefix sum over chunks, depth by depth), so
    # the placement is the serial one on any number of threads
    depth = 0
    for r in range(ray_count):
        depth = max(depth, kept[r])
    slots = np.zeros((n_chunks, depth + 1), np.int64)
    for c in range(n_chunks):
        first, stop = chunk_span(c, FINISH_CHUNK, ray_count)
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
        first, stop = chunk_span(c, FINISH_CHUNK, ray_count)
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


# -- crossing parity --------------------------------------------------------------------------
# The parity of each ray's surface crossings in one filtered traversal (``multihit``), and whether
# no crossing lay near enough an edge, or grazed its triangle enough, to be miscounted:
# ``contains_points``' vote.


class ParityScreen(NamedTuple):
    """When a ray's count of crossings cannot be trusted: ``capacity`` the most hits recorded a
    ray, ``edge_band`` (triangles,) float32 the barycentric band along each triangle's edges,
    ``graze`` float32 the |cos| at or below which a crossing grazes."""

    capacity: int
    edge_band: np.ndarray
    graze: np.float32


class Parity(NamedTuple):
    """``odd`` (n,) bool: an odd number of distinct triangles hit; ``clear`` (n,) bool: the
    count can be trusted (``ParityScreen``)."""

    odd: np.ndarray
    clear: np.ndarray


# The filter's address is an argument, not a global: a global would be compiled in as a constant
# and cached, and the filter lies at another address in the next process.
@njit(nogil=True, cache=True)
def _parity_chunk(words, first, stop, scene, filter_address, origins, directions, screen, parity):
    tracer = multihit.prepare_scratch(scene, words, filter_address)
    hits = np.empty((4, screen.capacity), np.float32)
    prims = np.empty(screen.capacity, np.int32)
    t, u, v, cos = hits[0], hits[1], hits[2], hits[3]
    rows = (t, prims, u, v, cos)
    for i in range(first, stop):
        found, dropped = multihit.trace_one(tracer, origins[i], directions[i], 0.0, np.inf, rows)
        clear = not dropped
        for k in range(found):
            band = screen.edge_band[prims[k]]
            if min(u[k], v[k], 1.0 - u[k] - v[k]) <= band or cos[k] <= screen.graze:
                clear = False
        parity.odd[i] = (found & 1) == 1
        parity.clear[i] = clear


@njit(parallel=True, nogil=True, cache=True)
def _crossing_parity(scene, filter_address, origins, directions, screen, parity):
    over_chunks(
        _parity_chunk,
        origins.shape[0],
        multihit.CHUNK,
        multihit.SCRATCH_WORDS,
        scene,
        filter_address,
        origins,
        directions,
        screen,
        parity,
    )


def crossing_parity(
    bvh: BVH,
    origins: np.ndarray,
    directions: np.ndarray,
    edge_band: np.ndarray,
    graze: float,
    capacity: int = 256,
) -> Parity:
    """Parity of each ray's surface crossings in ``t >= 0`` on ``bvh`` (committed, made with
    ``filters=True``), and whether it can be trusted.

    ``origins``, ``directions`` (n, 3) float32, ``edge_band`` (primitives,) float32. Returns a
    ``Parity``: ``clear`` where no hit lies within ``edge_band[prim]`` (barycentric) of its
    triangle's edge, none meets its triangle at |cos| <= ``graze``, and at most ``capacity``
    triangles were hit; where any of that fails, the count may be off by an edge or vertex
    counted twice or not at all, and the caller should ask another direction.
    """
    n = len(origins)
    parity = Parity(np.zeros(n, bool), np.zeros(n, bool))
    if n:
        screen = ParityScreen(
            int(capacity), np.ascontiguousarray(edge_band, np.float32), np.float32(graze)
        )
        with parallel_region:
            numba.set_num_threads(threads_for(n, bvh.threads))
            _crossing_parity(
                bvh.committed_scene(),
                multihit.record_and_reject.address,
                origins,
                directions,
                screen,
                parity,
            )
    return parity
