"""Scene files: the file equals the scene built in Python, TOML equals JSON, save → load round
trips, the shipped scenes, and the catalogue of bad input (each a ``SceneError`` naming the key)."""

from __future__ import annotations

import contextlib
import json
import math
import re
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import trimesh
from scene_compare import assert_same_scene, in_frame, sharing
from scipy.spatial.transform import Rotation

import embree_rt
import embree_rt.scene.loader as loader_module
import embree_rt.scene.meshes as meshes_module
from embree_rt import (
    PRESETS,
    Background,
    Camera,
    Checker,
    Floor,
    Material,
    PointLight,
    RenderSettings,
    Scene,
    SceneError,
    load_scene,
    preset,
    random_field,
    save_scene,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent

FULL_SCENE = """
[render]
width = 320
height = 200
spp = 3
max_depth = 4
seed = 11

[camera]
position = [0.5, 2.0, 8.0]
look_at = [0.0, 0.7, 0.0]
up = [0.0, 1.0, 0.1]
fov = 38.5

[background]
horizon = [0.9, 0.9, 1.0]
zenith = [0.1, 0.3, 0.8]

[[lights]]
position = [4.0, 9.0, 3.0]
color = [1.0, 0.9, 0.8]
intensity = 0.75

[[lights]]
position = [-5.0, 6.0, 1.0]

[materials.red_metal]
preset = "metal"
color = [0.8, 0.1, 0.1]

[materials.dense_glass]
preset = "glass"
ior = 1.9
color = [0.7, 1.0, 0.8]

[materials.plain]
diffuse = 0.5
ambient = 0.2
shininess = 12.0
specular = 0.25
reflectivity = 0.125
metallic = true

[floor]
height = -0.5
color_a = [1.0, 1.0, 0.9]
color_b = [0.0, 0.1, 0.2]
size = 2.5
preset = "glossy"
reflectivity = 0.4

[[spheres]]
center = [0.0, 1.0, 0.0]
radius = 1.0
material = "dense_glass"

[[spheres]]
center = [-2.0, 0.5, 1.0]
radius = 0.5
material = "red_metal"

[[spheres]]
center = [2.0, 0.25, 1.0]
radius = 0.25

[[sphere_arrays]]
file = "data/named.npz"

[[sphere_arrays]]
file = "data/ids.npz"

[[sphere_arrays]]
file = "data/plain.npz"
material = "plain"

[[meshes]]
file = "meshes/box.ply"
material = "red_metal"
translate = [1.0, 2.0, 3.0]
rotate = [15.0, 30.0, 45.0]
scale = [1.0, 2.0, 0.5]
smooth = false

[[meshes]]
file = "meshes/../meshes/box.ply"
scale = 0.5

[[meshes]]
file = "meshes/cone.off"
material = "plain"
transform = [[1, 0, 0, 4], [0, 2, 0, 0], [0, 0, 1, -1], [0, 0, 0, 1]]
"""


def _write_full_scene(folder: Path) -> dict:
    """Write FULL_SCENE's data files under ``folder``; returns the arrays and meshes it holds."""
    (folder / "data").mkdir()
    (folder / "meshes").mkdir()
    rng = np.random.default_rng(5)
    data = {
        "named": (
            rng.normal(size=(4, 3)),
            rng.uniform(0.1, 0.3, 4),
            np.array(["glass", "plain"] * 2),
        ),
        "ids": (
            rng.normal(size=(3, 3)).astype(np.float32),
            np.full(3, 0.2, np.float32),
            np.array([0, 5, 7]),
        ),
        "plain": (rng.normal(size=(2, 3)), np.array([0.3, 0.4]), None),
    }
    for name, (centers, radii, materials) in data.items():
        arrays = {"centers": centers, "radii": radii}
        if materials is not None:
            arrays["materials"] = materials
        np.savez(folder / "data" / f"{name}.npz", **arrays)
    box = trimesh.creation.box(extents=(1.0, 0.5, 0.25))
    cone = trimesh.creation.cone(radius=0.5, height=1.0, sections=12)
    box.export(folder / "meshes" / "box.ply")
    cone.export(folder / "meshes" / "cone.off")
    (folder / "scene.toml").write_text(FULL_SCENE)
    return {"arrays": data, "box": box, "cone": cone}


def _placement(translate, degrees_xyz, scale) -> np.ndarray:
    """Scale, then rotate about the fixed X, Y, Z axes in turn, then translate (scipy's
    extrinsic "xyz" Euler convention)."""
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_euler("xyz", degrees_xyz, degrees=True).as_matrix() @ np.diag(
        scale
    )
    matrix[:3, 3] = translate
    return matrix


def test_scene_file_equals_the_scene_built_in_python(tmp_path: Path) -> None:
    made = _write_full_scene(tmp_path)
    loaded = load_scene(tmp_path / "scene.toml")

    built = Scene(
        camera=Camera(position=(0.5, 2.0, 8.0), look_at=(0.0, 0.7, 0.0), up=(0, 1, 0.1), fov=38.5),
        background=Background(horizon=(0.9, 0.9, 1.0), zenith=(0.1, 0.3, 0.8)),
        render=RenderSettings(width=320, height=200, spp=3, max_depth=4, seed=11),
        floor=Floor(
            height=-0.5,
            checker=Checker(color_a=(1.0, 1.0, 0.9), color_b=(0.0, 0.1, 0.2), size=2.5),
            material=replace(PRESETS["glossy"], reflectivity=0.4),
        ),
    )
    built.lights = [
        PointLight(position=(4, 9, 3), color=(1.0, 0.9, 0.8), intensity=0.75),
        PointLight(position=(-5, 6, 1), color=(1, 1, 1), intensity=1.0),
    ]
    built.add_material("red_metal", preset("metal", color=(0.8, 0.1, 0.1)))
    built.add_material("dense_glass", preset("glass", ior=1.9, color=(0.7, 1.0, 0.8)))
    built.add_material(
        "plain",
        Material(
            diffuse=0.5,
            ambient=0.2,
            shininess=12.0,
            specular=0.25,
            reflectivity=0.125,
            metallic=True,
            color=PRESETS["matte"].color,
        ),
    )
    built.add_sphere((0, 1, 0), 1.0, "dense_glass")
    built.add_sphere((-2, 0.5, 1), 0.5, "red_metal")
    built.add_sphere((2, 0.25, 1), 0.25)
    for name in ("named", "ids", "plain"):
        centers, radii, materials = made["arrays"][name]
        built.add_spheres(centers, radii, "plain" if materials is None else materials)
    built.add_mesh(
        made["box"], "red_metal", _placement((1, 2, 3), (15, 30, 45), (1, 2, 0.5)), False
    )
    built.add_mesh(made["box"], None, np.diag([0.5, 0.5, 0.5, 1.0]))
    cone_placement = np.array([[1, 0, 0, 4], [0, 2, 0, 0], [0, 0, 1, -1], [0, 0, 0, 1.0]])
    built.add_mesh(made["cone"], "plain", cone_placement)

    # PLY stores float32 vertices; OFF keeps them to ~1e-10.
    assert_same_scene(loaded, built, mesh_atol=1e-7)
    # Integer material ids index the scene's material list: the presets, then the file's own.
    names = loaded.material_names
    assert names[:5] == list(PRESETS) and names[5:] == ["red_metal", "dense_glass", "plain"]
    ids_rows = slice(3 + 4, 3 + 4 + 3)
    assert [names[i] for i in loaded.sphere_materials[ids_rows]] == ["matte", "red_metal", "plain"]


def test_json_and_toml_of_one_document_load_to_the_same_scene(tmp_path: Path) -> None:
    _write_full_scene(tmp_path)
    document = tomllib.loads(FULL_SCENE)
    (tmp_path / "scene.json").write_text(json.dumps(document, indent=1))
    assert_same_scene(load_scene(tmp_path / "scene.json"), load_scene(tmp_path / "scene.toml"))


def test_paths_are_relative_to_the_scene_file_not_the_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _write_full_scene(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    scene = load_scene(Path("..") / "scene.toml")
    assert len(scene.sphere_radii) == 3 + 4 + 3 + 2 and len(scene.meshes) == 3


def _rich_scene(tmp_path: Path) -> Scene:
    scene = random_field(300, seed=2)
    scene.render = RenderSettings(width=77, height=55, spp=2, max_depth=3, seed=4)
    scene.background = Background(horizon=(1.0, 0.5, 0.25), zenith=(0.0, 0.0, 1.0))
    scene.add_material("glass", preset("glass", ior=1.33))  # a preset name, redefined
    scene.add_material("odd", Material(color=(0.1, 0.2, 0.3), specular=0.4, metallic=True))
    scene.add_sphere((9.0, 0.5, 9.0), 0.5, "glass")
    torus = trimesh.creation.torus(0.6, 0.2, major_sections=16, minor_sections=8)
    colored = trimesh.creation.box()
    colored.visual.face_colors = (255, 0, 0, 255)
    for angle in range(0, 360, 60):  # one mesh, six placements
        matrix = trimesh.transformations.rotation_matrix(np.radians(angle), (0, 1, 0))
        matrix[:3, 3] = (3 * np.cos(np.radians(angle)), 0.2, 3 * np.sin(np.radians(angle)))
        scene.add_mesh(torus, "odd" if angle % 120 else "mirror", matrix, smooth=angle < 180)
    scene.add_mesh(colored, transform=np.diag([1.0, 2.0, 3.0, 1.0]))  # its base color: red
    return scene


@pytest.mark.parametrize("suffix", [".toml", ".json"])
@pytest.mark.parametrize("floor", ["default", "none", "custom"])
def test_save_then_load_gives_the_same_scene(tmp_path: Path, suffix: str, floor: str) -> None:
    scene = _rich_scene(tmp_path)
    if floor == "none":
        scene.floor = None
    elif floor == "custom":
        scene.floor = Floor(height=0.25, checker=Checker(size=0.5), material=PRESETS["mirror"])
    path = tmp_path / f"saved{suffix}"
    save_scene(scene, path)
    again = load_scene(path)
    # Meshes go through PLY (float32 vertices); everything else is exact.
    assert_same_scene(again, scene, mesh_atol=1e-6)
    assert again.materials["base_color_ff0000"].color == (1.0, 0.0, 0.0)
    assert again.meshes[0].mesh is again.meshes[5].mesh  # still one shared mesh
    bulk = np.load(tmp_path / "saved.spheres.npz", allow_pickle=False)
    assert len(bulk["radii"]) == len(scene.sphere_radii)
    assert len(list(tmp_path.glob("saved.mesh*.ply"))) == 2  # one file per distinct mesh


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_a_saved_scene_writes_vectors_inline_as_a_person_would(tmp_path: Path, suffix: str) -> None:
    scene = Scene(camera=Camera(position=(0.0, 1.6, 6.5), look_at=(0.0, 0.8, 0.0), fov=45.0))
    scene.lights = [PointLight((4.0, 6.0, 4.0), (1.0, 0.9, 0.8)), PointLight((-5.0, 4.0, 2.0))]
    scene.add_material("odd", Material(color=(0.1, 0.2, 0.3), specular=0.4, metallic=True))
    scene.add_sphere((0.0, 1.0, 0.0), 1.0, "odd")
    torus = trimesh.creation.torus(0.6, 0.2, major_sections=16, minor_sections=8)
    for angle in range(0, 360, 60):  # one mesh, six placements
        matrix = trimesh.transformations.rotation_matrix(np.radians(angle), (0, 1, 0))
        matrix[:3, 3] = (3 * np.cos(np.radians(angle)), 0.2, 3 * np.sin(np.radians(angle)))
        scene.add_mesh(torus, "odd", matrix)
    scene.add_mesh(torus, "odd", np.eye(4))
    path = tmp_path / f"saved{suffix}"
    save_scene(scene, path)
    text = path.read_text(encoding="utf-8")
    lines = [line.strip() for line in text.splitlines()]
    if suffix == ".toml":
        camera = ["position = [0.0, 1.6, 6.5]", "look_at = [0.0, 0.8, 0.0]", "up = [0.0, 1.0, 0.0]"]
        assert "\n".join(["[camera]", *camera]) in text
        assert "[0.0, 0.0, 0.0, 1.0]," in lines  # a 4x4 transform: one row a line
        written = tomllib.loads(text)
    else:
        assert '"position": [0.0, 1.6, 6.5],' in lines
        written = json.loads(text)
    # No number stands on a line of its own, so the file is under half as long as the
    # one-number-a-line layout of the same document (tomli-w's, or json.dumps(indent=2)'s),
    # and it reads back exactly.
    number = re.compile(r"-?\d+(\.\d+)?(e-?\d+)?,?")
    assert not [line for line in lines if number.fullmatch(line)]
    spread = tomli_w.dumps(written) if suffix == ".toml" else json.dumps(written, indent=2)
    assert len(lines) < 0.5 * len(spread.splitlines())
    assert max(len(line) for line in text.splitlines()) <= 100
    assert_same_scene(load_scene(path), scene, mesh_atol=1e-6)


def test_save_of_an_empty_scene_round_trips(tmp_path: Path) -> None:
    scene = Scene()
    save_scene(scene, tmp_path / "empty.toml")
    assert_same_scene(load_scene(tmp_path / "empty.toml"), scene)
    assert not list(tmp_path.glob("*.npz"))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("", Floor()),
        ("floor = true", Floor()),
        ("floor = false", None),
        ("[floor]\nsize = 3", Floor(checker=Checker(size=3.0))),
        (
            '[floor]\npreset = "mirror"\nreflectivity = 0.5',
            Floor(material=replace(PRESETS["mirror"], reflectivity=0.5)),
        ),
    ],
)
def test_floor_absent_means_the_default_and_false_means_none(tmp_path, text, expected) -> None:
    (tmp_path / "s.toml").write_text(text)
    assert load_scene(tmp_path / "s.toml").floor == expected


