"""Camera samples in batches, run side by side on a thread pool and collected in order.

Shared by the beauty render (``integrator.Integrator.render_image``) and the AOV pass (``aovs``).
"""

from __future__ import annotations

import os
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor, TimeoutError
from itertools import pairwise


def worker_count(threads: int | None) -> int:
    """The threads a render runs batches on: ``threads``, or every core when None. Raises
    ValueError unless ``threads`` is None or a positive integer."""
    if threads is None:
        return os.cpu_count() or 1
    if int(threads) != threads or threads < 1:
        raise ValueError(f"threads: must be a positive integer, got {threads!r}")
    return int(threads)


def batch_ranges(total: int, batch_size: int, spp: int, workers: int) -> list[tuple[int, int]]:
    """(start, count) of each batch of the ``total`` camera samples, in order: whole pixels of
    ``spp`` samples, at most ``batch_size`` samples (or one pixel). With several workers the
    last round of batches is cut into three times as many pieces, so that no worker idles long
    while another finishes a full batch at the bottom of the image."""
    step = max(1, batch_size // spp) * spp
    starts = list(range(0, total, step))
    if workers > 1 and len(starts) > workers:
        tail = starts[-workers]
        pixels = (total - tail) // spp
        pieces = 3 * workers
        starts = starts[:-workers] + [tail + pixels * k // pieces * spp for k in range(pieces)]
    bounds = [*starts, total]
    return [(a, b - a) for a, b in pairwise(bounds) if b > a]


def ordered_results(pool: ThreadPoolExecutor, function, items, ahead: int):
    """``function(item)`` for each item, in order, with at most ``ahead`` extra items running.

    Waits in short slices: a thread blocked on a future without a timeout would not see the
    Ctrl-C that Python delivers to the main thread.
    """
    pending: deque[Future] = deque()
    items = iter(items)
    for item in items:
        pending.append(pool.submit(function, item))
        if len(pending) > ahead:
            yield _wait(pending.popleft())
    while pending:
        yield _wait(pending.popleft())


def _wait(future: Future):
    while True:
        try:
            return future.result(timeout=0.05)
        except TimeoutError:
            continue
