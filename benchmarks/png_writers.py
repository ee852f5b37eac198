"""8-bit PNG writers, in turns: Pillow at ``film.PNG_COMPRESS_LEVEL`` (every PNG filter tried on
every row, Pillow's way) against ``film.write_pixels`` (pypng, rows unfiltered, at the same
zlib level).

The images: a render of the random field of ``--count`` spheres (default 1e6) at ``--width`` x
``--height`` (1920x1080), 1 spp, tone-mapped as a PNG holds it, and each PNG of the gallery
(``docs/*.png``, decoded). Each writer writes each image to memory ``--turns`` times, the
order alternating from turn to turn; the CPU seconds of the writing thread
(``time.thread_time``: what the write takes from the other stages of a frame, whatever else
runs) and the wall seconds are the medians over turns, with the bytes written. Both writers'
files decode to the same pixels (checked, ``same_pixels``).

    python benchmarks/png_writers.py                        # 1e6 spheres, 1080p, 7 turns
    python benchmarks/png_writers.py --count 1000 --width 320 --height 180 --turns 3

Prints one JSON object on stdout.
"""

from __future__ import annotations

import io
import json
import statistics
import time
from pathlib import Path

import numpy as np
from output_stage import field_render
from PIL import Image

from embree_rt import film

ROOT = Path(__file__).resolve().parents[1]


def pillow(pixels: np.ndarray, handle) -> None:
    Image.fromarray(pixels).save(handle, format="PNG", compress_level=film.PNG_COMPRESS_LEVEL)


def write_pixels(pixels: np.ndarray, handle) -> None:
    film.write_pixels(pixels, handle, ".png")


WRITERS = {"pillow": pillow, "write_pixels": write_pixels}


def measured(pixels: np.ndarray, turns: int) -> dict:
    """Each writer's median CPU and wall seconds over ``turns`` and its bytes, for one image."""
    cpu: dict[str, list[float]] = {name: [] for name in WRITERS}
    wall: dict[str, list[float]] = {name: [] for name in WRITERS}
    files: dict[str, bytes] = {}
    for turn in range(turns):
        for name in list(WRITERS) if turn % 2 == 0 else list(WRITERS)[::-1]:
            buffer = io.BytesIO()
            began, began_cpu = time.perf_counter(), time.thread_time()
            WRITERS[name](pixels, buffer)
            cpu[name].append(time.thread_time() - began_cpu)
            wall[name].append(time.perf_counter() - began)
            files[name] = buffer.getvalue()
    decoded = [np.asarray(Image.open(io.BytesIO(files[name]))) for name in WRITERS]
    row: dict = {"size": f"{pixels.shape[1]}x{pixels.shape[0]}"}
    for name in WRITERS:
        row[f"{name}_cpu_s"] = round(statistics.median(cpu[name]), 4)
        row[f"{name}_wall_s"] = round(statistics.median(wall[name]), 4)
        row[f"{name}_bytes"] = len(files[name])
    row["same_pixels"] = all(np.array_equal(decoded[0], other) for other in decoded[1:])
    return row


def main() -> None:
    args, image = field_render(__doc__.splitlines()[0])
    images = {"random_field": film.tonemap(image)}
    for path in sorted(ROOT.glob("docs/*.png")):
        with Image.open(path) as picture:
            images[path.name] = np.asarray(picture.convert("RGB"))
    rows = {name: measured(pixels, args.turns) for name, pixels in images.items()}
    gallery = [row for name, row in rows.items() if name != "random_field"]
    totals = {
        f"gallery_{key}": round(sum(row[key] for row in gallery), 4)
        for key in gallery[0]
        if key.endswith(("_cpu_s", "_bytes"))
    }
    result = {
        "count": args.count,
        "turns": args.turns,
        "png_compress_level": film.PNG_COMPRESS_LEVEL,
        "images": rows,
        **totals,
        "same_pixels": all(row["same_pixels"] for row in rows.values()),
    }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
