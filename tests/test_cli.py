"""The ``embree-rt`` command, run for real in a subprocess.

Bad input: exit code 2, exactly one stderr line ``embree-rt: error: ...`` naming the file and the
key, no traceback, no output file, an existing image left byte for byte. Good input: PNG and NPY
images of the asked size (the PNG is the NPY tone-mapped by Reinhard and gamma 2.2, computed here),
``info`` counts that match the scene file, a million-sphere field, ``--save-scene``, and Ctrl-C
(exit 130, old image intact, no temp file left). A bug (any other exception, whatever its type):
a traceback, a request for a report, exit code 1.
"""

from __future__ import annotations

import errno
import importlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from embree_rt import load_scene, random_field
from embree_rt.cli import YOUNG_COLLECTION_OBJECTS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
TINY = ["--width", "16", "--height", "9", "--spp", "1"]
SPHERE = "[[spheres]]\ncenter = [0.0, 1.0, 0.0]\nradius = 1.0\n"
SECOND_SPHERE = "[[spheres]]\ncenter = [2.0, 0.5, 0.0]\n"


def run_cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


# -- bad input ------------------------------------------------------------------------------------


@dataclass
class Case:
    """One bad input: the scene file to write (``text`` None: leave it missing), the output name,
    extra flags, and the strings the one error line must contain."""

    scene: str
    text: str | None
    needles: list[str]
    output: str = "out.png"
    flags: list[str] = field(default_factory=list)


def _nan_json() -> str:
    # json.dumps writes the NaN literal that Python's (and many tools') JSON readers accept
    spheres = [{"center": [0, 1, 0], "radius": 1}, {"center": [2, 1, 0], "radius": float("nan")}]
    return json.dumps({"spheres": spheres})


CASES = {
    "missing scene file": Case("absent.toml", None, ["absent.toml", "no such file"]),
    "malformed toml": Case(
        "scene.toml", "[render\nwidth = 16\n", ["scene.toml", "(syntax)", "line 1"]
    ),
    "malformed json": Case(
        "scene.json", '{"render": {"width": 16,}}', ["scene.json", "(syntax)", "line 1"]
    ),
    "json top level not a table": Case("scene.json", "[1, 2]", ["scene.json", "(top level)"]),
    "unknown key": Case(
        "scene.toml", "[render]\nwidht = 16\n", ["render.widht", "did you mean 'width'"]
    ),
    "unknown section": Case(
        "scene.toml", "[camra]\nfov = 30\n", ["camra", "did you mean 'camera'"]
    ),
    "wrong type": Case(
        "scene.toml", SPHERE + SECOND_SPHERE + 'radius = "big"\n', ["spheres[1].radius", "'big'"]
    ),
    "negative radius": Case(
        "scene.toml", SPHERE + SECOND_SPHERE + "radius = -0.5\n", ["spheres[1].radius", ">= 1e-18"]
    ),
    "nan in json": Case("scene.json", _nan_json(), ["scene.json", "spheres[1].radius", "finite"]),
    "nan in toml": Case(
        "scene.toml",
        "[[spheres]]\ncenter = [0, nan, 0]\nradius = 1\n",
        ["spheres[0].center", "finite"],
    ),
    "fov zero": Case("scene.toml", "[camera]\nfov = 0\n", ["camera.fov", "> 0"]),
    # (not spp or width: the runs' own --spp and --width replace the file's value before it is
    # checked, as --set render.spp=1 would)
    "max_depth -1 in file": Case(
        "scene.toml", "[render]\nmax_depth = -1\n", ["render.max_depth", ">= 0"]
    ),
    "seed -1 in file": Case("scene.toml", "[render]\nseed = -1\n", ["render.seed", ">= 0"]),
    "width -1 flag": Case("scene.toml", SPHERE, ["--width", "-1"], flags=["--width", "-1"]),
    "undefined material": Case(
        "scene.toml", SPHERE + 'material = "nope"\n', ["spheres[0].material", "'nope'"]
    ),
    "unknown preset": Case(
        "scene.toml", '[materials.x]\npreset = "velvet"\n', ["materials.x.preset", "velvet"]
    ),
    "missing mesh": Case(
        "scene.toml",
        '[[meshes]]\nfile = "nowhere.obj"\n',
        ["meshes[0].file", "nowhere.obj", "no such file"],
    ),
    "garbage ply": Case(
        "scene.toml",
        SPHERE + '[[meshes]]\nfile = "garbage.ply"\n',
        ["meshes[0].file", "garbage.ply"],
    ),
    "face index out of range": Case(
        "scene.toml", '[[meshes]]\nfile = "bad_index.ply"\n', ["meshes[0].file", "bad_index.ply"]
    ),
    "empty mesh": Case(
        "scene.toml",
        '[[meshes]]\nfile = "empty.obj"\n',
        ["meshes[0].file", "empty.obj", "no triangles"],
    ),
    "npz without radii": Case(
        "scene.toml",
        '[[sphere_arrays]]\nfile = "no_radii.npz"\n',
        ["sphere_arrays[0].file", "no_radii.npz", "radii"],
    ),
    "output in a missing directory": Case(
        "scene.toml", SPHERE, ["missing_dir", "does not exist"], output="missing_dir/out.png"
    ),
    "unknown output extension": Case("scene.toml", SPHERE, ["out.bmp", ".bmp"], output="out.bmp"),
}

