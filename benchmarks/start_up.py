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

The sides take turns (A, B, C, ...), each side's first run discarded (disk caches, numba's
cache), so that a shared machine's drifting load falls on all alike. Each figure is the median
over ``--turns``: wall seconds, and CPU seconds (user + system, the process's own rusage);
``saved_s`` is the median over turns of the per-turn difference of walls, ``ratio`` the median
per-turn ratio (above 1: the command as it is is faster). Load averages at the start and end.

    python benchmarks/start_up.py --turns 3
    python benchmarks/start_up.py --turns 11 --file x.gsd

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


def run(command: list[str]) -> Run:
    """One process of ``command`` (its output thrown away): wall and CPU seconds (the
    children's rusage grows by the finished process's own); it must exit 0."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=ROOT)
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


def sides(folder: Path, particles: Path | None) -> dict[str, list[str]]:
    """Each side's command line."""
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
    return commands


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--turns", type=int, default=7)
    parser.add_argument("--file", type=Path, help="a particle file to render at 1080p as well")
    args = parser.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as directory:
        commands = sides(Path(directory), args.file)
        for command in commands.values():  # warm-up: disk caches, numba's cache
            run(command)
        runs: dict[str, list[Run]] = {name: [] for name in commands}
        for turn in range(args.turns):
            for name, command in commands.items():
                runs[name].append(run(command))
                print(f"  {name} turn {turn}: {runs[name][-1].wall_s:.3f} s", file=sys.stderr)
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
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
