"""Compiled query loops: numba kernels that call Embree's ray queries on all cores.

Each kernel walks its rays in chunks, one chunk per parallel iteration, and fills an
``RTCRayHit`` (or ``RTCRayHit8`` packet) in a scratch row owned by that chunk, so threads never
share memory and every ray's answer is independent of the thread count.

Embree's functions are linked by name (``numba.types.ExternalFunction``) with their addresses
registered in LLVM's symbol table, so the compiled kernels can be cached on disk.
"""

from __future__ import annotations

import llvmlite.binding as llvm
import numpy as np
from numba import njit, prange, types

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
RAYHIT_WORDS = 24
RAYHIT_ALIGN = 16

# RTCRayHit8: the same fields as structure-of-arrays, 8 lanes each, 32-byte aligned.
LANES = 8
PACKET_WORDS = 21 * LANES
PACKET_ALIGN = 32

INVALID_ID = library.INVALID_ID
SCRATCH_WORDS = PACKET_WORDS + PACKET_ALIGN // 4 + LANES  # packet + alignment slack + valid mask
CHUNK = 256  # rays per parallel iteration: small enough to balance, large enough to amortise

_SIGNATURE_1 = types.void(types.uintp, types.uintp, types.uintp)
_SIGNATURE_8 = types.void(types.uintp, types.uintp, types.uintp, types.uintp)
_NAMES = ("rtcIntersect1", "rtcOccluded1", "rtcIntersect8", "rtcOccluded8")


def register_symbols() -> None:
    """Tell LLVM where Embree's query functions live in this process (before kernels load)."""
    for name in _NAMES:
        llvm.add_symbol(name, library.function_address(name))


rtc_intersect1 = types.ExternalFunction("rtcIntersect1", _SIGNATURE_1)
rtc_occluded1 = types.ExternalFunction("rtcOccluded1", _SIGNATURE_1)
rtc_intersect8 = types.ExternalFunction("rtcIntersect8", _SIGNATURE_8)
rtc_occluded8 = types.ExternalFunction("rtcOccluded8", _SIGNATURE_8)


@njit(inline="always")
def _aligned_word(row: np.ndarray, alignment: int) -> int:
    return ((alignment - (row.ctypes.data & (alignment - 1))) & (alignment - 1)) >> 2


@njit(inline="always")
def _fill_ray(words, floats, b, i, origins, directions, tnear, tfar):
    floats[b + RAY_ORG] = origins[i, 0]
    floats[b + RAY_ORG + 1] = origins[i, 1]
    floats[b + RAY_ORG + 2] = origins[i, 2]
    floats[b + RAY_TNEAR] = tnear[i]
    floats[b + RAY_DIR] = directions[i, 0]
    floats[b + RAY_DIR + 1] = directions[i, 1]
    floats[b + RAY_DIR + 2] = directions[i, 2]
    floats[b + RAY_TIME] = 0.0
    floats[b + RAY_TFAR] = tfar[i]
    words[b + RAY_MASK] = 0xFFFFFFFF
    words[b + RAY_ID] = 0
    words[b + RAY_FLAGS] = 0


@njit(inline="always")
def _intersect1_chunk(scene, words, first, stop, origins, directions, tnear, tfar, t, normal,
                      u, v, prim, geom, inst):  # fmt: skip
    floats = words.view(np.float32)
    b = _aligned_word(words, RAYHIT_ALIGN)
    address = words.ctypes.data + 4 * b
    for i in range(first, stop):
        _fill_ray(words, floats, b, i, origins, directions, tnear, tfar)
        words[b + HIT_GEOM_ID] = INVALID_ID
        words[b + HIT_INST_ID] = INVALID_ID
        rtc_intersect1(scene, address, 0)
        if words[b + HIT_GEOM_ID] == INVALID_ID:
            _store_miss(i, t, normal, u, v, prim, geom, inst)
        else:
            t[i] = floats[b + RAY_TFAR]
            prim[i] = np.int32(words[b + HIT_PRIM_ID])
            geom[i] = np.int32(words[b + HIT_GEOM_ID])
            inst[i] = np.int32(words[b + HIT_INST_ID])
            normal[i, 0] = floats[b + HIT_NG]
            normal[i, 1] = floats[b + HIT_NG + 1]
            normal[i, 2] = floats[b + HIT_NG + 2]
            u[i] = floats[b + HIT_U]
            v[i] = floats[b + HIT_V]


