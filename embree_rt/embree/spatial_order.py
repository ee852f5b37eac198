"""A spatial order for user-geometry spheres: Morton (Z-order) of their centres.

Embree's own primitives copy their data into the BVH's leaves, so neighbours in the tree are
neighbours in memory. User geometry keeps its data where the user pointer says, and the
callbacks fetch sphere ``primID`` from there: in the caller's order, spheres that share a leaf
can be megabytes apart, one cache miss each. Stored in Morton order, the spheres a ray meets
one after another mostly share cache lines and pages (issue 10's 1e6-sphere field, randomly
ordered: camera rays 1.1x, shadow rays 1.25x faster; a field already generated in spatial
order, as ``embree-rt random``'s rings are, gains nothing and pays about 10 ms a million
spheres for the sort).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from embree_rt.compiled.morton import CELLS, radix_order, spread_bits
from embree_rt.embree.sphere_buffers import pack_spheres


@njit(nogil=True, cache=True)
def morton_codes(centers):
    """(n,) uint32 30-bit Morton codes of (n, 3) float32 ``centers`` in their bounding cube.

    One scale for all three axes (the cube's side), so a flat field keeps its flat axis at the
    fine end of the code instead of having it stretched to the size of the others.
    """
    n = centers.shape[0]
    codes = np.empty(n, np.uint32)
    if n == 0:
        return codes
    low = np.empty(3, np.float64)
    high = np.empty(3, np.float64)
    for axis in range(3):
        low[axis] = high[axis] = centers[0, axis]
    for i in range(n):
        for axis in range(3):
            c = np.float64(centers[i, axis])
            low[axis] = min(low[axis], c)
            high[axis] = max(high[axis], c)
    side = max(high[0] - low[0], high[1] - low[1], high[2] - low[2])
    scale = CELLS / side if side > 0.0 else 0.0
    for i in range(n):
        code = 0
        for axis in range(3):
            q = np.int64((np.float64(centers[i, axis]) - low[axis]) * scale)
            code |= spread_bits(min(max(q, 0), CELLS)) << axis
        codes[i] = code
    return codes


@njit(nogil=True, cache=True)
def spatial_order(centers):
    """(n,) int32 permutation putting (n, 3) float32 ``centers`` in Morton order: element k is
    the index of the k-th sphere along the curve; equal codes keep their input order
    (``morton.radix_order``), so the result is a pure function of the centres."""
    return radix_order(morton_codes(centers)).astype(np.int32)


@njit(nogil=True, cache=True)
def store_in_spatial_order(centers, radii):
    """Spheres ``centers`` (n, 3), ``radii`` (n,) float32 as user geometry stores them.

    Returns the (n, 4) float32 (x, y, z, r) buffer in Morton order, ``order`` (n,) int32 (the
    index of the sphere in each slot), ``slot`` (n,) int32 (the slot of each sphere), whether
    the spheres came in that order already (``order`` is the identity) and their reach
    (``sphere_buffers.pack_spheres``).
    """
    order = spatial_order(centers)
    n = len(order)
    packed = np.empty((max(n, 1), 4), np.float32)[:n]
    reach = pack_spheres(centers, radii, order, packed)
    slot = np.empty(n, np.int32)
    in_order = True
    for k in range(n):
        i = order[k]
        in_order &= i == k
        slot[i] = k
    return packed, order, slot, in_order, reach


@njit(nogil=True, cache=True)
def spheres_in_spatial_order(centers, radii, labels):
    """Spheres ``centers`` (n, 3), ``radii`` (n,) float32 and their ``labels`` (n,) int32 put
    in Morton order, for a caller that keeps its own tables in the BVH's order. Returns
    ``order`` (n,) int32 (see ``spatial_order``), the three arrays gathered in that order (one
    compiled pass: NumPy's row gathers take 2-4x as long) and whether they came in that order
    already (``order`` is the identity)."""
    order = spatial_order(centers)
    n = len(order)
    out_centers = np.empty((n, 3), np.float32)
    out_radii = np.empty(n, np.float32)
    out_labels = np.empty(n, np.int32)
    in_order = True
    for k in range(n):
        i = order[k]
        in_order &= i == k
        out_centers[k, 0] = centers[i, 0]
        out_centers[k, 1] = centers[i, 1]
        out_centers[k, 2] = centers[i, 2]
        out_radii[k] = radii[i]
        out_labels[k] = labels[i]
    return order, out_centers, out_radii, out_labels, in_order
