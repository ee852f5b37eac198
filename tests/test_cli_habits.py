"""What users of other renderers expect of the ``embree-rt`` command (issue: the habits users
bring): mesh files rendered straight, ``--set`` over any scene key, ``--version`` and helpful
usage, more image formats, the look, papercuts. Run for real in a subprocess, as test_cli.py."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
TINY = ["--width", "16", "--height", "9", "--spp", "1"]


def run_cli(*args: str, timeout: float = 120, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )


def box_obj_with_missing_texture(folder: Path) -> Path:
    """A box OBJ whose material library names a texture that is not there: one warning."""
    box = trimesh.creation.box()
    lines = ["mtllib box.mtl", *(f"v {x} {y} {z}" for x, y, z in box.vertices), "vt 0 0",
             "usemtl skin", *(f"f {a + 1}/1 {b + 1}/1 {c + 1}/1" for a, b, c in box.faces)]
    (folder / "box.obj").write_text("\n".join(lines) + "\n")
    (folder / "box.mtl").write_text("newmtl skin\nKd 0.5 0.5 0.5\nmap_Kd skin.jpg\n")
    return folder / "box.obj"


# -- 0. mesh files on the command line --------------------------------------------------------


def test_a_mesh_file_renders_on_its_own_and_its_warnings_are_one_line_each(tmp_path: Path) -> None:
    mesh = box_obj_with_missing_texture(tmp_path)
    output = tmp_path / "out.png"
    result = run_cli("render", str(mesh), "-o", str(output), *TINY)
    assert result.returncode == 0, result.stderr
    warning, summary = result.stderr.splitlines()
    assert warning.startswith(f"embree-rt: warning: {tmp_path / 'box.mtl'}: map_Kd")
    assert "skin.jpg" in warning
    assert summary.startswith("embree-rt: 16x9 at 1 spp")
    with Image.open(output) as image:
        assert image.size == (16, 9) and image.mode == "RGB"
        pixels = np.asarray(image)
    assert pixels.std() > 1  # the box over the floor, not a blank

    # --no-floor: the floor's checker is gone, the pixels under the box are the sky's
    bare = tmp_path / "bare.npy"
    assert run_cli("render", str(mesh), "-o", str(bare), *TINY, "--no-floor").returncode == 0
    floored = tmp_path / "floored.npy"
    assert run_cli("render", str(mesh), "-o", str(floored), *TINY).returncode == 0
    assert not np.array_equal(np.load(bare)[-1], np.load(floored)[-1])


def test_info_of_a_mesh_file_says_what_was_chosen(tmp_path: Path) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1)
    mesh.export(tmp_path / "ball.stl")
    result = run_cli("info", str(tmp_path / "ball.stl"), "--no-floor")
    assert result.returncode == 0, result.stderr
    notes = [line.split(":", 1)[1].strip() for line in result.stdout.splitlines()
             if line.startswith("note:")]  # fmt: skip
    assert notes == ["camera: framed from the bounds", "lights: the default rig of two",
                     "floor: none"]  # fmt: skip
    assert f"triangles:  {len(mesh.faces):,} stored" in result.stdout
    assert "floor:      none" in result.stdout


def test_a_file_neither_scene_nor_mesh_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "scene.yaml").write_text("render: {}\n")
    result = run_cli("render", str(tmp_path / "scene.yaml"), "-o", str(tmp_path / "o.png"))
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1, result.stderr
    assert ".toml" in result.stderr and ".glb" in result.stderr and "scene.yaml" in result.stderr
