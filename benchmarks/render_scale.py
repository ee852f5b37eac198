"""End-to-end render throughput on random sphere fields, against bare Embree traversal.

For each sphere count it renders the random field once (peak memory is read after it), once
more recording every ray query, then ``--repeat`` times, each render followed at once by a
replay of the recorded rays through the bare BVH queries (no shading) on as many threads.
``efficiency`` is the median over those pairs of replay time / render time, i.e. rays/s end to
end over raw rays/s: pairs taken close together keep the ratio fair on a noisy shared machine.
``render_s`` and ``raw_rays_per_s`` are the best of their runs.

    python benchmarks/render_scale.py                       # 1e3..1e6 spheres, 1920x1080, 1 spp
    python benchmarks/render_scale.py --counts 1000000 --threads 1

Prints one JSON object per count on stdout.
"""

from __future__ import annotations

import argparse
import json
import resource
import threading
import time

import numpy as np

from embree_rt import Renderer
from embree_rt.integrator import DEFAULT_BATCH_SIZE
from embree_rt.scene import random_field


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class RecordingGeometry:
    """Stands in for a renderer's ``SceneGeometry`` and records every query it forwards, as
    (kind, origins, directions, tfar, coherent) with rays as (3, n) columns."""

    def __init__(self, geometry) -> None:
        self.geometry = geometry
        self.log: list = []
        self._lock = threading.Lock()

    def __getattr__(self, name: str):
        return getattr(self.geometry, name)

    def intersect_compact(self, origins, directions, tnear=0.0, tfar=np.inf, coherent=False):
        with self._lock:
            self.log.append(("intersect", origins, directions, tfar, coherent))
        return self.geometry.intersect_compact(origins, directions, tnear, tfar, coherent)

    def occluded_toward(self, points, rows, target):
        # The shadow segments as the rays they are: from each point to the target, t in [0, 1].
        origins = np.take(points, rows, axis=1)
        directions = np.asarray(target, np.float32)[:, None] - origins
        with self._lock:
            self.log.append(("occluded", origins, directions, 1.0, False))
        return self.geometry.occluded_toward(points, rows, target)


def record_queries(renderer: Renderer, image: dict) -> list:
    """Every ray query one render of ``image`` makes."""
    geometry = renderer.geometry
    renderer.geometry = recorder = RecordingGeometry(geometry)
    try:
        renderer.render(**image)
    finally:
        renderer.geometry = geometry
    return recorder.log


def replay(renderer: Renderer, log: list, threads: int | None = None) -> float:
    """Seconds the bare BVH takes to answer every query of ``log`` again (Embree's traversal
    and nothing else: no hit records, no floor plane), on ``threads`` threads (by default as
    many as the render had)."""
    bvh = renderer.geometry.bvh
    bvh.threads = renderer.workers if threads is None else threads
    # Compile and warm the kernels this thread count uses, outside the timing.
    # (numba compiles per memory layout: these are Fortran-ordered (n, 3) views, as logged.)
    _, origins, directions, _, _ = log[0]
    origins, directions = (
        np.ascontiguousarray(origins[:, :64]),
        np.ascontiguousarray(directions[:, :64]),
    )
    bvh.intersect(origins.T, directions.T)
    bvh.intersect(origins.T, directions.T, coherent=True)
    bvh.occluded(origins.T, directions.T)
    elapsed = 0.0
    for kind, origins, directions, tfar, coherent in log:
        start = time.perf_counter()
        # The log holds rays as (3, n) columns; the BVH takes (n, 3) views of them.
        if kind == "intersect":
            bvh.intersect(origins.T, directions.T, coherent=coherent)
        else:
            bvh.occluded(origins.T, directions.T, 0.0, tfar)
        elapsed += time.perf_counter() - start
    return elapsed


def run(count: int, args: argparse.Namespace) -> dict:
    scene = random_field(count, seed=args.seed)
    image = dict(width=args.width, height=args.height, spp=args.spp, max_depth=args.max_depth,
                 seed=args.seed)  # fmt: skip
    with Renderer(scene, threads=args.threads, batch_size=args.batch_size) as renderer:
        # Compile and warm the kernels on a tiny image so the timed render measures rendering.
        renderer.render(width=16, height=9, spp=1, max_depth=args.max_depth, seed=args.seed)
        stats = renderer.render(**image).stats
        peak_rss = peak_rss_mb()  # before the log below holds every ray in memory
        rays_by_kind = dict(stats.rays)
        render_s = [stats.render_s]
        # Once more, logging every query (not timed).
        log = record_queries(renderer, image)
        # Timed renders, each followed at once by a replay of its rays: the machine's load
        # changes slowly, so each pair's ratio is a fair one even when the load does change.
        raw_s = []
        for _ in range(args.repeat):
            render_s.append(renderer.render(**image).stats.render_s)
            raw_s.append(replay(renderer, log))
        efficiency = float(np.median(np.divide(raw_s, render_s[1:])))
        best_s = min(render_s)
        rays = sum(rays_by_kind.values())
        return {
            "count": count,
            "width": args.width,
            "height": args.height,
            "spp": args.spp,
            "max_depth": args.max_depth,
            "threads": renderer.workers,
            "batch_size": renderer.batch_size,
            "build_s": round(stats.build_s, 4),
            "render_s": round(best_s, 3),
            "render_s_all": [round(x, 3) for x in render_s],
            "rays": rays_by_kind,
            "rays_per_s": round(rays / best_s),
            "raw_rays_per_s": round(rays / min(raw_s)),
            "raw_s_all": [round(x, 3) for x in raw_s],
            "efficiency": round(efficiency, 3),
            "peak_rss_mb": round(peak_rss, 1),
            "repeat": args.repeat,
        }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[1000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--max-depth", type=int, default=6)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch-size", type=int, default=DEFAULT_BATCH_SIZE)
    parser.add_argument("--repeat", type=int, default=3, help="best of this many renders/replays")
    args = parser.parse_args()
    for count in args.counts:
        print(json.dumps(run(count, args)), flush=True)


if __name__ == "__main__":
    main()