def test_public_api() -> None:
    assert embree_rt.load_scene is embree_rt.scene.load_scene is loader_module.load_scene
    assert embree_rt.SceneError is embree_rt.scene.SceneError
    assert issubclass(SceneError, ValueError)
    error = SceneError("a/b.toml", "spheres[3].radius", "must be > 0, got -1")
    assert (error.file, error.key, error.problem) == (
        "a/b.toml",
        "spheres[3].radius",
        error.problem,
    )
    assert str(error) == "a/b.toml: spheres[3].radius: must be > 0, got -1"


# -- the shipped scenes ---------------------------------------------------------------------------

SCENES = sorted((ROOT / "scenes").glob("*.toml"))


def _objects(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 3) and top heights (n,) of every sphere and mesh placement (world bounds)."""
    centers, tops = (
        [scene.sphere_centers.astype(float)],
        [scene.sphere_centers[:, 1] + scene.sphere_radii],
    )
    for placement in scene.meshes:
        world = placement.mesh.copy()
        world.apply_transform(placement.transform)
        centers.append(world.bounds.mean(axis=0)[None])
        tops.append(world.bounds[1, 1:2])
    return np.concatenate(centers), np.concatenate(tops)


def test_the_shipped_scenes_are_the_five_of_the_issue_textured_meshes_and_gltf_materials() -> None:
    assert [p.name for p in SCENES] == [
        "benzene.toml",  # the scientific look: ball and stick, AO, white background
        "gltf_materials.toml",
        "material_spectrum.toml",
        "mesh_and_spheres.toml",
        "random_field.toml",
        "showcase.toml",
        "textured_meshes.toml",
        "three_spheres.toml",
    ]


@pytest.mark.parametrize("path", [p for p in SCENES if p.stem != "benzene"], ids=lambda p: p.stem)
def test_shipped_scene_is_a_good_tutorial_picture(path: Path) -> None:
    scene = load_scene(path)
    assert scene.floor is not None and scene.floor.material.reflectivity > 0
    assert scene.floor.height == 0.0
    # Every sphere rests on the floor.
    np.testing.assert_allclose(scene.sphere_centers[:, 1], scene.sphere_radii, rtol=1e-6)
    # One or two point lights, well above everything.
    centers, tops = _objects(scene)
    assert 1 <= len(scene.lights) <= 2
    assert all(light.position[1] > 2 * tops.max() for light in scene.lights)
    # The camera sees every object (a random field: every hero sphere and most of the rest).
    aspect = scene.render.width / scene.render.height
    visible = in_frame(scene.camera, aspect, centers)
    if path.stem == "random_field":
        assert visible[:3].all() and visible.mean() > 0.5
    else:
        assert visible.all(), np.flatnonzero(~visible)
    # Sky gradient: a bluer zenith than horizon.
    assert scene.background.zenith[2] > scene.background.zenith[0]


def _material(scene: Scene, sphere: int) -> Material:
    return scene.materials[scene.material_names[scene.sphere_materials[sphere]]]


def test_showcase_has_the_articles_six_spheres() -> None:
    scene = load_scene(ROOT / "scenes" / "showcase.toml")
    materials = [_material(scene, i) for i in range(len(scene.sphere_radii))]
    assert len(materials) == 6
    glass = [m for m in materials if m.transparency > 0]
    assert len(glass) == 2 and any(m.color[1] > max(m.color[0], m.color[2]) for m in glass)  # green
    metals = [m for m in materials if m.metallic]
    assert any(m.color[0] > 2 * m.color[1] for m in metals)  # red
    assert any(m.color[0] > m.color[1] > m.color[2] + 0.3 for m in metals)  # gold
    assert any(m.reflectivity >= 0.9 and m.transparency == 0 for m in materials)  # chrome
    assert any(m.reflectivity == 0 and m.color[2] > 2 * m.color[0] for m in materials)  # blue


def test_three_spheres_and_material_spectrum() -> None:
    three = load_scene(ROOT / "scenes" / "three_spheres.toml")
    red, glass, mirror = (_material(three, i) for i in np.argsort(three.sphere_centers[:, 0]))
    assert red.reflectivity == 0 and red.color[0] > 4 * red.color[1] and red.transparency == 0
    assert glass.transparency > 0 and mirror.reflectivity >= 0.9

    spectrum = load_scene(ROOT / "scenes" / "material_spectrum.toml")
    order = np.argsort(spectrum.sphere_centers[:, 0])
    assert np.ptp(spectrum.sphere_centers[:, 1:], axis=0).max() == 0  # a row
    row = [_material(spectrum, i) for i in order]
    # matte, glossy, metal, mirror: ever more specular and reflective; then glass.
    assert [m.specular for m in row[:4]] == sorted(m.specular for m in row[:4])
    assert [m.reflectivity for m in row[:4]] == sorted(m.reflectivity for m in row[:4])
    assert row[0].specular == 0 and row[2].metallic and row[4].transparency > 0


def test_mesh_scene_places_one_mesh_many_times_and_every_format() -> None:
    path = ROOT / "scenes" / "mesh_and_spheres.toml"
    scene = load_scene(path)
    counts = np.bincount(sharing(scene))
    assert counts.max() >= 12  # a ring of copies of one loaded mesh
    files = {m["file"].rsplit(".", 1)[1] for m in tomllib.loads(path.read_text())["meshes"]}
    assert {"obj", "ply", "stl", "off", "glb"} <= files
    assert len(scene.sphere_radii) >= 1


def test_random_field_scene_has_heroes_and_about_sixty_spheres() -> None:
    scene = load_scene(ROOT / "scenes" / "random_field.toml")
    assert 40 <= len(scene.sphere_radii) <= 100
    assert (scene.sphere_radii >= 0.99).sum() == 3


# -- bad input ------------------------------------------------------------------------------------

SPHERE = "[[spheres]]\ncenter = [0, 1, 0]\n"
MESH = '[[meshes]]\nfile = "box.ply"\n'
ARRAY = '[[sphere_arrays]]\nfile = "{}"\n'
IDENTITY = "[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"
# case: (file name, text, key, words the problem must contain)
BAD = {
    "missing file": ("absent.toml", None, "(file)", "no such file"),
    "a directory": ("folder.toml", None, "(file)", "is a directory, not a file"),
    "not utf-8": ("latin1.toml", None, "(file)", "cannot read"),
    "other suffix": ("scene.yaml", "a: 1", "(file)", ".toml or .json"),
    "malformed toml": ("s.toml", "[render]\nwidth = = 3", "(syntax)", "line 2"),
    "malformed json": ("s.json", '{\n"render":\n{"width": 3,}}', "(syntax)", "line 3"),
    "json list": ("s.json", "[1, 2]", "(top level)", "JSON object"),
    "unknown top key": (
        "s.toml",
        "[[sphere]]\ncenter = [0, 1, 0]",
        "sphere",
        "did you mean 'spheres'",
    ),
    "unknown render key": ("s.toml", "[render]\nwidht = 3", "render.widht", "did you mean 'width'"),
    "unknown material key": (
        "s.toml",
        "[materials.red]\ncolour = [1, 0, 0]",
        "materials.red.colour",
        "did you mean 'color'",
    ),
    "unknown sphere key": (
        "s.toml",
        SPHERE + "radius = 1\n" + SPHERE + "radious = 1",
        "spheres[1].radious",
        "did you mean 'radius'",
    ),
    "unknown mesh key": (
        "s.toml",
        MESH + "rotation = [0, 1, 0]",
        "meshes[0].rotation",
        "did you mean 'rotate'",
    ),
    "unknown field key": (
        "s.toml",
        "[random_field]\ncount = 5\ncont = 3",
        "random_field.cont",
        "did you mean 'count'",
    ),
    "unknown mix kind": (
        "s.toml",
        "[random_field]\ncount = 5\nmix = {mtal = 1}",
        "random_field.mix.mtal",
        "did you mean 'metal'",
    ),
    "section not a table": ("s.toml", "render = 3", "render", "expected a table"),
    "lights not a list": ("s.toml", "[lights]\nposition = [0, 5, 0]", "lights", "list of tables"),
    "material not a table": (
        "s.toml",
        '[materials]\nred = "metal"',
        "materials.red",
        "expected a table",
    ),
    "radius a string": (
        "s.toml",
        SPHERE + 'radius = "big"',
        "spheres[0].radius",
        "expected a number",
    ),
    "radius zero": ("s.toml", SPHERE + "radius = 0", "spheres[0].radius", ">= 1e-18"),
    "radius negative": ("s.toml", SPHERE + "radius = -1", "spheres[0].radius", ">= 1e-18"),
    "radius nan": ("s.toml", SPHERE + "radius = nan", "spheres[0].radius", "finite"),
    "radius missing": ("s.toml", SPHERE, "spheres[0].radius", "required"),
    "center inf": (
        "s.toml",
        "[[spheres]]\ncenter = [0, inf, 0]\nradius = 1",
        "spheres[0].center",
        "finite",
    ),
    "center two numbers": (
        "s.toml",
        "[[spheres]]\ncenter = [0, 1]\nradius = 1",
        "spheres[0].center",
        "three numbers",
    ),
    "center a bool": (
        "s.toml",
        "[[spheres]]\ncenter = [0, true, 1]\nradius = 1",
        "spheres[0].center",
        "numbers",
    ),
    "width -1": ("s.toml", "[render]\nwidth = -1", "render.width", ">= 1"),
    "width float": ("s.toml", "[render]\nwidth = 64.5", "render.width", "integer"),
    "height zero": ("s.toml", "[render]\nheight = 0", "render.height", ">= 1"),
    "spp zero": ("s.toml", "[render]\nspp = 0", "render.spp", ">= 1"),
    "max_depth negative": ("s.toml", "[render]\nmax_depth = -1", "render.max_depth", ">= 0"),
    "seed negative": ("s.toml", "[render]\nseed = -3", "render.seed", ">= 0"),
    "fov zero": ("s.toml", "[camera]\nfov = 0", "camera.fov", "> 0"),
    "fov 180": ("s.toml", "[camera]\nfov = 180", "camera.fov", "< 180"),
    "fov nan": ("s.json", '{"camera": {"fov": NaN}}', "camera.fov", "finite"),
    "camera at its target": (
        "s.toml",
        "[camera]\nposition = [1, 2, 3]\nlook_at = [1, 2, 3]",
        "camera.look_at",
        "differ",
    ),
    "up along the view": (
        "s.toml",
        "[camera]\nposition = [0, 5, 0]\nlook_at = [0, 0, 0]",
        "camera.up",
        "parallel",
    ),
    "light without position": (
        "s.toml",
        "[[lights]]\nintensity = 1",
        "lights[0].position",
        "required",
    ),
    "negative intensity": (
        "s.toml",
        "[[lights]]\nposition = [0, 5, 0]\nintensity = -1",
        "lights[0].intensity",
        ">= 0",
    ),
    "negative color": (
        "s.toml",
        "[[lights]]\nposition = [0, 5, 0]\ncolor = [1, -1, 1]",
        "lights[0].color",
        "negative",
    ),
    "horizon a string": (
        "s.toml",
        '[background]\nhorizon = "blue"',
        "background.horizon",
        "three numbers",
    ),
    "reflectivity 1.5": (
        "s.toml",
        "[materials.red]\nreflectivity = 1.5",
        "materials.red.reflectivity",
        "<= 1",
    ),
    "ior below 1": ("s.toml", "[materials.red]\nior = 0.5", "materials.red.ior", ">= 1"),
    "shininess zero": (
        "s.toml",
        "[materials.red]\nshininess = 0",
        "materials.red.shininess",
        "> 0",
    ),
    "unknown preset": (
        "s.toml",
        '[materials.red]\npreset = "plastic"',
        "materials.red.preset",
        "unknown preset",
    ),
    "metallic a string": (
        "s.toml",
        '[materials.red]\nmetallic = "yes"',
        "materials.red.metallic",
        "true or false",
    ),
    "floor a number": ("s.toml", "floor = 3", "floor", "expected a table"),
    "floor size zero": ("s.toml", "[floor]\nsize = 0", "floor.size", ">= 1e-18"),
    "floor reflectivity": ("s.toml", "[floor]\nreflectivity = -0.1", "floor.reflectivity", ">= 0"),
    "undefined sphere material": (
        "s.toml",
        SPHERE + 'radius = 1\nmaterial = "gold"',
        "spheres[0].material",
        "undefined material 'gold'",
    ),
    "undefined mesh material": (
        "s.toml",
        MESH + 'material = "gold"',
        "meshes[0].material",
        "undefined material",
    ),
    "undefined array material": (
        "s.toml",
        ARRAY.format("ok.npz") + 'material = "gold"',
        "sphere_arrays[0].material",
        "undefined material",
    ),
    "mesh file missing": (
        "s.toml",
        '[[meshes]]\nfile = "nowhere.obj"',
        "meshes[0].file",
        "no such file",
    ),
    "mesh file not given": ("s.toml", "[[meshes]]\nscale = 2", "meshes[0].file", "required"),
    "mesh unparsable": (
        "s.toml",
        '[[meshes]]\nfile = "garbage.ply"',
        "meshes[0].file",
        "garbage.ply",
    ),
    "mesh empty": ("s.toml", '[[meshes]]\nfile = "empty.obj"', "meshes[0].file", "no triangles"),
    "mesh nan vertex": ("s.toml", '[[meshes]]\nfile = "nan.obj"', "meshes[0].file", "NaN"),
    "mesh format": (
        "s.toml",
        '[[meshes]]\nfile = "model.fbx"',
        "meshes[0].file",
        "unsupported mesh format",
    ),
    "scale zero": ("s.toml", MESH + "scale = 0", "meshes[0].scale", "> 0"),
    "scale negative axis": ("s.toml", MESH + "scale = [1, -1, 1]", "meshes[0].scale", "> 0"),
    "rotate two numbers": (
        "s.toml",
        MESH + "rotate = [0, 90]",
        "meshes[0].rotate",
        "three numbers",
    ),
    "transform 3x3": (
        "s.toml",
        MESH + "transform = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]",
        "meshes[0].transform",
        "4x4",
    ),
    "transform singular": (
        "s.toml",
        MESH + "transform = [[0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]",
        "meshes[0].transform",
        "invertible",
    ),
    "transform and translate": (
        "s.toml",
        MESH + "translate = [1, 0, 0]\ntransform = " + IDENTITY,
        "meshes[0].translate",
        "either",
    ),
    "smooth a string": ("s.toml", MESH + 'smooth = "yes"', "meshes[0].smooth", "true or false"),
    "npz missing": ("s.toml", ARRAY.format("none.npz"), "sphere_arrays[0].file", "no such file"),
    "npz not a zip": ("s.toml", ARRAY.format("text.npz"), "sphere_arrays[0].file", "cannot read"),
    "npz a single array": ("s.toml", ARRAY.format("single.npy"), "sphere_arrays[0].file", ".npz"),
    "npz without radii": (
        "s.toml",
        ARRAY.format("no_radii.npz"),
        "sphere_arrays[0].file",
        "missing array 'radii'",
    ),
    "npz centers (n, 2)": (
        "s.toml",
        ARRAY.format("flat.npz"),
        "sphere_arrays[0].file",
        "centers must be (n, 3)",
    ),
    "npz radii too few": (
        "s.toml",
        ARRAY.format("short.npz"),
        "sphere_arrays[0].file",
        "radii must be (3,)",
    ),
    "npz radius negative": (
        "s.toml",
        ARRAY.format("negative.npz"),
        "sphere_arrays[0].file",
        "radii row 1",
    ),
    "npz center nan": ("s.toml", ARRAY.format("nan.npz"), "sphere_arrays[0].file", "centers row 2"),
    "npz unknown name": (
        "s.toml",
        ARRAY.format("names.npz"),
        "sphere_arrays[0].file",
        "undefined material 'gold'",
    ),
    "npz id out of range": (
        "s.toml",
        ARRAY.format("ids.npz"),
        "sphere_arrays[0].file",
        "out of range",
    ),
    "npz pickled objects": (
        "s.toml",
        ARRAY.format("objects.npz"),
        "sphere_arrays[0].file",
        "cannot read",
    ),
    "npz materials 2-d": (
        "s.toml",
        ARRAY.format("materials2d.npz"),
        "sphere_arrays[0].file",
        "materials must be (3,)",
    ),
    "field count zero": ("s.toml", "[random_field]\ncount = 0", "random_field.count", ">= 1"),
    "field count missing": ("s.toml", "[random_field]\nseed = 3", "random_field.count", "required"),
    "field count float": ("s.toml", "[random_field]\ncount = 1.5", "random_field.count", "integer"),
    "field extent zero": (
        "s.toml",
        "[random_field]\ncount = 9\nextent = 0",
        "random_field.extent",
        "> 0",
    ),
    "field extent tiny": (
        "s.toml",
        "[random_field]\ncount = 9\nextent = 1",
        "random_field.extent",
        "too small",
    ),
    "field radius reversed": (
        "s.toml",
        "[random_field]\ncount = 9\nradius = [0.3, 0.1]",
        "random_field.radius",
        "min <= max",
    ),
    "field radius one number": (
        "s.toml",
        "[random_field]\ncount = 9\nradius = 0.3",
        "random_field.radius",
        "[min, max]",
    ),
    "field radius too big": (
        "s.toml",
        "[random_field]\ncount = 10000\nextent = 20\nradius = [0.1, 0.5]",
        "random_field.radius",
        "too large",
    ),
    "field mix negative": (
        "s.toml",
        "[random_field]\ncount = 9\nmix = {glass = -1}",
        "random_field.mix.glass",
        ">= 0",
    ),
    "field mix all zero": (
        "s.toml",
        "[random_field]\ncount = 9\nmix = {glass = 0}",
        "random_field.mix",
        "> 0",
    ),
    "field heroes a number": (
        "s.toml",
        "[random_field]\ncount = 9\nheroes = 1",
        "random_field.heroes",
        "true or false",
    ),
}


def _write_support_files(folder: Path) -> None:
    (folder / "folder.toml").mkdir()
    (folder / "latin1.toml").write_bytes("# caf\xe9\n".encode("latin-1"))
    trimesh.creation.box().export(folder / "box.ply")
    (folder / "garbage.ply").write_bytes(b"ply\nthis is not a mesh\x00\x01\x02")
    (folder / "empty.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (folder / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    (folder / "model.fbx").write_bytes(b"\x00")
    (folder / "text.npz").write_text("not a zip archive")
    np.save(folder / "single.npy", np.zeros((3, 3)))
    good = {"centers": np.zeros((3, 3)), "radii": np.ones(3)}
    variants = {
        "ok": {},
        "no_radii": {"radii": None},
        "flat": {"centers": np.zeros((3, 2))},
        "short": {"radii": np.ones(2)},
        "negative": {"radii": np.array([1.0, -1.0, 1.0])},
        "nan": {"centers": np.array([[0, 0, 0], [0, 0, 0], [0, np.nan, 0]])},
        "names": {"materials": np.array(["matte", "gold", "glass"])},
        "ids": {"materials": np.array([0, 1, 99])},
        "objects": {"materials": np.array(["matte", None, 3], dtype=object)},
        "materials2d": {"materials": np.zeros((3, 2), np.int32)},
    }
    for name, changes in variants.items():
        arrays = {key: value for key, value in {**good, **changes}.items() if value is not None}
        np.savez(folder / f"{name}.npz", **arrays)


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_a_scene_error_naming_file_and_key(tmp_path: Path, case: str) -> None:
    name, text, key, words = BAD[case]
    _write_support_files(tmp_path)
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    error = caught.value
    assert (error.file, error.key) == (str(path), key)
    assert str(error) == f"{path}: {key}: {error.problem}"
    assert words in error.problem
    assert "\n" not in str(error)


# Sines of the angle between ``up`` and the viewing direction, either side of what the camera
# accepts (1e-6): the loader once let 1e-7 through on the unnormalised vectors.
UP_SINES = (0.0, 1e-9, 1e-7, 5e-7, 2e-6, 1e-5, 0.3)


@pytest.mark.parametrize("sine", UP_SINES)
def test_a_camera_that_loads_also_frames_an_image(tmp_path: Path, sine: float) -> None:
    """One rule for the camera: the loader refuses exactly the cameras the renderer would."""
    from embree_rt.camera import camera_frame

    # Looking straight down from 5 units up, with ``up`` tilted off the vertical by ``sine``.
    up = [sine * 3.0, -math.sqrt(1.0 - sine * sine) * 3.0, 0.0]  # any length: only the angle counts
    path = tmp_path / "s.toml"
    path.write_text(f"[camera]\nposition = [0, 5, 0]\nlook_at = [0, 0, 0]\nup = {up}\n")
    try:
        scene = load_scene(path)
    except SceneError as error:
        assert error.key == "camera.up" and "parallel" in error.problem
        with pytest.raises(ValueError, match=r"camera\.up"):
            camera_frame(Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=tuple(up)), 8, 8)
        assert sine < 1e-6
    else:
        frame = camera_frame(scene.camera, 8, 8)
        assert np.isfinite([frame.u, frame.v, frame.w]).all()
        assert sine >= 1e-6


def test_the_mistake_is_found_before_any_heavy_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A typo in the last table is reported before the random field is generated or any mesh
    or sphere array is read; a bad mesh is reported before the field is generated."""
    calls: list[str] = []

    def spy(module, name):
        function = getattr(module, name)

        def wrapper(*args, **kwargs):
            calls.append(name)
            return function(*args, **kwargs)

        monkeypatch.setattr(module, name, wrapper)

    spy(loader_module, "add_field_spheres")
    # The loader imports mesh loading when a scene has meshes (trimesh takes ~1 s to import).
    spy(meshes_module, "load_model")
    trimesh.creation.box().export(tmp_path / "box.ply")
    np.savez(tmp_path / "bulk.npz", centers=np.zeros((2, 3)), radii=np.ones(2))
    head = '[random_field]\ncount = 1000000\n[[sphere_arrays]]\nfile = "bulk.npz"\n' + MESH
    (tmp_path / "typo.toml").write_text(head + SPHERE + "radius = 1\nmaterial = 'hero_glas'\n")
    with pytest.raises(SceneError, match=r"spheres\[0\]\.material: undefined material"):
        load_scene(tmp_path / "typo.toml")
    assert calls == []

    (tmp_path / "bad_mesh.toml").write_text(head + '[[meshes]]\nfile = "missing.obj"\n')
    with pytest.raises(SceneError, match=r"meshes\[1\]\.file"):
        load_scene(tmp_path / "bad_mesh.toml")
    assert "add_field_spheres" not in calls and calls.count("load_model") == 2


