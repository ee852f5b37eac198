"""Ambient occlusion at reflected and refracted hits (``render.ao.bounces``), against the
closed forms of a camera inside a closed half-mirror sphere: every point inside a closed
sphere has ambient occlusion 0, so with bounces nothing but black is left; without them every
reflected hit keeps its plain ambient term, a geometric series in the mirror's share."""

from __future__ import annotations

import math

import numpy as np
import pytest

from embree_rt import Camera, Scene, render
from embree_rt.ambient_occlusion import AmbientOcclusion
from embree_rt.materials import Material
from embree_rt.scene.loader import load_scene
from embree_rt.scene.writer import save_scene

AMBIENT = 0.4
REFLECTIVITY = 0.5
COLOR = (0.9, 0.6, 0.3)
MAX_DEPTH = 4


def inside_a_mirror(bounces: bool) -> Scene:
    camera = Camera(position=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, -1.0), up=(0.0, 1.0, 0.0))
    scene = Scene(camera=camera, floor=None)  # no lights: ambient light alone
    scene.add_material(
        "half_mirror",
        Material(color=COLOR, ambient=AMBIENT, diffuse=0.0, reflectivity=REFLECTIVITY),
    )
    scene.add_sphere((0.0, 0.0, 0.0), 5.0, "half_mirror")
    scene.render.ao = AmbientOcclusion(samples=4, bounces=bounces)
    return scene


@pytest.mark.parametrize("bounces", [False, True])
def test_inside_a_closed_half_mirror_only_bounces_darken_the_reflections(bounces: bool) -> None:
    scene = inside_a_mirror(bounces)
    image = render(scene, width=24, height=16, spp=1, max_depth=MAX_DEPTH).image
    if bounces:
        assert (image == 0.0).all()
        return
    # the camera hit's ambient is occluded (0); the hit at depth d = 1..MAX_DEPTH, reached
    # with weight r^d, adds ambient (1 - r) colour
    series = sum(REFLECTIVITY**d for d in range(1, MAX_DEPTH + 1))
    expected = np.array(COLOR) * AMBIENT * (1 - REFLECTIVITY) * series
    np.testing.assert_allclose(image, np.broadcast_to(expected, image.shape), rtol=1e-5)


def test_the_key_and_the_flag_reach_the_render_and_the_file(tmp_path) -> None:
    scene = inside_a_mirror(True)
    save_scene(scene, tmp_path / "s.toml")
    assert load_scene(tmp_path / "s.toml").render.ao.bounces is True
    plain = inside_a_mirror(False)
    save_scene(plain, tmp_path / "p.toml")
    assert "bounces" not in (tmp_path / "p.toml").read_text()
    assert math.isinf(load_scene(tmp_path / "p.toml").render.ao.distance)
    from embree_rt.cli.parser import build_parser

    args = build_parser().parse_args(["render", "p.toml", "-o", "x.png", "--ao-bounces"])
    assert [(s.key, s.value) for s in args.settings] == [("render.ao.bounces", True)]
