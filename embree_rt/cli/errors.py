"""How the command ends: its exit codes, the error it raises for bad input, and what it says
when the fault is ours."""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress

from embree_rt.errors import InputError

EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a process Ctrl-C ended
EXIT_TERMINATED = 143  # 128 + SIGTERM
BUG_REPORT = (
    "embree-rt: internal error: this is a bug in embree_rt, not a problem with your input; "
    "please report it with the traceback above"
)


class UsageError(InputError):
    """Bad input found by the command itself; printed as one line, exit code 2."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread as Ctrl-C is: whatever Ctrl-C undoes (batches
    cancelled, temporary files removed) is undone for it too."""


@contextmanager
def interrupting_signals() -> Iterator[None]:
    """While inside, SIGINT raises KeyboardInterrupt and SIGTERM ``Terminated`` in the main
    thread, the first of them only: from then on both are ignored, inside and after, since the
    command is ending. A second Ctrl-C (an impatient user's) would otherwise cut the clean-up
    the first began, or land after the command's one line, as the interpreter exits, and end
    the process by the signal itself instead of the command's exit code. Off the main thread,
    where Python cannot take signals, nothing changes.

    A signal whose exception is raised inside a Python function that C code called (a ctypes
    callback: llvmlite's, as numba compiles) cannot leave it: ctypes prints it as "Exception
    ignored" and goes on, and the command would run to its end. Such an exception is taken
    from ``sys.unraisablehook`` and raised again outside: the signal is sent to the main
    thread once more, from another thread, so that it arrives once the callback has
    returned."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: int | None = None
    swallowed = False  # raised in a callback, and sent again

    def end(signum, frame) -> None:
        nonlocal received, swallowed
        received, swallowed = signum, False
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, signal.SIG_IGN)
        raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt

    def raise_again(report) -> None:
        nonlocal swallowed
        if received is None or not isinstance(report.exc_value, KeyboardInterrupt):
            unraisable_hook(report)
            return
        swallowed = True
        signal.signal(received, end)
        hook = sys._getframe()
        threading.Thread(target=send_again, args=(hook, received), daemon=True).start()

    def send_again(hook, signum: int) -> None:
        """Send ``signum`` to the main thread once it has left ``hook``'s frame: raised inside
        the hook, the exception would be lost too."""
        main = threading.main_thread().ident
        while hook in frames_of(sys._current_frames().get(main)):
            time.sleep(0.001)
        with suppress(ProcessLookupError):  # the process ended meanwhile
            signal.pthread_kill(main, signum)

    previous = {number: signal.signal(number, end) for number in (signal.SIGINT, signal.SIGTERM)}
    unraisable_hook, sys.unraisablehook = sys.unraisablehook, raise_again
    try:
        yield
    finally:
        sys.unraisablehook = unraisable_hook
        if received is None:
            for number, handler in previous.items():
                signal.signal(number, handler)
        elif swallowed:  # left before the signal sent again arrived: it ends the command here
            for number in (signal.SIGINT, signal.SIGTERM):
                signal.signal(number, signal.SIG_IGN)
            raise Terminated if received == signal.SIGTERM else KeyboardInterrupt


def frames_of(frame) -> list:
    """``frame`` and the frames that called it, innermost first."""
    frames = []
    while frame is not None:
        frames.append(frame)
        frame = frame.f_back
    return frames


class HeldSignals:
    """The signals (SIGINT, SIGTERM) that arrived while ``signals_held`` held them."""

    def __init__(self) -> None:
        self.received: list[int] = []

    def raise_held(self) -> None:
        """Raise what the first held signal stands for: ``Terminated`` or KeyboardInterrupt."""
        if not self.received:
            return
        self.received, first = [], self.received[0]
        raise Terminated if first == signal.SIGTERM else KeyboardInterrupt


@contextmanager
def signals_held() -> Iterator[HeldSignals]:
    """While inside, SIGINT and SIGTERM are noted instead of raised (for what must not be cut
    half-way, such as a cluster starting); ``raise_held`` raises the first afterwards. Off the
    main thread nothing changes."""
    held = HeldSignals()
    if threading.current_thread() is not threading.main_thread():
        yield held
        return

    def note(signum, frame) -> None:
        held.received.append(signum)

    previous = {number: signal.signal(number, note) for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield held
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
