"""Ambient occlusion's rays alone: the probe of rays that run far into the scene, against none.

A cube of ``--count`` spheres (radius 0.5, 0.8 a unit volume: the particle benchmark's files,
here made in memory) is rendered once at WIDTHxHEIGHT, 1 spp, with ``--samples`` AO rays a
camera hit, recording every AO query the integrator asks. The recorded queries are then
replayed on one thread (the integrator's: each worker asks its own batch's), in turns:

- ``probed``: as the tracer asks them (``tracing.hemisphere``: rays whose point two probes out
  lies inside the scene's box asked over the probe first, packets of ``HEMISPHERE_LANES``);
- ``whole``: every ray asked once in full (``PROBE_SHARE`` set to inf: no probe is short of
  the distance), in the same packets;
- ``whole_native``: the same with the BVH's native packet width (the code before the probe).

Each variant's answers are checked equal to the first's (bitwise). Seconds are the replaying
thread's CPU time (less moved by other work on a shared machine than the wall clock), the median
of ``--repeats`` turns; ``mrays_per_s`` the AO rays over it.

    python benchmarks/ao_rays.py                       # 1e6 spheres, 1920x1080, 12 samples
    python benchmarks/ao_rays.py --count 100000 --width 640 --height 360 --repeats 3

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import time

import numpy as np

from embree_rt import Camera, PointLight, Scene
from embree_rt.ambient_occlusion import AmbientOcclusion
from embree_rt.api import Renderer
from embree_rt.tracing import hemisphere

DENSITY = 0.8
RADIUS = 0.5


def cube_scene(count: int, width: int, height: int, samples: int) -> Scene:
    """``count`` spheres uniform in a cube at ``DENSITY``, seen from a corner, one light, no
    floor, ``samples`` AO rays a camera hit."""
    side = (count / DENSITY) ** (1.0 / 3.0)
    rng = np.random.default_rng(8)
    camera = Camera(position=(0.9 * side, 0.6 * side, 1.6 * side), look_at=(0.0, 0.0, 0.0))
    scene = Scene(camera=camera)
    scene.floor = None
    scene.lights.append(PointLight(position=(3.0 * side, 4.0 * side, 5.0 * side)))
    centers = rng.uniform(-side / 2, side / 2, (count, 3)).astype(np.float32)
    scene.add_spheres(centers, np.full(count, RADIUS, np.float32), "matte")
    scene.render.width, scene.render.height, scene.render.spp = width, height, 1
    scene.render.ao = AmbientOcclusion(samples=samples)
    return scene


def replay(geometry, queries: list, probe_share: float, lanes: int) -> tuple[float, list]:
    """CPU seconds of this thread to answer ``queries``, and the answers."""
    saved = hemisphere.PROBE_SHARE, hemisphere.HEMISPHERE_LANES
    hemisphere.PROBE_SHARE, hemisphere.HEMISPHERE_LANES = probe_share, lanes
    try:
        began = time.thread_time()
        answers = [geometry.occluded_hemispheres(query) for query in queries]
        return time.thread_time() - began, answers
    finally:
        hemisphere.PROBE_SHARE, hemisphere.HEMISPHERE_LANES = saved


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--samples", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    scene = cube_scene(args.count, args.width, args.height, args.samples)
    with Renderer(scene) as renderer:
        geometry = renderer.geometry
        asked = geometry.occluded_hemispheres
        queries = []

        def recording(query):
            queries.append(query)
            return asked(query)

        geometry.occluded_hemispheres = recording
        began = time.perf_counter()
        renderer.render()
        render_s = time.perf_counter() - began
        del geometry.occluded_hemispheres
        rays = sum(query.local.shape[1] for query in queries)
        native = geometry.bvh.lanes
        variants = {
            "probed": (hemisphere.PROBE_SHARE, hemisphere.HEMISPHERE_LANES),
            "whole": (math.inf, hemisphere.HEMISPHERE_LANES),
            "whole_native": (math.inf, native),
        }
        seconds: dict[str, list[float]] = {name: [] for name in variants}
        first = None
        for _ in range(args.repeats):
            for name, (share, lanes) in variants.items():
                spent, answers = replay(geometry, queries, share, lanes)
                seconds[name].append(spent)
                if first is None:
                    first = answers
                elif not all(np.array_equal(a, b) for a, b in zip(first, answers, strict=True)):
                    raise AssertionError(f"{name}: answers differ from the first variant's")
        blocked = float(np.mean(np.concatenate(first))) if rays else 0.0
    median = {name: statistics.median(values) for name, values in seconds.items()}
    result = {
        "count": args.count,
        "size": [args.width, args.height],
        "samples": args.samples,
        "ao_rays": rays,
        "blocked_share": blocked,
        "render_s": render_s,
        "load_average": list(os.getloadavg()),
        "cpu_s": median,
        "mrays_per_s": {name: rays / s / 1e6 for name, s in median.items() if s > 0},
        "whole_over_probed": median["whole"] / median["probed"] if median["probed"] else None,
        "native_over_probed": (
            median["whole_native"] / median["probed"] if median["probed"] else None
        ),
        "runs": seconds,
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
