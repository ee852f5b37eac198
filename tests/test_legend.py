"""The colour legend (``--legend``): the bar's pixels are the colormap's colours where the
particles' own colours are (matplotlib through the particles' look), only the bottom-right
corner of a display image changes, linear outputs carry no legend, and the JSON sidecar names
the range and the colours."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from PIL import Image

from embree_rt.film import Encoding, save_image
from embree_rt.legend import (
    Legend,
    draw_legend,
    legend_corner,
    legend_patch,
    legend_size,
    tick_values,
)

ROOT = Path(__file__).resolve().parents[1]


def viridis_bar(low: float, high: float) -> Legend:
    """A bar of matplotlib's viridis over [low, high], 8-bit as the particles' colours are."""
    colors = np.rint(matplotlib.colormaps["viridis"](np.linspace(0, 1, 256))[:, :3] * 255)
    return Legend("speed", colors.astype(np.uint8), value_range=(low, high), colormap="viridis")


def test_the_bar_shows_the_colormap_at_every_column() -> None:
    legend = viridis_bar(-1.0, 3.0)
    patch, place = legend_patch(legend, 120)
    bar = patch[place.top : place.top + place.height, place.left : place.left + place.width]
    cmap = matplotlib.colormaps["viridis"]
    for column in (0, place.width // 3, place.width // 2, place.width - 1):
        share = column / (place.width - 1)
        # the colormap's own 8-bit colour at this share, to within the 1/255 sampling step
        expected = np.rint(np.asarray(cmap(share)[:3]) * 255)
        for row in bar[:, column].astype(int):
            assert np.abs(row - expected).max() <= 2, (column, row, expected)
    assert (bar[:, 0] == legend.colors[0]).all() and (bar[:, -1] == legend.colors[-1]).all()


def test_ticks_are_round_values_within_the_range() -> None:
    assert np.allclose(tick_values(0.0, 1.0), [0.0, 0.2, 0.4, 0.6, 0.8, 1.0], rtol=0, atol=1e-12)
    ticks = tick_values(-2.905, 2.528)
    assert ticks.tolist() == [-2.0, 0.0, 2.0]
    assert tick_values(3.0, 3.0).tolist() == [3.0]


def test_only_the_bottom_right_corner_changes() -> None:
    rng = np.random.default_rng(4)
    pixels = rng.integers(0, 256, size=(200, 300, 3), dtype=np.uint8)
    legend = Legend("type", np.uint8([[255, 0, 0], [0, 0, 255]]), labels=("1", "2"))
    drawn = draw_legend(pixels, legend)
    patch, _ = legend_patch(legend, legend_size(legend, 200))
    top, left = legend_corner(pixels.shape, patch.shape)
    assert patch.shape[0] == 50 and top + patch.shape[0] < 200 and left + patch.shape[1] < 300
    outside = np.ones((200, 300), bool)
    outside[top : top + patch.shape[0], left : left + patch.shape[1]] = False
    assert (drawn[outside] == pixels[outside]).all()
    assert (drawn[~outside].reshape(patch.shape) == patch).all()
    # the key's swatches are its colours
    assert (patch.reshape(-1, 3) == [255, 0, 0]).all(axis=1).sum() > 20
    assert (patch.reshape(-1, 3) == [0, 0, 255]).all(axis=1).sum() > 20


@pytest.mark.parametrize("suffix", [".npy", ".npz", ".exr"])
def test_linear_outputs_carry_no_legend_and_the_sidecar_names_it(tmp_path, suffix) -> None:
    if suffix == ".exr":
        pytest.importorskip("OpenEXR")
    image = np.random.default_rng(1).uniform(0, 2, size=(64, 80, 3)).astype(np.float32)
    legend = viridis_bar(0.5, 7.0)
    save_image(image, tmp_path / f"plain{suffix}")
    save_image(image, tmp_path / f"legend{suffix}", Encoding(legend=legend))
    plain = (tmp_path / f"plain{suffix}").read_bytes()
    if suffix != ".exr":  # (an EXR's header holds no time: the bytes are the pixels' alone)
        assert (tmp_path / f"legend{suffix}").read_bytes() == plain
    record = json.loads((tmp_path / "legend.legend.json").read_text())["legend"]
    assert record["title"] == "speed" and record["range"] == [0.5, 7.0]
    assert record["colormap"] == "viridis" and record["colors"] == legend.colors.tolist()
    assert not (tmp_path / "plain.legend.json").exists()


def test_a_png_carries_the_legend_and_its_sidecar(tmp_path) -> None:
    image = np.full((80, 120, 3), 0.25, np.float32)
    legend = viridis_bar(0.0, 1.0)
    save_image(image, tmp_path / "a.png", Encoding(legend=legend))
    pixels = np.asarray(Image.open(tmp_path / "a.png"))
    plain = np.asarray(Image.open(_saved(image, tmp_path / "b.png")))
    assert (pixels != plain).any(axis=2).sum() > 100
    patch, _ = legend_patch(legend, legend_size(legend, 80))
    top, left = legend_corner(pixels.shape, patch.shape)
    assert (pixels[top:, left:][: patch.shape[0], : patch.shape[1]] == patch).all()
    assert (tmp_path / "a.legend.json").exists()


def _saved(image: np.ndarray, path: Path) -> Path:
    save_image(image, path)
    return path


def write_dump(path: Path, count: int = 60) -> np.ndarray:
    rng = np.random.default_rng(2)
    positions = rng.uniform(0, 8, size=(count, 3))
    speed = rng.uniform(1.0, 4.0, size=count)
    lines = ["ITEM: TIMESTEP", "0", "ITEM: NUMBER OF ATOMS", str(count)]
    lines += ["ITEM: BOX BOUNDS pp pp pp", "0 8", "0 8", "0 8", "ITEM: ATOMS id type x y z vx"]
    for i, ((x, y, z), v) in enumerate(zip(positions, speed, strict=True)):
        lines.append(f"{i + 1} {1 + i % 2} {x} {y} {z} {v}")
    path.write_text("\n".join(lines) + "\n")
    return speed


def test_the_command_line_legend_is_the_particles_colormap_and_range(tmp_path) -> None:
    speed = write_dump(tmp_path / "d.lammpstrj")
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    command = [sys.executable, "-m", "embree_rt", "render", "d.lammpstrj", "--legend"]
    size = ["--width", "96", "--height", "64", "--spp", "1", "--quiet"]
    done = subprocess.run(
        [*command, "--color-by", "vx", "--colormap", "plasma", "-o", "o.npz", *size],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "o.legend.json").read_text())["legend"]
    assert record["range"] == [float(f"{speed.min()}"), float(f"{speed.max()}")]
    plasma = np.rint(matplotlib.colormaps["plasma"]([0.0, 1.0])[:, :3] * 255)
    assert record["colors"][0] == plasma[0].tolist() and record["colors"][-1] == plasma[1].tolist()
    scene = str(ROOT / "scenes" / "benzene.toml")  # a scene file has no particles' colours
    done = subprocess.run(
        [sys.executable, "-m", "embree_rt", "render", scene, "--legend", "-o", "p.png"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "--legend" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "p.png").exists()
