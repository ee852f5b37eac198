"""Every hit along a ray, each primitive exactly once, in one Embree traversal.

How: each ray is traced once with ``rtcIntersect1`` and an *argument filter* (Embree 4's
``RTCIntersectArguments.filter`` with ``RTC_RAY_QUERY_FLAG_INVOKE_ARGUMENT_FILTER``, on a scene
built with ``RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS``), a numba ``@cfunc``. Embree calls it
for every triangle its intersection test accepts in ``[tnear, tfar]``; the filter records the
hit (distance, primitive, barycentrics, cosine to the normal) in the ray's own buffer and
*rejects* it, so the traversal goes on and visits every primitive the ray crosses. A primitive
already recorded is skipped (Embree may report one twice: spatial splits put a triangle in
several leaves). When the buffer is full, a nearer hit replaces the farthest kept one, so the
buffer ends with the ``capacity`` nearest hits and a flag saying more exist.

Why not re-casting from the last hit: a new query from ``tnear = t_last`` must exclude what was
already reported *at* that distance without excluding an unreported triangle at the same
distance (an edge shared by two triangles), and an offset past the hit misses or repeats hits
whenever it is too large or too small for the coordinates' float32 spacing (trimesh's
``ray_pyembree`` doubles its offset until it clears). One traversal that sees every accepted
triangle once has no distance rule at all: each hit is found once, at any scale.

The per-ray state travels in the ray query context: Embree passes the ``RTCRayQueryContext*``
of the query to the filter untouched, so the context here is a larger block that starts with
Embree's own context (``instID[0]``, ``instPrimID[0]``: 8 bytes in this build) and continues
with our words (``CONTEXT_*``, from byte 16).

Layouts (Embree 4.4 headers; proved by tests/test_multihit_layout.py):

- ``RTCIntersectArguments`` (rtcore_scene.h): {flags u32 @0, feature_mask u32 @4, context* @8,
  filter @16, intersect @24, [minWidthDistanceFactor f32 @32 if RTC_MIN_WIDTH]}: 40 bytes.
- ``RTCFilterFunctionNArguments`` (rtcore_common.h): {int* valid @0, geometryUserPtr @8,
  context* @16, RTCRayN* @24, RTCHitN* @32, N u32 @40}.
- ``RTCRayN`` / ``RTCHitN`` (rtcore_ray.h): structure of arrays, field k of lane i at 4-byte word
  k·N + i; the hit distance of the candidate is the ray's ``tfar`` (word 8); the hit's fields
  are Ng xyz (0–2), u (3), v (4), primID (5), geomID (6), instID (7), instPrimID (8).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import carray, njit, types

from embree_rt.compiled import pointers
from embree_rt.compiled.callbacks import on_first_use
from embree_rt.compiled.work_split import over_chunks, threads_for
from embree_rt.embree.kernels import (
    FEATURE_FLAG_ALL,
    HIT_GEOM_ID,
    HIT_INST_ID,
    INVALID_ID,
    RAY_DIR,
    RAY_FLAGS,
    RAY_ID,
    RAY_MASK,
    RAY_ORG,
    RAY_TFAR,
    RAY_TIME,
    RAY_TNEAR,
    Rays,
    aligned_word,
    rtc_intersect1,
)

# rtcore_common.h
RAY_QUERY_FLAG_INVOKE_ARGUMENT_FILTER = 1 << 1

# RTCIntersectArguments in 8-byte words
ARGS_FLAGS = 0  # flags | feature_mask << 32
ARGS_CONTEXT = 1
ARGS_FILTER = 2
ARGS_INTERSECT = 3
ARGS_WORDS = 6  # 40 bytes, rounded up

# RTCFilterFunctionNArguments in 8-byte words
FILTER_VALID = 0
FILTER_USER = 1  # the geometry's user pointer
FILTER_CONTEXT = 2
FILTER_RAY = 3
FILTER_HIT = 4
FILTER_N = 5

# RTCHitN fields (4-byte words, times N)
HITN_NG = 0
HITN_U = 3
HITN_V = 4
HITN_PRIM_ID = 5

# Our query context, in 8-byte words: Embree's RTCRayQueryContext in word 0, then ours.
CONTEXT_EMBREE = 0
CONTEXT_COUNT = 2  # hits recorded so far
CONTEXT_CAPACITY = 3  # room in the buffers
CONTEXT_MORE = 4  # 1 when a hit had to be dropped (more than `capacity` exist)
CONTEXT_T = 5  # addresses of the ray's buffers: t float32, prim int32, u, v, cos float32
CONTEXT_PRIM = 6
CONTEXT_U = 7
CONTEXT_V = 8
CONTEXT_COS = 9
CONTEXT_WORDS = 10

# One scratch row per parallel chunk: RTCRayHit (96 bytes, 16-aligned) + arguments + context.
_RAYHIT_WORDS64 = 12
SCRATCH_WORDS = 2 * (2 + _RAYHIT_WORDS64 + ARGS_WORDS + CONTEXT_WORDS)  # 4-byte words
CHUNK = 64  # rays per parallel iteration

_FILTER_SIGNATURE = types.void(types.uintp)


@on_first_use(_FILTER_SIGNATURE, nopython=True, cache=True)
def record_and_reject(address):
    """Argument filter: record each candidate hit in the context's buffers, then reject it
    (``prepare_scratch`` takes its ``address``)."""
    args = carray(pointers.words64(address), 6)
    n = np.int64(args[FILTER_N] & 0xFFFFFFFF)
    valid = carray(pointers.ints(args[FILTER_VALID]), n)
    context = carray(pointers.words64(args[FILTER_CONTEXT]), CONTEXT_WORDS)
    ray = carray(pointers.floats(args[FILTER_RAY]), 12 * n)
    hit = carray(pointers.floats(args[FILTER_HIT]), 9 * n)
    hit_words = carray(pointers.words32(args[FILTER_HIT]), 9 * n)
    capacity = np.int64(context[CONTEXT_CAPACITY])
    t_buffer = carray(pointers.floats(context[CONTEXT_T]), capacity)
    prim_buffer = carray(pointers.ints(context[CONTEXT_PRIM]), capacity)
    u_buffer = carray(pointers.floats(context[CONTEXT_U]), capacity)
    v_buffer = carray(pointers.floats(context[CONTEXT_V]), capacity)
    cos_buffer = carray(pointers.floats(context[CONTEXT_COS]), capacity)
    for lane in range(n):
        if valid[lane] == 0:
            continue
        valid[lane] = 0  # reject: Embree restores tfar and traverses on
        t = ray[RAY_TFAR * n + lane]
        prim = np.int32(hit_words[HITN_PRIM_ID * n + lane])
        count = np.int64(context[CONTEXT_COUNT])
        seen = False
        for k in range(count):
            if prim_buffer[k] == prim:
                seen = True
                break
        if seen:
            continue
        slot = count
        if count == capacity:
            context[CONTEXT_MORE] = 1
            slot = np.int64(0)
            for k in range(1, count):
                if t_buffer[k] > t_buffer[slot]:
                    slot = k
            if capacity == 0 or not t < t_buffer[slot]:
                continue
        else:
            context[CONTEXT_COUNT] = count + 1
        gx = hit[(HITN_NG + 0) * n + lane]
        gy = hit[(HITN_NG + 1) * n + lane]
        gz = hit[(HITN_NG + 2) * n + lane]
        dx = ray[(RAY_DIR + 0) * n + lane]
        dy = ray[(RAY_DIR + 1) * n + lane]
        dz = ray[(RAY_DIR + 2) * n + lane]
        norms = math.sqrt((gx * gx + gy * gy + gz * gz) * (dx * dx + dy * dy + dz * dz))
        t_buffer[slot] = t
        prim_buffer[slot] = prim
        u_buffer[slot] = hit[HITN_U * n + lane]
        v_buffer[slot] = hit[HITN_V * n + lane]
        cos_buffer[slot] = abs(gx * dx + gy * dy + gz * dz) / norms if norms > 0 else 0.0


@njit(inline="always")
def _put64(words, k, value):
    """Store a 64-bit value at 4-byte words k, k + 1 (little-endian)."""
    words[k] = np.uint32(value & 0xFFFFFFFF)
    words[k + 1] = np.uint32((value >> 32) & 0xFFFFFFFF)


@njit(inline="always")
def prepare_scratch(scene, words, filter_address):
    """Lay out RTCRayHit, RTCIntersectArguments and our context in ``words`` (a uint32 row:
    the same element type as the kernels' packets, which numba's parallel loops handle);
    returns the tracer ``trace_one`` takes: (scene, words, and the 4-byte word offsets of the
    three)."""
    rayhit = aligned_word(words, 16)
    args = rayhit + 2 * _RAYHIT_WORDS64
    context = args + 2 * ARGS_WORDS
    base = np.uint64(words.ctypes.data)
    for k in range(2 * (ARGS_WORDS + CONTEXT_WORDS)):
        words[args + k] = 0
    words[args] = RAY_QUERY_FLAG_INVOKE_ARGUMENT_FILTER  # flags
    words[args + 1] = FEATURE_FLAG_ALL  # feature_mask
    _put64(words, args + 2 * ARGS_CONTEXT, base + np.uint64(4 * context))
    _put64(words, args + 2 * ARGS_FILTER, np.uint64(filter_address))
    # rtcInitRayQueryContext: instID[0] = instPrimID[0] = RTC_INVALID_GEOMETRY_ID
    words[context] = INVALID_ID
    words[context + 1] = INVALID_ID
    return scene, words, rayhit, args, context


@njit(inline="always")
def trace_one(tracer, origin, direction, tnear, tfar, rows):
    """Trace one ray, recording its hits in ``rows`` = (t, prim, u, v, cos), (capacity,)
    float32, int32, float32, float32, float32 each; returns (count, more)."""
    scene, words, rayhit, args, context = tracer
    t, prim, u, v, cos = rows
    floats = words.view(np.float32)
    b = rayhit
    floats[b + RAY_ORG] = origin[0]
    floats[b + RAY_ORG + 1] = origin[1]
    floats[b + RAY_ORG + 2] = origin[2]
    floats[b + RAY_TNEAR] = tnear
    floats[b + RAY_DIR] = direction[0]
    floats[b + RAY_DIR + 1] = direction[1]
    floats[b + RAY_DIR + 2] = direction[2]
    floats[b + RAY_TIME] = 0.0
    floats[b + RAY_TFAR] = tfar
    words[b + RAY_MASK] = 0xFFFFFFFF
    words[b + RAY_ID] = 0
    words[b + RAY_FLAGS] = 0
    words[b + HIT_GEOM_ID] = INVALID_ID
    words[b + HIT_INST_ID] = INVALID_ID
    _put64(words, context + 2 * CONTEXT_COUNT, 0)
    _put64(words, context + 2 * CONTEXT_CAPACITY, t.shape[0])
    _put64(words, context + 2 * CONTEXT_MORE, 0)
    _put64(words, context + 2 * CONTEXT_T, t.ctypes.data)
    _put64(words, context + 2 * (CONTEXT_T + 1), prim.ctypes.data)
    _put64(words, context + 2 * (CONTEXT_T + 2), u.ctypes.data)
    _put64(words, context + 2 * (CONTEXT_T + 3), v.ctypes.data)
    _put64(words, context + 2 * (CONTEXT_T + 4), cos.ctypes.data)
    base = words.ctypes.data
    rtc_intersect1(scene, base + 4 * rayhit, base + 4 * args)
    return np.int64(words[context + 2 * CONTEXT_COUNT]), words[context + 2 * CONTEXT_MORE] != 0


@njit(inline="always")
def _sort_hits(count, t, prim, u, v, cos):
    """Insertion sort of one ray's hits by (t, prim): few hits a ray, already nearly sorted."""
    for i in range(1, count):
        tk, pk, uk, vk, ck = t[i], prim[i], u[i], v[i], cos[i]
        j = i - 1
        while j >= 0 and (t[j] > tk or (t[j] == tk and prim[j] > pk)):
            t[j + 1], prim[j + 1], u[j + 1] = t[j], prim[j], u[j]
            v[j + 1], cos[j + 1] = v[j], cos[j]
            j -= 1
        t[j + 1], prim[j + 1], u[j + 1], v[j + 1], cos[j + 1] = tk, pk, uk, vk, ck


