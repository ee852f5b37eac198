"""Occlusion of ambient occlusion's hemisphere rays, built inside the kernel.

Each of k surface points sends ``samples`` rays over its hemisphere, directions given in the
point's frame (``ambient_occlusion.cosine_local_directions``). Made in NumPy they were three
gathers of the frames to every ray, a (3, n) product, sum and division, the origins repeated to
every ray, two (n, 3) arrays transposed for the query and a pass for the ground plane; here
each packet is filled straight from the points' and frames' columns, each direction formed in
float32 as NumPy formed it (``t x + b y + n z``, then divided by its length summed ``(x² + y²)
+ z²``), so the rays, and the answers, are bitwise the ones ``BVH.occluded`` gives for the same
rays, and the analytic ground plane is tested before Embree is asked.

A ray that runs far through the scene's box is first asked over a short probe, t in [0, probe],
and asked again in full only when nothing blocks the probe. Embree's occlusion query stops at
the first hit it meets but visits a node's children in no particular order, so a ray that a
neighbour blocks a sphere away may first descend into the far side of the scene, through nodes
no other ray has brought into the cache: on a million touching spheres the rays that go into
the cube cost several times those that leave it. The probe keeps the traversal beside its
origin, where the point's other rays and its neighbours' have just been. The answers do not
change: the probe is the same ray with a shorter tfar, and both Embree's box tests and the hit
tests (t within [tnear, tfar]) only accept more as tfar grows, so whatever blocks the probe
blocks the whole ray, and a ray the probe leaves open is asked in full.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from embree_rt.ambient_occlusion import HemisphereQuery
from embree_rt.compiled.work_split import over_chunks
from embree_rt.embree import BVH
from embree_rt.embree.kernels import CHUNK, SCRATCH_WORDS, Query, occluded_made

# The probe's length as a share of the scene box's diagonal, and how far (in probe lengths)
# a ray must run inside the box to be probed first. Measured on this project's machine (one
# thread, the AO rays of a 1e6-sphere GSD cube and of the 1e6 random field replayed): probes of
# 1/30 to 1/60 of the diagonal did alike on the cube, and rays that leave the box within two
# probes (the cube's outward rays, nearly all of the field's) are faster asked once.
PROBE_SHARE = 1.0 / 40.0
PROBED_REACH = 2.0
# Packets of 8 rays: 16 (the widest native packet) traced these incoherent rays 5-10% slower.
HEMISPHERE_LANES = 8


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


class Probe(NamedTuple):
    """The short first query of rays that run far through the scene: ``length`` (float32, t
    in [0, length]; inf: no probe), asked of the rays whose point at ``reach`` (float32) lies
    strictly inside the scene's box ``lower`` .. ``upper`` ((3,) float32 each)."""

    length: np.float32
    reach: np.float32
    lower: np.ndarray
    upper: np.ndarray


class ChunkRays(NamedTuple):
    """Some of a chunk's rays, made once: ray ``which[p]`` of the chunk's ``origins`` and
    ``directions`` ((m, 3) float32) fills lane p's turn."""

    origins: np.ndarray
    directions: np.ndarray
    which: np.ndarray


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


@njit(inline="always")
def _chunk_lane(origins, directions, lane, source, p):
    """Lane ``lane`` filled with ray ``source.which[p]`` of a ``ChunkRays``."""
    q = source.which[p]
    for axis in range(3):
        origins[lane, axis] = source.origins[q, axis]
        directions[lane, axis] = source.directions[q, axis]
    return False


@njit(inline="always")
def _runs_far(origins, directions, q, probe):
    """Whether ray ``q``'s point at ``probe.reach`` lies strictly inside the probe's box."""
    for axis in range(3):
        x = origins[q, axis] + probe.reach * directions[q, axis]
        if not (x > probe.lower[axis] and x < probe.upper[axis]):
            return False
    return True


