"""What users of other renderers expect of the ``embree-rt`` command (issue: the habits users
bring): mesh files rendered straight, ``--set`` over any scene key, ``--version`` and helpful
usage, more image formats, the look, papercuts. Run for real in a subprocess, as test_cli.py."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import trimesh
from PIL import Image

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

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
    lines = [
        "mtllib box.mtl",
        *(f"v {x} {y} {z}" for x, y, z in box.vertices),
        "vt 0 0",
        "usemtl skin",
        *(f"f {a + 1}/1 {b + 1}/1 {c + 1}/1" for a, b, c in box.faces),
    ]
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


def test_each_warning_line_is_said_once(capsys: pytest.CaptureFixture[str]) -> None:
    """A scene file loaded twice by the command (a cluster's bricks are planned from a second
    load) says its warnings once, a library's too. "always": Python's own once-per-place
    record is reset whenever a library changes the warning filters, as many do."""
    import warnings

    from embree_rt.cli import one_line_warnings
    from embree_rt.scene.errors import InputWarning

    left_out = "scene.toml: meshes[{}].file: a texture left out"
    with one_line_warnings():
        warnings.simplefilter("always")
        for _ in range(2):
            warnings.warn(left_out.format(0), InputWarning, stacklevel=1)
            warnings.warn("overflow encountered in cast", RuntimeWarning, stacklevel=1)
        warnings.warn(left_out.format(1), InputWarning, stacklevel=1)
    assert capsys.readouterr().err.splitlines() == [
        "embree-rt: warning: scene.toml: meshes[0].file: a texture left out",
        "embree-rt: warning: test_cli_habits.py: RuntimeWarning: overflow encountered in cast",
        "embree-rt: warning: scene.toml: meshes[1].file: a texture left out",
    ]


def test_info_of_a_mesh_file_says_what_was_chosen(tmp_path: Path) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1)
    mesh.export(tmp_path / "ball.stl")
    result = run_cli("info", str(tmp_path / "ball.stl"), "--no-floor")
    assert result.returncode == 0, result.stderr
    notes = [
        line.split(":", 1)[1].strip()
        for line in result.stdout.splitlines()
        if line.startswith("note:")
    ]
    assert notes == [
        "camera: framed from the bounds",
        "lights: the default rig of two",
        "floor: none",
    ]
    assert f"triangles:  {len(mesh.faces):,} stored" in result.stdout
    assert "floor:      none" in result.stdout


def test_a_file_neither_scene_nor_mesh_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "scene.yaml").write_text("render: {}\n")
    result = run_cli("render", str(tmp_path / "scene.yaml"), "-o", str(tmp_path / "o.png"))
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1, result.stderr
    assert ".toml" in result.stderr and ".glb" in result.stderr and "scene.yaml" in result.stderr


# -- 1. --set ---------------------------------------------------------------------------------


def one_line_error(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    (line,) = result.stderr.splitlines()
    assert line.startswith("embree-rt: error: ")
    return line.removeprefix("embree-rt: error: ")


def test_set_changes_any_key_as_the_file_would(tmp_path: Path) -> None:
    """Each --set gives bitwise the image of the scene file with the same value written in it
    (the same document reaches the same loader and renderer)."""
    base = (ROOT / "scenes" / "three_spheres.toml").read_text()
    scene = tmp_path / "scene.toml"
    scene.write_text(base)
    edited = tmp_path / "edited.toml"
    document = tomllib.loads(base)
    document["camera"]["fov"] = 35
    document["lights"][0]["intensity"] = 2
    document.setdefault("materials", {}).setdefault("gold", {})["shininess"] = 200
    document["render"]["max_depth"] = 1
    edited.write_text(tomli_w.dumps(document))
    flags = [
        "-D",
        "camera.fov=35",
        "--set",
        "lights[0].intensity=2",
        "-D",
        "materials.gold.shininess=200",
        "-D",
        "render.max_depth=3",
        "--max-depth",
        "1",
    ]  # the last of render.max_depth wins
    assert (
        run_cli(
            "render", str(scene), "-o", str(tmp_path / "a.npy"), *TINY, *flags, "--quiet"
        ).returncode
        == 0
    )
    assert (
        run_cli("render", str(edited), "-o", str(tmp_path / "b.npy"), *TINY, "--quiet").returncode
        == 0
    )
    assert (
        run_cli("render", str(scene), "-o", str(tmp_path / "c.npy"), *TINY, "--quiet").returncode
        == 0
    )
    changed, written, plain = (np.load(tmp_path / f"{n}.npy") for n in "abc")
    np.testing.assert_array_equal(changed, written)
    assert not np.array_equal(changed, plain)


def test_set_refuses_what_the_loader_refuses_with_its_message(tmp_path: Path) -> None:
    scene = tmp_path / "scene.toml"
    scene.write_text((ROOT / "scenes" / "three_spheres.toml").read_text())
    output = tmp_path / "o.png"
    cases = {
        "camera.fov=0": ("camera.fov", "[camera]\nfov = 0\n"),
        "camera.fvo=30": ("camera.fvo", "[camera]\nfvo = 30\n"),
        "render.spp=many": ("render.spp", '[render]\nspp = "many"\n'),
    }
    for assignment, (key, text) in cases.items():
        line = one_line_error(run_cli("render", str(scene), "-o", str(output), "-D", assignment))
        (tmp_path / "bad.toml").write_text(text)
        in_file = one_line_error(run_cli("render", str(tmp_path / "bad.toml"), "-o", str(output)))
        # the loader's own words, said of the flag instead of the file
        assert line == f"--set {assignment}: " + in_file.split(": ", 1)[1]
        assert line.startswith(f"--set {assignment}: {key}: ")
    fvo = one_line_error(run_cli("render", str(scene), "-o", str(output), "-D", "camera.fvo=30"))
    assert "did you mean 'fov'?" in fvo
    width = one_line_error(run_cli("render", str(scene), "-o", str(output), "--width", "-1"))
    assert width == "--width -1: render.width: must be >= 1, got -1"
    past = one_line_error(run_cli("render", str(scene), "-o", str(output), "-D", "lights[9].x=1"))
    assert past.startswith("--set lights[9].x=1: lights[9]: no such entry: lights has ")
    assert not output.exists()


def test_set_reaches_a_mesh_files_scene_and_a_random_field(tmp_path: Path) -> None:
    mesh = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=1).export(mesh)
    for command in (["render", str(mesh)], ["random", "--count", "50"]):
        runs = {}
        unlit = ["-D", "lights[0].intensity=0", "-D", "lights[1].intensity=0"]
        for name, flags in {"plain": [], "lit": unlit}.items():
            out = tmp_path / f"{name}.npy"
            result = run_cli(*command, "-o", str(out), *TINY, *flags, "--quiet")
            assert result.returncode == 0, result.stderr
            runs[name] = np.load(out)
        assert runs["lit"].mean() < runs["plain"].mean()  # unlit: sky and reflections only
    line = one_line_error(
        run_cli("render", str(mesh), "-o", str(tmp_path / "x.png"), "-D", "spheres[0].radius=2")
    )
    assert line.startswith("--set spheres[0].radius=2: spheres: not settable on ")


# -- 2. version, usage, help ------------------------------------------------------------------


def test_version_is_the_projects() -> None:
    import embree_rt

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert embree_rt.__version__ == declared
    result = run_cli("--version")
    assert result.returncode == 0 and result.stdout == f"embree-rt {declared}\n", result.stderr


def test_bare_command_prints_usage_and_a_mistyped_flag_gets_a_suggestion() -> None:
    bare = run_cli()
    assert bare.returncode == 2 and bare.stdout == ""
    assert bare.stderr.startswith("usage: embree-rt")
    for command in ("render", "random", "info", "serve"):
        assert command in bare.stderr
    typo = run_cli("render", "scene.toml", "-o", "x.png", "--widht", "3")
    assert typo.returncode == 2
    assert typo.stderr.endswith("(did you mean '--width'?)\n")
    assert len(typo.stderr.splitlines()) == 1
    command = run_cli("rendr", "scene.toml")
    assert command.stderr.endswith("(did you mean 'render'?)\n")


def subcommands() -> dict:
    import argparse

    from embree_rt.cli import build_parser

    parser = build_parser()
    (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return commands.choices


def flags_of(parser) -> set[str]:
    return {flag for action in parser._actions for flag in action.option_strings}


def test_help_explains_every_flag_and_random_takes_every_rendering_flag() -> None:
    commands = subcommands()
    for name, parser in commands.items():
        for action in parser._actions:
            assert action.help, f"{name} {action.option_strings or action.dest}: no help text"
    render_help = " ".join(run_cli("render", "--help").stdout.split())  # lines unwrapped
    assert "(default: analytic)" in render_help  # --spheres
    assert "--frames" in render_help and "--overwrite" in render_help
    random_help = " ".join(run_cli("random", "--help").stdout.split())
    assert "--count N" in random_help and "spheres in the field" in random_help
    # random renders as render does: every flag of render's but those that say how a particle
    # file is read and drawn (a field has no file), and its own for the field
    from embree_rt.cli.particles import PARTICLE_FLAG_DEFAULTS

    particle_flags = {"--" + name.replace("_", "-") for name in PARTICLE_FLAG_DEFAULTS}
    assert flags_of(commands["render"]) - particle_flags <= flags_of(commands["random"])
    assert not particle_flags & flags_of(commands["random"])
    assert flags_of(commands["random"]) - flags_of(commands["render"]) == {
        "--count",
        "--save-scene",
        "--instance",
    }
    for name, parser in commands.items():  # each default said once, by the formatter
        for line in parser.format_help().split("\n  -"):
            assert " ".join(line.split()).count("(default:") <= 1, (name, line)


def test_threads_takes_the_spellings_of_pbrt_and_mitsuba() -> None:
    render = subcommands()["render"]
    for spelling in ("--threads", "--nthreads", "-t"):
        args = render.parse_args(["s.toml", "-o", "x.png", spelling, "3"])
        assert args.threads == 3


# -- 3. image formats -------------------------------------------------------------------------


def test_render_writes_jpeg_and_16_bit_tiff_and_refuses_what_a_format_cannot_take(
    tmp_path: Path,
) -> None:
    scene = str(ROOT / "scenes" / "three_spheres.toml")
    jpeg, tiff = tmp_path / "a.jpg", tmp_path / "a.tif"
    assert (
        run_cli(
            "render", scene, "-o", str(jpeg), *TINY, "--quality", "80", "--quiet", "--aov", "depth"
        ).returncode
        == 0
    )
    with Image.open(jpeg) as image, Image.open(tmp_path / "a.depth.jpg") as depth:
        assert (image.format, image.mode, image.size) == ("JPEG", "RGB", (16, 9))
        assert (depth.format, depth.size) == ("JPEG", (16, 9))  # beside it, in its format
    assert (
        run_cli("render", scene, "-o", str(tiff), *TINY, "--bit-depth", "16", "--quiet").returncode
        == 0
    )
    import tifffile

    assert tifffile.imread(tiff).dtype == np.uint16
    line = one_line_error(
        run_cli("render", scene, "-o", str(tmp_path / "b.webp"), "--bit-depth", "16")
    )
    assert "b.webp" in line and "16-bit" in line
    assert not (tmp_path / "b.webp").exists()


# -- 4. the look ------------------------------------------------------------------------------


def test_the_look_is_a_scene_key_and_a_flag_and_no_lights_is_one_warning(tmp_path: Path) -> None:
    base = (ROOT / "scenes" / "three_spheres.toml").read_text()
    scene = tmp_path / "scene.toml"
    scene.write_text(base)
    keyed = tmp_path / "keyed.toml"
    document = tomllib.loads(base)
    document["render"].update(tonemap="aces", exposure=1.5, transfer="srgb")
    keyed.write_text(tomli_w.dumps(document))
    runs = {
        "flags": [str(scene), "--tonemap", "aces", "--exposure", "1.5", "--transfer", "srgb"],
        "keys": [str(keyed)],
        "plain": [str(scene)],
        "linear": [str(scene), "--tonemap", "aces"],
    }
    pictures = {}
    for name, words in runs.items():
        suffix = ".npy" if name == "linear" else ".png"
        out = tmp_path / f"{name}{suffix}"
        assert run_cli("render", *words, "-o", str(out), *TINY, "--quiet").returncode == 0
        pictures[name] = np.load(out) if suffix == ".npy" else np.asarray(Image.open(out))
    np.testing.assert_array_equal(pictures["flags"], pictures["keys"])
    assert not np.array_equal(pictures["flags"], pictures["plain"])
    from embree_rt.film import Look, tonemap

    np.testing.assert_array_equal(pictures["plain"], tonemap(pictures["linear"]))  # look only
    np.testing.assert_array_equal(
        pictures["flags"], tonemap(pictures["linear"], Look(1.5, "aces", "srgb"))
    )
    line = one_line_error(
        run_cli("render", str(scene), "-o", str(tmp_path / "x.png"), "-D", "render.tonemap=filmic")
    )
    assert line.startswith("--set render.tonemap=filmic: render.tonemap: expected one of ")
    dark = tmp_path / "dark.toml"
    dark.write_text(SPHERE_ONLY)
    result = run_cli("render", str(dark), "-o", str(tmp_path / "dark.png"), *TINY, "--quiet")
    assert result.returncode == 0
    assert (
        result.stderr == f"embree-rt: warning: {dark}: lights: none: only the sky and "
        "ambient light show it\n"
    )


SPHERE_ONLY = "[[spheres]]\ncenter = [0.0, 1.0, 0.0]\nradius = 1.0\n"


# -- 5. papercuts -----------------------------------------------------------------------------


def test_info_into_a_closed_pipe_exits_quietly() -> None:
    """`embree-rt info scene.toml | head -1`: here the reader is gone before a line is
    written (head gone after its line is the same to the writer)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "embree_rt", "info", str(ROOT / "scenes" / "mesh_and_spheres.toml")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=ROOT,
    )
    process.stdout.close()
    stderr = process.stderr.read()
    process.wait(timeout=120)
    assert stderr == b""  # no traceback, no "this is a bug"
    assert process.returncode == 141  # as a process SIGPIPE ended (yes | head)


