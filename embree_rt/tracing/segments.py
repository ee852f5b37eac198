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
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from embree_rt.compiled.work_split import chunk_scratch, chunk_span, over_chunks
from embree_rt.embree import BVH
from embree_rt.embree.kernels import (
    CHUNK,
    OCCLUDED,
    RAY_TFAR,
    SCRATCH_WORDS,
    Rays,
    occluded_made,
    packet_layout,
    traced_packet,
)
from embree_rt.embree.validation import as_indices, as_points
from embree_rt.tracing.records import plane_crossing


class Segments(NamedTuple):
    """k segments from surface points to one target: ``points`` (3, n) float32, ``rows`` (k,)
    int64 the column of each segment's point, ``target`` (3,) float32; with ``has_plane`` the
    ground plane y = ``plane_y`` (float32) blocks too."""

    points: np.ndarray
    rows: np.ndarray
    target: np.ndarray
    has_plane: bool
    plane_y: np.float32


@njit(inline="always")
def _segment_lane(origins, directions, lane, points, r, target, has_plane, plane_y):
    """Write the segment from ``points[:, r]`` to ``target`` into packet lane ``lane`` (the
    direction ``target - p`` in float32, as NumPy forms it); True when the ground plane blocks
    it (then the lane is not used)."""
    for axis in range(3):
        origins[lane, axis] = points[axis, r]
        directions[lane, axis] = target[axis] - points[axis, r]
    if not has_plane:
        return False
    crossing = plane_crossing(
        origins[lane, 1], directions[lane, 1], np.float32(0.0), np.float32(1.0), plane_y
    )
    return not math.isnan(crossing)


@njit(inline="always")
def _listed_segment_lane(origins, directions, lane, segments, k):
    """``_segment_lane`` of segment ``k`` of ``segments`` (``Segments``)."""
    points, rows, target, has_plane, plane_y = segments
    return _segment_lane(origins, directions, lane, points, rows[k], target, has_plane, plane_y)


@njit(nogil=True, cache=True)
def occluded_toward_chunk(words, first_row, stop, query, segments, blocked):
    """Segments first_row .. stop: whether each is blocked, into ``blocked``; ``words`` a
    scratch row of ``kernels.SCRATCH_WORDS``."""
    one = np.float32(1.0)
    occluded_made(words, first_row, stop, query, _listed_segment_lane, segments, one, blocked)


# ``query`` a ``kernels.Query``, ``segments`` a ``Segments``, ``blocked`` (k,) bool out.


@njit(parallel=True, nogil=True, cache=True)
def occluded_segments(query, segments, blocked):
    n = segments.rows.shape[0]
    over_chunks(occluded_toward_chunk, n, CHUNK, SCRATCH_WORDS, query, segments, blocked)


class LightSegments(NamedTuple):
    """Segments from n surface points to one light, made only where they can carry its light:
    ``points`` (3, n) float32, ``normals`` (3, n) float32 unit normals on the points' side
    (a segment is made where ``(target - p) · normal > 0``), ``takes`` (n,) bool which points
    take light at all (empty: every point), ``target`` (3,) float32; with ``has_plane`` the
    ground plane y = ``plane_y`` (float32) blocks too."""

    points: np.ndarray
    normals: np.ndarray
    takes: np.ndarray
    target: np.ndarray
    has_plane: bool
    plane_y: np.float32


@njit(nogil=True, cache=True)
def toward_light_chunk(words, first, stop, query, light, visible, directions):
    """Points first .. stop of ``light`` (``LightSegments``): ``visible`` (n,) bool and the
    unit ``directions`` (3, n) float32 toward the light set where visible (both all zero on
    entry); returns how many segments were made (the points facing the light)."""
    lanes = query.lanes
    points, normals, takes, target, has_plane, plane_y = light
    floats, b = packet_layout(words)
    origins = np.empty((lanes, 3), np.float32)
    toward = np.empty((lanes, 3), np.float32)
    packet = Rays(origins, toward, np.zeros(lanes, np.float32), np.ones(lanes, np.float32))
    order = np.empty(lanes, np.int64)  # which point each filled lane is
    all_take = takes.shape[0] == 0
    made = 0
    i = first
    while i < stop:
        count = 0
        while count < lanes and i < stop:
            r = i
            i += 1
            if not (all_take or takes[r]):
                continue
            # (target - p) · normal, summed as shading.dot sums: (x + y) + z
            facing = (target[0] - points[0, r]) * normals[0, r]
            facing += (target[1] - points[1, r]) * normals[1, r]
            facing += (target[2] - points[2, r]) * normals[2, r]
            if not facing > 0:
                continue
            made += 1
            if not _segment_lane(origins, toward, count, points, r, target, has_plane, plane_y):
                order[count] = r
                count += 1
        if count == 0:
            continue
        traced_packet(words, floats, b, query, OCCLUDED, packet, 0, count)
        for lane in range(count):
            if floats[b + RAY_TFAR * lanes + lane] == -np.inf:
                continue
            r = order[lane]
            visible[r] = True
            # the unit direction as shading.normalize forms it: v · (1 / max(|v|, 1e-30))
            x, y, z = toward[lane, 0], toward[lane, 1], toward[lane, 2]
            length = np.sqrt(x * x + y * y + z * z)
            inverse = np.float32(1.0) / max(length, np.float32(1e-30))
            directions[0, r] = x * inverse
            directions[1, r] = y * inverse
            directions[2, r] = z * inverse
    return made


