"""Particle files beside OVITO 3: whole processes, from the file to the PNG, in turns.

Issues 35 and 36 measure embree_rt against OVITO's two ray tracers on files OVITO itself
wrote. Every timed run here is a fresh process, exec to exit (imports included: OVITO's
script begins with ``import ovito``, embree_rt's is the ``embree-rt render`` command), and the
sides take turns (A, B, C, A, B, C, ...) so that a shared machine's drifting load falls on
all of them alike; each figure is the median of ``--repeats`` turns, and each ratio the
median of the per-turn ratios (above 1: embree_rt is faster).

- ``files``: N particles (3 types, uniform in a cube at number density 0.8, OVITO's default
  radius 0.5, set in OVITO's scene and given to embree_rt as ``--radius``) written by OVITO's own
  exporters: ``export_file(pipeline, "x.dump",
  "lammps/dump", columns=[...])`` and ``"gsd/hoomd"``.
- ``render``: each file at WIDTHxHEIGHT, 1 spp, one light with shadows, no floor, rendered by
  ``embree-rt render`` (one point light where its default key light stands, ``--radius 0.5``),
  by OVITO's ``TachyonRenderer`` (its direct light with shadows; no ambient occlusion, no
  antialiasing) and by its ``OSPRayRenderer`` (1 spp, one refinement, no denoising, its direct
  light only: the ambient light, a second light sampled with shadow rays, off; one scattering
  event). OVITO's camera looks along embree_rt's framed direction and is zoomed to the scene
  (``Viewport.zoom_all``), so the pictures frame the particles roughly alike.
- ``read``: the 1e7-particle text dump read by embree_rt (``read_particles``) and by OVITO
  (``import_file`` + ``compute``, positions touched), each in a fresh process; the read alone
  (after the imports) and the whole process.
- ``ao`` (issue 36): the 1e6 GSD with 12 ambient-occlusion rays a camera hit: ``--ao 12`` in
  turns with Tachyon at ``ambient_occlusion_samples=12``. With the plain run's rays and render
  time from embree_rt's summary line: the AO rays' own rate in Mrays/s.
- ``bonds`` (issue 36): 1e6 round curve segments (``Scene.add_curves``, bonds 1 long, radius
  0.1, between points at density 0.8) built into a BVH and rendered at 1080p, 1 spp.
- ``--huge N`` (issue 35): an N-particle GSD written with gsd itself (OVITO's exporter needs
  the whole dataset in its own memory too), ``embree-rt info`` on it (the memory budget's
  verdict), then the render under ``/usr/bin/time -v``: wall time and peak memory.

OVITO runs in its own interpreter (``--ovito-python``; default this one), as it brings its own
Qt and ~600 MB (``pip install -e '.[bench]'``; its renderers need Debian's ``libvulkan1
mesa-vulkan-drivers``). Each side's first run is discarded (disk caches, numba's cache) unless
``--no-warm-up``. Load
average at the start and the end are in the JSON. Generated files live in ``--folder`` (a
temporary folder unless given; kept when given, and reused when already there).

    python benchmarks/particles.py --counts 100000 --repeats 1 --skip read ao bonds
    python benchmarks/particles.py --ovito-python /path/to/venv-ovito/bin/python
    python benchmarks/particles.py --counts --skip read ao bonds --huge 100000000
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

DENSITY = 0.8  # particles per unit volume: a Lennard-Jones liquid's, spheres of radius 0.5
RADIUS = 0.5  # every particle's, in OVITO's scene and as embree_rt's --radius
# embree_rt's framed view of a z-up particle file looks from the centre toward this direction
# (its azimuth 30°, elevation 20°, turned from its y-up convention back to the file's z up).
VIEW_FROM = (
    math.sin(math.radians(30)) * math.cos(math.radians(20)),
    -math.cos(math.radians(30)) * math.cos(math.radians(20)),
    math.sin(math.radians(20)),
)
KEY_LIGHT = (4.0, 7.0, 6.0)  # embree_rt's default key light, in model radii (y up)

# Run by OVITO's interpreter as ``python -c OVITO_SCRIPT MODE ARGS...``. Modes:
#   write COUNT FOLDER FRAMES STEP: x.gsd and x.dump (FRAMES > 1: a trajectory, each frame
#     moving every particle by STEP times a normal step)
#   render FILE PNG tachyon|ospray AO_SAMPLES WIDTH HEIGHT
#   anim FILE PATTERN tachyon|ospray WIDTH HEIGHT (every frame, PATTERN with a "*")
#   read FILE (prints the seconds of import_file + compute)
OVITO_SCRIPT = (
    f"VIEW_FROM = {VIEW_FROM!r}\nDENSITY = {DENSITY!r}\nRADIUS = {RADIUS!r}\n"
    + r"""
