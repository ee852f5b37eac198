"""Frames per second of a particle trajectory, whole commands, in turns.

Writes a trajectory of ``--count`` particles (default 1e6) over ``--frames`` frames (default 20),
each particle a random walk, as a GSD file (the ``gsd`` library's writer) and a LAMMPS text
dump (by hand: no library writes one), then times as fresh processes (exec to exit, imports
included), median of ``--repeats``, the variants in turns:

- ``gsd`` / ``dump``: ``embree-rt render FILE -o DIR/f_{frame:04d}.png`` (refit, overlap);
- ``gsd_no_refit``: the same with ``--no-refit`` (a BVH built every frame);
- ``pipeline_overlap`` / ``pipeline_sequential``: the frames pipeline from Python on the GSD
  file, with and without reading and writing beside the render;
- ``loop_this`` / ``loop_base``: a Python loop over the same positions, one ``render`` (a fresh
  BVH) and one PNG a frame, through the Python API that both this tree and ``--base`` (the
  release before this work, which reads no particle files) have; ``--base`` is its checkout,
  put on PYTHONPATH for that variant only. Its scene is not the command's: one light, no
  per-particle colours and another camera, so it traces about half the command's rays (3.7 M
  against 7.6 M a frame at 1e6 and 1080p) and its render costs well under half as much;
- ``loop_same``: a Python loop of ``render`` (a fresh BVH) and one PNG a frame over the
  command's own scenes (``Scene.from_particles`` each frame, with the first frame's camera,
  lights and floor, as the command draws them: the same images), nothing overlapped: what
  the command's frames would cost without its pipeline, the yardstick for what the file
  path adds (``steady_vs_same``).

Each variant also runs on the first frame alone, so ``first_frame_s`` is that whole process and
``steady_frame_s`` = (all frames - first frame) / (frames - 1), the cost of each further frame;
``fps`` is frames / the whole command's seconds. 1920x1080, 1 spp, the default look.

    python benchmarks/frames.py                                   # 1e6 x 20 frames
    python benchmarks/frames.py --count 20000 --frames 4 --width 320 --height 180 --repeats 1

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# The Python-API loop: the same in both trees (Scene, add_spheres, render, RenderResult.save).
LOOP = """
import sys
import numpy as np
import embree_rt as rt
positions = np.load(sys.argv[1], mmap_mode="r")
radii = np.load(sys.argv[2])
out, width, height = sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
frames = int(sys.argv[6])
lo, hi = positions[0].min(axis=0), positions[0].max(axis=0)
centre, size = (lo + hi) / 2, float((hi - lo).max())
for k in range(frames):
    scene = rt.Scene()
    scene.add_spheres(np.asarray(positions[k]), radii, "matte")
    scene.camera = rt.Camera(
        position=tuple(centre + np.array([0.0, -1.6 * size, 0.9 * size])),
        look_at=tuple(centre),
    )
    scene.lights = [rt.PointLight(position=tuple(centre + size), intensity=3.0 * size * size)]
    result = rt.render(scene, width=width, height=height, spp=1)
    result.save(f"{out}/f_{k:04d}.png")
"""

# A plain loop over the command's own scenes, read each frame, one fresh BVH and one PNG a
# frame, nothing overlapped: the same images as the command.
LOOP_SAME = """
import sys
import embree_rt as rt
path, out, width, height, frames = sys.argv[1:6]
first = rt.Scene.from_particles(path, frame=0)
for k in range(int(frames)):
    scene = first if k == 0 else rt.Scene.from_particles(path, frame=k)
    scene.camera, scene.lights, scene.floor = first.camera, first.lights, first.floor
    result = rt.render(scene, width=int(width), height=int(height), spp=1)
    result.save(f"{out}/f_{k:04d}.png")
"""

# The frames pipeline through Python, overlapped or not: what reading and writing beside the
# render save (the command line always overlaps).
PIPELINE = """
import sys
import embree_rt as rt
from embree_rt.cli.trajectory import FrameRendering, render_frames
path, out, width, height, frames, overlap = sys.argv[1:7]
first = rt.Scene.from_particles(path, frame=0)
def read(n):
    scene = rt.Scene.from_particles(path, frame=n)
    scene.camera, scene.lights, scene.floor = first.camera, first.lights, first.floor
    scene.render = scene.render.with_overrides(width=int(width), height=int(height), spp=1)
    return scene
