"""glTF materials on the Whitted renderer, each property on a glTF file the test writes itself
(``assets/make_assets.py``'s ``GltfWriter``) and checked against what must show: emission on a
black, unlit world; glass absorption against Beer–Lambert's closed form; cutouts and one-sided
surfaces against the render without them; texture addressing against the texels the glTF spec
names.
"""

from __future__ import annotations

import importlib.util
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import embree_rt as rt
from embree_rt.scene.errors import InputWarning
from embree_rt.scene.gltf_materials import texture_transform_matrix
from embree_rt.textures import (
    CLAMP_TO_EDGE,
    MIRRORED_REPEAT,
    REPEAT,
    Sampler,
    sample_texture,
    texels_from_image,
)

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
    return rt.render(rt.load_scene(path)).image.astype(np.float64)


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
    material = writer.material(
        {
            "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
            "emissiveFactor": [0.5, 1.0, 0.25],
            "emissiveTexture": {"index": texture},
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3.0}},
        }
    )
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
    material = writer.material(
        {
            "pbrMetallicRoughness": {"baseColorFactor": [*color, 1]},
            "extensions": {"KHR_materials_unlit": {}},
        }
    )
    writer.mesh(vertices, faces, material)
    glb = write_glb(tmp_path / "unlit.glb", writer)
    lights = "\n[[lights]]\nposition = [1.0, 2.0, 5.0]\nintensity = 3.0\n"
    for extra in ("", lights):
        image = render_text(tmp_path, scene_text([glb], extra=extra))
        np.testing.assert_allclose(image[SIZE // 2, SIZE // 2], color, rtol=1e-6)


def test_the_scene_file_emission_key_glows(tmp_path: Path) -> None:
    text = (
        scene_text([])
        + """
[materials.lamp]
color = [0.0, 0.0, 0.0]
emission = [2.0, 0.5, 0.125]

[[spheres]]
center = [0.0, 0.0, 0.0]
radius = 0.8
material = "lamp"
"""
    )
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
    path.write_text(f'[materials.odd]\npreset = "glass"\n{key} = {value}\n', encoding="utf-8")
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
    rt.save_scene(scene, tmp_path / "saved.toml")
    loaded = rt.load_scene(tmp_path / "saved.toml")
    assert loaded.materials["glow"] == glow and loaded.materials["tinted"] == tinted
    assert "emission" not in (tmp_path / "saved.toml").read_text().split("[materials.tinted]")[1]


# -- transmission, glass and Beer–Lambert --------------------------------------------------------

SCHLICK_R0 = ((1.5 - 1.0) / (1.5 + 1.0)) ** 2  # reflectance at normal incidence, IOR 1.5


def slab(writer, thickness: float, material: int) -> None:
    """A 2 x 2 x ``thickness`` box centred at the origin, faces flat (own vertices, normals)."""
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 2.0, thickness))
    box.unmerge_vertices()
    normals = np.repeat(box.face_normals, 3, axis=0)
    writer.mesh(box.vertices, box.faces, material, NORMAL=normals)


