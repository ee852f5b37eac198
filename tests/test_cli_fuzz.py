"""A property-based fuzz of the command line itself (the loader's own is tests/test_scene_fuzz.py):
Hypothesis draws ``render`` and ``random`` command lines from the flags and values users type,
sensible and not (sizes of 0, -1, text for numbers, NaN, unknown names, a ``{frame}`` pattern
for a still, ``--partition`` without a cluster, keys that do not exist), and every one must end
in exactly one of two ways:

- exit code 0, and the image (and any AOV files) written; or
- exit code 2, exactly one line on stderr (``embree-rt: error: ...``), and nothing written.

Never a traceback, never another exit code. The command runs in this process (``cli.main``),
on images of at most 16x16 pixels, so the whole fuzz takes seconds.
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from embree_rt.cli import main

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "scenes" / "three_spheres.toml"

numbers = st.sampled_from(["-1", "0", "x", "1.5", "nan", "", "99999999999999999999999"])
small = st.integers(1, 16).map(str)
values = {
    "--width": st.one_of(small, numbers),
    "--height": st.one_of(small, numbers),
    "--spp": st.one_of(st.integers(1, 3).map(str), numbers),
    "--max-depth": st.one_of(st.integers(0, 3).map(str), numbers),
    "--seed": st.one_of(st.integers(0, 2**31).map(str), numbers),
    "--fov": st.sampled_from(["35", "0", "180", "179.9", "nan", "inf", "-5", "x"]),
    "--exposure": st.sampled_from(["0", "1", "-3", "nan", "1e39", "x"]),
    "--tonemap": st.sampled_from(["reinhard", "aces", "none", "filmic", ""]),
    "--transfer": st.sampled_from(["gamma2.2", "srgb", "linear"]),
    "--bit-depth": st.sampled_from(["8", "16", "12", "x"]),
    "--quality": st.sampled_from(["1", "90", "100", "0", "101", "x"]),
    "--aov": st.sampled_from(["depth", "depth,normal", "albedo,object_id", "deep", "", ","]),
    "--spheres": st.sampled_from(["analytic", "point", "mesh", "cubes"]),
    "--threads": st.sampled_from(["1", "2", "0", "x"]),
    "--frames": st.sampled_from(["0:1", "0", "x"]),
    "--partition": st.sampled_from(["2", "0"]),
    "--scheduler-timeout": st.sampled_from(["1", "0", "nan"]),
    "--set": st.sampled_from(
        [
            "camera.fov=40",
            "render.max_depth=2",
            "lights[0].intensity=2",
            "render.width=8",
            "render.width=-4",
            "floor.height=nan",
            "materials.gold.shininess=200",
            "nonsense.key=1",
            "novalue",
            "=3",
        ]
    ),
    "--camera-position": st.sampled_from(["0 1 5", "0 0 0", "nan 1 2", "1 2"]),
    "--look-at": st.sampled_from(["0 1 0", "0 1 5", "x y z"]),
}
switches = ["--no-floor", "--overwrite", "--quiet"]
outputs = st.sampled_from(
    ["out.png", "out.npy", "out.npz", "out.jpg", "out.tif", "out.webp", "out.gif", "out",
     "f_{frame}.png", "sub/out.png", "out.{x}.png"]
)  # fmt: skip


@st.composite
def command_lines(draw) -> list[str]:
    """A ``render`` or ``random`` command line with a few flags, in any order."""
    if draw(st.booleans()):
        line = ["render", str(SCENE)]
    else:
        line = ["random", "--count", draw(st.sampled_from(["1", "12", "40", "0", "x"]))]
    line += ["-o", draw(outputs)]
    # small images unless a flag asks otherwise: the fuzz must stay quick
    line += ["--width", "12", "--height", "8", "--spp", "1"]
    for flag in draw(st.lists(st.sampled_from(sorted(values)), max_size=4, unique=True)):
        value = draw(values[flag])
        line += (
            [flag, *value.split(" ")]
            if flag in ("--camera-position", "--look-at")
            else [
                flag,
                value,
            ]
        )
    line += draw(st.lists(st.sampled_from(switches), max_size=2, unique=True))
    return line


def run(line: list[str], folder: Path) -> tuple[int, str]:
    """``main(line)`` run from ``folder``: the exit code and what it printed on stderr."""
    stderr, stdout = io.StringIO(), io.StringIO()
    previous = Path.cwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(stdout):
            code = main(line)
    finally:
        os.chdir(previous)
    return code, stderr.getvalue()


@settings(
    max_examples=100,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(line=command_lines())
def test_any_command_line_renders_or_is_one_line_exit_2(line: list[str]) -> None:
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        code, stderr = run(line, folder)
        written = sorted(str(path.relative_to(folder)) for path in folder.rglob("*"))
        assert "Traceback" not in stderr, stderr
        assert code in (0, 2), (code, stderr)
        event(f"exit {code}")  # --hypothesis-show-statistics counts them
        if code == 2:
            assert stderr.count("\n") == 1 and stderr.startswith("embree-rt: error: "), stderr
            assert written == [], written  # no image, no temporary file, no directory
            return
        output = line[line.index("-o") + 1]
        assert output in written, (written, stderr)
        if output.endswith(".npy"):
            image = np.load(folder / output)
            assert np.isfinite(image).all()
