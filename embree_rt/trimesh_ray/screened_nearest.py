"""Nearest hits of float64 rays, each screened for whether Embree's float32 answer may be wrong.

One compiled pass on all cores: each ray is moved into the BVH's local frame (shifted, scaled,
rounded to float32 once, its direction made unit), traced with Embree's nearest-hit query, and
its hit *screened*: it is suspect if it lies within a float32-scaled band of its triangle's edge
(barycentric), meets the triangle at a grazing angle, or lies at the ray's origin. Callers trust
the clear hits as they are and decide the suspect ones again (in float64, against the triangles
around them). Doing the frame change, the query and the screening in one pass spares the
NumPy temporaries of each step, which cost more than the query itself for small meshes.

Given the mesh's box, the rays are traced in the order of where they enter it
(``local_frame.entry_key``): the frame pass also keys each ray, a radix sort orders the keys, a
gather pass copies the local rays into that order, the trace and screening run over them, and a
last pass puts the answers back in the caller's order.

The band: Embree's float32 barycentrics err by a few ulps of the largest coordinate involved
(``magnitude``: the ray's origin's or the mesh's) over the triangle's smallest altitude, so a hit
is suspect when ``min(u, v, 1 - u - v) <= band_ulps * eps32 * magnitude / altitude[prim]``.
That table is read only for hits that fail the same test with the mesh's smallest positive
altitude (a wider band): most hits pass it, and the table (one float64 per triangle, megabytes
on big meshes) is then never touched, which is where the pass spent most of its time.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from embree_rt.compiled.morton import radix_order
from embree_rt.compiled.work_split import (
    chunk_count,
    chunk_scratch,
    chunk_span,
    parallel_region,
    threads_for,
)
from embree_rt.embree import BVH
from embree_rt.embree.kernels import (
    CHUNK,
    SCRATCH_WORDS,
    NearestHits,
    Query,
    Rays,
    intersect_chunk,
)
from embree_rt.trimesh_ray.local_frame import box, entry_key, frame, local_coordinate, refuse_rays

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
def _gather_chunk(first, stop, order, rays, limits, ordered_rays, ordered_limits):
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
def _scatter_chunk(first, stop, order, ordered_prim, ordered_suspect, prim, suspect):
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
            _gather_chunk(first, stop, order, rays, limits, ordered_rays, ordered_limits)
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
            _scatter_chunk(first, stop, order, ordered_prim, ordered_suspect, prim, suspect)


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
