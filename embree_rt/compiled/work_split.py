"""How many threads a batch of rays is worth, the lock every parallel region takes, and how a
batch splits into the chunks of a parallel loop."""

from __future__ import annotations

import threading

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

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


# ``over_chunks`` is the body of every parallel driver that hands chunks to a chunk kernel. It
# cannot be a plain compiled function taking the kernel and its arguments: a kernel passed to a
# cached driver is part of its disk-cache key, which changes from process to process (every
# process compiled it again), and numba's parallel loops take tuples one level deep, so the
# arguments cannot travel as one tuple of named tuples. As an overload inlined into each
# driver, its loop becomes that driver's own, its arguments are the driver's, passed one by one.


def over_chunks(chunk, n, size, words, a, b=None, c=None, d=None, e=None, f=None, g=None, h=None):
    """In a compiled ``parallel=True`` driver: ``chunk(row, first, stop, a, b, ...)`` (the
    arguments given, up to eight) for each chunk ``first .. stop`` of ``size`` of ``n`` items,
    in a ``prange`` loop, ``row`` the chunk's own ``words`` uint32 scratch row
    (``chunk_scratch``); ``chunk`` a compiled function the driver names."""
    raise NotImplementedError("over_chunks runs only inside a compiled driver")


@overload(over_chunks, inline="always")
def _over_chunks(chunk, n, size, words, a, b=None, c=None, d=None, e=None, f=None, g=None, h=None):
    # An argument left out is None (or numba's Omitted); an argument given as None has the
    # type ``none`` and is passed on.
    given = [
        name
        for name, value in zip("abcdefgh", (a, b, c, d, e, f, g, h), strict=True)
        if value is not None and not isinstance(value, types.Omitted)
    ]
    source = (
        "def over_chunks(chunk, n, size, words, a, b=None, c=None, d=None, e=None, f=None,\n"
        "                g=None, h=None):\n"
        "    scratch = chunk_scratch(n, size, words)\n"
        "    for i in prange(len(scratch)):\n"
        "        first, stop = chunk_span(i, size, n)\n"
        f"        chunk(scratch[i], first, stop, {', '.join(given)})\n"
    )
    space = {"prange": prange, "chunk_scratch": chunk_scratch, "chunk_span": chunk_span}
    exec(source, space)
    return space["over_chunks"]