def test_info_prints_round_bounds_no_negative_memory_and_plurals_that_agree(
    tmp_path: Path,
) -> None:
    scene = tmp_path / "scene.toml"
    # float32 radii and centres that print as noise when widened to float64
    np.savez(
        tmp_path / "s.npz",
        centers=np.array([[0.1, 3.1, -0.7]], np.float32),
        radii=np.array([0.3], np.float32),
    )
    mesh = trimesh.creation.box()
    mesh.export(tmp_path / "box.ply")
    scene.write_text(
        '[[sphere_arrays]]\nfile = "s.npz"\n[[meshes]]\nfile = "box.ply"\n'
        "translate = [5.0, 0.5, 0.0]\n"
    )
    result = run_cli("info", str(scene))
    assert result.returncode == 0, result.stderr
    info = dict(line.split(":", 1) for line in result.stdout.splitlines() if ":" in line)
    assert info["bounds"].strip() == "[-0.2, 0, -1] .. [5.5, 3.4, 0.5]"
    assert info["meshes"].strip() == "1 placement of 1 distinct mesh"
    assert info["arrays"].strip() == "0 instance arrays holding 0 instances"
    measured = float(info["memory"].split(",")[1].split("MiB")[0])
    assert measured >= 0


def test_a_frame_pattern_makes_its_directories(tmp_path: Path) -> None:
    pattern = tmp_path / "shots" / "take1" / "f_{frame:04d}.png"
    result = run_cli(
        "render",
        str(ROOT / "scenes" / "animations" / "three_spheres_flight.toml"),
        "-o",
        str(pattern),
        *TINY,
        "--frames",
        "0:2",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "shots" / "take1").iterdir()) == [
        "f_0000.png",
        "f_0001.png",
        "transforms.json",
    ]


