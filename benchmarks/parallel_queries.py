"""The compiled queries' parallel drivers (``work_split.over_chunks``) on 2 threads; prints JSON.

On the random sphere field of ``--count`` spheres with its floor, a ``SceneGeometry`` on
``--threads`` threads answers, on the camera rays of a ``--size`` square image at 1 spp: the
camera rays' nearest hits made inside the query (``intersect_camera``), the same rays again as
arrays (``BVH.intersect``, ``BVH.occluded``), shadow segments from the hits to a light
(``occluded_toward``) and ambient occlusion's rays over the hits' hemispheres
(``occluded_hemispheres``, ``--ao`` a hit). On an icosphere of ``--subdivisions``, trimesh's
``contains_points`` of ``--points`` random points in its box (the crossing parity's driver) and
every hit of rays through it (``BVH.all_hits``). Each query runs ``--repeat`` times; a row is
its median seconds and its rays (or points) per second.

    python benchmarks/parallel_queries.py --count 100000 --size 512
    python benchmarks/parallel_queries.py --count 1000 --size 64 --repeat 2   # a quick check

To compare two trees, run it under each (``PYTHONPATH=<tree>``), whole processes taking turns
(compiling or loading the kernels included, so a kernel that misses numba's disk cache shows).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
import trimesh

from embree_rt.ambient_occlusion import (
    HemisphereFrames,
    HemisphereQuery,
    cosine_local_directions,
    orthonormal_frames,
)
from embree_rt.camera import camera_frame, camera_rays
from embree_rt.embree import BVH, Rays
from embree_rt.geometry import SceneGeometry
from embree_rt.scene.random_field import random_field
from embree_rt.trimesh_ray import RayMeshIntersector


def median_seconds(call, repeat: int) -> float:
    """The median wall seconds of ``repeat`` calls of ``call()``."""
    seconds = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds)


def row(name: str, seconds: float, items: int) -> dict:
    return {"query": name, "items": items, "seconds": seconds, "per_second": items / seconds}


def field_rows(args: argparse.Namespace) -> list[dict]:
    """The renderer's queries on the sphere field."""
    scene = random_field(args.count, seed=1)
    frame = camera_frame(scene.camera, args.size, args.size)
    camera = camera_rays(frame, 1, 0)
    index = np.arange(args.size * args.size, dtype=np.int64)
    rows = []
    with SceneGeometry(scene, threads=args.threads) as geometry:
        seconds = median_seconds(lambda: geometry.intersect_camera(camera, index), args.repeat)
        rows.append(row("intersect_camera", seconds, len(index)))
        hit_rows, hits, directions = geometry.intersect_camera(camera, index)
        origins = np.broadcast_to(camera.origin, (len(index), 3))
        rays = Rays(np.ascontiguousarray(origins), np.ascontiguousarray(directions.T))
        for name in ("intersect", "occluded"):
            query = getattr(geometry.bvh, name)
            rows.append(row(name, median_seconds(lambda q=query: q(rays), args.repeat), len(index)))
        normals = hits.normal
        points = hits.position + normals * np.float32(1e-3)
        light = np.array([10.0, 40.0, -10.0], np.float32)
        shadow_rows = np.arange(points.shape[1], dtype=np.int64)
        seconds = median_seconds(
            lambda: geometry.occluded_toward(points, shadow_rows, light), args.repeat
        )
        rows.append(row("occluded_toward", seconds, len(shadow_rows)))
        tangent, bitangent = orthonormal_frames(normals)
        local = cosine_local_directions(index[hit_rows], args.ao, seed=0)
        ao = HemisphereQuery(
            points, HemisphereFrames(tangent, bitangent, normals), local, float(np.inf)
        )
        seconds = median_seconds(lambda: geometry.occluded_hemispheres(ao), args.repeat)
        rows.append(row("occluded_hemispheres", seconds, local.shape[1]))
    return rows


def mesh_rows(args: argparse.Namespace) -> list[dict]:
    """trimesh's queries that run the multi-hit drivers."""
    mesh = trimesh.creation.icosphere(subdivisions=args.subdivisions)
    rng = np.random.default_rng(2)
    points = rng.uniform(-1.1, 1.1, (args.points, 3))
    intersector = RayMeshIntersector(mesh)
    seconds = median_seconds(lambda: intersector.contains_points(points), args.repeat)
    rows = [row("contains_points", seconds, len(points))]
    bvh = BVH(threads=args.threads, filters=True)
    bvh.add_triangles(mesh.vertices.astype(np.float32), mesh.faces)
    bvh.commit()
    origins = np.zeros((args.points, 3), np.float32)
    origins[:, 2] = -3.0
    origins[:, :2] = points[:, :2]
    directions = np.tile(np.float32([0.0, 0.0, 1.0]), (args.points, 1))
    rays = Rays(origins, directions)
    seconds = median_seconds(lambda: bvh.all_hits(rays, capacity=8), args.repeat)
    rows.append(row("all_hits", seconds, len(origins)))
    bvh.close()
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=100_000, help="spheres in the field")
    parser.add_argument("--size", type=int, default=512, help="the image's width and height")
    parser.add_argument("--ao", type=int, default=4, help="ambient occlusion's rays a hit")
    parser.add_argument("--subdivisions", type=int, default=6, help="the icosphere's")
    parser.add_argument("--points", type=int, default=200_000, help="contains_points' points")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows = field_rows(args) + mesh_rows(args)
    config = {**vars(args), "total_s": time.perf_counter() - start}
    print(json.dumps({"config": config, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