def test_light_through_a_glass_slab_is_absorbed_by_beer_lambert(tmp_path: Path) -> None:
    """Head-on through a slab of thickness L with KHR_materials_volume: the pixel is the sky
    (white) reflected at the front, plus what both surfaces transmit times ``c^(L/d)``
    (attenuationColor c, attenuationDistance d). max_depth 2 stops after one pass through."""
    thickness, color, distance = 0.4, np.array([0.5, 0.8, 0.95]), 0.5
    images = {}
    for name, volume in (
        (
            "absorbing",
            {
                "thicknessFactor": thickness,
                "attenuationColor": color.tolist(),
                "attenuationDistance": distance,
            },
        ),
        ("thin", {"attenuationColor": color.tolist(), "attenuationDistance": distance}),
    ):
        writer = MAKE.GltfWriter()
        material = writer.material(
            {
                "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
                "extensions": {
                    "KHR_materials_transmission": {"transmissionFactor": 1.0},
                    "KHR_materials_volume": volume,
                },
            }
        )
        slab(writer, thickness, material)
        glb = write_glb(tmp_path / f"{name}.glb", writer)
        white = "\n[background]\nhorizon = [1.0, 1.0, 1.0]\nzenith = [1.0, 1.0, 1.0]\n"
        text = scene_text([glb], depth=2).replace(
            "[background]\nhorizon = [0.0, 0.0, 0.0]\nzenith = [0.0, 0.0, 0.0]\n", white
        )
        images[name] = render_text(tmp_path, text, f"{name}.toml")[SIZE // 2, SIZE // 2]
    transmitted = (1 - SCHLICK_R0) ** 2
    np.testing.assert_allclose(
        images["absorbing"], SCHLICK_R0 + transmitted * color ** (thickness / distance), rtol=2e-4
    )
    # thicknessFactor 0 (the default) is a thin wall: nothing is absorbed.
    np.testing.assert_allclose(images["thin"], SCHLICK_R0 + transmitted, rtol=2e-4)


def test_scene_file_glass_absorbs_along_the_path_inside(tmp_path: Path) -> None:
    """A glass sphere of radius r seen through its centre: the path inside is 2r (a narrow
    field of view keeps the centre pixel's ray within 0.007 of the axis, where the chord is
    shorter by less than 1e-5 of itself)."""
    radius, color, distance = 0.7, np.array([0.3, 0.6, 0.9]), 0.8
    text = scene_text([], depth=2).replace(
        "horizon = [0.0, 0.0, 0.0]\nzenith = [0.0, 0.0, 0.0]",
        "horizon = [1.0, 1.0, 1.0]\nzenith = [1.0, 1.0, 1.0]",
    )
    text = text.replace("fov = 30.0", "fov = 2.0")
    text += f"""
[materials.tinted]
color = [1.0, 1.0, 1.0]
ambient = 0.0
diffuse = 0.0
transparency = 1.0
ior = 1.5
attenuation_color = {color.tolist()}
attenuation_distance = {distance}

[[spheres]]
center = [0.0, 0.0, 0.0]
radius = {radius}
material = "tinted"
"""
    pixel = render_text(tmp_path, text)[SIZE // 2, SIZE // 2]
    expected = SCHLICK_R0 + (1 - SCHLICK_R0) ** 2 * color ** (2 * radius / distance)
    np.testing.assert_allclose(pixel, expected, rtol=2e-4)


def test_transmission_makes_a_gltf_material_glass_with_its_ior_and_tint() -> None:
    from embree_rt.scene.gltf_materials import material_from_gltf

    glass = material_from_gltf(
        {
            "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.9, 0.4, 1.0]},
            "extensions": {
                "KHR_materials_transmission": {"transmissionFactor": 0.8},
                "KHR_materials_ior": {"ior": 1.33},
            },
        }
    )
    assert glass.is_glass and glass.transparency == 0.8 and glass.ior == 1.33
    assert glass.color == pytest.approx((0.2, 0.9, 0.4))
    default = material_from_gltf(
        {"extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}}}
    )
    assert default.ior == 1.5 and default.attenuation_distance == math.inf


# -- one-sided surfaces --------------------------------------------------------------------------


def lamp_world(tmp_path: Path, meshes: list[Path], name: str) -> np.ndarray:
    """An emissive ball behind where the meshes go, on the black world, and a light."""
    text = (
        scene_text(meshes)
        + """
[[lights]]
position = [4.0, 0.5, -1.0]

[materials.lamp]
color = [0.4, 0.4, 0.4]
emission = [0.2, 0.6, 0.3]

[[spheres]]
center = [0.0, 0.0, -2.0]
radius = 1.0
material = "lamp"
"""
    )
    return render_text(tmp_path, text, name)


def facing_quad(tmp_path: Path, name: str, facing: float, **material) -> Path:
    """A 1.2-wide quad at z = 0 facing +z (``facing`` 1, toward the camera) or -z (-1)."""
    writer = MAKE.GltfWriter()
    vertices, faces, uv = MAKE.quad(1.2)
    if facing < 0:
        faces = faces[:, ::-1]
    index = writer.material(
        {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.5, 0.1, 1]}, **material}
    )
    writer.mesh(vertices, faces, index, TEXCOORD_0=uv)
    return write_glb(tmp_path / f"{name}.glb", writer)


def test_a_one_sided_plane_seen_from_behind_is_not_there(tmp_path: Path) -> None:
    """Bitwise: the filter rejects every hit on the back, so each ray finds the very hit it
    finds without the plane (Embree's triangle test does not depend on what else is in the
    BVH). The light is beside the ball, so that no shadow ray crosses the plane (one-sided
    surfaces still cast shadows both ways)."""
    without = lamp_world(tmp_path, [], "without.toml")
    back = lamp_world(tmp_path, [facing_quad(tmp_path, "back", -1.0)], "back.toml")
    np.testing.assert_array_equal(back, without)
    front = lamp_world(tmp_path, [facing_quad(tmp_path, "front", 1.0)], "front.toml")
    both = lamp_world(
        tmp_path, [facing_quad(tmp_path, "both", -1.0, doubleSided=True)], "both.toml"
    )
    centre = (SIZE // 2, SIZE // 2)
    assert not np.array_equal(front[centre], without[centre])
    assert not np.array_equal(both[centre], without[centre])


# -- alpha: cutouts and see-through --------------------------------------------------------------


def alpha_quad(tmp_path: Path, name: str, alpha_codes: np.ndarray, **material) -> Path:
    """A 1.2-wide double-sided orange quad at z = 0 whose base colour texture is white with
    alpha ``alpha_codes`` (h, w) uint8, read nearest."""
    writer = MAKE.GltfWriter()
    h, w = alpha_codes.shape
    rgba = np.concatenate([np.full((h, w, 3), 255, np.uint8), alpha_codes[..., None]], axis=2)
    texture = writer.texture(Image.fromarray(rgba, "RGBA"), {"magFilter": 9728})
    index = writer.material(
        {
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.9, 0.5, 0.1, 1],
                "baseColorTexture": {"index": texture},
                "metallicFactor": 0.0,
            },
            "doubleSided": True,
            **material,
        }
    )
    vertices, faces, uv = MAKE.quad(1.2)
    writer.mesh(vertices, faces, index, TEXCOORD_0=uv)
    return write_glb(tmp_path / f"{name}.glb", writer)