def test_a_bad_file_never_escapes_as_another_exception(tmp_path: Path) -> None:
    """Random bytes and random JSON values in every slot give SceneError, nothing else."""
    rng = np.random.default_rng(0)
    values = [None, True, -1, 0, 1.5, float("nan"), "x", [], [1], [1, 2, "a"], {}, {"a": 1}]
    slots = [
        ("render", "width"),
        ("camera", "position"),
        ("camera", "fov"),
        ("background", "zenith"),
        ("floor", "size"),
        ("floor", "color_a"),
        ("random_field", "count"),
        ("random_field", "radius"),
        ("random_field", "mix"),
        ("materials", "red"),
    ]
    for section, key in slots:
        for value in values:
            document = {section: {key: value}}
            for entry in ("spheres", "meshes", "lights", "sphere_arrays"):
                document[entry] = [{"center": value, "radius": value, "file": value}]
            path = tmp_path / f"{section}_{key}.json"
            path.write_text(json.dumps(document))
            with pytest.raises(SceneError):
                load_scene(path)
    for size in (1, 10, 300):
        path = tmp_path / f"noise{size}.toml"
        path.write_bytes(rng.integers(0, 256, size, dtype=np.uint8).tobytes())
        with contextlib.suppress(SceneError):  # anything else fails the test
            load_scene(path)