# Cases that also run with an image already at the output path, one per stage that can fail:
# flags, output path, syntax, validation, mesh import.
OVERWRITE_CASES = [
    "width -1 flag",
    "unknown output extension",
    "malformed toml",
    "negative radius",
    "garbage ply",
    "face index out of range",
]


def write_bad_inputs(folder: Path) -> None:
    """The files the bad scenes point at."""
    (folder / "garbage.ply").write_bytes(b"ply\nformat ascii 1.0\n\x00\xff\xfe garbage \x01\x02")
    # a face that names vertex 7 of 3: trimesh loads it without complaint
    (folder / "bad_index.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"
    )
    (folder / "empty.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    np.savez(folder / "no_radii.npz", centers=np.zeros((4, 3)))


@dataclass
class BadRun:
    """One bad-input run: the CLI's answer, the files around it before, the output path and
    (when an image was there first) its bytes."""

    result: subprocess.CompletedProcess
    folder: Path
    scene: Path
    output: Path
    files_before: set[Path]
    image_before: bytes | None


def bad_run(name: str, folder: Path, existing_image: bool) -> BadRun:
    case = CASES[name]
    write_bad_inputs(folder)
    scene = folder / case.scene
    if case.text is not None:
        scene.write_text(case.text, encoding="utf-8")
    output = folder / case.output
    image_before = None
    if existing_image:
        Image.new("RGB", (5, 3), (10, 20, 30)).save(output, format="PNG")
        image_before = output.read_bytes()
    files_before = set(folder.rglob("*"))
    result = run_cli("render", str(scene), "-o", str(output), *TINY, *case.flags, "--quiet")
    return BadRun(result, folder, scene, output, files_before, image_before)


@pytest.fixture(scope="module")
def bad_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, bool], BadRun]:
    """Every bad-input run, two at a time: each is a fresh interpreter that spends most of its
    second importing trimesh, and two cores can do two of those at once."""
    jobs = [(name, False) for name in CASES] + [(name, True) for name in OVERWRITE_CASES]
    folders = [tmp_path_factory.mktemp("bad") for _ in jobs]
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = pool.map(lambda job, folder: bad_run(job[0], folder, job[1]), jobs, folders)
        return dict(zip(jobs, runs, strict=True))


def assert_one_line_error(result: subprocess.CompletedProcess, needles: list[str]) -> None:
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("embree-rt: error: ")
    for needle in needles:
        assert needle in lines[0], f"{needle!r} missing from {lines[0]!r}"
    assert result.stdout == ""


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_is_one_line_exit_2_and_writes_nothing(name: str, bad_runs) -> None:
    run = bad_runs[name, False]
    assert_one_line_error(run.result, CASES[name].needles)
    assert not run.output.exists()
    assert set(run.folder.rglob("*")) == run.files_before  # nothing new: no image, no temp file


