"""numba's own set-up, done on a thread of its own while the caller does other work.

The first kernel a process calls, even one numba loads from its on-disk cache, first sets numba
up: it installs every registry of the NumPy and Python functions numba compiles, and imports
SciPy's linear algebra to learn whether BLAS is there (``numba.np.arraymath``). That is most of
a second of one core's time under load and 0.3-0.5 s on a quiet machine, paid on the command's
one busy thread inside whichever phase calls the first kernel (a render's BVH: its spheres'
Morton order). ``start_numba_set_up`` does it on another thread, so that it runs on the core
the caller leaves idle while it reads or generates a scene; a kernel called meanwhile waits
for it on numba's compiler lock, so nothing is done twice.
"""

from __future__ import annotations

import threading

from numba import njit


@njit(cache=True)
def _smallest_kernel():
    """Loading this from numba's cache (compiling it, the first time) sets numba up."""
    return 1


def _set_up() -> None:
    try:
        _smallest_kernel()
    except Exception:
        # The caller's own first kernel sets numba up again, and raises what failed there.
        return


def start_numba_set_up() -> threading.Thread:
    """Start setting numba up on a new thread and return it (not a daemon: the process waits
    for it at exit rather than stop it inside an import)."""
    thread = threading.Thread(target=_set_up, name="numba set-up")
    thread.start()
    return thread
