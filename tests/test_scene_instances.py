"""Meshes placed by the thousand: ``--spheres mesh`` and a scene's ``instances`` go into the BVH
as Embree instance arrays, and render as the same meshes placed one by one do."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from embree_rt import Scene, SceneError, load_scene, render, save_scene
from embree_rt.geometry import SceneGeometry
from embree_rt.scene import meshes as meshes_module
from embree_rt.scene.instances import placement_matrices
from embree_rt.scene.random_field import random_field


def test_mesh_spheres_are_one_instance_array_with_each_spheres_material():
    scene = random_field(60, seed=4)
    with SceneGeometry(scene, spheres="mesh", threads=1) as geometry:
        assert geometry.bvh.geometry_count == 1  # one array, however many spheres
        assert geometry.bvh.instance_count == geometry.instance_count == 60
        # straight down onto each sphere's top: its own material, its own outward normal
        centers = scene.sphere_centers.astype(np.float64)
        origins = (centers + np.array([0.0, 50.0, 0.0])).T.astype(np.float32)
        directions = np.tile(np.float32([[0.0], [-1.0], [0.0]]), (1, 60))
        surfaces = geometry.intersect(origins, directions)
    assert surfaces.hit.all() and not surfaces.floor.any()
    np.testing.assert_array_equal(surfaces.material, scene.sphere_materials)
    top = centers[:, 1] + scene.sphere_radii
    # an icosphere of 3 subdivisions lies within 0.3% of its radius inside the sphere
    np.testing.assert_allclose(surfaces.position[1], top, atol=0.004 * scene.sphere_radii.max())
    assert np.all(surfaces.normal[1] > 0.99) and np.all(surfaces.face_normal[1] > 0.99)


# -- scene files ------------------------------------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]
GEM = ROOT / "assets" / "gem.ply"
SCENE_HEAD = """
[render]
width = 72
height = 48
spp = 2
max_depth = 3

[camera]
position = [0.0, 4.0, 6.0]
look_at = [0.0, 0.3, 0.0]
fov = 50.0

[[lights]]
position = [4.0, 8.0, 5.0]

[materials.red]
preset = "glossy"
color = [0.9, 0.2, 0.1]
"""


def scattered(count: int, seed: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """positions (n, 3), rotations (n, 3) degrees, scales (n, 3): a grid of turned, stretched
    and squashed copies, some mirrored in the transforms form."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    positions = np.stack(
        [
            1.3 * (np.arange(count) % side) - 2.6,
            rng.uniform(0.3, 0.6, count),
            1.3 * (np.arange(count) // side) - 2.6,
        ],
        axis=1,
    )
    rotations = rng.uniform(-180, 180, size=(count, 3))
    scales = rng.uniform(0.5, 0.9, size=(count, 3))
    return positions, rotations, scales


def write_instances_scene(folder: Path, arrays: dict, entry: str = "", mesh: Path = GEM) -> Path:
    np.savez(folder / "placements.npz", **arrays)
    scene = folder / "scene.toml"
    scene.write_text(
        SCENE_HEAD
        + f"""
[[instances]]
mesh = "{mesh}"
transforms = "placements.npz"
{entry}
"""
    )
    return scene


def test_positions_rotations_scales_are_the_meshes_rotate_convention(tmp_path: Path):
    positions, rotations, scales = scattered(5)
    materials = np.array(["red", "matte", "red", "metal", "matte"])
    scene = load_scene(
        write_instances_scene(
            tmp_path,
            {
                "positions": positions,
                "rotations": rotations,
                "scales": scales,
                "materials": materials,
            },
        )
    )
    (entry,) = scene.instances
    assert len(entry) == 5
    names = np.asarray(scene.material_names)[entry.materials]
    np.testing.assert_array_equal(names, materials)
    # the same placement written as a [[meshes]] entry
    lines = [SCENE_HEAD]
    for p, r, s in zip(positions, rotations, scales, strict=True):
        lines.append(
            f'[[meshes]]\nfile = "{GEM}"\ntranslate = {p.tolist()}\n'
            f"rotate = {r.tolist()}\nscale = {s.tolist()}\n"
        )
    (tmp_path / "meshes.toml").write_text("\n".join(lines))
    meshes = load_scene(tmp_path / "meshes.toml")
    expected = np.stack([m.transform for m in meshes.meshes])
    np.testing.assert_allclose(entry.transforms, expected, rtol=0, atol=1e-12)