@pytest.mark.parametrize("name", OVERWRITE_CASES)
def test_bad_input_leaves_an_existing_image_alone(name: str, bad_runs) -> None:
    run = bad_runs[name, True]
    assert_one_line_error(run.result, CASES[name].needles)
    assert run.output.read_bytes() == run.image_before
    assert set(run.folder.rglob("*")) == run.files_before


def test_usage_errors_are_one_line_too(tmp_path: Path) -> None:
    assert_one_line_error(run_cli("render"), ["required", "scene", "--output"])
    assert_one_line_error(
        run_cli("random", "--count", "0", "-o", str(tmp_path / "x.png")), ["--count"]
    )
    assert not (tmp_path / "x.png").exists()


# -- good input -----------------------------------------------------------------------------------


def reinhard_gamma(linear: np.ndarray) -> np.ndarray:
    """(h, w, 3) linear radiance → uint8 the way the seed article maps it: c / (1 + c), ^(1/2.2)."""
    mapped = (np.maximum(linear, 0) / (1 + np.maximum(linear, 0))) ** (1 / 2.2)
    return np.clip(np.rint(mapped * 255), 0, 255).astype(np.uint8)


def test_render_writes_png_and_npy_of_the_asked_size(tmp_path: Path) -> None:
    scene = ROOT / "scenes" / "three_spheres.toml"
    size = ["--width", "32", "--height", "18", "--spp", "1"]
    png, npy = tmp_path / "x.png", tmp_path / "x.npy"
    result = run_cli("render", str(scene), "-o", str(png), *size)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    with Image.open(png) as image:
        assert image.format == "PNG" and image.size == (32, 18) and image.mode == "RGB"
        pixels = np.asarray(image)
    assert run_cli("render", str(scene), "-o", str(npy), *size, "--quiet").returncode == 0
    linear = np.load(npy)
    assert linear.shape == (18, 32, 3) and linear.dtype == np.float32
    assert np.isfinite(linear).all() and (linear >= 0).all()
    assert linear.std() > 0.01  # an image, not a blank
    # same scene and seed: the PNG is exactly the NPY tone-mapped (off by one at most: rounding)
    difference = np.abs(pixels.astype(int) - reinhard_gamma(linear).astype(int))
    assert difference.max() <= 1
    assert not list(tmp_path.glob(".x.*"))  # no temp files left behind


def expected_counts(scene_file: Path) -> dict[str, int]:
    """Spheres, placements, distinct meshes and triangles of a scene file, counted from the
    file itself with trimesh (a glTF places one mesh per node)."""
    document = tomllib.loads(scene_file.read_text(encoding="utf-8"))
    files: dict[Path, list[tuple[str, int]]] = {}
    placements = placed_triangles = 0
    for entry in document.get("meshes", []):
        path = (scene_file.parent / entry["file"]).resolve()
        if path not in files:
            loaded = trimesh.load(str(path), process=False)
            if isinstance(loaded, trimesh.Scene):
                nodes = loaded.graph.nodes_geometry
                geometry = [loaded.graph[n][1] for n in nodes]
                files[path] = [(f"{path}:{g}", len(loaded.geometry[g].faces)) for g in geometry]
            else:
                files[path] = [(str(path), len(loaded.faces))]
        placements += len(files[path])
        placed_triangles += sum(faces for _, faces in files[path])
    distinct = dict(item for parts in files.values() for item in parts)
    return {
        "spheres": len(document.get("spheres", [])),
        "placements": placements,
        "distinct": len(distinct),
        "stored": sum(distinct.values()),
        "placed": placed_triangles,
        "lights": len(document.get("lights", [])),
    }


