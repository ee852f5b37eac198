"""Mesh files as other programs write them render as the files say, or say in one line why not.

Every file here is made by the test: glTF JSON and binary chunks written by hand (a Draco blob
from DracoPy's encoder, sparse accessors, EXT_mesh_gpu_instancing, required extensions, missing
buffers and images), PLY triangle strips, OBJs with texture coordinates and no material, MTLs
with Windows paths. Geometry is checked against an independent reference: the triangles as the
file defines them (decoded here from the arrays the test wrote, by the rules of the format, in
float64), traced per pixel by trimesh's pure-NumPy ray–triangle test; coverage must match on
every pixel whose answer float32 rounding cannot change, and depth to the rounding of the
coordinates over the cosine of incidence (``tolerances``).
"""

from __future__ import annotations

import importlib.util
import json
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh
from bvh_reference import triangle_hits
from camera_samples import primary_rays
from PIL import Image
from scipy.spatial.transform import Rotation
from tolerances import RTOL32, assert_close

from embree_rt import Scene, SceneError, load_scene
from embree_rt.camera import camera_frame
from embree_rt.geometry import SceneGeometry
from embree_rt.scene.errors import InputWarning
from embree_rt.scene.meshes import load_model, mesh_material, mesh_surface
from embree_rt.textures import texels_from_image

WIDTH, HEIGHT = 64, 48


# -- writing files by hand -----------------------------------------------------------------------

_COMPONENT = {
    np.dtype(t): code
    for t, code in [
        (np.float32, 5126),
        (np.uint32, 5125),
        (np.uint16, 5123),
        (np.int16, 5122),
        (np.uint8, 5121),
        (np.int8, 5120),
    ]
}
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


class Gltf:
    """A glTF 2.0 document and its one binary buffer, built field by field."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.tree: dict = {
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "accessors": [],
            "bufferViews": [],
        }

    def view(self, data: bytes) -> int:
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.tree["bufferViews"].append(
            {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        )
        self.blob += data
        return len(self.tree["bufferViews"]) - 1

    def accessor(
        self,
        values: np.ndarray | None,
        count: int | None = None,
        dtype=np.float32,
        width: int | None = None,
        **fields,
    ) -> int:
        """An accessor of ``values`` ((n,) or (n, k)) in a view of their own; None: no view."""
        accessor: dict = dict(fields)
        if values is not None:
            values = np.ascontiguousarray(values, dtype)
            count, width = len(values), (1 if values.ndim == 1 else values.shape[1])
            accessor["bufferView"] = self.view(
                values.astype(values.dtype.newbyteorder("<")).tobytes()
            )
        accessor.update(componentType=_COMPONENT[np.dtype(dtype)], count=count, type=_TYPE[width])
        self.tree["accessors"].append(accessor)
        return len(self.tree["accessors"]) - 1

    def mesh(self, primitive: dict) -> int:
        self.tree["meshes"].append({"primitives": [primitive]})
        return len(self.tree["meshes"]) - 1

    def triangles(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        """A mesh of one indexed triangle primitive."""
        position = self.accessor(
            vertices, min=vertices.min(axis=0).tolist(), max=vertices.max(axis=0).tolist()
        )
        indices = self.accessor(np.asarray(faces).ravel(), dtype=np.uint32)
        return self.mesh({"attributes": {"POSITION": position}, "indices": indices})

    def node(self, root: bool = True, **fields) -> int:
        self.tree["nodes"].append(fields)
        index = len(self.tree["nodes"]) - 1
        if root:
            self.tree["scenes"][0]["nodes"].append(index)
        return index

    def write_glb(self, path: Path) -> Path:
        tree = {**self.tree, "buffers": [{"byteLength": len(self.blob)}]}
        text = json.dumps(tree).encode()
        text += b" " * (-len(text) % 4)
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text
        body += struct.pack("<II", len(blob), 0x004E4942) + blob
        path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
        return path

    def write_gltf(self, path: Path, buffer_name: str = "data.bin") -> Path:
        """A .gltf with its buffer in an external file ``buffer_name`` (not written when the
        name is None-like: a test of a missing buffer leaves it out)."""
        tree = {**self.tree, "buffers": [{"byteLength": len(self.blob), "uri": buffer_name}]}
        path.write_text(json.dumps(tree))
        return path


def scene_file(
    tmp_path: Path, mesh: str, camera: tuple[np.ndarray, np.ndarray] | None = None, extra: str = ""
) -> Path:
    """A scene file placing ``mesh`` as it is, with no floor, seen from ``camera``
    (position, look_at)."""
    lines = ["floor = false", f"[render]\nwidth = {WIDTH}\nheight = {HEIGHT}"]
    if camera is not None:
        position, look_at = camera
        lines.append(
            f"[camera]\nposition = {np.round(position, 6).tolist()}\n"
            f"look_at = {np.round(look_at, 6).tolist()}\nfov = 40.0"
        )
    lines.append(f'[[meshes]]\nfile = "{mesh}"\n{extra}')
    path = tmp_path / "scene.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def camera_on(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A camera position and target that show all of ``vertices`` (n, 3), from the front,
    a little above and to the side."""
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    center, radius = (low + high) / 2, np.linalg.norm(high - low) / 2
    return center + radius * np.array([0.8, 1.1, 2.6]), center