import sys
import time

import ovito
from ovito.io import export_file, import_file
from ovito.vis import OSPRayRenderer, TachyonRenderer, Viewport


def renderer(kind, ao_samples):
    if kind == "tachyon":
        return TachyonRenderer(
            antialiasing=False,
            direct_light=True,
            shadows=True,
            ambient_occlusion=ao_samples > 0,
            ambient_occlusion_samples=max(ao_samples, 1),
        )
    return OSPRayRenderer(
        samples_per_pixel=1,
        refinement_iterations=1,
        denoising_enabled=False,
        direct_light_enabled=True,
        ambient_light_enabled=False,
        max_scattering_events=1,
    )


def add_to_scene(path):
    # Every particle of radius RADIUS: OVITO's default is 1.2, and GSD type names such as
    # "B" and "C" would take element radii.
    pipeline = import_file(path)
    particles = pipeline.source.data.particles_
    particles.vis.radius = RADIUS
    for kind in particles.particle_types_.types_:
        kind.radius = 0.0
    pipeline.add_to_scene()


def viewport(size):
    view = Viewport(type=Viewport.Type.Perspective, camera_dir=tuple(-v for v in VIEW_FROM))
    view.zoom_all(size)
    return view


def write(count, folder, frames, step):
    import numpy as np
    from ovito.pipeline import Pipeline, PipelineSourceInterface, PythonSource

    side = (count / DENSITY) ** (1.0 / 3.0)
    rng = np.random.default_rng(35)
    base = rng.uniform(0.0, side, (count, 3))
    types = rng.integers(1, 4, count)

    class Field(PipelineSourceInterface):
        def compute_trajectory_length(self, **kwargs):
            return frames

        def create(self, data, *, frame, **kwargs):
            moved = base + np.random.default_rng(frame).normal(0.0, step * frame, (count, 3))
            data.create_cell([[side, 0, 0, 0], [0, side, 0, 0], [0, 0, side, 0]], pbc=(True,) * 3)
            particles = data.create_particles(count=count)
            particles.create_property("Position", data=moved)
            particles.create_property("Particle Type", data=types)
            particles.create_property("Particle Identifier", data=np.arange(1, count + 1))

    pipeline = Pipeline(source=PythonSource(delegate=Field()))
    many = {"multiple_frames": True} if frames > 1 else {}
    columns = ["Particle Identifier", "Particle Type", "Position.X", "Position.Y", "Position.Z"]
    export_file(pipeline, folder + "/x.dump", "lammps/dump", columns=columns, **many)
    export_file(pipeline, folder + "/x.gsd", "gsd/hoomd", **many)


mode = sys.argv[1]
if mode == "write":
    write(int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), float(sys.argv[5]))
elif mode == "render":
    path, png, kind, ao = sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5])
    size = (int(sys.argv[6]), int(sys.argv[7]))
    add_to_scene(path)
    viewport(size).render_image(size=size, filename=png, renderer=renderer(kind, ao))
elif mode == "anim":
    path, pattern, kind = sys.argv[2], sys.argv[3], sys.argv[4]
    size = (int(sys.argv[5]), int(sys.argv[6]))
    add_to_scene(path)
    viewport(size).render_anim(pattern, size=size, renderer=renderer(kind, 0))
