"""numba set up in the command's own process without SciPy: what numba would import SciPy
for there is never asked.

The first kernel a process loads, even from numba's disk cache, makes numba import its whole
library of implementations, and one of them, ``numba.np.arraymath``, checks at its import
whether a BLAS is there by importing ``scipy.linalg.cython_blas``: all of ``scipy.linalg``,
and through SciPy's array-API layer ``numpy.f2py`` and ``numpy.testing`` (in CPU time about
half of what importing NumPy and numba takes), only to decide whether ``np.correlate`` and
``np.convolve`` call ``np.dot``. ``import numba`` itself imports SciPy to check its version.
No kernel of embree_rt calls ``np.correlate`` or ``np.convolve`` (``tests/test_imports.py``
reads them all), so in the command's process numba is imported, and its implementations
loaded, while SciPy looks absent; then SciPy imports as ever (a kernel typing ``np.dot`` or
``np.linalg`` imports it then, as numba always does). A library user's process is left alone:
its numba finds SciPy's BLAS.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

HIDDEN = "scipy"


@contextmanager
def numba_loaded_without_scipy(enabled: bool) -> Iterator[None]:
    """Inside, SciPy looks absent to every import (``None`` in ``sys.modules``: an import of it
    or of any module in it raises ImportError); when the block ends without an exception,
    numba's library of implementations is imported, SciPy still absent, and SciPy then becomes
    importable again. Nothing is done unless ``enabled``, or when SciPy is already imported.
    The block is for code that imports only embree_rt's own modules, NumPy and numba (the
    command line's parse, whose checks of flag values import the scene model)."""
    if not enabled or HIDDEN in sys.modules:
        yield
        return
    sys.modules[HIDDEN] = None  # type: ignore[assignment]
    try:
        yield
        import numba.np.arraymath  # noqa: F401  (its BLAS check runs at import: here)
    finally:
        if HIDDEN in sys.modules and sys.modules[HIDDEN] is None:
            del sys.modules[HIDDEN]
