"""Moving spheres between frames: ``BVH.move_spheres`` (update in place, refit) against a fresh
build, and what a tree kept over large motion costs the rays, in turns.

``--count`` random spheres (default 1e6, radius 0.1-0.5 in a cube of side 200) are moved by a
random walk of ``--step`` (in units of the mean radius) a frame, for ``--frames`` frames. Each
frame: ``move_spheres`` on the movable BVH, a fresh BVH built on the same spheres, and the same
camera-like rays traced through both (the order alternating frame to frame). ``move_s`` against
``build_s`` says whether Embree refitted or rebuilt; ``trace_ratio`` (moved / fresh, per
frame) is the quality a kept tree has lost after the motion so far: the number a rule "rebuild
when the spheres have moved more than X" is read from. The hits are checked equal (bitwise).
With ``--kind point`` (Embree's own ``RTC_GEOMETRY_TYPE_SPHERE_POINT``) the same spheres are
also built as user geometry and traced in turn (``trace_point_over_user``).

    python benchmarks/refit.py                              # 1e6 spheres, 8 frames
    python benchmarks/refit.py --count 20000 --frames 3 --rays 20000
    python benchmarks/refit.py --kind point    # Embree's point spheres, beside user spheres

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from embree_rt.embree import Rays
from embree_rt.embree.bvh import BVH


def timed(function):
    began = time.perf_counter()
    result = function()
    return time.perf_counter() - began, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--step", type=float, default=1.0)
    parser.add_argument("--rays", type=int, default=500_000)
    parser.add_argument(
        "--kind", choices=("user", "point"), default="user", help="user or Embree's point spheres"
    )
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    centers = rng.uniform(-100.0, 100.0, (args.count, 3)).astype(np.float32)
    radii = rng.uniform(0.1, 0.5, args.count).astype(np.float32)
    origins = np.tile(np.float32([0.0, 0.0, -300.0]), (args.rays, 1))
    directions = rng.normal(0.0, 0.2, (args.rays, 3)).astype(np.float32)
    directions[:, 2] = 1.0
    moving = BVH(movable=True)
    geom_id = moving.add_spheres(centers, radii, kind=args.kind)
    first_build_s, _ = timed(moving.commit)
    moving.intersect(Rays(origins[:1000], directions[:1000]))  # (the query's compile, not timed)
    rows = []
    moved = centers.copy()
    for frame in range(1, args.frames + 1):
        moved += rng.normal(0.0, args.step * float(radii.mean()), moved.shape).astype(np.float32)
        move_s, _ = timed(lambda moved=moved: moving.move_spheres(geom_id, moved, radii))
        fresh = BVH()
        fresh.add_spheres(moved, radii, kind=args.kind)
        build_s, _ = timed(fresh.commit)
        trees = {"moved": moving, "fresh": fresh}
        if args.kind == "point":  # the same spheres as user geometry, built and traced in turn
            trees["user"] = BVH()
            trees["user"].add_spheres(moved, radii)
            user_build_s, _ = timed(trees["user"].commit)
            trees["user"].intersect(Rays(origins[:1000], directions[:1000]))
        names = list(trees) if frame % 2 else list(trees)[::-1]
        traces = {
            name: timed(lambda tree=trees[name]: tree.intersect(Rays(origins, directions)))
            for name in names
        }
        same = bool(np.array_equal(traces["moved"][1].t, traces["fresh"][1].t)) and bool(
            np.array_equal(traces["moved"][1].prim_id, traces["fresh"][1].prim_id)
        )
        fresh.close()
        extra = {}
        if "user" in trees:
            trees["user"].close()
            extra = {
                "build_user_s": round(user_build_s, 4),
                "trace_user_s": round(traces["user"][0], 4),
                "trace_point_over_user": round(traces["fresh"][0] / traces["user"][0], 3),
            }
        rows.append(
            {
                "frame": frame,
                "moved_radii": round(args.step * frame**0.5, 3),
                "move_s": round(move_s, 4),
                "build_s": round(build_s, 4),
                "trace_moved_s": round(traces["moved"][0], 4),
                "trace_fresh_s": round(traces["fresh"][0], 4),
                "trace_ratio": round(traces["moved"][0] / traces["fresh"][0], 3),
                "same_hits": same,
                **extra,
            }
        )
    moving.close()
    result = {
        "count": args.count,
        "kind": args.kind,
        "rays": args.rays,
        "step_radii": args.step,
        "first_build_s": round(first_build_s, 4),
        "frames": rows,
        "median_move_over_build": round(
            float(np.median([row["move_s"] / row["build_s"] for row in rows])), 3
        ),
    }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