# -- start-up, prefixes, the flags random shares ------------------------------------------------


@pytest.mark.parametrize("line", [["--version"], ["--help"], ["render", "--help"]])
def test_version_and_help_load_neither_numpy_nor_numba(line: list[str]) -> None:
    """What ``python -X importtime`` lists, and what ``sys.modules`` holds after ``main``."""
    result = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "embree_rt", *line],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr
    imported = {
        row.rsplit("|", 1)[-1].strip()
        for row in result.stderr.splitlines()
        if row.startswith("import time:")
    }
    assert "embree_rt.cli.parser" in imported  # the listing does see the command's imports
    heavy = {"numpy", "numba", "trimesh", "distributed", "llvmlite"}
    assert {name for name in imported if name.split(".")[0] in heavy} == set()
    probe = (
        "import sys\nfrom embree_rt.cli import main\n"
        f"code = main({line!r})\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'numba'}))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.stdout.splitlines()[-1] == "[]", result.stdout + result.stderr


@pytest.mark.parametrize(
    ("line", "flag", "meant"),
    [
        (["render", "s.toml", "-o", "x.png", "--ao-dist", "2"], "--ao-dist", "--ao-distance"),
        (["random", "--count", "5", "-o", "x.png", "--inst", "m.obj"], "--inst", "--instance"),
        (["info", "s.toml", "--sphere", "mesh"], "--sphere", "--spheres"),
        (["serve", "--po", "0"], "--po", "--port"),
        (
            ["render", "s.toml", "-o", "x.png", "--scheduler-time", "3"],
            "--scheduler-time",
            "--scheduler-timeout",
        ),
    ],
)
def test_a_flag_is_never_read_from_its_prefix(
    capsys: pytest.CaptureFixture, line: list[str], flag: str, meant: str
) -> None:
    """``--ao-dist`` is not taken for ``--ao-distance``: a prefix that names one flag today
    could name another tomorrow. It is refused, with the flag it may have meant."""
    from embree_rt.cli import main

    assert main(line) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"unrecognized arguments: {flag}" in err, err
    assert f"(did you mean {meant!r}?)" in err


def test_random_takes_render_flags_no_floor_overwrite_and_frames(tmp_path: Path) -> None:
    """``--no-floor`` leaves out the field's floor (the bottom rows see the sky, as a field
    rendered bare does), ``--overwrite`` is taken, ``--frames`` is refused as for any still."""
    import embree_rt as rt
    from embree_rt.cli import main

    tiny = ["--width", "24", "--height", "12", "--spp", "1", "--quiet"]
    bare, floored = tmp_path / "bare.npy", tmp_path / "floored.npy"
    flags = ["random", "--count", "30", *tiny]
    assert main([*flags, "-o", str(bare), "--no-floor", "--overwrite"]) == 0
    assert main([*flags, "-o", str(floored)]) == 0
    field = rt.random_field(30, seed=0)
    field.render = field.render.with_overrides(width=24, height=12, spp=1)
    field.floor = None
    expected = rt.render(field).image  # the same field built in Python, without its floor
    assert np.array_equal(np.load(bare), expected)
    assert not np.array_equal(np.load(floored), expected)
    assert main([*flags, "-o", str(tmp_path / "x.png"), "--frames", "0:1"]) == 2
    assert not (tmp_path / "x.png").exists()