def test_info_counts_what_the_file_holds() -> None:
    scene_file = ROOT / "scenes" / "mesh_and_spheres.toml"
    expected = expected_counts(scene_file)
    # the file has 16 [[meshes]] entries, one of them the three-node trio.glb
    assert scene_file.read_text().count("[[meshes]]") + 2 == expected["placements"]
    console_script = Path(sys.executable).with_name("embree-rt")
    result = subprocess.run(
        [str(console_script), "info", str(scene_file)], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    lines = dict(line.split(":", 1) for line in result.stdout.splitlines())
    info = {key.strip(): value.strip() for key, value in lines.items()}
    assert info["spheres"] == f"{expected['spheres']:,}"
    assert info["instances"] == f"{expected['placements']:,}"
    assert info["meshes"] == (
        f"{expected['placements']:,} placements of {expected['distinct']:,} distinct meshes"
    )
    assert info["triangles"] == f"{expected['stored']:,} stored, {expected['placed']:,} placed"
    assert info["lights"] == str(expected["lights"])
    assert info["floor"] == "y = 0"
    # a count agrees with the list it heads: the scene's materials and the floor's
    listed = [line for line in result.stdout.splitlines() if line.startswith("  material ")]
    assert info["materials"] == str(len(listed))
    assert any(line.endswith(": floor") for line in listed)
    assert re.fullmatch(
        r"BVH ~[\d.]+ MiB \(estimate\), [\d.]+ MiB measured \(resident set growth while "
        r"building, compiling left out\); scene [\d.]+ MiB \(its arrays\)",
        info["memory"],
    ), info["memory"]


def test_the_compile_clock_hears_each_compile_once_and_says_so_once(capsys) -> None:
    from numba import njit

    from embree_rt.cli.clock import CompileClock

    clock = CompileClock(notice="compiling")
    with clock.listening():
        add = njit(lambda x: x + 1)  # no cache: compiled at its first call, for each type
        assert add(1) == 2 and add(2) == 3
        assert add(1.5) == 2.5
    assert add(True) == 2  # compiled after listening: not heard
    assert len(clock.intervals) == 2  # int, then float: a call of a compiled type is not one
    assert all(end > start for start, end in clock.intervals)
    assert clock.seconds() == pytest.approx(sum(end - start for start, end in clock.intervals))
    start, end = clock.intervals[0]
    assert clock.seconds(start, (start + end) / 2) == pytest.approx((end - start) / 2)
    assert capsys.readouterr().err == "compiling\n"  # once, at the first


def test_info_says_compile_time_apart_from_the_build(
    monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """A build that compiles a kernel (as a fresh install's first does): the compile is its
    own line, and the build's time is the rest."""
    from numba import njit

    from embree_rt import cli
    from embree_rt.cli import info

    real = info.SceneGeometry

    def compiling_first(*args, **kwargs):
        assert njit(lambda x: x * 3)(2) == 6  # compiled here, inside the build
        return real(*args, **kwargs)

    monkeypatch.setattr(info, "SceneGeometry", compiling_first)
    started = time.perf_counter()
    assert cli.main(["info", str(ROOT / "scenes" / "three_spheres.toml")]) == 0
    elapsed = time.perf_counter() - started
    lines = dict(line.split(":", 1) for line in capsys.readouterr().out.splitlines())
    compile_s = float(lines["compile"].split()[0])
    build_s = float(lines["BVH build"].split()[0])
    assert compile_s > 0 and compile_s + build_s < elapsed


def test_a_million_sphere_field_renders(tmp_path: Path) -> None:
    output = tmp_path / "out.png"
    result = run_cli(
        "random",
        "--count",
        "1000000",
        "-o",
        str(output),
        "--width",
        "64",
        "--height",
        "36",
        "--spp",
        "1",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    with Image.open(output) as image:
        assert image.size == (64, 36)
        assert np.asarray(image).std() > 1  # not blank


def test_save_scene_writes_the_generated_field(tmp_path: Path) -> None:
    saved, first, second = tmp_path / "s.toml", tmp_path / "a.npy", tmp_path / "b.npy"
    result = run_cli(
        "random", "--count", "500", "--save-scene", str(saved), "-o", str(first), *TINY, "--quiet"
    )
    assert result.returncode == 0, result.stderr
    loaded = load_scene(saved)
    assert len(loaded.sphere_radii) == 500
    reference = random_field(500, seed=0)  # the command's default seed
    np.testing.assert_array_equal(loaded.sphere_centers, reference.sphere_centers)
    np.testing.assert_array_equal(loaded.sphere_radii, reference.sphere_radii)
    # Rendering the saved file gives the very image the random command rendered. Bitwise, on
    # any ISA: both renders run on one machine from the same float32 spheres and the same
    # camera, lights and materials (TOML writes every float so that it reads back exactly),
    # so they perform the same float operations on the same values.
    assert run_cli("render", str(saved), "-o", str(second), *TINY, "--quiet").returncode == 0
    np.testing.assert_array_equal(np.load(first), np.load(second))


def test_bad_save_scene_target_writes_nothing(tmp_path: Path) -> None:
    output = tmp_path / "out.png"
    result = run_cli(
        "random",
        "--count",
        "10",
        "--save-scene",
        str(tmp_path / "s.yaml"),
        "-o",
        str(output),
        *TINY,
        "--quiet",
    )
    assert_one_line_error(result, ["--save-scene", "s.yaml"])
    assert list(tmp_path.iterdir()) == []


# -- Ctrl-C ---------------------------------------------------------------------------------------


def wait_until_busy(pid: int, cpu_seconds: float, timeout: float = 60.0) -> None:
    """Wait until process ``pid`` has used ``cpu_seconds`` of CPU (all threads), or has ended.

    Imports, generating 200k spheres and the BVH take about 1.5 CPU seconds; a fixed wall-clock
    wait would be too short on a busy machine and interrupt the imports instead of the render."""
    ticks = os.sysconf("SC_CLK_TCK")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except FileNotFoundError:
            return
        if fields[0] == "Z":  # ended, not yet reaped
            return
        if (int(fields[11]) + int(fields[12])) / ticks >= cpu_seconds:  # utime + stime
            return
        time.sleep(0.1)


# -- bad input or a bug: which is which -----------------------------------------------------------


def test_a_ctrl_c_raised_inside_a_c_callback_still_ends_the_command(capfd) -> None:
    """A Ctrl-C whose KeyboardInterrupt is raised in a Python function C code called (ctypes
    swallows it, "Exception ignored": llvmlite's callbacks as numba compiles the first render's
    kernels) is raised again once the callback has returned, though more such callbacks follow
    (a compilation makes many), and nothing is printed of the swallowed one."""
    import ctypes

    from embree_rt.cli.errors import interrupting_signals

    @ctypes.CFUNCTYPE(None)
    def interrupted_callback() -> None:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)  # the handler runs here, inside the callback

    @ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_int)
    def busy_callback(n: int) -> int:
        return sum(range(n))

    handlers = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}
    callbacks_after = 0
    try:
        with pytest.raises(KeyboardInterrupt), interrupting_signals():
            interrupted_callback()
            while callbacks_after < 100_000:  # seconds of callbacks, if it is never raised
                busy_callback(100)
                callbacks_after += 1
    finally:
        for number, handler in handlers.items():
            signal.signal(number, handler)
    assert callbacks_after < 100_000
    assert capfd.readouterr().err == ""


