"""Counter-based random numbers: the value for (seed, sample index, dimension) never depends on
how samples are split into batches or threads."""

from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def _splitmix64(x: np.ndarray) -> np.ndarray:
    x = x + _GOLDEN
    x = (x ^ (x >> np.uint64(30))) * _MIX1
    x = (x ^ (x >> np.uint64(27))) * _MIX2
    return x ^ (x >> np.uint64(31))


def uniform(seed: int, index: np.ndarray, dimension: int) -> np.ndarray:
    """(n,) float32 in [0, 1) hashed from ``seed``, (n,) integer ``index`` and ``dimension``."""
    with np.errstate(over="ignore"):
        stream = np.uint64(seed & 0xFFFFFFFFFFFFFFFF) * np.uint64(1_000_003)
        key = _splitmix64(stream + np.uint64(dimension))
        bits = _splitmix64(np.asarray(index).astype(np.uint64) ^ key)
    # The top 24 bits fit a float32 mantissa exactly, so the result stays strictly below 1.
    return ((bits >> np.uint64(40)).astype(np.float32) * np.float32(2.0**-24)).astype(np.float32)
