"""Compiled query loops: numba kernels that call Embree's ray queries on all cores.

Each kernel walks its rays in chunks, one chunk per parallel iteration, and fills an
``RTCRayHit`` (or an ``RTCRayHit4/8/16`` packet) in a scratch row owned by that chunk, so threads
never share memory and every ray's answer is independent of the thread count.

Embree's functions are linked by name (``numba.types.ExternalFunction``) with their addresses
registered in LLVM's symbol table, so the compiled kernels can be cached on disk.
"""

from __future__ import annotations

from typing import NamedTuple

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types

from embree_rt.compiled.work_split import over_chunks
from embree_rt.embree import library

# RTCRayHit, in 4-byte words (Embree 4, RTC_MAX_INSTANCE_LEVEL_COUNT = 1): RTCRay is 48 bytes,
# RTCHit is padded to 48 bytes by its 16-byte alignment.
RAY_ORG = 0
RAY_TNEAR = 3
RAY_DIR = 4
RAY_TIME = 7
RAY_TFAR = 8
RAY_MASK = 9
RAY_ID = 10
RAY_FLAGS = 11
HIT_NG = 12
HIT_U = 15
HIT_V = 16
HIT_PRIM_ID = 17
HIT_GEOM_ID = 18
HIT_INST_ID = 19
HIT_INST_PRIM_ID = 20

# RTCRayHit4/8/16: the same fields as structure-of-arrays, one word per lane, aligned to the
# packet's width in bytes (16/32/64).
MAX_LANES = 16
PACKET_FIELDS = 21
PACKET_ALIGN = 64
LANE_CHOICES = (1, 4, 8, 16)

INVALID_ID = library.INVALID_ID

# RTCIntersectArguments and RTCOccludedArguments share one layout (rtcore_scene.h): flags u32,
# feature_mask u32, context*, filter, intersect/occluded[, minWidthDistanceFactor f32]: 40 bytes.
RAY_QUERY_FLAG_COHERENT = 1 << 16  # rtcore_common.h
FEATURE_FLAG_ALL = 0xFFFFFFFF
# Coherent queries: with this flag Embree traces a packet whose rays share an octant by
# testing each node against the packet's frustum first (its "fast coherent code path"), and
# switches to single rays later; context and callbacks stay NULL, so it is otherwise a plain
# query. Read-only, so every thread may pass the same block.
_COHERENT_ARGUMENTS = np.zeros(5, np.uint64)
_COHERENT_ARGUMENTS[0] = RAY_QUERY_FLAG_COHERENT | FEATURE_FLAG_ALL << 32


def query_arguments(coherent: bool) -> int:
    """The address of the query arguments the kernels pass to Embree: 0 (Embree's defaults,
    tuned for incoherent rays) or the coherent block above."""
    return _COHERENT_ARGUMENTS.ctypes.data if coherent else 0


class Query(NamedTuple):
    """How a kernel asks Embree: ``scene`` the committed ``RTCScene``, ``arguments`` the address
    of the query arguments (``query_arguments``) or 0, ``lanes`` 1 (``rtcIntersect1`` on an
    ``RTCRayHit``) or a packet width, 4, 8 or 16."""

    scene: int
    arguments: int
    lanes: int


class Rays(NamedTuple):
    """n rays ``origins + t * directions``, ``tnear <= t <= tfar``: ``origins``, ``directions``
    (n, 3), ``tnear``, ``tfar`` scalars or (n,), as a caller asks the BVH's queries
    (``BVH.intersect(Rays(origins, directions, tfar=d))``); as the kernels take them
    (``BVH.query_rays``), (n, 3) and (n,) float32."""

    origins: np.ndarray
    directions: np.ndarray
    tnear: float | np.ndarray = 0.0
    tfar: float | np.ndarray = np.inf