def _one_sphere_scene(folder: Path) -> Path:
    scene = folder / "scene.toml"
    # lit: a scene without lights would add a warning line to the stderr these tests read
    scene.write_text(SPHERE + "[[lights]]\nposition = [3.0, 5.0, 4.0]\n", encoding="utf-8")
    return scene


def _fail_with(error: BaseException):
    def fail(*args, **kwargs):
        raise error

    return fail


# What a bug deep inside embree_rt may raise; none of it is the user's to fix.
BUGS = {
    "ValueError": ValueError("operands could not be broadcast together"),
    "RuntimeError": RuntimeError("Embree failed in rtcCommitScene: invalid argument"),
    "OSError": OSError(5, "Input/output error"),
    "KeyError": KeyError("pixel"),
    "TypeError": TypeError("unsupported operand"),
}
# Where each command meets the bug: (command line, (module, attribute) to break), the attribute
# broken in the module that calls it.
BROKEN_STAGES = {
    "render": (["render", "{scene}", "-o", "{out}"], ("embree_rt.cli.render", "render")),
    "random": (["random", "--count", "5", "-o", "{out}"], ("embree_rt.cli.render", "render")),
    "random field": (
        ["random", "--count", "5", "-o", "{out}"],
        ("embree_rt.cli.sources", "add_field_spheres"),
    ),
    "info": (["info", "{scene}"], ("embree_rt.cli.info", "SceneGeometry")),
}


