"""Scene files: parse to the scene built in Python, save/load round trips, mesh formats."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from bvh_reference import triangle_hits

from embree_rt import Camera, Material, PointLight, Scene, load_scene, preset, random_field
from embree_rt.shapes import SceneGeometry


def test_scene_file_parses_to_the_scene_built_in_python(tmp_path: Path) -> None:
    np.savez(
        tmp_path / "bulk.npz",
        centers=np.array([[1, 0.5, 2], [3, 0.25, -1]], float),
        radii=np.array([0.5, 0.25]),
        materials=np.array(["gold", "glass"]),
    )
    (tmp_path / "scene.toml").write_text(
        """
[render]
width = 64
height = 32
spp = 2
seed = 9
[camera]
position = [0, 2, 9]
look_at = [0, 1, 0]
fov = 35
[[lights]]
position = [1, 8, 2]
intensity = 0.7
[materials.gold]
preset = "metal"
color = [1.0, 0.8, 0.3]
[[spheres]]
center = [0, 1, 0]
radius = 1
material = "gold"
[[sphere_arrays]]
file = "bulk.npz"
"""
    )
    loaded = load_scene(tmp_path / "scene.toml")
    built = Scene(camera=Camera(position=(0, 2, 9), look_at=(0, 1, 0), fov=35))
    built.render.width, built.render.height, built.render.spp, built.render.seed = 64, 32, 2, 9
    built.lights.append(PointLight(position=(1, 8, 2), intensity=0.7))
    built.add_material("gold", preset("metal", color=(1.0, 0.8, 0.3)))
    built.add_sphere((0, 1, 0), 1.0, "gold")
    built.add_spheres([[1, 0.5, 2], [3, 0.25, -1]], [0.5, 0.25], np.array(["gold", "glass"]))
    assert loaded.render == built.render
    assert loaded.camera == Camera(position=(0, 2, 9), look_at=(0, 1, 0), up=(0, 1, 0), fov=35)
    assert loaded.lights == built.lights
    assert loaded.materials == built.materials
    assert loaded.floor == built.floor
    np.testing.assert_array_equal(loaded.sphere_centers, built.sphere_centers)
    np.testing.assert_array_equal(loaded.sphere_radii, built.sphere_radii)
    np.testing.assert_array_equal(loaded.sphere_materials, built.sphere_materials)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_save_then_load_gives_the_same_scene(tmp_path: Path, suffix: str) -> None:
    scene = random_field(200, seed=3)
    scene.add_material("odd", Material(color=(0.1, 0.2, 0.3), specular=0.4, metallic=True))
    scene.add_mesh(trimesh.creation.box(), "odd", transform=np.diag([1.0, 2.0, 3.0, 1.0]))
    path = tmp_path / f"saved{suffix}"
    scene.save(path)
    again = load_scene(path)
    assert again.camera == scene.camera and again.lights == scene.lights
    assert again.render == scene.render and again.floor == scene.floor
    names, again_names = np.array(scene.material_names), np.array(again.material_names)
    np.testing.assert_array_equal(
        names[scene.sphere_materials], again_names[again.sphere_materials]
    )
    np.testing.assert_allclose(again.sphere_centers, scene.sphere_centers)
    np.testing.assert_allclose(again.sphere_radii, scene.sphere_radii)
    assert again.materials["odd"] == scene.materials["odd"]
    assert len(again.meshes) == 1
    np.testing.assert_allclose(again.meshes[0].transform, scene.meshes[0].transform)
    np.testing.assert_allclose(again.meshes[0].mesh.bounds, scene.meshes[0].mesh.bounds)


def _expected_placement(translate, rotate_degrees, scale) -> np.ndarray:
    ax, ay, az = (math.radians(a) for a in rotate_degrees)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    matrix = np.eye(4)
    matrix[:3, :3] = rz @ ry @ rx @ np.diag(scale)
    matrix[:3, 3] = translate
    return matrix


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".off", ".glb"])
def test_each_mesh_format_round_trips_to_the_same_hits(tmp_path: Path, suffix: str) -> None:
    original = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    original.export(tmp_path / f"ball{suffix}")
    (tmp_path / "scene.toml").write_text(
        f"""
floor = false
[[meshes]]
file = "ball{suffix}"
translate = [0.5, 1.0, -0.25]
rotate = [10.0, 20.0, 30.0]
scale = [1.0, 1.5, 0.75]
smooth = false
"""
    )
    scene = load_scene(tmp_path / "scene.toml")
    (placement,) = scene.meshes
    expected = _expected_placement((0.5, 1.0, -0.25), (10, 20, 30), (1.0, 1.5, 0.75))
    np.testing.assert_allclose(placement.transform, expected, atol=1e-12)

    world = original.copy()
    world.apply_transform(expected)
    rng = np.random.default_rng(0)
    targets = world.sample(300, seed=1)
    origins = rng.normal(size=(len(targets), 3)) * 0.3 + [0.5, 1.0, 6.0]
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    with SceneGeometry(scene) as geometry:
        ours = geometry.intersect(origins.astype(np.float32), directions.astype(np.float32))
    # trimesh's pure-NumPy ray-triangle test on the mesh baked into world space.
    reference_t = triangle_hits(origins, directions, world.vertices, world.faces).t
    both = np.isfinite(reference_t)
    assert both.mean() > 0.9
    assert (ours.hit == both).mean() > 0.99  # a ray exactly on an edge may go either way
    agree = both & ours.hit
    np.testing.assert_allclose(ours.t[agree], reference_t[agree], rtol=1e-4, atol=1e-5)


def test_a_mesh_file_used_twice_is_loaded_once_and_placed_twice(tmp_path: Path) -> None:
    trimesh.creation.box(extents=(1, 1, 1)).export(tmp_path / "box.ply")
    (tmp_path / "scene.toml").write_text(
        """
floor = false
[[meshes]]
file = "box.ply"
translate = [-3, 0, 0]
[[meshes]]
file = "box.ply"
translate = [3, 0, 0]
scale = 2
"""
    )
    scene = load_scene(tmp_path / "scene.toml")
    first, second = scene.meshes
    assert first.mesh is second.mesh
    with SceneGeometry(scene) as geometry:
        assert geometry.instance_count == 2
        origins = np.array([[-3, 0, 10], [3, 0, 10], [0, 0, 10]], np.float32)
        down = np.tile(np.array([0, 0, -1], np.float32), (3, 1))
        hits = geometry.intersect(origins, down)
    # Faces of the unit box at z = +0.5 (copy at x = -3) and z = +1 (copy scaled 2 at x = 3).
    np.testing.assert_allclose(hits.t, [9.5, 9.0, np.inf], rtol=1e-6)


def test_multi_node_gltf_keeps_node_transforms(tmp_path: Path) -> None:
    gltf = trimesh.Scene()
    for x in (-2.0, 2.0):
        gltf.add_geometry(
            trimesh.creation.box(extents=(1, 1, 1)),
            transform=trimesh.transformations.translation_matrix([x, 0, 0]),
        )
    gltf.export(tmp_path / "pair.glb")
    (tmp_path / "scene.toml").write_text(
        'floor = false\n[[meshes]]\nfile = "pair.glb"\ntranslate = [0, 5, 0]\n'
    )
    scene = load_scene(tmp_path / "scene.toml")
    centers = sorted(tuple(np.round(m.transform[:3, 3], 6)) for m in scene.meshes)
    assert centers == [(-2.0, 5.0, 0.0), (2.0, 5.0, 0.0)]
