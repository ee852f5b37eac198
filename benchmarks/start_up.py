"""The command's fixed costs: whole processes that do almost no work, in turns.

Every timed run is a fresh process, exec to exit. The sides:

- ``interpreter``: ``python -c pass``, the floor under any command;
- ``version``: ``embree-rt --version`` (the parser alone: no NumPy, no numba);
- ``tiny``: ``embree-rt render`` of a GSD file of 20 particles at 16x9, 1 spp: the imports,
  the parse, numba's set-up and the loading of every kernel a particle render runs from
  numba's cache, the exit; the render itself is nothing;
- ``tiny_scipy_visible``: the same command in a process that imported ``scipy.linalg``
  before it started, so that numba's check for a BLAS finds SciPy there, as it did before the
  command set numba up without SciPy (``embree_rt/cli/numba_setup.py``): what that saves is
  ``tiny_scipy_visible`` - ``tiny``.

``--file PARTICLES`` adds ``file`` and ``file_scipy_visible``: that file rendered at 1920x1080,
1 spp, no floor, ``--radius 0.5`` (issue 35's command, e.g. the 1e6-particle GSD).

``--random COUNT`` adds ``random``: ``embree-rt random --count COUNT --width 1920 --height
1080 --spp 1`` (issue 37's command, at 1e6). With ``--base CHECKOUT`` it adds ``random_base``,
the same command run from another checkout (``PYTHONPATH=CHECKOUT``, from a folder outside
this one, checked to import from there; e.g. the release before), with ``random_vs_base`` the
median per-turn ratio of walls (below 1: this tree is faster) and whether the two PNGs'
decoded pixels are equal. Run each side once before (numba compiles a fresh checkout's
kernels on its first run, which the warm-up run absorbs).

The sides take turns (A, B, C, ...), each side's first run discarded (disk caches, numba's
cache), so that a shared machine's drifting load falls on all alike. Each figure is the median
over ``--turns``: wall seconds, and CPU seconds (user + system, the process's own rusage);
``saved_s`` is the median over turns of the per-turn difference of walls, ``ratio`` the median
per-turn ratio (above 1: the command as it is is faster). Load averages at the start and end.

    python benchmarks/start_up.py --turns 3
    python benchmarks/start_up.py --turns 11 --file x.gsd
    python benchmarks/start_up.py --turns 7 --random 1000000 --base ../release-checkout

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SCIPY_FIRST = (
    "import runpy, sys\n"
    "import scipy.linalg\n"
    "sys.argv = ['embree-rt', *sys.argv[1:]]\n"
    "runpy.run_module('embree_rt', run_name='__main__')\n"
)


class Run(NamedTuple):
    wall_s: float
    cpu_s: float


class Side(NamedTuple):
    """A command line, the folder it runs in, and what it adds to ``PYTHONPATH`` (None: this
    checkout, found from its folder)."""

    command: list[str]
    cwd: Path = ROOT
    python_path: Path | None = None


def environment(python_path: Path | None) -> dict[str, str]:
    """This process's environment, with ``python_path`` first on ``PYTHONPATH`` when given."""
    env = dict(os.environ)
    if python_path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(python_path), env.get("PYTHONPATH", "")])
    return env


def run(side: Side) -> Run:
    """One process of ``side`` (its output thrown away): wall and CPU seconds (the children's
    rusage grows by the finished process's own); it must exit 0."""
    command = side.command
    env = environment(side.python_path)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    done = subprocess.run(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=side.cwd, env=env
    )
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{command} exited {done.returncode}: {done.stderr.decode()[-2000:]}")
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return Run(wall, cpu)


def small_gsd(path: Path) -> Path:
    """A GSD file of one frame of 20 particles of two types."""
    import gsd.hoomd

    frame = gsd.hoomd.Frame()
    frame.particles.N = 20
    frame.particles.position = np.random.default_rng(1).uniform(-3, 3, (20, 3)).astype(np.float32)
    frame.particles.types = ["A", "B"]
    frame.particles.typeid = (np.arange(20) % 2).astype(np.uint32)
    frame.configuration.box = [10.0, 10.0, 10.0, 0.0, 0.0, 0.0]
    with gsd.hoomd.open(str(path), "w") as trajectory:
        trajectory.append(frame)
    return path


