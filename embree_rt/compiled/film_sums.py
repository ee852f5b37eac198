"""Per-pixel sums of a film block, compiled: each sample added where it lands, as it comes.

The sums are those ``np.bincount(pixel, weights=rgb[c])`` forms, channel by channel: every
sample converted exactly to float64 and added to its pixel's running sum in the order the
samples arrive, starting from zero, so the bits are the same. Here no sample list is kept
and concatenated, no pass sweeps the whole block, and the ray weight times its radiance is
multiplied (in float32, as NumPy's ``weight * rgb`` would) inside the loop instead of into a
temporary.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(nogil=True, cache=True)
def add_samples(sums, first, pixel, rgb):
    """Add (3, n) float32 ``rgb`` to the (3, count) float64 ``sums`` of pixels ``first ..
    first + count - 1`` at the (n,) int64 ``pixel`` indices. Returns the index of the first
    sample outside the block (then nothing was added), or -1."""
    count = sums.shape[1]
    n = pixel.shape[0]
    for i in range(n):
        p = pixel[i] - first
        if p < 0 or p >= count:
            return i
    for i in range(n):
        p = pixel[i] - first
        sums[0, p] += np.float64(rgb[0, i])
        sums[1, p] += np.float64(rgb[1, i])
        sums[2, p] += np.float64(rgb[2, i])
    return -1


@njit(nogil=True, cache=True)
def add_weighted(sums, first, pixel, weight, rgb, columns):
    """``add_samples`` of the float32 products ``weight[:, j] * rgb[:, k]``, j = ``columns[k]``
    ((k,) int64; ``weight`` (3, n) float32 and ``pixel`` (n,) read at those columns) or, with
    ``columns`` None, j = k (``weight`` may be a zero-stride view, camera rays' ones). Returns
    as ``add_samples`` does, with k for the sample."""
    count = sums.shape[1]
    n = rgb.shape[1]
    for k in range(n):
        j = k if columns is None else columns[k]
        p = pixel[j] - first
        if p < 0 or p >= count:
            return k
    for k in range(n):
        j = k if columns is None else columns[k]
        p = pixel[j] - first
        sums[0, p] += np.float64(weight[0, j] * rgb[0, k])
        sums[1, p] += np.float64(weight[1, j] * rgb[1, k])
        sums[2, p] += np.float64(weight[2, j] * rgb[2, k])
    return -1


@njit(nogil=True, cache=True)
def mean_image(sums, spp):
    """(n, 3) float32 pixel-major means of the (3, n) float64 ``sums`` over ``spp`` samples:
    each divided in float64 and rounded once to float32, as NumPy's
    ``np.divide(sums.T, spp, out=float32)`` does, in one pass."""
    mean = np.empty((sums.shape[1], 3), np.float32)
    mean_into(mean, 0, sums, spp)
    return mean


@njit(nogil=True, cache=True)
def mean_into(mean, first, sums, spp):
    """``mean_image(sums, spp)`` written into rows ``first ..`` of the (m, 3) float32
    ``mean``. When ``spp`` is a power of two the sums are multiplied by its reciprocal, which
    is exact: x / 2^k and x · 2^-k are the same real number, so IEEE rounds them to the same
    double (subnormal results included), and a multiplication costs a fraction of a division."""
    n = sums.shape[1]
    if spp & (spp - 1) == 0:
        scale = 1.0 / np.float64(spp)
        for p in range(n):
            mean[first + p, 0] = np.float32(sums[0, p] * scale)
            mean[first + p, 1] = np.float32(sums[1, p] * scale)
            mean[first + p, 2] = np.float32(sums[2, p] * scale)
        return
    divisor = np.float64(spp)
    for p in range(n):
        mean[first + p, 0] = np.float32(sums[0, p] / divisor)
        mean[first + p, 1] = np.float32(sums[1, p] / divisor)
        mean[first + p, 2] = np.float32(sums[2, p] / divisor)
