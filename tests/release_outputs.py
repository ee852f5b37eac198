"""Digests of what a release outputs, to check that a change leaves every output bitwise as it was.

    PYTHONPATH=CHECKOUT python tests/release_outputs.py OUT.json   # digests of CHECKOUT's outputs
    python tests/release_outputs.py --compare BEFORE.json AFTER.json  # exit 1 on any difference

Recorded (sha256 of each array's dtype, shape and bytes):

- Every scene of the gallery (``scenes/*.toml``) and the two ``embree-rt random`` commands under
  the README's gallery, rendered by the command line (``python -m embree_rt``) to a PNG (the
  decoded 8-bit pixels) and, separately, to an ``.npz`` with every AOV (the linear float32
  beauty and each AOV array). Sizes are reduced to keep the run to a few minutes on two cores:
  640x360 at 2 samples per pixel (the gallery renders 1280x720 at 8; the random fields 1920x1080
  and 1280x720 at 1 spp, here 640x360 at 1 spp with the same sphere counts). ``--full`` renders
  the scenes at their own size and samples instead (both sides must use the same mode).
- Two frames of the animated scene, and the three-sphere scene with ``--spheres point`` and
  ``--spheres mesh``.
- ``embree_rt.trimesh_ray.RayMeshIntersector`` on the meshes and rays of
  ``benchmarks/trimesh_ray.py`` (the 1.3M-triangle icosphere, the torus asset, the 1e5-triangle
  height field; rays from seed 1, points from seed 2, 100,000 of each as the README's run): the
  outputs of ``intersects_first``, ``intersects_any``, ``intersects_id`` (first hits and all
  hits, with locations, with ``max_hits=3`` and with ``tnear=0``), ``intersects_location`` and
  ``contains_points``, plus all hits of rays aimed exactly at mesh vertices.

Only public entry points are used (the command line and ``embree_rt.trimesh_ray``), so the same
script measures a checkout from before and after an internal reorganisation. The benchmark's
mesh and ray makers are restated here (same seeds) because the benchmark imports internals.
Bitwise equality across the two runs holds on one machine: Embree picks its kernels by the
CPU's instruction set, so compare digests made on the same CPU.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

AOVS = "depth,normal,albedo,object_id,material_id"
SMALL = ["--width", "640", "--height", "360"]
RAYS = 100_000


def digest(array: np.ndarray) -> str:
    """sha256 of an array's dtype, shape and C-order bytes."""
    array = np.ascontiguousarray(array)
    h = hashlib.sha256(f"{array.dtype.str}{array.shape}".encode())
    h.update(array.tobytes())
    return h.hexdigest()


def checkout() -> Path:
    """The checkout whose ``embree_rt`` this process imports (PYTHONPATH's): its scenes and assets
    are rendered, and the command line runs from it so that it imports the same code."""
    import embree_rt

    return Path(embree_rt.__file__).resolve().parent.parent


def cli(args: list[str], root: Path) -> None:
    """Run ``python -m embree_rt ARGS`` in ``root``; raise with its stderr on failure."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    done = subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    if done.returncode != 0:
        raise SystemExit(f"embree-rt {' '.join(args)}: exit {done.returncode}\n{done.stderr}")


def png_pixels(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        return np.asarray(image)


def renders(full: bool, workdir: Path) -> dict[str, str]:
    """Digests of every CLI render (see the module docstring), keyed by job and array."""
    root = checkout()
    scene_size = [] if full else [*SMALL, "--spp", "2"]
    jobs: dict[str, list[str]] = {
        f"scene:{path.stem}": [str(path.relative_to(root)), *scene_size]
        for path in sorted((root / "scenes").glob("*.toml"))
    }
    jobs["random:1e6"] = [
        "random",
        "--count",
        "1000000",
        "--spp",
        "1",
        *(["--width", "1920", "--height", "1080"] if full else SMALL),
    ]
    jobs["random:1e5_torus_instances"] = [
        *["random", "--count", "100000", "--instance", "assets/torus.obj", "--spp", "1"],
        *(["--width", "1280", "--height", "720"] if full else SMALL),
    ]
    three = "scenes/three_spheres.toml"
    jobs["spheres_point:three_spheres"] = [three, "--spheres", "point", *SMALL, "--spp", "2"]
    jobs["spheres_mesh:three_spheres"] = [three, "--spheres", "mesh", *SMALL, "--spp", "2"]
    out: dict[str, str] = {}
    for name, args in jobs.items():
        command = args if args[0] == "random" else ["render", *args]
        stem = workdir / name.replace(":", "_")
        began = time.perf_counter()
        cli([*command, "-o", f"{stem}.png", "--quiet"], root)
        out[f"{name}/png"] = digest(png_pixels(Path(f"{stem}.png")))
        cli([*command, "-o", f"{stem}.npz", "--aov", AOVS, "--quiet"], root)
        with np.load(f"{stem}.npz", allow_pickle=False) as arrays:
            for key in sorted(arrays.files):
                out[f"{name}/npz/{key}"] = digest(arrays[key])
        print(f"{name}: {time.perf_counter() - began:.1f} s", file=sys.stderr, flush=True)
    flight = "scenes/animations/three_spheres_flight.toml"
    cli(
        [
            "render",
            flight,
            "-o",
            str(workdir / "flight_{frame:02d}.png"),
            "--frames",
            "0:2",
            *SMALL,
            "--spp",
            "2",
            "--quiet",
        ],
        root,
    )
    for frame in range(2):
        out[f"animation:three_spheres_flight/frame{frame}/png"] = digest(
            png_pixels(workdir / f"flight_{frame:02d}.png")
        )
    return out


def scan_like(triangles: int, seed: int = 0):
    """benchmarks/trimesh_ray.py's noisy height field of about ``triangles`` triangles."""
    import trimesh

    side = int(np.sqrt(triangles / 2)) + 1
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 10, side), np.linspace(0, 10, side), indexing="ij")
    z = np.sin(x) * np.cos(y) + 0.02 * rng.normal(size=x.shape)
    vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    index = np.arange(side * side).reshape(side, side)
    a, b, c, d = index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]
    faces = np.vstack(
        [
            np.column_stack([a.ravel(), b.ravel(), c.ravel()]),
            np.column_stack([a.ravel(), c.ravel(), d.ravel()]),
        ]
    )
    return trimesh.Trimesh(vertices, faces, process=False)


