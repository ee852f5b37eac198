"""Mesh import through scene files: every format keeps its triangles, placements compose as
translate · rotate · scale, glTF node transforms survive, a file used twice is one BVH child.

References are independent of the loader: placements are composed here from closed-form rotation
matrices, hit distances come from trimesh's pure-NumPy ray–triangle test on the mesh baked into
world space, and glTF node transforms are the matrices this file built the glTF from.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from tolerances import (
    RTOL32,
    assert_close,
    assert_vectors_close,
    coordinate_scale,
    position_atol,
    ray_t_atol,
)
from trimesh.ray.ray_triangle import ray_triangle_id

from embree_rt import Scene, SceneError, load_scene
from embree_rt.embree import BVH
from embree_rt.geometry import SceneGeometry

FORMATS = ("obj", "ply", "stl", "off", "glb")


# -- independent references ----------------------------------------------------------------------


def rotation_xyz(degrees: tuple[float, float, float]) -> np.ndarray:
    """(3, 3) float64 rotation for ``rotate = [ax, ay, az]``: about X first, then Y, then Z."""
    ax, ay, az = (math.radians(a) for a in degrees)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def placement(translate, rotate, scale) -> np.ndarray:
    """(4, 4) float64 T · R · S."""
    t = np.eye(4)
    t[:3, 3] = translate
    r = np.eye(4)
    r[:3, :3] = rotation_xyz(rotate)
    s = np.diag([*np.broadcast_to(np.asarray(scale, float), (3,)), 1.0])
    return t @ r @ s


def translation(offset) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, 3] = offset
    return matrix


def baked(mesh: trimesh.Trimesh, transform: np.ndarray) -> trimesh.Trimesh:
    """A copy of ``mesh`` with ``transform`` applied to its vertices (world space)."""
    world = mesh.copy()
    world.apply_transform(transform)
    return world


class _AllBoxes:
    """The broad phase trimesh's ray test asks an rtree for, by brute force over triangle boxes
    (rtree is not installed; this keeps the reference pure NumPy)."""

    def __init__(self, triangles: np.ndarray) -> None:
        self.lower = triangles.min(axis=1)
        self.upper = triangles.max(axis=1)
        self.bounds = np.r_[self.lower.min(axis=0), self.upper.max(axis=0)]

    def intersection(self, box: np.ndarray) -> np.ndarray:
        overlap = (self.lower <= box[3:]).all(axis=1) & (self.upper >= box[:3]).all(axis=1)
        return np.flatnonzero(overlap)


def trimesh_first_hits(world: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray):
    """Nearest hit per ray by trimesh's NumPy ray–triangle test: (n,) float64 t (inf on a miss)
    and (n,) int64 triangle index (-1 on a miss); ``directions`` are unit vectors."""
    triangles = np.asarray(world.triangles, np.float64)
    tri, ray, location = ray_triangle_id(
        triangles, origins, directions, tree=_AllBoxes(triangles), multiple_hits=True
    )
    t = np.full(len(origins), np.inf)
    face = np.full(len(origins), -1, np.int64)
    if len(tri):
        distance = np.einsum("ij,ij->i", location - origins[ray], directions[ray])
        order = np.lexsort((distance, ray))  # per ray, nearest first
        first = order[np.r_[True, ray[order][1:] != ray[order][:-1]]]
        t[ray[first]] = distance[first]
        face[ray[first]] = tri[first]
    return t, face


def rays_at_faces(world: trimesh.Trimesh, rng: np.random.Generator, count: int):
    """``count`` rays from outside the mesh, each aimed at an interior point of a random face (so
    it must hit), then ``count`` rays pointing away from the mesh (so they must miss)."""
    center = world.bounds.mean(axis=0)
    reach = 4.0 * np.linalg.norm(world.extents)
    faces = rng.integers(0, len(world.faces), count)
    weights = rng.uniform(0.15, 1.0, (count, 3))
    weights /= weights.sum(axis=1, keepdims=True)
    targets = np.einsum("nk,nkj->nj", weights, world.triangles[faces])
    away = rng.normal(size=(count, 3))
    away /= np.linalg.norm(away, axis=1, keepdims=True)
    origins = center + reach * away
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.concatenate([origins, origins])
    directions = np.concatenate([directions, away])
    # round once, so Embree and the reference trace the very same float32 rays
    return origins.astype(np.float32), directions.astype(np.float32)


def same_triangles(loaded: trimesh.Trimesh, original: trimesh.Trimesh, tolerance: float) -> None:
    """Same surface whatever the vertex order, merging or face order: sorted face centroids,
    area, volume and bounds agree (STL stores three vertices per face, OBJ may renumber)."""
    assert len(loaded.faces) == len(original.faces)

    def sorted_centroids(mesh):
        centroids = np.asarray(mesh.triangles_center, np.float64)
        return centroids[np.lexsort(np.round(centroids, 5).T[::-1])]

    np.testing.assert_allclose(sorted_centroids(loaded), sorted_centroids(original), atol=tolerance)
    np.testing.assert_allclose(loaded.bounds, original.bounds, atol=tolerance)
    assert loaded.area == pytest.approx(original.area, rel=1e-6)
    assert loaded.volume == pytest.approx(original.volume, rel=1e-6)


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def ellipsoid() -> trimesh.Trimesh:
    """An off-centre, anisotropic icosphere: rotation, scale and translation all show."""
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    mesh.apply_scale([1.0, 0.6, 0.8])
    mesh.apply_translation([0.3, -0.1, 0.2])
    return mesh


# -- tests ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_keeps_the_triangles_and_the_placement(fmt: str, tmp_path: Path) -> None:
    original = ellipsoid()
    original.export(tmp_path / f"shape.{fmt}")
    translate, rotate, scale = (1.5, 2.0, -3.0), (30.0, -45.0, 60.0), (1.5, 0.5, 2.0)
    write(
        tmp_path / "scene.toml",
        f"""
