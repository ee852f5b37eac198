"""Reading the ``.npz`` archives scene files name (sphere arrays, instance placements).

An archive is a zip of ``.npy`` files, and a few megabytes of zip can unpack to gigabytes:
``array_headers`` reads the shapes its ``.npy`` headers declare, from the start of each member,
so that what they would take is known (and held against the memory available, by the loader)
before any array is unpacked.
"""

from __future__ import annotations

import math
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

# (shape, dtype) of each array of an archive, by name.
Headers = dict[str, tuple[tuple[int, ...], np.dtype]]


def array_headers(path: Path) -> Headers | None:
    """The shape and dtype every ``.npy`` member of the zip at ``path`` declares, read without
    unpacking its data; None when ``path`` is not a zip. Raises OSError or ValueError for an
    unreadable file or header."""
    if not zipfile.is_zipfile(path):
        return None
    headers: Headers = {}
    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                # Versions 2 and 3 differ only in the header's text encoding.
                read = (
                    np.lib.format.read_array_header_1_0
                    if version == (1, 0)
                    else (np.lib.format.read_array_header_2_0)
                )
                shape, _, dtype = read(member)
            headers[info.filename[: -len(".npy")]] = (tuple(shape), dtype)
    return headers


def unpacked_bytes(headers: Headers) -> int:
    """What the arrays of ``headers`` take in memory once unpacked (Python ints: no overflow)."""
    return sum(math.prod(shape) * dtype.itemsize for shape, dtype in headers.values())


def read_archive(path: Path, fail: Callable[[str], Exception]) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` at ``path``, by name, read with ``allow_pickle=False``; a
    missing file, a plain ``.npy``, a corrupt archive or pickled object arrays are raised as
    ``fail("problem")``."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {name: archive[name] for name in archive.files}
    except FileNotFoundError:
        raise fail("no such file") from None
    except AttributeError:  # np.load gave a plain array: a .npy, not an archive
        raise fail("expected an .npz archive of arrays") from None
    except Exception as error:  # a corrupt zip, pickled object arrays, a directory...
        raise fail(f"cannot read .npz: {error}") from None