# Alpha 0 in the middle column of a 3 x 3 grid, 255 elsewhere.
SLOT = np.array([[255, 0, 255]] * 3, np.uint8)


def test_a_cutout_shows_what_is_behind_it_where_alpha_is_below_the_cutoff(tmp_path) -> None:
    """MASK: pixels whose rays pass the cut-out middle third equal the render without the quad
    (bitwise: the filter rejects those hits, so the rays find what they find without it);
    pixels over the solid thirds show the quad."""
    without = lamp_world(tmp_path, [], "without.toml")
    masked = lamp_world(
        tmp_path, [alpha_quad(tmp_path, "mask", SLOT, alphaMode="MASK")], "mask.toml"
    )
    opaque = lamp_world(tmp_path, [alpha_quad(tmp_path, "opaque", SLOT)], "opaque.toml")
    # The quad spans x in [-0.6, 0.6] at z = 0; its middle third |x| < 0.2 is cut out. In the
    # image (fov 30 at distance 6), 0.2 is 0.2 / (6 tan 15°) of the half width: 2 pixels.
    middle = slice(SIZE // 2 - 1, SIZE // 2 + 1)
    np.testing.assert_array_equal(masked[middle, middle], without[middle, middle])
    side = (SIZE // 2, SIZE // 2 + 3)
    np.testing.assert_array_equal(masked[side], opaque[side])
    assert not np.array_equal(masked[side], without[side])


def test_a_cutout_casts_a_shadow_with_the_hole(tmp_path: Path) -> None:
    """A masked quad held level 1 above the floor, the light far up and behind: the quad's
    shadow falls beside it, and the floor in the shadow of the hole is lit exactly as with no
    quad at all (bitwise: the shadow rays' filter rejects the hole's hits), the floor in the
    shadow of the solid part is not."""
    glb = alpha_quad(tmp_path, "leaf", SLOT, alphaMode="MASK", alphaCutoff=0.5)

    def render(meshes: list[Path]) -> np.ndarray:
        text = f"""
[render]
width = {SIZE}
height = {SIZE}
spp = 1
max_depth = 1

[camera]
position = [0.0, 6.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, -1.0]
fov = 30.0

[[lights]]
position = [0.0, 40.0, 40.0]

[floor]
color_a = [0.8, 0.8, 0.8]
color_b = [0.8, 0.8, 0.8]
reflectivity = 0.0
"""
        for mesh in meshes:  # the quad turned level (facing up), 1 above the floor
            text += f'\n[[meshes]]\nfile = "{mesh}"\nrotate = [-90.0, 0.0, 0.0]\n'
            text += "translate = [0.0, 1.0, 0.0]\n"
        path = tmp_path / f"shadow{len(meshes)}.toml"
        path.write_text(text, encoding="utf-8")
        return rt.render(rt.load_scene(path)).image.astype(np.float64)

    bare, shaded = render([]), render([glb])
    # A quad point (x, 1, z) shadows the floor at (40/39) (x, 0, z - 1) (seen from the light);
    # the floor at z = -1.2 is in the shadow's span, and its camera ray passes y = 1 at
    # z = -1.0, clear of the quad. The image's right is +x and its top -z, 9.95 pixels a unit.
    scale = SIZE / (2 * 6.0 * math.tan(math.radians(15)))
    row = int(SIZE / 2 - 1.2 * scale)
    hole = (row, SIZE // 2)  # x in [0, 0.1]: in the shadow of the cut-out middle, |x| < 0.2
    solid = (row, int(SIZE / 2 + 0.35 * scale))  # x in [0.3, 0.4]: shadow of the solid third
    np.testing.assert_array_equal(shaded[hole], bare[hole])
    assert shaded[solid].max() < 0.5 * bare[solid].max()
    # The same quad opaque (alphaMode absent) shadows the floor there too.
    whole = render([alpha_quad(tmp_path, "whole", SLOT)])
    assert whole[hole].max() < 0.5 * bare[hole].max()


def test_blend_lets_one_minus_alpha_through(tmp_path: Path) -> None:
    """BLEND with coverage a = factor alpha × texture alpha over an emissive ball: the pixel is
    a × the quad's own colour (unlit: its base colour) + (1 − a) × the ball behind."""
    alpha_code = 102  # 0.4
    codes = np.full((1, 1), alpha_code, np.uint8)
    glb = alpha_quad(
        tmp_path, "veil", codes, alphaMode="BLEND", extensions={"KHR_materials_unlit": {}}
    )
    without = lamp_world(tmp_path, [], "without.toml")
    veiled = lamp_world(tmp_path, [glb], "veiled.toml")
    a = alpha_code / 255.0
    centre = (SIZE // 2, SIZE // 2)
    np.testing.assert_allclose(
        veiled[centre], a * np.array([0.9, 0.5, 0.1]) + (1 - a) * without[centre], rtol=1e-5
    )


# -- texture addressing --------------------------------------------------------------------------


def spec_texel(i: int, size: int, mode: int) -> int:
    """The texel index the OpenGL 4.6 spec (§8.14.2, which glTF's samplers follow) names for
    integer texel coordinate ``i`` on an axis of ``size`` texels."""
    if mode == REPEAT:
        return i % size
    if mode == CLAMP_TO_EDGE:
        return min(max(i, 0), size - 1)

    def mirror(a: int) -> int:
        return a if a >= 0 else -(1 + a)

    return (size - 1) - mirror((i % (2 * size)) - size)


@pytest.mark.parametrize("mode", [REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT])
@pytest.mark.parametrize("nearest", [True, False])
def test_wrap_modes_sample_the_texels_the_spec_names(mode: int, nearest: bool) -> None:
    """A 5 x 1 texture of distinct texels sampled along u from -3 to 3 (v in the row): each
    sample is the spec's texel (nearest; samples on a boundary between texels left out) or
    the spec's two neighbours blended by the distance to their centres (linear), in float64."""
    width = 5
    texels = np.zeros((1, width, 4), np.float32)
    texels[0, :, 0] = np.arange(width) + 1.0  # texel i holds i + 1
    texels[0, :, 3] = 1.0
    u = np.linspace(-3, 3, 601, dtype=np.float32)
    uv = np.stack([u, np.full_like(u, 0.5)])
    got = sample_texture(texels, uv, Sampler(wrap_s=mode, nearest=nearest))[0]
    for value, coordinate in zip(got, u.astype(np.float64), strict=True):
        if nearest:
            if abs(coordinate * width - round(coordinate * width)) < 1e-4:
                continue  # on a texel boundary: float32 rounding decides (either is right)
            expected = spec_texel(math.floor(coordinate * width), width, mode) + 1.0
        else:
            x = coordinate * width - 0.5
            i0 = math.floor(x)
            f = x - i0
            expected = (1 - f) * (spec_texel(i0, width, mode) + 1) + f * (
                spec_texel(i0 + 1, width, mode) + 1
            )
        assert value == pytest.approx(expected, abs=2e-4), (coordinate, mode)


def test_wrap_modes_reach_the_renderer(tmp_path: Path) -> None:
    """A quad with UVs 0..3 across, a 2 x 1 texture (red, blue) read nearest: per wrap mode, the
    colour of each sixth of the quad (u in [k/2, (k+1)/2)) is the texel the spec names."""
    codes = np.array([[[255, 0, 0], [0, 0, 255]]], np.uint8)
    palette = srgb_to_linear(codes[0]) * np.array([1.0, 1.0, 1.0])
    vertices, faces, uv = MAKE.quad(1.2)
    uv = uv * np.array([3.0, 1.0], np.float32)
    for mode in (REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT):
        writer = MAKE.GltfWriter()
        texture = writer.texture(rgb_image(codes), {"magFilter": 9728, "wrapS": mode})
        index = writer.material(
            {
                "pbrMetallicRoughness": {"baseColorTexture": {"index": texture}},
                "extensions": {"KHR_materials_unlit": {}},
            }
        )
        writer.mesh(vertices, faces, index, TEXCOORD_0=uv)
        glb = write_glb(tmp_path / f"wrap{mode}.glb", writer)
        image = render_text(tmp_path, scene_text([glb]), f"wrap{mode}.toml")
        scale = SIZE / (2 * 6.0 * math.tan(math.radians(15)))
        for sixth in range(6):
            x = -0.6 + 0.2 * (sixth + 0.5)  # the middle of the sixth, in the scene
            column = int(SIZE / 2 + x * scale)
            texel = spec_texel(sixth, 2, mode)  # u·w = sixth + ½: integer part `sixth`
            np.testing.assert_allclose(
                image[SIZE // 2, column],
                palette[texel],
                rtol=1e-6,
                err_msg=f"mode {mode}, sixth {sixth}",
            )


def test_texture_transform_and_texcoord_1_choose_what_is_sampled(tmp_path: Path) -> None:
    """KHR_texture_transform with scale (0.5, 1) and offset (0.5, 0) maps the quad's u in [0, 1]
    onto the texture's right half: the quad is the right texel all over. With texCoord 1 the
    texture follows TEXCOORD_1 (here u reversed), which trimesh does not keep."""
    codes = np.array([[[255, 0, 0], [0, 0, 255]]], np.uint8)
    red, blue = srgb_to_linear(codes[0])
    vertices, faces, uv = MAKE.quad(1.2)
    scale = SIZE / (2 * 6.0 * math.tan(math.radians(15)))
    left, right = int(SIZE / 2 - 0.45 * scale), int(SIZE / 2 + 0.45 * scale)
    cases = {
        "transform": (
            {"extensions": {"KHR_texture_transform": {"offset": [0.5, 0.0], "scale": [0.5, 1]}}},
            (blue, blue),
        ),
        "second_set": ({"texCoord": 1}, (blue, red)),
        "first_set": ({}, (red, blue)),
    }
    for name, (info, (want_left, want_right)) in cases.items():
        writer = MAKE.GltfWriter()
        texture = writer.texture(rgb_image(codes), {"magFilter": 9728})
        index = writer.material(
            {
                "pbrMetallicRoughness": {"baseColorTexture": {"index": texture, **info}},
                "extensions": {"KHR_materials_unlit": {}},
            }
        )
        reversed_u = uv * np.array([-1.0, 1.0], np.float32) + np.array([1.0, 0.0], np.float32)
        writer.mesh(vertices, faces, index, TEXCOORD_0=uv, TEXCOORD_1=reversed_u)
        glb = write_glb(tmp_path / f"{name}.glb", writer)
        image = render_text(tmp_path, scene_text([glb]), f"{name}.toml")
        np.testing.assert_allclose(image[SIZE // 2, left], want_left, rtol=1e-6, err_msg=name)
        np.testing.assert_allclose(image[SIZE // 2, right], want_right, rtol=1e-6, err_msg=name)


def test_texture_transform_matrix_follows_the_extension() -> None:
    """The extension's example: rotation by θ, then scale, then offset, applied to (u, v)."""
    theta = 0.3
    matrix = texture_transform_matrix(
        {"offset": [0.1, -0.2], "rotation": theta, "scale": [2.0, 0.5]}
    )
    u, v = 0.25, 0.75
    su, sv = 2.0 * u, 0.5 * v
    # KHR_texture_transform's rotation matrix: [[cos, sin], [-sin, cos]] on (u, v).
    ru = math.cos(theta) * su + math.sin(theta) * sv
    rv = -math.sin(theta) * su + math.cos(theta) * sv
    np.testing.assert_allclose(matrix @ [u, v, 1.0], [ru + 0.1, rv - 0.2, 1.0], atol=1e-12)


def test_texels_keep_their_alpha_and_data_textures_stay_linear() -> None:
    codes = np.array([[[10, 128, 255, 51]]], np.uint8)
    colour = texels_from_image(Image.fromarray(codes, "RGBA"))
    data = texels_from_image(Image.fromarray(codes, "RGBA"), srgb=False)
    want = [*srgb_to_linear(codes[0, 0, :3]), 0.2]
    np.testing.assert_allclose(colour[0, 0], want, rtol=1e-6)
    np.testing.assert_allclose(data[0, 0], codes[0, 0] / 255.0, rtol=1e-6)


def test_ignored_extensions_are_named_in_one_warning_line(tmp_path: Path) -> None:
    writer = MAKE.GltfWriter()
    vertices, faces, _ = MAKE.quad(1.0)
    index = writer.material(
        {
            "extensions": {
                "KHR_materials_clearcoat": {"clearcoatFactor": 1},
                "KHR_materials_sheen": {},
                "KHR_materials_unlit": {},
            }
        }
    )
    writer.mesh(vertices, faces, index)
    glb = write_glb(tmp_path / "coated.glb", writer)
    path = tmp_path / "coated.toml"
    path.write_text(scene_text([glb]), encoding="utf-8")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rt.load_scene(path)
    (line,) = [str(w.message) for w in caught if issubclass(w.category, InputWarning)]
    assert str(glb) in line and "\n" not in line
    assert "KHR_materials_clearcoat, KHR_materials_sheen ignored (no counterpart" in line
    assert "KHR_materials_unlit" not in line  # honoured, not ignored


def test_a_glb_rendered_on_its_own_reads_its_materials_as_a_scene_file_does(tmp_path) -> None:
    """Scene.from_file and a scene file naming the glTF read it through one loader: each mesh
    carries the same glTF looks and gets the same material (emission, glass, absorption)."""
    from embree_rt.scene.gltf_materials import LOOKS_KEY

    glb = ROOT / "assets" / "gltf_materials.glb"
    alone = rt.Scene.from_file(glb)
    path = tmp_path / "named.toml"
    path.write_text(scene_text([str(glb)]), encoding="utf-8")
    named = rt.load_scene(path)
    assert len(alone.meshes) == len(named.meshes) == 6
    for by_itself, by_name in zip(alone.meshes, named.meshes, strict=True):
        assert LOOKS_KEY in by_itself.mesh.metadata and LOOKS_KEY in by_name.mesh.metadata
        assert alone.materials[by_itself.material] == named.materials[by_name.material]
    materials = [alone.materials[m.material] for m in alone.meshes]
    assert any(m.emission != (0.0, 0.0, 0.0) for m in materials)
    assert any(m.is_glass and m.attenuation_distance < math.inf for m in materials)


# -- normal maps and occlusion -------------------------------------------------------------------


def normal_codes(normal) -> np.ndarray:
    """The 8-bit RGB code of a tangent-space normal, as a normal map stores it."""
    return np.round((np.asarray(normal) + 1) / 2 * 255).astype(np.uint8)


@pytest.mark.parametrize("tangent", [None, (0.0, 1.0, 0.0, 1.0)])
def test_a_normal_map_turns_the_shading_normal_by_its_angle(tmp_path: Path, tangent) -> None:
    """A constant normal map tilted by θ toward the tangent: the shading normal of the quad
    (facing +z) turns by θ toward T, which is +x (increasing u) from the UVs, or the file's
    TANGENT (+y here); the bitangent is N × T (times w). Read from the normal AOV."""
    theta = math.radians(25.0)
    code = normal_codes([math.sin(theta), 0.0, math.cos(theta)])
    decoded = code / 255.0 * 2 - 1  # what the map holds after 8 bits
    writer = MAKE.GltfWriter()
    texture = writer.texture(rgb_image(code[None, None, :]))
    index = writer.material({"normalTexture": {"index": texture}})
    vertices, faces, uv = MAKE.quad(2.0)
    attributes = {"TEXCOORD_0": uv, "NORMAL": np.tile([0.0, 0.0, 1.0], (4, 1))}
    if tangent is not None:
        attributes["TANGENT"] = np.tile(tangent, (4, 1))
    writer.mesh(vertices, faces, index, **attributes)
    glb = write_glb(tmp_path / "bumpy.glb", writer)
    path = tmp_path / "bumpy.toml"
    path.write_text(scene_text([glb]), encoding="utf-8")
    layers = rt.render(rt.load_scene(path), aovs=["normal"]).aovs
    got = layers["normal"][SIZE // 2, SIZE // 2].astype(np.float64)
    t_axis = np.array([1.0, 0, 0]) if tangent is None else np.array(tangent[:3])
    b_axis = np.cross([0.0, 0, 1], t_axis)
    expected = decoded[0] * t_axis + decoded[1] * b_axis + decoded[2] * np.array([0.0, 0, 1])
    expected /= np.linalg.norm(expected)
    np.testing.assert_allclose(got, expected, atol=2e-6)
    assert math.degrees(math.acos(got[2])) == pytest.approx(25.0, abs=0.3)  # 8-bit rounding


def test_occlusion_scales_the_ambient_term(tmp_path: Path) -> None:
    """No lights, black world: the quad shows ambient × colour alone, and an occlusion map of
    value o with strength s scales it by 1 + s (o − 1)."""
    images = {}
    for name, occlusion in (("open", None), ("occluded", {"strength": 0.8})):
        writer = MAKE.GltfWriter()
        material = {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.6, 0.3, 1]}}
        if occlusion is not None:
            texture = writer.texture(rgb_image([[[102, 0, 0]]]))  # o = 0.4 in the red channel
            material["occlusionTexture"] = {"index": texture, **occlusion}
        vertices, faces, uv = MAKE.quad(2.0)
        writer.mesh(vertices, faces, writer.material(material), TEXCOORD_0=uv)
        glb = write_glb(tmp_path / f"{name}.glb", writer)
        images[name] = render_text(tmp_path, scene_text([glb]), f"{name}.toml")
    centre = (SIZE // 2, SIZE // 2)
    assert images["open"][centre].min() > 0
    np.testing.assert_allclose(
        images["occluded"][centre], images["open"][centre] * (1 + 0.8 * (0.4 - 1)), rtol=1e-6
    )


def test_the_gallery_file_holds_every_feature_it_shows() -> None:
    """assets/gltf_materials.glb (what make_assets writes, checked byte for byte by
    test_mesh_looks) loads with an emissive texture, glass with absorption, cut-outs and a
    normal map, each read by the project's glTF material reader."""
    from embree_rt.scene.gltf_materials import LOOKS_KEY
    from embree_rt.scene.meshes import load_mesh_parts

    parts = load_mesh_parts(ROOT / "assets" / "gltf_materials.glb", "gallery.toml", "file")
    looks = [mesh.metadata[LOOKS_KEY] for mesh, _ in parts]
    assert any(item.emissive is not None and item.material.emission != (0, 0, 0) for item in looks)
    assert any(
        item.material.is_glass and item.material.attenuation_distance < math.inf for item in looks
    )
    assert sum(item.alpha_mode == "MASK" for item in looks) == 3
    assert any(item.normal is not None for item in looks)


# -- textures that vary the Blinn-Phong parameters -----------------------------------------------


def split_quad(tmp_path: Path, name: str, material: dict, textures: dict) -> Path:
    """A 2-wide quad facing the camera; ``textures`` maps a material path ("pbr.<key>" or an
    extension's key) to 2 x 1 RGB codes (left texel, right texel), read nearest."""
    writer = MAKE.GltfWriter()
    material = {
        key: (dict(value) if isinstance(value, dict) else value) for key, value in material.items()
    }
    for where, codes in textures.items():
        index = writer.texture(rgb_image(codes), {"magFilter": 9728})
        block, key = where.split(".")
        if block == "pbr":
            material.setdefault("pbrMetallicRoughness", {})[key] = {"index": index}
        else:
            material["extensions"][block][key] = {"index": index}
    vertices, faces, uv = MAKE.quad(2.0)
    writer.mesh(
        vertices,
        faces,
        writer.material(material),
        TEXCOORD_0=uv,
        NORMAL=np.tile([0.0, 0.0, 1.0], (4, 1)),
    )
    return write_glb(tmp_path / f"{name}.glb", writer)


def test_a_metallic_roughness_texture_varies_the_surface_per_point(tmp_path: Path) -> None:
    """Left texel: metallic 0, roughness 1; right: metallic 1, roughness 0.2 (B and G). Each
    half renders as the same quad with those values as constant factors (the per-material
    mapping), with a light for highlights and a ball to reflect."""
    extra = """
[[lights]]
position = [1.5, 2.0, 6.0]

[materials.lamp]
color = [0.2, 0.5, 0.9]
emission = [0.3, 0.6, 0.9]

[[spheres]]
center = [0.0, 0.0, 4.0]
radius = 0.5
material = "lamp"
"""
    base = {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.6, 0.3, 1]}}
    textured = split_quad(
        tmp_path, "mr", base, {"pbr.metallicRoughnessTexture": [[[0, 255, 0], [0, 51, 255]]]}
    )
    image = render_text(tmp_path, scene_text([textured], extra=extra), "mr.toml")
    scale = SIZE / (2 * 6.0 * math.tan(math.radians(15)))
    for column, (metallic, roughness) in (
        (int(SIZE / 2 - 0.3 * scale), (0.0, 1.0)),
        (int(SIZE / 2 + 0.3 * scale), (1.0, 0.2)),
    ):
        constant = {
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.9, 0.6, 0.3, 1],
                "metallicFactor": metallic,
                "roughnessFactor": roughness,
            }
        }
        glb = split_quad(tmp_path, f"constant{metallic}", constant, {})
        reference = render_text(tmp_path, scene_text([glb], extra=extra), f"c{metallic}.toml")
        np.testing.assert_allclose(image[:, column], reference[:, column], rtol=2e-5, atol=1e-6)
    assert not np.allclose(
        image[:, int(SIZE / 2 - 0.3 * scale)], image[:, int(SIZE / 2 + 0.3 * scale)]
    )


def test_a_transmission_texture_makes_glass_where_it_is_white(tmp_path: Path) -> None:
    """Transmission texture R = 1 on the left, 0 on the right, factor 1: the left half renders
    as the quad with transmission 1 everywhere, the right as the opaque quad."""
    extra = """
[materials.lamp]
color = [0.2, 0.5, 0.9]
emission = [0.3, 0.6, 0.9]

[[spheres]]
center = [0.0, 0.0, -2.0]
radius = 1.5
material = "lamp"
"""

    def material(factor: float) -> dict:
        transmission = {"KHR_materials_transmission": {"transmissionFactor": factor}}
        return {
            "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1], "metallicFactor": 0.0},
            "doubleSided": True,
            "extensions": transmission,
        }

    textured = split_quad(
        tmp_path,
        "tx",
        material(1.0),
        {"KHR_materials_transmission.transmissionTexture": [[[255, 0, 0], [0, 0, 0]]]},
    )
    image = render_text(tmp_path, scene_text([textured], extra=extra), "tx.toml")
    scale = SIZE / (2 * 6.0 * math.tan(math.radians(15)))
    left, right = int(SIZE / 2 - 0.3 * scale), int(SIZE / 2 + 0.3 * scale)
    for column, factor in ((left, 1.0), (right, 0.0)):
        glb = split_quad(tmp_path, f"plain{factor}", material(factor), {})
        reference = render_text(tmp_path, scene_text([glb], extra=extra), f"p{factor}.toml")
        np.testing.assert_allclose(
            image[SIZE // 2, column], reference[SIZE // 2, column], rtol=2e-5, atol=1e-6
        )
    assert not np.allclose(image[SIZE // 2, left], image[SIZE // 2, right])


def test_only_meshes_that_need_a_filter_get_one() -> None:
    """Opaque closed meshes (the glTF cube, single-sided as glTF's default is) and meshes of
    other formats trace with no filter; an open one-sided quad and a cut-out get one."""
    from embree_rt.mesh_attributes import mesh_hit_filter
    from embree_rt.scene.gltf_materials import LOOKS_KEY
    from embree_rt.scene.meshes import load_mesh_parts

    def filters(name: str) -> list:
        parts = load_mesh_parts(ROOT / "assets" / name, "scene.toml", "file")
        return [(mesh_hit_filter(mesh), mesh.metadata.get(LOOKS_KEY)) for mesh, _ in parts]

    assert [f for f, _ in filters("quadrant_cube.glb")] == [None]
    assert [f for f, _ in filters("torus.obj")] == [None]
    gallery = filters("gltf_materials.glb")  # panel, ball, three leaves, bumps: open but glass
    for hit_filter, looks in gallery:
        if looks.material.is_glass:
            assert hit_filter is None
        else:
            assert hit_filter is not None and (hit_filter.occluded != 0) == (
                looks.alpha_mode == "MASK"
            )
    assert sum(f is None for f, _ in gallery) == 1
