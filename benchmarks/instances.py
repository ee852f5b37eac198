"""Building many mesh instances: one Embree instance array (``BVH.add_instances``) against one
instance geometry per placement (``BVH.add_instance``), printed as JSON.

    python benchmarks/instances.py [--count 1000000] [--single-count 2000] [--turns 3]

The child is an icosphere of 320 triangles. Placements are random rotations about y, scales in
[0.5, 1.5] and positions on a square field. The array is timed from the (n, 4, 4) float64
matrices (validation included) to a committed scene; per-placement instances are timed for a
smaller count and extrapolated linearly (their cost per call is flat: each is its own Embree
geometry). Memory: resident-set growth from before the build to after the commit, and the
process's peak over the same span, per instance, beyond the child mesh.
"""

from __future__ import annotations

import argparse
import gc
import json
import resource
import time

import numpy as np
import trimesh

from embree_rt.embree import BVH


def resident_bytes() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * resource.getpagesize()


def peak_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def random_placements(count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, count)
    scale = rng.uniform(0.5, 1.5, count)
    side = 2.0 * np.sqrt(count)
    matrices = np.zeros((count, 4, 4))
    matrices[:, 0, 0] = np.cos(angle) * scale
    matrices[:, 0, 2] = np.sin(angle) * scale
    matrices[:, 1, 1] = scale
    matrices[:, 2, 0] = -np.sin(angle) * scale
    matrices[:, 2, 2] = np.cos(angle) * scale
    matrices[:, 0, 3] = rng.uniform(-side, side, count)
    matrices[:, 1, 3] = scale
    matrices[:, 2, 3] = rng.uniform(-side, side, count)
    matrices[:, 3, 3] = 1.0
    return matrices


def build_array(child: BVH, matrices: np.ndarray) -> dict:
    gc.collect()
    before = resident_bytes()
    start = time.perf_counter()
    top = BVH()
    top.add_instances(child, matrices)
    added = time.perf_counter()
    top.commit()
    done = time.perf_counter()
    grown = resident_bytes() - before
    top.close()
    return {
        "add_s": added - start,
        "commit_s": done - added,
        "total_s": done - start,
        "resident_bytes_per_instance": grown / len(matrices),
    }


def build_singles(child: BVH, matrices: np.ndarray) -> dict:
    start = time.perf_counter()
    top = BVH()
    for matrix in matrices:
        top.add_instance(child, matrix)
    added = time.perf_counter()
    top.commit()
    done = time.perf_counter()
    top.close()
    return {
        "add_s": added - start,
        "commit_s": done - added,
        "total_s": done - start,
        "per_instance_us": 1e6 * (done - start) / len(matrices),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--single-count", type=int, default=2000)
    parser.add_argument("--turns", type=int, default=3)
    args = parser.parse_args()
    mesh = trimesh.creation.icosphere(subdivisions=2)
    child = BVH()
    child.add_triangles(mesh.vertices, mesh.faces)
    child.commit()
    matrices = random_placements(args.count)
    few = matrices[: args.single_count]
    build_array(child, few)  # warm: first-call costs out of the timings
    peak_before = peak_bytes()
    resident_before = resident_bytes()
    arrays, singles = [], []
    for _ in range(args.turns):  # in turns, so a busy minute hits both alike
        arrays.append(build_array(child, matrices))
        singles.append(build_singles(child, few))
    peak_growth = max(0, peak_bytes() - max(peak_before, resident_before))
    array_s = float(np.median([a["total_s"] for a in arrays]))
    single_us = float(np.median([s["per_instance_us"] for s in singles]))
    print(
        json.dumps(
            {
                "instances": args.count,
                "child_triangles": len(mesh.faces),
                "array": {
                    "median_s": array_s,
                    "turns": arrays,
                    "peak_growth_bytes_per_instance": peak_growth / args.count,
                },
                "one_geometry_per_instance": {
                    "measured_count": args.single_count,
                    "median_us_per_instance": single_us,
                    "extrapolated_s": single_us * 1e-6 * args.count,
                    "turns": singles,
                },
                "speedup": single_us * 1e-6 * args.count / array_s,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
