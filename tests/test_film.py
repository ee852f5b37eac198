"""The film (embree_rt/film.py): accumulation of (3, n) column samples against a Python loop,
tone mapping against hand values and plain Python, and image files: Pillow / NumPy / OpenEXR
round trips, early path errors, atomic replacement."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from embree_rt import film
from embree_rt.film import Film, FilmBlock, check_output_path, save_image, tonemap

WIDTH, HEIGHT = 7, 5


def random_samples(seed: int, count: int, first: int = 0, stop: int = WIDTH * HEIGHT):
    """(count,) int64 pixels in [first, stop) and their (3, count) float32 colors."""
    rng = np.random.default_rng(seed)
    pixel = rng.integers(first, stop, count).astype(np.int64)
    rgb = rng.uniform(0.0, 4.0, (3, count)).astype(np.float32)
    return pixel, rgb


def loop_sums(pixel: np.ndarray, rgb: np.ndarray, size: int, offset: int = 0) -> np.ndarray:
    """(size, 3) float64 per-pixel sums of the (3, n) column samples, one sample at a time."""
    sums = np.zeros((size, 3))
    for i, p in enumerate(pixel.tolist()):
        for channel in range(3):
            sums[p - offset][channel] += float(rgb[channel, i])
    return sums


def as_image(sums: np.ndarray) -> np.ndarray:
    """Row-major pixel sums (WIDTH * HEIGHT, 3) → (HEIGHT, WIDTH, 3), pixel p at (p // W, p % W)."""
    image = np.zeros((HEIGHT, WIDTH, 3))
    for p in range(WIDTH * HEIGHT):
        image[p // WIDTH, p % WIDTH] = sums[p]
    return image


NO_SAMPLES = (np.zeros(0, np.int64), np.zeros((3, 0), np.float32))


def add_samples(target: Film, pixel: np.ndarray, rgb: np.ndarray) -> None:
    """Add (3, n) ``rgb`` at the (n,) ``pixel`` indices of the whole ``target`` film, as one
    block covering every pixel."""
    block = FilmBlock(0, target.width * target.height)
    block.add(pixel, rgb)
    target.add_block(block)


# -- accumulation ---------------------------------------------------------------------------------


def test_film_sums_samples_per_pixel_like_a_loop() -> None:
    accumulated = Film(WIDTH, HEIGHT)
    batches = [random_samples(0, 3000), random_samples(1, 500), random_samples(2, 700)]
    for pixel, rgb in batches:  # several batches into one film
        add_samples(accumulated, pixel, rgb)
    add_samples(accumulated, *NO_SAMPLES)  # empty: no-op
    pixel = np.concatenate([p for p, _ in batches])
    rgb = np.concatenate([c for _, c in batches], axis=1)
    expected = as_image(loop_sums(pixel, rgb, WIDTH * HEIGHT))
    for spp in (1, 4, 8):
        image = accumulated.image(spp)
        assert image.dtype == np.float32 and image.shape == (HEIGHT, WIDTH, 3)
        assert image.flags.c_contiguous
        np.testing.assert_allclose(image, expected / spp, rtol=1e-6)


def test_film_image_puts_pixel_indices_row_major() -> None:
    marked = Film(WIDTH, HEIGHT)
    # Column i of np.eye(3, 4) is sample i: red, green, blue, then black.
    corners = np.array([0, WIDTH - 1, WIDTH, WIDTH * HEIGHT - 1])
    add_samples(marked, corners, np.eye(3, 4, dtype=np.float32))
    image = marked.image(1)
    assert image[0, 0].tolist() == [1, 0, 0]  # top left
    assert image[0, WIDTH - 1].tolist() == [0, 1, 0]  # top right
    assert image[1, 0].tolist() == [0, 0, 1]  # second row
    assert image.sum() == 3.0  # the fourth sample is black: nothing anywhere else


def test_film_accumulates_in_double_precision() -> None:
    # In float32, 1e8 + 1 rounds back to 1e8 and the single 1 would be lost.
    target = Film(1, 1)
    for value in (1e8, 1.0, -1e8):
        add_samples(target, np.zeros(1, np.int64), np.full((3, 1), value, np.float32))
    np.testing.assert_array_equal(target.image(1), 1.0)


def test_film_refuses_a_mean_of_no_samples() -> None:
    with pytest.raises(ValueError, match="spp"):
        Film(2, 2).image(0)


def test_film_block_add_sums_its_own_pixels_like_a_loop() -> None:
    first, count = 9, 13
    block = FilmBlock(first, count)
    pixel, rgb = random_samples(3, 2000, first, first + count)
    block.add(pixel[:1200], rgb[:, :1200])
    block.add(pixel[1200:], rgb[:, 1200:])
    block.add(*NO_SAMPLES)
    sums = block.sums
    assert sums.dtype == np.float64 and sums.shape == (3, count)
    np.testing.assert_allclose(sums, loop_sums(pixel, rgb, count, first).T, rtol=1e-12)


def test_film_add_block_equals_adding_the_samples_directly() -> None:
    # Batches as the integrator makes them: consecutive pixel ranges, the last one short,
    # and one range rendered in two blocks (two batches sharing a pixel).
    ranges = [(0, 12), (12, 12), (24, 11), (30, 5)]
    blocked, direct = Film(WIDTH, HEIGHT), Film(WIDTH, HEIGHT)
    all_pixels, all_rgb = [], []
    for seed, (first, count) in enumerate(ranges):
        pixel, rgb = random_samples(10 + seed, 300, first, first + count)
        block = FilmBlock(first, count)
        block.add(pixel, rgb)
        blocked.add_block(block)
        add_samples(direct, pixel, rgb)
        all_pixels.append(pixel)
        all_rgb.append(rgb)
    expected = as_image(loop_sums(np.concatenate(all_pixels), np.concatenate(all_rgb, axis=1), 35))
    np.testing.assert_allclose(blocked.image(4), expected / 4, rtol=1e-6)
    np.testing.assert_allclose(blocked.image(4), direct.image(4), rtol=1e-12)


def test_film_keeps_blocks_in_pixel_order_apart_and_gives_the_bits_of_the_summed_film() -> None:
    """Blocks in pixel order that do not overlap (a render's batches) are kept apart and
    their means written straight into the image; any other order folds them into one float64
    sum. The two ways are bitwise equal (0 + x is x: each pixel's sum is its block's), gaps
    included (0 / spp), and a block added again after the image was read still counts."""
    ranges = [(0, 9), (12, 10), (22, 13)]  # pixels 9..11 in no block
    blocks = []
    for seed, (first, count) in enumerate(ranges):
        block = FilmBlock(first, count)
        block.add(*random_samples(30 + seed, 200, first, first + count))
        blocks.append(block)
    in_order, reversed_order = Film(WIDTH, HEIGHT), Film(WIDTH, HEIGHT)
    for block in blocks:
        in_order.add_block(block)
    for block in blocks[::-1]:
        reversed_order.add_block(block)
    image = in_order.image(3)
    assert image.tobytes() == reversed_order.image(3).tobytes()
    assert not image.reshape(-1, 3)[9:12].any() and image.reshape(-1, 3)[:9].all()
    in_order.add_block(blocks[1])  # an overlap: now summed in the whole-film buffer
    reversed_order.add_block(blocks[1])
    assert in_order.image(2).tobytes() == reversed_order.image(2).tobytes()
    twice = (blocks[1].sums * 2).T.astype(np.float32)  # (x + x is 2x exactly)
    assert in_order.image(1).reshape(-1, 3)[12:22].tobytes() == twice.tobytes()
    with pytest.raises(ValueError, match=r"block of pixels 30\.\.35 is outside the film.s 35"):
        in_order.add_block(FilmBlock(30, 6))


def test_film_blocks_split_from_one_batch_add_up_to_the_same_image() -> None:
    pixel, rgb = random_samples(20, 300)
    pixel = np.sort(pixel)
    direct = Film(WIDTH, HEIGHT)
    add_samples(direct, pixel, rgb)
    blocked = Film(WIDTH, HEIGHT)
    for first, count in ((0, 4), (4, 19), (23, 12)):
        block = FilmBlock(first, count)
        inside = (pixel >= first) & (pixel < first + count)
        block.add(pixel[inside], rgb[:, inside])
        blocked.add_block(block)
    np.testing.assert_allclose(blocked.image(2), direct.image(2), rtol=1e-12)


def test_film_block_summing_as_it_goes_is_bitwise_one_bincount_of_all_samples() -> None:
    """A block sums each sample into its pixel as it is added, in float64, in the order added:
    bitwise one ``np.bincount`` per channel over all the samples concatenated (bincount adds its
    weights in input order too). IEEE-754 addition is correctly rounded on every x86-64 ISA, so
    the same additions in the same order give the same bits. Values spread over 12 decades, so
    that another order (sums of the groups added up) gives other bits: asserted, so the test can
    tell."""
    first, count = 4, 9
    rng = np.random.default_rng(7)
    adds = []
    for size in rng.integers(0, 60, 40):
        pixel = rng.integers(first, first + count, size).astype(np.int64)
        rgb = (10.0 ** rng.uniform(-6, 6, (3, size))).astype(np.float32)
        adds.append((pixel, rgb))
    as_it_goes = FilmBlock(first, count)
    for pixel, rgb in adds:
        as_it_goes.add(pixel, rgb)
    local = np.concatenate([pixel for pixel, _ in adds]) - first
    weights = np.concatenate([rgb for _, rgb in adds], axis=1).astype(np.float64)
    at_end = np.stack([np.bincount(local, weights=w, minlength=count) for w in weights])
    assert as_it_goes.sums.tobytes() == at_end.tobytes()
    grouped = np.zeros((3, count))
    for pixel, rgb in adds:
        grouped += block_sums(first, count, pixel, rgb)
    assert grouped.tobytes() != at_end.tobytes()
    np.testing.assert_allclose(grouped, at_end, rtol=1e-12)


def block_sums(first: int, count: int, pixel: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """(3, count) float64 sums of one block holding just these samples."""
    block = FilmBlock(first, count)
    block.add(pixel, rgb)
    return block.sums


# -- tone mapping ---------------------------------------------------------------------------------


def reference_tonemap(c: float) -> int:
    """Reinhard c / (1 + c), gamma 1/2.2, to 8 bits, in plain Python."""
    c = max(c, 0.0)
    return round(255 * (c / (1 + c)) ** (1 / 2.2))


def test_tonemap_hand_values() -> None:
    image = np.array(
        [
            [[0.0, 1.0, 1e9], [-1.0, -1e30, 3.0]],
            [[1e30, -2.0, np.inf], [0.25, 1e-6, 9.0]],
        ],
        np.float32,
    )
    mapped = tonemap(image)
    assert mapped.dtype == np.uint8 and mapped.shape == (2, 2, 3)
    one = round(255 * 0.5 ** (1 / 2.2))
    assert one == 186
    three = round(255 * 0.75 ** (1 / 2.2))
    quarter, tiny, nine = (round(255 * (c / (1 + c)) ** (1 / 2.2)) for c in (0.25, 1e-6, 9.0))
    assert mapped.tolist() == [
        [[0, one, 255], [0, 0, three]],  # negatives clamp to black
        [[255, 0, 255], [quarter, tiny, nine]],
    ]


def test_tonemap_saturates_at_infinity_and_rejects_nan() -> None:
    mapped = tonemap(np.array([[[np.inf, -np.inf, 3.4e38]]], np.float32))
    assert mapped.tolist() == [[[255, 0, 255]]]
    partly = np.zeros((2, 2, 3), np.float32)
    partly[1, 0, 2] = np.nan
    for broken in (np.array([[[0.5, np.nan, 0.5]]], np.float32), partly):
        with pytest.raises(ValueError, match="image contains NaN"):
            tonemap(broken)
    with pytest.raises(ValueError, match="image contains NaN"):
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
    # Monotone over both ramps.
    assert np.all(np.diff(mapped[:3000].astype(int)) >= 0)
    assert np.all(np.diff(mapped[3000:].astype(int)) >= 0)


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


@pytest.mark.parametrize("name", ["render.npy", "RENDER.NPY"])
def test_npy_round_trip_is_exact(tmp_path: Path, name: str) -> None:
    image = linear_image(1)
    image[0, 0] = [np.inf, -1e30, 1e-30]  # linear output keeps what PNG cannot
    path = tmp_path / name
    save_image(image, str(path))
    loaded = np.load(path)
    assert loaded.dtype == np.float32 and loaded.shape == image.shape
    np.testing.assert_array_equal(loaded, image)
    assert loaded.tobytes() == image.tobytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_exr_round_trip_is_exact(tmp_path: Path) -> None:
    import OpenEXR

    image = linear_image(4)
    path = tmp_path / "render.exr"
    save_image(image, path)
    with OpenEXR.File(str(path)) as loaded:
        pixels = loaded.channels()["RGB"].pixels
    assert pixels.dtype == np.float32
    np.testing.assert_array_equal(pixels, image)


def test_exr_without_openexr_is_a_clear_runtime_error(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "OpenEXR", None)  # makes `import OpenEXR` fail
    with pytest.raises(RuntimeError, match="pip install openexr"):
        check_output_path(tmp_path / "render.exr")
    with pytest.raises(RuntimeError, match="pip install openexr"):
        save_image(linear_image(), tmp_path / "render.exr")
    assert list(tmp_path.iterdir()) == []


def test_saving_over_an_old_file_replaces_it_whole_with_the_usual_mode(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    try:
        fresh = tmp_path / "fresh.png"
        save_image(linear_image(), fresh)
        assert fresh.stat().st_mode & 0o777 == 0o644  # not tempfile's private 0600
        path = tmp_path / "render.png"
        path.write_bytes(b"old")
        save_image(np.zeros((HEIGHT, WIDTH, 3), np.float32), path)
        save_image(np.ones((HEIGHT, WIDTH, 3), np.float32), path)
        with Image.open(path) as png:
            assert png.size == (WIDTH, HEIGHT)
            assert np.all(np.asarray(png) == reference_tonemap(1.0))
        assert path.stat().st_mode & 0o777 == 0o644
    finally:
        os.umask(umask)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fresh.png", "render.png"]


class DiskFullError(Exception):
    pass


@pytest.mark.parametrize("error", [DiskFullError, KeyboardInterrupt, MemoryError])
@pytest.mark.parametrize("suffix", [".png", ".npy", ".exr", ".jpg", ".tif"])
def test_a_writer_failing_midway_leaves_the_old_image_untouched(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str, error: type[BaseException]
) -> None:
    path = tmp_path / f"render{suffix}"
    save_image(linear_image(2), path)
    before = path.read_bytes()
    mode = path.stat().st_mode
    calls = []

    def half_a_writer(image: np.ndarray, handle, encoding=None) -> None:
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
    assert len(calls) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


@pytest.mark.parametrize(
    "name, message",
    [
        ("render.bmp", "unknown image extension"),
        ("render", "unknown image extension"),
        ("render.png.bak", "unknown image extension"),
        ("render.np", "unknown image extension"),
        ("missing/render.png", "does not exist"),
        ("missing/render.npy", "does not exist"),
        ("missing/deeper/render.png", "does not exist"),
        ("a_directory.png", "is a directory"),
    ],
)
def test_bad_paths_are_refused_before_anything_is_written(
    tmp_path: Path, monkeypatch, name: str, message: str
) -> None:
    (tmp_path / "a_directory.png").mkdir()
    path = tmp_path / name
    calls = []
    for suffix in film.WRITERS:
        monkeypatch.setitem(film.WRITERS, suffix, lambda image, handle, *_: calls.append(handle))
    with pytest.raises(ValueError, match=message) as error:
        check_output_path(path)
    assert str(path) in str(error.value)
    with pytest.raises(ValueError, match=message):
        save_image(linear_image(), path)
    assert calls == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_directory.png"]


def test_images_of_the_wrong_shape_are_refused(tmp_path: Path) -> None:
    for shape in ((4, 4), (4, 4, 4), (0, 4, 3)):
        with pytest.raises(ValueError, match="image"):
            save_image(np.zeros(shape, np.float32), tmp_path / "render.npy")
    assert list(tmp_path.iterdir()) == []


# -- display formats and 16 bits ------------------------------------------------------------------


@pytest.mark.parametrize(
    "suffix, name, lossless",
    [
        (".png", "PNG", True),
        (".tif", "TIFF", True),
        (".TIFF", "TIFF", True),
        (".jpg", "JPEG", False),
        (".jpeg", "JPEG", False),
        (".webp", "WEBP", False),
    ],
)
def test_display_formats_round_trip_through_pillow(
    tmp_path: Path, suffix: str, name: str, lossless: bool
) -> None:
    # smooth ramps, which lossy codecs keep (random pixels would lose their chroma)
    rows, columns = 0.5 + np.mgrid[0 : 4 * HEIGHT, 0 : 4 * WIDTH] / 16.0
    image = np.stack([columns, rows, np.full_like(rows, 0.7)], axis=-1).astype(np.float32)
    path = tmp_path / f"render{suffix}"
    save_image(image, path)
    with Image.open(path) as loaded:
        assert loaded.format == name and loaded.mode == "RGB"
        assert loaded.size == (4 * WIDTH, 4 * HEIGHT)
        pixels = np.asarray(loaded).astype(int)
    difference = np.abs(pixels - tonemap(image).astype(int))
    if lossless:
        assert difference.max() == 0
    else:  # lossy at the default quality: close on average
        assert difference.mean() < 3
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_quality_trades_size_for_fidelity(tmp_path: Path) -> None:
    image = linear_image(6)
    sizes = {}
    for quality in (20, 95):
        path = tmp_path / f"q{quality}.jpg"
        save_image(image, path, film.Encoding(quality=quality))
        sizes[quality] = path.stat().st_size
    assert sizes[20] < sizes[95]


@pytest.mark.parametrize("suffix", [".png", ".tif", ".tiff"])
def test_sixteen_bit_images_hold_the_tone_map_to_16_bits(tmp_path: Path, suffix: str) -> None:
    image = linear_image(7)
    path = tmp_path / f"render{suffix}"
    save_image(image, path, film.Encoding(bit_depth=16))
    with Image.open(path) as loaded:  # Pillow reads it (as 8-bit RGB: it holds no 16-bit RGB)
        assert loaded.mode == "RGB" and loaded.size == (WIDTH, HEIGHT)
    if suffix == ".png":
        import png

        _, _, rows, info = png.Reader(filename=str(path)).asDirect()
        assert (info["bitdepth"], info["planes"]) == (16, 3)
        pixels = np.array([list(row) for row in rows], np.uint16).reshape(HEIGHT, WIDTH, 3)
    else:
        import tifffile

        pixels = tifffile.imread(path)
    assert pixels.dtype == np.uint16 and pixels.shape == (HEIGHT, WIDTH, 3)
    # the same curve as 8 bits, in plain Python, to 65535 steps
    expected = np.vectorize(lambda c: 65535 * (max(c, 0) / (1 + max(c, 0))) ** (1 / 2.2))(
        image.astype(np.float64)
    )
    assert np.abs(pixels - expected).max() <= 1
    assert np.abs(pixels / 257.0 - tonemap(image)).max() <= 0.5 + 1e-9  # 8 bits: rounded


@pytest.mark.parametrize(
    "name, encoding, message",
    [
        ("render.jpg", film.Encoding(bit_depth=16), "16-bit"),
        ("render.npy", film.Encoding(bit_depth=16), "16-bit"),
        ("render.png", film.Encoding(quality=80), "quality applies"),
        ("render.webp", film.Encoding(quality=101), "1 to 100"),
    ],
)
def test_encodings_a_format_cannot_take_are_refused_before_writing(
    tmp_path: Path, name: str, encoding: film.Encoding, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        save_image(linear_image(), tmp_path / name, encoding)
    assert list(tmp_path.iterdir()) == []


# -- the look --------------------------------------------------------------------------------


def test_the_default_look_is_the_seed_articles_bitwise() -> None:
    image = linear_image(8)
    for look in (film.Look(), film.Look(0.0, "reinhard", "gamma2.2")):
        np.testing.assert_array_equal(tonemap(image, look), tonemap(image))
        expected = np.vectorize(reference_tonemap)(image.astype(np.float64))
        assert np.abs(tonemap(image, look).astype(int) - expected).max() <= 1


def test_exposure_scales_the_light_by_powers_of_two() -> None:
    image = linear_image(9)
    for stops in (-2.0, 1.0, 3.0):
        # times 2^k is exact in float32: the same display values, bitwise
        np.testing.assert_array_equal(
            film.display_values(image, film.Look(exposure=stops)),
            film.display_values(image * np.float32(2.0**stops)),
        )
    brighter = film.display_values(image, film.Look(exposure=1.0))
    assert (brighter >= film.display_values(image)).all()


def test_aces_and_none_and_srgb_follow_their_formulas() -> None:
    values = np.concatenate([np.linspace(0.0, 4.0, 2000), np.geomspace(1e-6, 1e6, 2000)])
    image = values.astype(np.float32).reshape(-1, 1, 1).repeat(3, axis=2)
    x = values.astype(np.float32).astype(np.float64)
    aces = np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0, 1)
    srgb = lambda c: np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)  # noqa: E731
    cases = {
        ("aces", "gamma2.2"): aces ** (1 / 2.2),
        ("none", "gamma2.2"): np.minimum(x, 1.0) ** (1 / 2.2),
        ("reinhard", "srgb"): srgb(x / (1 + x)),
        ("aces", "srgb"): srgb(aces),
    }
    for (curve, transfer), expected in cases.items():
        got = film.display_values(image, film.Look(tonemap=curve, transfer=transfer))[:, 0, 0]
        np.testing.assert_allclose(got, expected, atol=2e-6, err_msg=f"{curve}, {transfer}")
        assert np.all(np.diff(got[:2000]) >= 0)  # monotone
    infinite = np.full((1, 1, 3), np.inf, np.float32)
    for curve in film.TONEMAPS:
        assert tonemap(infinite, film.Look(tonemap=curve)).tolist() == [[[255, 255, 255]]]
