"""The film: accumulation, tone mapping, and image files that are written whole or not at all."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from embree_rt import film
from embree_rt.film import Film, FilmBlock, check_output_path, save_image, tonemap

rng = np.random.default_rng(99)


def random_image(height: int = 5, width: int = 7) -> np.ndarray:
    image = rng.exponential(1.0, (height, width, 3)).astype(np.float32)
    image[0, 0] = 0.0
    image[-1, -1] = 50.0
    return image


# -- accumulation -----------------------------------------------------------------------------


def test_film_sums_equal_a_python_loop() -> None:
    width, height = 6, 4
    loop = np.zeros((height, width, 3))
    target = Film(width, height)
    for _ in range(3):  # several batches into one film
        pixel = rng.integers(0, width * height, 500).astype(np.int64)
        rgb = rng.random((500, 3)).astype(np.float32)
        target.add(pixel, rgb)
        for p, value in zip(pixel, rgb, strict=True):
            loop[p // width, p % width] += value  # row-major: pixel = row * width + column
    target.add(np.zeros(0, np.int64), np.zeros((0, 3), np.float32))
    image = target.image(4)
    assert image.shape == (height, width, 3) and image.dtype == np.float32
    np.testing.assert_allclose(image, loop / 4, rtol=1e-6)


def test_film_accumulates_in_double_precision() -> None:
    # In float32, 1e8 + 1 rounds back to 1e8 and the single 1 would be lost.
    target = Film(1, 1)
    for value in (1e8, 1.0, -1e8):
        target.add(np.zeros(1, np.int64), np.full((1, 3), value, np.float32))
    np.testing.assert_array_equal(target.image(1), 1.0)


def test_film_blocks_add_up_to_the_same_image() -> None:
    width, height = 5, 3
    pixel = np.sort(rng.integers(0, width * height, 300)).astype(np.int64)
    rgb = rng.random((300, 3)).astype(np.float32)
    direct = Film(width, height)
    direct.add(pixel, rgb)
    blocked = Film(width, height)
    for first, count in ((0, 4), (4, 9), (13, 2)):
        block = FilmBlock(first, count)
        inside = (pixel >= first) & (pixel < first + count)
        block.add(pixel[inside], rgb[inside])
        blocked.add_block(block)
    np.testing.assert_allclose(blocked.image(2), direct.image(2), rtol=1e-12)


def test_film_refuses_pixels_outside_it() -> None:
    target = Film(2, 2)
    with pytest.raises(ValueError, match="pixel"):
        target.add(np.array([4], np.int64), np.ones((1, 3), np.float32))
    with pytest.raises(ValueError, match="spp"):
        target.image(0)


# -- tone mapping ---------------------------------------------------------------------------------


def test_tonemap_hand_computed_values() -> None:
    linear = np.array([[[0.0, 1.0, 1e30], [-2.0, 3.0, np.inf], [0.25, 1e-6, 9.0]]], np.float32)
    mapped = tonemap(linear)
    assert mapped.dtype == np.uint8 and mapped.shape == (1, 3, 3)
    assert mapped[0, 0].tolist() == [0, round(255 * 0.5 ** (1 / 2.2)), 255]
    assert mapped[0, 0, 1] == 186
    assert mapped[0, 1, 0] == 0  # negative clamps to black
    assert mapped[0, 1, 1] == round(255 * 0.75 ** (1 / 2.2))
    assert mapped[0, 1, 2] == 255
    for c, value in zip((0.25, 1e-6, 9.0), mapped[0, 2], strict=True):
        assert value == round(255 * (c / (1 + c)) ** (1 / 2.2))


def test_tonemap_is_monotone_and_rejects_nan() -> None:
    ramp = np.geomspace(1e-4, 1e4, 3000, dtype=np.float32)
    mapped = tonemap(np.repeat(ramp[None, :, None], 3, axis=2))
    assert (np.diff(mapped[0, :, 0].astype(int)) >= 0).all()
    broken = np.zeros((2, 2, 3), np.float32)
    broken[1, 0, 2] = np.nan
    with pytest.raises(ValueError, match="image contains NaN"):
        tonemap(broken)


# -- files --------------------------------------------------------------------------------


def test_png_round_trip_through_pillow(tmp_path: Path) -> None:
    image = random_image()
    path = tmp_path / "picture.png"
    save_image(image, path)
    with Image.open(path) as loaded:
        assert loaded.format == "PNG" and loaded.mode == "RGB"
        assert loaded.size == (7, 5)
        np.testing.assert_array_equal(np.asarray(loaded), tonemap(image))


def test_npy_round_trip_is_exact_and_extensions_ignore_case(tmp_path: Path) -> None:
    image = random_image()
    for name in ("linear.npy", "LINEAR2.NPY"):
        save_image(image, tmp_path / name)
        loaded = np.load(tmp_path / name)
        assert loaded.dtype == np.float32
        np.testing.assert_array_equal(loaded, image)
    save_image(image, tmp_path / "upper.PNG")
    with Image.open(tmp_path / "upper.PNG") as loaded:
        assert loaded.format == "PNG"


def test_exr_round_trip_is_exact(tmp_path: Path) -> None:
    import OpenEXR

    image = random_image()
    path = tmp_path / "linear.exr"
    save_image(image, path)
    with OpenEXR.File(str(path)) as loaded:
        pixels = loaded.channels()["RGB"].pixels
    assert pixels.dtype == np.float32
    np.testing.assert_array_equal(pixels, image)


def test_exr_without_openexr_is_a_clear_runtime_error(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "OpenEXR", None)  # makes `import OpenEXR` fail
    with pytest.raises(RuntimeError, match="pip install openexr"):
        check_output_path(tmp_path / "linear.exr")
    with pytest.raises(RuntimeError, match="pip install openexr"):
        save_image(random_image(), tmp_path / "linear.exr")
    assert list(tmp_path.iterdir()) == []


def test_overwriting_gives_the_usual_file_mode(tmp_path: Path) -> None:
    path = tmp_path / "picture.png"
    path.write_bytes(b"old")
    save_image(random_image(), path)
    with Image.open(path) as loaded:
        assert loaded.size == (7, 5)
    umask = os.umask(0o022)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["picture.png"]


class WriterError(Exception):
    pass


@pytest.mark.parametrize("failure", [WriterError, KeyboardInterrupt])
@pytest.mark.parametrize("suffix", [".png", ".npy", ".exr"])
def test_a_failed_write_leaves_the_old_file_and_no_temp_files(
    tmp_path: Path, monkeypatch, failure: type[BaseException], suffix: str
) -> None:
    path = tmp_path / f"picture{suffix}"
    save_image(random_image(), path)
    before = path.read_bytes()

    def broken_writer(image: np.ndarray, handle) -> None:
        handle.write(b"half an image")
        raise failure

    monkeypatch.setitem(film.WRITERS, suffix, broken_writer)
    with pytest.raises(failure):
        save_image(random_image(), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    # A first write that fails leaves nothing at all.
    with pytest.raises(failure):
        save_image(random_image(), tmp_path / f"new{suffix}")
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


@pytest.mark.parametrize(
    "name, message",
    [
        ("picture.jpg", "unknown image extension"),
        ("picture", "unknown image extension"),
        ("missing/picture.png", "does not exist"),
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
        monkeypatch.setitem(film.WRITERS, suffix, lambda image, handle: calls.append(handle))
    with pytest.raises(ValueError, match=message) as error:
        check_output_path(path)
    assert str(path) in str(error.value)
    with pytest.raises(ValueError, match=message):
        save_image(random_image(), path)
    assert calls == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_directory.png"]


def test_images_of_the_wrong_shape_are_refused(tmp_path: Path) -> None:
    for shape in ((4, 4), (4, 4, 4), (0, 4, 3)):
        with pytest.raises(ValueError, match="image"):
            save_image(np.zeros(shape, np.float32), tmp_path / "picture.npy")
    assert list(tmp_path.iterdir()) == []
