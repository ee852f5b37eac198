"""embree_rt.trimesh_ray against trimesh's own ray and proximity backends and Open3D, taking
turns; prints JSON.

Meshes: a subdivided sphere (icosphere, 1.3e6 triangles), the project's torus asset (trimesh
ships no models, so no featuretype mesh; ``assets/torus.obj``) and a 1e5-triangle scan-like
mesh (a noisy height field). Queries: first hit (``intersects_first``) and multi-hit
(``intersects_location``, all hits) of rays from a sphere around the mesh toward random points
in its box, ``contains_points`` of random points in the box, and for the same points
``on_surface`` (closest point) and ``signed_distance`` (closed meshes only). Backends: ours
(2 threads), trimesh's ``ray_pyembree`` (embreex, one thread), on a small sample its pure-NumPy
``ray_triangle`` and its own ``ProximityQuery`` (rtree and NumPy), and, when ``open3d`` is
installed (``open3d-cpu``, the ``bench`` extra), Open3D's ``RaycastingScene`` on 2 threads
(Embree 4 too): ``cast_rays``, ``list_intersections`` (and the count-only
``count_intersections``), ``compute_occupancy`` (one ray a point), ``compute_closest_points``
and ``compute_signed_distance``. Each turn runs every backend once on the same inputs; rows
report the median rate over turns and ``vs_<backend>``, the median over turns of our rate ÷
that backend's (its rate taken on its own sample, where smaller).

``--ceiling``: instead, what bounds the first-hit query. The same rays, already in the BVH's
local frame (float32, unit directions, as ``RayMeshIntersector`` makes them), through the bare
nearest-hit query of our BVH (``BVH.intersect``: no screening, no frame change, no float64
refinement) on 1 and 2 threads, with Embree's watertight test (``robust``, what
``RayMeshIntersector`` builds) and without, and (``*_entry_ordered``) on the rays sorted by
where they enter the mesh's box, the order ``intersects_first`` traces them in on big meshes;
beside embreex's own ``EmbreeScene.run`` on the same local rays (one thread), trimesh's
embreex ``intersects_first`` (the benchmark's baseline) and our ``intersects_first``; each
taken once a turn. ``*_vs_trimesh_embreex`` is the median over turns of a rate ÷ trimesh's
embreex ``intersects_first`` in the same turn. And all hits: our ``intersects_location`` and
the bare traversal with the recording filter (``BVH.all_hits``, 8 hits of room, 2 threads) in
the given order and (``*_segment_ordered``) in the order ``intersects_location`` traces them in
on big meshes (``local_frame.ordered_local_rays``), each ÷ trimesh's embreex
``intersects_location``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

from embree_rt.embree import Rays

# ray_triangle's NumPy calls wake OpenBLAS's worker threads, which then busy-wait on the other
# core for a while: the backend timed next (ours, on two threads) lost that core (measured:
# first hits on the height field 33 ms alone, 52-56 ms right after ray_triangle). One BLAS
# thread removes that artefact; embreex and ray_triangle are single-threaded anyway.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
from pathlib import Path

import numpy as np
import trimesh
from trimesh.ray import ray_pyembree, ray_triangle

from embree_rt.embree import BVH
from embree_rt.trimesh_ray import ProximityQuery, RayMeshIntersector
from embree_rt.trimesh_ray.local_frame import ordered_local_rays

ASSETS = Path(__file__).resolve().parent.parent / "assets"


def scan_like(triangles: int, seed: int = 0) -> trimesh.Trimesh:
    """A height field with noise: a laser-scan-like open surface of about ``triangles``."""
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


def rays(mesh: trimesh.Trimesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    center, size = mesh.bounds.mean(axis=0), mesh.scale
    start = rng.normal(size=(n, 3))
    origins = center + 2 * size * start / np.linalg.norm(start, axis=1)[:, None]
    return origins, rng.uniform(mesh.bounds[0], mesh.bounds[1], (n, 3)) - origins


def timed(function, *args) -> float:
    start = time.perf_counter()
    function(*args)
    return time.perf_counter() - start


def entry_order(origins: np.ndarray, directions: np.ndarray, box: np.ndarray) -> np.ndarray:
    """(n,) order of rays (n, 3) by a Morton code of where each enters the box [0, box]: NumPy's
    version of the order ``RayMeshIntersector`` traces first hits in on big meshes
    (``embree_rt.trimesh_ray.local_frame``), to time the bare query on rays so ordered."""
    o, d = origins.astype(np.float64), directions.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (0.0 - o) / d, (box - o) / d
        near = np.nanmax(np.minimum(t0, t1), axis=1).clip(0)
        far = np.nanmin(np.maximum(t0, t1), axis=1)
        step = np.where(near <= far, near, 0.0)
        cells = np.clip((o + step[:, None] * d) / np.where(box > 0, box, 1), 0, 1) * 1023
    code = np.zeros(len(o), np.uint64)
    for axis in range(3):
        cell = cells[:, axis].astype(np.uint64)
        for bit in range(10):
            code |= ((cell >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


def ceiling(name: str, mesh: trimesh.Trimesh, n: int, turns: int) -> dict:
    """One mesh's row of first-hit rates of the bare queries (see the module docstring)."""
    origins, directions = rays(mesh, n, seed=1)
    ours = RayMeshIntersector(mesh)
    ours.intersects_first(origins[:10], directions[:10])
    scene = ours._scene  # the local frame and faces exactly as the intersector has them
    local_origins = scene.to_local(origins)
    local_directions = trimesh.util.unitize(directions).astype(np.float32)
    local_vertices = scene.to_local(np.asarray(mesh.vertices, np.float64))
    theirs = ray_pyembree.RayMeshIntersector(mesh)
    theirs.intersects_first(origins[:10], directions[:10])
    runs = {
        "trimesh_embreex": lambda: theirs.intersects_first(origins, directions),
        "embreex_bare": lambda: theirs._scene.scene.run(local_origins, local_directions),
        "embree_rt_first_hit": lambda: ours.intersects_first(origins, directions),
    }
    order = entry_order(local_origins, local_directions, local_vertices.max(axis=0))
    ordered_origins = np.ascontiguousarray(local_origins[order])
    ordered_directions = np.ascontiguousarray(local_directions[order])
    for robust in (True, False):
        for threads in (1, 2):
            bvh = BVH(threads=threads, lanes=1, robust=robust)
            bvh.add_triangles(local_vertices, scene.faces)
            bvh.commit()
            bvh.intersect(Rays(local_origins[:10], local_directions[:10]))
            key = f"bare_{'robust' if robust else 'plain'}_{threads}t"
            runs[key] = lambda bvh=bvh: bvh.intersect(Rays(local_origins, local_directions))
            if robust:
                runs[f"{key}_entry_ordered"] = lambda bvh=bvh: bvh.intersect(
                    Rays(ordered_origins, ordered_directions)
                )
    # all hits: the bare traversal with the recording filter, as RayMeshIntersector's scene
    # holds it (8 hits of room a ray, as its first trace), beside trimesh's embreex
    runs["all_hits_trimesh_embreex"] = lambda: theirs.intersects_location(origins, directions)
    runs["all_hits_embree_rt"] = lambda: ours.intersects_location(origins, directions)
    runs["all_hits_bare_2t"] = lambda: scene.bvh.all_hits(
        Rays(local_origins, local_directions, 0.0, np.inf), 8
    )
    # and on the rays in the order intersects_location traces them in on big meshes (by the
    # middle of each ray's path through the box)
    segment = ordered_local_rays(
        origins,
        trimesh.util.unitize(directions),
        scene.origin,
        scene.scale,
        scene.extent,
        mesh.bounds,
        2,
    ).local[:2]
    runs["all_hits_bare_2t_segment_ordered"] = lambda: scene.bvh.all_hits(Rays(*segment), 8)
    rates: dict[str, list[float]] = {key: [] for key in runs}
    for _ in range(turns):
        for key, run in runs.items():
            rates[key].append(n / timed(run))
    baseline = rates["trimesh_embreex"]
    versus_all = {
        f"{key}_vs_trimesh_embreex": round(
            float(
                np.median(
                    [
                        rate / base
                        for rate, base in zip(
                            rates[key], rates["all_hits_trimesh_embreex"], strict=True
                        )
                    ]
                )
            ),
            2,
        )
        for key in ("all_hits_embree_rt", "all_hits_bare_2t", "all_hits_bare_2t_segment_ordered")
    }
    return {
        "mesh": name,
        "triangles": len(mesh.faces),
        "rays": n,
        "turns": turns,
        "load_average": round(os.getloadavg()[0], 2),
        **{f"{key}_krays_s": round(float(np.median(v)) / 1e3, 1) for key, v in rates.items()},
        **{
            f"{key}_vs_trimesh_embreex": round(
                float(np.median([rate / base for rate, base in zip(v, baseline, strict=True)])), 2
            )
            for key, v in rates.items()
            if key != "trimesh_embreex" and not key.startswith("all_hits")
        },
        **versus_all,
    }