def assert_pixels_match(scene, vertices: np.ndarray, faces: np.ndarray) -> int:
    """Per pixel (one ray through each): the scene's geometry hits exactly where trimesh's
    NumPy ray–triangle test on (vertices, faces) does, at the same depth. Returns how many
    pixels the mesh covers."""
    frame = camera_frame(scene.camera, WIDTH, HEIGHT)
    origins, directions, _ = primary_rays(frame, 1, 0, 0, WIDTH * HEIGHT)
    reference = triangle_hits(origins.T, directions.T, vertices, faces)
    scene.floor = None
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(origins, directions)
    clear = ~reference.ambiguous
    np.testing.assert_array_equal(hits.hit[clear], reference.prim_id[clear] >= 0)
    both = clear & hits.hit
    assert_close(hits.t[both], reference.t[both], atol=reference.t_atol[both], rtol=RTOL32)
    return int(both.sum())


def warning_lines(caught: list[warnings.WarningMessage]) -> list[str]:
    return [str(w.message) for w in caught if issubclass(w.category, InputWarning)]


# -- 1. Draco --------------------------------------------------------------------------------------


def test_a_draco_compressed_gltf_renders_its_decoded_triangles(tmp_path: Path) -> None:
    import DracoPy

    original = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    original.apply_scale([1.0, 0.6, 0.8])
    encoded = DracoPy.encode(
        original.vertices.astype(np.float32), original.faces.astype(np.uint32), quantization_bits=14
    )
    decoded = DracoPy.decode(encoded)  # what the file defines: the quantized points
    vertices = np.asarray(decoded.points, np.float64)
    faces = np.asarray(decoded.faces, np.int64)
    position_id = next(
        a["unique_id"]
        for a in decoded.attributes
        if a["attribute_type"] == DracoPy.AttributeType.POSITION
    )
    gltf = Gltf()
    draco_view = gltf.view(encoded)
    position = gltf.accessor(
        None,
        count=len(vertices),
        width=3,
        min=vertices.min(axis=0).tolist(),
        max=vertices.max(axis=0).tolist(),
    )
    indices = gltf.accessor(None, count=faces.size, dtype=np.uint32, width=1)
    gltf.mesh(
        {
            "attributes": {"POSITION": position},
            "indices": indices,
            "extensions": {
                "KHR_draco_mesh_compression": {
                    "bufferView": draco_view,
                    "attributes": {"POSITION": position_id},
                }
            },
        }
    )
    gltf.node(mesh=0, translation=[0.5, 1.0, -0.5])
    gltf.tree["extensionsUsed"] = gltf.tree["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    gltf.write_glb(tmp_path / "draco.glb")

    world = vertices + np.array([0.5, 1.0, -0.5])
    scene = load_scene(scene_file(tmp_path, "draco.glb", camera_on(world)))
    (placed,) = scene.meshes
    assert len(placed.mesh.faces) == len(original.faces)
    covered = assert_pixels_match(scene, world, faces)
    assert covered > 0.1 * WIDTH * HEIGHT
    # and the decoded shape is the original to the quantization step (2 / 2^14 of the range)
    np.testing.assert_allclose(
        np.sort(vertices, axis=0), np.sort(original.vertices, axis=0), atol=2.0 / 2**14 * 2
    )


# -- 2. sparse accessors ---------------------------------------------------------------------------


def strip_grid(columns: int) -> tuple[np.ndarray, np.ndarray]:
    """A flat strip of 2 x ``columns`` vertices in the y = 0 plane and its triangles."""
    x = np.linspace(-2.0, 2.0, columns)
    vertices = np.concatenate(
        [
            np.stack([x, np.zeros(columns), np.zeros(columns)], axis=1),
            np.stack([x, np.zeros(columns), np.ones(columns)], axis=1),
        ]
    )
    faces = [[i, i + 1, columns + i] for i in range(columns - 1)]
    faces += [[i + 1, columns + i + 1, columns + i] for i in range(columns - 1)]
    return vertices.astype(np.float32), np.array(faces, np.uint32)


@pytest.mark.parametrize("base", ["a buffer view", "zeros"])
def test_sparse_accessor_positions_are_applied(tmp_path: Path, base: str) -> None:
    """Positions = the base view (or zeros) with ``accessor.sparse`` substitutions: two peaks
    raised out of a flat strip. Without them the strip is flat (or every vertex at 0)."""
    vertices, faces = strip_grid(9)
    rows = np.array([2, 6, 11, 15], np.uint16)  # the peaks, on both edges of the strip
    raised = vertices[rows].copy()
    raised[:, 1] = [1.5, 1.0, 1.5, 1.0]
    gltf = Gltf()
    sparse = {
        "count": len(rows),
        "indices": {"bufferView": gltf.view(rows.tobytes()), "componentType": 5123},
        "values": {"bufferView": gltf.view(raised.tobytes())},
    }
    expected = vertices.astype(np.float64)
    if base == "zeros":
        expected[:] = 0.0
    expected[rows] = raised
    position = gltf.accessor(
        vertices if base == "a buffer view" else None,
        count=len(vertices),
        width=3,
        sparse=sparse,
        min=expected.min(axis=0).tolist(),
        max=expected.max(axis=0).tolist(),
    )
    indices = gltf.accessor(faces.ravel(), dtype=np.uint32)
    gltf.mesh({"attributes": {"POSITION": position}, "indices": indices})
    gltf.node(mesh=0)
    gltf.write_glb(tmp_path / "sparse.glb")

    scene = load_scene(scene_file(tmp_path, "sparse.glb", camera_on(expected)))
    (placed,) = scene.meshes
    np.testing.assert_array_equal(placed.mesh.vertices, expected)
    if base == "a buffer view":
        assert assert_pixels_match(scene, expected, faces) > 0.05 * WIDTH * HEIGHT


# -- 3. EXT_mesh_gpu_instancing --------------------------------------------------------------------


@pytest.mark.parametrize("rotation_type", [np.float32, np.int16])
def test_gpu_instancing_places_every_copy_as_an_instance_array(
    tmp_path: Path, rotation_type
) -> None:
    """Five copies of a box by TRANSLATION / ROTATION (x, y, z, w; float or normalized short) /
    SCALE, under a node that is itself moved and turned: world = node · T · R · S."""
    box = trimesh.creation.box(extents=(0.6, 0.3, 0.4))
    rng = np.random.default_rng(3)
    translation = rng.uniform(-2.0, 2.0, (5, 3)).astype(np.float32)
    quaternions = Rotation.random(5, random_state=4).as_quat()  # x, y, z, w
    scale = rng.uniform(0.5, 1.5, (5, 3)).astype(np.float32)
    if rotation_type is np.int16:
        stored = np.round(quaternions * 32767).astype(np.int16)
        quaternions = np.maximum(stored / 32767.0, -1.0)  # what the file defines
    else:
        stored = quaternions.astype(np.float32)
        quaternions = stored.astype(np.float64)
    gltf = Gltf()
    gltf.triangles(box.vertices.astype(np.float32), box.faces)
    attributes = {
        "TRANSLATION": gltf.accessor(translation),
        "ROTATION": gltf.accessor(
            stored,
            dtype=rotation_type,
            **({"normalized": True} if rotation_type is np.int16 else {}),
        ),
        "SCALE": gltf.accessor(scale),
    }
    node_rotation = Rotation.from_euler("y", 30, degrees=True)
    parent = gltf.node(children=[1], translation=[0.0, 1.0, 0.0])
    gltf.node(
        root=False,
        mesh=0,
        rotation=node_rotation.as_quat().tolist(),
        extensions={"EXT_mesh_gpu_instancing": {"attributes": attributes}},
    )
    assert parent == 0
    gltf.tree["extensionsUsed"] = ["EXT_mesh_gpu_instancing"]
    gltf.write_glb(tmp_path / "copies.glb")

    copies = []
    for t, q, s in zip(translation, quaternions, scale, strict=True):
        local = Rotation.from_quat(q / np.linalg.norm(q)).apply(box.vertices * s) + t
        copies.append(node_rotation.apply(local) + np.array([0.0, 1.0, 0.0]))
    world = np.concatenate(copies)
    faces = np.concatenate([box.faces + i * len(box.vertices) for i in range(5)])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(scene_file(tmp_path, "copies.glb", camera_on(world)))
    assert warning_lines(caught) == []
    assert scene.meshes == []  # the prototype is not also placed on its own
    (array,) = scene.instances
    assert len(array) == 5
    assert assert_pixels_match(scene, world, faces) > 0.05 * WIDTH * HEIGHT


# -- 4. extensions -------------------------------------------------------------------------------


def box_gltf() -> Gltf:
    gltf = Gltf()
    box = trimesh.creation.box()
    gltf.triangles(box.vertices.astype(np.float32), box.faces)
    gltf.node(mesh=0)
    return gltf


def test_a_required_extension_we_cannot_honour_refuses_the_file(tmp_path: Path) -> None:
    gltf = box_gltf()
    gltf.tree["extensionsUsed"] = ["KHR_texture_transform", "GOOGLE_texture_basis"]
    gltf.tree["extensionsRequired"] = ["GOOGLE_texture_basis"]
    path = gltf.write_glb(tmp_path / "basis.glb")
    scene = scene_file(tmp_path, "basis.glb")
    with pytest.raises(SceneError) as caught:
        load_scene(scene)
    message = str(caught.value)
    assert message.startswith(f"{scene}: meshes[0].file: {path}: extensionsRequired[0]: ")
    assert "GOOGLE_texture_basis" in message and "not supported" in message
    assert "\n" not in message
    with pytest.raises(SceneError, match=r"basis\.glb: extensionsRequired\[0\]: .*GOOGLE"):
        load_model(path)  # the file on its own: the file is the one named


def test_an_optional_extension_we_ignore_is_one_warning_line(tmp_path: Path) -> None:
    gltf = box_gltf()
    gltf.tree["extensionsUsed"] = [
        "KHR_materials_sheen",
        "GOOGLE_texture_basis",
        "KHR_texture_transform",
        "EXT_mesh_gpu_instancing",
        "KHR_materials_clearcoat",
    ]
    gltf.write_glb(tmp_path / "optional.glb")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(scene_file(tmp_path, "optional.glb"))
    (line,) = warning_lines(caught)
    assert "optional.glb: extensionsUsed: " in line and "\n" not in line
    assert "KHR_materials_sheen, KHR_materials_clearcoat ignored (no counterpart" in line
    assert "GOOGLE_texture_basis ignored (not supported by embree_rt)" in line
    # supported (the glTF materials honour KHR_texture_transform): no word about them
    assert "EXT_mesh_gpu_instancing" not in line and "KHR_texture_transform" not in line
    assert len(scene.meshes) == 1


# -- 5. PLY triangle strips ------------------------------------------------------------------------


def reference_strip_faces(strips: list[list[int]]) -> np.ndarray:
    """Triangles of strips by the rule, one at a time: a -1 restarts; triangle k of a run
    is (a, b, c) = run[k:k+3], swapped to (b, a, c) for odd k; degenerate ones dropped."""
    faces = []
    for strip in strips:
        run: list[int] = []
        for index in [*strip, -1]:
            if index < 0:
                for k in range(len(run) - 2):
                    a, b, c = run[k : k + 3]
                    triangle = (b, a, c) if k % 2 else (a, b, c)
                    if len(set(triangle)) == 3:
                        faces.append(triangle)
                run = []
            else:
                run.append(index)
    return np.array(faces, np.int64)


def strip_ply(path: Path, vertices: np.ndarray, strips: list[list[int]], binary: bool) -> Path:
    header = [
        "ply",
        f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
        f"element vertex {len(vertices)}",
        "property float x",
        "property float y",
        "property float z",
        f"element tristrips {len(strips)}",
        "property list int int vertex_indices",
        "end_header",
    ]
    if binary:
        body = np.asarray(vertices, "<f4").tobytes()
        for strip in strips:
            body += np.array([len(strip), *strip], "<i4").tobytes()
        path.write_bytes(("\n".join(header) + "\n").encode() + body)
    else:
        lines = [" ".join(map(str, v)) for v in vertices]
        lines += [" ".join(map(str, [len(s), *s])) for s in strips]
        path.write_text("\n".join(header + lines) + "\n")
    return path


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_ply_triangle_strips_are_decoded(tmp_path: Path, binary: bool) -> None:
    """A bumpy grid of 6 x 5 vertices as strips along its rows, with -1 restarts and a
    repeated index (a degenerate join); a binary file holds one strip, as scanners write."""
    n = 6
    x, z = np.meshgrid(np.arange(n, dtype=float), np.arange(5, dtype=float))
    y = 0.3 * np.sin(x) * np.cos(z)
    vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1).astype(np.float32)
    rows = [[i for k in range(n) for i in ((r + 1) * n + k, r * n + k)] for r in range(4)]
    joined = [*rows[0], -1, *rows[1], rows[1][-1], rows[2][0], *rows[2], -1, *rows[3]]
    strips = [joined] if binary else [[*rows[0], -1, *rows[1]], rows[2], rows[3]]
    path = strip_ply(tmp_path / "strips.ply", vertices, strips, binary)
    faces = reference_strip_faces(strips)
    assert len(faces) == 4 * 2 * (n - 1)
    normals = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    assert (np.sign(normals[:, 1]) == np.sign(normals[0, 1])).all()  # one winding throughout

    scene = load_scene(scene_file(tmp_path, path.name, camera_on(vertices)))
    (placed,) = scene.meshes
    loaded = {tuple(np.roll(f, -int(np.argmin(f)))) for f in np.asarray(placed.mesh.faces)}
    assert loaded == {tuple(np.roll(f, -int(np.argmin(f)))) for f in faces}  # same windings
    assert assert_pixels_match(scene, vertices.astype(np.float64), faces) > 0.1 * WIDTH * HEIGHT


