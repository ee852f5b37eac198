"""The film: linear accumulation, Reinhard tone mapping, gamma, and atomic image files.

Display images (.png, .jpg/.jpeg, .tif/.tiff, .webp) hold the tone-mapped picture, 8 bits a
channel through Pillow, or 16 (``Encoding.bit_depth``; .png and .tif/.tiff) for grading: Pillow
holds no 16-bit RGB image (its 16-bit modes are single-channel), so 16-bit PNG goes through
pypng and 16-bit TIFF through tifffile, both small pure-Python writers; 8-bit PNG goes through
pypng too, for speed (``PNG_COMPRESS_LEVEL``). Data images (.npy, .npz, .exr) hold the linear
float32 radiance."""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import cache, partial
from pathlib import Path
from typing import BinaryIO, NamedTuple

import numpy as np

from embree_rt.batches import worker_count
from embree_rt.choices import BACKGROUNDS, TONEMAPS, TRANSFERS
from embree_rt.compiled import display_codes, film_sums
from embree_rt.legend import Legend, draw_legend

GAMMA = 2.2
# zlib level of 8-bit PNGs (Pillow's default is 6). Measured with Pillow 13 on zlib-ng 2.3 on a
# 1080p render of the 1e6-sphere field (docs/performance.md, "The output stage"): level 2 wrote
# in 0.43x level 6's time a file 10% larger; 1 was no faster and larger still, 3 slower.
# 8-bit PNGs are written by pypng, rows unfiltered, at this level: Pillow tries every PNG filter
# on every row, which cost more than the compression (docs/performance.md, "The output stage";
# benchmarks/png_writers.py).
PNG_COMPRESS_LEVEL = 2
# The compiled tone map runs spans of this many rows on Python threads, each taking the next
# span as it comes free, below ``DISPLAY_SERIAL_CHANNELS`` on the calling thread alone. Not a
# numba parallel loop: its static halves waited on the busy core (2 cores, other processes
# running: a 320x180 image took 48 ms in a prange, 0.7 ms on one thread; 1080p 90 ms, 46 ms).
DISPLAY_ROWS_PER_TASK = 32
DISPLAY_SERIAL_CHANNELS = 1 << 20
# Display formats: Pillow's name for each extension.
PILLOW_FORMATS = {
    ".png": "PNG",
    ".jpg": "JPEG",
    ".jpeg": "JPEG",
    ".tif": "TIFF",
    ".tiff": "TIFF",
    ".webp": "WEBP",
}
IMAGE_SUFFIXES = (*PILLOW_FORMATS, ".npy", ".npz", ".exr")
SIXTEEN_BIT_SUFFIXES = (".png", ".tif", ".tiff")
QUALITY_SUFFIXES = (".jpg", ".jpeg", ".webp")
DEFAULT_QUALITY = 90
# The formats that hold an alpha channel (a transparent background, ``choices.BACKGROUNDS``).
ALPHA_SUFFIXES = (".png", ".tif", ".tiff", ".webp")


class Encoding(NamedTuple):
    """How a display image stores its pixels: ``bit_depth`` 8, or 16 for .png and .tif/.tiff;
    ``quality`` 1 to 100 for the lossy .jpg/.jpeg and .webp (None: ``DEFAULT_QUALITY``);
    ``look`` the tone mapping (``Look``; None: the default); ``background`` one of
    ``BACKGROUNDS``: other than "sky", the image carries a 4th channel, the share of each
    pixel's camera rays that met something (its colour channels hold nothing where they did
    not), and the background goes where they did not (``composite``); ``legend`` what the
    colours mean (``legend.Legend``): drawn into display images, and written beside every
    format as a JSON sidecar (``legend_json_path``), None for neither."""

    bit_depth: int = 8
    quality: int | None = None
    look: Look | None = None
    background: str = "sky"
    legend: Legend | None = None


DEFAULT_ENCODING = Encoding()


