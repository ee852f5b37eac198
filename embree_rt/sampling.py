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


def _hash_bits(seed: int, index: np.ndarray, dimension: int) -> np.ndarray:
    """(n,) uint64: the hash of ``seed``, each (n,) int64/uint64 sample ``index`` and
    ``dimension``, with full avalanche: every output bit depends on every input bit."""
    index = np.asarray(index)
    if index.dtype.kind not in "iu":
        raise TypeError(f"index: expected an integer array, got dtype {index.dtype}")
    if int(dimension) != dimension or dimension < 0:
        raise ValueError(f"dimension: expected a non-negative integer, got {dimension!r}")
    key = hash_key(seed, dimension)
    with np.errstate(over="ignore"):
        return _splitmix64(index.astype(np.uint64) ^ key)


def hash_key(seed: int, dimension: int) -> np.uint64:
    """The uint64 key of (``seed``, ``dimension``): sample i's hash is ``splitmix64(i ^ key)``
    (compiled code that draws the same numbers takes the key from here)."""
    with np.errstate(over="ignore"):
        # Hashing the seed before adding the dimension keeps every (seed, dimension) pair on its
        # own 64-bit key: no two pairs alias, as they would with key = seed * k + dimension.
        seed_key = _splitmix64(np.uint64(int(seed) & _UINT64_MASK))
        return _splitmix64(seed_key + np.uint64(int(dimension) & _UINT64_MASK))


def _unit_float(bits24: np.ndarray) -> np.ndarray:
    # 24 bits fit a float32 mantissa exactly, so the result stays strictly below 1.
    return bits24.astype(np.float32) * np.float32(2.0**-24)


def uniform(seed: int, index: np.ndarray, dimension: int) -> np.ndarray:
    """(n,) float32 uniform in [0, 1), a hash of ``seed``, each of the (n,) int64/uint64 sample
    ``index`` values and the non-negative ``dimension``.

    The same (seed, index, dimension) always gives the same value; different seeds or
    dimensions give independent streams.
    """
    return _unit_float(_hash_bits(seed, index, dimension) >> np.uint64(40))


def uniform_pair(seed: int, index: np.ndarray, dimension: int) -> tuple[np.ndarray, np.ndarray]:
    """Two (n,) float32 uniform in [0, 1) from one hash of (``seed``, ``index``,
    ``dimension``): its top 24 bits and the 24 below them, independent of each other as the
    hash's bits are. Half the cost of two ``uniform`` streams, for a 2D sample (the jitter).
    The pair's stream is ``uniform``'s own for the first value: do not also draw ``uniform``
    at ``dimension`` for something else."""
    bits = _hash_bits(seed, index, dimension)
    return (
        _unit_float(bits >> np.uint64(40)),
        _unit_float((bits >> np.uint64(16)) & np.uint64(0xFFFFFF)),
    )
