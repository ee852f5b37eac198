"""How much faster two (or more) threads render than one, measured in alternation.

The machine this project runs on is shared: its speed drifts by tens of percent from one minute
to the next, so separate runs per thread count compare different machines. This renders the
same random field with a one-thread renderer and an N-thread renderer taking turns, and reports
each turn's time ratio; ``speedup`` is their median. The same is done for the bare traversal
(the render's recorded rays replayed through the BVH on 1 and on N threads), which shows what
the cores deliver at that moment.

    python benchmarks/thread_scaling.py                      # 1e6 spheres, 1920x1080, 1 spp
    python benchmarks/thread_scaling.py --count 1000 --rounds 7

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics

from render_scale import record_queries, replay  # run as a script: benchmarks/ is on sys.path

from embree_rt import Renderer
from embree_rt.scene import random_field


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=1_000_000, help="spheres")
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--rounds", type=int, default=5, help="alternating pairs of renders")
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--max-depth", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    scene = random_field(args.count, seed=args.seed)
    image = dict(
        width=args.width, height=args.height, spp=args.spp, max_depth=args.max_depth, seed=args.seed
    )
    with Renderer(scene, threads=1) as one, Renderer(scene, threads=args.threads) as many:
        for renderer in (one, many):  # compile, warm the heap and the kernels
            renderer.render(**image)
        log = record_queries(one, image)
        render_1, render_n, replay_1, replay_n = [], [], [], []
        for _ in range(args.rounds):
            render_1.append(one.render(**image).stats.render_s)
            render_n.append(many.render(**image).stats.render_s)
            replay_1.append(replay(one, log, 1))
            replay_n.append(replay(one, log, args.threads))
    speedup = [a / b for a, b in zip(render_1, render_n, strict=True)]
    raw_speedup = [a / b for a, b in zip(replay_1, replay_n, strict=True)]
    result = {
        "count": args.count,
        "threads": args.threads,
        "width": args.width,
        "height": args.height,
        "spp": args.spp,
        "max_depth": args.max_depth,
        "render_s_1": [round(s, 3) for s in render_1],
        f"render_s_{args.threads}": [round(s, 3) for s in render_n],
        "speedup": round(statistics.median(speedup), 3),
        "speedup_all": [round(s, 2) for s in speedup],
        "raw_speedup": round(statistics.median(raw_speedup), 3),
        "raw_speedup_all": [round(s, 2) for s in raw_speedup],
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
