"""Hostile and extreme scene input: whatever a file holds, loading ends in a ``SceneError`` of one
line naming the file and the key, or in a scene that renders without NaN; never another exception.

The cases are the ones a hostile user tried: parser limits (nesting, the digits of an integer),
numbers float64 holds and float32 does not, names with NUL or newline characters, a zip bomb.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from embree_rt import load_scene
from embree_rt.scene import SceneError

SPHERE = "[[spheres]]\ncenter = [0, 1, 0]\nradius = 1\n"
DIGITS_400 = "1" + "0" * 400


def _load_error(path: Path, text: str) -> SceneError:
    path.write_text(text)
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    message = str(caught.value)
    assert "\n" not in message and "\r" not in message and message.isprintable()
    return caught.value


# case: (file name, text, key, words the problem must contain)
PARSER_LIMITS = {
    "600 nested toml arrays": ("s.toml", "a = " + "[" * 600 + "]" * 600, "(syntax)", "nested"),
    "600 nested toml tables": (
        "s.toml", "a = " + "{b = " * 600 + "1" + "}" * 600, "(syntax)", "nested",
    ),
    "100000 nested json lists": ("s.json", '{"a": ' + "[" * 100_000 + "]" * 100_000 + "}",
                                 "(syntax)", "nested"),
    "20 nested json tables": (
        "s.json", '{"render": ' + '{"a": ' * 20 + "1" + "}" * 21, "render" + ".a" * 16,
        "levels deep",
    ),
    "4400-digit toml integer": (
        "s.toml", "[render]\nwidth = " + "1" * 4400, "(syntax)", "more than 4300 digits",
    ),
    "4400-digit json integer": (
        "s.json", '{"render": {"width": ' + "1" * 4400 + "}}", "(syntax)", "4300 digits",
    ),
    "400-digit radius": (
        "s.toml", SPHERE.replace("radius = 1", f"radius = {DIGITS_400}"), "spheres[0].radius",
        "finite",
    ),
    "400-digit centre": (
        "s.toml", SPHERE.replace("[0, 1, 0]", f"[{DIGITS_400}, 1, 0]"), "spheres[0].center",
        "finite",
    ),
    "400-digit negative fov": ("s.json", json.dumps({"camera": {"fov": -(10**400)}}),
                               "camera.fov", "finite"),
    "NUL in a mesh file name": (
        "s.toml", '[[meshes]]\nfile = "a\\u0000b.obj"', "meshes[0].file", "NUL",
    ),
    "NUL in a sphere array name": (
        "s.toml", '[[sphere_arrays]]\nfile = "a\\u0000.npz"', "sphere_arrays[0].file", "NUL",
    ),
    "NUL in a placements name": (
        "s.toml", '[[instances]]\nmesh = "m.obj"\ntransforms = "\\u0000"',
        "instances[0].transforms", "NUL",
    ),
}


@pytest.mark.parametrize("case", sorted(PARSER_LIMITS))
def test_parser_limits_are_one_line_scene_errors(tmp_path: Path, case: str) -> None:
    name, text, key, words = PARSER_LIMITS[case]
    error = _load_error(tmp_path / name, text)
    assert (error.file, error.key) == (str(tmp_path / name), key)
    assert words in error.problem


def test_a_newline_in_a_key_or_a_file_name_stays_on_one_line(tmp_path: Path) -> None:
    error = _load_error(tmp_path / "s.toml", '[render]\n"wid\\nth" = 3\n')
    assert error.key == "render.wid\nth"
    assert "'render.wid\\nth'" in str(error)  # quoted by repr: where the key ends is plain
    error = _load_error(tmp_path / "s.toml", '[[meshes]]\nfile = "a\\nb.obj"\n')
    assert "a\\nb.obj" in str(error) and "no such file" in str(error)
    folder = tmp_path / "new\nline"
    folder.mkdir()
    error = _load_error(folder / "s.toml", "[render]\nwidth = 0\n")
    assert str(error).startswith(repr(str(folder / "s.toml")) + ": render.width: ")


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "embree_rt", *args], capture_output=True,
                          text=True, timeout=300, cwd=cwd)  # fmt: skip


def test_the_command_says_one_line_and_exits_2_for_a_parser_limit(tmp_path: Path) -> None:
    (tmp_path / "deep.toml").write_text("a = " + "[" * 600 + "]" * 600)
    result = _run("render", "deep.toml", "-o", "out.png", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "deep.toml: (syntax):" in result.stderr
    assert not (tmp_path / "out.png").exists()
