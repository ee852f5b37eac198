"""Morton (Z-order) codes and the radix sort that orders them: the two pieces every spatial
ordering in embree_rt is made of (spheres in the BVH's storage, trimesh rays in tracing order)."""

from __future__ import annotations

import numpy as np
from numba import njit

BITS_PER_AXIS = 10  # a 30-bit code
CELLS = (1 << BITS_PER_AXIS) - 1  # the largest cell index on an axis
_DIGIT_BITS = 10  # radix sort: three passes of 1024 buckets (they fit in L1)
_DIGITS = 3


@njit(inline="always")
def spread_bits(x):
    """The low 10 bits of ``x`` moved to every third bit (bit k to bit 3k)."""
    x &= 0x3FF
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


@njit(nogil=True, cache=True)
def radix_order(keys):
    """(n,) int64 stable ascending order of (n,) uint32 ``keys`` below 2**30: an LSD radix
    sort, serial, so equal keys keep their input order and the result is a pure function of
    the keys. Already sorted keys are recognised in one pass and cost nothing more."""
    n = keys.shape[0]
    order = np.arange(n)
    ordered = True
    for i in range(1, n):
        if keys[i] < keys[i - 1]:
            ordered = False
            break
    if ordered:
        return order
    spare = np.empty(n, np.int64)
    counts = np.empty(1 << _DIGIT_BITS, np.int64)
    mask = np.uint32((1 << _DIGIT_BITS) - 1)
    for digit in range(_DIGITS):
        shift = np.uint32(digit * _DIGIT_BITS)
        counts[:] = 0
        for i in range(n):
            counts[(keys[i] >> shift) & mask] += 1
        total = 0
        for b in range(counts.shape[0]):
            count = counts[b]
            counts[b] = total
            total += count
        for i in range(n):
            j = order[i]
            b = (keys[j] >> shift) & mask
            spare[counts[b]] = j
            counts[b] += 1
        order, spare = spare, order
    return order
