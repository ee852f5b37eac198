"""Where a trajectory frame's seconds go: the command's scene against the Python loop's, in turns.

``benchmarks/frames.py`` times whole commands; this splits one frame into its stages, in one
process, for the two scenes it compares: the command's (``Scene.from_particles`` of a GSD
frame with the first frame's camera, lights and floor: what ``embree-rt render x.gsd --frames``
draws) and its ``loop_this`` variant's (the same positions as one matte sphere set, one light,
another camera). Each round reads a frame of each (``read_s``), builds its BVH
(``Renderer``, ``build_s``), renders it (``render_s``, and the rays it traced by kind), tone
maps it (``tonemap_s``) and encodes the PNG in memory (``png_s``), the two scenes taking turns.
Prints one JSON object: each stage's median over the rounds, per scene.

    python benchmarks/frame_stages.py                       # 1e6 particles, 1080p, 5 rounds
    python benchmarks/frame_stages.py --count 20000 --width 320 --height 180 --rounds 2
"""

from __future__ import annotations

import argparse
import io
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from frames import write_trajectory

import embree_rt as rt
from embree_rt import film

FRAMES = 4  # a frame is read again every FRAMES - 1 rounds: none of them is the first


def command_scene(path: Path, frame: int, first: rt.Scene, size: tuple[int, int]) -> rt.Scene:
    """Frame ``frame`` of the GSD file as the command draws a frame after the first."""
    scene = rt.Scene.from_particles(path, frame=frame)
    scene.camera, scene.lights, scene.floor = first.camera, first.lights, first.floor
    scene.render = scene.render.with_overrides(width=size[0], height=size[1], spp=1)
    return scene


def loop_scene(positions: np.ndarray, radii: np.ndarray, frame: int, size) -> rt.Scene:
    """Frame ``frame`` as ``frames.py``'s Python loop draws it (its ``LOOP``)."""
    lo, hi = positions[0].min(axis=0), positions[0].max(axis=0)
    centre, extent = (lo + hi) / 2, float((hi - lo).max())
    scene = rt.Scene()
    scene.add_spheres(np.asarray(positions[frame]), radii, "matte")
    scene.camera = rt.Camera(
        position=tuple(centre + np.array([0.0, -1.6 * extent, 0.9 * extent])),
        look_at=tuple(centre),
    )
    scene.lights = [rt.PointLight(position=tuple(centre + extent), intensity=3.0 * extent**2)]
    scene.render = scene.render.with_overrides(width=size[0], height=size[1], spp=1)
    return scene


def one_frame(make) -> dict:
    """The stages' seconds of one frame whose scene ``make()`` reads, and its rays."""
    began = time.perf_counter()
    scene = make()
    read = time.perf_counter()
    with rt.Renderer(scene) as renderer:
        built = time.perf_counter()
        result = renderer.render()
        rendered = time.perf_counter()
    pixels = result.to_srgb8()
    mapped = time.perf_counter()
    film.write_pixels(pixels, io.BytesIO(), ".png")
    encoded = time.perf_counter()
    return {
        "read_s": read - began,
        "build_s": built - read,
        "render_s": rendered - built,
        "tonemap_s": mapped - rendered,
        "png_s": encoded - mapped,
        "rays": dict(result.stats.rays),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    size = (args.width, args.height)
    with tempfile.TemporaryDirectory() as name:
        paths = write_trajectory(Path(name), args.count, FRAMES)
        positions = np.load(paths["positions"], mmap_mode="r")
        radii = np.load(paths["radii"])
        first = rt.Scene.from_particles(paths["gsd"], frame=0)
        makers = {
            "command": lambda k: command_scene(paths["gsd"], k, first, size),
            "loop_this": lambda k: loop_scene(positions, radii, k, size),
        }
        one_frame(lambda: makers["command"](0))  # numba's and Embree's one-off loading
        rounds: dict[str, list[dict]] = {name: [] for name in makers}
        for index in range(args.rounds):
            frame = 1 + index % (FRAMES - 1)
            for name, make in makers.items():  # in turns
                rounds[name].append(one_frame(lambda make=make, frame=frame: make(frame)))
    report: dict = {"count": args.count, "width": args.width, "height": args.height}
    report["rounds"] = args.rounds
    for name, frames in rounds.items():
        stages = {
            key: statistics.median(f[key] for f in frames) for key in frames[0] if key != "rays"
        }
        stages["frame_s"] = sum(stages.values())
        stages["rays"] = frames[-1]["rays"]
        report[name] = stages
    report["render_ratio"] = report["command"]["render_s"] / report["loop_this"]["render_s"]
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