def benchmark_rays(mesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """benchmarks/trimesh_ray.py's rays: from a sphere around the mesh toward its box."""
    rng = np.random.default_rng(seed)
    center, size = mesh.bounds.mean(axis=0), mesh.scale
    start = rng.normal(size=(n, 3))
    origins = center + 2 * size * start / np.linalg.norm(start, axis=1)[:, None]
    return origins, rng.uniform(mesh.bounds[0], mesh.bounds[1], (n, 3)) - origins


def trimesh_queries() -> dict[str, str]:
    """Digests of every RayMeshIntersector query on the benchmark's meshes and rays."""
    import trimesh

    from embree_rt.trimesh_ray import RayMeshIntersector

    meshes = {
        "icosphere_1.3M": trimesh.creation.icosphere(subdivisions=8),
        "torus_asset": trimesh.load(checkout() / "assets" / "torus.obj", force="mesh"),
        "scan_like_1e5": scan_like(100_000),
    }
    out: dict[str, str] = {}
    for name, mesh in meshes.items():
        began = time.perf_counter()
        o, d = benchmark_rays(mesh, RAYS, seed=1)
        points = np.random.default_rng(2).uniform(mesh.bounds[0], mesh.bounds[1], (RAYS, 3))
        # rays aimed exactly at vertices, where the rules for edges and vertices decide
        vertex = np.random.default_rng(3).integers(0, len(mesh.vertices), 20_000)
        to_vertex = np.asarray(mesh.vertices)[vertex] - o[:20_000]
        ray = RayMeshIntersector(mesh)
        results = {
            "intersects_first": ray.intersects_first(o, d),
            "intersects_any": ray.intersects_any(o, d),
            "intersects_id_first": ray.intersects_id(
                o, d, multiple_hits=False, return_locations=True
            ),
            "intersects_id_all": ray.intersects_id(o, d, multiple_hits=True, return_locations=True),
            "intersects_id_all_ids": ray.intersects_id(o, d, multiple_hits=True),
            "intersects_id_max_hits_3": ray.intersects_id(o, d, max_hits=3, return_locations=True),
            "intersects_id_tnear_0": ray.intersects_id(o, d, return_locations=True, tnear=0.0),
            "intersects_location": ray.intersects_location(o, d),
            "contains_points": ray.contains_points(points),
            "vertex_rays_all": ray.intersects_id(o[:20_000], to_vertex, return_locations=True),
            "vertex_rays_first": ray.intersects_first(o[:20_000], to_vertex),
        }
        for query, result in results.items():
            parts = result if isinstance(result, tuple) else (result,)
            for i, part in enumerate(parts):
                out[f"trimesh:{name}/{query}/{i}"] = digest(np.asarray(part))
        print(f"trimesh {name}: {time.perf_counter() - began:.1f} s", file=sys.stderr, flush=True)
    return out


def cpu_isa() -> list[str]:
    """The vector instruction sets Embree chooses kernels by, as the CPU reports them."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split("flags", 1)[1].split("\n", 1)[0].split()
    except (OSError, IndexError):
        return []
    return sorted({"sse4_2", "avx", "avx2", "avx512f"} & set(flags))


def compare(before: Path, after: Path) -> int:
    """Print every output whose digest differs or that only one side has; 0 when none."""
    a = json.loads(before.read_text())
    b = json.loads(after.read_text())
    if a["mode"] != b["mode"]:
        print(f"not comparable: {before} is {a['mode']}, {after} is {b['mode']}")
        return 1
    a, b = a["outputs"], b["outputs"]
    differ = [key for key in sorted(a.keys() & b.keys()) if a[key] != b[key]]
    only = sorted(a.keys() ^ b.keys())
    for key in differ:
        print(f"differs: {key}")
    for key in only:
        print(f"only in {before if key in a else after}: {key}")
    print(
        f"{len(a.keys() & b.keys()) - len(differ)} of {len(a.keys() | b.keys())} outputs "
        "bitwise equal"
    )
    return 1 if differ or only else 0


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("out", nargs="?", type=Path, help="JSON file of digests to write")
    parser.add_argument(
        "--compare",
        nargs=2,
        type=Path,
        metavar=("A", "B"),
        help="compare two JSON files of digests instead",
    )
    parser.add_argument(
        "--full",
        action="store_true",
        help="render the gallery scenes at their own size and samples",
    )
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    if args.out is None:
        parser.error("give OUT.json or --compare A B")
    import embree_rt

    print(f"measuring the checkout at {checkout()}", file=sys.stderr, flush=True)
    began = time.perf_counter()
    with tempfile.TemporaryDirectory() as workdir:
        outputs = renders(args.full, Path(workdir))
    outputs.update(trimesh_queries())
    record = {
        "mode": "full" if args.full else "reduced",
        # not compared: where the code came from and on what it ran
        "meta": {
            "embree_rt": str(Path(embree_rt.__file__).parent),
            "machine": platform.machine(),
            "isa": cpu_isa(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "seconds": round(time.perf_counter() - began, 1),
        },
        "outputs": outputs,
    }
    args.out.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    print(f"{len(outputs)} digests -> {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
