"""The compiled output stage (``compiled.display_codes`` through ``film.tonemap``) against NumPy's
``display_values`` + ``quantize`` and against the float64 closed form.

Why the codes are NumPy's bit for bit on every ISA: the compiled pass computes no power. It
reads the thresholds where NumPy's own curve (on the machine running the test, whatever
power NumPy takes there) steps from one code to the next, found by bisection over float32 bit
patterns; the steps before the curve (clamp, exposure product, Reinhard's division, ACES's
products and sums, the clip) are single IEEE operations, the same bits in NumPy and in numba
(no fastmath, no FMA contraction). That holds if NumPy's curve followed by rounding never
steps back down; the sweep of 64 values either side of every threshold checks it where it
could fail.
"""

from __future__ import annotations

import numpy as np
import pytest

from embree_rt import film
from embree_rt.film import Look

LOOKS = [
    Look(exposure, tonemap, transfer)
    for tonemap in film.TONEMAPS
    for transfer in film.TRANSFERS
    for exposure in (0.0, -1.25, 2.0)
]


def numpy_codes(image: np.ndarray, look: Look) -> np.ndarray:
    with np.errstate(over="ignore"):  # exposure times the largest float32 is inf, as meant
        return film.quantize(film.display_values(image, look), 8)


def hdr_image(seed: int, shape=(61, 97)) -> np.ndarray:
    """(h, w, 3) float32 radiance over many decades, with the edge values the stage must
    take: +inf, negatives, -0.0, subnormals, the largest float32."""
    rng = np.random.default_rng(seed)
    image = rng.exponential(1.0, (*shape, 3)) * 10.0 ** rng.uniform(-7, 3, (*shape, 3))
    image = image.astype(np.float32)
    edges = [np.inf, -1.0, -0.0, 0.0, 1e-44, np.finfo(np.float32).max, 1.0, 0.5]
    image.reshape(-1)[: len(edges)] = edges
    return image


def around_thresholds(transfer: str, reach: int = 64) -> np.ndarray:
    """(1, n, 3) float32: every float32 within ``reach`` ulps of each code threshold."""
    bits = film.code_thresholds(transfer).view(np.uint32).astype(np.int64)
    steps = np.arange(-reach, reach + 1)
    values = (bits[:, None] + steps[None, :]).clip(0, None).astype(np.uint32).view(np.float32)
    values = values.reshape(-1)
    return np.repeat(values, 3).reshape(1, -1, 3)


@pytest.mark.parametrize("look", LOOKS, ids=str)
def test_compiled_codes_are_numpys_bitwise(look: Look) -> None:
    image = hdr_image(7)
    assert np.array_equal(film.tonemap(image, look), numpy_codes(image, look))


@pytest.mark.parametrize("transfer", film.TRANSFERS)
def test_codes_at_every_step_of_the_curve_are_numpys(transfer: str) -> None:
    # tone map "none" with no exposure passes m in [0, 1] through unchanged: these values land
    # on the table's steps themselves
    look = Look(0.0, "none", transfer)
    values = around_thresholds(transfer)
    assert np.array_equal(film.tonemap(values, look), numpy_codes(values, look))


@pytest.mark.parametrize("transfer", film.TRANSFERS)
def test_each_threshold_is_where_numpys_code_steps_up(transfer: str) -> None:
    thresholds = film.code_thresholds(transfer)
    assert np.all(np.diff(thresholds) > 0)
    before = np.nextafter(thresholds, np.float32(-1.0))
    codes = np.arange(1, 256)
    assert np.all(
        numpy_codes(thresholds.reshape(1, -1, 1).repeat(3, 2), Look(0.0, "none", transfer))[0, :, 0]
        >= codes
    )
    assert np.all(
        numpy_codes(before.reshape(1, -1, 1).repeat(3, 2), Look(0.0, "none", transfer))[0, :, 0]
        < codes
    )


@pytest.mark.parametrize("look", LOOKS, ids=str)
def test_codes_are_within_one_of_the_float64_closed_form(look: Look) -> None:
    image = hdr_image(11)
    x = np.maximum(image.astype(np.float64), 0.0) * 2.0**look.exposure
    with np.errstate(invalid="ignore", over="ignore"):
        if look.tonemap == "reinhard":
            m = np.where(np.isinf(x), 1.0, x / (1.0 + x))
        elif look.tonemap == "aces":
            v = np.minimum(x, 1e15)
            m = np.where(
                np.isinf(x),
                1.0,
                np.clip(v * (2.51 * v + 0.03) / (v * (2.43 * v + 0.59) + 0.14), 0, 1),
            )
        else:
            m = np.minimum(x, 1.0)
    if look.transfer == "srgb":
        shown = np.where(m <= 0.0031308, 12.92 * m, 1.055 * m ** (1 / 2.4) - 0.055)
    else:
        shown = m ** (1 / 2.2)
    expected = np.rint(np.clip(shown, 0, 1) * 255)
    assert np.abs(film.tonemap(image, look).astype(np.int64) - expected).max() <= 1


def test_nan_is_refused_and_odd_shapes_are_read_in_c_order() -> None:
    image = hdr_image(3)
    strided = np.asfortranarray(image)
    assert np.array_equal(film.tonemap(strided), numpy_codes(image, film.DEFAULT_LOOK))
    image[5, 6, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        film.tonemap(image)


def test_png_holds_the_compiled_codes(tmp_path) -> None:
    from PIL import Image

    image = hdr_image(5)
    film.save_image(image, tmp_path / "out.png")
    with Image.open(tmp_path / "out.png") as decoded:
        assert np.array_equal(np.asarray(decoded), numpy_codes(image, film.DEFAULT_LOOK))


def test_rows_run_on_threads_give_the_serial_codes() -> None:
    # large enough for the threaded path (film.DISPLAY_SERIAL_CHANNELS), with a NaN in the last
    # span: every span's count reaches the caller
    rows = 2 * film.DISPLAY_ROWS_PER_TASK + 5
    columns = film.DISPLAY_SERIAL_CHANNELS // (3 * rows) + 1
    image = hdr_image(13, (rows, columns))
    assert image.size >= film.DISPLAY_SERIAL_CHANNELS
    assert np.array_equal(film.tonemap(image), numpy_codes(image, film.DEFAULT_LOOK))
    image[-1, -1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        film.tonemap(image)