class NearestHits(NamedTuple):
    """The nearest-hit kernels' answers for n rays, as Embree gives them: ``t`` (n,) float32
    (inf on a miss), ``normal`` (n, 3) float32 geometric normal in the hit object's space,
    ``u``, ``v`` (n,) float32, ``prim``, ``geom``, ``inst`` (n,) int32 (-1 where none)."""

    t: np.ndarray
    normal: np.ndarray
    u: np.ndarray
    v: np.ndarray
    prim: np.ndarray
    geom: np.ndarray
    inst: np.ndarray


# packet + alignment slack + valid mask, for the widest packet
SCRATCH_WORDS = PACKET_FIELDS * MAX_LANES + PACKET_ALIGN // 4 + MAX_LANES
CHUNK = 256  # rays per parallel iteration: small enough to balance, large enough to amortise

_SIGNATURE_1 = types.void(types.uintp, types.uintp, types.uintp)
_SIGNATURE_N = types.void(types.uintp, types.uintp, types.uintp, types.uintp)
_NAMES = (
    "rtcIntersect1",
    "rtcOccluded1",
    "rtcIntersect4",
    "rtcOccluded4",
    "rtcIntersect8",
    "rtcOccluded8",
    "rtcIntersect16",
    "rtcOccluded16",
)


def register_symbols() -> None:
    """Tell LLVM where Embree's query functions live in this process (before kernels load)."""
    for name in _NAMES:
        llvm.add_symbol(name, library.function_address(name))


rtc_intersect1 = types.ExternalFunction("rtcIntersect1", _SIGNATURE_1)
rtc_occluded1 = types.ExternalFunction("rtcOccluded1", _SIGNATURE_1)
rtc_intersect4 = types.ExternalFunction("rtcIntersect4", _SIGNATURE_N)
rtc_occluded4 = types.ExternalFunction("rtcOccluded4", _SIGNATURE_N)
rtc_intersect8 = types.ExternalFunction("rtcIntersect8", _SIGNATURE_N)
rtc_occluded8 = types.ExternalFunction("rtcOccluded8", _SIGNATURE_N)
rtc_intersect16 = types.ExternalFunction("rtcIntersect16", _SIGNATURE_N)
rtc_occluded16 = types.ExternalFunction("rtcOccluded16", _SIGNATURE_N)


@njit(inline="always")
def aligned_word(row: np.ndarray, alignment: int) -> int:
    return ((alignment - (row.ctypes.data & (alignment - 1))) & (alignment - 1)) >> 2


@njit(inline="always")
def _store_miss(i, hits):
    hits.t[i] = np.inf
    hits.prim[i] = -1
    hits.geom[i] = -1
    hits.inst[i] = -1
    hits.normal[i, 0] = 0.0
    hits.normal[i, 1] = 0.0
    hits.normal[i, 2] = 0.0
    hits.u[i] = 0.0
    hits.v[i] = 0.0


@njit(inline="always")
def _fill_packet(words, floats, b, lanes, first, count, rays):
    """Write ``rays`` (``Rays``) first .. first + count into the packet at word ``b`` (one ray:
    ``lanes`` 1, an ``RTCRayHit``, whose fields are the same words with one lane)."""
    origins, directions, tnear, tfar = rays
    valid = b + PACKET_FIELDS * lanes
    for lane in range(lanes):
        i = first + min(lane, count - 1)  # idle lanes repeat a live ray and are masked off
        floats[b + RAY_ORG * lanes + lane] = origins[i, 0]
        floats[b + (RAY_ORG + 1) * lanes + lane] = origins[i, 1]
        floats[b + (RAY_ORG + 2) * lanes + lane] = origins[i, 2]
        floats[b + RAY_TNEAR * lanes + lane] = tnear[i]
        floats[b + RAY_DIR * lanes + lane] = directions[i, 0]
        floats[b + (RAY_DIR + 1) * lanes + lane] = directions[i, 1]
        floats[b + (RAY_DIR + 2) * lanes + lane] = directions[i, 2]
        floats[b + RAY_TIME * lanes + lane] = 0.0
        floats[b + RAY_TFAR * lanes + lane] = tfar[i]
        words[b + RAY_MASK * lanes + lane] = 0xFFFFFFFF
        words[b + RAY_ID * lanes + lane] = 0
        words[b + RAY_FLAGS * lanes + lane] = 0
        words[b + HIT_GEOM_ID * lanes + lane] = INVALID_ID
        words[b + HIT_INST_ID * lanes + lane] = INVALID_ID
        words[valid + lane] = 0xFFFFFFFF if lane < count else 0