@pytest.mark.parametrize(
    "element, needle",
    [
        ("element edge 1\nproperty int vertex1\nproperty int vertex2\n", "element 'edge'"),
        ("", "only vertices (a point cloud)"),
    ],
)
def test_a_ply_without_triangles_says_which_element(
    tmp_path: Path, element: str, needle: str
) -> None:
    text = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        f"property float z\n{element}end_header\n0 0 0\n1 0 0\n0 1 0\n"
    )
    text += "0 1\n" if element else ""
    (tmp_path / "odd.ply").write_text(text)
    with pytest.raises(SceneError) as caught:
        load_scene(scene_file(tmp_path, "odd.ply"))
    assert needle in str(caught.value) and "no triangles" not in str(caught.value)


# -- 6. OBJ with texture coordinates and no material ----------------------------------------------


def test_an_obj_with_uvs_and_no_material_keeps_the_default_look(tmp_path: Path) -> None:
    box = trimesh.creation.box()
    plain = "".join(f"v {x} {y} {z}\n" for x, y, z in box.vertices)
    uv = plain + "".join(f"vt {u} {v}\n" for u, v in np.random.default_rng(1).random((8, 2)))
    (tmp_path / "plain.obj").write_text(
        plain + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in box.faces)
    )
    (tmp_path / "uv.obj").write_text(
        uv
        + "".join(f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}\n" for a, b, c in box.faces)
    )
    with_uv = load_scene(scene_file(tmp_path, "uv.obj"))
    (placed,) = with_uv.meshes
    assert mesh_material(placed.mesh) is None and mesh_surface(placed.mesh) is None
    assert placed.material == "matte"
    without = load_scene(scene_file(tmp_path, "plain.obj")).meshes[0]
    assert without.material == placed.material


