"""World normals of instance hits: Embree reports an instance hit's geometric normal in the
instanced object's own space; one compiled rule takes it to world space for single instances
and instance arrays alike (``world_normal``), and every query that reports normals applies it.

Single instances (``BVH.add_instance``) and top-level geometry read a (g, 3, 3) float32 table by
top-level geometry id: the inverse-transpose of each instance's linear part, computed in float64
and rounded once (the identity for geometry that is not an instance); the product is taken in
float32. Instance arrays (``BVH.add_instances``) need no per-instance table: their normal comes
from the instance's own (3, 4) float32 transform, as cofactor(M) · n / det(M) (= M⁻ᵀ n) in
float64. Dividing by the determinant, not only by its size, keeps the normal on the same side of
the surface under a mirroring transform (det < 0), so it keeps its relation to the ray:
n_world · d_world = n · (M⁻¹ d_world) = n · d_object. The array table is
``instance_arrays``' (``ARRAY_*`` columns by geometry id).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from embree_rt.embree.instance_arrays import is_array, transforms_of


@njit(inline="always")
def _cofactor_normal(m, p, gx, gy, gz):
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


@njit(inline="always")
def world_normal(normal_matrices, arrays, top, copy, gx, gy, gz):
    """The unnormalised world normal (float64 x, y, z) of a hit on top-level geometry ``top``
    (the instance's geometry id for an instance hit) whose normal in the object's space is
    ``gx``, ``gy``, ``gz`` (float32); ``copy`` is the instance's number in an instance array
    (read only there). ``normal_matrices`` (g, 3, 3) float32 and ``arrays`` (the array table)
    as the module docstring says. The one copy of this rule."""
    if is_array(arrays, top):
        return _cofactor_normal(
            transforms_of(arrays, top), copy, np.float64(gx), np.float64(gy), np.float64(gz)
        )
    m = normal_matrices[top]
    wx = m[0, 0] * gx + m[0, 1] * gy + m[0, 2] * gz
    wy = m[1, 0] * gx + m[1, 1] * gy + m[1, 2] * gz
    wz = m[2, 0] * gx + m[2, 1] * gy + m[2, 2] * gz
    return np.float64(wx), np.float64(wy), np.float64(wz)


@njit(inline="always")
def unit_world_normal(normal_matrices, arrays, top, copy, gx, gy, gz):
    """``world_normal`` scaled to unit length in float64 (a zero normal stays zero)."""
    wx, wy, wz = world_normal(normal_matrices, arrays, top, copy, gx, gy, gz)
    length = math.sqrt(wx * wx + wy * wy + wz * wz)
    if length == 0.0:
        length = 1.0
    return wx / length, wy / length, wz / length


@njit(nogil=True, cache=True)
def hits_to_world(inst, inst_prim, normal, normal_matrices, arrays):
    """In place, for n raw hits: ``normal`` (n, 3) float32 from the object's space to world
    space (unnormalised) where the hit is in an instance (``inst`` (n,) int32 >= 0), and
    ``inst_prim`` (n,) int32 set to -1 where the hit is not in an instance array."""
    for i in range(inst.shape[0]):
        top = inst[i]
        if not is_array(arrays, top):
            inst_prim[i] = -1
        if top < 0:
            continue
        wx, wy, wz = world_normal(
            normal_matrices, arrays, top, inst_prim[i], normal[i, 0], normal[i, 1], normal[i, 2]
        )
        normal[i, 0] = wx
        normal[i, 1] = wy
        normal[i, 2] = wz


@njit(nogil=True, cache=True)
def shading_normals(inst, inst_prim, normals, normal_matrices, arrays):
    """(3, k) float32 world normals of k instance hits (``inst``, ``inst_prim`` (k,) int32)
    from ``normals`` (k, 3) float32 in the object's space (smooth shading normals): unit length
    (in float64) for instance-array hits, unnormalised for single instances.

    Zeros come out as +0.0 on single instances (their float32 sums start from +0.0, as NumPy's
    ``einsum`` sums them, which the shading normals were made with), and the inputs' zeros are
    taken as +0.0; both only choose the sign of a zero, which can still steer a secondary ray
    (a direction of -0.0 is traversed as -inf, not +inf), so they stay as the images were made.
    """
    k = inst.shape[0]
    out = np.empty((3, k), np.float32)
    zero = np.float32(0.0)
    for j in range(k):
        top = inst[j]
        gx, gy, gz = normals[j, 0] + zero, normals[j, 1] + zero, normals[j, 2] + zero
        if is_array(arrays, top):
            wx, wy, wz = unit_world_normal(normal_matrices, arrays, top, inst_prim[j], gx, gy, gz)
        else:
            wx, wy, wz = world_normal(normal_matrices, arrays, top, inst_prim[j], gx, gy, gz)
            wx, wy, wz = wx + zero, wy + zero, wz + zero
        out[0, j] = wx
        out[1, j] = wy
        out[2, j] = wz
    return out