# The chunk bodies are functions of their own, called from the prange loops as kernels.py's are:
# written inline in the loop body, numba's parallel lowering lost the stores into the scratch row
# that Embree reads through its address (measured: every ray went out with zero fields).
@njit(nogil=True, cache=True)
def _all_hits_chunk(words, first, stop, scene, filter_address, rays, hits):
    origins, directions, tnear, tfar = rays
    t, prim, u, v, cos, count, more = hits
    tracer = prepare_scratch(scene, words, filter_address)
    for i in range(first, stop):
        rows = (t[i], prim[i], u[i], v[i], cos[i])
        found, dropped = trace_one(tracer, origins[i], directions[i], tnear[i], tfar[i], rows)
        _sort_hits(found, t[i], prim[i], u[i], v[i], cos[i])
        count[i] = found
        more[i] = dropped


@njit(parallel=True, nogil=True, cache=True)
def _all_hits(scene, filter_address, rays, hits):
    n = rays.origins.shape[0]
    over_chunks(_all_hits_chunk, n, CHUNK, SCRATCH_WORDS, scene, filter_address, rays, hits)


class HitBuffers(NamedTuple):
    """Every hit of n rays, up to ``capacity`` a ray (see ``all_hits``): ``t`` (n, capacity)
    float32, ``prim`` (n, capacity) int32, ``u``, ``v``, ``cos`` (n, capacity) float32,
    ``count`` (n,) int64, ``more`` (n,) bool."""

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    cos: np.ndarray
    count: np.ndarray
    more: np.ndarray


