"""A coherent tracing order for batches of incoherent rays: a Morton code of where each ray
enters the mesh's bounding box (``morton.spread_bits``), sorted by ``morton.radix_order``.

Why: a ray's traversal reads the BVH nodes and triangles around where it goes, and on a big
mesh (a million triangles: a BVH of ~100 MB) those reads miss every cache level when
consecutive rays go to unrelated places. Traced in the order of where they enter the box,
consecutive rays mostly meet the same part of the mesh, so the nodes and triangles one ray
fetched are still in cache for the next. Measured on a 1.3M-triangle icosphere and a 1e5-triangle
height field with trimesh's benchmark rays (from a sphere around the mesh toward random points
in it), one thread: 1.25-1.6x the random order's rate; the ray's origin alone gave 1.1x, origin
and direction together 1.15-1.4x (the entry point is the nearest cheap stand-in for where the
ray hits, and ordering by the true hit point gave 1.8x). On a 2,304-triangle mesh, whose BVH
fits in cache, 1.08x: less than the sort costs.

For all hits a ray's traversal visits the nodes along its whole path through the box, not just
around its first hit, so ``segment_key`` keys it by the middle of that path: with the same rays
and the filtered all-hits traversal (``multihit.all_hits``), one thread, the middle gave
1.2-1.3x the random order's rate on the icosphere, 1.4-1.45x on the height field and 1.1x on
the 2,304-triangle torus; the entry point 1.05-1.15x, 1.15x and 1.05x; Morton codes of entry and
exit together (6-D) or of the middle and the direction fell in between.

The order changes nothing in any ray's answer: each ray is still one single-ray query of an
immutable BVH, whose result depends on that ray alone (see the callers).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from embree_rt.compiled.morton import CELLS, spread_bits


@njit(inline="always")
def _box_span(origin, direction, lower, upper):
    """(near, far): the ray's parameters where it enters (0 when it starts inside) and leaves
    the box ``lower`` .. ``upper``; near > far when it misses."""
    near, far = 0.0, math.inf
    for k in range(3):
        d = direction[k]
        if d == 0.0:
            if origin[k] < lower[k] or origin[k] > upper[k]:
                far = -1.0  # parallel to this slab and outside it
        else:
            reciprocal = 1.0 / d
            t0 = (lower[k] - origin[k]) * reciprocal
            t1 = (upper[k] - origin[k]) * reciprocal
            near = max(near, min(t0, t1))
            far = min(far, max(t0, t1))
    return near, far


@njit(inline="always")
def _point_code(origin, direction, step, lower, cells_per_unit):
    """uint32 Morton code of the point ``origin + step * direction`` clamped to the grid."""
    code = np.uint32(0)
    for k in range(3):
        cell = (origin[k] + step * direction[k] - lower[k]) * cells_per_unit[k]
        cell = min(max(cell, 0.0), float(CELLS))  # also maps nan (a non-finite ray) to 0
        code |= np.uint32(spread_bits(np.uint32(cell))) << np.uint32(k)
    return code


@njit(inline="always")
def entry_key(origin, direction, lower, upper, cells_per_unit):
    """uint32 Morton code of where the ray ``origin``, ``direction`` ((3,) float64 rows) enters
    the box ``lower`` .. ``upper`` ((3,) float64), on a grid of 1024 cells an axis
    (``cells_per_unit`` (3,): 1023 / the box's size, 0 along a flat axis); a ray starting inside
    is keyed by its origin, one that misses by its origin clamped to the box."""
    near, far = _box_span(origin, direction, lower, upper)
    step = near if near <= far else 0.0
    return _point_code(origin, direction, step, lower, cells_per_unit)


@njit(inline="always")
def segment_key(origin, direction, lower, upper, cells_per_unit):
    """uint32 Morton code of the middle of the ray's segment inside the box ``lower`` ..
    ``upper`` (arguments as ``entry_key``'s; the segment from where the ray enters, or its
    origin when it starts inside, to where it leaves), for queries that follow each ray through
    the whole box (all hits) rather than to its first hit; a ray that misses is keyed by its
    origin clamped to the box."""
    near, far = _box_span(origin, direction, lower, upper)
    step = 0.5 * (near + far) if near <= far and far < math.inf else 0.0
    return _point_code(origin, direction, step, lower, cells_per_unit)


def box_cells(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """(3,) float64 grid cells per unit length along each axis of the box ``lower`` ..
    ``upper`` for ``entry_key`` (0 along an axis where the box is flat)."""
    size = np.asarray(upper, np.float64) - np.asarray(lower, np.float64)
    with np.errstate(divide="ignore"):
        return np.where(size > 0, CELLS / np.where(size > 0, size, 1.0), 0.0)


class Box(NamedTuple):
    """The box rays are keyed in: ``lower``, ``upper`` (3,) float64 corners and
    ``cells_per_unit`` (3,) float64 (``box_cells``)."""

    lower: np.ndarray
    upper: np.ndarray
    cells_per_unit: np.ndarray


def box(bounds: np.ndarray) -> Box:
    """The ``Box`` of ``bounds`` (2, 3) float (lower and upper corners)."""
    lower, upper = np.asarray(bounds, np.float64)
    return Box(lower, upper, box_cells(lower, upper))