floor = false
[[meshes]]
file = "shape.{fmt}"
material = "mirror"
smooth = false
translate = {list(translate)}
rotate = {list(rotate)}
scale = {list(scale)}
""",
    )
    scene = load_scene(tmp_path / "scene.toml")
    assert scene.floor is None
    (placed,) = scene.meshes
    assert placed.material == "mirror" and placed.smooth is False
    same_triangles(placed.mesh, original, tolerance=1e-6)
    expected = placement(translate, rotate, scale)
    np.testing.assert_allclose(placed.transform, expected, atol=1e-12)

    world = baked(original, expected)
    origins, directions = rays_at_faces(world, np.random.default_rng(7), 200)
    reference_t, reference_face = trimesh_first_hits(
        world, origins.astype(np.float64), directions.astype(np.float64)
    )
    aimed = np.arange(len(origins)) < 200
    assert np.isfinite(reference_t[aimed]).all() and np.isinf(reference_t[~aimed]).all()
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(origins.T, directions.T)
    np.testing.assert_array_equal(hits.hit, np.isfinite(reference_t))
    # float32 against float64: t to rounding of the coordinates over the cosine of incidence
    outward = world.face_normals[reference_face[aimed]]
    t_atol = ray_t_atol(
        origins[aimed], directions[aimed], coordinate_scale(world.vertices), normals=outward
    )
    assert_close(hits.t[aimed], reference_t[aimed], atol=t_atol, rtol=RTOL32)
    expected_position = origins[aimed] + directions[aimed] * reference_t[aimed, None]
    assert_vectors_close(
        hits.position.T[aimed], expected_position, atol=t_atol + position_atol(origins)
    )
    assert (hits.material[aimed] == scene.material_index("mirror")).all()
    # flat shading: the normal is the world face normal of the face the reference hit (a ray
    # on a shared edge may report the neighbour, whose normal is still within a few degrees)
    cosine = np.einsum("ij,ij->i", hits.normal.T[aimed], outward)
    assert (cosine > 0.9).all()
    assert np.mean(cosine > 1 - 1e-5) > 0.95


def test_rotation_order_is_x_then_y_then_z(tmp_path: Path) -> None:
    """Closed form: rotating the point (1, 0, 0) by 90 degrees about X leaves it, then about Y
    sends it to (0, 0, -1), then about Z leaves it; Z first would give (0, 0, 1)."""
    trimesh.Trimesh(
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [[0, 1, 2]], process=False
    ).export(tmp_path / "tri.ply")
    write(
        tmp_path / "scene.toml",
        '[[meshes]]\nfile = "tri.ply"\nrotate = [90.0, 90.0, 90.0]\ntranslate = [0, 5, 0]\n',
    )
    (placed,) = load_scene(tmp_path / "scene.toml").meshes
    corners = trimesh.transform_points(placed.mesh.vertices, placed.transform)
    # x axis: Rx keeps it, Ry(90) -> -z, Rz keeps -z.  y axis: Rx(90) -> z, Ry(90) -> x,
    # Rz(90) -> y.  z axis: Rx(90) -> -y, Ry keeps it, Rz(90) -> x.
    np.testing.assert_allclose(corners, [[0, 5, -1], [0, 6, 0], [1, 5, 0]], atol=1e-12)


def test_scalar_scale_and_explicit_transform(tmp_path: Path) -> None:
    ellipsoid().export(tmp_path / "shape.off")
    matrix = [[0.0, -2.0, 0.0, 1.0], [2.0, 0.0, 0.0, 2.0], [0.0, 0.0, 2.0, 3.0], [0, 0, 0, 1]]
    write(
        tmp_path / "scene.toml",
        f"""
