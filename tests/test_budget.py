"""Inputs that cannot fit are refused up front: one line saying what they need and what the
machine has, exit code 2, nothing written, in about the time it takes to start the interpreter
(and with its memory: nothing was allocated). The estimates behind it are checked against the
peak memory that a field, a BVH and a render really add."""

from __future__ import annotations

import math
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from embree_rt import Scene, render
from embree_rt.budget import (
    FILM_BYTES_PER_PIXEL,
    SCENE_BYTES_PER_SPHERE,
    MemoryBudgetError,
    available_memory,
    field_bytes,
    format_bytes,
    geometry_bytes,
    image_bytes,
    require,
)
from embree_rt.integrator import DEFAULT_BATCH_SIZE

ROOT = Path(__file__).resolve().parent.parent
AVAILABLE = available_memory() or 0
# The inputs of issue 11, made bigger on a machine so big that they would fit there.
HUGE_COUNT = max(10_000_000_000, 10 * AVAILABLE // SCENE_BYTES_PER_SPHERE)
HUGE_FIELD = max(5_000_000_000, 10 * AVAILABLE // SCENE_BYTES_PER_SPHERE)
HUGE_SIDE = max(100_000, math.isqrt(10 * AVAILABLE // FILM_BYTES_PER_PIXEL))
HUGE_SIZE_FLAGS = ["--width", str(HUGE_SIDE), "--height", str(HUGE_SIDE)]
NEED = r"would need ~[\d.,]+ GB of memory, this machine has [\d.,]+ GB available"


def run_refused(folder: Path, *args: str) -> tuple[subprocess.CompletedProcess, float, int]:
    """Run ``embree-rt *args`` in ``folder``; returns the result, its wall seconds and its peak
    resident memory in bytes."""
    started = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "embree_rt", *args],
        cwd=folder,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    stdout, stderr = process.communicate(timeout=120)
    seconds = time.perf_counter() - started
    # ru_maxrss of the children waited for so far: the largest, which is this one at most
    # (the interpreters of the other runs are as small).
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    result = subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)
    return result, seconds, peak * 1024


CASES = {
    "random --count": (["random", "--count", str(HUGE_COUNT), "-o", "out.png"], None, "--count: "),
    "--width --height": (
        ["render", "scene.toml", "-o", "out.png", *HUGE_SIZE_FLAGS],
        "[[spheres]]\ncenter = [0.0, 1.0, 0.0]\nradius = 1.0\n"
        "[[lights]]\nposition = [2.0, 4.0, 2.0]\n",  # lit: no no-lights warning beside the error
        "--width 100000, --height 100000: ",
    ),
    "random_field.count": (
        ["render", "scene.toml", "-o", "out.png"],
        f"[random_field]\ncount = {HUGE_FIELD}\n",
        "scene.toml: random_field.count: ",
    ),
}


@pytest.mark.parametrize("name", list(CASES))
def test_an_input_that_cannot_fit_is_refused_up_front(name: str, tmp_path: Path) -> None:
    args, scene_text, key = CASES[name]
    if scene_text is not None:
        (tmp_path / "scene.toml").write_text(scene_text, encoding="utf-8")
    before = set(tmp_path.iterdir())
    result, seconds, peak = run_refused(tmp_path, *args)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"embree-rt: error: {key}"), lines[0]
    assert re.search(NEED, lines[0]), lines[0]
    assert result.stdout == ""
    assert set(tmp_path.iterdir()) == before  # no image, no temporary file
    # Refused before allocating: an interpreter's start-up time and memory (trimesh, numba and
    # Embree loaded), nowhere near the terabytes asked for.
    assert seconds < 30
    assert peak < 1.5e9


def test_the_api_refuses_too() -> None:
    scene = Scene()
    scene.add_sphere((0.0, 1.0, 0.0), 1.0)
    started = time.perf_counter()
    with pytest.raises(MemoryBudgetError, match=rf"a {HUGE_SIDE}x{HUGE_SIDE} image .*{NEED}"):
        render(scene, width=HUGE_SIDE, height=HUGE_SIDE, spp=1)
    assert time.perf_counter() - started < 1.0


def test_the_message_names_what_matters() -> None:
    error = MemoryBudgetError({"spheres": (10**9, "a billion"), "image": (10, "a speck")}, 2**30)
    assert str(error) == (
        "a billion would need ~1 GB of memory, this machine has 1.07 GB available"
    )
    assert error.largest == "spheres" and error.needed == 10**9 + 10
    assert format_bytes(8.8e11) == "880 GB" and format_bytes(5.12e8) == "0.512 GB"
    require({"nothing": (0, "nothing")})  # fits anywhere


MEASURE = """
import sys
from pathlib import Path
from embree_rt import Scene, render, save_image
from embree_rt.compiled import retain_freed_memory
from embree_rt.geometry import SceneGeometry
from embree_rt.scene import load_scene, random_field

MIRROR_ROOM = '''
floor = false
camera = {position = [0.0, 0.0, 0.0], look_at = [0.0, 0.0, -1.0]}
lights = [{position = [0.0, 2.0, 1.0]}]
materials.mirror = {reflectivity = 1.0}
spheres = [{center = [0.0, 0.0, 0.0], radius = 5.0, material = "mirror"}]
'''

def status(field):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024

phase, count, output = sys.argv[1], int(sys.argv[2]), sys.argv[3]
retain_freed_memory()  # as the renderer runs: freed arrays stay in the heap
tiny = Scene()
tiny.add_sphere((0.0, 1.0, 0.0), 1.0)
if phase == "image":
    # the most a batch holds: inside a closed mirror every ray hits and reflects at every depth
    room = Path(output).with_name("mirror_room.toml")
    room.write_text(MIRROR_ROOM)
    scene = load_scene(room)
else:
    scene = random_field(count) if phase in ("user", "point") else None
render(scene if phase == "image" else tiny, width=8, height=8, spp=1)  # kernels loaded first
before = status("VmRSS")
Path("/proc/self/clear_refs").write_text("5")  # reset the peak (VmHWM) to VmRSS
if phase == "field":
    random_field(count)
elif phase in ("user", "point"):
    SceneGeometry(scene, spheres="analytic" if phase == "user" else "point", threads=1).close()
else:  # what the command does with an image: render it and write a PNG
    save_image(render(scene, width=1920, height=1080, spp=1, threads=2).image, output)
print(status("VmHWM") - before)
"""


@pytest.mark.parametrize("phase", ["field", "user", "point", "image"])
def test_the_estimates_match_the_memory_really_used(phase: str, tmp_path: Path) -> None:
    """The peak memory that a 2e6-sphere field, its BVH (user geometry, point spheres) and a
    1920x1080 render written as a PNG add, each in a fresh process, against the estimate:
    within a factor of two either way."""
    count = 2_000_000
    result = subprocess.run(
        [sys.executable, "-c", MEASURE, phase, str(count), str(tmp_path / "image.png")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr
    grown = int(result.stdout.splitlines()[-1])
    estimate = {
        "field": field_bytes(count),
        "user": geometry_bytes(count, "user"),
        "point": geometry_bytes(count, "point"),
        "image": image_bytes(1920, 1080, 1, DEFAULT_BATCH_SIZE, workers=2),
    }[phase]
    assert 0.5 <= grown / estimate <= 2.0, (grown, estimate)


def test_info_estimates_the_bvh_from_the_budgets_figures(tmp_path: Path, capsys) -> None:
    """``embree-rt info`` and the budget read one table of bytes per sphere: the estimate it
    prints for a field of spheres is that table's figure for the kind they enter as."""
    from embree_rt import cli
    from embree_rt.budget import GEOMETRY_BYTES_PER_SPHERE

    count = 20_000
    scene_file = tmp_path / "field.toml"
    scene_file.write_text(f"[random_field]\ncount = {count}\n", encoding="utf-8")
    for spheres, kind in (("analytic", "user"), ("point", "point")):
        assert cli.main(["info", str(scene_file), "--spheres", spheres]) == 0
        out = capsys.readouterr().out
        estimate = re.search(r"memory: +BVH ~([\d.]+) MiB \(estimate\)", out)
        assert estimate is not None, out
        expected = count * GEOMETRY_BYTES_PER_SPHERE[kind] / 2**20
        assert float(estimate.group(1)) == pytest.approx(expected, abs=0.051)