def sides(
    folder: Path, particles: Path | None, random_count: int | None, base: Path | None
) -> dict[str, Side]:
    """Each side's command line, folder and path."""
    python = sys.executable
    tiny = [
        "render", str(small_gsd(folder / "small.gsd")), "-o", str(folder / "tiny.png"),
        "--width", "16", "--height", "9", "--spp", "1", "--quiet", "--overwrite",
    ]  # fmt: skip
    commands = {
        "interpreter": [python, "-c", "pass"],
        "version": [python, "-m", "embree_rt", "--version"],
        "tiny": [python, "-m", "embree_rt", *tiny],
        "tiny_scipy_visible": [python, "-c", SCIPY_FIRST, *tiny],
    }
    if particles is not None:
        big = [
            "render", str(particles), "-o", str(folder / "file.png"), "--width", "1920",
            "--height", "1080", "--spp", "1", "--no-floor", "--radius", "0.5", "--quiet",
            "--overwrite",
        ]  # fmt: skip
        commands["file"] = [python, "-m", "embree_rt", *big]
        commands["file_scipy_visible"] = [python, "-c", SCIPY_FIRST, *big]
    runs = {name: Side(command) for name, command in commands.items()}
    if random_count is not None:
        field = ["random", "--count", str(random_count), "--width", "1920", "--height", "1080",
                 "--spp", "1", "--quiet", "-o"]  # fmt: skip
        runs["random"] = Side([python, "-m", "embree_rt", *field, str(folder / "random.png")])
        if base is not None:
            check_imports_from(base, folder)
            base_command = [python, "-m", "embree_rt", *field, str(folder / "random_base.png")]
            runs["random_base"] = Side(base_command, folder, base)
    return runs


def check_imports_from(checkout: Path, folder: Path) -> None:
    """Refuse a ``checkout`` whose embree_rt is not the one a process started in ``folder``
    with it on ``PYTHONPATH`` imports."""
    done = subprocess.run(
        [sys.executable, "-c", "import embree_rt; print(embree_rt.__file__)"],
        capture_output=True, text=True, cwd=folder, env=environment(checkout), check=True,
    )  # fmt: skip
    imported = Path(done.stdout.strip()).resolve()
    if not imported.is_relative_to(checkout.resolve()):
        raise SystemExit(f"--base {checkout}: embree_rt imports from {imported}")


def decoded_pixels(path: Path) -> np.ndarray:
    """The 8-bit pixels of the PNG at ``path`` (pypng, which the command writes with)."""
    import png

    width, height, rows, info = png.Reader(filename=str(path)).asDirect()
    return np.vstack(list(rows)).reshape(height, width, info["planes"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--turns", type=int, default=7)
    parser.add_argument("--file", type=Path, help="a particle file to render at 1080p as well")
    parser.add_argument("--random", type=int, help="the random field of this many spheres too")
    parser.add_argument("--base", type=Path, help="with --random: another checkout's command too")
    args = parser.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as directory:
        commands = sides(Path(directory), args.file, args.random, args.base)
        for command in commands.values():  # warm-up: disk caches, numba's cache
            run(command)
        runs: dict[str, list[Run]] = {name: [] for name in commands}
        for turn in range(args.turns):
            for name, command in commands.items():
                runs[name].append(run(command))
                print(f"  {name} turn {turn}: {runs[name][-1].wall_s:.3f} s", file=sys.stderr)
        pixels_equal = None
        if "random_base" in commands:
            pixels_equal = bool(
                np.array_equal(
                    decoded_pixels(Path(directory) / "random.png"),
                    decoded_pixels(Path(directory) / "random_base.png"),
                )
            )
    result: dict = {
        "turns": args.turns,
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    for name, done in runs.items():
        result[name] = {
            "wall_s": [round(r.wall_s, 3) for r in done],
            "median_wall_s": round(statistics.median(r.wall_s for r in done), 3),
            "median_cpu_s": round(statistics.median(r.cpu_s for r in done), 3),
        }
    for side in ("tiny", "file"):
        if side in runs:
            pairs = list(zip(runs[f"{side}_scipy_visible"], runs[side], strict=True))
            result[f"{side}_saved_s"] = round(
                statistics.median(a.wall_s - b.wall_s for a, b in pairs), 3
            )
            result[f"{side}_ratio"] = round(
                statistics.median(a.wall_s / b.wall_s for a, b in pairs), 3
            )
    if pixels_equal is not None:
        pairs = list(zip(runs["random"], runs["random_base"], strict=True))
        result["random_vs_base"] = round(
            statistics.median(a.wall_s / b.wall_s for a, b in pairs), 3
        )
        result["random_cpu_vs_base"] = round(
            statistics.median(a.cpu_s / b.cpu_s for a, b in pairs), 3
        )
        result["random_pixels_equal_base"] = pixels_equal
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
