"""Peak memory against bounce depth: a camera and a light inside a closed perfect mirror.

Every ray reflects at every depth (nothing escapes, the mirror loses nothing), so each bounce
traces and shades as many rays as the first. What a render holds must not grow with the depth:
each depth runs ``embree-rt render`` in a process of its own, and its peak resident memory
(``ru_maxrss`` of that process alone, by ``os.wait4``) is reported.

    python benchmarks/depth_memory.py                      # 320x180, 1 spp, depths 6 60 600
    python benchmarks/depth_memory.py --depths 6 600 6000 --width 160 --height 90

Prints one JSON object on stdout: peak RSS in MB and seconds per depth.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

MIRROR_ROOM = """\
floor = false

[camera]
position = [0.0, 0.0, 0.0]
look_at = [0.0, 0.0, -1.0]
fov = 60.0

[[lights]]
position = [0.0, 2.0, 1.0]

[materials.perfect_mirror]
reflectivity = 1.0
specular = 0.5

[[spheres]]
center = [0.0, 0.0, 0.0]
radius = 5.0
material = "perfect_mirror"
"""


def peak_rss(command: list[str]) -> tuple[float, float]:
    """(peak resident MB, wall seconds) of running ``command`` to completion."""
    began = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise SystemExit(f"{' '.join(command)}: exit {process.returncode}")
    return usage.ru_maxrss / 1024, time.perf_counter() - began  # ru_maxrss: KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--depths", type=int, nargs="+", default=[6, 60, 600])
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=180)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as directory:
        scene = Path(directory) / "mirror_room.toml"
        scene.write_text(MIRROR_ROOM)
        for depth in args.depths:
            command = [
                sys.executable,
                "-m",
                "embree_rt",
                "render",
                str(scene),
                "--quiet",
                "-o",
                str(Path(directory) / f"depth_{depth}.npy"),
                "--max-depth",
                str(depth),
                "--width",
                str(args.width),
                "--height",
                str(args.height),
                "--spp",
                str(args.spp),
                *(["--threads", str(args.threads)] if args.threads else []),
            ]
            rss, seconds = peak_rss(command)
            results[str(depth)] = {"peak_rss_mb": round(rss, 1), "seconds": round(seconds, 2)}
    image = {"width": args.width, "height": args.height, "spp": args.spp}
    print(json.dumps({"scene": "closed mirror room", **image, "depths": results}, indent=2))


if __name__ == "__main__":
    main()