# -- the random field, from a file and as a picture ----------------------------------------------


def test_random_field_block_equals_random_field_in_python(tmp_path: Path) -> None:
    (tmp_path / "field.toml").write_text(
        """
[random_field]
count = 700
seed = 5
extent = 12.5
radius = [0.1, 0.2]
mix = { matte = 2, metal = 1 }
heroes = false

[render]
width = 100

[materials.metal_03]
preset = "mirror"

[[spheres]]
center = [0.0, 3.0, 0.0]
radius = 3.0
material = "matte_01"
"""
    )
    expected = random_field(
        700, seed=5, extent=12.5, radius=(0.1, 0.2), mix={"matte": 2, "metal": 1}, heroes=False
    )
    expected.render = replace(expected.render, width=100)
    expected.add_material("metal_03", preset("mirror"))  # replaces the palette's, in place
    expected.add_sphere((0, 3, 0), 3.0, "matte_01")
    assert_same_scene(load_scene(tmp_path / "field.toml"), expected)


def _angular_radius(camera: Camera, center, radius: float) -> float:
    """Half the angle, in degrees, a sphere takes up seen from the camera."""
    distance = np.linalg.norm(np.subtract(center, camera.position))
    return float(np.degrees(np.arcsin(min(1.0, radius / distance))))