def encoding_problem(suffix: str, encoding: Encoding) -> str | None:
    """What keeps ``encoding`` from applying to a file with the extension ``suffix``, or None."""
    if encoding.bit_depth not in (8, 16):
        return f"bit depth must be 8 or 16, got {encoding.bit_depth}"
    if encoding.bit_depth == 16 and suffix not in SIXTEEN_BIT_SUFFIXES:
        return f"16-bit images are written as {', '.join(SIXTEEN_BIT_SUFFIXES)}, not {suffix}"
    if encoding.background not in BACKGROUNDS:
        return f"background must be one of {', '.join(BACKGROUNDS)}, got {encoding.background!r}"
    if encoding.background == "transparent" and suffix not in ALPHA_SUFFIXES:
        return f"a transparent background needs an alpha channel: {', '.join(ALPHA_SUFFIXES)}"
    if encoding.quality is not None:
        if suffix not in QUALITY_SUFFIXES:
            return f"quality applies to the lossy {', '.join(QUALITY_SUFFIXES)}, not {suffix}"
        if not 1 <= encoding.quality <= 100:
            return f"quality must be 1 to 100, got {encoding.quality}"
    return None


TEMP_TOKEN_HEX = 16  # hex digits of the random part of a temporary file's name


class Film:
    """Sums radiance per pixel in float64; ``image(spp)`` is the linear mean.

    Pixels are numbered row-major, ``row * width + column``, row 0 at the top.
    """

    def __init__(self, width: int, height: int) -> None:
        self.width = int(width)
        self.height = int(height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"film size must be positive, got {width}x{height}")
        # One float64 accumulator per channel (float32 sums of millions of samples drift),
        # made only when blocks overlap: blocks that come in pixel order without overlapping
        # (a render's batches, each pixel summed in one block) are kept as (first, sums) and
        # their means written straight into the image, with no whole-film buffer to fault in
        # and add into (0 + x is x: the same bits).
        self._sum: np.ndarray | None = None
        self._blocks: list[tuple[int, np.ndarray]] = []
        self._end = 0  # where the kept blocks end

    def add_block(self, block: FilmBlock) -> None:
        """Add a finished block's sums into its pixels."""
        if block.first < 0 or block.first + block.count > self.width * self.height:
            raise ValueError(
                f"block of pixels {block.first}..{block.first + block.count - 1} is outside "
                f"the film's {self.width * self.height}"
            )
        if self._sum is None and block.first >= self._end:
            self._blocks.append((block.first, block.sums))
            self._end = block.first + block.count
            return
        if self._sum is None:  # an overlap: from here on, sums in the whole-film buffer
            self._sum = np.zeros((3, self.width * self.height), np.float64)
            for first, sums in self._blocks:
                self._sum[:, first : first + sums.shape[1]] += sums
            self._blocks = []
        self._sum[:, block.first : block.first + block.count] += block.sums

    def image(self, spp: int) -> np.ndarray:
        """(height, width, 3) float32: the sums divided by ``spp`` samples per pixel."""
        if spp < 1:
            raise ValueError(f"spp: must be >= 1, got {spp}")
        # One pass: divide in float64, round once to float32, written pixel-major.
        if self._sum is not None:
            mean = film_sums.mean_image(self._sum, spp)
        else:
            mean = np.empty((self.width * self.height, 3), np.float32)
            covered = 0
            for first, sums in self._blocks:
                mean[covered:first] = 0.0  # pixels no block reached: 0 / spp
                film_sums.mean_into(mean, first, sums, spp)
                covered = first + sums.shape[1]
            mean[covered:] = 0.0
        return mean.reshape(self.height, self.width, 3)


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
        self,
        pixel: np.ndarray,
        weight: np.ndarray,
        rgb: np.ndarray,
        columns: np.ndarray | None = None,
    ) -> None:
        """``add(pixel[columns], weight[:, columns] * rgb)`` with no temporaries: ``pixel``
        (n,) int64, ``weight`` (3, n) float32 ray weights, ``rgb`` (3, k)
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


class Look(NamedTuple):
    """How linear radiance becomes display values: ``exposure`` in stops (the radiance times
    ``2 ** exposure``), ``tonemap`` (``TONEMAPS``: Reinhard ``c / (1 + c)``, the ACES filmic
    fit of Narkowicz 2015, or none: clipped at 1), ``transfer`` (``TRANSFERS``: a pure power
    ``1/2.2``, or sRGB's piecewise curve). The default is the seed article's look."""

    exposure: float = 0.0
    tonemap: str = "reinhard"
    transfer: str = "gamma2.2"


DEFAULT_LOOK = Look()
_TONEMAP_IDS = {
    "reinhard": display_codes.TONEMAP_REINHARD,
    "aces": display_codes.TONEMAP_ACES,
    "none": display_codes.TONEMAP_NONE,
}


def tonemap(image: np.ndarray, look: Look = DEFAULT_LOOK) -> np.ndarray:
    """(h, w, 3) linear radiance → (h, w, 3) uint8 display values: ``display_values``
    quantized to 8 bits, bit for bit, in one compiled pass (``compiled.display_codes``, which
    reads the transfer curve's code thresholds, ``code_thresholds``), spans of rows taken by
    a thread each as it comes free. NaN is a bug upstream and raises ValueError."""
    check_look(look)
    image = np.ascontiguousarray(image, np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (h, w, 3) image, got shape {image.shape}")
    out = np.empty(image.shape, np.uint8)
    scale = np.float32(2.0**look.exposure) if look.exposure else np.float32(1.0)
    tables = code_table(look.transfer)
    tonemap_id = _TONEMAP_IDS[look.tonemap]

    def convert(first: int) -> int:
        stop = min(first + DISPLAY_ROWS_PER_TASK, image.shape[0])
        return display_codes.display_codes(image, first, stop, scale, tonemap_id, *tables, out)

    starts = range(0, image.shape[0], DISPLAY_ROWS_PER_TASK)
    workers = min(worker_count(None), len(starts))
    if workers < 2 or image.size < DISPLAY_SERIAL_CHANNELS:
        nans = sum(map(convert, starts))
    else:
        with ThreadPoolExecutor(workers) as pool:
            nans = sum(pool.map(convert, starts))
    if nans:
        raise ValueError("image contains NaN")
    return out


@cache
def code_table(transfer: str) -> tuple[np.ndarray, np.ndarray]:
    """The ``transfer`` curve's (255,) float32 ``code_thresholds`` and their (BUCKETS,) uint8
    ``display_codes.bucket_codes``: what the compiled pass reads, made once a process."""
    thresholds = code_thresholds(transfer)
    return thresholds, display_codes.bucket_codes(thresholds)


def code_thresholds(transfer: str) -> np.ndarray:
    """(255,) float32: element k - 1 is the smallest tone-mapped value m in [0, 1] whose 8-bit
    code (``quantize`` of the ``transfer`` curve, computed by NumPy as ``display_values`` does)
    is k or more. Found by bisection over the bit patterns of float32 m, all 255 at once (31
    steps: non-negative floats order as their bits do)."""
    low = np.zeros(display_codes.THRESHOLDS, np.uint32)
    high = np.full(display_codes.THRESHOLDS, np.float32(1.0).view(np.uint32))
    wanted = np.arange(1, display_codes.THRESHOLDS + 1)
    while (low < high).any():
        middle = low + (high - low) // 2
        reached = _transfer_codes(middle.view(np.float32), transfer) >= wanted
        high = np.where(reached, middle, high)
        low = np.where(reached, low, middle + 1)
    return low.view(np.float32)


def _transfer_codes(mapped: np.ndarray, transfer: str) -> np.ndarray:
    """(n,) uint8 codes of contiguous float32 tone-mapped values, by ``display_values``' curve."""
    curve = srgb_encode(mapped) if transfer == "srgb" else mapped ** np.float32(1.0 / GAMMA)
    return quantize(curve, 8)


def check_look(look: Look) -> None:
    """Raise ValueError unless ``look`` names a known tone map and transfer curve."""
    if look.tonemap not in TONEMAPS or look.transfer not in TRANSFERS:
        raise ValueError(
            f"look: tonemap must be one of {TONEMAPS} and transfer one of "
            f"{TRANSFERS}, got {look.tonemap!r} and {look.transfer!r}"
        )


def display_values(image: np.ndarray, look: Look = DEFAULT_LOOK) -> np.ndarray:
    """(h, w, 3) linear radiance → (h, w, 3) float32 display values in [0, 1], per channel:
    negatives clamp to 0, then ``look``'s exposure, tone map (+inf maps to 1) and transfer
    curve. The default (Reinhard, gamma 1/2.2) is computed as it always was. NaN is a bug
    upstream and raises ValueError.
    """
    check_look(look)
    image = np.asarray(image, np.float32)
    if np.isnan(image).any():
        raise ValueError("image contains NaN")
    linear = np.maximum(image, np.float32(0.0))
    if look.exposure:
        linear = linear * np.float32(2.0**look.exposure)
    with np.errstate(invalid="ignore", over="ignore"):
        if look.tonemap == "reinhard":
            mapped = np.where(
                np.isinf(linear), np.float32(1.0), linear / (np.float32(1.0) + linear)
            )
        elif look.tonemap == "aces":
            mapped = np.where(np.isinf(linear), np.float32(1.0), aces(linear))
        else:
            mapped = np.minimum(linear, np.float32(1.0))
    if look.transfer == "srgb":
        return srgb_encode(mapped)
    return mapped ** np.float32(1.0 / GAMMA)


def aces(linear: np.ndarray) -> np.ndarray:
    """Narkowicz's fit of the ACES filmic curve, ``x (2.51 x + 0.03) / (x (2.43 x + 0.59) +
    0.14)`` clipped to [0, 1], on finite non-negative float32 ``linear`` (same shape)."""
    a, b, c, d, e = (np.float32(v) for v in (2.51, 0.03, 2.43, 0.59, 0.14))
    # large x: the ratio tends to a / c > 1; dividing through by x keeps it finite
    x = np.minimum(linear, np.float32(1e15))
    return np.clip((x * (a * x + b)) / (x * (c * x + d) + e), np.float32(0.0), np.float32(1.0))


def srgb_encode(mapped: np.ndarray) -> np.ndarray:
    """sRGB's transfer curve (IEC 61966-2-1) on float32 values in [0, 1]: ``12.92 x`` up to
    0.0031308, ``1.055 x^(1/2.4) - 0.055`` above."""
    curve = np.float32(1.055) * mapped ** np.float32(1.0 / 2.4) - np.float32(0.055)
    return np.where(mapped <= np.float32(0.0031308), np.float32(12.92) * mapped, curve)


def quantize(display: np.ndarray, bits: int) -> np.ndarray:
    """Float display values in [0, 1] → uint8 (``bits`` 8) or uint16 (16): ``round((2^bits -
    1) ·)``, clipped."""
    top = float(2**bits - 1)
    dtype = np.uint8 if bits == 8 else np.uint16
    return np.clip(np.rint(display * np.float32(top)), 0, top).astype(dtype)


def check_output_path(path: str | os.PathLike, encoding: Encoding = DEFAULT_ENCODING) -> None:
    """Check, before any rendering, that an image can be written to ``path`` as ``encoding``.

    Raises ValueError naming the path for an unknown extension, an encoding it cannot take, a
    missing or unwritable directory, a directory in the way, or a name too long for the file
    system (the temporary name it is written under included); RuntimeError for ``.exr``
    without the OpenEXR package.
    """
    target = Path(path)
    check_image_name(target, encoding)
    directory = target.parent
    try:
        # os.stat, not is_dir: a loop of links or a file in the path is said as what it is
        if not stat.S_ISDIR(os.stat(directory).st_mode):
            raise ValueError(f"{target}: {directory} is not a directory")
        if not os.access(directory, os.W_OK | os.X_OK):
            raise ValueError(f"{target}: directory {directory} is not writable")
        if target.is_dir():
            raise ValueError(f"{target}: is a directory")
        longest = os.pathconf(directory, "PC_NAME_MAX")
    except FileNotFoundError:
        raise ValueError(f"{target}: directory {directory} does not exist") from None
    except OSError as error:  # a path too long for the system, a directory that cannot be read
        raise ValueError(f"{target}: {error.strerror or error}") from None
    name = len(os.fsencode(target.name))
    extra = len(os.fsencode(temp_path(target).name)) - name
    if name + extra > longest:
        raise ValueError(
            f"{target}: file name too long ({name} bytes): this file system takes names of up "
            f"to {longest} bytes, and the image is first written under a temporary name {extra} "
            "bytes longer"
        )


def check_image_name(path: str | os.PathLike, encoding: Encoding = DEFAULT_ENCODING) -> None:
    """``check_output_path``'s checks of the name alone: a known extension that can take
    ``encoding`` (ValueError), and OpenEXR present for ``.exr`` (RuntimeError)."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise ValueError(
            f"{target}: unknown image extension {target.suffix or '(none)'!r}; "
            f"use one of {', '.join(IMAGE_SUFFIXES)}"
        )
    if (problem := encoding_problem(suffix, encoding)) is not None:
        raise ValueError(f"{target}: {problem}")
    if suffix == ".exr":
        _exr_module()


def _exr_module():
    try:
        import OpenEXR
    except ImportError:
        from embree_rt.errors import install_hint

        raise RuntimeError(
            f"writing .exr images needs the OpenEXR package: {install_hint('exr', 'openexr')}"
        ) from None
    return OpenEXR


def write_pixels(
    pixels: np.ndarray, handle: BinaryIO, suffix: str, quality: int | None = None
) -> None:
    """Write (h, w, 3) (or with alpha (h, w, 4)) uint8 or uint16 display ``pixels`` as the
    display format of ``suffix``
    (``PILLOW_FORMATS``) to ``handle``: PNG through pypng (8-bit rows unfiltered at zlib level
    ``PNG_COMPRESS_LEVEL``), other uint8 formats through Pillow (``quality`` for JPEG and
    WebP), uint16 TIFF through tifffile."""
    height, width, channels = pixels.shape
    alpha = channels == 4
    if suffix == ".png":
        import png

        depth = 16 if pixels.dtype == np.uint16 else 8
        level = PNG_COMPRESS_LEVEL if depth == 8 else None
        writer = png.Writer(
            width, height, greyscale=False, alpha=alpha, bitdepth=depth, compression=level
        )
        writer.write(handle, pixels.reshape(height, width * channels))
        return
    if pixels.dtype == np.uint16:
        import tifffile

        extra = {"extrasamples": ["unassalpha"]} if alpha else {}
        tifffile.imwrite(handle, pixels, photometric="rgb", **extra)
        return
    from PIL import Image

    name = PILLOW_FORMATS[suffix]
    options = {"quality": quality or DEFAULT_QUALITY} if suffix in QUALITY_SUFFIXES else {}
    Image.fromarray(pixels).save(handle, format=name, **options)


def composite(values: np.ndarray, alpha: np.ndarray, background: str) -> np.ndarray:
    """(h, w, 3) float32 ``values`` (display values in [0, 1], or linear radiance) of pixels
    whose camera rays met something in the (h, w) float32 share ``alpha`` (and nothing
    elsewhere) over ``background``: white adds ``1 - alpha`` of white, black nothing;
    transparent gives (h, w, 4) straight (not premultiplied) colour and alpha, as PNG holds."""
    if background == "white":
        return values + (np.float32(1.0) - alpha)[..., None]
    if background == "black":
        return values
    with np.errstate(divide="ignore", invalid="ignore"):
        straight = np.where(alpha[..., None] > 0, values / alpha[..., None], np.float32(0.0))
    return np.concatenate([np.minimum(straight, np.float32(1.0)), alpha[..., None]], axis=2)


def _write_display(
    suffix: str, image: np.ndarray, handle: BinaryIO, encoding: Encoding = DEFAULT_ENCODING
) -> None:
    look = encoding.look or DEFAULT_LOOK
    if image.shape[2] == 4:  # an alpha channel: composited over the encoding's background
        values = composite(display_values(image[..., :3], look), image[..., 3], encoding.background)
        pixels = quantize(values, encoding.bit_depth)
    elif encoding.bit_depth == 8:
        pixels = tonemap(image, look)
    else:
        pixels = quantize(display_values(image, look), encoding.bit_depth)
    if encoding.legend is not None:
        pixels = draw_legend(pixels, encoding.legend)
    write_pixels(pixels, handle, suffix, encoding.quality)


def linear_picture(image: np.ndarray, encoding: Encoding) -> np.ndarray:
    """(h, w, 3) float32 linear ``image`` as the data formats hold it: with an alpha channel
    (``Encoding.background``) composited over white (radiance 1) or black."""
    image = np.asarray(image, np.float32)
    if image.shape[2] == 4:
        image = composite(image[..., :3], image[..., 3], encoding.background)
    return image


def _write_npy(image: np.ndarray, handle: BinaryIO, encoding: Encoding = DEFAULT_ENCODING) -> None:
    save_npy(linear_picture(image, encoding), handle)


class _WriteOnly:
    """A binary file seen only through its ``write``: NumPy then writes it in chunks with that
    method instead of with ``ndarray.tofile``."""

    def __init__(self, handle: BinaryIO) -> None:
        self.write = handle.write


def save_npy(array: np.ndarray, handle: BinaryIO) -> None:
    """``np.save`` of ``array`` to the binary file ``handle``, through the file's own writes: a
    failed write then raises the OSError of its errno ("No space left on device"), where
    ``tofile`` (NumPy's way with a real file) says only "N requested and M written"."""
    np.save(_WriteOnly(handle), array)


def _write_npz(image: np.ndarray, handle: BinaryIO, encoding: Encoding = DEFAULT_ENCODING) -> None:
    np.savez(handle, beauty=linear_picture(image, encoding))


def _write_exr(image: np.ndarray, handle: BinaryIO, encoding: Encoding = DEFAULT_ENCODING) -> None:
    write_exr_channels({"RGB": np.ascontiguousarray(linear_picture(image, encoding))}, handle)


def write_exr_channels(channels: dict[str, np.ndarray], handle: BinaryIO) -> None:
    """Write ``channels`` (name -> (h, w) float32 or uint32 array; "RGB" -> (h, w, 3) float32,
    stored as R, G, B) as a ZIP-compressed scanline EXR to the file ``handle`` is open on."""
    OpenEXR = _exr_module()
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    # OpenEXR writes by file name; the open handle only reserved that name.
    with OpenEXR.File(header, channels) as exr:
        exr.write(os.fspath(handle.name))


# Writers by extension: writer(image, binary file handle opened on the temp file's path,
# Encoding).
WRITERS: dict[str, Callable[..., None]] = {
    **{suffix: partial(_write_display, suffix) for suffix in PILLOW_FORMATS},
    ".npy": _write_npy,
    ".npz": _write_npz,
    ".exr": _write_exr,
}


def check_image_shape(
    image: np.ndarray, path: str | os.PathLike, encoding: Encoding = DEFAULT_ENCODING
) -> np.ndarray:
    """``image`` as an array; ValueError naming ``path`` unless it is (h, w, 3), h, w >= 1, or
    (h, w, 4) with a background other than the sky (``Encoding``)."""
    image = np.asarray(image)
    channels = 3 if encoding.background == "sky" else 4
    if image.ndim != 3 or image.shape[2] != channels or image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(
            f"{path}: expected an (h, w, {channels}) image with background "
            f"{encoding.background!r}, got shape {image.shape}"
        )
    return image


def save_image(
    image: np.ndarray, path: str | os.PathLike, encoding: Encoding = DEFAULT_ENCODING
) -> None:
    """Write the (h, w, 3) float32 linear ``image`` to ``path`` by its extension
    (case-insensitive): ``.png``, ``.jpg``/``.jpeg``, ``.tif``/``.tiff``, ``.webp`` tone-mapped
    (``encoding``: 8 or 16 bits, quality), ``.npy``, ``.npz`` (as ``beauty``) and ``.exr``
    linear float32.

    Atomic (``write_atomically``): on any failure, Ctrl-C included, an existing file at
    ``path`` is left as it was and no partial file is left.
    """
    check_output_path(path, encoding)
    image = check_image_shape(image, path, encoding)
    target = Path(path)
    writer = WRITERS[target.suffix.lower()]
    files = [(target, lambda handle: writer(image, handle, encoding))]
    write_atomically(files + legend_sidecar(target, encoding))


def legend_json_path(target: Path) -> Path:
    """The legend sidecar of the image ``target``: ``render.legend.json`` beside ``render.png``."""
    return target.with_name(f"{target.stem}.legend.json")


def legend_sidecar(target: Path, encoding: Encoding) -> list[tuple[Path, Callable]]:
    """The legend's JSON sidecar of the image ``target`` as ``write_atomically`` takes files
    (none without a legend)."""
    if encoding.legend is None:
        return []
    record = encoding.legend.json_bytes()
    return [(legend_json_path(target), lambda handle: handle.write(record))]


def temp_path(target: Path) -> Path:
    """A fresh name to write ``target`` under until it is complete: hidden, beside it."""
    return target.with_name(f".{target.name}.{secrets.token_hex(TEMP_TOKEN_HEX // 2)}.tmp")


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
            temp = temp_path(target)
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