class Open3DScene:
    """Open3D's ``RaycastingScene`` on ``threads`` threads, answering the benchmark's queries:
    rays as given (origins, directions (n, 3) float64) become its (n, 6) float32 tensor."""

    def __init__(self, mesh: trimesh.Trimesh, threads: int = 2) -> None:
        import open3d

        self._core = open3d.core
        self.scene = open3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            open3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
            open3d.core.Tensor(np.asarray(mesh.faces, np.uint32)),
        )
        self.threads = threads

    def _rays(self, origins, directions):
        return self._core.Tensor(np.hstack([origins, directions]).astype(np.float32))

    def _points(self, points):
        return self._core.Tensor(np.asarray(points, np.float32))

    def first_hit(self, origins, directions) -> np.ndarray:
        answer = self.scene.cast_rays(self._rays(origins, directions), nthreads=self.threads)
        return answer["primitive_ids"].numpy()

    def all_hits(self, origins, directions) -> np.ndarray:
        """(k,) ray index of every hit; the answer also holds the hit points' coordinates."""
        answer = self.scene.list_intersections(
            self._rays(origins, directions), nthreads=self.threads
        )
        return answer["ray_ids"].numpy()

    def hit_counts(self, origins, directions) -> np.ndarray:
        return self.scene.count_intersections(
            self._rays(origins, directions), nthreads=self.threads
        ).numpy()

    def occupancy(self, points) -> np.ndarray:
        return self.scene.compute_occupancy(self._points(points), nthreads=self.threads).numpy()

    def closest_points(self, points) -> np.ndarray:
        answer = self.scene.compute_closest_points(self._points(points), nthreads=self.threads)
        return answer["points"].numpy()

    def signed_distance(self, points) -> np.ndarray:
        return self.scene.compute_signed_distance(
            self._points(points), nthreads=self.threads
        ).numpy()


