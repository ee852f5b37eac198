"""Backgrounds of a paper's figure: camera rays that meet nothing show white, black or nothing
(alpha) instead of the sky, composited over the share of each pixel's samples that met
something; what the rays that met something show is unchanged."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from embree_rt import Camera, PointLight, Scene, render


def scene_with(background: str) -> Scene:
    scene = Scene(floor=None, camera=Camera(position=(0.0, 0.0, 5.0), look_at=(0.0, 0.0, 0.0)))
    scene.lights.append(PointLight(position=(2.0, 3.0, 4.0)))
    scene.add_sphere((0.0, 0.0, 0.0), 1.0, "glossy")
    scene.render.background = background
    return scene


SIZE = {"width": 48, "height": 32, "spp": 4}


@pytest.mark.parametrize("background", ["white", "black", "transparent"])
def test_backgrounds_composite_over_the_camera_rays_that_met_nothing(tmp_path, background) -> None:
    sky = render(scene_with("sky"), **SIZE)
    result = render(scene_with(background), **SIZE)
    alpha = result.alpha
    # alpha: the sphere's disc (radius tan-wise 1 / sqrt(24) of the half-height tan(22.5°))
    assert alpha.shape == (32, 48) and alpha[16, 24] == 1.0 and alpha[0, 0] == 0.0
    rim = (alpha > 0) & (alpha < 1)
    assert rim.any() and set(np.unique(alpha[rim] * 4)) <= {1.0, 2.0, 3.0}
    radius = 16 / math.tan(math.radians(22.5)) / math.sqrt(24)  # pixels
    assert abs(alpha.sum() - math.pi * radius**2) < 2 * math.pi * radius
    inside = alpha == 1
    assert result.image[inside].tobytes() == sky.image[inside].tobytes()
    assert (result.image[alpha == 0] == 0).all()
    result.save(tmp_path / "figure.png")
    picture = np.asarray(Image.open(tmp_path / "figure.png"))
    expected_corner = {"white": [255] * 3, "black": [0] * 3, "transparent": [0, 0, 0, 0]}
    assert picture[0, 0].tolist() == expected_corner[background]
    if background == "transparent":
        assert picture.shape == (32, 48, 4)
        np.testing.assert_array_equal(picture[..., 3], np.rint(alpha * 255))
        np.testing.assert_array_equal(picture[inside][:, :3], sky.to_srgb8()[inside])
    else:
        np.testing.assert_array_equal(picture[inside], sky.to_srgb8()[inside])


def test_a_transparent_background_needs_a_format_with_alpha(tmp_path) -> None:
    result = render(scene_with("transparent"), **SIZE)
    for name in ("figure.jpg", "figure.npy", "figure.exr"):
        with pytest.raises(ValueError, match="alpha channel"):
            result.save(tmp_path / name)
        assert not (tmp_path / name).exists()