@pytest.mark.parametrize("count", [3, 60, 5000, 1_000_000])
def test_random_field_camera_shows_the_heroes_big_and_the_field_receding(count: int) -> None:
    scene = random_field(count, seed=1)
    camera, aspect = scene.camera, scene.render.width / scene.render.height
    heroes = np.flatnonzero(scene.sphere_radii >= 0.99)
    assert len(heroes) == 3
    assert in_frame(camera, aspect, scene.sphere_centers[heroes]).all()
    for row in heroes:  # each hero spans at least a tenth of the picture's height
        size = 2 * _angular_radius(camera, scene.sphere_centers[row], scene.sphere_radii[row])
        assert size >= 0.1 * camera.fov
    centers = scene.sphere_centers.astype(np.float64)
    reach = np.hypot(centers[:, 0], centers[:, 2]).max()
    seen = in_frame(camera, aspect, centers)
    distance = np.linalg.norm(centers - camera.position, axis=1)
    # The field reaches back: something near its far edge is in the picture.
    assert distance[seen].max() >= 0.5 * reach
    # Lights: one or two, well above, and every sphere sees one at least 15 degrees up.
    assert 1 <= len(scene.lights) <= 2
    lights = np.array([light.position for light in scene.lights])
    offset = lights[None, :, :] - centers[:, None, :]
    elevation = np.degrees(np.arctan2(offset[..., 1], np.hypot(offset[..., 0], offset[..., 2])))
    assert (elevation.max(axis=1) >= 15).all()