@njit(nogil=True, cache=True, error_model="numpy")
def occluded_hemisphere_chunk(words, first, stop, query, rays, probe, blocked):
    """Rays first .. stop of ``rays`` (``HemisphereRays``): whether each is blocked, into
    ``blocked`` (n,) bool; those that run far inside the box probed first (``Probe``);
    ``words`` a scratch row of ``kernels.SCRATCH_WORDS``. Taken ``CHUNK`` rays at a time
    (a one-thread query is one chunk of the whole batch): each group's probes and then its
    whole rays, while the nodes they share are still in the cache, in arrays of one group."""
    size = min(stop - first, CHUNK)
    origins = np.empty((size, 3), np.float32)
    directions = np.empty((size, 3), np.float32)
    probed = np.empty(size, np.int64)
    whole = np.empty(size, np.int64)
    answers = np.empty(size, np.bool_)
    probes = probe.length < rays.distance
    for start in range(first, stop, CHUNK):
        probed_count = 0
        whole_count = 0
        for q in range(min(stop - start, CHUNK)):
            if _hemisphere_lane(origins, directions, q, rays, start + q):
                blocked[start + q] = True
            elif probes and _runs_far(origins, directions, q, probe):
                probed[probed_count] = q
                probed_count += 1
            else:
                whole[whole_count] = q
                whole_count += 1
        if probed_count:
            some = ChunkRays(origins, directions, probed)
            occluded_made(words, 0, probed_count, query, _chunk_lane, some, probe.length, answers)
            for p in range(probed_count):
                if answers[p]:
                    blocked[start + probed[p]] = True
                else:  # open over the probe: asked again in full
                    whole[whole_count] = probed[p]
                    whole_count += 1
        if whole_count:
            some = ChunkRays(origins, directions, whole)
            occluded_made(words, 0, whole_count, query, _chunk_lane, some, rays.distance, answers)
            for p in range(whole_count):
                blocked[start + whole[p]] = answers[p]


# ``query`` a ``kernels.Query``, ``rays`` a ``HemisphereRays``, ``probe`` a ``Probe``,
# ``blocked`` (n,) bool out.


@njit(parallel=True, nogil=True, cache=True, error_model="numpy")
def occluded_hemispheres_parallel(query, rays, probe, blocked):
    n = rays.local.shape[1]
    over_chunks(occluded_hemisphere_chunk, n, CHUNK, SCRATCH_WORDS, query, rays, probe, blocked)


def scene_probe(lower: np.ndarray, upper: np.ndarray) -> Probe:
    """The ``Probe`` of a scene whose box is ``lower`` .. ``upper`` ((3,) float32, as
    ``BVH.bounds`` gives it): ``PROBE_SHARE`` of its diagonal, asked of rays that run
    ``PROBED_REACH`` probes inside it; none (inf) for an empty or unbounded box."""
    lower = np.asarray(lower, np.float32)
    upper = np.asarray(upper, np.float32)
    diagonal = float(np.linalg.norm(upper.astype(np.float64) - lower.astype(np.float64)))
    if not (np.all(lower <= upper) and math.isfinite(diagonal) and diagonal > 0.0):
        return Probe(np.float32(np.inf), np.float32(np.inf), lower, upper)
    length = np.float32(diagonal * PROBE_SHARE)
    return Probe(length, np.float32(length * PROBED_REACH), lower, upper)


def occluded_hemispheres(
    bvh: BVH, query: HemisphereQuery, plane_y: float | None = None
) -> np.ndarray:
    """(n,) bool: whether anything in ``bvh`` (with ``plane_y``, the ground plane y = plane_y
    too) lies within ``query.distance`` (inf: any) on each of the n = k * samples rays of
    ``query`` (``HemisphereQuery``: ray r from point ``points[:, r // samples]`` ((3, k)
    float32) along ``local[:, r]`` ((3, n) float32, unit) turned into the world by that point's
    ``frames`` and normalised in float32); the rays that run far through the BVH's box
    probed first (``scene_probe``), in packets of at most ``HEMISPHERE_LANES``: the answers
    those of ``BVH.occluded`` for the same rays."""
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
        query = bvh.query(False)
        query = Query(query.scene, query.arguments, min(query.lanes, HEMISPHERE_LANES))
        arguments = (query, rays, scene_probe(*bvh.bounds()), blocked)
        bvh.run_query(occluded_hemisphere_chunk, occluded_hemispheres_parallel, arguments, n)
    return blocked