def test_one_material_or_the_files_look(tmp_path: Path):
    positions, _, _ = scattered(4)
    scene = load_scene(
        write_instances_scene(tmp_path, {"positions": positions}, 'material = "red"')
    )
    assert scene.instances[0].materials.tolist() == [scene.material_index("red")] * 4
    assert not scene.instances[0].mesh_colors
    looks = load_scene(write_instances_scene(tmp_path, {"positions": positions}))
    assert looks.instances[0].mesh_colors


def test_scene_save_writes_the_placements_back(tmp_path: Path):
    positions, rotations, scales = scattered(7)
    transforms = placement_matrices(positions, rotations, scales)
    transforms[2, :3, 0] *= -1  # a mirrored copy
    scene = load_scene(
        write_instances_scene(
            tmp_path, {"transforms": transforms}, 'material = "red"\nsmooth = false'
        )
    )
    save_scene(scene, tmp_path / "saved.toml")
    assert (tmp_path / "saved.instances0.npz").is_file()
    again = load_scene(tmp_path / "saved.toml")
    (before,), (after,) = scene.instances, again.instances
    np.testing.assert_array_equal(after.transforms, before.transforms)
    np.testing.assert_array_equal(after.materials, before.materials)
    assert after.smooth is False
    np.testing.assert_allclose(after.mesh.vertices, before.mesh.vertices, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(after.mesh.faces, before.mesh.faces)


def _pickled() -> dict:
    return {"transforms": np.array([np.eye(4), "not a matrix"], dtype=object)}


BAD_PLACEMENTS = {
    "wrong shape": ({"transforms": np.zeros((3, 3, 4))}, "transforms must be (n, 4, 4) numbers"),
    "positions shape": ({"positions": np.zeros((3, 2))}, "positions must be (n, 3) numbers"),
    "NaN": (
        {"transforms": np.stack([np.eye(4), np.diag([1.0, np.nan, 1.0, 1.0])])},
        "transforms row 1: expected a 4x4 matrix of finite numbers",
    ),
    "NaN position": (
        {"positions": np.array([[0, 0, 0], [np.inf, 0, 0.0]])},
        "positions row 1 is not finite",
    ),
    "singular": (
        {"transforms": np.stack([np.eye(4), np.eye(4), np.diag([1.0, 0.0, 1.0, 1.0])])},
        "transforms row 2: must be invertible",
    ),
    "zero scale": (
        {"positions": np.zeros((2, 3)), "scales": np.array([1.0, 0.0])},
        "scales row 1 must be finite and > 0",
    ),
    "rotations shape": (
        {"positions": np.zeros((2, 3)), "rotations": np.zeros((3, 3))},
        "rotations must be (2, 3) degrees",
    ),
    "pickled": (None, "cannot read .npz"),
    "neither": ({"centers": np.zeros((2, 3))}, "unknown array 'centers'"),
    "both": ({"transforms": np.eye(4)[None], "positions": np.zeros((1, 3))}, "give either"),
    "empty": ({"transforms": np.zeros((0, 4, 4))}, "transforms: no placements"),
    "materials": (
        {"positions": np.zeros((2, 3)), "materials": np.array(["red", "plaid"])},
        "undefined material 'plaid'",
    ),
    "material ids": (
        {"positions": np.zeros((2, 3)), "materials": np.array([0, 99])},
        "materials: id out of range",
    ),
}


@pytest.mark.parametrize("name", list(BAD_PLACEMENTS))
def test_a_bad_placements_file_is_one_line_before_any_mesh_loads(name, tmp_path, monkeypatch):
    arrays, needle = BAD_PLACEMENTS[name]
    if arrays is None:  # np.savez pickles object arrays; the loader must refuse to unpickle
        arrays = _pickled()
    path = write_instances_scene(tmp_path, arrays)

    def no_mesh(*args, **kwargs):
        raise AssertionError("a mesh was loaded before the placements were checked")

    monkeypatch.setattr(meshes_module, "load_model", no_mesh)
    with pytest.raises(SceneError) as error:
        load_scene(path)
    message = str(error.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: instances[0].transforms: {tmp_path / 'placements.npz'}: ")
    assert needle in message


def test_the_command_reports_a_bad_placements_file_in_one_line(tmp_path: Path):
    path = write_instances_scene(
        tmp_path, {"transforms": np.stack([np.eye(4), np.diag([1.0, 1.0, 0.0, 1.0])])}
    )
    result = subprocess.run(
        [sys.executable, "-m", "embree_rt", "render", str(path), "-o", str(tmp_path / "out.png")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        f"embree-rt: error: {path}: instances[0].transforms: {tmp_path / 'placements.npz'}: "
        "transforms row 1: must be invertible: its linear part is singular in float32 (singular "
        "values 1 to 0, a ratio beyond 8.4e+06)"
    ]
    assert not (tmp_path / "out.png").exists()


def test_instances_render_as_the_same_meshes_placed_one_by_one(tmp_path: Path):
    positions, rotations, scales = scattered(16)
    transforms = placement_matrices(positions, rotations, scales)
    transforms[::4, :3, 0] *= -1  # mirrored copies too
    materials = np.array(["red", "metal", "glass", "matte"] * 4)
    instances = load_scene(
        write_instances_scene(tmp_path, {"transforms": transforms, "materials": materials})
    )
    lines = [SCENE_HEAD]
    for matrix, material in zip(transforms, materials, strict=True):
        lines.append(
            f'[[meshes]]\nfile = "{GEM}"\nmaterial = "{material}"\ntransform = {matrix.tolist()}\n'
        )
    (tmp_path / "meshes.toml").write_text("\n".join(lines))
    one_by_one = load_scene(tmp_path / "meshes.toml")
    with SceneGeometry(instances) as geometry:
        assert geometry.bvh.geometry_count == 1 and geometry.instance_count == 16
    image = render(instances).image
    reference = render(one_by_one).image
    covered = (
        np.abs(
            image
            - render(
                Scene(camera=instances.camera, lights=instances.lights, render=instances.render)
            ).image
        ).max(axis=2)
        > 0.05
    )
    assert covered.mean() > 0.1  # the copies fill a good part of the picture
    # The two paths trace the same float32 transforms through Embree; they differ only in how
    # the world normal is rounded (cofactors in float64 against an inverse kept in float32) and
    # in the coordinate bound that sizes secondary-ray offsets. That moves a pixel by far less
    # than an 8-bit step, except where a secondary ray grazes an edge and goes the other way
    # (measured on AVX2: at most 8.8e-6 anywhere, 89% of pixels bitwise equal).
    difference = np.abs(image - reference).max(axis=2)
    assert np.mean(difference > 1.0 / 512) < 0.002, np.sort(difference.ravel())[-10:]
    assert difference.mean() < 1e-4


# -- the command --------------------------------------------------------------------------------


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        capture_output=True,
        text=True,
        timeout=180,
        cwd=ROOT,
    )


def test_random_instance_replaces_small_spheres_and_renders_as_meshes_placed_one_by_one(
    tmp_path: Path,
):
    image_path, saved = tmp_path / "field.npy", tmp_path / "field.toml"
    result = run_cli(
        "random",
        "--count",
        "40",
        "--instance",
        str(GEM),
        "--seed",
        "3",
        "--width",
        "64",
        "--height",
        "40",
        "--spp",
        "2",
        "--max-depth",
        "3",
        "--save-scene",
        str(saved),
        "-o",
        str(image_path),
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    scene = load_scene(saved)
    field = random_field(40, seed=3)
    heroes = 3
    np.testing.assert_array_equal(scene.sphere_radii, field.sphere_radii[:heroes])
    (entry,) = scene.instances
    assert len(entry) == 40 - heroes
    np.testing.assert_array_equal(entry.materials, field.sphere_materials[heroes:])
    linear = entry.transforms[:, :3, :3]
    scale = linear[:, 1, 1]
    # only a turn about y and a uniform scale: rows (s cos, 0, s sin), (0, s, 0), (-s sin, 0, s cos)
    np.testing.assert_allclose(linear[:, 1], np.stack([0 * scale, scale, 0 * scale], 1), atol=1e-12)
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", linear, linear), scale[:, None, None] ** 2 * np.eye(3), atol=1e-12
    )
    assert len(np.unique(np.round(np.arctan2(linear[:, 0, 2], linear[:, 0, 0]), 6))) == 40 - heroes
    # scaled to fit the sphere's ball, then lowered onto the sphere's bottom: inside the
    # sphere's footprint and height, and touching its bottom
    world = np.einsum("nij,kj->nki", linear, entry.mesh.vertices) + entry.transforms[:, None, :3, 3]
    centers = field.sphere_centers[heroes:].astype(np.float64)
    radii = field.sphere_radii[heroes:].astype(np.float64)
    span = np.linalg.norm(world[:, :, None] - world[:, None, :], axis=3).max(axis=(1, 2))
    assert np.all(span <= 2 * radii * (1 + 1e-6))
    sideways = np.linalg.norm((world - centers[:, None])[:, :, [0, 2]], axis=2).max(axis=1)
    assert np.all(sideways <= radii * (1 + 1e-6))
    assert np.all(world[:, :, 1].max(axis=1) <= centers[:, 1] + radii)
    np.testing.assert_allclose(world[:, :, 1].min(axis=1), centers[:, 1] - radii, atol=1e-6)
    # the image equals the same placements as one [[meshes]] placement each
    one_by_one = load_scene(saved)
    one_by_one.instances = []
    names = one_by_one.material_names
    for matrix, material in zip(entry.transforms, entry.materials, strict=True):
        one_by_one.add_mesh(entry.mesh, names[material], matrix)
    reference = render(one_by_one, width=64, height=40, spp=2, max_depth=3).image
    image = np.load(image_path)
    difference = np.abs(image - reference).max(axis=2)
    assert np.mean(difference > 1.0 / 512) < 0.002 and difference.mean() < 1e-4


def test_info_reports_instances_meshes_triangles_and_memory(tmp_path: Path):
    positions, rotations, scales = scattered(9)
    path = write_instances_scene(
        tmp_path,
        {"positions": positions, "rotations": rotations, "scales": scales},
        'material = "red"',
    )
    result = run_cli("info", str(path))
    assert result.returncode == 0, result.stderr
    info = {
        k.strip(): v.strip() for k, v in (line.split(":", 1) for line in result.stdout.splitlines())
    }
    assert info["instances"] == "9"
    assert info["arrays"] == "1 instance array holding 9 instances"
    assert info["meshes"] == "9 placements of 1 distinct mesh"
    assert info["triangles"] == "20 stored, 180 placed"
    assert "MiB (estimate)" in info["memory"] and "MiB measured" in info["memory"]


def test_a_bad_instance_mesh_is_one_line_and_writes_nothing(tmp_path: Path):
    missing = tmp_path / "nothing.ply"
    result = run_cli(
        "random", "--count", "10", "--instance", str(missing), "-o", str(tmp_path / "out.png")
    )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [f"embree-rt: error: --instance: {missing}: no such file"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("asset", ["quadrant_cube.glb", "trio.glb"])
def test_a_meshs_own_look_and_nodes_carry_over_to_its_instances(asset: str, tmp_path: Path):
    """No material: each copy looks as the file says (quadrant_cube.glb: a texture), and a
    multi-node glTF (trio.glb) is one mesh, its nodes baked: the same picture as the file placed
    by one [[meshes]] entry per copy."""
    path = ROOT / "assets" / asset
    positions, rotations, _ = scattered(9, seed=8)
    transforms = placement_matrices(positions, rotations, np.full(9, 0.6))
    instances = load_scene(write_instances_scene(tmp_path, {"transforms": transforms}, mesh=path))
    lines = [SCENE_HEAD] + [
        f'[[meshes]]\nfile = "{path}"\ntransform = {m.tolist()}\n' for m in transforms
    ]
    (tmp_path / "meshes.toml").write_text("\n".join(lines))
    one_by_one = load_scene(tmp_path / "meshes.toml")
    (entry,) = instances.instances
    nodes = len(one_by_one.meshes) // 9  # placements per copy: one per node
    assert len(entry.mesh.faces) == sum(len(m.mesh.faces) for m in one_by_one.meshes[:nodes])
    assert entry.mesh_colors
    image, reference = render(instances).image, render(one_by_one).image
    bare = Scene(camera=instances.camera, lights=instances.lights, render=instances.render)
    empty = render(bare).image
    assert (np.abs(image - empty).max(axis=2) > 0.05).mean() > 0.05
    difference = np.abs(image - reference).max(axis=2)
    assert np.mean(difference > 1.0 / 512) < 0.002 and difference.mean() < 1e-4
