"""``Renderer.render_views``: many views of one BVH written as they are rendered, each file
bitwise what one render and ``RenderResult.save`` of that view write; bad patterns refused
before anything is rendered.

Why bitwise: each view is rendered from the same rays by the same code on the same BVH as a
fresh render of that camera (test_api's argument), and written by the same writers.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.aovs import camera_data

SIZE = {"width": 32, "height": 20, "spp": 2, "max_depth": 3, "seed": 1}


def small_scene() -> rt.Scene:
    scene = rt.Scene(camera=rt.Camera(position=(0.0, 1.5, 6.0), look_at=(0.0, 0.8, 0.0)))
    scene.lights.append(rt.PointLight(position=(3.0, 6.0, 4.0)))
    scene.add_sphere((0.0, 1.0, 0.0), 1.0, "glass")
    scene.add_sphere((-1.8, 0.5, 0.6), 0.5, "mirror")
    scene.add_sphere((1.7, 0.6, -0.4), 0.6, "matte")
    return scene


def views(scene: rt.Scene) -> list[rt.Camera]:
    return [
        replace(scene.camera, position=(6.0 * np.sin(a), 1.5, 6.0 * np.cos(a)))
        for a in (0.0, 0.7, 1.4)
    ]


def test_views_are_written_as_single_renders_write_them(tmp_path: Path) -> None:
    scene = small_scene()
    cameras = views(scene)
    with rt.Renderer(scene) as renderer:
        paths = renderer.render_views(
            cameras, str(tmp_path / "view_{:02d}.npz"), aovs=("depth", "normal"), **SIZE
        )
    assert paths == [tmp_path / f"view_{k:02d}.npz" for k in range(3)]
    for camera, path in zip(cameras, paths, strict=True):
        alone = rt.render(replace(scene, camera=camera), aovs=("depth", "normal"), **SIZE)
        with np.load(path) as written:
            np.testing.assert_array_equal(written["beauty"], alone.image)
            np.testing.assert_array_equal(written["depth"], alone.aovs["depth"])
            np.testing.assert_array_equal(written["normal"], alone.aovs["normal"])
            np.testing.assert_array_equal(written["K"], camera_data(alone.camera)["K"])
    images = [np.load(path)["beauty"] for path in paths]
    assert not np.array_equal(images[0], images[1])


def test_png_views_carry_their_camera_without_aovs(tmp_path: Path) -> None:
    from PIL import Image

    scene = small_scene()
    cameras = views(scene)[:2]
    with rt.Renderer(scene) as renderer:
        paths = renderer.render_views(cameras, str(tmp_path / "v{}.png"), **SIZE)
    for camera, path in zip(cameras, paths, strict=True):
        alone = rt.render(replace(scene, camera=camera), **SIZE)
        with Image.open(path) as decoded:
            np.testing.assert_array_equal(np.asarray(decoded), alone.to_srgb8())
        record = json.loads(path.with_name(f"{path.stem}.camera.json").read_text())
        assert record["width"] == SIZE["width"]


def test_bad_patterns_are_refused_before_any_view(tmp_path: Path) -> None:
    scene = small_scene()
    with rt.Renderer(scene) as renderer:
        with pytest.raises(ValueError, match="one file name"):
            renderer.render_views(views(scene), str(tmp_path / "same.png"), **SIZE)
        with pytest.raises(ValueError, match="does not exist"):
            renderer.render_views(views(scene), str(tmp_path / "no" / "v{}.png"), **SIZE)
    assert list(tmp_path.iterdir()) == []
