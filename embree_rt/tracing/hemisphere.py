"""Occlusion of ambient occlusion's hemisphere rays, built inside the kernel.

Each of k surface points sends ``samples`` rays over its hemisphere, directions given in the
point's frame (``ambient_occlusion.cosine_local_directions``). Made in NumPy they were three
gathers of the frames to every ray, a (3, n) product, sum and division, the origins repeated to
every ray, two (n, 3) arrays transposed for the query and a pass for the ground plane; here
each packet is filled straight from the points' and frames' columns, each direction formed in
float32 as NumPy formed it (``t x + b y + n z``, then divided by its length summed ``(x² + y²)
+ z²``), so the rays, and the answers, are bitwise the ones ``BVH.occluded`` gives for the same
rays, and the analytic ground plane is tested before Embree is asked.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from embree_rt.ambient_occlusion import HemisphereQuery
from embree_rt.compiled.work_split import over_chunks
from embree_rt.embree import BVH
from embree_rt.embree.kernels import CHUNK, SCRATCH_WORDS, occluded_made


class HemisphereRays(NamedTuple):
    """n = k * samples rays from k surface points: ``points`` (3, k) float32 their origins;
    ``tangent``, ``bitangent``, ``normal`` (3, k) float32 each point's orthonormal frame;
    ``local`` (3, n) float32 each ray's unit direction in its point's frame (ray r from point
    r // ``samples``); each blocked within ``distance`` (float32, inf: any), by the ground
    plane y = ``plane_y`` (float32) too with ``has_plane``."""

    points: np.ndarray
    tangent: np.ndarray
    bitangent: np.ndarray
    normal: np.ndarray
    local: np.ndarray
    samples: int
    distance: np.float32
    has_plane: bool
    plane_y: np.float32


@njit(inline="always", error_model="numpy")
def _hemisphere_lane(origins, directions, lane, rays, r):
    """Write ray ``r`` of ``rays`` (``HemisphereRays``) into packet lane ``lane``; True when
    the ground plane blocks it within its distance (then the lane is not used)."""
    points, tangent, bitangent, normal, local, samples, distance, has_plane, plane_y = rays
    i = r // samples
    x, y, z = local[0, r], local[1, r], local[2, r]
    for axis in range(3):
        origins[lane, axis] = points[axis, i]
        directions[lane, axis] = (tangent[axis, i] * x + bitangent[axis, i] * y) + normal[
            axis, i
        ] * z
    dx, dy, dz = directions[lane, 0], directions[lane, 1], directions[lane, 2]
    length = np.sqrt((dx * dx + dy * dy) + dz * dz)
    for axis in range(3):
        directions[lane, axis] /= length
    if not has_plane:
        return False
    # As NumPy tests it: t in float32 (±inf or NaN for a ray parallel to the plane), against
    # the distance in float32.
    t = (plane_y - origins[lane, 1]) / directions[lane, 1]
    return t > 0 and t <= distance


@njit(nogil=True, cache=True, error_model="numpy")
def occluded_hemisphere_chunk(words, first, stop, query, rays, blocked):
    """Rays first .. stop of ``rays`` (``HemisphereRays``): whether each is blocked, into
    ``blocked`` (n,) bool; ``words`` a scratch row of ``kernels.SCRATCH_WORDS``."""
    occluded_made(words, first, stop, query, _hemisphere_lane, rays, rays.distance, blocked)


# ``query`` a ``kernels.Query``, ``rays`` a ``HemisphereRays``, ``blocked`` (n,) bool out.


@njit(parallel=True, nogil=True, cache=True, error_model="numpy")
def occluded_hemispheres_parallel(query, rays, blocked):
    n = rays.local.shape[1]
    over_chunks(occluded_hemisphere_chunk, n, CHUNK, SCRATCH_WORDS, query, rays, blocked)


def occluded_hemispheres(
    bvh: BVH, query: HemisphereQuery, plane_y: float | None = None
) -> np.ndarray:
    """(n,) bool: whether anything in ``bvh`` (with ``plane_y``, the ground plane y = plane_y
    too) lies within ``query.distance`` (inf: any) on each of the n = k * samples rays of
    ``query`` (``HemisphereQuery``: ray r from point ``points[:, r // samples]`` ((3, k)
    float32) along ``local[:, r]`` ((3, n) float32, unit) turned into the world by that point's
    ``frames`` and normalised in float32); traced in the BVH's packets, as ``BVH.occluded``
    traces them (single rays were no faster on a 1e6-sphere scene, measured on this project's
    machine, and packets keep the answers those of ``BVH.occluded``)."""
    points, frames, local, distance = query.points, query.frames, query.local, query.distance
    points = np.ascontiguousarray(points, np.float32)
    k = points.shape[1]
    local = np.ascontiguousarray(local, np.float32)
    n = local.shape[1]
    if points.shape != (3, k) or local.shape != (3, n) or (k and n % k) or (n and not k):
        shapes = f"{points.shape}, {local.shape}"
        raise ValueError(f"points (3, k), local (3, k * samples): got {shapes}")
    tangent, bitangent, normal = (np.ascontiguousarray(f, np.float32) for f in frames)
    blocked = np.zeros(n, bool)
    if n:
        has_plane = plane_y is not None
        rays = HemisphereRays(
            points,
            tangent,
            bitangent,
            normal,
            local,
            n // k,
            np.float32(distance),
            has_plane,
            np.float32(plane_y if has_plane else 0.0),
        )
        arguments = (bvh.query(False), rays, blocked)
        bvh.run_query(occluded_hemisphere_chunk, occluded_hemispheres_parallel, arguments, n)
    return blocked