# Embree's query entry points by packet width: 1 (an ``RTCRayHit``, no valid mask), 4, 8, 16
INTERSECT = (rtc_intersect1, rtc_intersect4, rtc_intersect8, rtc_intersect16)
OCCLUDED = (rtc_occluded1, rtc_occluded4, rtc_occluded8, rtc_occluded16)


@njit(inline="always")
def _query_packet(entries, lanes, valid_address, scene, address, arguments):
    # the packet at `address` through the `lanes`-wide one of `entries`
    one, four, eight, sixteen = entries
    if lanes == 8:
        eight(valid_address, scene, address, arguments)
    elif lanes == 16:
        sixteen(valid_address, scene, address, arguments)
    elif lanes == 4:
        four(valid_address, scene, address, arguments)
    else:
        one(scene, address, arguments)


@njit(inline="always")
def packet_layout(words):
    """Where a packet lies in ``words``, a uint32 scratch row of ``SCRATCH_WORDS``: the row's
    float32 view and the packet's first word ``b`` (aligned for Embree); lane ``lane`` of field
    ``F`` is word ``b + F * lanes + lane``. Made once a chunk: the place is the same for every
    packet, and a view per packet would be a new array for each single ray."""
    return words.view(np.float32), aligned_word(words, PACKET_ALIGN)


@njit(inline="always")
def traced_packet(words, floats, b, query, entries, rays, first, stop):
    """Rays first .. stop of ``rays`` (``Rays``), at most ``query.lanes`` of them, as one
    packet at ``floats``, ``b`` (``packet_layout``'s) of ``words``, through Embree's
    ``entries`` (``INTERSECT`` or ``OCCLUDED``: the 1, 4, 8 and 16-wide entry points), the
    ``query`` a ``Query``. Returns how many rays the packet took; their answers are left in it."""
    scene, arguments, lanes = query
    count = min(lanes, stop - first)
    address = words.ctypes.data + 4 * b
    _fill_packet(words, floats, b, lanes, first, count, rays)
    _query_packet(entries, lanes, address + 4 * PACKET_FIELDS * lanes, scene, address, arguments)
    return count


@njit(nogil=True, cache=True)
def intersect_chunk(words, first_ray, stop, query, rays, hits, inst_prim):
    """Rays first_ray .. stop of ``rays`` (``Rays``) through Embree's nearest-hit query
    (``query``: a ``Query``), their answers into ``hits`` (``NearestHits``), with ``words`` a
    uint32 scratch row of ``SCRATCH_WORDS``. ``inst_prim``: (n,) int32 for Embree's
    instPrimID[0] (instance arrays), or None; numba compiles the None case apart, with the test
    pruned: the plain loop pays nothing for it."""
    lanes = query.lanes
    floats, b = packet_layout(words)
    for first in range(first_ray, stop, lanes):
        count = traced_packet(words, floats, b, query, INTERSECT, rays, first, stop)
        for lane in range(count):
            i = first + lane
            if words[b + HIT_GEOM_ID * lanes + lane] == INVALID_ID:
                _store_miss(i, hits)
                if inst_prim is not None:
                    inst_prim[i] = -1
            else:
                hits.t[i] = floats[b + RAY_TFAR * lanes + lane]
                hits.prim[i] = np.int32(words[b + HIT_PRIM_ID * lanes + lane])
                hits.geom[i] = np.int32(words[b + HIT_GEOM_ID * lanes + lane])
                hits.inst[i] = np.int32(words[b + HIT_INST_ID * lanes + lane])
                if inst_prim is not None:
                    inst_prim[i] = np.int32(words[b + HIT_INST_PRIM_ID * lanes + lane])
                hits.normal[i, 0] = floats[b + HIT_NG * lanes + lane]
                hits.normal[i, 1] = floats[b + (HIT_NG + 1) * lanes + lane]
                hits.normal[i, 2] = floats[b + (HIT_NG + 2) * lanes + lane]
                hits.u[i] = floats[b + HIT_U * lanes + lane]
                hits.v[i] = floats[b + HIT_V * lanes + lane]