@pytest.mark.parametrize("stage", sorted(BROKEN_STAGES))
@pytest.mark.parametrize("bug", sorted(BUGS))
def test_a_bug_is_reported_as_a_bug_exit_1_not_as_bad_input(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys, stage: str, bug: str
) -> None:
    from embree_rt import cli

    line, (module, attribute) = BROKEN_STAGES[stage]
    monkeypatch.setattr(importlib.import_module(module), attribute, _fail_with(BUGS[bug]))
    out = tmp_path / "out.png"
    values = {"scene": str(_one_sphere_scene(tmp_path)), "out": str(out)}
    argv = [part.format(**values) for part in line]
    code = cli.main([*argv, *([*TINY, "--quiet"] if argv[0] != "info" else [])])
    err = capsys.readouterr().err
    assert code == cli.EXIT_BUG == 1, err
    assert "Traceback (most recent call last)" in err and f"{bug}: " in err
    assert err.splitlines()[-1] == cli.BUG_REPORT
    assert "embree-rt: error:" not in err
    assert not out.exists()


def test_a_failed_write_of_the_image_is_bad_input(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    import errno

    from embree_rt import cli, film

    monkeypatch.setitem(film.WRITERS, ".png", _fail_with(OSError(errno.ENOSPC, "No space left")))
    out = tmp_path / "out.png"
    code = cli.main(["render", str(_one_sphere_scene(tmp_path)), "-o", str(out), *TINY, "--quiet"])
    err = capsys.readouterr().err
    assert code == cli.EXIT_BAD_INPUT
    assert err == f"embree-rt: error: {out}: cannot write: No space left\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]  # no image, no temp file


def test_a_failed_write_of_the_saved_scene_is_bad_input(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    from embree_rt import cli
    from embree_rt.cli import sources

    # where the command calls it
    monkeypatch.setattr(sources, "save_scene", _fail_with(PermissionError(13, "Permission denied")))
    saved, out = tmp_path / "field.toml", tmp_path / "out.png"
    code = cli.main(
        ["random", "--count", "5", "--save-scene", str(saved), "-o", str(out), *TINY, "--quiet"]
    )
    assert code == cli.EXIT_BAD_INPUT
    assert (
        capsys.readouterr().err == f"embree-rt: error: {saved}: cannot write: Permission denied\n"
    )
    assert not out.exists()


def test_a_field_the_flags_ask_for_but_cannot_have_is_bad_input(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    from embree_rt import cli
    from embree_rt.scene.random_field import FieldParameterError

    refusal = FieldParameterError("count", "needs 80 GB, the machine has 8")
    sources = importlib.import_module("embree_rt.cli.sources")
    monkeypatch.setattr(sources, "plan_field", _fail_with(refusal))  # where the command plans it
    out = tmp_path / "out.png"
    code = cli.main(["random", "--count", "5", "-o", str(out), *TINY, "--quiet"])
    assert code == cli.EXIT_BAD_INPUT
    assert capsys.readouterr().err == "embree-rt: error: --count: needs 80 GB, the machine has 8\n"


def test_an_embree_library_that_is_not_there_is_bad_input(tmp_path: Path) -> None:
    out = tmp_path / "out.png"
    result = subprocess.run(
        [sys.executable, "-m", "embree_rt", "random", "--count", "5", "-o", str(out), *TINY],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        env={**os.environ, "EMBREE_RT_LIBRARY": str(tmp_path / "libembree4.so.4")},
    )
    assert_one_line_error(result, ["EMBREE_RT_LIBRARY", "libembree4.so.4", "no such file"])
    assert not out.exists()


def test_the_summary_line_splits_the_whole_wall_time(tmp_path: Path) -> None:
    """The command's whole time, from the process's start, split into start-up, compile, making
    the scene (generating the field, or loading the file), the BVH, rendering and output: the
    parts add up to the total (each rounded to 0.01 s), and the total is the process's wall time
    as the caller measures it, less only the interpreter's exit."""
    runs = {}
    for made, line in {
        "generate": ["random", "--count", "20000", "-o", str(tmp_path / "a.png"), *TINY],
        "load": [
            "render",
            str(ROOT / "scenes" / "three_spheres.toml"),
            "-o",
            str(tmp_path / "b.png"),
            *TINY,
        ],
    }.items():
        started = time.perf_counter()
        result = run_cli(*line)
        runs[made] = (result, time.perf_counter() - started)
    for made, (result, wall_s) in runs.items():
        assert result.returncode == 0, result.stderr
        line = result.stderr.strip()
        match = re.fullmatch(
            rf"embree-rt: 16x9 at 1 spp in ([\d.]+) s \(start-up ([\d.]+) s, compile ([\d.]+) s, "
            rf"{made} ([\d.]+) s, BVH ([\d.]+) s, render ([\d.]+) s, output ([\d.]+) s\): "
            r"[\d,]+ rays, [\d.]+ Mrays/s -> .+\.png",
            line,
        )
        assert match, line
        total, startup, *parts = (float(value) for value in match.groups())
        assert min(parts) >= 0 and abs(startup + sum(parts) - total) <= 0.035, line
        # start-up is the interpreter and the imports: never nothing, never the whole
        assert 0.01 < startup < total, line
        # the process's clock ticks are 10 ms; exiting (threads joined, caches closed) is not in it
        assert total <= wall_s + 0.02 and wall_s - total < 1.5, (line, wall_s)


def test_the_command_leaves_its_objects_to_the_exit_and_a_caller_s_run_does_not(
    tmp_path: Path,
) -> None:
    """``main()`` for the process's own arguments (the command) freezes what it made
    (``gc.freeze``: the interpreter's exit then skips collecting it) and collects the youngest
    generation less often; ``main(argv)`` from a caller that goes on (a test, a notebook)
    leaves the collector as it was. Each in a fresh
    interpreter, whose collector has frozen nothing before."""
    line = ["random", "--count", "50", *TINY, "--quiet", "-o"]
    for argv, frozen in ((None, True), ("given", False)):
        out = str(tmp_path / f"{argv}.png")
        script = (
            "import gc, sys\n"
            "from embree_rt.cli import main\n"
            f"sys.argv = ['embree-rt', *{line!r}, {out!r}]\n"
            "assert gc.get_freeze_count() == 0\n"
            f"code = main() if {argv is None} else main(sys.argv[1:])\n"
            "print(code, gc.get_freeze_count() > 0, gc.get_threshold()[0])\n"
        )
        done = subprocess.run(
            [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr
        young = YOUNG_COLLECTION_OBJECTS if frozen else 700  # Python's own, left as it was
        assert done.stdout.split() == ["0", str(frozen), str(young)], (argv, done.stdout)
        assert Path(out).is_file()


def test_the_sphere_flag_offers_exactly_the_geometry_modes() -> None:
    """The command spells the modes out (so --help loads no Embree): they must be the same."""
    from embree_rt import cli, geometry

    assert cli.SPHERE_CHOICES == geometry.SPHERE_MODES


# -- SIGTERM, long names, full disks --------------------------------------------------------------


def name_max(folder: Path) -> int:
    return os.pathconf(folder, "PC_NAME_MAX")


@pytest.mark.parametrize("over", ["the name", "its temporary name"])
def test_an_output_name_too_long_for_the_file_system_is_refused_up_front(
    tmp_path: Path, over: str
) -> None:
    """A name over the limit fails with ENAMETOOLONG; one within it by fewer bytes than the
    temporary name adds (``.NAME.<16 hex>.tmp``) is refused before rendering too, saying why
    (it would otherwise fail once the image is rendered)."""
    stem = "x" * (name_max(tmp_path) + 1 if over == "the name" else name_max(tmp_path) - 10)
    output = tmp_path / f"{stem}.npy"
    result = run_cli("render", str(_one_sphere_scene(tmp_path)), "-o", str(output), *TINY)
    reason = os.strerror(errno.ENAMETOOLONG) if over == "the name" else "temporary name"
    assert_one_line_error(result, [reason])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


def test_a_npy_write_to_a_full_device_says_no_space_left(tmp_path: Path) -> None:
    """/dev/full fails every write with ENOSPC, as a full disk does: the error keeps its errno
    (NumPy's ``tofile`` would report "N requested and M written" with none)."""
    from embree_rt import film

    image = np.ones((64, 64, 3), np.float32)  # 48 KiB: more than the file's buffer
    aov_file = lambda image, handle: film.save_npy(image[..., 0], handle)  # noqa: E731
    for write in (film.WRITERS[".npy"], aov_file):
        # the write or the close that flushes it fails
        with pytest.raises(OSError) as caught, open("/dev/full", "wb") as handle:
            write(image, handle)
        assert caught.value.errno == errno.ENOSPC
        assert caught.value.strerror == os.strerror(errno.ENOSPC)


def test_a_file_size_limit_is_said_with_its_errno(tmp_path: Path) -> None:
    """The command under RLIMIT_FSIZE (SIGXFSZ ignored, so writes past it fail with EFBIG):
    the one error line gives the system's reason, not a count of bytes written."""
    import resource

    def limit_file_size() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (64 << 10, 64 << 10))

    output = tmp_path / "out.npy"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "embree_rt",
            "render",
            str(_one_sphere_scene(tmp_path)),
            "-o",
            str(output),
            "--width",
            "128",
            "--height",
            "128",
            "--spp",
            "1",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        preexec_fn=limit_file_size,
    )
    assert result.returncode == 2, result.stderr
    reason = os.strerror(errno.EFBIG)
    assert result.stderr == f"embree-rt: error: {output}: cannot write: {reason}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]


# -- flag values beyond what a render can number or hold -------------------------------------------

THREE_SPHERES = str(ROOT / "scenes" / "three_spheres.toml")  # 1280x720 in its file
HUGE_FLAGS = {
    "spp beyond int64": (
        ["render", THREE_SPHERES, "--spp", str(2**63)],
        ["--spp 9223372036854775808: render.spp: must be <= 9223372036854775807"],
    ),
    "seed beyond uint64": (
        ["render", THREE_SPHERES, "--seed", str(2**64)],
        ["--seed 18446744073709551616: render.seed: must be <= 18446744073709551615"],
    ),
    "samples beyond int64 with the file's size": (
        ["render", THREE_SPHERES, "--spp", str(2**62)],
        [
            "--spp 4611686018427387904: render.spp: a 1280x720 image at 4611686018427387904 spp",
            "more than",
            "int64",
        ],
    ),
    "samples beyond int64, the width a flag": (
        ["random", "--count", "5", "--width", str(2**62), "--height", "4"],
        ["render.spp: a 4611686018427387904x4 image", "int64"],
    ),
    "one pixel of 2**62 samples": (
        ["render", THREE_SPHERES, "--spp", str(2**62), "--width", "1", "--height", "1"],
        [
            "--spp 4611686018427387904: the samples in flight at 4611686018427387904 spp would",
            "available",
        ],
    ),
    "one pixel of 1e11 samples, random": (
        ["random", "--count", "5", "--spp", str(10**11), "--width", "1", "--height", "1"],
        ["--spp 100000000000: the samples in flight at 100000000000 spp would need", "available"],
    ),
}


@pytest.mark.parametrize("case", sorted(HUGE_FLAGS))
def test_flag_values_beyond_what_a_render_can_number_or_hold_are_refused(
    tmp_path: Path, case: str
) -> None:
    """Checked once the flags override the file's settings, before anything is allocated: a
    pixel's samples all go in one batch, so a million-billion of them is refused for memory."""
    argv, needles = HUGE_FLAGS[case]
    output = tmp_path / "out.npy"
    result = run_cli(*argv, "-o", str(output), "--quiet", timeout=60)
    assert_one_line_error(result, needles)
    assert list(tmp_path.iterdir()) == []


def test_a_file_asking_one_pixel_too_many_samples_is_blamed_on_its_spp(tmp_path: Path) -> None:
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f"[render]\nwidth = 1\nheight = 1\nspp = {10**12}\n[[lights]]\nposition = [0, 5, 0]\n"
        + SPHERE
    )
    result = run_cli("render", str(scene), "-o", str(tmp_path / "out.npy"), "--quiet")
    assert_one_line_error(result, [f"{scene}: render.spp: the samples in flight", "would need"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]
