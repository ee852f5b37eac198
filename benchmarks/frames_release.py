"""A trajectory's cost per frame against the release before issue 37, on the same scene, in turns.

Issue 37 asks a steady frame of ``embree-rt render FILE --frames 0:F`` to cost at most half of
what a frame cost the release before it (a43d705), which read no particle files: its users
rendered a trajectory with a Python loop of ``render(scene)`` and ``save``. ``frames.py``'s
``loop_base`` draws other pictures than the command (another camera and rig), so here the
release's loop draws the command's own scene:

- ``embree_rt``: the command ``benchmarks/frames_ovito.py`` times (``particles.py``'s
  ``embree_render_command``: the file framed by default, one light where the default key light
  stands, no floor, ``--radius 0.5``) with ``--frames 0:F``;
- ``release``: under ``--base`` on ``PYTHONPATH``, a loop over the same frames' sphere centres
  (read by this tree once, before the timing, each frame as a ``.npy`` the loop maps), each
  particle's type colour as one of a few matte materials (the command colours by type, every
  particle matte), the command's camera and light, no floor; one ``render`` (a fresh BVH) and
  one PNG a frame.

Whole processes, exec to exit, in turns after one discarded run each; the steady seconds a frame
from the PNGs' modification times, first to last, over F - 1. The first frames of the two sides
are compared (PSNR of the decoded 8-bit pixels) to show they are the same picture.

    python benchmarks/frames_release.py GSD_FILE --base CHECKOUT [--frames 20] [--repeats 3]

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from particles import embree_render_command, key_light, load_average, run

RADIUS = 0.5

# The release's Python API (Scene, add_material, add_spheres, Camera, PointLight, render, save).
RELEASE_LOOP = """
import json, sys
import numpy as np
import embree_rt as rt
folder, out, frames = sys.argv[1], sys.argv[2], int(sys.argv[3])
setup = json.loads(open(folder + "/scene.json").read())
ids = np.load(folder + "/materials.npy")
radii = np.full(len(ids), setup["radius"], np.float32)
for k in range(frames):
    scene = rt.Scene()
    for name, color in setup["colors"].items():
        scene.add_material(name, rt.Material(**{**setup["matte"], "color": tuple(color)}))
    # ids index the materials table, whose presets come before the colours added here
    first_id = scene.material_index(next(iter(setup["colors"])))
    centers = np.load(f"{folder}/centers_{k:04d}.npy", mmap_mode="r")
    scene.add_spheres(centers, radii, ids + first_id)
    scene.camera = rt.Camera(**setup["camera"])
    scene.lights = [rt.PointLight(position=tuple(setup["light"]))]
    scene.floor = None
    result = rt.render(scene, width=setup["width"], height=setup["height"], spp=1)
    result.save(f"{out}/f_{k:04d}.png")
"""


def prepare(path: Path, folder: Path, frames: int, size: tuple[int, int]) -> None:
    """Each frame's sphere centres and the first frame's colours, camera and light, as the
    command draws them, written under ``folder`` for the release's loop."""
    import embree_rt as rt
    from embree_rt.textures import SRGB8_TO_LINEAR

    first = rt.Scene.from_particles(str(path), frame=0, floor=False)
    colors, ids = np.unique(first.sphere_colors, axis=0, return_inverse=True)
    matte = first.materials["matte"]
    fields = ("ambient", "diffuse", "specular", "shininess", "reflectivity")
    camera = first.camera
    setup = {
        # a particle's colour is 8-bit sRGB; a material's is linear
        "colors": {
            f"type{i}": [float(SRGB8_TO_LINEAR[c]) for c in row] for i, row in enumerate(colors)
        },
        "matte": {name: getattr(matte, name) for name in fields},
        "camera": {
            "position": list(camera.position),
            "look_at": list(camera.look_at),
            "up": list(camera.up),
            "fov": camera.fov,
        },
        "light": list(key_light(path)),
        "radius": RADIUS,
        "width": size[0],
        "height": size[1],
    }
    (folder / "scene.json").write_text(json.dumps(setup))
    np.save(folder / "materials.npy", ids.reshape(-1).astype(np.int32))
    for k in range(frames):
        scene = first if k == 0 else rt.Scene.from_particles(str(path), frame=k, floor=False)
        np.save(folder / f"centers_{k:04d}.npy", np.asarray(scene.sphere_centers, np.float32))


def timed(command: list[str], out: Path, frames: int, env: dict) -> dict:
    """One whole process writing ``frames`` PNGs into the empty folder ``out``."""
    out.mkdir(parents=True)
    started = time.time()
    done = run(command) if env is None else run_with(command, env)
    written = sorted(os.stat(png).st_mtime for png in out.glob("f_*.png"))
    if len(written) != frames:
        raise SystemExit(f"{command[:3]}: {len(written)} of {frames} frames written in {out}")
    steady = (written[-1] - written[0]) / (frames - 1) if frames > 1 else 0.0
    return {"seconds": done.seconds, "first_frame_s": written[0] - started, "steady_s": steady}


def run_with(command: list[str], env: dict):
    saved = dict(os.environ)
    os.environ.update(env)
    try:
        return run(command)
    finally:
        os.environ.clear()
        os.environ.update(saved)


def psnr(a: Path, b: Path) -> float:
    from PIL import Image

    x = np.asarray(Image.open(a).convert("RGB"), np.float64)
    y = np.asarray(Image.open(b).convert("RGB"), np.float64)
    mse = float(np.mean((x - y) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(255.0**2 / mse)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("path", type=Path, help="a GSD or dump trajectory")
    parser.add_argument("--base", required=True, help="checkout of the release before")
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    args = parser.parse_args()
    size = (args.width, args.height)
    report: dict = {"load_average_start": load_average(), "frames": args.frames, "size": size}
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        prepare(args.path, folder, args.frames, size)
        ours = embree_render_command(
            args.path, Path("OUT") / "f_{frame:04d}.png", size, key_light(args.path)
        )
        ours += ["--frames", f"0:{args.frames}"]

        def side(name: str, turn: int) -> dict:
            out = folder / f"{name}_{turn}"
            if name == "embree_rt":
                command = [str(out) + c[3:] if c.startswith("OUT") else c for c in ours]
                return timed(command, out, args.frames, None)
            command = [sys.executable, "-c", RELEASE_LOOP, str(folder), str(out)]
            command.append(str(args.frames))
            return timed(command, out, args.frames, {"PYTHONPATH": args.base})

        runs: dict[str, list[dict]] = {"embree_rt": [], "release": []}
        for turn in range(-1, args.repeats):
            for name in runs:
                done = side(name, turn)
                if turn >= 0:
                    runs[name].append(done)
        for name, done in runs.items():
            report[name] = {
                "seconds": [round(r["seconds"], 2) for r in done],
                "median_s": round(statistics.median(r["seconds"] for r in done), 2),
                "steady_s_per_frame": round(statistics.median(r["steady_s"] for r in done), 3),
                "first_frame_s": round(statistics.median(r["first_frame_s"] for r in done), 2),
            }
        pairs = list(zip(runs["embree_rt"], runs["release"], strict=True))
        report["steady_ratio"] = round(
            statistics.median(a["steady_s"] / b["steady_s"] for a, b in pairs), 3
        )
        report["whole_ratio"] = round(
            statistics.median(a["seconds"] / b["seconds"] for a, b in pairs), 3
        )
        report["first_frame_psnr_db"] = round(
            psnr(folder / "embree_rt_0" / "f_0000.png", folder / "release_0" / "f_0000.png"), 2
        )
    report["load_average_end"] = load_average()
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