@njit(inline="always")
def _store_miss(i, t, normal, u, v, prim, geom, inst):
    t[i] = np.inf
    prim[i] = -1
    geom[i] = -1
    inst[i] = -1
    normal[i, 0] = 0.0
    normal[i, 1] = 0.0
    normal[i, 2] = 0.0
    u[i] = 0.0
    v[i] = 0.0


@njit(inline="always")
def _occluded1_chunk(scene, words, first, stop, origins, directions, tnear, tfar, blocked):
    floats = words.view(np.float32)
    b = _aligned_word(words, RAYHIT_ALIGN)
    address = words.ctypes.data + 4 * b
    for i in range(first, stop):
        _fill_ray(words, floats, b, i, origins, directions, tnear, tfar)
        rtc_occluded1(scene, address, 0)
        blocked[i] = floats[b + RAY_TFAR] == -np.inf


@njit(inline="always")
def _fill_packet(words, floats, b, first, count, origins, directions, tnear, tfar):
    valid = b + PACKET_WORDS
    for lane in range(LANES):
        i = first + min(lane, count - 1)  # idle lanes repeat a live ray and are masked off
        floats[b + RAY_ORG * LANES + lane] = origins[i, 0]
        floats[b + (RAY_ORG + 1) * LANES + lane] = origins[i, 1]
        floats[b + (RAY_ORG + 2) * LANES + lane] = origins[i, 2]
        floats[b + RAY_TNEAR * LANES + lane] = tnear[i]
        floats[b + RAY_DIR * LANES + lane] = directions[i, 0]
        floats[b + (RAY_DIR + 1) * LANES + lane] = directions[i, 1]
        floats[b + (RAY_DIR + 2) * LANES + lane] = directions[i, 2]
        floats[b + RAY_TIME * LANES + lane] = 0.0
        floats[b + RAY_TFAR * LANES + lane] = tfar[i]
        words[b + RAY_MASK * LANES + lane] = 0xFFFFFFFF
        words[b + RAY_ID * LANES + lane] = 0
        words[b + RAY_FLAGS * LANES + lane] = 0
        words[b + HIT_GEOM_ID * LANES + lane] = INVALID_ID
        words[b + HIT_INST_ID * LANES + lane] = INVALID_ID
        words[valid + lane] = 0xFFFFFFFF if lane < count else 0


@njit(inline="always")
def _intersect8_chunk(scene, words, first_ray, stop, origins, directions, tnear, tfar, t, normal,
                      u, v, prim, geom, inst):  # fmt: skip
    floats = words.view(np.float32)
    b = _aligned_word(words, PACKET_ALIGN)
    address = words.ctypes.data + 4 * b
    valid_address = address + 4 * PACKET_WORDS
    for first in range(first_ray, stop, LANES):
        count = min(LANES, stop - first)
        _fill_packet(words, floats, b, first, count, origins, directions, tnear, tfar)
        rtc_intersect8(valid_address, scene, address, 0)
        for lane in range(count):
            i = first + lane
            if words[b + HIT_GEOM_ID * LANES + lane] == INVALID_ID:
                _store_miss(i, t, normal, u, v, prim, geom, inst)
            else:
                t[i] = floats[b + RAY_TFAR * LANES + lane]
                prim[i] = np.int32(words[b + HIT_PRIM_ID * LANES + lane])
                geom[i] = np.int32(words[b + HIT_GEOM_ID * LANES + lane])
                inst[i] = np.int32(words[b + HIT_INST_ID * LANES + lane])
                normal[i, 0] = floats[b + HIT_NG * LANES + lane]
                normal[i, 1] = floats[b + (HIT_NG + 1) * LANES + lane]
                normal[i, 2] = floats[b + (HIT_NG + 2) * LANES + lane]
                u[i] = floats[b + HIT_U * LANES + lane]
                v[i] = floats[b + HIT_V * LANES + lane]


@njit(inline="always")
def _occluded8_chunk(scene, words, first_ray, stop, origins, directions, tnear, tfar, blocked):
    floats = words.view(np.float32)
    b = _aligned_word(words, PACKET_ALIGN)
    address = words.ctypes.data + 4 * b
    valid_address = address + 4 * PACKET_WORDS
    for first in range(first_ray, stop, LANES):
        count = min(LANES, stop - first)
        _fill_packet(words, floats, b, first, count, origins, directions, tnear, tfar)
        rtc_occluded8(valid_address, scene, address, 0)
        for lane in range(count):
            blocked[first + lane] = floats[b + RAY_TFAR * LANES + lane] == -np.inf