render_frames(
    range(int(frames)),
    read,
    lambda n, result: result.save(f"{out}/f_{n:04d}.png"),
    FrameRendering(overlap=overlap == "1"),
)
"""


def write_trajectory(folder: Path, count: int, frames: int) -> dict[str, Path]:
    """The GSD file, the LAMMPS dump and the positions (frames, count, 3) float32 as .npy."""
    import gsd.hoomd

    rng = np.random.default_rng(0)
    side = 2.0 * count ** (1 / 3)  # about one particle per 8 unit cells
    start = rng.uniform(0, side, (count, 3)).astype(np.float32)
    steps = rng.normal(0.0, 0.05, (frames, count, 3)).astype(np.float32)
    positions = start + np.cumsum(steps, axis=0)
    types = rng.integers(0, 3, count).astype(np.uint32)
    diameters = np.where(types == 0, 1.0, 0.7).astype(np.float32)
    paths = {"gsd": folder / "t.gsd", "dump": folder / "t.lammpstrj"}
    with gsd.hoomd.open(paths["gsd"], mode="w") as trajectory:
        for k in range(frames):
            frame = gsd.hoomd.Frame()
            frame.configuration.step = k
            frame.configuration.box = [side, side, side, 0, 0, 0]
            frame.particles.N = count
            frame.particles.types = ["A", "B", "C"]
            frame.particles.typeid = types
            frame.particles.position = positions[k] - side / 2  # GSD boxes are centred
            frame.particles.diameter = diameters
            trajectory.append(frame)
    with open(paths["dump"], "w") as out:
        for k in range(frames):
            out.write(f"ITEM: TIMESTEP\n{k}\nITEM: NUMBER OF ATOMS\n{count}\n")
            out.write("ITEM: BOX BOUNDS pp pp pp\n" + f"0 {side:g}\n" * 3)
            out.write("ITEM: ATOMS id type x y z radius\n")
            table = np.column_stack(
                [np.arange(1, count + 1), types + 1, positions[k], diameters / 2]
            )
            np.savetxt(out, table, fmt=["%d", "%d", "%.5f", "%.5f", "%.5f", "%.3f"])
    paths["positions"] = folder / "positions.npy"
    np.save(paths["positions"], positions - side / 2)
    paths["radii"] = folder / "radii.npy"
    np.save(paths["radii"], diameters / 2)
    return paths


def command(variant: str, paths: dict[str, Path], out: Path, frames: int, args) -> list[str]:
    size = ["--width", str(args.width), "--height", str(args.height), "--spp", "1"]
    if variant.startswith("loop"):
        return [
            sys.executable,
            "-c",
            LOOP,
            str(paths["positions"]),
            str(paths["radii"]),
            str(out),
            str(args.width),
            str(args.height),
            str(frames),
        ]
    if variant == "loop_same":
        return [
            *[sys.executable, "-c", LOOP_SAME, str(paths["gsd"]), str(out)],
            *[str(args.width), str(args.height), str(frames)],
        ]
    if variant.startswith("pipeline"):
        overlap = "1" if variant == "pipeline_overlap" else "0"
        return [
            *[sys.executable, "-c", PIPELINE, str(paths["gsd"]), str(out)],
            *[str(args.width), str(args.height), str(frames), overlap],
        ]
    source = paths["dump" if variant == "dump" else "gsd"]
    extra = ["--no-refit"] if variant == "gsd_no_refit" else []
    pattern = str(out / "f_{frame:04d}.png")
    return [
        *[sys.executable, "-m", "embree_rt", "render", str(source), "-o", pattern],
        *[*size, "--frames", f"0:{frames}", "--quiet", *extra],
    ]


def timed_run(variant: str, paths, folder: Path, frames: int, args) -> float:
    out = folder / f"out_{variant}"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    tree = args.base if variant == "loop_base" else str(ROOT)
    env = {**os.environ, "PYTHONPATH": tree}
    began = time.perf_counter()
    done = subprocess.run(
        command(variant, paths, out, frames, args), env=env, capture_output=True, text=True
    )
    seconds = time.perf_counter() - began
    if done.returncode != 0:
        raise SystemExit(f"{variant}: exit {done.returncode}: {done.stderr.strip()[-2000:]}")
    written = len(list(out.glob("f_*.png")))
    if written != frames:
        raise SystemExit(f"{variant}: wrote {written} frames, expected {frames}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--base", default="/work/wt/base", help="checkout of the release before")
    args = parser.parse_args()
    variants = ["gsd", "dump", "gsd_no_refit", "pipeline_overlap", "pipeline_sequential"]
    variants += ["loop_same", "loop_this"]
    if args.base and Path(args.base, "embree_rt").is_dir():
        variants.append("loop_base")
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        paths = write_trajectory(folder, args.count, args.frames)
        times: dict[tuple[str, int], list[float]] = {}
        for _ in range(args.repeats):
            for variant in variants:  # in turns, so a busy moment touches each alike
                for frames in (1, args.frames):
                    seconds = timed_run(variant, paths, folder, frames, args)
                    times.setdefault((variant, frames), []).append(seconds)
    report: dict = {
        "count": args.count,
        "frames": args.frames,
        "width": args.width,
        "height": args.height,
        "repeats": args.repeats,
        "variants": {},
    }
    for variant in variants:
        first = statistics.median(times[variant, 1])
        whole = statistics.median(times[variant, args.frames])
        report["variants"][variant] = {
            "whole_s": whole,
            "fps": args.frames / whole,
            "first_frame_s": first,
            "steady_frame_s": (whole - first) / max(args.frames - 1, 1),
        }
    same = report["variants"]["loop_same"]
    for row in report["variants"].values():
        row["steady_vs_same"] = row["steady_frame_s"] / same["steady_frame_s"]
    base = report["variants"].get("loop_base")
    if base:
        for row in report["variants"].values():
            row["steady_vs_base"] = row["steady_frame_s"] / base["steady_frame_s"]
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
