"""Instance arrays: n placements of committed child BVHs as ONE Embree geometry, compiled.

Embree 4's ``RTC_GEOMETRY_TYPE_INSTANCE_ARRAY`` holds n instances in one geometry: the
transforms are one ``RTC_BUFFER_TYPE_TRANSFORM`` buffer (here ``RTC_FORMAT_FLOAT3X4_ROW_MAJOR``,
NumPy's ``M[:, :3, :4]`` as float32, 48 bytes an instance) and, for several children, an
``RTC_BUFFER_TYPE_INDEX`` buffer of ``RTC_FORMAT_UINT`` picking each instance's child scene. A
hit reports ``instID[0]`` = the array's geometry id and ``instPrimID[0]`` = the instance's index
(``RTCHit`` word 20; in a packet, word 20·N + lane), with ``Ng`` in the child's own space.

This module holds the compiled passes that know about them:

- ``intersect`` / ``intersect_serial``: the query kernels of ``kernels`` that also copy out
  ``instPrimID`` (used only by BVHs holding instance arrays, so the others keep the lean loop).
- ``hits_to_world``: world normals of instance-array hits for ``BVH.intersect``.
- ``finish_records``: the same for ``BVH.intersect_records``' hit records, with each
  instance's own label and coordinate bound.

None of them needs a per-instance (n, 3, 3) normal table: the world normal is computed from
the instance's (3, 4) transform itself, as cofactor(M) · n / det(M) (= M⁻ᵀ n). Dividing by the
determinant, not only by its size, keeps the normal on the same side of the surface under a
mirroring transform (det < 0), so it keeps its relation to the ray: n_world · d_world =
n · (M⁻¹ d_world) = n · d_object.

Each BVH describes its arrays to these passes in one table, ``ARRAY_*`` columns by top-level
geometry id, (g, ``ARRAY_COLUMNS``) uint64: the address of the (n, 3, 4) float32 transforms (0:
the geometry is not an instance array), n, the address of the (n,) uint32 child index (0: one
child), the address of the (c,) float32 coordinate bound of each child, and the address of the
caller's (n,) int32 per-instance labels (0: the geometry's label for all).
"""

from __future__ import annotations

import math

import numpy as np
from numba import carray, njit

from embree_rt.compiled import pointers

ARRAY_TRANSFORMS = 0
ARRAY_COUNT = 1
ARRAY_CHILD_INDEX = 2
ARRAY_CHILD_BOUND = 3
ARRAY_LABELS = 4
ARRAY_COLUMNS = 5


_float_pointer = pointers.floats
_uint_pointer = pointers.words32
_int_pointer = pointers.ints


# -- normals ----------------------------------------------------------------------------------


@njit(inline="always")
def _transforms(table, g):
    return carray(_float_pointer(table[g, ARRAY_TRANSFORMS]), (table[g, ARRAY_COUNT], 3, 4))


@njit(inline="always")
def _world_normal(m, p, gx, gy, gz):
    """M⁻ᵀ (gx, gy, gz) in float64 for instance ``p`` of the (n, 3, 4) transforms ``m``: the
    cofactor matrix of the 3 × 3 part times the normal, over its determinant (sign included)."""
    a = np.float64(m[p, 0, 0])
    b = np.float64(m[p, 0, 1])
    c = np.float64(m[p, 0, 2])
    d = np.float64(m[p, 1, 0])
    e = np.float64(m[p, 1, 1])
    f = np.float64(m[p, 1, 2])
    g = np.float64(m[p, 2, 0])
    h = np.float64(m[p, 2, 1])
    k = np.float64(m[p, 2, 2])
    c00 = e * k - f * h
    c01 = f * g - d * k
    c02 = d * h - e * g
    c10 = c * h - b * k
    c11 = a * k - c * g
    c12 = b * g - a * h
    c20 = b * f - c * e
    c21 = c * d - a * f
    c22 = a * e - b * d
    determinant = a * c00 + b * c01 + c * c02
    wx = (c00 * gx + c01 * gy + c02 * gz) / determinant
    wy = (c10 * gx + c11 * gy + c12 * gz) / determinant
    wz = (c20 * gx + c21 * gy + c22 * gz) / determinant
    return wx, wy, wz


@njit(nogil=True, cache=True)
def hits_to_world(inst, inst_prim, normal, table):
    """In place, for n raw hits: ``normal`` (n, 3) float32 from the child's space to world
    space where the hit is in an instance array (M⁻ᵀ n, unnormalised), and ``inst_prim`` (n,)
    int32 set to -1 where it is not. ``inst`` (n,) int32 top-level ids, ``table`` the BVH's
    array table (see the module docstring)."""
    for i in range(inst.shape[0]):
        g = inst[i]
        if g < 0 or g >= table.shape[0] or table[g, ARRAY_TRANSFORMS] == 0:
            inst_prim[i] = -1
            continue
        wx, wy, wz = _world_normal(_transforms(table, g), inst_prim[i], np.float64(normal[i, 0]),
                                   np.float64(normal[i, 1]), np.float64(normal[i, 2]))  # fmt: skip
        normal[i, 0] = wx
        normal[i, 1] = wy
        normal[i, 2] = wz


