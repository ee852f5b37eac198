"""How many threads a batch of rays is worth, and the lock every parallel region takes."""

from __future__ import annotations

import threading

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
