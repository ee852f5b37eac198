"""The multi-hit query's common case in one compiled pass: rays whose every hit is clear of
edges and grazing angles, turned from ``multihit.all_hits``' buffers into final hits.

For such a ray Embree's float32 answer needs no second look: each hit's distance is taken in
float64 from the ray's origin to the triangle's plane (``plane_distances.plane_distance``, as
trimesh computes it), hits at the origin or along a face are dropped, and the rest are sorted by
(distance, triangle). A ray with a hit within ``band_scale * magnitude / altitude`` (barycentric)
of an edge, at |cos| <= ``graze``, or that overflowed its buffer (when a retrace with more room
follows) is *messy*: left to the caller's float64 path. In NumPy this pass was a dozen passes
and gathers over every hit, more than the traversal itself on small meshes.

In parallel over chunks of rays, with an output layout that does not depend on the thread
count: each chunk writes its hits into its own range of a scratch array (sized by the hits the
traversal found in the chunk, an upper bound), then the kept counts' prefix sum places each
chunk's hits in the output, chunk after chunk. So the result is the serial pass's, bit for bit,
on any number of threads (the arithmetic of a hit reads only its own ray and triangle).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from embree_rt.compiled.pointers import prefetch
from embree_rt.compiled.work_split import chunk_count, chunk_span, parallel_region, threads_for
from embree_rt.embree.multihit import HitBuffers
from embree_rt.trimesh_ray.hit_inputs import Hits, MeshTables, Tolerances, WorldRays
from embree_rt.trimesh_ray.plane_distances import insert_by_distance, plane_distance

CHUNK = 512  # rays per parallel iteration
_AHEAD = 8  # rays whose triangles' rows are fetched ahead (4: 4.7 ms, 8: 4.0, 16: 8-12)


@njit(nogil=True, cache=True, error_model="numpy")
def _settle_chunk(first, stop, k, hits, retrace_more, rays, mesh, tolerances, messy, out):
    # rays first .. stop, their kept hits written from index k of `out` (rays, tris, distance)
    # on; returns the index past them
    prim, u, v, cos = hits.prim, hits.u, hits.v, hits.cos
    count, more = hits.count, hits.more
    origins, directions, magnitude = rays.origins, rays.directions, rays.magnitude
    near, inclusive = rays.near, rays.inclusive
    planes, altitude, floor_altitude = mesh.planes, mesh.altitude, mesh.floor_altitude
    band_scale, graze, parallel_cos = (
        tolerances.band_scale,
        tolerances.graze,
        tolerances.parallel_cos,
    )
    out_rays, out_tris, out_distance = out.rays, out.tris, out.distance
    one = np.float32(1.0)
    floor_scale = band_scale / floor_altitude if floor_altitude > 0 else np.inf
    rows = planes.ctypes.data
    for i in range(first, stop):
        # The triangles' rows are scattered over tables of tens of MB on a big mesh: their
        # loads, one after the other, left this pass waiting on memory. Started _AHEAD rays
        # early they overlap (the distances on the icosphere's hits: 10.4 -> 4.0 ms).
        if i + _AHEAD < stop:
            for j in range(count[i + _AHEAD]):
                p = prim[i + _AHEAD, j]
                prefetch(rows + 48 * p)  # a row's 48 bytes may cross a line
                prefetch(rows + 48 * p + 40)
        found = count[i]
        bad = retrace_more and more[i]
        for j in range(found):
            if bad:
                break
            p = prim[i, j]
            # float32, as the NumPy screening of the same buffers computes it
            edge = min(min(u[i, j], v[i, j]), one - u[i, j] - v[i, j])
            bad = cos[i, j] <= graze
            # the triangle's own altitude (a cache miss on a big mesh) only for hits inside the
            # mesh-wide band, which is at least as wide: the same answer
            if not bad and edge <= floor_scale * magnitude[i]:
                own = altitude[p]
                bad = own <= 0 or edge <= band_scale * magnitude[i] / own
        messy[i] = bad
        if bad:
            continue
        start = k
        for j in range(found):
            p = prim[i, j]
            distance, along = plane_distance(planes, origins, directions, i, p)
            ahead = distance >= near[i] if inclusive else distance > near[i]
            if not (ahead and along > parallel_cos):
                continue
            insert_by_distance(out_distance, out_tris, start, k, distance, p)
            out_rays[k] = i
            k += 1
    return k


@njit(nogil=True, cache=True)
def _copy_chunk(source, stop, target, kept, ray_offset, out):
    for k in range(source, stop):
        out.rays[target] = kept.rays[k] + ray_offset
        out.tris[target] = kept.tris[k]
        out.distance[target] = kept.distance[k]
        target += 1


@njit(parallel=True, nogil=True, cache=True)
def _settle(hits, retrace_more, rays, mesh, tolerances, messy, scratch, ray_offset, out):
    count = hits.count
    n = count.shape[0]
    n_chunks = chunk_count(n, CHUNK)
    starts = np.zeros(n_chunks + 1, np.int64)  # each chunk's scratch range: hits found
    for i in range(n):
        starts[i // CHUNK + 1] += count[i]
    for c in range(n_chunks):
        starts[c + 1] += starts[c]
    ends = np.empty(n_chunks, np.int64)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        ends[c] = _settle_chunk(
            first,
            stop,
            starts[c],
            hits,
            retrace_more,
            rays,
            mesh,
            tolerances,
            messy,
            scratch,
        )
    places = np.zeros(n_chunks + 1, np.int64)  # each chunk's place in the output
    for c in range(n_chunks):
        places[c + 1] = places[c] + ends[c] - starts[c]
    for c in prange(n_chunks):
        _copy_chunk(starts[c], ends[c], places[c], scratch, ray_offset, out)
    return places[n_chunks]


def _new_hits(size: int) -> Hits:
    return Hits(np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size))


def settled_hits(
    hits: HitBuffers,
    retrace_more: bool,
    rays: WorldRays,
    mesh: MeshTables,
    tolerances: Tolerances,
    threads: int = 1,
    scratch: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ray_offset: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Final hits of the clear rays of one ``all_hits`` block, and which rays are messy.

    ``hits``: ``all_hits``' ``HitBuffers`` for n rays; ``retrace_more``: rays with ``more`` set
    are messy (the caller traces them again with more room); ``rays``: the n rays
    (``hit_inputs.world_rays``); ``mesh``: the mesh's tables (a triangle of altitude 0 is
    degenerate: always messy); ``tolerances``: ``band_scale``, ``graze`` (the messy |cos|) and
    ``parallel_cos`` (the dropping |cos|) are read. ``scratch``, ``out``: (int64, int64,
    float64) arrays of at least as many items as ``hits`` holds, or None for new ones.

    Returns ``rays`` (k,) int64 (``ray_offset`` + 0 .. n - 1, ascending), ``tris`` (k,)
    int64, ``distance`` (k,) float64 sorted by (distance, triangle) within each ray, and
    ``messy`` (n,) bool.
    """
    n = len(hits.count)
    messy = np.zeros(n, bool)
    if not n:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), messy
    total = int(hits.count.sum())
    scratch = Hits(*scratch) if scratch is not None else _new_hits(total)
    out = Hits(*out) if out is not None else _new_hits(total)
    with parallel_region:
        numba.set_num_threads(threads_for(n, threads))
        kept = _settle(
            hits,
            bool(retrace_more),
            rays,
            mesh,
            tolerances,
            messy,
            scratch,
            int(ray_offset),
            out,
        )
    return out.rays[:kept], out.tris[:kept], out.distance[:kept], messy
