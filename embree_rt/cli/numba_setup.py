"""numba set up in the command's own process without SciPy, and without PyYAML when there is no
numba config file to read: what numba would import them for is never asked.

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

``import numba`` also imports PyYAML (``numba.core.config``: 20-30 ms of the command's
start-up on this project's machine, loaded) for one use: reading ``.numba_config.yaml`` from
the working directory, which it looks for once, when it is imported. Where there is no such
file numba never parses YAML, so PyYAML is hidden too; where there is one, numba reads it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

HIDDEN = "scipy"
# What numba imports PyYAML for, and the file's name as numba spells it (numba.core.config).
YAML = "yaml"
NUMBA_CONFIG_FILE = ".numba_config.yaml"


@contextmanager
def numba_loaded_without_scipy(enabled: bool) -> Iterator[None]:
    """Inside, SciPy looks absent to every import (``None`` in ``sys.modules``: an import of it
    or of any module in it raises ImportError), and so does PyYAML unless numba is imported
    already or the working directory holds numba's config file; when the block ends without an
    exception, numba's library of implementations is imported, SciPy still absent, and both
    then become importable again. Nothing is done unless ``enabled``, and a module already
    imported is not hidden. The block is for code that imports only embree_rt's own modules,
    NumPy and numba (the command line's parse, whose checks of flag values import the scene
    model)."""
    if not enabled:
        yield
        return
    hidden = [HIDDEN]
    if "numba" not in sys.modules and not os.path.exists(NUMBA_CONFIG_FILE):
        hidden.append(YAML)
    hidden = [name for name in hidden if name not in sys.modules]
    for name in hidden:
        sys.modules[name] = None  # type: ignore[assignment]
    try:
        yield
        if HIDDEN in hidden:
            import numba.np.arraymath  # noqa: F401  (its BLAS check runs at import: here)
    finally:
        for name in hidden:
            if name in sys.modules and sys.modules[name] is None:
                del sys.modules[name]
