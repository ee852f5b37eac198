"""The film: linear accumulation, Reinhard tone mapping, gamma, and atomic image files."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

GAMMA = 2.2
IMAGE_SUFFIXES = (".png", ".npy", ".exr")


class Film:
    """Sums radiance per pixel; ``image(spp)`` is the (height, width, 3) float32 mean."""

    def __init__(self, width: int, height: int) -> None:
        self.width = int(width)
        self.height = int(height)
        self._sum = np.zeros((3, self.width * self.height), np.float64)

    def add(self, pixel: np.ndarray, rgb: np.ndarray) -> None:
        """Add (n, 3) float32 ``rgb`` to the (n,) int64 ``pixel`` indices (row-major)."""
        if len(pixel) == 0:
            return
        size = self.width * self.height
        for channel in range(3):
            self._sum[channel] += np.bincount(pixel, weights=rgb[:, channel], minlength=size)

    def add_block(self, block: FilmBlock) -> None:
        """Add a finished block's sums into its pixels."""
        self._sum[:, block.first : block.first + block.count] += block.sums

    def image(self, spp: int) -> np.ndarray:
        mean = (self._sum / spp).astype(np.float32)
        return np.ascontiguousarray(mean.T.reshape(self.height, self.width, 3))


class FilmBlock:
    """Sums for the ``count`` consecutive pixels from ``first``: what one batch of camera samples
    accumulates on its own (no locking, and cheaper than bincounts over the whole film)."""

    def __init__(self, first: int, count: int) -> None:
        self.first = int(first)
        self.count = int(count)
        self.sums = np.zeros((3, self.count), np.float64)

    def add(self, pixel: np.ndarray, rgb: np.ndarray) -> None:
        """Add (n, 3) float32 ``rgb`` to the (n,) int64 ``pixel`` indices inside the block."""
        if len(pixel) == 0:
            return
        local = pixel - self.first
        for channel in range(3):
            self.sums[channel] += np.bincount(local, weights=rgb[:, channel], minlength=self.count)


def tonemap(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) float32 linear → (h, w, 3) uint8: Reinhard ``c / (1 + c)``, then gamma 1/2.2."""
    image = np.asarray(image, np.float32)
    if np.isnan(image).any():
        raise ValueError("image contains NaN")
    linear = np.maximum(image, 0.0)
    mapped = (linear / (1.0 + linear)) ** (1.0 / GAMMA)
    return np.clip(np.rint(mapped * 255.0), 0, 255).astype(np.uint8)


def check_output_path(path: str | os.PathLike) -> None:
    """Raise ValueError, before any rendering, if ``path`` cannot take an image."""
    target = Path(path)
    if target.suffix.lower() not in IMAGE_SUFFIXES:
        raise ValueError(
            f"{target}: unknown image extension {target.suffix or '(none)'!r}; "
            f"use one of {', '.join(IMAGE_SUFFIXES)}"
        )
    if not target.parent.resolve().is_dir():
        raise ValueError(f"{target}: directory {target.parent} does not exist")
    if target.suffix.lower() == ".exr":
        _exr_module()


def _exr_module():
    try:
        import OpenEXR
    except ImportError:
        raise ValueError(
            "writing .exr needs the OpenEXR package: pip install 'embree-rt[exr]'"
        ) from None
    return OpenEXR


def _write_png(image: np.ndarray, handle) -> None:
    from PIL import Image

    Image.fromarray(tonemap(image), "RGB").save(handle, format="PNG")


def _write_npy(image: np.ndarray, handle) -> None:
    np.save(handle, np.asarray(image, np.float32))


def _write_exr(image: np.ndarray, handle) -> None:
    OpenEXR = _exr_module()
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {"RGB": np.ascontiguousarray(image, np.float32)}
    handle.close()
    with OpenEXR.File(header, channels) as exr:
        exr.write(handle.name)


WRITERS = {".png": _write_png, ".npy": _write_npy, ".exr": _write_exr}


def save_image(image: np.ndarray, path: str | os.PathLike) -> None:
    """Write the (h, w, 3) float32 linear ``image``: ``.png`` tone-mapped 8-bit, ``.npy`` and
    ``.exr`` linear. Atomic: a temp file in the same directory is renamed over ``path`` only
    once complete, so a failure or Ctrl-C never leaves a partial or clobbered image."""
    check_output_path(path)
    target = Path(path)
    writer = WRITERS[target.suffix.lower()]
    handle = tempfile.NamedTemporaryFile(  # noqa: SIM115 (closed below, renamed on success)
        dir=target.parent, prefix=f".{target.name}.", suffix=target.suffix, delete=False
    )
    try:
        with handle:
            writer(image, handle)
        # The temp file is private (0600); give the image the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(handle.name, 0o666 & ~umask)
        os.replace(handle.name, target)
    except BaseException:
        Path(handle.name).unlink(missing_ok=True)
        raise
