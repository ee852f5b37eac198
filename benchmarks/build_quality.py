"""Embree build quality and the compact flag on a huge random field: build time, memory, speed.

For each setting (``--qualities`` x compact off/on) a fresh process generates the random field
of ``--count`` spheres, builds the spheres' BVH with ``BVH(build_quality=..., compact=...)``
(``--kind``: user-geometry spheres, or Embree's own point spheres),
and traces the field's own camera rays (1920x1080, one per pixel) and shadow rays from their
hits toward the first light, on all threads. Reported per setting: build seconds, the peak
memory the build added (``VmHWM`` after the build minus ``VmRSS`` before it, with the peak
reset by ``/proc/self/clear_refs``), bytes per sphere of the BVH as built (``VmRSS`` growth),
primary and shadow Mrays/s, and a checksum of the hits (the same rays must find the same
spheres whatever the BVH).

    python benchmarks/build_quality.py --count 10000000
    python benchmarks/build_quality.py --count 30000000 --qualities low medium --no-compact

Prints one JSON object ``{"config": ..., "rows": [...]}`` on stdout and a markdown table on stderr.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from embree_rt.embree import Rays


def _status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"no {field} in /proc/self/status")


def measure(count: int, kind: str, quality: str, compact: bool, width: int, height: int) -> dict:
    """One setting, in this process (run it in a fresh one for a clean peak)."""
    import numpy as np

    from embree_rt.camera import camera_frame, sample_rays
    from embree_rt.embree import BVH
    from embree_rt.scene import random_field

    scene = random_field(count)
    frame = camera_frame(scene.camera, width, height)
    origins, directions, _ = sample_rays(frame, 1, 0, np.arange(width * height))
    before = _status_kib("VmRSS")
    Path("/proc/self/clear_refs").write_text("5")  # reset VmHWM to the current RSS
    started = time.perf_counter()
    bvh = BVH(build_quality=quality, compact=compact)
    bvh.add_spheres(scene.sphere_centers, scene.sphere_radii, kind=kind)
    bvh.commit()
    build_s = time.perf_counter() - started
    peak, after = _status_kib("VmHWM"), _status_kib("VmRSS")

    def best_of(function, repeats: int = 3) -> tuple[float, object]:
        times, result = [], None
        for _ in range(repeats):
            began = time.perf_counter()
            result = function()
            times.append(time.perf_counter() - began)
        return min(times), result

    primary_s, hits = best_of(lambda: bvh.intersect(Rays(origins.T, directions.T)))
    hit = np.flatnonzero(hits.geom_id >= 0)
    points = origins.T[hit] + directions.T[hit] * hits.t[hit, None]
    light = np.asarray(scene.lights[0].position, np.float32)
    to_light = light - points
    normal = hits.normal[hit]
    points += normal / np.linalg.norm(normal, axis=1)[:, None] * np.float32(1e-3)
    shadow_s, blocked = best_of(lambda: bvh.occluded(Rays(points, to_light, 0.0, 1.0)))
    bvh.close()
    return {
        "count": count,
        "kind": kind,
        "quality": quality,
        "compact": compact,
        "build_s": round(build_s, 2),
        "build_peak_gb": round((peak - before) / 2**20, 3),
        "bvh_bytes_per_sphere": round((after - before) * 1024 / count, 1),
        "primary_mrays_s": round(len(origins[0]) / primary_s / 1e6, 2),
        "shadow_mrays_s": round(len(points) / shadow_s / 1e6, 2),
        "hits": len(hit),
        "prim_id_sum": int(hits.prim_id[hit].astype(np.int64).sum()),
        "blocked": int(np.count_nonzero(blocked)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=10_000_000)
    parser.add_argument(
        "--kind",
        choices=("user", "point"),
        default="user",
        help="spheres as user geometry (default) or Embree's SPHERE_POINT",
    )
    parser.add_argument("--qualities", nargs="+", default=["low", "medium", "high"])
    parser.add_argument("--no-compact", action="store_true", help="only without the flag")
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--one", nargs=2, metavar=("QUALITY", "COMPACT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        quality, compact = args.one[0], args.one[1] == "1"
        print(json.dumps(measure(args.count, args.kind, quality, compact, args.width, args.height)))
        return
    rows = []
    for quality in args.qualities:
        for compact in (False,) if args.no_compact else (False, True):
            command = [
                sys.executable,
                __file__,
                "--count",
                str(args.count),
                "--kind",
                args.kind,
                "--width",
                str(args.width),
                "--height",
                str(args.height),
                "--one",
                quality,
                "1" if compact else "0",
            ]
            output = subprocess.run(command, check=True, capture_output=True, text=True).stdout
            rows.append(json.loads(output.splitlines()[-1]))
            print(json.dumps(rows[-1]), file=sys.stderr)
    config = {"count": args.count, "kind": args.kind, "width": args.width, "height": args.height}
    print(json.dumps({"config": config, "rows": rows}))
    print(
        "| quality | compact | build s | build peak GB | BVH B/sphere | primary Mrays/s | "
        "shadow Mrays/s |",
        file=sys.stderr,
    )
    print("|---|---|---:|---:|---:|---:|---:|", file=sys.stderr)
    for row in rows:
        print(
            f"| {row['quality']} | {row['compact']} | {row['build_s']} | {row['build_peak_gb']} "
            f"| {row['bvh_bytes_per_sphere']} | {row['primary_mrays_s']} | "
            f"{row['shadow_mrays_s']} |",
            file=sys.stderr,
        )


if __name__ == "__main__":
    main()
