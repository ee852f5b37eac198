"""The film (embree_rt/film.py): accumulation against a Python loop, tone mapping against hand
values, and image files: Pillow / NumPy round trips, early path errors, atomic replacement."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from embree_rt import film
from embree_rt.film import Film, FilmBlock, save_image, tonemap

WIDTH, HEIGHT = 7, 5


def random_samples(seed: int, count: int, first: int = 0, stop: int = WIDTH * HEIGHT):
    rng = np.random.default_rng(seed)
    pixel = rng.integers(first, stop, count).astype(np.int64)
    rgb = rng.uniform(0.0, 4.0, (count, 3)).astype(np.float32)
    return pixel, rgb


def loop_sums(pixel: np.ndarray, rgb: np.ndarray, size: int, offset: int = 0) -> np.ndarray:
    """(size, 3) float64 per-pixel sums, one sample at a time."""
    sums = np.zeros((size, 3))
    for p, color in zip(pixel.tolist(), rgb.tolist(), strict=True):
        for channel in range(3):
            sums[p - offset][channel] += color[channel]
    return sums


def as_image(sums: np.ndarray) -> np.ndarray:
    """Row-major pixel sums (WIDTH * HEIGHT, 3) → (HEIGHT, WIDTH, 3), pixel p at (p // W, p % W)."""
    image = np.zeros((HEIGHT, WIDTH, 3))
    for p in range(WIDTH * HEIGHT):
        image[p // WIDTH, p % WIDTH] = sums[p]
    return image


# -- accumulation ---------------------------------------------------------------------------------


def test_film_add_sums_samples_per_pixel_like_a_loop() -> None:
    accumulated = Film(WIDTH, HEIGHT)
    first = random_samples(0, 3000)
    second = random_samples(1, 500)
    accumulated.add(*first)
    accumulated.add(*second)
    accumulated.add(np.zeros(0, np.int64), np.zeros((0, 3), np.float32))  # empty: no-op
    pixel = np.concatenate([first[0], second[0]])
    rgb = np.concatenate([first[1], second[1]])
    expected = as_image(loop_sums(pixel, rgb, WIDTH * HEIGHT))
    for spp in (1, 8):
        image = accumulated.image(spp)
        assert image.dtype == np.float32 and image.shape == (HEIGHT, WIDTH, 3)
        assert image.flags.c_contiguous
        np.testing.assert_allclose(image, expected / spp, rtol=1e-6)


def test_film_image_puts_pixel_indices_row_major() -> None:
    marked = Film(WIDTH, HEIGHT)
    marked.add(np.array([0, WIDTH - 1, WIDTH, WIDTH * HEIGHT - 1]), np.eye(4, 3, dtype=np.float32))
    image = marked.image(1)
    assert image[0, 0].tolist() == [1, 0, 0]  # top left
    assert image[0, WIDTH - 1].tolist() == [0, 1, 0]  # top right
    assert image[1, 0].tolist() == [0, 0, 1]  # second row
    assert image.sum() == 3.0  # the fourth sample is black: nothing anywhere else


def test_film_block_add_sums_its_own_pixels_like_a_loop() -> None:
    first, count = 9, 13
    block = FilmBlock(first, count)
    pixel, rgb = random_samples(2, 2000, first, first + count)
    block.add(pixel[:1200], rgb[:1200])
    block.add(pixel[1200:], rgb[1200:])
    block.add(np.zeros(0, np.int64), np.zeros((0, 3), np.float32))
    np.testing.assert_allclose(block.sums.T, loop_sums(pixel, rgb, count, first), rtol=1e-12)


def test_film_add_block_equals_adding_the_samples_directly() -> None:
    # Three batches as the integrator makes them: consecutive pixel ranges, the last one short,
    # and one range rendered in two blocks (two batches sharing a pixel).
    ranges = [(0, 12), (12, 12), (24, 11), (30, 5)]
    blocked, direct = Film(WIDTH, HEIGHT), Film(WIDTH, HEIGHT)
    all_pixels, all_rgb = [], []
    for seed, (first, count) in enumerate(ranges):
        pixel, rgb = random_samples(10 + seed, 300, first, first + count)
        block = FilmBlock(first, count)
        block.add(pixel, rgb)
        blocked.add_block(block)
        direct.add(pixel, rgb)
        all_pixels.append(pixel)
        all_rgb.append(rgb)
    expected = as_image(loop_sums(np.concatenate(all_pixels), np.concatenate(all_rgb), 35))
    np.testing.assert_allclose(blocked.image(4), expected / 4, rtol=1e-6)
    np.testing.assert_allclose(blocked.image(4), direct.image(4), rtol=1e-6)


# -- tone mapping ---------------------------------------------------------------------------------


def reference_tonemap(c: float) -> int:
    """Reinhard c / (1 + c), gamma 1/2.2, to 8 bits, in plain Python."""
    c = max(c, 0.0)
    return round(255 * (c / (1 + c)) ** (1 / 2.2))


def test_tonemap_hand_values() -> None:
    image = np.array([[[0.0, 1.0, 1e9], [-1.0, -1e30, 3.0]]], np.float32)
    mapped = tonemap(image)
    assert mapped.dtype == np.uint8 and mapped.shape == (1, 2, 3)
    one = round(255 * 0.5 ** (1 / 2.2))
    assert one == 186
    three = round(255 * 0.75 ** (1 / 2.2))
    assert mapped.tolist() == [[[0, one, 255], [0, 0, three]]]


def test_tonemap_saturates_at_infinity_and_rejects_nan() -> None:
    mapped = tonemap(np.array([[[np.inf, -np.inf, 3.4e38]]], np.float32))
    assert mapped.tolist() == [[[255, 0, 255]]]
    with pytest.raises(ValueError):
        tonemap(np.array([[[0.5, np.nan, 0.5]]], np.float32))
    with pytest.raises(ValueError):
        tonemap(np.full((4, 4, 3), np.nan, np.float32))


def test_tonemap_matches_plain_python_over_the_range() -> None:
    values = np.concatenate([np.linspace(0.0, 2.0, 3000), np.geomspace(1e-6, 1e6, 3000)])
    values = values.astype(np.float32)
    mapped = tonemap(values.reshape(-1, 1, 3)).ravel()
    exact = np.array([255 * (v / (1 + v)) ** (1 / 2.2) for v in values.astype(np.float64).tolist()])
    expected = np.array([reference_tonemap(v) for v in values.astype(np.float64).tolist()])
    # float32 against float64 may round the other way right at a half: only there allow 1.
    tie = np.abs(exact - np.floor(exact) - 0.5) < 1e-3
    np.testing.assert_array_equal(mapped[~tie], expected[~tie])
    assert np.all(np.abs(mapped[tie].astype(int) - expected[tie]) <= 1)
    assert np.all(np.diff(mapped[:3000].astype(int)) >= 0)  # monotone


# -- image files ----------------------------------------------------------------------------------


def linear_image(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.5, 6.0, (HEIGHT, WIDTH, 3)).astype(np.float32)


@pytest.mark.parametrize("suffix", [".png", ".PNG"])
def test_png_round_trip_is_the_tone_mapped_image(tmp_path: Path, suffix: str) -> None:
    image = linear_image()
    path = tmp_path / f"render{suffix}"
    save_image(image, path)
    with Image.open(path) as png:
        assert png.format == "PNG" and png.mode == "RGB" and png.size == (WIDTH, HEIGHT)
        pixels = np.asarray(png)
    np.testing.assert_array_equal(pixels, tonemap(image))
    expected = np.vectorize(reference_tonemap)(image.astype(np.float64))
    assert np.abs(pixels.astype(int) - expected).max() <= 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_npy_round_trip_is_exact(tmp_path: Path) -> None:
    image = linear_image(1)
    image[0, 0] = [np.inf, -1e30, 1e-30]  # linear output keeps what PNG cannot
    path = tmp_path / "render.npy"
    save_image(image, str(path))
    loaded = np.load(path)
    assert loaded.dtype == np.float32 and loaded.shape == image.shape
    np.testing.assert_array_equal(loaded, image)
    assert loaded.tobytes() == image.tobytes()


def test_saved_images_get_the_usual_file_mode(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    try:
        path = tmp_path / "render.png"
        save_image(linear_image(), path)
        assert path.stat().st_mode & 0o777 == 0o644
    finally:
        os.umask(umask)


@pytest.mark.parametrize("name", ["render.jpg", "render", "render.png.bak", "render.np"])
def test_unknown_extensions_are_rejected_before_writing(tmp_path: Path, name: str) -> None:
    (tmp_path / "keep.txt").write_text("x")
    with pytest.raises(ValueError):
        save_image(linear_image(), tmp_path / name)
    with pytest.raises(ValueError):
        film.check_output_path(tmp_path / name)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


@pytest.mark.parametrize("suffix", [".png", ".npy"])
def test_a_missing_directory_is_rejected_before_writing(tmp_path: Path, suffix: str) -> None:
    with pytest.raises(ValueError):
        save_image(linear_image(), tmp_path / "missing" / f"render{suffix}")
    with pytest.raises(ValueError):
        film.check_output_path(tmp_path / "missing" / "deeper" / f"render{suffix}")
    assert list(tmp_path.iterdir()) == []


def test_saving_over_an_old_image_replaces_it_whole(tmp_path: Path) -> None:
    path = tmp_path / "render.png"
    save_image(np.zeros((HEIGHT, WIDTH, 3), np.float32), path)
    save_image(np.ones((HEIGHT, WIDTH, 3), np.float32), path)
    with Image.open(path) as png:
        assert np.all(np.asarray(png) == reference_tonemap(1.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["render.png"]


class DiskFullError(Exception):
    pass


@pytest.mark.parametrize("error", [DiskFullError, KeyboardInterrupt, MemoryError])
@pytest.mark.parametrize("suffix", [".png", ".npy"])
def test_a_writer_failing_midway_leaves_the_old_image_untouched(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str, error: type[BaseException]
) -> None:
    path = tmp_path / f"render{suffix}"
    save_image(linear_image(2), path)
    before = path.read_bytes()
    mode = path.stat().st_mode
    calls = []

    def half_a_writer(image: np.ndarray, handle) -> None:
        calls.append(handle)
        handle.write(b"\x89PNG half an image")
        handle.flush()
        raise error

    monkeypatch.setitem(film.WRITERS, suffix, half_a_writer)
    with pytest.raises(error):
        save_image(linear_image(3), path)
    assert len(calls) == 1  # the failure really happened inside the writer
    assert path.read_bytes() == before
    assert path.stat().st_mode == mode
    # No temp file left behind (hidden ones included).
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]

    # With no old image, a failed write leaves nothing at all.
    fresh = tmp_path / f"fresh{suffix}"
    with pytest.raises(error):
        save_image(linear_image(3), fresh)
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
