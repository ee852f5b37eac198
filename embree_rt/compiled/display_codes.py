"""Linear radiance to 8-bit display codes in one compiled pass: clamp, exposure, tone map, then
the transfer curve and quantisation read from a table of 255 thresholds.

The transfer curve (a power 1/2.2, or sRGB's) followed by ``round(255 ·)`` is a step function
of the tone-mapped value m in [0, 1]: code k is reached at the smallest float32 m whose code is
k or more. The caller measures those 255 thresholds once with its own NumPy curve
(``film.code_thresholds``), and this pass counts the thresholds at or below m: a table indexed
by m's top bits gives the count at the start of m's bucket, and a step or two over the
thresholds inside the bucket finishes it (a binary search over all 255 took 80 ns a channel,
its branches unpredictable). No power is computed here: a compiled ``powf`` is not NumPy's on every
ISA (NumPy 2 takes SVML's on AVX-512, glibc's elsewhere), while the table is NumPy's own on
the machine that runs it, so the codes are NumPy's whenever its curve is monotone in m.

Exposure (one float32 product), Reinhard (one float32 division), ACES (float32 products and
sums, no contraction into FMA: numba leaves ``fastmath`` off) and the clip of "none" are IEEE
operations, the same bits as NumPy's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

TONEMAP_REINHARD = 0
TONEMAP_ACES = 1
TONEMAP_NONE = 2
THRESHOLDS = 255  # codes 1..255 each begin at one threshold


@njit(nogil=True, cache=True)
def _tone_mapped(x, scale, tonemap):
    """float32 m in [0, 1] of one finite or +inf, non-negative float32 channel ``x``."""
    linear = x * scale
    if linear == np.inf:
        return np.float32(1.0)
    if tonemap == TONEMAP_REINHARD:
        return linear / (np.float32(1.0) + linear)
    if tonemap == TONEMAP_ACES:
        v = min(linear, np.float32(1e15))
        top = v * (np.float32(2.51) * v + np.float32(0.03))
        bottom = v * (np.float32(2.43) * v + np.float32(0.59)) + np.float32(0.14)
        return min(max(top / bottom, np.float32(0.0)), np.float32(1.0))
    return min(linear, np.float32(1.0))


BUCKET_SHIFT = 14  # a bucket: the float32 values sharing their bits above the lowest 14
BUCKETS = (0x3F800000 >> BUCKET_SHIFT) + 1  # buckets of [0, 1]: 65,025 codes, 64 KB


def bucket_codes(thresholds: np.ndarray) -> np.ndarray:
    """(BUCKETS,) uint8: the code of the first float32 value of each bucket (how many of the
    (255,) ascending float32 ``thresholds`` are at or below it). A bucket spans 2^-9 of its
    values' size, a quarter of a code at most on a power 1/2.2 or sRGB curve, so the codes of
    the values inside it are found from its own code in a step or two."""
    starts = (np.arange(BUCKETS, dtype=np.uint32) << BUCKET_SHIFT).view(np.float32)
    return np.searchsorted(thresholds, starts, side="right").astype(np.uint8)


@njit(nogil=True, cache=True)
def display_codes(image, first, stop, scale, tonemap, thresholds, buckets, out):
    """Fill rows ``first .. stop - 1`` of ``out`` (h, w, 3) uint8 with the display codes of
    ``image`` (h, w, 3) float32 linear radiance: negatives clamp to 0, then times the float32
    exposure ``scale``, the tone map (``TONEMAP_*``; +inf maps to 1) and the code the (255,)
    float32 ``thresholds`` and their (BUCKETS,) uint8 ``buckets`` (``bucket_codes``) give.
    Returns the number of NaN channels (then those rows of ``out`` are not to be used).

    Without the GIL: the caller runs row spans on threads of its own. A code is how many of
    the 255 ascending ``thresholds`` are <= the tone-mapped m in [0, 1]: its bucket's code
    (``bucket_codes``, indexed by m's bits) and the thresholds inside the bucket."""
    value = np.empty(1, np.float32)
    bits = value.view(np.uint32)  # m's bits: numba has no scalar view
    found = 0
    for row in range(first, stop):
        for column in range(image.shape[1]):
            for channel in range(3):
                x = image[row, column, channel]
                if x != x:
                    found += 1
                    continue
                m = _tone_mapped(max(x, np.float32(0.0)), scale, tonemap)
                code = 0
                if m > np.float32(0.0):  # not -0.0, whose bits would index past the table
                    value[0] = m
                    code = np.int64(buckets[bits[0] >> BUCKET_SHIFT])
                    while code < THRESHOLDS and thresholds[code] <= m:
                        code += 1
                out[row, column, channel] = code
    return found