def open3d_available() -> bool:
    try:
        import open3d  # noqa: F401
    except ImportError:
        return False
    return True


def take_turns(runs: dict, turns: int) -> dict[str, list[float]]:
    """``runs``: name -> (function of no arguments, items it answers); every run once a turn,
    in the same order. Returns name -> rate (items/s) of each turn."""
    rates: dict[str, list[float]] = {key: [] for key in runs}
    for _ in range(turns):
        for key, (run, count) in runs.items():
            rates[key].append(count / timed(run))
    return rates


def row(rates: dict[str, list[float]], ours: str) -> dict:
    """Median rates (k items/s) and ``vs_<name>``: median over turns of ours ÷ each other's."""
    out = {f"{key}_k_s": round(float(np.median(v)) / 1e3, 2) for key, v in rates.items()}
    for key, v in rates.items():
        if key != ours:
            out[f"vs_{key}"] = round(
                float(np.median([a / b for a, b in zip(rates[ours], v, strict=True)])), 2
            )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--reference-rays", type=int, default=2_000)
    parser.add_argument(
        "--reference-points",
        type=int,
        default=1_000,
        help="points for trimesh's own (slow) proximity queries",
    )
    parser.add_argument("--turns", type=int, default=3)
    parser.add_argument(
        "--ceiling", action="store_true", help="bare nearest-hit rates instead (see the docstring)"
    )
    args = parser.parse_args()
    meshes = {
        "icosphere_1.3M": trimesh.creation.icosphere(subdivisions=8),
        "torus_asset": trimesh.load(ASSETS / "torus.obj", force="mesh"),
        "scan_like_1e5": scan_like(100_000),
    }
    if args.ceiling:
        for name, mesh in meshes.items():
            print(json.dumps(ceiling(name, mesh, args.rays, args.turns)), flush=True)
        return
    with_open3d = open3d_available()
    for name, mesh in meshes.items():
        for line in mesh_rows(name, mesh, args, with_open3d):
            print(json.dumps(line), flush=True)