# Drivers: the parallel ones spread chunks over numba's threads; the serial ones run in the
# calling thread with no threading layer at all, so several Python threads may call them at once.

SINGLE_WORDS = RAYHIT_WORDS + RAYHIT_ALIGN // 4


@njit(parallel=True, nogil=True, cache=True)
def intersect1(scene, origins, directions, tnear, tfar, t, normal, u, v, prim, geom, inst):
    n = origins.shape[0]
    n_chunks = (n + CHUNK - 1) // CHUNK
    scratch = np.empty((n_chunks, SINGLE_WORDS), np.uint32)
    for c in prange(n_chunks):
        _intersect1_chunk(scene, scratch[c], c * CHUNK, min(n, (c + 1) * CHUNK), origins,
                          directions, tnear, tfar, t, normal, u, v, prim, geom, inst)  # fmt: skip


@njit(nogil=True, cache=True)
def intersect1_serial(scene, origins, directions, tnear, tfar, t, normal, u, v, prim, geom, inst):
    scratch = np.empty(SINGLE_WORDS, np.uint32)
    _intersect1_chunk(scene, scratch, 0, origins.shape[0], origins, directions, tnear, tfar, t,
                      normal, u, v, prim, geom, inst)  # fmt: skip


@njit(parallel=True, nogil=True, cache=True)
def occluded1(scene, origins, directions, tnear, tfar, blocked):
    n = origins.shape[0]
    n_chunks = (n + CHUNK - 1) // CHUNK
    scratch = np.empty((n_chunks, SINGLE_WORDS), np.uint32)
    for c in prange(n_chunks):
        _occluded1_chunk(scene, scratch[c], c * CHUNK, min(n, (c + 1) * CHUNK), origins,
                         directions, tnear, tfar, blocked)  # fmt: skip


@njit(nogil=True, cache=True)
def occluded1_serial(scene, origins, directions, tnear, tfar, blocked):
    scratch = np.empty(SINGLE_WORDS, np.uint32)
    _occluded1_chunk(scene, scratch, 0, origins.shape[0], origins, directions, tnear, tfar,
                     blocked)  # fmt: skip


@njit(parallel=True, nogil=True, cache=True)
def intersect8(scene, origins, directions, tnear, tfar, t, normal, u, v, prim, geom, inst):
    n = origins.shape[0]
    n_chunks = (n + CHUNK - 1) // CHUNK
    scratch = np.empty((n_chunks, SCRATCH_WORDS), np.uint32)
    for c in prange(n_chunks):
        _intersect8_chunk(scene, scratch[c], c * CHUNK, min(n, (c + 1) * CHUNK), origins,
                          directions, tnear, tfar, t, normal, u, v, prim, geom, inst)  # fmt: skip


@njit(nogil=True, cache=True)
def intersect8_serial(scene, origins, directions, tnear, tfar, t, normal, u, v, prim, geom, inst):
    scratch = np.empty(SCRATCH_WORDS, np.uint32)
    _intersect8_chunk(scene, scratch, 0, origins.shape[0], origins, directions, tnear, tfar, t,
                      normal, u, v, prim, geom, inst)  # fmt: skip


@njit(parallel=True, nogil=True, cache=True)
def occluded8(scene, origins, directions, tnear, tfar, blocked):
    n = origins.shape[0]
    n_chunks = (n + CHUNK - 1) // CHUNK
    scratch = np.empty((n_chunks, SCRATCH_WORDS), np.uint32)
    for c in prange(n_chunks):
        _occluded8_chunk(scene, scratch[c], c * CHUNK, min(n, (c + 1) * CHUNK), origins,
                         directions, tnear, tfar, blocked)  # fmt: skip


@njit(nogil=True, cache=True)
def occluded8_serial(scene, origins, directions, tnear, tfar, blocked):
    scratch = np.empty(SCRATCH_WORDS, np.uint32)
    _occluded8_chunk(scene, scratch, 0, origins.shape[0], origins, directions, tnear, tfar,
                     blocked)  # fmt: skip