@pytest.mark.parametrize("count", [1, 12, 400])
def test_random_field_without_heroes_frames_the_field(count: int) -> None:
    scene = random_field(count, seed=2, heroes=False)
    camera, aspect = scene.camera, scene.render.width / scene.render.height
    centers = scene.sphere_centers.astype(np.float64)
    nearest = int(np.argmin(np.hypot(centers[:, 0], centers[:, 2])))
    assert in_frame(camera, aspect, centers[nearest : nearest + 1]).all()
    size = 2 * _angular_radius(camera, centers[nearest], scene.sphere_radii[nearest])
    assert size >= 0.03 * camera.fov  # a sphere, not a speck
    assert in_frame(camera, aspect, centers).mean() >= min(1.0, 40 / count)


# -- the assets -----------------------------------------------------------------------------------


def _make_assets_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_assets", ROOT / "assets" / "make_assets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_assets_are_what_make_assets_makes_one_per_format(tmp_path: Path) -> None:
    make = _make_assets_module()
    expected = {
        "torus.obj": make.torus(),
        "gem.ply": make.gem(),
        "capsule.stl": make.capsule(),
        "cone.off": make.cone(),
        "twisted_box.glb": make.twisted_box(),
        "trio.glb": make.trio(),
    }
    on_disk = sorted(p.name for p in (ROOT / "assets").iterdir() if p.suffix != ".py")
    # and the meshes with looks of their own, which tests/test_mesh_looks.py checks, the glTF
    # material gallery (tests/test_gltf_materials.py) and still_life.glb
    # (tests/test_real_world_files.py)
    looks = [
        "gltf_materials.glb",
        "node_scaled.glb",
        "painted_ball.ply",
        "quadrant_cube.glb",
        "quadrant_cube.mtl",
        "quadrant_cube.obj",
        "quadrants.png",
        "still_life.glb",
        "zero_normals.obj",
    ]
    # the particle files of the gallery (tests/test_particles.py checks them)
    particles = ["helix.pdb", "peptide.pdb", "membrane.gsd", "packing.lammpstrj"]
    assert on_disk == sorted([*expected, *looks, *particles])
    document = {"floor": False, "meshes": [{"file": str(ROOT / "assets" / n)} for n in expected]}
    (tmp_path / "assets.json").write_text(json.dumps(document))
    scene = load_scene(tmp_path / "assets.json")
    assert len(scene.meshes) == 5 + 3  # trio.glb: three nodes
    for name, made in expected.items():
        assert (ROOT / "assets" / name).stat().st_size < 200_000
        if isinstance(made, trimesh.Scene):  # world-space parts, sorted by position
            made_parts = sorted(made.dump(), key=lambda m: tuple(m.bounds[0]))
            loaded = list(scene.meshes[5:])
        else:
            made_parts = [made]
            loaded = [scene.meshes[list(expected).index(name)]]
        loaded_bounds = sorted(
            (trimesh.transform_points(p.mesh.bounds, p.transform) for p in loaded),
            key=lambda b: tuple(b[0]),
        )
        for want, got, part in zip(made_parts, loaded_bounds, loaded, strict=True):
            np.testing.assert_allclose(got, want.bounds, atol=1e-6)
            assert len(part.mesh.faces) == len(want.faces)
    # trio.glb's balls carry their own colors: three matte base-color materials.
    trio_materials = {scene.materials[p.material].color for p in scene.meshes[5:]}
    assert len(trio_materials) == 3


