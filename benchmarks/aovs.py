"""What AOVs cost: the AOV pass against the beauty render it accompanies, taking turns.

The random field of ``--count`` spheres (default 1e6) at 1920x1080, 1 spp, max depth 6, one
``Renderer`` built once and warmed. Each turn renders the beauty, then runs the AOV pass
(``embree_rt.aovs.render_aovs``, all five AOVs: one pixel-centre ray per pixel and its
bookkeeping, what ``render(..., aovs=...)`` adds), the order alternating from turn to turn.
``overhead`` is the median over turns of AOV pass / beauty, by wall time and by process CPU
time (the latter robust to other load on a shared machine): each turn's two runs lie close
together, so the ratio stays fair while the machine's load drifts.

    python benchmarks/aovs.py                       # 1e6 spheres, 5 turns
    python benchmarks/aovs.py --count 100000 --turns 3

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from embree_rt import Renderer
from embree_rt.aovs import AOV_NAMES, render_aovs
from embree_rt.camera import camera_frame
from embree_rt.scene import random_field


def timed(function) -> tuple[float, float]:
    """(wall s, process CPU s) of ``function()``."""
    wall, cpu = time.perf_counter(), time.process_time()
    function()
    return time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--max-depth", type=int, default=6)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--turns", type=int, default=5)
    args = parser.parse_args()
    scene = random_field(args.count, seed=0)
    image = dict(
        width=args.width, height=args.height, spp=args.spp, max_depth=args.max_depth, seed=0
    )
    frame = camera_frame(scene.camera, args.width, args.height)
    with Renderer(scene, threads=args.threads) as renderer:
        # Compile and warm both paths on a small image, outside the timing.
        renderer.render(**{**image, "width": 64, "height": 36})
        render_aovs(renderer, camera_frame(scene.camera, 64, 36), AOV_NAMES)
        beauty = {"wall": [], "cpu": []}
        aov_pass = {"wall": [], "cpu": []}
        for turn in range(args.turns):
            steps = [
                (beauty, lambda: renderer.render(**image)),
                (aov_pass, lambda: render_aovs(renderer, frame, AOV_NAMES)),
            ]
            for times, step in steps if turn % 2 == 0 else steps[::-1]:
                wall, cpu = timed(step)
                times["wall"].append(wall)
                times["cpu"].append(cpu)
        overhead = {
            clock: float(np.median(np.divide(aov_pass[clock], beauty[clock])))
            for clock in ("wall", "cpu")
        }
        result = {
            "count": args.count,
            "width": args.width,
            "height": args.height,
            "spp": args.spp,
            "max_depth": args.max_depth,
            "threads": renderer.workers,
            "aovs": list(AOV_NAMES),
            "turns": args.turns,
            "beauty_s": [round(x, 3) for x in beauty["wall"]],
            "aov_pass_s": [round(x, 3) for x in aov_pass["wall"]],
            "beauty_cpu_s": [round(x, 3) for x in beauty["cpu"]],
            "aov_pass_cpu_s": [round(x, 3) for x in aov_pass["cpu"]],
            "overhead_wall": round(overhead["wall"], 4),
            "overhead_cpu": round(overhead["cpu"], 4),
            "aov_rays_per_s": round(args.width * args.height / min(aov_pass["wall"])),
        }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
