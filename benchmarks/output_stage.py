"""The output stage, film to PNG file: today's NumPy path against the compiled one, in turns.

The random field of ``--count`` spheres (default 1e6) is rendered once at ``--width`` x
``--height`` (1920x1080), 1 spp; its linear image is then written as a PNG, turn by turn, by

- ``numpy``: the release before the compiled stage: ``display_values`` (NumPy's clamp,
  Reinhard, power 1/2.2) and ``quantize``, then Pillow at its default zlib level (6);
- ``compiled``: ``film.save_image``: ``film.tonemap``'s compiled pass, then the PNG writer
  of ``film.write_pixels`` at ``film.PNG_COMPRESS_LEVEL`` (``benchmarks/png_writers.py``
  compares the writers alone);

each to its own file, the order alternating from turn to turn, and the tone map alone timed
beside each. ``speedup`` is the median over turns of numpy / compiled, by wall time. Both files
decode to the same pixels (checked, ``same_pixels``).

    python benchmarks/output_stage.py                          # 1e6 spheres, 1080p, 7 turns
    python benchmarks/output_stage.py --count 1000 --width 320 --height 180 --turns 3

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

from embree_rt import film, render
from embree_rt.scene import random_field


def numpy_pixels(image: np.ndarray) -> np.ndarray:
    """The release before the compiled stage: NumPy's tone map and quantisation."""
    return film.quantize(film.display_values(image, film.DEFAULT_LOOK), 8)


def numpy_png(image: np.ndarray, path: Path) -> None:
    Image.fromarray(numpy_pixels(image)).save(path, format="PNG")


def timed(function) -> float:
    began = time.perf_counter()
    function()
    return time.perf_counter() - began


def field_render(description: str) -> tuple[argparse.Namespace, np.ndarray]:
    """The command line (``--count``, ``--width``, ``--height``, ``--turns``) and the (h, w, 3)
    float32 linear image of the random field it names, 1 spp, seed 0: the image the output
    benchmarks write."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--count", type=int, default=1_000_000)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--turns", type=int, default=7)
    args = parser.parse_args()
    scene = random_field(args.count, seed=0)
    return args, render(scene, width=args.width, height=args.height, spp=1, seed=0).image


def main() -> None:
    args, image = field_render(__doc__.splitlines()[0])
    with tempfile.TemporaryDirectory() as directory:
        paths = {"numpy": Path(directory, "numpy.png"), "compiled": Path(directory, "compiled.png")}
        writers = {
            "numpy": lambda: numpy_png(image, paths["numpy"]),
            "compiled": lambda: film.save_image(image, paths["compiled"]),
        }
        tone_maps = {"numpy": lambda: numpy_pixels(image), "compiled": lambda: film.tonemap(image)}
        for name in writers:  # compile and warm, outside the timing
            writers[name]()
            paths[name].unlink()
        seconds = {name: [] for name in writers}
        tone_map_seconds = {name: [] for name in writers}
        for turn in range(args.turns):
            for name in list(writers) if turn % 2 == 0 else list(writers)[::-1]:
                tone_map_seconds[name].append(timed(tone_maps[name]))
                seconds[name].append(timed(writers[name]))
                size = paths[name].stat().st_size
                if turn < args.turns - 1:
                    paths[name].unlink()
                else:
                    seconds[f"{name}_bytes"] = size
        decoded = [np.asarray(Image.open(paths[name])) for name in writers]
        result = {
            "count": args.count,
            "width": args.width,
            "height": args.height,
            "turns": args.turns,
            "png_compress_level": film.PNG_COMPRESS_LEVEL,
            **{f"{name}_s": [round(x, 4) for x in seconds[name]] for name in writers},
            **{
                f"{name}_tone_map_s": [round(x, 4) for x in tone_map_seconds[name]]
                for name in writers
            },
            **{f"{name}_bytes": seconds[f"{name}_bytes"] for name in writers},
            "speedup": round(float(np.median(np.divide(seconds["numpy"], seconds["compiled"]))), 3),
            "tone_map_speedup": round(
                float(
                    np.median(np.divide(tone_map_seconds["numpy"], tone_map_seconds["compiled"]))
                ),
                3,
            ),
            "same_pixels": bool(np.array_equal(*decoded)),
        }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
