"""Counter-based random numbers: the value for (seed, sample index, dimension) is a pure hash of
the three, so it never depends on how samples are split into batches or threads."""

from __future__ import annotations

import numpy as np

_UINT64_MASK = 0xFFFFFFFFFFFFFFFF
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def _splitmix64(x: np.ndarray | np.uint64) -> np.ndarray | np.uint64:
    """SplitMix64's finaliser: a bijection of uint64 with full avalanche (Steele et al. 2014)."""
    x = x + _GOLDEN
    x = (x ^ (x >> np.uint64(30))) * _MIX1
    x = (x ^ (x >> np.uint64(27))) * _MIX2
    return x ^ (x >> np.uint64(31))


def uniform(seed: int, index: np.ndarray, dimension: int) -> np.ndarray:
    """(n,) float32 uniform in [0, 1), a hash of ``seed``, each of the (n,) int64/uint64 sample
    ``index`` values and the non-negative ``dimension``.

    The same (seed, index, dimension) always gives the same value; different seeds or
    dimensions give independent streams.
    """
    index = np.asarray(index)
    if index.dtype.kind not in "iu":
        raise TypeError(f"index: expected an integer array, got dtype {index.dtype}")
    if int(dimension) != dimension or dimension < 0:
        raise ValueError(f"dimension: expected a non-negative integer, got {dimension!r}")
    with np.errstate(over="ignore"):
        # Hashing the seed before adding the dimension keeps every (seed, dimension) pair on its
        # own 64-bit key: no two pairs alias, as they would with key = seed * k + dimension.
        seed_key = _splitmix64(np.uint64(int(seed) & _UINT64_MASK))
        key = _splitmix64(seed_key + np.uint64(int(dimension) & _UINT64_MASK))
        bits = _splitmix64(index.astype(np.uint64) ^ key)
    # The top 24 bits fit a float32 mantissa exactly, so the result stays strictly below 1.
    return (bits >> np.uint64(40)).astype(np.float32) * np.float32(2.0**-24)
