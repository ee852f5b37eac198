"""Outlines (a material's ``outline``): seen orthographically, a sphere's rim and a tube's
edges go black in a band ``outline · radius`` wide, by the closed form of where a point of a
circle of radius r lies seen side-on; everything off the band is the image without outlines,
bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from embree_rt import Camera, Scene, render
from embree_rt.camera import camera_frame, sample_rays
from embree_rt.materials import Material
from embree_rt.scene.loader import load_scene
from embree_rt.scene.writer import save_scene

SIZE = 97
VIEW_HEIGHT = 2.5
RADIUS = 1.0
# Samples within this much of the band's edges are left out: a float32 hit there may fall
# either side (the pixel is 2.5 / 97 = 0.026 wide, so this is a small part of a pixel).
MARGIN = 1e-3


def outlined_scene(width: float, tube: bool) -> Scene:
    camera = Camera(
        position=(0.0, 0.0, 10.0),
        look_at=(0.0, 0.0, 0.0),
        up=(0.0, 1.0, 0.0),
        projection="orthographic",
        view_height=VIEW_HEIGHT,
    )
    scene = Scene(camera=camera, floor=None)
    scene.add_material("inked", Material(color=(0.9, 0.5, 0.2), outline=width))
    if tube:  # a horizontal tube reaching past the image's sides
        scene.add_curves(np.array([[-5.0, 0.0, 0.0], [5.0, 0.0, 0.0]]), RADIUS, "inked")
    else:
        scene.add_sphere((0.0, 0.0, 0.0), RADIUS, "inked")
    return scene


def sample_distances(scene: Scene, tube: bool) -> np.ndarray:
    """(SIZE * SIZE,) float64: how far each pixel's one sample (spp 1, seed 0) lies from the
    sphere's centre (or the tube's axis) across the view, pixel by pixel."""
    frame = camera_frame(scene.camera, SIZE, SIZE)
    index = np.arange(SIZE * SIZE, dtype=np.int64)
    origins, _, pixel = sample_rays(frame, 1, 0, index)
    across = origins.astype(np.float64)[:2]  # the view is along -z: x and y lie in the image
    distance = np.abs(across[1]) if tube else np.hypot(across[0], across[1])
    result = np.empty(SIZE * SIZE)
    result[pixel] = distance
    return result


@pytest.mark.parametrize("tube", [False, True], ids=["sphere", "tube"])
@pytest.mark.parametrize("width", [0.1, 0.35])
def test_the_band_within_width_times_radius_of_the_silhouette_is_black(
    width: float, tube: bool
) -> None:
    scene = outlined_scene(width, tube)
    image = render(scene, width=SIZE, height=SIZE, spp=1, seed=0).image.reshape(-1, 3)
    plain_scene = outlined_scene(0.0, tube)
    plain = render(plain_scene, width=SIZE, height=SIZE, spp=1, seed=0).image.reshape(-1, 3)
    distance = sample_distances(scene, tube)
    inner = RADIUS * (1.0 - width)
    on_band = (distance > inner + MARGIN) & (distance < RADIUS - MARGIN)
    off_band = (distance < inner - MARGIN) | (distance > RADIUS + MARGIN)
    assert on_band.sum() > 2 * SIZE and off_band.sum() > SIZE * SIZE // 2
    assert (image[on_band] == 0.0).all()
    assert (plain[on_band] > 0.0).all()
    # Off the band the outline changes nothing: the same float32 operations on the same hits
    # (only the band's weights are zeroed), so the bits are equal on any machine.
    assert image[off_band].tobytes() == plain[off_band].tobytes()
    # The band's width in pixels along the middle row (column for the tube) is the closed
    # form's width · radius · pixels per unit, to a pixel.
    rows = image.reshape(SIZE, SIZE, 3)
    line = rows[:, SIZE // 2] if tube else rows[SIZE // 2]
    black = np.flatnonzero((line == 0.0).all(axis=1))
    half = black[black < SIZE // 2]
    assert abs(len(half) - width * RADIUS * SIZE / VIEW_HEIGHT) <= 1.0


def test_no_outline_is_the_default_and_a_file_keeps_the_key(tmp_path) -> None:
    assert Material().outline == 0.0
    scene = outlined_scene(0.25, tube=False)
    save_scene(scene, tmp_path / "scene.toml")
    assert "outline = 0.25" in (tmp_path / "scene.toml").read_text()
    assert load_scene(tmp_path / "scene.toml").materials["inked"].outline == 0.25
    with pytest.raises(ValueError, match="outline"):
        Material(outline=1.5)