# ``query`` a ``kernels.Query``, ``light`` a ``LightSegments``, ``visible`` (n,) bool and
# ``directions`` (3, n) float32 out, zeros on entry; each returns the number of segments made.


@njit(parallel=True, nogil=True, cache=True)
def toward_light(query, light, visible, directions):
    n = light.points.shape[1]
    scratch = chunk_scratch(n, CHUNK, SCRATCH_WORDS)
    made = np.zeros(len(scratch), np.int64)
    for c in prange(len(scratch)):
        first, stop = chunk_span(c, CHUNK, n)
        made[c] = toward_light_chunk(scratch[c], first, stop, query, light, visible, directions)
    return made.sum()


def occluded_toward(
    bvh: BVH,
    points: np.ndarray,
    rows: np.ndarray,
    target: np.ndarray,
    plane_y: float | None = None,
) -> np.ndarray:
    """(k,) bool: whether anything in ``bvh`` (with ``plane_y``, the ground plane y = plane_y
    too) lies on the segment from each point ``points[:, rows[i]]`` to ``target``, the ray
    ``p + t (target - p)`` with t in [0, 1]: the answers ``BVH.occluded`` gives for those rays,
    which are built inside the kernel. ``points`` (3, n) float, ``rows`` (k,) int indices into
    its columns, ``target`` (3,)."""
    query = bvh.query(False)
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[0] != 3:
        raise ValueError(f"points: expected shape (3, n), got {points.shape}")
    points = np.ascontiguousarray(as_points(points.T, "points").T)
    rows = as_indices(rows, "rows", points.shape[1])
    target = as_points(np.reshape(target, (1, 3)), "target")[0].copy()
    blocked = np.zeros(len(rows), bool)
    if len(rows):
        has_plane = plane_y is not None
        shadow = Segments(
            points, rows, target, has_plane, np.float32(plane_y if has_plane else 0.0)
        )
        arguments = (query, shadow, blocked)
        bvh.run_query(occluded_toward_chunk, occluded_segments, arguments, len(rows))
    return blocked


def toward_lights(
    bvh: BVH,
    points: np.ndarray,
    normals: np.ndarray,
    targets: np.ndarray,
    takes: np.ndarray,
    plane_y: float | None = None,
) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
    """Per light, what each of n surface points sees of it in ``bvh``: for each row of
    ``targets`` (L, 3) in turn (computed when asked for), (n,) bool ``visible``, (3, n) float32
    unit ``directions`` toward the light where visible (zero elsewhere) and the number of
    shadow segments made. A segment ``p + t (target - p)``, t in [0, 1], is made from each
    point ``points`` (3, n) float whose unit normal ``normals`` (3, n) float faces the light
    (``(target - p) · normal > 0``) and that ``takes`` ((n,) bool) light; it is the segment
    ``occluded_toward`` traces, built inside the kernel, and the plane y = ``plane_y`` blocks
    it too. The points are checked once for all lights."""
    query = bvh.query(False)
    points, normals = (np.asarray(values) for values in (points, normals))
    for name, values in (("points", points), ("normals", normals)):
        if values.ndim != 2 or values.shape != (3, points.shape[-1]):
            raise ValueError(f"{name}: expected shape (3, n), got {values.shape}")
    n = points.shape[1]
    points = np.ascontiguousarray(as_points(points.T, "points").T)
    normals = np.ascontiguousarray(as_points(normals.T, "normals").T)
    targets = as_points(np.reshape(targets, (-1, 3)), "targets")
    if np.shape(takes) != (n,) or np.asarray(takes).dtype != bool:
        raise ValueError(f"takes: expected ({n},) bool, got {np.shape(takes)}")
    takes = np.ascontiguousarray(takes)
    has_plane = plane_y is not None
    plane = np.float32(plane_y if has_plane else 0.0)
    for target in targets:
        visible = np.zeros(n, bool)
        directions = np.zeros((3, n), np.float32)
        made = 0
        if n:
            light = LightSegments(points, normals, takes, target.copy(), has_plane, plane)
            made = bvh.run_query(
                toward_light_chunk, toward_light, (query, light, visible, directions), n
            )
        yield visible, directions, int(made)
