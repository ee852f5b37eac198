"""Trajectories beside OVITO 3: frames per second of whole processes, in turns (issue 37).

A trajectory of FRAMES frames of N particles (the field of ``particles.py``, every particle
moved by a normal step each frame) is written by OVITO's own exporters as a LAMMPS dump and a
GSD file. Each is rendered, every frame to a PNG at WIDTHxHEIGHT and 1 spp under one light with
shadows, as a fresh process (exec to exit, imports included) by:

- ``embree_rt``: ``embree-rt render FILE -o f_{frame:04d}.png --frames 0:FRAMES`` (one light
  where its default key light stands, no floor, ``--radius 0.5``);
- ``tachyon`` and ``ospray``: OVITO's ``Viewport.render_anim`` with its ``TachyonRenderer`` /
  ``OSPRayRenderer`` set as in ``particles.py`` (1 spp, one refinement, no denoising).

The sides take turns (A, B, C, A, B, C, ...) after one discarded run each (unless
``--no-warm-up``); reported per side:
whole-process seconds and frames per second (median of ``--repeats``), the first frame's
latency (process start to the first PNG on disk) and the steady state's seconds a frame (the
PNGs' modification times, first to last, over FRAMES - 1), and the per-turn ratios of the
others' seconds to embree_rt's (above 1: embree_rt is faster).

``write_trajectory`` and ``frames_run`` are the pieces ``benchmarks/frames.py`` may call.

    python benchmarks/frames_ovito.py --count 10000 --frames 5 --repeats 1 --width 480 --height 270
    python benchmarks/frames_ovito.py --ovito-python /path/to/venv-ovito/bin/python
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from particles import (
    embree_render_command,
    key_light,
    load_average,
    ovito_command,
    run,
    summary_parts,
    turns,
)

STEP = 0.05  # each frame moves every particle by a normal step of this size, times the frame


class FramesRun(NamedTuple):
    """One whole process rendering every frame: wall seconds, peak memory (MB), the first PNG's
    latency from the process's start, seconds a frame after it, embree_rt's summary or {}."""

    seconds: float
    peak_mb: float
    first_frame_s: float
    steady_s_per_frame: float
    summary: dict


def write_trajectory(ovito_python: str, folder: Path, count: int, frames: int) -> dict[str, Path]:
    """OVITO's exporters' ``x.dump`` and ``x.gsd`` of ``frames`` frames of ``count``
    particles under ``folder`` (written unless there already)."""
    where = folder / f"traj{count}x{frames}"
    files = {"dump": where / "x.dump", "gsd": where / "x.gsd"}
    if not all(path.exists() for path in files.values()):
        where.mkdir(parents=True, exist_ok=True)
        run(ovito_command(ovito_python, "write", count, where, frames, STEP))
    return files


def frames_run(
    side: str, path: Path, out: Path, frames: int, size: tuple[int, int], ovito_python: str
) -> FramesRun:
    """Every frame of ``path`` rendered into the empty folder ``out`` by ``side`` (embree_rt,
    tachyon or ospray) as one fresh process."""
    out.mkdir(parents=True)
    if side == "embree_rt":
        command = embree_render_command(path, out / "f_{frame:04d}.png", size, key_light(path))
        command += ["--frames", f"0:{frames}"]
    else:
        command = ovito_command(ovito_python, "anim", path, out / "f_*.png", side, *size)
    started = time.time()
    done = run(command)
    written = sorted(os.stat(png).st_mtime for png in out.glob("f_*.png"))
    if len(written) != frames:
        raise RuntimeError(f"{side}: {len(written)} of {frames} frames written in {out}")
    steady = (written[-1] - written[0]) / (frames - 1) if frames > 1 else 0.0
    summary = summary_parts(done.stderr) if side == "embree_rt" else {}
    return FramesRun(done.seconds, done.peak_mb, written[0] - started, steady, summary)


def in_turns(
    sides: dict[str, Callable[[int], FramesRun]], repeats: int, frames: int, warm_up: bool = True
) -> dict:
    """One discarded run a side, then ``repeats`` turns; medians and per-turn ratios."""
    runs = turns(sides, repeats, warm_up)
    out: dict = {}
    for name, done in runs.items():
        median = statistics.median(r.seconds for r in done)
        out[name] = {
            "seconds": [round(r.seconds, 2) for r in done],
            "median_s": round(median, 2),
            "frames_per_s": round(frames / median, 3),
            "first_frame_s": round(statistics.median(r.first_frame_s for r in done), 2),
            "steady_s_per_frame": round(statistics.median(r.steady_s_per_frame for r in done), 3),
            "peak_mb": round(max(r.peak_mb for r in done)),
        }
        if done[0].summary:
            out[name]["summary_last_turn"] = done[-1].summary
    for name, done in runs.items():
        if name != "embree_rt" and "embree_rt" in runs:
            pairs = zip(done, runs["embree_rt"], strict=True)
            out[f"{name}_over_embree_rt"] = round(
                statistics.median(theirs.seconds / ours.seconds for theirs, ours in pairs), 2
            )
            pairs = zip(done, runs["embree_rt"], strict=True)
            out[f"{name}_over_embree_rt_steady"] = round(
                statistics.median(
                    theirs.steady_s_per_frame / ours.steady_s_per_frame for theirs, ours in pairs
                ),
                2,
            )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--formats", nargs="*", default=["gsd", "dump"], choices=["gsd", "dump"])
    parser.add_argument(
        "--sides", nargs="*", default=["embree_rt", "tachyon", "ospray"],
        choices=["embree_rt", "tachyon", "ospray"],
    )  # fmt: skip
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--no-warm-up", dest="warm_up", action="store_false",
        help="time from the first run (the files already in the disk cache, numba's cache made)",
    )  # fmt: skip
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--ovito-python", default=sys.executable)
    parser.add_argument("--folder", type=Path, help="keep the files here (default: temporary)")
    args = parser.parse_args()
    size = (args.width, args.height)
    result: dict = {"load_average_start": load_average(), "count": args.count}
    result |= {"frames": args.frames, "size": list(size)}
    with tempfile.TemporaryDirectory() as scratch:
        folder = args.folder or Path(scratch)
        files = write_trajectory(args.ovito_python, folder, args.count, args.frames)
        images = Path(tempfile.mkdtemp(dir=scratch))
        for kind in args.formats:
            print(f"{kind}: {args.count:,} particles, {args.frames} frames", file=sys.stderr)

            def side(name: str, path: Path = files[kind], kind: str = kind):
                return lambda turn: frames_run(
                    name, path, images / f"{kind}_{name}_{turn}", args.frames, size,
                    args.ovito_python,
                )  # fmt: skip

            sides = {name: side(name) for name in args.sides}
            result[kind] = in_turns(sides, args.repeats, args.frames, args.warm_up)
    result["load_average_end"] = load_average()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
