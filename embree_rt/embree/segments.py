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
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from embree_rt.compiled.work_split import chunk_scratch, chunk_span
from embree_rt.embree.kernels import (
    CHUNK,
    OCCLUDED,
    RAY_TFAR,
    SCRATCH_WORDS,
    Rays,
    packet_layout,
    traced_packet,
)
from embree_rt.embree.records import plane_crossing


class Segments(NamedTuple):
    """k segments from surface points to one target: ``points`` (3, n) float32, ``rows`` (k,)
    int64 the column of each segment's point, ``target`` (3,) float32; with ``has_plane`` the
    ground plane y = ``plane_y`` (float32) blocks too."""

    points: np.ndarray
    rows: np.ndarray
    target: np.ndarray
    has_plane: bool
    plane_y: np.float32


@njit(nogil=True, cache=True)
def occluded_toward_chunk(words, first_row, stop, query, segments, blocked):
    """Segments first_row .. stop: whether each is blocked, into ``blocked``; ``words`` a
    scratch row of ``kernels.SCRATCH_WORDS``."""
    lanes = query.lanes
    points, rows, target, has_plane, plane_y = segments
    floats, b = packet_layout(words)
    # One packet's rays at a time, as traced_packet takes them: (lanes, 3) origins, directions.
    origins = np.empty((lanes, 3), np.float32)
    directions = np.empty((lanes, 3), np.float32)
    packet = Rays(origins, directions, np.zeros(lanes, np.float32), np.ones(lanes, np.float32))
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
                crossing = plane_crossing(
                    origins[count, 1],
                    directions[count, 1],
                    np.float32(0.0),
                    np.float32(1.0),
                    plane_y,
                )
            if not math.isnan(crossing):
                blocked[k] = True
            else:
                order[count] = k
                count += 1
            k += 1
        if count == 0:
            continue
        traced_packet(words, floats, b, query, OCCLUDED, packet, 0, count)
        for lane in range(count):
            blocked[order[lane]] = floats[b + RAY_TFAR * lanes + lane] == -np.inf


# ``query`` a ``kernels.Query``, ``segments`` a ``Segments``, ``blocked`` (k,) bool out.


@njit(parallel=True, nogil=True, cache=True)
def occluded_toward(query, segments, blocked):
    n = segments.rows.shape[0]
    scratch = chunk_scratch(n, CHUNK, SCRATCH_WORDS)
    for c in prange(len(scratch)):
        first, stop = chunk_span(c, CHUNK, n)
        occluded_toward_chunk(scratch[c], first, stop, query, segments, blocked)