def new_hit_buffers(n: int, capacity: int) -> HitBuffers:
    """Empty ``HitBuffers`` for ``all_hits`` of n rays."""
    shape = (n, capacity)
    return HitBuffers(
        np.empty(shape, np.float32),
        np.empty(shape, np.int32),
        np.empty(shape, np.float32),
        np.empty(shape, np.float32),
        np.empty(shape, np.float32),
        np.empty(n, np.int64),
        np.empty(n, bool),
    )


def all_hits(
    scene: int, rays: Rays, capacity: int, threads: int, out: HitBuffers | None = None
) -> HitBuffers:
    """Up to ``capacity`` nearest hits of each ray, each primitive once, sorted by (t, prim).

    ``scene`` is a committed Embree scene built with
    ``library.SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS`` (``BVH(filters=True)``); ``rays`` a
    ``Rays`` as the kernels take them, ``origins``, ``directions`` (n, 3) float32, ``tnear``,
    ``tfar`` (n,) float32 (hits with tnear <= t <= tfar). Returns ``HitBuffers``: ``t``
    (n, capacity) float32, ``prim`` (n, capacity) int32, ``u``, ``v`` (n, capacity) float32
    barycentrics (weights of the triangle's second and third vertex), ``cos`` (n, capacity)
    float32 |cos| of the angle between ray and geometric normal, ``count`` (n,) int64 hits kept
    (row entries past it are undefined), ``more`` (n,) bool: the ray has more hits than
    ``capacity``. ``out``: ``HitBuffers`` of at least those shapes to fill (their leading n rows
    are returned), so that a caller tracing block after block reuses memory that is already
    mapped.
    """
    n = len(rays.origins)
    if out is None or len(out[0]) < n or out[0].shape[1] != capacity:
        out = new_hit_buffers(n, capacity)
    hits = HitBuffers(*(array[:n] for array in out))
    if n:
        numba.set_num_threads(threads_for(n, threads))
        _all_hits(scene, record_and_reject.address, rays, hits)
    return hits
