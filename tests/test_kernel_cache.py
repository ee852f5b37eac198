"""The compiled queries' parallel drivers load from numba's disk cache in a new process.

Every driver runs ``work_split.over_chunks``, an overload inlined into it. A driver whose cache
key changes from process to process (a kernel handed to it from Python, a driver made by a
factory around a kernel) compiles again in every process, seconds each, and still answers
right: only a second process's cache log shows it. The script below runs each driver on 2
threads (one thread would take the serial path and skip them); run twice, the second process
must save nothing to the cache and load every driver from it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Each query below runs through its parallel driver, named in DRIVERS as numba's cache files
# name them (module.function).
SCRIPT = """
import numpy as np
import trimesh

from embree_rt.ambient_occlusion import (
    HemisphereFrames, HemisphereQuery, cosine_local_directions, orthonormal_frames,
)
from embree_rt.camera import camera_frame, camera_rays
from embree_rt.embree import BVH, Rays
from embree_rt.geometry import SceneGeometry
from embree_rt.scene.random_field import random_field
from embree_rt.trimesh_ray.hit_passes import crossing_parity

scene = random_field(50, seed=1)
camera = camera_rays(camera_frame(scene.camera, 16, 16), 1, 0)
index = np.arange(256, dtype=np.int64)
with SceneGeometry(scene, threads=2) as geometry:
    rows, hits, directions = geometry.intersect_camera(camera, index)
    points, normals = hits.position, hits.normal
    light = np.float32([[10.0, 40.0, -10.0]])
    geometry.occluded_toward(points, np.arange(points.shape[1]), light[0])
    list(geometry.toward_lights(points, normals, light, np.ones(points.shape[1], bool)))
    local = cosine_local_directions(index[rows], 2, seed=0)
    frames = HemisphereFrames(*orthonormal_frames(normals), normals)
    geometry.occluded_hemispheres(HemisphereQuery(points, frames, local, float("inf")))
    rays = Rays(np.zeros((4, 3), np.float32), np.tile(np.float32([0, 0, 1]), (4, 1)))
    geometry.bvh.intersect(rays)
    geometry.bvh.occluded(rays)
mesh = trimesh.creation.icosphere(subdivisions=1)
bvh = BVH(threads=2, filters=True)
bvh.add_triangles(mesh.vertices.astype(np.float32), mesh.faces)
bvh.commit()
origins = np.float32([[0.0, 0.0, -3.0], [0.1, 0.2, -3.0]])
directions = np.float32([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
bvh.all_hits(Rays(origins, directions))
crossing_parity(bvh, origins, directions, np.zeros(len(mesh.faces), np.float32), 0.0)
bvh.close()
"""

DRIVERS = (
    "kernels.intersect",
    "kernels.occluded",
    "camera_query.intersect_camera",
    "segments.occluded_segments",
    "segments.toward_light",
    "hemisphere.occluded_hemispheres_parallel",
    "multihit._all_hits",
    "hit_passes._crossing_parity",
)


def _cache_log() -> list[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NUMBA_DEBUG_CACHE": "1"}
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=900
    )
    assert done.returncode == 0, done.stderr
    return [line for line in done.stdout.splitlines() if line.startswith("[cache]")]


def test_a_second_process_loads_every_query_driver_from_the_disk_cache():
    _cache_log()  # fills the cache where it is cold
    log = _cache_log()
    assert [line for line in log if "saved" in line] == []
    for driver in DRIVERS:
        loaded = [line for line in log if "data loaded" in line and f"{driver}-" in line]
        assert loaded, f"{driver} was not loaded from the cache"