elif mode == "read":
    started = time.perf_counter()
    data = import_file(sys.argv[2]).compute()
    low = data.particles.positions[...].min(axis=0)
    print(time.perf_counter() - started, len(data.particles), low[0])
"""
)

EMBREE_READ_SCRIPT = """
import sys
import time

from embree_rt.scene.particles import read_particles

started = time.perf_counter()
frame = read_particles(sys.argv[1])
print(time.perf_counter() - started, len(frame.positions), frame.positions[:, 0].min())
"""

BONDS_SCRIPT = (
    f"DENSITY = {DENSITY!r}\n"
    + """
import json
import sys
import time

import numpy as np

from embree_rt import Camera, PointLight, Renderer, Scene

count, width, height, png = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
side = (count / DENSITY) ** (1.0 / 3.0)
rng = np.random.default_rng(36)
middles = rng.uniform(0.0, side, (count, 3))
directions = rng.normal(size=(count, 3))
directions /= np.linalg.norm(directions, axis=1, keepdims=True)
points = np.empty((2 * count, 3))
points[0::2], points[1::2] = middles - directions / 2, middles + directions / 2
started = time.perf_counter()
scene = Scene(floor=None)
scene.add_curves(points, 0.1, "matte", starts=np.arange(0, 2 * count, 2), color=(0.8, 0.3, 0.2))
centre = np.full(3, side / 2)
scene.camera = Camera(position=tuple(centre + side * np.array([0.8, 0.6, 1.4])),
                      look_at=tuple(centre), fov=40.0)
scene.lights = [PointLight(position=tuple(centre + side * np.array([2.0, 3.5, 3.0])))]
scene.render.width, scene.render.height, scene.render.spp = width, height, 1
added = time.perf_counter()
renderer = Renderer(scene)
built = time.perf_counter()
result = renderer.render()
rendered = time.perf_counter()
result.save(png)
saved = time.perf_counter()
print(json.dumps({"segments": count, "add_curves_s": added - started, "bvh_s": built - added,
                  "render_s": rendered - built, "save_s": saved - rendered}))
"""
)


class Run(NamedTuple):
    """One process: wall seconds exec to exit, peak resident memory (MB), its output."""

    seconds: float
    peak_mb: float
    stdout: str
    stderr: str


def run(command: list[str]) -> Run:
    """``command`` as a fresh process, its wall time and peak memory (``os.wait4``'s rusage of
    that child alone). Raises RuntimeError with its stderr's tail when it fails."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        started = time.perf_counter()
        process = subprocess.Popen(command, stdout=out, stderr=err)
        _, status, usage = os.wait4(process.pid, 0)
        seconds = time.perf_counter() - started
        process.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if process.returncode != 0:
        raise RuntimeError(f"{command[:4]} failed ({process.returncode}): {stderr[-800:]}")
    return Run(seconds, usage.ru_maxrss / 1024.0, stdout, stderr)


def load_average() -> list[float]:
    with open("/proc/loadavg") as stats:
        return [float(v) for v in stats.read().split()[:3]]


def summary_parts(stderr: str) -> dict[str, float]:
    """The stage seconds and the ray count of embree_rt's summary line (``render 0.98 s``,
    ``624,481 rays``), keyed by stage; ``whole`` the line's total."""
    line = next((t for t in reversed(stderr.splitlines()) if t.startswith("embree-rt: ")), "")
    stages = re.search(r"\((.*?)\)", line)
    pairs = re.findall(r"([a-zA-Z-]+) ([\d.]+) s\b", stages.group(1) if stages else "")
    parts = {name: float(value) for name, value in pairs}
    whole = re.search(r" in ([\d.]+) s", line)
    rays = re.search(r"([\d,]+) rays", line)
    if whole:
        parts["whole"] = float(whole.group(1))
    if rays:
        parts["rays"] = float(rays.group(1).replace(",", ""))
    return parts


def embree_rt() -> list[str]:
    return [sys.executable, "-m", "embree_rt"]