# -- 7. MTL texture names with Windows separators -------------------------------------------------


@pytest.mark.parametrize("written", [r".\textures\Tex.png", r"C:\Users\artist\maps\Tex.png"])
def test_mtl_texture_names_with_backslashes_are_found(tmp_path: Path, written: str) -> None:
    """3ds Max writes ``map_Kd .\\textures\\Tex.png``: read with ``/``, the file is found; an
    absolute Windows path falls back to the bare name beside the OBJ."""
    folder = tmp_path / "textures" if written.startswith(".") else tmp_path
    folder.mkdir(exist_ok=True)
    image = Image.fromarray(np.random.default_rng(2).integers(0, 256, (8, 8, 3), np.uint8))
    image.save(folder / "Tex.png")
    box = trimesh.creation.box()
    lines = [
        "mtllib box.mtl",
        *(f"v {x} {y} {z}" for x, y, z in box.vertices),
        *(f"vt {u} {v}" for u, v in np.random.default_rng(1).random((8, 2))),
        "usemtl skin",
        *(f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in box.faces),
    ]
    (tmp_path / "box.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "box.mtl").write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd {written}\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        (placed,) = load_scene(scene_file(tmp_path, "box.obj")).meshes
    assert warning_lines(caught) == []
    surface = mesh_surface(placed.mesh)
    assert surface is not None and surface.texels is not None
    np.testing.assert_array_equal(surface.texels, texels_from_image(Image.open(folder / "Tex.png")))


# -- 8. missing files ------------------------------------------------------------------------------


def test_a_missing_gltf_image_is_one_warning_naming_its_key(tmp_path: Path) -> None:
    gltf = box_gltf()
    gltf.tree["images"] = [{"uri": "present.png"}, {"uri": "gone.png"}]
    gltf.tree["textures"] = [{"source": 0}, {"source": 1}]
    gltf.tree["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}}]
    gltf.tree["meshes"][0]["primitives"][0]["material"] = 0
    Image.new("RGB", (2, 2), (10, 200, 30)).save(tmp_path / "present.png")
    gltf.write_glb(tmp_path / "textured.glb")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(scene_file(tmp_path, "textured.glb"))
    (line,) = warning_lines(caught)
    assert line.startswith(f"{tmp_path / 'textured.glb'}: images[1].uri: no such file 'gone.png'")


def test_a_missing_mtl_texture_is_one_warning_naming_map_kd(tmp_path: Path) -> None:
    box = trimesh.creation.box()
    lines = [
        "mtllib box.mtl",
        *(f"v {x} {y} {z}" for x, y, z in box.vertices),
        "vt 0 0",
        "usemtl skin",
        *(f"f {a + 1}/1 {b + 1}/1 {c + 1}/1" for a, b, c in box.faces),
    ]
    (tmp_path / "box.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "box.mtl").write_text("newmtl skin\nKd 0.5 0.5 0.5\nmap_Kd skin.jpg\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(scene_file(tmp_path, "box.obj"))
    (line,) = warning_lines(caught)
    assert line.startswith(
        f"{tmp_path / 'box.mtl'}: map_Kd (material 'skin'): no such file 'skin.jpg'"
    )


def test_a_missing_buffer_names_the_file_and_the_key(tmp_path: Path) -> None:
    path = box_gltf().write_gltf(tmp_path / "split.gltf", "split.bin")  # the .bin is not written
    scene = scene_file(tmp_path, "split.gltf")
    with pytest.raises(SceneError) as caught:
        load_scene(scene)
    message = str(caught.value)
    assert message.startswith(
        f"{scene}: meshes[0].file: {path}: buffers[0].uri: no such file 'split.bin'"
    )
    from embree_rt.cli import main

    output = tmp_path / "out.png"
    assert main(["render", str(scene), "-o", str(output), "--quiet"]) == 2
    assert not output.exists()


# -- 9. a mesh file rendered on its own ------------------------------------------------------------


def in_view(camera, width: int, height: int, points: np.ndarray) -> np.ndarray:
    """(n,) bool: each point in front of the pinhole ``camera`` and inside its image, by the
    pinhole's closed form (vertical ``fov``, the image's aspect)."""
    position = np.asarray(camera.position, float)
    forward = np.asarray(camera.look_at, float) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = points - position
    depth = d @ forward
    half = np.tan(np.radians(camera.fov) / 2)
    return (
        (depth > 0)
        & (np.abs(d @ up) < half * depth)
        & (np.abs(d @ right) < half * width / height * depth)
    )


def test_a_gltf_renders_from_its_own_camera_under_its_own_lights(tmp_path: Path) -> None:
    """A camera on a child node of a moved, turned parent; a point, a spot and a directional
    light; the mesh seen through the file's camera hits where the reference says."""
    gltf = box_gltf()
    turn = Rotation.from_euler("y", 20, degrees=True)
    gltf.node(children=[2], translation=[0.5, 0.0, 0.0], rotation=turn.as_quat().tolist())
    tilt = Rotation.from_euler("x", -15, degrees=True)
    gltf.node(root=False, camera=0, translation=[0.0, 1.2, 4.0], rotation=tilt.as_quat().tolist())
    gltf.tree["cameras"] = [
        {"type": "perspective", "perspective": {"yfov": 0.6, "aspectRatio": 2.0, "znear": 0.1}}
    ]
    down = Rotation.from_euler("x", -90, degrees=True)  # -z turned to point down
    gltf.node(translation=[0.0, 3.0, 0.0], extensions={"KHR_lights_punctual": {"light": 0}})
    gltf.node(
        translation=[2.0, 2.0, 0.0],
        rotation=down.as_quat().tolist(),
        extensions={"KHR_lights_punctual": {"light": 1}},
    )
    gltf.node(rotation=down.as_quat().tolist(), extensions={"KHR_lights_punctual": {"light": 2}})
    gltf.tree["extensions"] = {
        "KHR_lights_punctual": {
            "lights": [
                {"type": "point", "intensity": 90.0, "color": [1.0, 0.5, 0.25]},
                {"type": "spot", "intensity": 80.0, "spot": {"outerConeAngle": 0.5}},
                {"type": "directional", "intensity": 5.0},
            ]
        }
    }
    gltf.tree["extensionsUsed"] = ["KHR_lights_punctual"]
    box_vertices = np.asarray(gltf_box_vertices(gltf))
    path = gltf.write_glb(tmp_path / "staged.glb")

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = Scene.from_file(path)
    (line,) = warning_lines(caught)
    assert "extensions.KHR_lights_punctual.lights[1]: a spot light, rendered as a point" in line
    eye = turn.apply([0.0, 1.2, 4.0]) + np.array([0.5, 0.0, 0.0])
    forward = (turn * tilt).apply([0.0, 0.0, -1.0])
    np.testing.assert_allclose(scene.camera.position, eye, atol=1e-12)
    aim = np.asarray(scene.camera.look_at) - eye
    np.testing.assert_allclose(aim / np.linalg.norm(aim), forward, atol=1e-12)
    np.testing.assert_allclose(scene.camera.up, (turn * tilt).apply([0.0, 1.0, 0.0]), atol=1e-12)
    assert scene.camera.fov == pytest.approx(np.degrees(0.6))
    assert scene.render.width == 2 * scene.render.height
    # the lights: E = I / d^2 at the box's centre (the origin), lux for the directional one
    point, spot, sun = scene.lights
    strengths = np.array([90.0 / 9.0, 80.0 / 8.0, 5.0])
    assert [light.intensity for light in scene.lights] == pytest.approx(strengths / strengths.sum())
    assert point.color == (1.0, 0.5, 0.25)
    np.testing.assert_allclose(spot.position, [2.0, 2.0, 0.0])
    sun_direction = np.asarray(sun.position) / np.linalg.norm(sun.position)
    np.testing.assert_allclose(sun_direction, [0.0, 1.0, 0.0], atol=1e-9)  # shining down
    assert np.linalg.norm(sun.position) > 1e3
    assert scene.floor is not None and scene.floor.height < box_vertices[:, 1].min()
    assert f"camera: cameras[0] of {path}" in scene.notes
    scene.render.width, scene.render.height = WIDTH, HEIGHT
    covered = assert_pixels_match(scene, box_vertices, trimesh.creation.box().faces)
    assert covered > 0.05 * WIDTH * HEIGHT


def gltf_box_vertices(gltf: Gltf) -> np.ndarray:
    """The box_gltf's positions as its bytes hold them."""
    view = gltf.tree["bufferViews"][gltf.tree["accessors"][0]["bufferView"]]
    data = bytes(gltf.blob[view["byteOffset"] : view["byteOffset"] + view["byteLength"]])
    return np.frombuffer(data, "<f4").reshape(-1, 3).astype(np.float64)


@pytest.mark.parametrize("floor", [True, False])
def test_a_file_without_camera_or_lights_is_framed_and_lit(tmp_path: Path, floor: bool) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.apply_scale([300.0, 500.0, 200.0])  # a large model, off the origin
    mesh.apply_translation([1000.0, 600.0, -50.0])
    mesh.export(tmp_path / "big.stl")
    scene = Scene.from_file(tmp_path / "big.stl", floor=floor)
    settings = scene.render
    assert in_view(scene.camera, settings.width, settings.height, mesh.vertices).all()
    assert len(scene.lights) == 2
    if floor:
        assert 0.0 < mesh.vertices[:, 1].min() - scene.floor.height < 1.0
    else:
        assert scene.floor is None
    scene.render.width, scene.render.height = WIDTH, HEIGHT
    assert assert_pixels_match(scene, mesh.vertices, mesh.faces) > 0.1 * WIDTH * HEIGHT


def test_from_trimesh_uses_the_trimesh_scenes_camera() -> None:
    box = trimesh.creation.box()
    loaded = trimesh.Scene(box)
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("y", 30, degrees=True).as_matrix()
    pose[:3, 3] = Rotation.from_euler("y", 30, degrees=True).apply([0.0, 0.0, 5.0])
    loaded.camera = trimesh.scene.Camera(fov=(50.0, 40.0), resolution=(500, 400))
    loaded.camera_transform = pose
    scene = Scene.from_trimesh(loaded, floor=False)
    np.testing.assert_allclose(scene.camera.position, pose[:3, 3], atol=1e-12)
    aim = np.asarray(scene.camera.look_at) - pose[:3, 3]
    np.testing.assert_allclose(aim / np.linalg.norm(aim), -pose[:3, 2], atol=1e-12)
    assert scene.camera.fov == pytest.approx(40.0) and scene.floor is None


def test_the_still_life_asset_renders_straight_from_its_file() -> None:
    """assets/still_life.glb (the README's picture) on its own: every part where
    make_assets.py put it (its parts baked at their node transforms, as made), seen by the
    framed camera, every triangle in view, over a floor under the table's feet."""
    root = Path(__file__).resolve().parent.parent / "assets"
    spec = importlib.util.spec_from_file_location("make_assets", root / "make_assets.py")
    make = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make)
    made = make.still_life(make.quadrants()).to_mesh()  # world space, as made
    scene = Scene.from_file(root / "still_life.glb")
    assert len(scene.meshes) == 9  # top, four legs, metal ball, torus, painted ball, cube
    assert len({id(placed.mesh) for placed in scene.meshes}) == 6  # the legs share a mesh
    assert in_view(scene.camera, scene.render.width, scene.render.height, made.vertices).all()
    assert 0.0 < made.vertices[:, 1].min() - scene.floor.height < 1e-3
    scene.render.width, scene.render.height = WIDTH, HEIGHT
    assert assert_pixels_match(scene, made.vertices, made.faces) > 0.1 * WIDTH * HEIGHT
