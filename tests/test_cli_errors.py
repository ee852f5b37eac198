"""Bad input through the real command: one line naming file and key, exit 2, no output file."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
GOOD = """
[render]
width = 16
height = 9
spp = 1

[[spheres]]
center = [0.0, 1.0, 0.0]
radius = 1.0
"""


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args], capture_output=True, text=True, timeout=300
    )


SPHERE = "[[spheres]]\ncenter = [0, 1, 0]\n"
CASES = {
    "malformed toml": ("scene.toml", "[render\nwidth = 3", "(syntax)"),
    "malformed json": ("scene.json", '{"render": {"width": 3,}}', "(syntax)"),
    "unknown key": ("scene.toml", "[render]\nwidht = 3", "did you mean 'width'"),
    "wrong type": ("scene.toml", SPHERE + 'radius = "big"', "spheres[0].radius"),
    "negative radius": ("scene.toml", SPHERE + "radius = -1", "spheres[0].radius"),
    "nan": ("scene.toml", "[[spheres]]\ncenter = [0, nan, 0]\nradius = 1", "spheres[0].center"),
    "fov zero": ("scene.toml", "[camera]\nfov = 0", "camera.fov"),
    "spp zero": ("scene.toml", "[render]\nspp = 0", "render.spp"),
    "width negative": ("scene.toml", "[render]\nwidth = -1", "render.width"),
    "undefined material": ("scene.toml", SPHERE + 'radius = 1\nmaterial = "nope"', "material"),
    "missing mesh": ("scene.toml", '[[meshes]]\nfile = "nowhere.obj"', "meshes[0].file"),
    "garbage mesh": ("scene.toml", '[[meshes]]\nfile = "garbage.ply"', "meshes[0].file"),
    "empty mesh": ("scene.toml", '[[meshes]]\nfile = "empty.obj"', "meshes[0].file"),
    "npz without radii": ("scene.toml", '[[sphere_arrays]]\nfile = "bad.npz"', "sphere_arrays"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_scene_is_one_line_exit_2_and_no_output(case: str, tmp_path: Path) -> None:
    name, text, key = CASES[case]
    (tmp_path / "garbage.ply").write_bytes(b"ply\nthis is not a mesh\x00\x01\x02")
    (tmp_path / "empty.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    np.savez(tmp_path / "bad.npz", centers=np.zeros((2, 3)))
    scene = tmp_path / name
    scene.write_text(text)
    output = tmp_path / "out.png"
    result = run_cli("render", str(scene), "-o", str(output), "--quiet")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"embree-rt: error: {scene}: ")
    assert key in lines[0]
    assert "Traceback" not in result.stderr
    assert not output.exists()


def test_missing_scene_file(tmp_path: Path) -> None:
    result = run_cli("render", str(tmp_path / "absent.toml"), "-o", str(tmp_path / "o.png"))
    assert result.returncode == 2
    assert "absent.toml" in result.stderr and "no such file" in result.stderr
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize(
    ("arguments", "needle"),
    [
        (["--width", "-1"], "--width"),
        (["-o", "out.bmp"], "unknown image extension"),
        (["-o", "missing_dir/out.png"], "does not exist"),
    ],
)
def test_bad_flags_leave_the_old_image_alone(arguments, needle, tmp_path: Path) -> None:
    scene = tmp_path / "scene.toml"
    scene.write_text(GOOD)
    output = tmp_path / "out.png"
    Image.new("RGB", (3, 2), (1, 2, 3)).save(output)
    before = output.read_bytes()
    flags = ["-o", str(output)] if "-o" not in arguments else []
    arguments = [
        str(tmp_path / a) if a.startswith(("out.", "missing_dir")) else a for a in arguments
    ]
    result = run_cli("render", str(scene), *flags, *arguments, "--quiet")
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1
    assert needle in result.stderr
    assert output.read_bytes() == before


def test_render_writes_the_image_and_npy(tmp_path: Path) -> None:
    scene = tmp_path / "scene.toml"
    scene.write_text(GOOD)
    png, npy = tmp_path / "a.png", tmp_path / "a.npy"
    assert run_cli("render", str(scene), "-o", str(png), "--quiet").returncode == 0
    assert Image.open(png).size == (16, 9)
    assert run_cli("render", str(scene), "-o", str(npy), "--width", "8", "--quiet").returncode == 0
    image = np.load(npy)
    assert image.shape == (9, 8, 3) and image.dtype == np.float32
    assert np.isfinite(image).all() and (image >= 0).all()


def test_a_million_sphere_field_renders(tmp_path: Path) -> None:
    output = tmp_path / "million.png"
    scene = tmp_path / "million.toml"
    result = run_cli(
        "random", "--count", "1000000", "-o", str(output), "--width", "64", "--height", "36",
        "--spp", "1", "--quiet",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert Image.open(output).size == (64, 36)
    small = run_cli("random", "--count", "500", "-o", str(output), "--width", "8", "--height",
                    "8", "--save-scene", str(scene), "--quiet")  # fmt: skip
    assert small.returncode == 0, small.stderr
    from embree_rt import load_scene

    assert len(load_scene(scene).sphere_radii) == 500


def test_info_counts_the_mesh_scene() -> None:
    result = run_cli("info", str(ROOT / "scenes" / "mesh_and_spheres.toml"))
    assert result.returncode == 0, result.stderr
    text = (ROOT / "scenes" / "mesh_and_spheres.toml").read_text()
    placements = text.count("[[meshes]]") - 1 + 3  # trio.glb holds three nodes
    assert f"spheres:    {text.count('[[spheres]]')}" in result.stdout
    assert f"instances:  {placements}" in result.stdout