def mesh_rows(name: str, mesh: trimesh.Trimesh, args, with_open3d: bool):
    """One mesh's rows, query by query (each yielded once its turns are done)."""
    n = args.rays
    origins, directions = rays(mesh, n, seed=1)
    points = np.random.default_rng(2).uniform(mesh.bounds[0], mesh.bounds[1], (n, 3))
    # ray_triangle's r-tree hands it every triangle in each ray's bounding box (most of a
    # sphere's for a ray through it): its memory grows as rays x triangles
    reference_rays = max(3, min(args.reference_rays, 4_000_000 // len(mesh.faces)))
    few = slice(0, reference_rays)
    few_points = slice(0, args.reference_points)
    start = time.perf_counter()
    ours = RayMeshIntersector(mesh)
    ours.intersects_first(origins[:10], directions[:10])
    build_ours = time.perf_counter() - start
    start = time.perf_counter()
    embreex = ray_pyembree.RayMeshIntersector(mesh)
    embreex.intersects_first(origins[:10], directions[:10])
    build_embreex = time.perf_counter() - start
    numpy_rays = ray_triangle.RayMeshIntersector(mesh)
    numpy_rays.intersects_first(origins[:10], directions[:10])
    nearest = ProximityQuery(mesh)
    nearest.on_surface(points[:10])
    their_nearest = trimesh.proximity.ProximityQuery(mesh)
    their_nearest.on_surface(points[:10])
    o, d, p = origins, directions, points
    queries = {
        "first_hit": {
            "embree_rt": (lambda: ours.intersects_first(o, d), n),
            "embreex": (lambda: embreex.intersects_first(o, d), n),
            "ray_triangle": (lambda: numpy_rays.intersects_first(o[few], d[few]), reference_rays),
        },
        "multi_hit": {
            "embree_rt": (lambda: ours.intersects_location(o, d), n),
            "embreex": (lambda: embreex.intersects_location(o, d), n),
            "ray_triangle": (
                lambda: numpy_rays.intersects_location(o[few], d[few]),
                reference_rays,
            ),
        },
        "contains_points": {
            "embree_rt": (lambda: ours.contains_points(p), n),
            "embreex": (lambda: embreex.contains_points(p), n),
            "ray_triangle": (lambda: numpy_rays.contains_points(p[few]), reference_rays),
        },
        "on_surface": {
            "embree_rt": (lambda: nearest.on_surface(p), n),
            "trimesh": (lambda: their_nearest.on_surface(p[few_points]), len(p[few_points])),
        },
    }
    if mesh.is_watertight:  # a sign needs an inside
        queries["signed_distance"] = {
            "embree_rt": (lambda: nearest.signed_distance(p), n),
            "trimesh": (lambda: their_nearest.signed_distance(p[few_points]), len(p[few_points])),
        }
    extra = {}
    if with_open3d:
        start = time.perf_counter()
        open3d_scene = Open3DScene(mesh)
        open3d_scene.first_hit(origins[:10], directions[:10])
        extra["build_s_open3d"] = round(time.perf_counter() - start, 3)
        queries["first_hit"]["open3d"] = (lambda: open3d_scene.first_hit(o, d), n)
        queries["multi_hit"]["open3d"] = (lambda: open3d_scene.all_hits(o, d), n)
        queries["multi_hit"]["open3d_count_only"] = (lambda: open3d_scene.hit_counts(o, d), n)
        if mesh.is_watertight:
            queries["contains_points"]["open3d"] = (lambda: open3d_scene.occupancy(p), n)
            queries["signed_distance"]["open3d"] = (lambda: open3d_scene.signed_distance(p), n)
        queries["on_surface"]["open3d"] = (lambda: open3d_scene.closest_points(p), n)
    for query, runs in queries.items():
        answers = {}
        if query == "multi_hit":
            answers["hits_embree_rt"] = len(ours.intersects_location(o, d)[1])
            answers["hits_embreex"] = len(embreex.intersects_location(o, d)[1])
            if with_open3d:
                answers["hits_open3d"] = len(open3d_scene.all_hits(o, d))
                counts = np.bincount(ours.intersects_location(o, d)[1], minlength=n)
                answers["rays_whose_count_differs_open3d"] = int(
                    (counts != open3d_scene.hit_counts(o, d)).sum()
                )
        if query == "on_surface" and with_open3d:
            # distances, not points: a point about equidistant from several triangles has
            # closest points far apart, each engine naming its own
            distance = nearest.on_surface(p)[1]
            theirs = np.linalg.norm(open3d_scene.closest_points(p) - p, axis=1)
            answers["distance_gap_open3d_max"] = float(np.abs(distance - theirs).max() / mesh.scale)
        yield {
            "mesh": name,
            "triangles": len(mesh.faces),
            "query": query,
            "rays": n,
            "ray_triangle_rays": reference_rays,
            "trimesh_points": args.reference_points,
            "load_average": round(os.getloadavg()[0], 2),
            **row(take_turns(runs, args.turns), "embree_rt"),
            "build_s_embree_rt": round(build_ours, 3),
            "build_s_embreex": round(build_embreex, 3),
            **extra,
            **answers,
        }


if __name__ == "__main__":
    main()
