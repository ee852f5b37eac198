"""Nearest hits of float64 rays, each screened for whether Embree's float32 answer may be wrong.

One compiled pass on all cores: each ray is moved into the BVH's local frame (shifted, scaled,
rounded to float32 once, its direction made unit), traced with Embree's nearest-hit query, and
its hit *screened*: it is suspect if it lies within a float32-scaled band of its triangle's edge
(barycentric), meets the triangle at a grazing angle, or lies at the ray's origin. Callers trust
the clear hits as they are and decide the suspect ones again (in float64, against the triangles
around them). Doing the frame change, the query and the screening in one pass spares the
NumPy temporaries of each step, which cost more than the query itself for small meshes.

The band: Embree's float32 barycentrics err by a few ulps of the largest coordinate involved
(``magnitude``: the ray's origin's or the mesh's) over the triangle's smallest altitude, so a hit
is suspect when ``min(u, v, 1 - u - v) <= band_ulps * eps32 * magnitude / altitude[prim]``.
That table is read only for hits that fail the same test with the mesh's smallest positive
altitude (a wider band): most hits pass it, and the table (one float64 per triangle, megabytes
on big meshes) is then never touched, which is where the pass spent most of its time.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from embree_rt.embree.kernels import CHUNK, SCRATCH_WORDS, _intersect_chunk

_EPS32 = np.float64(np.finfo(np.float32).eps)
# trimesh.util.unitize leaves vectors no longer than this as they are
_UNIT_THRESHOLD = 1e-12


@njit(nogil=True, cache=True)
def _screened_chunk(scene, lanes, words, first, stop, origins, directions, shift, scale, extent,
                    near_world, near_ulps, altitude, floor_altitude, band_ulps, graze,
                    near_factor, local_origins, local_directions, tnear, tfar, t, normal, u, v,
                    prim, geom, inst, origin_limit, suspect, bad):  # fmt: skip
    # the local frame, as trimesh_ray._LocalScene.to_local and trimesh.util.unitize compute it
    given = near_world.shape[0] > 0
    for i in range(first, stop):
        magnitude = extent
        finite = True
        for k in range(3):
            local = np.float32((origins[i, k] - shift[k]) * scale)
            local_origins[i, k] = local
            finite = finite and math.isfinite(local)
            magnitude = max(magnitude, abs(np.float64(local)))
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        reciprocal = 1.0 / norm if norm > _UNIT_THRESHOLD else 1.0
        local_directions[i, 0] = np.float32(dx * reciprocal)
        local_directions[i, 1] = np.float32(dy * reciprocal)
        local_directions[i, 2] = np.float32(dz * reciprocal)
        near = near_world[i] * scale if given else near_ulps * _EPS32 * magnitude
        # Embree from a little short of tnear: which hits count as at the origin is decided
        # in float64 by the caller for the suspect ones
        tnear[i] = np.float32(near * 0.5)
        tfar[i] = np.inf
        origin_limit[i] = near_factor * near
        if not (finite and math.isfinite(norm) and math.isfinite(near)):
            bad[0] = True
            local_origins[i, 0] = 0.0  # a harmless ray: the caller raises
            local_origins[i, 1] = 0.0
            local_origins[i, 2] = 0.0
            local_directions[i, 0] = 0.0
            local_directions[i, 1] = 0.0
            local_directions[i, 2] = 0.0
    _intersect_chunk(scene, lanes, words, first, stop, local_origins, local_directions, tnear,
                     tfar, t, normal, u, v, prim, geom, inst, None)  # fmt: skip
    floor_band_scale = band_ulps * _EPS32 / floor_altitude if floor_altitude > 0 else np.inf
    for i in range(first, stop):
        p = prim[i]
        if p < 0:
            suspect[i] = False
            continue
        gx, gy, gz = np.float64(normal[i, 0]), np.float64(normal[i, 1]), np.float64(normal[i, 2])
        dx = np.float64(local_directions[i, 0])
        dy = np.float64(local_directions[i, 1])
        dz = np.float64(local_directions[i, 2])
        norms = math.sqrt((gx * gx + gy * gy + gz * gz) * (dx * dx + dy * dy + dz * dz))
        cos = abs(gx * dx + gy * dy + gz * dz) / norms if norms > 0 else 0.0
        ui, vi = np.float64(u[i]), np.float64(v[i])
        edge = min(ui, vi, 1.0 - ui - vi)
        magnitude = extent
        for k in range(3):
            magnitude = max(magnitude, abs(np.float64(local_origins[i, k])))
        near_edge = edge <= floor_band_scale * magnitude
        if near_edge:  # only now read this triangle's own altitude
            own = altitude[p]
            near_edge = own <= 0 or edge <= band_ulps * _EPS32 * magnitude / own
        suspect[i] = near_edge or cos <= graze or t[i] <= origin_limit[i]


@njit(parallel=True, nogil=True, cache=True)
def _screened(scene, lanes, origins, directions, shift, scale, extent, near_world, near_ulps,
              altitude, floor_altitude, band_ulps, graze, near_factor, prim, suspect, bad):
    n = origins.shape[0]
    local_origins = np.empty((n, 3), np.float32)
    local_directions = np.empty((n, 3), np.float32)
    tnear = np.empty(n, np.float32)
    tfar = np.empty(n, np.float32)
    t = np.empty(n, np.float32)
    normal = np.empty((n, 3), np.float32)
    u = np.empty(n, np.float32)
    v = np.empty(n, np.float32)
    geom = np.empty(n, np.int32)
    inst = np.empty(n, np.int32)
    origin_limit = np.empty(n, np.float64)
    n_chunks = (n + CHUNK - 1) // CHUNK
    scratch = np.empty((n_chunks, SCRATCH_WORDS), np.uint32)
    for c in prange(n_chunks):
        _screened_chunk(scene, lanes, scratch[c], c * CHUNK, min(n, (c + 1) * CHUNK), origins,
                        directions, shift, scale, extent, near_world, near_ulps, altitude,
                        floor_altitude, band_ulps, graze, near_factor, local_origins,
                        local_directions, tnear, tfar, t, normal, u, v, prim, geom, inst,
                        origin_limit, suspect, bad)  # fmt: skip


def screened_nearest(
    scene: int,
    lanes: int,
    threads: int,
    origins: np.ndarray,
    directions: np.ndarray,
    shift: np.ndarray,
    scale: float,
    extent: float,
    near: np.ndarray | None,
    near_ulps: float,
    altitude: np.ndarray,
    floor_altitude: float,
    band_ulps: float,
    graze: float,
    near_factor: float,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Nearest hit of each ray and whether it is suspect (see the module docstring).

    ``origins``, ``directions`` (n, 3) float64 world rays (directions need not be unit);
    ``shift`` (3,) float64 and ``scale``: the local frame is ``(p - shift) * scale`` in float64,
    rounded to float32; ``extent``: the mesh's largest local coordinate; ``near`` (n,) float64
    world distances, or None for ``near_ulps`` float32 ulps of each ray's magnitude: Embree
    looks from half of it, and a hit within ``near_factor`` times it is suspect; ``altitude``
    (primitives,) float64 smallest altitude of each triangle in the local frame (0 for a
    degenerate one: always suspect), ``floor_altitude`` its smallest value (so 0 when any
    triangle is degenerate); ``graze``: hits at |cos| <= it are suspect.

    Returns ``prim`` (n,) int32 (-1 for a miss, never suspect), ``suspect`` (n,) bool and
    ``finite``: False when some ray had a non-finite coordinate (its answer is meaningless).
    """
    n = len(origins)
    prim = np.empty(n, np.int32)
    suspect = np.empty(n, bool)
    bad = np.zeros(1, bool)
    if n:
        numba.set_num_threads(threads)
        _screened(scene, lanes, np.ascontiguousarray(origins, np.float64),
                  np.ascontiguousarray(directions, np.float64),
                  np.ascontiguousarray(shift, np.float64), float(scale), float(extent),
                  np.zeros(0) if near is None else np.ascontiguousarray(near, np.float64),
                  float(near_ulps), np.ascontiguousarray(altitude, np.float64),
                  float(floor_altitude), float(band_ulps), float(graze), float(near_factor), prim,
                  suspect, bad)  # fmt: skip
    return prim, suspect, not bad[0]
