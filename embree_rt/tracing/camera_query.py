"""Nearest hits of camera rays made inside the kernel from their sample indices.

A render's first bounce asks for the rays of a batch of camera samples. Made in NumPy they are
two (3, n) arrays formed in a dozen passes (hash, jitter, screen position, direction, length),
then validated and read again by the query. Here each chunk of samples has its directions
written by ``compiled.camera_rays`` (bitwise the rays ``camera.sample_rays`` gives) into the
one array shading needs afterwards, and is traced at once while they are in cache; the eye,
``tnear`` and ``tfar`` are the same for every ray and are never spread into arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from embree_rt.compiled.camera_rays import CameraRays, write_directions
from embree_rt.compiled.work_split import over_chunks
from embree_rt.embree import BVH
from embree_rt.embree.kernels import CHUNK, SCRATCH_WORDS, Rays, intersect_chunk
from embree_rt.tracing.records import HitLabels, HitRecords, records_of


def camera_query_rays(origin: np.ndarray, directions: np.ndarray, origins=None) -> Rays:
    """The ``kernels.Rays`` view of n camera rays from one (3,) float32 ``origin`` (or, for an
    orthographic camera, from the columns of (3, n) float32 ``origins``) along the columns of
    (3, n) float32 ``directions`` (as the kernels below fill them), t in [0, inf]: the eye,
    tnear and tfar repeated by zero strides, not copied."""
    n = directions.shape[1]
    return Rays(
        np.broadcast_to(origin, (n, 3)) if origins is None else origins.T,
        directions.T,
        np.broadcast_to(np.float32(0.0), (n,)),
        np.broadcast_to(np.float32(np.inf), (n,)),
    )


@njit(nogil=True, cache=True)
def intersect_camera_chunk(
    words, first, stop, query, camera, index, directions, origins, rays, hits, inst_prim
):
    """Samples first .. stop: their directions (and an orthographic camera's origins) written,
    their rays traced (``intersect_chunk``)."""
    write_directions(camera, index, first, stop, directions, origins)
    intersect_chunk(words, first, stop, query, rays, hits, inst_prim)


# ``query`` a ``kernels.Query``; ``camera`` a ``compiled.camera_rays.CameraRays``, ``index``
# (n,) int64 sample indices; ``directions`` (3, n) float32 to fill, ``origins`` (3, n) float32
# to fill for an orthographic camera (else None), ``rays`` their ``camera_query_rays`` view;
# ``hits`` a ``kernels.NearestHits`` and ``inst_prim`` (n,) int32 or None, as
# ``kernels.intersect`` fills them.


@njit(parallel=True, nogil=True, cache=True)
def intersect_camera(query, camera, index, directions, origins, rays, hits, inst_prim):
    over_chunks(
        intersect_camera_chunk,
        index.shape[0],
        CHUNK,
        SCRATCH_WORDS,
        query,
        camera,
        index,
        directions,
        origins,
        rays,
        hits,
        inst_prim,
    )


def intersect_camera_records(
    bvh: BVH, camera: CameraRays, index: np.ndarray, labels: HitLabels, ids: bool = True
) -> tuple[HitRecords, np.ndarray]:
    """``records.intersect_records`` of the camera rays of samples ``index`` (n,) int64 (below
    ``width * height * spp`` of ``camera``) in ``bvh``, made inside the query: bitwise the
    records of ``camera.sample_rays``' rays, coherent. Returns the records and the rays' (3, n)
    float32 unit directions."""
    query = bvh.query(True)
    index = np.ascontiguousarray(index, np.int64)
    n = len(index)
    directions = np.empty((3, n), np.float32)
    origins = np.empty((3, n), np.float32) if camera.orthographic else None
    rays = camera_query_rays(camera.origin, directions, origins)
    hits = bvh.empty_hits(n)
    if n:
        arguments = (query, camera, index, directions, origins, rays, *bvh.kernel_hits(hits))
        bvh.run_query(intersect_camera_chunk, intersect_camera, arguments, n)
    if origins is None:
        origins = np.broadcast_to(camera.origin[:, None], (3, n))
    records = records_of(bvh, origins, directions, rays.tnear, rays.tfar, hits, labels, ids)
    return records, directions
