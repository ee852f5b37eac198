"""How many threads a batch of rays is worth, the lock every parallel region takes, and how a
batch splits into the chunks of a parallel loop."""

from __future__ import annotations

import threading

import numpy as np
from numba import njit

# Parallel regions (numba ``prange`` kernels: queries, the trimesh passes) run one at a time:
# numba's fallback threading layer (workqueue) must not be entered from two threads at once.
# Serial kernels need no threading layer, so many Python threads may run them concurrently.
parallel_region = threading.Lock()

# Below this many rays a query runs on the calling thread alone. Waking numba's other threads
# costs little on an idle machine, but on a loaded one the region waits until every thread has
# been scheduled: measured here (2 cores, one busy), 35 suspect rays of a first-hit query took
# 5 ms on two threads, about 40 us on one.
SERIAL_RAYS = 1024


def threads_for(rays: int, threads: int) -> int:
    """The threads to trace ``rays`` rays on, given ``threads`` available: 1 for small batches."""
    return 1 if rays < SERIAL_RAYS else threads


# Parallel drivers split their items into chunks of a fixed size, one per ``prange`` iteration.


@njit(inline="always")
def chunk_count(n: int, size: int) -> int:
    """How many chunks of ``size`` items cover ``n`` items."""
    return (n + size - 1) // size


@njit(inline="always")
def chunk_span(c: int, size: int, n: int) -> tuple[int, int]:
    """Items ``first .. stop`` of chunk ``c`` of ``n`` items in chunks of ``size`` (the last one
    shorter)."""
    return c * size, min(n, (c + 1) * size)


@njit(inline="always")
def chunk_scratch(n: int, size: int, words: int) -> np.ndarray:
    """(chunks, ``words``) uint32: a scratch row for each chunk of ``size`` of ``n`` items,
    made before the parallel loop so that no chunk allocates."""
    return np.empty((chunk_count(n, size), words), np.uint32)