def key_light(path: Path) -> tuple[float, float, float]:
    """Where embree_rt's default key light stands for the particle file ``path`` (its bounds
    from ``embree-rt info --json``, turned z up to y up): the one light of every render."""
    info = json.loads(run([*embree_rt(), "info", str(path), "--json"]).stdout)
    (x0, y0, z0), (x1, y1, z1) = info["bounds"]
    low, high = (x0, z0, -y1), (x1, z1, -y0)
    radius = math.dist(low, high) / 2.0
    return tuple(
        (lo + hi) / 2.0 + radius * k for lo, hi, k in zip(low, high, KEY_LIGHT, strict=True)
    )


def embree_render_command(
    path: Path, png: Path, size: tuple[int, int], light: tuple, ao: int = 0
) -> list[str]:
    """``embree-rt render`` of a particle file framed by default under one light, no floor."""
    position = ", ".join(f"{v:.6g}" for v in light)
    command = [*embree_rt(), "render", str(path), "-o", str(png), "--width", str(size[0])]
    command += ["--height", str(size[1]), "--spp", "1", "--no-floor", "--radius", str(RADIUS)]
    command += ["-D", f"lights=[{{position=[{position}]}}]"]
    return command + (["--ao", str(ao)] if ao else [])


def ovito_command(ovito_python: str, *args: object) -> list[str]:
    return [ovito_python, "-c", OVITO_SCRIPT, *(str(a) for a in args)]


def turns(sides: dict[str, Callable[[int], Any]], repeats: int, warm_up: bool = True) -> dict:
    """Each side (called with its turn, -1 for the warm-up) run once and discarded unless not
    ``warm_up``, then ``repeats`` turns of every side in order; each side's runs (objects with
    ``seconds``) by name."""
    for side in sides.values() if warm_up else ():
        side(-1)
    runs: dict[str, list] = {name: [] for name in sides}
    for turn in range(repeats):
        for name, side in sides.items():
            runs[name].append(side(turn))
            print(f"  {name} turn {turn}: {runs[name][-1].seconds:.2f} s", file=sys.stderr)
    return runs


def in_turns(sides: dict[str, Callable[[int], Run]], repeats: int, warm_up: bool = True) -> dict:
    """Each side run once, discarded, then ``repeats`` turns of every side in order: each
    side's runs, medians and per-turn ratios to ``embree_rt`` (others' seconds / ours)."""
    runs = turns(sides, repeats, warm_up)
    out: dict = {
        name: {
            "seconds": [round(r.seconds, 3) for r in done],
            "median_s": round(statistics.median(r.seconds for r in done), 3),
            "peak_mb": round(max(r.peak_mb for r in done)),
        }
        for name, done in runs.items()
    }
    ours = runs["embree_rt"]
    for name, done in runs.items():
        if name != "embree_rt":
            ratios = [
                theirs.seconds / mine.seconds for theirs, mine in zip(done, ours, strict=True)
            ]
            out[f"{name}_over_embree_rt"] = round(statistics.median(ratios), 2)
    for name, done in runs.items():
        stages = [summary_parts(r.stderr) for r in done]
        if name.startswith("embree_rt") and all(stages):
            out[name]["summary"] = {
                key: round(statistics.median(s.get(key, 0.0) for s in stages), 3)
                for key in stages[0]
            }
    return out


def write_files(ovito_python: str, folder: Path, count: int) -> dict[str, Path]:
    """The OVITO-written ``x.dump`` and ``x.gsd`` of ``count`` particles under ``folder``
    (written unless there already)."""
    where = folder / f"n{count}"
    files = {"dump": where / "x.dump", "gsd": where / "x.gsd"}
    if not all(path.exists() for path in files.values()):
        where.mkdir(parents=True, exist_ok=True)
        started = time.perf_counter()
        run(ovito_command(ovito_python, "write", count, where, 1, 0.0))
        print(f"wrote {count:,} in {time.perf_counter() - started:.1f} s", file=sys.stderr)
    return files


