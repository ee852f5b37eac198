"""Occlusion of segments from surface points to one point (a light), built inside the kernel.

A renderer's shadow rays run from a subset of its shading points to each light, as the segment
``p + t (light - p)``, t in [0, 1]. Made in NumPy they cost two gathers and a subtraction per
axis, two (k, 3) arrays, their validation and a second compiled pass for the ground plane; here
each packet is filled straight from the points' columns, the direction formed in float32 as
NumPy would form it (so the rays, and the answers, are bitwise the ones ``BVH.occluded`` gives
for the same segments), and the analytic ground plane is tested before Embree is asked: a
segment the plane blocks needs no traversal.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from embree_rt.embree.kernels import (
    CHUNK,
    PACKET_ALIGN,
    PACKET_FIELDS,
    RAY_TFAR,
    SCRATCH_WORDS,
    aligned_word,
    fill_packet,
    occluded_packet,
)
from embree_rt.embree.records import plane_crossing


@njit(inline="always")
def _segments_chunk(scene, query, lanes, words, first_row, stop, points, rows, target, has_plane,
                    plane_y, blocked):  # fmt: skip
    floats = words.view(np.float32)
    b = aligned_word(words, PACKET_ALIGN)
    address = words.ctypes.data + 4 * b
    valid_address = address + 4 * PACKET_FIELDS * lanes
    # One packet's rays at a time, as fill_packet takes them: (lanes, 3) origins, directions.
    origins = np.empty((lanes, 3), np.float32)
    directions = np.empty((lanes, 3), np.float32)
    near = np.zeros(lanes, np.float32)
    far = np.ones(lanes, np.float32)
    order = np.empty(lanes, np.int64)  # which segment each filled lane is
    k = first_row
    while k < stop:
        count = 0
        while count < lanes and k < stop:
            r = rows[k]
            for axis in range(3):
                origins[count, axis] = points[axis, r]
                directions[count, axis] = target[axis] - points[axis, r]
            crossing = np.float32(np.nan)
            if has_plane:
                crossing = plane_crossing(origins[count, 1], directions[count, 1],
                                          np.float32(0.0), np.float32(1.0), plane_y)  # fmt: skip
            if not math.isnan(crossing):
                blocked[k] = True
            else:
                order[count] = k
                count += 1
            k += 1
        if count == 0:
            continue
        fill_packet(words, floats, b, lanes, 0, count, origins, directions, near, far)
        occluded_packet(lanes, valid_address, scene, address, query)
        for lane in range(count):
            blocked[order[lane]] = floats[b + RAY_TFAR * lanes + lane] == -np.inf


# ``points`` (3, n) float32, ``rows`` (k,) int64 indices into its columns, ``target`` (3,)
# float32, ``blocked`` (k,) bool out; ``query`` and ``lanes`` as in ``kernels``.


@njit(parallel=True, nogil=True, cache=True)
def occluded_toward(scene, query, lanes, points, rows, target, has_plane, plane_y, blocked):
    n = rows.shape[0]
    n_chunks = (n + CHUNK - 1) // CHUNK
    scratch = np.empty((n_chunks, SCRATCH_WORDS), np.uint32)
    for c in prange(n_chunks):
        _segments_chunk(scene, query, lanes, scratch[c], c * CHUNK, min(n, (c + 1) * CHUNK),
                        points, rows, target, has_plane, plane_y, blocked)  # fmt: skip


@njit(nogil=True, cache=True)
def occluded_toward_serial(scene, query, lanes, points, rows, target, has_plane, plane_y,
                           blocked):  # fmt: skip
    scratch = np.empty(SCRATCH_WORDS, np.uint32)
    _segments_chunk(scene, query, lanes, scratch, 0, rows.shape[0], points, rows, target,
                    has_plane, plane_y, blocked)  # fmt: skip
