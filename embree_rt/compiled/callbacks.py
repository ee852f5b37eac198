"""Functions Embree calls back (numba ``@cfunc``s), compiled when first needed, not at import.

``numba.cfunc`` with a signature compiles its function, or loads it from numba's on-disk
cache, when it decorates it: a module that declared one paid for it on import, and with it
numba's first-use set-up, whether or not the process ever built a BVH that calls it (the
multi-hit filter alone cost every command 0.2 s before its first clock tick). ``on_first_use``
declares the same callback and compiles it the first time its ``address`` is asked for.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from numba import cfunc
from numba.core.ccallback import CFunc


class Callback:
    """``function`` as a ``@cfunc`` of ``signature`` with numba's ``options``, compiled the
    first time ``address`` is read and kept (with its machine code) for the process's life."""

    def __init__(self, signature, function: Callable, options: dict) -> None:
        self.signature = signature
        self.function = function
        self.options = options
        self.__name__ = function.__name__
        self.__doc__ = function.__doc__
        self._compiled: CFunc | None = None
        self._lock = threading.Lock()

    @property
    def compiled(self) -> CFunc:
        """numba's ``CFunc``, compiled (or loaded from numba's cache) on the first call."""
        if self._compiled is None:
            with self._lock:
                if self._compiled is None:
                    self._compiled = cfunc(self.signature, **self.options)(self.function)
        return self._compiled

    @property
    def address(self) -> int:
        """The machine code's address: what Embree is handed."""
        return self.compiled.address


def on_first_use(signature, **options) -> Callable[[Callable], Callback]:
    """Decorator: the function as a ``Callback`` of ``signature`` (numba's ``cfunc`` options,
    e.g. ``nopython=True, cache=True``), compiled on the first read of its ``address``."""
    return lambda function: Callback(signature, function, options)
