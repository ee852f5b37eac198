"""The film: linear accumulation, Reinhard tone mapping, gamma, and atomic image files."""

from __future__ import annotations

import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import numpy as np

from embree_rt.compiled import film_sums

GAMMA = 2.2
IMAGE_SUFFIXES = (".png", ".npy", ".npz", ".exr")


class Film:
    """Sums radiance per pixel in float64; ``image(spp)`` is the linear mean.

    Pixels are numbered row-major, ``row * width + column``, row 0 at the top.
    """

    def __init__(self, width: int, height: int) -> None:
        self.width = int(width)
        self.height = int(height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"film size must be positive, got {width}x{height}")
        # One float64 accumulator per channel: float32 sums of millions of samples drift.
        self._sum = np.zeros((3, self.width * self.height), np.float64)

    def add_block(self, block: FilmBlock) -> None:
        """Add a finished block's sums into its pixels."""
        self._sum[:, block.first : block.first + block.count] += block.sums

    def image(self, spp: int) -> np.ndarray:
        """(height, width, 3) float32: the sums divided by ``spp`` samples per pixel."""
        if spp < 1:
            raise ValueError(f"spp: must be >= 1, got {spp}")
        # One pass: divide in float64, round once to float32, written pixel-major.
        return film_sums.mean_image(self._sum, spp).reshape(self.height, self.width, 3)


class FilmBlock:
    """Sums for the ``count`` consecutive pixels from ``first``: what one batch of camera samples
    accumulates on its own (no locking, and cheaper than bincounts over the whole film).

    Each sample is summed into its pixel as it is added (``compiled.film_sums``), in float64,
    in the order added: the sums are bitwise those of one ``np.bincount`` per channel over all
    the samples concatenated.
    """

    def __init__(self, first: int, count: int) -> None:
        self.first = int(first)
        self.count = int(count)
        self._sums = np.zeros((3, self.count), np.float64)

    def add(self, pixel: np.ndarray, rgb: np.ndarray) -> None:
        """Add (3, n) float32 ``rgb`` to the (n,) int64 ``pixel`` indices inside the block."""
        self._check(film_sums.add_samples(self._sums, self.first, pixel, rgb), pixel, None)

    def add_weighted(
        self, pixel: np.ndarray, weight: np.ndarray | None, rgb: np.ndarray,
        columns: np.ndarray | None = None,
    ) -> None:  # fmt: skip
        """``add(pixel[columns], weight[:, columns] * rgb)`` with no temporaries: ``pixel``
        (n,) int64, ``weight`` (3, n) float32 ray weights (None: all ones), ``rgb`` (3, k)
        float32, ``columns`` (k,) int64 the rays ``rgb`` belongs to (None: all n, k = n)."""
        outside = film_sums.add_weighted(self._sums, self.first, pixel, weight, rgb, columns)
        self._check(outside, pixel, columns)

    def _check(self, outside: int, pixel: np.ndarray, columns: np.ndarray | None) -> None:
        """Raise ValueError naming sample ``outside``'s pixel unless it is -1 (all inside)."""
        if outside >= 0:
            at = outside if columns is None else columns[outside]
            raise ValueError(
                f"pixel {int(pixel[at])} is outside the block's pixels "
                f"{self.first}..{self.first + self.count - 1}"
            )

    @property
    def sums(self) -> np.ndarray:
        """(3, count) float64 per-pixel sums of everything added so far."""
        return self._sums