@njit(nogil=True, cache=True)
def occluded_chunk(words, first_ray, stop, query, rays, blocked):
    """Rays first_ray .. stop of ``rays`` (``Rays``) through Embree's occlusion query, whether
    each is blocked into ``blocked`` (n,) bool; ``query`` and ``words`` as ``intersect_chunk``'s."""
    lanes = query.lanes
    floats, b = packet_layout(words)
    for first in range(first_ray, stop, lanes):
        count = traced_packet(words, floats, b, query, OCCLUDED, rays, first, stop)
        for lane in range(count):
            blocked[first + lane] = floats[b + RAY_TFAR * lanes + lane] == -np.inf


@njit(inline="always")
def occluded_made(words, first, stop, query, make_ray, source, tfar, blocked):
    """Rays first .. stop made inside the kernel through Embree's occlusion query, whether
    each is blocked into ``blocked`` (n,) bool; ``query`` and ``words`` as ``occluded_chunk``'s.
    ``make_ray(origins, directions, lane, source, r)`` writes ray r of ``source`` into lane
    ``lane`` of a packet's (lanes, 3) float32 ``origins`` and ``directions`` (t in [0, ``tfar``],
    float32), and returns True where it finds the ray blocked without Embree (the lane is then
    filled again by the next ray). Inlined into a chunk kernel, which names its ``make_ray``."""
    lanes = query.lanes
    floats, b = packet_layout(words)
    origins = np.empty((lanes, 3), np.float32)
    directions = np.empty((lanes, 3), np.float32)
    tnear = np.zeros(lanes, np.float32)
    packet = Rays(origins, directions, tnear, np.full(lanes, tfar, np.float32))
    order = np.empty(lanes, np.int64)  # which ray each filled lane is
    r = first
    while r < stop:
        count = 0
        while count < lanes and r < stop:
            if make_ray(origins, directions, count, source, r):
                blocked[r] = True
            else:
                order[count] = r
                count += 1
            r += 1
        if count == 0:
            continue
        traced_packet(words, floats, b, query, OCCLUDED, packet, 0, count)
        for lane in range(count):
            blocked[order[lane]] = floats[b + RAY_TFAR * lanes + lane] == -np.inf


# The parallel drivers spread chunks over numba's threads (``work_split.over_chunks``); on one
# thread, a chunk kernel called from Python over all the rays needs no threading layer at all, so
# several Python threads may run it at once. ``query`` a ``Query``, ``rays`` a ``Rays``, ``hits`` a
# ``NearestHits`` to fill, ``inst_prim`` an (n,) int32 array for the hits' instance-array copy
# numbers, or None; ``blocked`` (n,) bool.


@njit(parallel=True, nogil=True, cache=True)
def intersect(query, rays, hits, inst_prim):
    n = rays.origins.shape[0]
    over_chunks(intersect_chunk, n, CHUNK, SCRATCH_WORDS, query, rays, hits, inst_prim)


@njit(parallel=True, nogil=True, cache=True)
def occluded(query, rays, blocked):
    n = rays.origins.shape[0]
    over_chunks(occluded_chunk, n, CHUNK, SCRATCH_WORDS, query, rays, blocked)