def render_sides(
    ovito_python: str, path: Path, out: Path, size: tuple[int, int], ao: int = 0
) -> dict[str, Callable[[int], Run]]:
    light = key_light(path)

    def ours(turn: int) -> Run:
        return run(embree_render_command(path, out / f"e{turn}.png", size, light, ao))

    def theirs(kind: str) -> Callable[[int], Run]:
        return lambda turn: run(
            ovito_command(ovito_python, "render", path, out / f"{kind}{turn}.png", kind, ao, *size)
        )

    sides = {"embree_rt": ours, "tachyon": theirs("tachyon")}
    if not ao:
        sides["ospray"] = theirs("ospray")
    return sides


def read_sides(ovito_python: str, path: Path) -> dict[str, Callable[[int], Run]]:
    return {
        "embree_rt": lambda turn: run([sys.executable, "-c", EMBREE_READ_SCRIPT, str(path)]),
        "ovito": lambda turn: run(ovito_command(ovito_python, "read", path)),
    }


def read_seconds(result: dict, runs_stdout: dict[str, list[str]]) -> None:
    for name, lines in runs_stdout.items():
        result[name]["read_s"] = [round(float(line.split()[0]), 3) for line in lines]


def camera_hits(path: Path, npz: Path, size: tuple[int, int], light: tuple) -> int:
    """How many pixels' camera rays hit a particle (the ``object_id`` AOV, one unjittered ray
    a pixel): at 1 spp each such hit casts the AO samples (the summary line's ray count leaves
    AO rays out)."""
    import numpy as np

    run([*embree_render_command(path, npz, size, light), "--aov", "object_id"])
    with np.load(npz) as arrays:
        return int(np.count_nonzero(arrays["object_id"] >= 0))


def write_huge_gsd(folder: Path, count: int) -> Path:
    """An N-particle GSD under ``folder``, written by gsd itself unless there already."""
    import gsd.hoomd
    import numpy as np

    path = folder / f"huge{count}.gsd"
    if not path.exists():
        side = (count / DENSITY) ** (1.0 / 3.0)
        frame = gsd.hoomd.Frame()
        frame.particles.N = count
        frame.particles.types = ["A", "B", "C"]
        rng = np.random.default_rng(8)
        frame.particles.position = rng.uniform(-side / 2, side / 2, (count, 3)).astype(np.float32)
        frame.particles.typeid = rng.integers(0, 3, count, dtype=np.uint32)
        frame.configuration.box = [side, side, side, 0, 0, 0]
        with gsd.hoomd.open(path, "w") as trajectory:
            trajectory.append(frame)
        del frame
    return path


