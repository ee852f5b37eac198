"""glTF materials on the Whitted renderer, each property on a glTF file the test writes itself
(``assets/make_assets.py``'s ``GltfWriter``) and checked against what must show: emission on a
black, unlit world; glass absorption against Beer–Lambert's closed form; cutouts and one-sided
surfaces against the render without them; texture addressing against the texels the glTF spec
names.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import embree_rt as rt

ROOT = Path(__file__).resolve().parent.parent


def _make_assets():
    spec = importlib.util.spec_from_file_location("make_assets", ROOT / "assets" / "make_assets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


MAKE = _make_assets()
SIZE = 32
BLACK_WORLD = """
floor = false

[render]
width = {size}
height = {size}
spp = 1
max_depth = {depth}

[camera]
position = [0.0, 0.0, {camera_z}]
look_at = [0.0, 0.0, 0.0]
fov = 30.0

[background]
horizon = [0.0, 0.0, 0.0]
zenith = [0.0, 0.0, 0.0]
"""


def write_glb(path: Path, writer) -> Path:
    path.write_bytes(writer.glb())
    return path


def scene_text(meshes: list[str], *, camera_z: float = 6.0, depth: int = 4, extra: str = "") -> str:
    text = BLACK_WORLD.format(size=SIZE, depth=depth, camera_z=camera_z) + extra
    for mesh in meshes:
        text += f'\n[[meshes]]\nfile = "{mesh}"\n'
    return text


def render_text(tmp_path: Path, text: str, name: str = "scene.toml") -> np.ndarray:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return rt.render(rt.load_scene(path)).astype(np.float64)


def rgb_image(codes) -> Image.Image:
    return Image.fromarray(np.asarray(codes, np.uint8), "RGB")


def srgb_to_linear(code) -> np.ndarray:
    c = np.asarray(code, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# -- emission and unlit --------------------------------------------------------------------------


def test_an_emissive_patch_shows_its_emission_on_a_black_world(tmp_path: Path) -> None:
    """No lights, black sky, black base colour: what the camera sees of the quad is its
    emission alone, factor × strength × the emissive texture (left half one texel colour, right
    half the other), in the linear film."""
    writer = MAKE.GltfWriter()
    codes = [[[200, 40, 90], [30, 160, 250]]]  # one row, two texels: left, right
    texture = writer.texture(rgb_image(codes), {"magFilter": 9728, "minFilter": 9728})
    vertices, faces, uv = MAKE.quad(2.0)
    material = writer.material({
        "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
        "emissiveFactor": [0.5, 1.0, 0.25], "emissiveTexture": {"index": texture},
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3.0}},
    })  # fmt: skip
    writer.mesh(vertices, faces, material, TEXCOORD_0=uv)
    glb = write_glb(tmp_path / "glow.glb", writer)
    image = render_text(tmp_path, scene_text([glb]))
    factor = np.array([0.5, 1.0, 0.25]) * 3.0
    row = SIZE // 2
    left, right = image[row, SIZE // 2 - 3], image[row, SIZE // 2 + 2]
    np.testing.assert_allclose(left, factor * srgb_to_linear(codes[0][0]), rtol=1e-5)
    np.testing.assert_allclose(right, factor * srgb_to_linear(codes[0][1]), rtol=1e-5)
    assert image[1, 1].max() == 0.0  # the black sky around it


def test_an_unlit_surface_shows_its_base_colour_whatever_the_light(tmp_path: Path) -> None:
    writer = MAKE.GltfWriter()
    vertices, faces, _ = MAKE.quad(2.0)
    color = [0.8, 0.3, 0.05]
    material = writer.material({"pbrMetallicRoughness": {"baseColorFactor": [*color, 1]},
                                "extensions": {"KHR_materials_unlit": {}}})  # fmt: skip
    writer.mesh(vertices, faces, material)
    glb = write_glb(tmp_path / "unlit.glb", writer)
    lights = "\n[[lights]]\nposition = [1.0, 2.0, 5.0]\nintensity = 3.0\n"
    for extra in ("", lights):
        image = render_text(tmp_path, scene_text([glb], extra=extra))
        np.testing.assert_allclose(image[SIZE // 2, SIZE // 2], color, rtol=1e-6)


def test_the_scene_file_emission_key_glows(tmp_path: Path) -> None:
    text = scene_text([]) + """
[materials.lamp]
color = [0.0, 0.0, 0.0]
emission = [2.0, 0.5, 0.125]

[[spheres]]
center = [0.0, 0.0, 0.0]
radius = 0.8
material = "lamp"
"""
    image = render_text(tmp_path, text)
    np.testing.assert_allclose(image[SIZE // 2, SIZE // 2], [2.0, 0.5, 0.125], rtol=1e-6)


@pytest.mark.parametrize(
    ("key", "value", "problem"),
    [
        ("emission", "[1.0, -0.5, 0.0]", "must not be negative"),
        ("emission", '"bright"', "expected a list of three numbers"),
        ("attenuation_color", "[0.5, 1.5, 0.5]", "each must lie in [0, 1]"),
        ("attenuation_distance", "0.0", "must be > 0"),
        ("unlit", "1", "expected true or false"),
    ],
)
def test_bad_material_keys_name_file_key_and_problem(tmp_path, key, value, problem) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(f"[materials.odd]\npreset = \"glass\"\n{key} = {value}\n", encoding="utf-8")
    with pytest.raises(rt.SceneError) as caught:
        rt.load_scene(path)
    message = str(caught.value)
    assert str(path) in message and f"materials.odd.{key}" in message and problem in message


def test_new_material_keys_survive_saving_and_loading(tmp_path: Path) -> None:
    scene = rt.Scene()
    glow = rt.Material(emission=(1.5, 0.0, 0.25), unlit=True)
    tinted = rt.preset("glass", attenuation_color=(0.5, 0.8, 1.0), attenuation_distance=0.3)
    scene.add_material("glow", glow)
    scene.add_material("tinted", tinted)
    scene.save(tmp_path / "saved.toml")
    loaded = rt.load_scene(tmp_path / "saved.toml")
    assert loaded.materials["glow"] == glow and loaded.materials["tinted"] == tinted
    assert "emission" not in (tmp_path / "saved.toml").read_text().split("[materials.tinted]")[1]
