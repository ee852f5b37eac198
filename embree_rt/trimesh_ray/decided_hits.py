"""The multi-hit query's rays that the compiled settling pass leaves (``settled_hits``: a hit
within float32 reach of an edge, or grazing), decided in float64 in one compiled pass.

For each such ray, as ``trimesh.ray.ray_triangle`` decides: every hit near an edge or grazing
(*suspect*) is replaced by the triangles around it, those sharing a vertex position with it
(``fans``), each tested in float64 with ray_triangle's formulas (``planes_lines``' distance,
then ``points_to_barycentric``'s Cramer's rule within ``zero``); the ray's other hits stand as
Embree found them. The union, each triangle once, keeps what lies ahead of the origin and is
not met along its plane, sorted by (distance, triangle). Rays with no suspect hit (whose
buffers overflowed and were traced again) go through the same pass, with nothing to test.

In NumPy these were a dozen passes with gathers, uniques and sorts over every candidate pair
(about 10 µs a ray, a tenth of an all-hits query on the 1.3M-triangle icosphere). Such rays
are 1-2% of a batch, but each reads a few dozen scattered table rows (fetched ahead, see
``pointers.prefetch``): in parallel over chunks of rays, each writing its own ranges, so the
output is the same on any number of threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from embree_rt.compiled.pointers import prefetch
from embree_rt.compiled.work_split import chunk_count, chunk_span, parallel_region, threads_for
from embree_rt.embree.multihit import HitBuffers
from embree_rt.trimesh_ray.hit_inputs import Fans, Hits, MeshTables, Tolerances, WorldRays
from embree_rt.trimesh_ray.plane_distances import insert_by_distance, plane_distance

CHUNK = 16  # rays per parallel iteration


class Chosen(NamedTuple):
    """The rays decided: ``rows`` (m,) int64 in the hit buffers, ``positions`` (m,) int64 in
    the world rays."""

    rows: np.ndarray
    positions: np.ndarray


class DecideWork(NamedTuple):
    """Each ray's range of candidates (``bound`` (m + 1,) int64), the candidates (int64) and
    whether each is ``tested`` in float64 (else Embree's hit stands), the kept hits' ``tris``
    (int64) and ``distance`` (float64), and how many each ray ``kept`` (m,) int64."""

    bound: np.ndarray
    candidates: np.ndarray
    tested: np.ndarray
    tris: np.ndarray
    distance: np.ndarray
    kept: np.ndarray


@njit(inline="always")
def _is_suspect(u, v, cos, edge_band_scale, altitude, graze):
    # as settled_hits screens: float32 distance from an edge against a float64 band
    edge = min(min(u, v), np.float32(1.0) - u - v)
    return edge <= edge_band_scale / altitude or cos <= graze


@njit(inline="always", error_model="numpy")
def _barycentric_hit(triangles, f, px, py, pz, zero):
    """ray_triangle's test of point p against triangle f: trimesh.triangles.points_to_barycentric
    (Cramer's rule; its row dot products summed as (x + y) + z, as trimesh's ``diagonal_dot``
    sums them) within ``zero`` of the triangle."""
    ax, ay, az = triangles[f, 0, 0], triangles[f, 0, 1], triangles[f, 0, 2]
    e0x, e0y, e0z = triangles[f, 1, 0] - ax, triangles[f, 1, 1] - ay, triangles[f, 1, 2] - az
    e1x, e1y, e1z = triangles[f, 2, 0] - ax, triangles[f, 2, 1] - ay, triangles[f, 2, 2] - az
    wx, wy, wz = px - ax, py - ay, pz - az
    dot00 = (e0x * e0x + e0y * e0y) + e0z * e0z
    dot01 = (e0x * e1x + e0y * e1y) + e0z * e1z
    dot02 = (e0x * wx + e0y * wy) + e0z * wz
    dot11 = (e1x * e1x + e1y * e1y) + e1z * e1z
    dot12 = (e1x * wx + e1y * wy) + e1z * wz
    inverse_denominator = 1.0 / (dot00 * dot11 - dot01 * dot01)
    b2 = (dot00 * dot12 - dot01 * dot02) * inverse_denominator
    b1 = (dot11 * dot02 - dot01 * dot12) * inverse_denominator
    b0 = 1 - b1 - b2
    low, high = -zero, 1 + zero
    return (b0 > low and b1 > low and b2 > low) and (b0 < high and b1 < high and b2 < high)


@njit(nogil=True, cache=True, error_model="numpy")
def _bounds_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, totals):
    rows, positions = chosen.rows, chosen.positions
    prim, u, v, cos, count = hits.prim, hits.u, hits.v, hits.cos, hits.count
    magnitude = rays.magnitude
    altitude = mesh.altitude
    band_scale, graze = tolerances.band_scale, tolerances.graze
    canonical, fan_starts = fans.canonical, fans.starts
    for a in range(first, stop):  # candidates of each ray, at most
        r, q = rows[a], positions[a]
        total = 0
        for j in range(count[r]):
            p = prim[r, j]
            total += 1
            if _is_suspect(
                u[r, j], v[r, j], cos[r, j], band_scale * magnitude[q], altitude[p], graze
            ):
                for c in range(3):
                    corner = canonical[p, c]
                    total += fan_starts[corner + 1] - fan_starts[corner]
        totals[a] = total


@njit(nogil=True, cache=True, error_model="numpy")
def _decide_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, work):
    # rays first .. stop; ray a's candidates and hits in bound[a] .. bound[a + 1] of `work`'s
    # arrays, kept[a] hits
    rows, positions = chosen.rows, chosen.positions
    prim, u, v, cos, count = hits.prim, hits.u, hits.v, hits.cos, hits.count
    origins, directions, magnitude = rays.origins, rays.directions, rays.magnitude
    near, inclusive = rays.near, rays.inclusive
    planes, triangles, altitude = mesh.planes, mesh.triangles, mesh.altitude
    band_scale, graze = tolerances.band_scale, tolerances.graze
    parallel_cos, zero = tolerances.parallel_cos, tolerances.zero
    canonical, fan_starts, fan_faces = fans.canonical, fans.starts, fans.faces
    bound, candidates, tested = work.bound, work.candidates, work.tested
    out_tris, out_distance, kept = work.tris, work.distance, work.kept
    for a in range(first, stop):
        r, q = rows[a], positions[a]
        stop_a = bound[a]
        for j in range(count[r]):
            p = prim[r, j]
            if _is_suspect(
                u[r, j], v[r, j], cos[r, j], band_scale * magnitude[q], altitude[p], graze
            ):
                for c in range(3):
                    corner = canonical[p, c]
                    for s in range(fan_starts[corner], fan_starts[corner + 1]):
                        candidates[stop_a] = fan_faces[s]
                        tested[stop_a] = True
                        stop_a += 1
            else:
                candidates[stop_a] = p
                tested[stop_a] = False
                stop_a += 1
        # the candidates' rows (scattered over tables of tens of MB on a big mesh) fetched now,
        # to arrive while they are sorted
        for i in range(bound[a], stop_a):
            f = candidates[i]
            prefetch(planes.ctypes.data + 48 * f)
            prefetch(planes.ctypes.data + 48 * f + 40)
            if tested[i]:
                prefetch(triangles.ctypes.data + triangles.strides[0] * f)
                prefetch(triangles.ctypes.data + triangles.strides[0] * f + 64)
        # by (triangle, tested): a triangle's first entry says whether Embree's hit stands
        for i in range(bound[a] + 1, stop_a):
            f, flag = candidates[i], tested[i]
            j = i - 1
            while j >= bound[a] and (
                candidates[j] > f or (candidates[j] == f and tested[j] and not flag)
            ):
                candidates[j + 1], tested[j + 1] = candidates[j], tested[j]
                j -= 1
            candidates[j + 1], tested[j + 1] = f, flag
        start = k = bound[a]
        for i in range(bound[a], stop_a):
            f = candidates[i]
            if i > bound[a] and candidates[i - 1] == f:
                continue
            distance, along = plane_distance(planes, origins, directions, q, f)
            if not along > parallel_cos:
                continue
            if tested[i] and not _barycentric_hit(
                triangles,
                f,
                origins[q, 0] + directions[q, 0] * distance,
                origins[q, 1] + directions[q, 1] * distance,
                origins[q, 2] + directions[q, 2] * distance,
                zero,
            ):
                continue
            if not (distance >= near[q] if inclusive else distance > near[q]):
                continue
            insert_by_distance(out_distance, out_tris, start, k, distance, f)
            k += 1
        kept[a] = k - start


@njit(nogil=True, cache=True)
def _gather_chunk(first, stop, positions, work, places, out):
    bound, tris, distance, kept = work.bound, work.tris, work.distance, work.kept
    for a in range(first, stop):
        for i in range(kept[a]):
            out.rays[places[a] + i] = positions[a]
            out.tris[places[a] + i] = tris[bound[a] + i]
            out.distance[places[a] + i] = distance[bound[a] + i]


@njit(inline="always")
def _offsets(counts):
    """(m + 1,) int64 starts of m consecutive ranges of ``counts`` (m,) int64 entries."""
    offsets = np.zeros(counts.shape[0] + 1, np.int64)
    for a in range(counts.shape[0]):
        offsets[a + 1] = offsets[a] + counts[a]
    return offsets


@njit(parallel=True, nogil=True, cache=True, error_model="numpy")
def _decide(rows, positions, hits, rays, mesh, tolerances, fans):
    # in parallel over chunks of rays, each in its own ranges (a prefix sum of bounds, then of
    # kept hits): the same output on any number of threads
    m = rows.shape[0]
    n_chunks = chunk_count(m, CHUNK)
    chosen = Chosen(rows, positions)
    totals = np.empty(m, np.int64)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, m)
        _bounds_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, totals)
    bound = _offsets(totals)
    kept = np.empty(m, np.int64)
    # each ray's range of candidates, then candidates, tested (decided in float64, else
    # Embree's hit stands), tris, distance, and how many of its hits each ray keeps
    work = DecideWork(
        bound,
        np.empty(bound[m], np.int64),
        np.empty(bound[m], np.bool_),
        np.empty(bound[m], np.int64),
        np.empty(bound[m], np.float64),
        kept,
    )
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, m)
        _decide_chunk(first, stop, chosen, hits, rays, mesh, tolerances, fans, work)
    places = _offsets(kept)
    out = Hits(
        np.empty(places[m], np.int64),
        np.empty(places[m], np.int64),
        np.empty(places[m], np.float64),
    )
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, m)
        _gather_chunk(first, stop, positions, work, places, out)
    return out


def decided_hits(
    rows: np.ndarray,
    positions: np.ndarray,
    hits: HitBuffers,
    rays: WorldRays,
    mesh: MeshTables,
    tolerances: Tolerances,
    fans: Fans,
    threads: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Final hits of the rays in rows ``rows`` (m,) int64 of ``multihit.all_hits``' buffers
    ``hits``, decided as the module docstring says.

    ``positions`` (m,) int64: each ray's index into ``rays`` (``hit_inputs.world_rays``);
    ``mesh``: the mesh's tables; ``tolerances``: ``band_scale`` and ``graze`` (which hits are
    suspect), ``parallel_cos`` (|cos| at or below which a ray misses a triangle's plane) and
    ``zero`` (ray_triangle's barycentric tolerance); ``fans``: (canonical faces (triangles,
    3), starts, faces) CSR of the faces around each vertex position; ``threads``: how many to
    run on (the answer is the same for any).

    Returns ``rays`` (k,) int64 (positions, in the order of ``positions``), ``tris`` (k,) int64
    and ``distance`` (k,) float64, sorted by (distance, triangle) within each ray.
    """
    if not len(rows):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    with parallel_region:
        numba.set_num_threads(threads_for(len(rows) * 16, threads))
        return _decide(
            np.ascontiguousarray(rows, np.int64),
            np.ascontiguousarray(positions, np.int64),
            HitBuffers(*hits[:7]),
            rays,
            mesh,
            tolerances,
            Fans(*fans),
        )