[[meshes]]
file = "shape.off"
scale = 2.5
translate = [0, 1, 0]
[[meshes]]
file = "shape.off"
transform = {matrix}
""",
    )
    uniform, explicit = load_scene(tmp_path / "scene.toml").meshes
    np.testing.assert_allclose(uniform.transform, placement((0, 1, 0), (0, 0, 0), 2.5))
    np.testing.assert_array_equal(explicit.transform, np.array(matrix))


def multi_node_gltf(path: Path) -> dict[str, tuple[trimesh.Trimesh, np.ndarray]]:
    """Write a glTF of three nodes — a box, a ball, and a child node of the box that reuses the
    ball mesh — and return node name → (mesh, world transform) as built here."""
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    box_world = translation([1.0, 0.0, 0.0])
    ball_world = translation([0.0, 2.0, 0.0]) @ placement((0, 0, 0), (0, 0, 90), 1.0)
    child_local = translation([0.0, 0.0, 3.0]) @ np.diag([2.0, 2.0, 2.0, 1.0])
    gltf = trimesh.Scene()
    gltf.add_geometry(box, node_name="box", geom_name="box", transform=box_world)
    gltf.add_geometry(ball, node_name="ball", geom_name="ball", transform=ball_world)
    gltf.graph.update(frame_to="child", frame_from="box", geometry="ball", matrix=child_local)
    gltf.export(path)
    return {
        "box": (box, box_world),
        "ball": (ball, ball_world),
        "child": (ball, box_world @ child_local),
    }


def test_gltf_nodes_keep_their_transforms(tmp_path: Path) -> None:
    nodes = multi_node_gltf(tmp_path / "multi.glb")
    write(
        tmp_path / "scene.toml",
        '[[meshes]]\nfile = "multi.glb"\ntranslate = [10.0, 0.0, -5.0]\nrotate = [0, 30, 0]\n',
    )
    scene = load_scene(tmp_path / "scene.toml")
    assert len(scene.meshes) == 3
    outer = placement((10.0, 0.0, -5.0), (0, 30, 0), 1.0)
    unmatched = list(scene.meshes)
    for name, (mesh, node_world) in nodes.items():
        expected = outer @ node_world
        matches = [
            m
            for m in unmatched
            if len(m.mesh.faces) == len(mesh.faces) and np.allclose(m.transform, expected)
        ]
        assert len(matches) == 1, f"node {name}: no mesh placed at outer @ node transform"
        unmatched.remove(matches[0])
        same_triangles(matches[0].mesh, mesh, tolerance=1e-6)
        world_vertices = trimesh.transform_points(matches[0].mesh.vertices, matches[0].transform)
        np.testing.assert_allclose(
            [world_vertices.min(axis=0), world_vertices.max(axis=0)],
            baked(mesh, expected).bounds,
            atol=1e-5,
        )
    # the node that reuses the ball mesh shares the loaded mesh object: one BVH child for both
    balls = [m for m in scene.meshes if len(m.mesh.faces) == len(nodes["ball"][0].faces)]
    assert balls[0].mesh is balls[1].mesh
    with SceneGeometry(scene) as geometry:
        assert geometry.instance_count == 3
        assert len(geometry.mesh_face_offset) == 2


def test_a_file_used_twice_is_loaded_once_and_instanced(tmp_path: Path) -> None:
    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(tmp_path / "box.ply")
    write(
        tmp_path / "scene.toml",
        """