def tonemap(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) linear radiance → (h, w, 3) uint8 display values.

    Per channel: negatives clamp to 0, Reinhard ``c / (1 + c)`` (+inf maps to 1), gamma
    ``1/2.2``, then ``round(255 ·)``. NaN is a bug upstream and raises ValueError.
    """
    image = np.asarray(image, np.float32)
    if np.isnan(image).any():
        raise ValueError("image contains NaN")
    linear = np.maximum(image, np.float32(0.0))
    with np.errstate(invalid="ignore"):
        mapped = np.where(np.isinf(linear), np.float32(1.0), linear / (np.float32(1.0) + linear))
    display = mapped ** np.float32(1.0 / GAMMA)
    return np.clip(np.rint(display * np.float32(255.0)), 0, 255).astype(np.uint8)


def check_output_path(path: str | os.PathLike) -> None:
    """Check, before any rendering, that an image can be written to ``path``.

    Raises ValueError naming the path for an unknown extension, a missing or unwritable
    directory, or a directory in the way; RuntimeError for ``.exr`` without the OpenEXR package.
    """
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise ValueError(
            f"{target}: unknown image extension {target.suffix or '(none)'!r}; "
            f"use one of {', '.join(IMAGE_SUFFIXES)}"
        )
    directory = target.parent
    if not directory.is_dir():
        raise ValueError(f"{target}: directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ValueError(f"{target}: directory {directory} is not writable")
    if target.is_dir():
        raise ValueError(f"{target}: is a directory")
    if suffix == ".exr":
        _exr_module()


def _exr_module():
    try:
        import OpenEXR
    except ImportError:
        raise RuntimeError(
            "writing .exr images needs the OpenEXR package: pip install openexr "
            "(or pip install 'embree-rt[exr]')"
        ) from None
    return OpenEXR


def _write_png(image: np.ndarray, handle: BinaryIO) -> None:
    from PIL import Image

    Image.fromarray(tonemap(image)).save(handle, format="PNG")


def _write_npy(image: np.ndarray, handle: BinaryIO) -> None:
    np.save(handle, np.asarray(image, np.float32))


def _write_npz(image: np.ndarray, handle: BinaryIO) -> None:
    np.savez(handle, beauty=np.asarray(image, np.float32))


def _write_exr(image: np.ndarray, handle: BinaryIO) -> None:
    write_exr_channels({"RGB": np.ascontiguousarray(image, np.float32)}, handle)


def write_exr_channels(channels: dict[str, np.ndarray], handle: BinaryIO) -> None:
    """Write ``channels`` (name -> (h, w) float32 or uint32 array; "RGB" -> (h, w, 3) float32,
    stored as R, G, B) as a ZIP-compressed scanline EXR to the file ``handle`` is open on."""
    OpenEXR = _exr_module()
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    # OpenEXR writes by file name; the open handle only reserved that name.
    with OpenEXR.File(header, channels) as exr:
        exr.write(os.fspath(handle.name))


# Writers by extension: writer(image, binary file handle opened on the temp file's path).
WRITERS: dict[str, Callable[[np.ndarray, BinaryIO], None]] = {
    ".png": _write_png,
    ".npy": _write_npy,
    ".npz": _write_npz,
    ".exr": _write_exr,
}


def check_image_shape(image: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """``image`` as an array; ValueError naming ``path`` unless it is (h, w, 3), h, w >= 1."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f"{path}: expected an (h, w, 3) image, got shape {image.shape}")
    return image


def save_image(image: np.ndarray, path: str | os.PathLike) -> None:
    """Write the (h, w, 3) float32 linear ``image`` to ``path`` by its extension
    (case-insensitive): ``.png`` tone-mapped 8-bit, ``.npy``, ``.npz`` (as ``beauty``) and
    ``.exr`` linear float32.

    Atomic (``write_atomically``): on any failure, Ctrl-C included, an existing file at
    ``path`` is left as it was and no partial file is left.
    """
    check_output_path(path)
    image = check_image_shape(image, path)
    target = Path(path)
    writer = WRITERS[target.suffix.lower()]
    write_atomically([(target, lambda handle: writer(image, handle))])


def write_atomically(files: list[tuple[Path, Callable[[BinaryIO], None]]]) -> None:
    """Write each of ``files`` (target path, writer(binary handle)) all or nothing.

    Every file goes to a temp file in its target's directory; only once all are complete are
    they renamed over their targets. On any failure, Ctrl-C included, the temp files are
    removed and existing files at the targets are left as they were.
    """
    temps: list[Path] = []
    try:
        for target, write in files:
            # A plain exclusive open(), not tempfile's: the umask then gives the image the usual
            # mode (tempfile's files are private, 0600). A name someone else holds raises
            # FileExistsError before it joins ``temps``: never delete another's file.
            temp = target.with_name(f".{target.name}.{secrets.token_hex(8)}.tmp")
            handle = open(temp, "xb")  # noqa: SIM115 (closed by the with below)
            temps.append(temp)
            with handle:
                write(handle)
        for temp, (target, _) in zip(temps, files, strict=True):
            os.replace(temp, target)
    except BaseException:
        for temp in temps:
            temp.unlink(missing_ok=True)
        raise
