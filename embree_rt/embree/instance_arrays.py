"""Instance arrays: n placements of committed child BVHs as ONE Embree geometry, compiled.

Embree 4's ``RTC_GEOMETRY_TYPE_INSTANCE_ARRAY`` holds n instances in one geometry: the
transforms are one ``RTC_BUFFER_TYPE_TRANSFORM`` buffer (here ``RTC_FORMAT_FLOAT3X4_ROW_MAJOR``,
NumPy's ``M[:, :3, :4]`` as float32, 48 bytes an instance) and, for several children, an
``RTC_BUFFER_TYPE_INDEX`` buffer of ``RTC_FORMAT_UINT`` picking each instance's child scene. A
hit reports ``instID[0]`` = the array's geometry id and ``instPrimID[0]`` = the instance's index
(``RTCHit`` word 20; in a packet, word 20·N + lane), with ``Ng`` in the child's own space.

This module holds the table that describes them to compiled passes, and what reads a hit's
array, instance and child from it (``is_array``, ``transforms_of``, ``child_of_hits``). World
normals of their hits are ``world_normals``'.

Each BVH describes its arrays to these passes in one table, ``ARRAY_*`` columns by top-level
geometry id, (g, ``ARRAY_COLUMNS``) uint64: the address of the (n, 3, 4) float32 transforms (0:
the geometry is not an instance array), n, the address of the (n,) uint32 child index (0: one
child), the address of the (c,) float32 coordinate bound of each child, and the address of the
caller's (n,) int32 per-instance labels (0: the geometry's label for all).
"""

from __future__ import annotations

import numpy as np
from numba import carray, njit

from embree_rt.compiled import pointers

ARRAY_TRANSFORMS = 0
ARRAY_COUNT = 1
ARRAY_CHILD_INDEX = 2
ARRAY_CHILD_BOUND = 3
ARRAY_LABELS = 4
ARRAY_COLUMNS = 5


@njit(inline="always")
def is_array(table, g):
    """Whether top-level geometry ``g`` is an instance array in the BVH's array ``table``."""
    return g >= 0 and g < table.shape[0] and table[g, ARRAY_TRANSFORMS] != 0


@njit(inline="always")
def transforms_of(table, g):
    """The (n, 3, 4) float32 transforms of instance array ``g``, where the BVH keeps them."""
    return carray(pointers.floats(table[g, ARRAY_TRANSFORMS]), (table[g, ARRAY_COUNT], 3, 4))


@njit(nogil=True, cache=True)
def child_of_hits(inst, inst_prim, table):
    """(k,) int32: which of its array's children each of k hits is in (0 for a one-child array;
    -1 for a hit outside any instance array)."""
    k = inst.shape[0]
    out = np.full(k, -1, np.int32)
    for j in range(k):
        g = inst[j]
        if not is_array(table, g):
            continue
        if table[g, ARRAY_CHILD_INDEX] == 0:
            out[j] = 0
        else:
            index = carray(pointers.words32(table[g, ARRAY_CHILD_INDEX]), table[g, ARRAY_COUNT])
            out[j] = np.int32(index[inst_prim[j]])
    return out
