"""Reading the ``.npz`` archives scene files name (sphere arrays, instance placements)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np


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