@njit(nogil=True, cache=True)
def normals_to_world(inst, inst_prim, normals, table):
    """(3, k) float32 unit world normals of k instance-array hits from ``normals`` (3, k) in
    their child's space (``inst``, ``inst_prim`` (k,) int32 each hit's array and instance);
    columns of other hits are copied unchanged."""
    k = inst.shape[0]
    out = np.empty((3, k), np.float32)
    for j in range(k):
        g = inst[j]
        if g < 0 or g >= table.shape[0] or table[g, ARRAY_TRANSFORMS] == 0:
            out[0, j] = normals[0, j]
            out[1, j] = normals[1, j]
            out[2, j] = normals[2, j]
            continue
        wx, wy, wz = _world_normal(
            _transforms(table, g), inst_prim[j], np.float64(normals[0, j]),
            np.float64(normals[1, j]), np.float64(normals[2, j]),
        )  # fmt: skip
        length = math.sqrt(wx * wx + wy * wy + wz * wz)
        if length == 0.0:
            length = 1.0
        out[0, j] = wx / length
        out[1, j] = wy / length
        out[2, j] = wz / length
    return out


@njit(nogil=True, cache=True)
def child_of_hits(inst, inst_prim, table):
    """(k,) int32: which of its array's children each of k hits is in (0 for a one-child array;
    -1 for a hit outside any instance array)."""
    k = inst.shape[0]
    out = np.full(k, -1, np.int32)
    for j in range(k):
        g = inst[j]
        if g < 0 or g >= table.shape[0] or table[g, ARRAY_TRANSFORMS] == 0:
            continue
        if table[g, ARRAY_CHILD_INDEX] == 0:
            out[j] = 0
        else:
            index = carray(_uint_pointer(table[g, ARRAY_CHILD_INDEX]), table[g, ARRAY_COUNT])
            out[j] = np.int32(index[inst_prim[j]])
    return out


# -- hit records ------------------------------------------------------------------------------


@njit(nogil=True, cache=True)
def finish_records(rays, start, stop, inst, inst_prim, ng, normal, label, scale, table):
    """Complete ``records.build_records``' output for the instance-array hits among columns
    [start, stop) (its "other" group), in place, and return their (stop - start,) int32
    instance numbers (-1 for hits outside an instance array).

    Per ray: ``rays`` (k,) int64 the ray of each column; ``inst``, ``inst_prim`` (n,) int32 and
    ``ng`` (n, 3) float32 the raw hits (Ng in the child's space). Per column, overwritten for
    instance-array hits: ``normal`` (3, k) float32 the unit world normal; ``label`` (k,) int64
    the instance's own label where the array has per-instance labels; ``scale`` (k,) float32 a
    bound on the coordinates of the instance: max over axes of |translation| + the child's
    coordinate bound × the row's sum of |M|, which contains the instance's whole child.
    """
    out = np.full(stop - start, -1, np.int32)
    for j in range(start, stop):
        i = rays[j]
        g = inst[i]
        if g < 0 or g >= table.shape[0] or table[g, ARRAY_TRANSFORMS] == 0:
            continue
        p = inst_prim[i]
        out[j - start] = p
        m = _transforms(table, g)
        wx, wy, wz = _world_normal(m, p, np.float64(ng[i, 0]), np.float64(ng[i, 1]),
                                   np.float64(ng[i, 2]))  # fmt: skip
        length = math.sqrt(wx * wx + wy * wy + wz * wz)
        if length == 0.0:
            length = 1.0
        normal[0, j] = wx / length
        normal[1, j] = wy / length
        normal[2, j] = wz / length
        if table[g, ARRAY_LABELS] != 0:
            labels = carray(_int_pointer(table[g, ARRAY_LABELS]), table[g, ARRAY_COUNT])
            label[j] = labels[p]
        child = 0
        if table[g, ARRAY_CHILD_INDEX] != 0:
            index = carray(_uint_pointer(table[g, ARRAY_CHILD_INDEX]), table[g, ARRAY_COUNT])
            child = index[p]
        bound = np.float64(
            carray(_float_pointer(table[g, ARRAY_CHILD_BOUND]), child + 1)[child]
        )
        largest = 0.0
        for row in range(3):
            reach = abs(np.float64(m[p, row, 3])) + bound * (
                abs(np.float64(m[p, row, 0])) + abs(np.float64(m[p, row, 1]))
                + abs(np.float64(m[p, row, 2]))
            )  # fmt: skip
            largest = max(largest, reach)
        scale[j] = largest
    return out
