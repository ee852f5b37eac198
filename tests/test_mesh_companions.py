"""The files a mesh makes trimesh read beside it (``scene.mesh_companions``), against the
reference that matters: the files trimesh itself opens while loading the mesh, recorded by a
resolver that watches every read. And the cluster's scene key, which stamps those files."""

from __future__ import annotations

import base64
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
from trimesh.resolvers import FilePathResolver

from embree_rt.distributed import SceneFile
from embree_rt.scene.mesh_companions import companion_files

ASSETS = Path(__file__).resolve().parent.parent / "assets"


class RecordingResolver(FilePathResolver):
    """trimesh's own file resolver, noting the path of every file it reads."""

    def __init__(self, source: str) -> None:
        super().__init__(source)
        self.read: list[Path] = []

    def get(self, name: str) -> bytes:
        data = super().get(name)
        for candidate in (name.strip(), name.strip().lstrip("/"), os.path.split(name)[-1]):
            path = (Path(self.parent).resolve() / candidate).resolve()
            if path.is_file() and path.read_bytes() == data:
                self.read.append(path)
                break
        return data


def files_trimesh_reads(mesh: Path) -> list[Path]:
    resolver = RecordingResolver(str(mesh))
    trimesh.load(str(mesh), resolver=resolver, process=False)
    return list(dict.fromkeys(resolver.read))


def _textured_obj(directory: Path, mtllib: str = "cube.mtl", map_kd: str = "quadrants.png"):
    obj = directory / "cube.obj"
    text = (ASSETS / "quadrant_cube.obj").read_text().replace("quadrant_cube.mtl", mtllib)
    obj.write_text(text)
    (directory / "quadrants.png").write_bytes((ASSETS / "quadrants.png").read_bytes())
    (directory / mtllib.strip().lstrip("/").split("/")[-1]).write_text(
        f"newmtl quadrants\nKd 1 1 1\nmap_Kd {map_kd}\n"
    )
    return obj


def test_an_obj_names_its_library_and_the_library_its_texture(tmp_path: Path) -> None:
    obj = _textured_obj(tmp_path)
    expected = [(tmp_path / "cube.mtl").resolve(), (tmp_path / "quadrants.png").resolve()]
    assert files_trimesh_reads(obj) == expected
    assert companion_files(obj) == expected


def test_every_path_a_name_may_be_read_from_is_listed(tmp_path: Path) -> None:
    # A library named by an absolute path outside the mesh's directory and a texture reached
    # through "..": this trimesh falls back to the bare file names beside the mesh (older 4.x
    # releases read the paths as written), so both are stamped, where they exist or not.
    obj = _textured_obj(tmp_path, mtllib="/elsewhere/cube.mtl", map_kd="../textures/quadrants.png")
    read = files_trimesh_reads(obj)
    assert read == [(tmp_path / "cube.mtl").resolve(), (tmp_path / "quadrants.png").resolve()]
    assert companion_files(obj) == [
        Path("/elsewhere/cube.mtl"),
        (tmp_path / "elsewhere" / "cube.mtl").resolve(),
        (tmp_path / "cube.mtl").resolve(),
        (tmp_path.parent / "textures" / "quadrants.png").resolve(),
        (tmp_path / "quadrants.png").resolve(),
    ]
    assert set(read) <= set(companion_files(obj))


def test_a_missing_texture_is_listed_where_it_would_be_read(tmp_path: Path) -> None:
    obj = _textured_obj(tmp_path)
    (tmp_path / "quadrants.png").unlink()
    assert companion_files(obj) == [
        (tmp_path / "cube.mtl").resolve(),
        (tmp_path / "quadrants.png").resolve(),
    ]


def test_a_gltf_names_its_external_buffers_and_images_not_its_data_uris(tmp_path: Path) -> None:
    files = trimesh.creation.box().export(file_type="gltf")  # {"model.gltf": ..., "*.bin": ...}
    tree = json.loads(files["model.gltf"])
    for name, data in files.items():
        if name != "model.gltf":
            (tmp_path / name).write_bytes(data)
    png = (ASSETS / "quadrants.png").read_bytes()
    (tmp_path / "look.png").write_bytes(png)
    inline = "data:image/png;base64," + base64.b64encode(png).decode()
    tree["images"] = [{"uri": "look.png"}, {"uri": inline}]
    tree["textures"] = [{"source": 0}, {"source": 1}]
    tree["materials"] = [
        {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}},
        {"emissiveTexture": {"index": 1}},
    ]
    tree["meshes"][0]["primitives"][0]["material"] = 0
    gltf = tmp_path / "box.gltf"
    gltf.write_text(json.dumps(tree))
    buffers = [(tmp_path / b["uri"]).resolve() for b in tree["buffers"]]
    expected = [*buffers, (tmp_path / "look.png").resolve()]
    assert len(buffers) >= 1
    assert sorted(files_trimesh_reads(gltf)) == sorted(expected)
    assert companion_files(gltf) == expected


@pytest.mark.parametrize(
    "name", ["quadrant_cube.glb", "painted_ball.ply", "capsule.stl", "cone.off", "torus.obj"]
)
def test_self_contained_meshes_name_nothing(name: str) -> None:
    assert files_trimesh_reads(ASSETS / name) == []
    assert companion_files(ASSETS / name) == []


def test_a_file_that_is_no_mesh_names_nothing(tmp_path: Path) -> None:
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"not a glb at all")
    empty = tmp_path / "empty.obj"
    empty.write_bytes(b"")
    assert companion_files(bad) == []
    assert companion_files(empty) == []


def test_the_cluster_key_changes_with_a_texture_and_not_with_other_files(tmp_path: Path) -> None:
    _textured_obj(tmp_path)
    scene = tmp_path / "scene.toml"
    scene.write_text('[[meshes]]\nfile = "cube.obj"\n[camera]\nposition = [0, 1, -6]\n')
    key = SceneFile(str(scene)).digest()
    (tmp_path / "unrelated.png").write_bytes(b"x")
    assert SceneFile(str(scene)).digest() == key
    texture = tmp_path / "quadrants.png"
    stat = texture.stat()
    texture.write_bytes(np.flipud(np.frombuffer(texture.read_bytes(), np.uint8)).tobytes())
    os.utime(texture, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))  # repainted
    assert SceneFile(str(scene)).digest() != key
    key = SceneFile(str(scene)).digest()
    time.sleep(0.01)
    (tmp_path / "cube.mtl").write_text("newmtl quadrants\nKd 1 0 0\n")
    assert SceneFile(str(scene)).digest() != key
