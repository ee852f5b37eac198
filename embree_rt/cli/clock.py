"""Where a command's wall time goes: the process's start (interpreter and imports before the
command ran), and numba's compiling of the kernels (which happens on a fresh install, inside
whatever phase first calls a kernel), so that the summary line and ``info`` can say each apart.

Numba compiles a kernel only when its on-disk cache has no copy (``cache=True``): its
``numba:compile`` event fires on a cache miss and on nothing else, so listening to it is the
cheap way to learn that this run compiles, and for how long.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from numba.core import event

# A fresh install's kernels, compiled once on the project's 2-core machine: 20-30 s in all.
FIRST_COMPILE_NOTICE = (
    "embree-rt: compiling the renderer's kernels, once after installing (about half a minute); "
    "later runs load them from numba's cache"
)


def process_age_s() -> float:
    """Seconds since this process started (Linux's /proc, to its clock tick), or 0.0 where it
    cannot be read."""
    try:
        with open("/proc/self/stat", "rb") as stat:
            # the command name (2nd field) may hold spaces: fields are counted after its ")"
            fields = stat.read().rsplit(b")", 1)[1].split()
        with open("/proc/uptime", "rb") as uptime:
            now_s = float(uptime.read().split()[0])
        started_s = int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0
    return max(now_s - started_s, 0.0)


def resident_bytes() -> int:
    """This process's resident set in bytes (Linux), or 0 where /proc is missing."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


class CompileClock:
    """The seconds numba spends compiling kernels while ``listening``: ``intervals`` holds each
    outermost compile's (start, end) on ``time.perf_counter``'s clock (a kernel's callees
    compile inside it and are not counted twice), ``resident_growth`` the bytes the resident
    set grew by during them (LLVM's memory, hundreds of MiB: not the scene's). ``notice`` is
    printed to stderr at the first compile, unless None."""

    def __init__(self, notice: str | None = FIRST_COMPILE_NOTICE) -> None:
        self.intervals: list[tuple[float, float]] = []
        self.resident_growth = 0
        self.notice = notice
        self._depth = 0
        self._started = 0.0
        self._resident_before = 0
        self._lock = threading.Lock()

    @contextmanager
    def listening(self) -> Iterator[CompileClock]:
        clock = self

        class Listener(event.Listener):
            def on_start(self, _event) -> None:
                clock.compile_started()

            def on_end(self, _event) -> None:
                clock.compile_ended()

        listener = Listener()
        event.register("numba:compile", listener)
        try:
            yield self
        finally:
            event.unregister("numba:compile", listener)

    def compile_started(self) -> None:
        with self._lock:
            self._depth += 1
            if self._depth > 1:
                return
            self._started = time.perf_counter()
            self._resident_before = resident_bytes()
            notice, self.notice = self.notice, None
        if notice is not None:
            print(notice, file=sys.stderr, flush=True)

    def compile_ended(self) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                self.intervals.append((self._started, time.perf_counter()))
                self.resident_growth += resident_bytes() - self._resident_before

    def seconds(self, start: float = -float("inf"), end: float = float("inf")) -> float:
        """Seconds of compiling between ``start`` and ``end`` (``time.perf_counter``)."""
        return sum(max(0.0, min(end, stop) - max(start, begin)) for begin, stop in self.intervals)