floor = false
[[meshes]]
file = "box.ply"
smooth = false
translate = [-3.0, 1.0, 0.0]
[[meshes]]
file = "./box.ply"
smooth = false
translate = [3.0, 1.0, 0.0]
rotate = [0.0, 45.0, 0.0]
scale = 2.0
""",
    )
    scene = load_scene(tmp_path / "scene.toml")
    first, second = scene.meshes
    assert first.mesh is second.mesh

    # Rays straight down from y = 10. The first box is a unit cube centred at (-3, 1, 0), top at
    # y = 1.5; the second, scaled 2 and turned 45 degrees about y, has its top at y = 2 over the
    # diamond |x - 3| + |z| <= sqrt(2).
    columns = np.array(
        [
            [-3.1, 0.2, 1.5],  # inside the first cube's top
            [-2.4, 0.0, np.inf],  # just beside it
            [3.1, 0.2, 2.0],  # centre of the turned box
            [3.0 + 1.3, 0.0, 2.0],  # in the diamond, outside the unturned square
            [3.0 + 0.9, 0.9, np.inf],  # in the unturned square, outside the diamond
            [0.0, 0.0, np.inf],  # between the two
        ]
    )
    origins = np.column_stack([columns[:, 0], np.full(len(columns), 10.0), columns[:, 1]])
    directions = np.tile([0.0, -1.0, 0.0], (len(columns), 1))
    with SceneGeometry(scene) as geometry:
        assert geometry.instance_count == 2
        assert len(geometry.mesh_face_offset) == 1  # one BVH child
        assert geometry.triangle_count == 2 * len(first.mesh.faces)
        hits = geometry.intersect(origins.T.astype(np.float32), directions.T.astype(np.float32))
    expected_t = 10.0 - columns[:, 2]
    np.testing.assert_array_equal(hits.hit, np.isfinite(expected_t))
    hit = hits.hit
    assert_close(hits.t[hit], expected_t[hit], atol=ray_t_atol(origins[hit], directions[hit], 10.0))
    np.testing.assert_allclose(
        hits.normal.T[hits.hit], [[0, 1, 0]] * int(hits.hit.sum()), atol=1e-5
    )


# -- tiny and singular scales ----------------------------------------------------------------------


def node_scaled_gltf(path: Path, node_scale) -> None:
    """A glTF holding one box 100 units on a side under a node that scales it by
    ``node_scale`` (a number or three), as many exporters write centimetre models."""
    gltf = trimesh.Scene()
    node = np.diag([*np.broadcast_to(np.asarray(node_scale, float), (3,)), 1.0])
    gltf.add_geometry(trimesh.creation.box(extents=(100.0, 100.0, 100.0)), transform=node)
    gltf.export(path)


@pytest.mark.parametrize("scale", [0.01, 1e-4])
def test_a_tiny_uniform_scale_on_a_node_scaled_gltf_loads_and_traces(
    tmp_path: Path, scale: float
) -> None:
    node_scaled_gltf(tmp_path / "centimetres.glb", 0.01)
    write(
        tmp_path / "scene.toml",
        f'floor = false\n[[meshes]]\nfile = "centimetres.glb"\nscale = {scale}\n',
    )
    scene = load_scene(tmp_path / "scene.toml")
    (placed,) = scene.meshes
    np.testing.assert_allclose(placed.transform, np.diag([0.01 * scale] * 3 + [1.0]), rtol=1e-12)
    # The box is 100 · 0.01 · scale wide: a ray down the z axis from 1 unit away meets its
    # front face at half that.
    half = 50.0 * 0.01 * scale
    # (3, 2) origins: on the axis, and beside the box
    origins = np.array([[0.0, 0.0, 1.0], [2 * half, 0.0, 1.0]], np.float32).T
    directions = np.tile(np.float32([[0.0], [0.0], [-1.0]]), (1, 2))
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(origins, directions)
    assert hits.hit.tolist() == [True, False]
    assert_close(hits.t[:1], [1.0 - half], atol=position_atol(1.0))


@pytest.mark.parametrize(
    "entry, node_scale, key",
    [
        ("scale = [1.0, 1.0, 1e-9]", 1.0, "meshes[0].scale"),
        (
            "transform = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1e-9, 0], [0, 0, 0, 1]]",
            1.0,
            "meshes[0].transform",
        ),
        # each flattens by 1e-4, well conditioned on its own; together by 1e-8
        ("scale = [1.0, 1.0, 1e-4]", [1.0, 1.0, 1e-4], "meshes[0].scale"),
        ("scale = 2.0", [1.0, 1.0, 1e-9], "meshes[0].file"),  # the file's own node
    ],
    ids=["scale", "transform", "scale with the node", "node"],
)
def test_a_singular_placement_names_the_key_that_makes_it(
    tmp_path: Path, entry: str, node_scale, key: str
) -> None:
    node_scaled_gltf(tmp_path / "box.glb", node_scale)
    write(tmp_path / "scene.toml", f'[[meshes]]\nfile = "box.glb"\n{entry}\n')
    with pytest.raises(SceneError) as caught:
        load_scene(tmp_path / "scene.toml")
    assert str(caught.value).startswith(f"{tmp_path / 'scene.toml'}: {key}: ")
    assert "must be invertible" in str(caught.value)


PLACEMENTS = {  # scene-file entry -> the placement it asks for
    "scale = 1e-4": np.diag([1e-4, 1e-4, 1e-4, 1.0]),
    "scale = [1.0, 1.0, 1e-5]": np.diag([1.0, 1.0, 1e-5, 1.0]),
    "scale = [1.0, 1.0, 1e-7]": np.diag([1.0, 1.0, 1e-7, 1.0]),
    "scale = [1.0, 1.0, 1e-13]": np.diag([1.0, 1.0, 1e-13, 1.0]),
    "scale = [1e3, 1e-3, 1.0]": np.diag([1e3, 1e-3, 1.0, 1.0]),
    "transform = [[1e-5, 0, 0, 0], [0, 1e-5, 0, 0], [0, 0, 1e-5, 0], [0, 0, 0, 1]]": np.diag(
        [1e-5, 1e-5, 1e-5, 1.0]
    ),
    "transform = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1e-7, 0], [0, 0, 0, 1]]": np.diag(
        [1.0, 1.0, 1e-7, 1.0]
    ),
}


@pytest.mark.parametrize("entry", sorted(PLACEMENTS))
def test_a_placement_that_loads_also_builds(tmp_path: Path, entry: str) -> None:
    """One rule for placements: the loader refuses exactly what the BVH would refuse."""
    node_scaled_gltf(tmp_path / "box.glb", 0.01)
    write(tmp_path / "scene.toml", f'[[meshes]]\nfile = "box.glb"\n{entry}\n')
    world = PLACEMENTS[entry] @ np.diag([0.01, 0.01, 0.01, 1.0])
    child = BVH()
    child.add_triangles(trimesh.creation.box().vertices, trimesh.creation.box().faces)
    child.commit()
    with child, BVH() as top:
        try:
            top.add_instance(child, world)
        except ValueError as refused:
            assert "must be invertible" in str(refused)
            with pytest.raises(SceneError, match="must be invertible"):
                load_scene(tmp_path / "scene.toml")
            return
    scene = load_scene(tmp_path / "scene.toml")
    np.testing.assert_allclose(scene.meshes[0].transform, world, rtol=1e-12)
    with SceneGeometry(scene) as geometry:
        assert geometry.instance_count == 1


# -- the Python API ------------------------------------------------------------------------------


def test_add_mesh_takes_a_trimesh_scene_as_the_loader_does(tmp_path: Path) -> None:
    """``Scene.add_mesh(trimesh.load("x.glb"))``: one placement per node, at the caller's
    transform after the node's, exactly as a ``[[meshes]]`` entry of the same file."""
    multi_node_gltf(tmp_path / "multi.glb")
    write(
        tmp_path / "scene.toml",
        '[[meshes]]\nfile = "multi.glb"\ntranslate = [10.0, 0.0, -5.0]\nrotate = [0, 30, 0]\n',
    )
    from_file = load_scene(tmp_path / "scene.toml")
    loaded = trimesh.load(tmp_path / "multi.glb", process=False)
    assert isinstance(loaded, trimesh.Scene)
    built = Scene()
    placed = built.add_mesh(loaded, transform=placement((10.0, 0.0, -5.0), (0, 30, 0), 1.0))
    assert placed == built.meshes and len(placed) == 3
    for ours, theirs in zip(built.meshes, from_file.meshes, strict=True):
        np.testing.assert_allclose(ours.transform, theirs.transform, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(ours.mesh.faces, theirs.mesh.faces)
        np.testing.assert_array_equal(ours.mesh.vertices, theirs.mesh.vertices)
        assert ours.material == theirs.material and ours.smooth == theirs.smooth
    balls = [m.mesh for m in built.meshes if len(m.mesh.faces) != 12]  # the box has 12
    assert len(balls) == 2 and balls[0] is balls[1]  # the reused ball: one BVH child
    with SceneGeometry(built) as geometry:
        assert geometry.instance_count == 3
        assert len(geometry.mesh_face_offset) == 2


@pytest.mark.parametrize(
    "arguments, error, argument",
    [
        (("box.glb",), TypeError, "mesh"),
        ((trimesh.creation.box().vertices,), TypeError, "mesh"),
        ((trimesh.creation.box(), 3), TypeError, "material"),
        ((trimesh.creation.box(), "gold"), ValueError, "undefined material 'gold'"),
        ((trimesh.creation.box(), None, np.eye(3)), ValueError, "transform"),
        ((trimesh.creation.box(), None, np.diag([1.0, 1.0, 0.0, 1.0])), ValueError, "transform"),
        ((trimesh.creation.box(), None, None, "yes"), TypeError, "smooth"),
        ((trimesh.Scene(),), ValueError, "mesh"),
    ],
    ids=["a path", "an array", "material 3", "unknown material", "3x3", "flat", "smooth", "empty"],
)
def test_add_mesh_rejects_what_it_cannot_place_before_adding_anything(
    arguments, error: type, argument: str
) -> None:
    scene = Scene()
    with pytest.raises(error, match=argument):
        scene.add_mesh(*arguments)
    assert scene.meshes == [] and set(scene.materials) == set(Scene().materials)