def huge(folder: Path, count: int, size: tuple[int, int]) -> dict:
    """An N-particle GSD (``write_huge_gsd``), ``embree-rt info`` on it, and its render under
    ``/usr/bin/time -v``."""
    path = write_huge_gsd(folder, count)
    info = run([*embree_rt(), "info", str(path)])
    command = embree_render_command(path, folder / "huge.png", size, key_light(path))
    timed = run(["/usr/bin/time", "-v", *command])
    peak = re.search(r"Maximum resident set size \(kbytes\): (\d+)", timed.stderr)
    return {
        "count": count,
        "file_gb": round(path.stat().st_size / 1e9, 2),
        "info": info.stdout.strip().splitlines(),
        "seconds": round(timed.seconds, 2),
        "peak_gb": round(int(peak.group(1)) / 1e6, 2) if peak else None,
        "summary": summary_parts(timed.stderr),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", type=int, nargs="*", default=[100_000, 1_000_000, 10_000_000])
    parser.add_argument("--formats", nargs="*", default=["gsd", "dump"], choices=["gsd", "dump"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--no-warm-up", dest="warm_up", action="store_false",
        help="time from the first run (the files already in the disk cache, numba's cache made)",
    )  # fmt: skip
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--read-count", type=int, default=10_000_000)
    parser.add_argument("--ao-count", type=int, default=1_000_000)
    parser.add_argument("--ao-samples", type=int, default=12)
    parser.add_argument("--bonds", type=int, default=1_000_000)
    parser.add_argument("--huge", type=int, default=0, help="also an N-particle GSD (0: not)")
    parser.add_argument("--skip", nargs="*", default=[], choices=["render", "read", "ao", "bonds"])
    parser.add_argument("--ovito-python", default=sys.executable)
    parser.add_argument("--folder", type=Path, help="keep the files here (default: temporary)")
    args = parser.parse_args()
    size = (args.width, args.height)
    with tempfile.TemporaryDirectory() as scratch:
        folder = args.folder or Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        images = folder / "images" if args.folder else Path(scratch)
        images.mkdir(exist_ok=True)
        result: dict = {"load_average_start": load_average(), "size": list(size)}
        result["ovito"] = run(
            [args.ovito_python, "-c", "import ovito; print(ovito.version_string)"]
        ).stdout.strip()
        if "render" not in args.skip:
            result["render"] = []
            for count in args.counts:
                for kind, path in write_files(args.ovito_python, folder, count).items():
                    if kind in args.formats:
                        print(f"render {kind} {count:,}", file=sys.stderr)
                        sides = render_sides(args.ovito_python, path, images, size)
                        entry = {"count": count, "format": kind}
                        result["render"].append(entry | in_turns(sides, args.repeats, args.warm_up))
        if "read" not in args.skip:
            path = write_files(args.ovito_python, folder, args.read_count)["dump"]
            print(f"read dump {args.read_count:,}", file=sys.stderr)
            sides = read_sides(args.ovito_python, path)
            outputs: dict[str, list[str]] = {name: [] for name in sides}

            def keeping(name: str, side: Callable[[int], Run]) -> Callable[[int], Run]:
                def timed(turn: int) -> Run:
                    done = side(turn)
                    if turn >= 0:
                        outputs[name].append(done.stdout)
                    return done

                return timed

            read = in_turns(
                {n: keeping(n, s) for n, s in sides.items()}, args.repeats, args.warm_up
            )
            read_seconds(read, outputs)
            pairs = zip(read["ovito"]["read_s"], read["embree_rt"]["read_s"], strict=True)
            read["read_ovito_over_embree_rt"] = round(
                statistics.median(theirs / ours for theirs, ours in pairs), 2
            )
            result["read"] = {"count": args.read_count} | read
        if "ao" not in args.skip:
            path = write_files(args.ovito_python, folder, args.ao_count)["gsd"]
            print(f"ao {args.ao_count:,}", file=sys.stderr)
            sides = render_sides(args.ovito_python, path, images, size, ao=args.ao_samples)
            light = key_light(path)
            sides["embree_rt_no_ao"] = lambda turn: run(
                embree_render_command(path, images / f"plain{turn}.png", size, light)
            )
            ao = {"count": args.ao_count, "samples": args.ao_samples} | in_turns(
                sides, args.repeats, args.warm_up
            )
            with_ao, plain = ao["embree_rt"]["summary"], ao["embree_rt_no_ao"]["summary"]
            extra_rays = args.ao_samples * camera_hits(path, images / "ids.npz", size, light)
            extra_seconds = with_ao["render"] - plain["render"]
            ao["ao_rays"] = extra_rays
            ao["ao_mrays_per_s"] = (
                round(extra_rays / extra_seconds / 1e6, 2) if extra_seconds > 0 else None
            )
            result["ao"] = ao
        if "bonds" not in args.skip:
            print(f"bonds {args.bonds:,}", file=sys.stderr)
            command = [sys.executable, "-c", BONDS_SCRIPT, str(args.bonds), *map(str, size)]
            done = run([*command, str(images / "bonds.png")])
            result["bonds"] = json.loads(done.stdout) | {
                "whole_s": round(done.seconds, 2),
                "peak_mb": round(done.peak_mb),
            }
        if args.huge:
            print(f"huge {args.huge:,}", file=sys.stderr)
            result["huge"] = huge(folder, args.huge, size)
        result["load_average_end"] = load_average()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