# -- Scene.add_spheres ------------------------------------------------------------------------


def test_add_spheres_copies_unless_told_to_take_the_arrays() -> None:
    centers = np.array([[0.0, 1.0, 0.0], [2.0, 0.5, 0.0]], np.float32)
    radii = np.array([1.0, 0.5], np.float32)
    materials = np.array([0, 1], np.int32)
    copied = Scene()
    copied.add_spheres(centers, radii, materials)
    taken = Scene()
    taken.add_spheres(centers, radii, materials, copy=False)
    for kept, given in zip(
        (taken.sphere_centers, taken.sphere_radii, taken.sphere_materials),
        (centers, radii, materials),
        strict=True,
    ):
        assert np.shares_memory(kept, given)  # no copy of a hundred million spheres
    assert not np.shares_memory(copied.sphere_centers, centers)
    # Taken only into an empty scene: a second batch is appended as ever.
    taken.add_spheres(centers + 5, radii, "glass", copy=False)
    np.testing.assert_array_equal(taken.sphere_centers, np.concatenate([centers, centers + 5]))
    assert taken.sphere_materials.tolist() == [0, 1, *[taken.material_index("glass")] * 2]


def test_add_spheres_rejects_material_indices_beyond_int32() -> None:
    """An int64 index 2**32 must not wrap around to material 0 on its way to int32."""
    with pytest.raises(ValueError, match="index out of range"):
        Scene().add_spheres([[0.0, 1.0, 0.0]], [1.0], np.array([2**32], np.int64))
