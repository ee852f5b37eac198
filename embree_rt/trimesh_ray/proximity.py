"""embree_rt's point queries behind trimesh's proximity API: ``ProximityQuery(mesh)`` answers as
``trimesh.proximity.ProximityQuery`` does, on Embree's point query on all cores.

- ``on_surface(points)``: the closest point on the mesh, its distance and its triangle, found by
  ``rtcPointQuery`` with a compiled callback and computed in float64 relative to the mesh's box
  corner, so the answers hold at any scale and any distance from the origin
  (below). Ties follow trimesh's rule, made scale-free: triangles whose
  distances agree within ``TIE_TOLERANCE`` times the mesh's size (trimesh's ``tol.merge`` read
  relative to the mesh; trimesh compares squared distances to it absolutely) tie; of those, the
  one whose normal points most towards the point wins (trimesh compares the best two, here
  all of them), and where that too ties, or the point lies on the surface, the lowest index.
- ``vertex(points)``: the nearest vertex, from trimesh's own KD-tree of the mesh's vertices
  (``mesh.kdtree``, the tree trimesh asks, so its answers and tie rule are trimesh's), queried
  on all cores.
- ``signed_distance(points)``: trimesh's sign convention, positive inside, negative outside, and
  positive (unsigned) within ``TIE_TOLERANCE`` times the mesh's size of the surface. Where the
  closest point lies inside its triangle (not on an edge or a vertex), the point minus it is
  along that triangle's normal, so the side of the triangle's plane is the side of the
  surface; elsewhere (closest point on an edge or vertex, where a face's side can mislead at
  sharp edges) the sign is embree_rt's ``contains_points``, exact ray parity, as trimesh falls
  back to its ``contains_points``. Both agree with ``contains_points`` on closed, consistently
  wound meshes; on open ones, as trimesh's, the sign is whatever those rules give.

The closest triangles. The closest point of a triangle mesh to each of many points: Embree's
point query on all cores, every distance in float64.

Embree's BVH holds the triangles rounded to float32 in a local frame (``(p - shift) * scale``);
it only says which triangles may be near. A compiled callback (``@cfunc``) computes each
candidate's closest point in float64 (Ericson, *Real-Time Collision Detection*, 5.1.5) from the
float64 triangles shifted by ``shift`` (so a mesh far from the origin keeps its precision) and
shrinks the query's radius to the best distance so far, plus a tie tolerance and a float32
margin: Embree then skips every node that cannot hold a nearer triangle, and never one that
could (the margin covers the rounding of the query point, of the triangles and of Embree's own
box distance: 16 float32 ulps of the largest coordinate involved).

Ties (a point as near to several triangles, as at an edge or a vertex, to within
``tolerance``): the callback keeps every triangle within the tolerance of the best distance so
far, so when the query ends it holds exactly those within the tolerance of the final best. Of
those, trimesh's rule (``trimesh.proximity.closest_point``): the triangle whose normal points
most towards the point (largest cosine between its unit normal and the point minus its closest
point); where the cosines tie too (within ``DOT_TOLERANCE``), or the point lies within the
tolerance of the surface (no direction to compare), the lowest triangle index. The choice is a
function of the set of tied triangles alone, not of the order in which Embree visits them.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numba
import numpy as np
import trimesh
from numba import carray, njit, prange
from trimesh import caching

from embree_rt.compiled.callbacks import on_first_use
from embree_rt.compiled.pointers import doubles, floats, words64
from embree_rt.compiled.work_split import chunk_count, chunk_span, parallel_region, threads_for
from embree_rt.embree import BVH, point_query
from embree_rt.trimesh_ray.intersector import RayMeshIntersector

# trimesh's tol.merge (1e-8), relative to the mesh's size (its bounding box's diagonal)
TIE_TOLERANCE = 1e-8
# Embree's frame: the mesh about 100 units wide, as RayMeshIntersector's
_LOCAL_SIZE = 100.0


# -- the closest triangles, in one compiled pass -----------------------------------------

# The triangle table: a, b, c (shifted, float64) and the unit normal, one row a triangle.
TABLE_COLUMNS = 12
# Cosines closer than this to the largest count as equal (then the lowest index wins).
DOT_TOLERANCE = 1e-9
# Tied triangles kept per point at first; a point with more is queried again with more room.
FIRST_CAPACITY = 16
_EPS32 = float(np.finfo(np.float32).eps)
_EPS64 = float(np.finfo(np.float64).eps)
_MARGIN_ULPS = 16.0
_TOLERANCE_ULPS = 64.0
CHUNK = 64  # points per parallel iteration

# The callback's state, one block of float64 words per query (the address Embree passes on)
_POINT = 0  # x, y, z: the point, shifted (float64)
_BEST = 3  # smallest squared distance so far
_TOLERANCE = 4  # tie tolerance on distances (world units)
_SCALE = 5  # world units -> Embree's local units
_MARGIN = 6  # float32 slack of the radius (local units)
_COUNT = 7  # tied triangles kept
_CAPACITY = 8
_OVERFLOW = 9  # 1.0 when a tied triangle found no room
_TABLE = 10  # address of the triangle table (an integer, in the uint64 view)
_HEADER = 12
# A kept triangle: squared distance, index, closest point x, y, z, 1.0 when in its interior
_ENTRY = 6
_E_D2 = 0
_E_TRIANGLE = 1
_E_CLOSEST = 2
_E_INTERIOR = 5


@njit(inline="always")
def _on_segment(px, py, pz, ax, ay, az, bx, by, bz):
    """Closest point to p on segment ab (a when the segment has no length)."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    length2 = ex * ex + ey * ey + ez * ez
    t = 0.0
    if length2 > 0.0:
        t = min(max(((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / length2, 0.0), 1.0)
    return ax + t * ex, ay + t * ey, az + t * ez


@njit(inline="always")
def _nearer(px, py, pz, best, x, y, z):
    """(x, y, z) and its squared distance to p if nearer than ``best`` = (x, y, z, d2)."""
    d2 = (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2
    return (x, y, z, d2) if d2 < best[3] else best


@njit(inline="always")
def _corner_regions(p, corner, a, edge, other, along, across):
    """Ericson's Voronoi regions of a triangle's ``corner`` (b or c) and of its ``edge`` from
    a (corner - a), for point p; ``other`` is the triangle's other edge from a, ``along`` and
    ``across`` the dot products of ``edge`` and ``other`` with p - a. Returns (inside, x, y, z,
    near, far, weight): whether the closest point lies in one of these regions, and then that
    point; ``near`` and ``far``, the dot products of ``edge`` and ``other`` with p - corner, and
    ``weight``, the barycentric weight of the corner opposite the edge, for the later tests.
    (For corner c the products come in the other order, which leaves them bitwise the same.)"""
    qx, qy, qz = p[0] - corner[0], p[1] - corner[1], p[2] - corner[2]
    near = edge[0] * qx + edge[1] * qy + edge[2] * qz
    far = other[0] * qx + other[1] * qy + other[2] * qz
    if near >= 0.0 and far <= near:
        return True, corner[0], corner[1], corner[2], near, far, 0.0
    weight = along * far - near * across
    if weight <= 0.0 and along >= 0.0 and near <= 0.0:
        s = along / (along - near) if along > near else 0.0
        return True, a[0] + s * edge[0], a[1] + s * edge[1], a[2] + s * edge[2], near, far, weight
    return False, 0.0, 0.0, 0.0, near, far, weight


@njit(inline="always")
def closest_on_triangle(px, py, pz, t):
    """Closest point to p on the triangle t[0:9] (a, b, c), float64, by Ericson's Voronoi
    regions. Returns (x, y, z, interior): interior is True when the point is inside the
    triangle (not on an edge or a vertex). A degenerate triangle is its three edges."""
    ax, ay, az = t[0], t[1], t[2]
    abx, aby, abz = t[3] - ax, t[4] - ay, t[5] - az
    acx, acy, acz = t[6] - ax, t[7] - ay, t[8] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, False
    p, a, ab, ac = (px, py, pz), (ax, ay, az), (abx, aby, abz), (acx, acy, acz)
    inside, x, y, z, d3, d4, vc = _corner_regions(p, (t[3], t[4], t[5]), a, ab, ac, d1, d2)
    if inside:
        return x, y, z, False
    inside, x, y, z, d6, d5, vb = _corner_regions(p, (t[6], t[7], t[8]), a, ac, ab, d2, d1)
    if inside:
        return x, y, z, False
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        span = (d4 - d3) + (d5 - d6)
        w = (d4 - d3) / span if span > 0.0 else 0.0
        return (t[3] + w * (t[6] - t[3]), t[4] + w * (t[7] - t[4]), t[5] + w * (t[8] - t[5]), False)
    total = va + vb + vc
    if total > 0.0:
        v = vb / total
        w = vc / total
        return (ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w, True)
    # no area (collinear or coincident corners): the nearest of the three edges
    best = (ax, ay, az, np.inf)
    x, y, z = _on_segment(px, py, pz, ax, ay, az, t[3], t[4], t[5])
    best = _nearer(px, py, pz, best, x, y, z)
    x, y, z = _on_segment(px, py, pz, t[3], t[4], t[5], t[6], t[7], t[8])
    best = _nearer(px, py, pz, best, x, y, z)
    x, y, z = _on_segment(px, py, pz, t[6], t[7], t[8], ax, ay, az)
    best = _nearer(px, py, pz, best, x, y, z)
    return best[0], best[1], best[2], False


# error_model="numpy": no Python exception can leave a callback Embree calls
@on_first_use(point_query.CALLBACK_SIGNATURE, nopython=True, cache=True, error_model="numpy")
def _visit(address):
    """Embree's point query callback: the candidate's float64 closest point, kept when within
    the tie tolerance of the best so far; a new best prunes the kept ones and shrinks the
    query's radius."""
    args = carray(words64(address), point_query.ARGS_WORDS)
    user = args[point_query.ARGS_USER]
    header = carray(doubles(user), _HEADER)
    triangle = np.int64(args[point_query.ARGS_IDS] & 0xFFFFFFFF)
    table = carray(words64(user), _HEADER)[_TABLE]
    t = carray(doubles(table + 8 * TABLE_COLUMNS * triangle), TABLE_COLUMNS)
    px, py, pz = header[_POINT], header[_POINT + 1], header[_POINT + 2]
    x, y, z, interior = closest_on_triangle(px, py, pz, t)
    d2 = (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2
    tolerance = header[_TOLERANCE]
    reach = math.sqrt(header[_BEST]) + tolerance
    if d2 > reach * reach:
        return 0
    count = np.int64(header[_COUNT])
    capacity = np.int64(header[_CAPACITY])
    entries = carray(doubles(user + 8 * _HEADER), _ENTRY * capacity)
    changed = 0
    if d2 < header[_BEST]:
        header[_BEST] = d2
        reach = math.sqrt(d2) + tolerance
        limit = reach * reach
        kept = 0
        for e in range(count):
            if entries[e * _ENTRY + _E_D2] <= limit:
                for k in range(_ENTRY):
                    entries[kept * _ENTRY + k] = entries[e * _ENTRY + k]
                kept += 1
        count = kept
        query = carray(floats(args[point_query.ARGS_QUERY]), point_query.QUERY_WORDS)
        radius = np.float32(reach * header[_SCALE] + header[_MARGIN])
        if radius < query[point_query.QUERY_RADIUS]:
            query[point_query.QUERY_RADIUS] = radius
            changed = 1
    for e in range(count):  # a triangle split across BVH leaves is visited more than once
        if entries[e * _ENTRY + _E_TRIANGLE] == triangle:
            header[_COUNT] = count
            return changed
    if count < capacity:
        e = count * _ENTRY
        entries[e + _E_D2] = d2
        entries[e + _E_TRIANGLE] = triangle
        entries[e + _E_CLOSEST] = x
        entries[e + _E_CLOSEST + 1] = y
        entries[e + _E_CLOSEST + 2] = z
        entries[e + _E_INTERIOR] = 1.0 if interior else 0.0
        count += 1
    else:
        header[_OVERFLOW] = 1.0
    header[_COUNT] = count
    return changed


@njit(inline="always")
def _chosen(header, entries, table):
    """The entry the tie rule picks among those within the tolerance of the best (module
    docstring), or -1 when the query found no triangle."""
    count = np.int64(header[_COUNT])
    best = math.sqrt(header[_BEST])
    tolerance = header[_TOLERANCE]
    limit = (best + tolerance) ** 2
    px, py, pz = header[_POINT], header[_POINT + 1], header[_POINT + 2]
    facing = best > tolerance
    largest = -np.inf
    if facing:
        for e in range(count):
            if entries[e * _ENTRY + _E_D2] <= limit:
                largest = max(largest, _cosine(entries, e, table, px, py, pz))
    chosen = -1
    for e in range(count):
        if entries[e * _ENTRY + _E_D2] > limit:
            continue
        if facing and _cosine(entries, e, table, px, py, pz) < largest - DOT_TOLERANCE:
            continue
        if chosen < 0 or entries[e * _ENTRY + _E_TRIANGLE] < entries[chosen * _ENTRY + _E_TRIANGLE]:
            chosen = e
    return chosen


@njit(inline="always")
def _cosine(entries, e, table, px, py, pz):
    """Cosine between kept triangle e's unit normal and the point minus its closest point."""
    row = np.int64(entries[e * _ENTRY + _E_TRIANGLE])
    c = e * _ENTRY + _E_CLOSEST
    dx, dy, dz = px - entries[c], py - entries[c + 1], pz - entries[c + 2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return -np.inf
    return (table[row, 9] * dx + table[row, 10] * dy + table[row, 11] * dz) / length


class _Query(NamedTuple):
    """One closest-point pass: the Embree scene and the callback, the frame (``shift``,
    ``scale``, ``extent``), the tie ``tolerance``, the triangle table and the room for tied
    triangles per point (``capacity``)."""

    scene: int
    callback: int
    shift: np.ndarray
    scale: float
    extent: float
    tolerance: float
    table: np.ndarray
    capacity: int


class _Found(NamedTuple):
    """The pass's answers for n points: ``closest`` (n, 3) float64, ``distance`` (n,) float64,
    ``triangle`` (n,) int64, ``interior`` (n,) bool, ``overflow`` (n,) bool (more tied
    triangles than ``capacity``)."""

    closest: np.ndarray
    distance: np.ndarray
    triangle: np.ndarray
    interior: np.ndarray
    overflow: np.ndarray


@njit(nogil=True, cache=True, error_model="numpy")
def _closest_chunk(query, first, stop, points, scratch, user, found):
    scene, callback, shift, scale = query.scene, query.callback, query.shift, query.scale
    extent, tolerance, table, capacity = query.extent, query.tolerance, query.table, query.capacity
    closest, distance, triangle = found.closest, found.distance, found.triangle
    interior, overflow = found.interior, found.overflow
    b = point_query.init_scratch(scratch)
    words = user.view(np.uint64)
    entries = user[_HEADER:]
    for i in range(first, stop):
        px = points[i, 0] - shift[0]
        py = points[i, 1] - shift[1]
        pz = points[i, 2] - shift[2]
        qx, qy, qz = np.float32(px * scale), np.float32(py * scale), np.float32(pz * scale)
        local = max(extent, abs(np.float64(qx)), abs(np.float64(qy)), abs(np.float64(qz)))
        reach = point_query.LARGEST_COORDINATE
        if not (abs(qx) <= reach and abs(qy) <= reach and abs(qz) <= reach):
            # not finite (NaN compares false), or beyond Embree's reach
            triangle[i] = -1
            overflow[i] = False
            continue
        user[_POINT] = px
        user[_POINT + 1] = py
        user[_POINT + 2] = pz
        user[_BEST] = np.inf
        user[_TOLERANCE] = tolerance + _TOLERANCE_ULPS * _EPS64 * local / scale
        user[_SCALE] = scale
        user[_MARGIN] = _MARGIN_ULPS * _EPS32 * local
        user[_COUNT] = 0.0
        user[_CAPACITY] = capacity
        user[_OVERFLOW] = 0.0
        words[_TABLE] = table.ctypes.data
        point_query.point_query(scene, scratch, b, qx, qy, qz, np.inf, callback, user.ctypes.data)
        overflow[i] = user[_OVERFLOW] != 0.0
        e = _chosen(user, entries, table)
        if e < 0:  # cannot be: every triangle is within an infinite radius
            triangle[i] = -1
            continue
        c = e * _ENTRY
        closest[i, 0] = entries[c + _E_CLOSEST] + shift[0]
        closest[i, 1] = entries[c + _E_CLOSEST + 1] + shift[1]
        closest[i, 2] = entries[c + _E_CLOSEST + 2] + shift[2]
        distance[i] = math.sqrt(entries[c + _E_D2])
        triangle[i] = np.int64(entries[c + _E_TRIANGLE])
        interior[i] = entries[c + _E_INTERIOR] != 0.0


@njit(parallel=True, nogil=True, cache=True, error_model="numpy")
def _closest(query, points, found):
    n = points.shape[0]
    n_chunks = chunk_count(n, CHUNK)
    scratch = np.empty((n_chunks, point_query.SCRATCH_WORDS), np.uint32)
    user = np.empty((n_chunks, _HEADER + _ENTRY * query.capacity), np.float64)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        _closest_chunk(query, first, stop, points, scratch[c], user[c], found)


@njit(nogil=True, cache=True, error_model="numpy")
def _closest_serial(query, points, found):
    scratch = np.empty(point_query.SCRATCH_WORDS, np.uint32)
    user = np.empty(_HEADER + _ENTRY * query.capacity, np.float64)
    _closest_chunk(query, 0, points.shape[0], points, scratch, user, found)


@functools.cache
def _symbols_registered() -> bool:
    point_query.register_symbols()
    return True


def triangle_table(triangles: np.ndarray, normals: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """(k, TABLE_COLUMNS) float64 table for ``closest_points``: (k, 3, 3) float64 ``triangles``
    shifted by ``shift`` (3,), then their (k, 3) unit ``normals`` (zero for degenerate ones)."""
    table = np.empty((len(triangles), TABLE_COLUMNS), np.float64)
    table[:, :9] = (np.asarray(triangles, np.float64) - shift).reshape(-1, 9)
    table[:, 9:] = normals
    return table


def closest_points(
    scene: int,
    table: np.ndarray,
    points: np.ndarray,
    shift: np.ndarray,
    scale: float,
    extent: float,
    tolerance: float,
    threads: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The closest point of the mesh to each point, and which triangle it lies on.

    ``scene``: a committed Embree scene of the triangles of ``table`` (``triangle_table``,
    shifted by ``shift``) in the frame ``float32((p - shift) * scale)``, primitive i being row
    i; ``extent`` the largest |coordinate| of its vertices in that frame; ``points`` (n, 3)
    float64; ``tolerance`` the tie tolerance on distances (world units; each point's own float64
    rounding is added to it); ``threads`` to run on.

    Returns ``closest`` (n, 3) float64, ``distance`` (n,) float64, ``triangle`` (n,) int64 (-1
    where no triangle was found: a non-finite point, or one whose local coordinates exceed
    ``point_query.LARGEST_COORDINATE``) and ``interior`` (n,) bool (the closest point is inside
    its triangle, not on an edge or a vertex).
    """
    _symbols_registered()
    points = np.ascontiguousarray(points, np.float64)
    shift = np.ascontiguousarray(shift, np.float64)
    n = len(points)
    closest = np.zeros((n, 3), np.float64)
    distance = np.zeros(n, np.float64)
    triangle = np.full(n, -1, np.int64)
    interior = np.zeros(n, bool)
    rows = np.arange(n)
    capacity = FIRST_CAPACITY
    while len(rows):
        subset = points if len(rows) == n else points[rows]
        found = _Found(
            np.zeros((len(rows), 3)),
            np.zeros(len(rows)),
            np.full(len(rows), -1, np.int64),
            np.zeros(len(rows), bool),
            np.zeros(len(rows), bool),
        )
        query = _Query(
            scene,
            _visit.address,
            shift,
            float(scale),
            float(extent),
            float(tolerance),
            table,
            capacity,
        )
        used = threads_for(len(rows), threads)
        if used == 1:
            _closest_serial(query, subset, found)
        else:
            with parallel_region:
                numba.set_num_threads(used)
                _closest(query, subset, found)
        closest[rows], distance[rows], triangle[rows], interior[rows] = found[:4]
        rows = rows[found.overflow]  # tied with more triangles than there was room for: again
        capacity *= 8
    return closest, distance, triangle, interior


# -- the query ---------------------------------------------------------------------------


class _PointScene:
    """The mesh's triangles in Embree (float32, shifted to the box's corner and scaled to about
    100 units) and the float64 table the callback reads."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        vertices = np.asarray(mesh.vertices, np.float64)
        faces = np.asarray(mesh.faces, np.int64)
        if len(faces) == 0:
            raise ValueError("mesh: has no triangles to be near to")
        self.shift = vertices[faces.reshape(-1)].min(axis=0)
        size = float(mesh.scale)
        self.scale = _LOCAL_SIZE / size if size > 0 else 1.0
        self.tolerance = TIE_TOLERANCE * size
        local = ((vertices - self.shift) * self.scale).astype(np.float32)
        self.extent = float(np.abs(local[faces.reshape(-1)]).max())
        self.bvh = BVH(lanes=1)
        self.bvh.add_triangles(local, faces)
        self.bvh.commit()
        normals = np.asarray(mesh.face_normals, np.float64)
        self.table = triangle_table(np.asarray(mesh.triangles, np.float64), normals, self.shift)
        self.normals = normals


def _as_query_points(points) -> np.ndarray:
    """(n, 3) float64, or trimesh's error for another shape."""
    points = np.asanyarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        if points.size == 0:
            return np.zeros((0, 3))
        raise ValueError("points must be (n,3)!")
    return np.ascontiguousarray(points)


class ProximityQuery:
    """Proximity queries on a ``trimesh.Trimesh`` (see the module docstring)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        self._mesh = mesh
        self._cache = caching.Cache(id_function=mesh.__hash__)

    @caching.cache_decorator
    def _scene(self) -> _PointScene:
        return _PointScene(self._mesh)

    @caching.cache_decorator
    def _rays(self) -> RayMeshIntersector:
        ray = getattr(self._mesh, "ray", None)
        return ray if isinstance(ray, RayMeshIntersector) else RayMeshIntersector(self._mesh)

    def _closest(self, points: np.ndarray):
        scene = self._scene
        answers = closest_points(
            scene.bvh.committed_scene(),
            scene.table,
            points,
            scene.shift,
            scene.scale,
            scene.extent,
            scene.tolerance,
            numba.config.NUMBA_NUM_THREADS,
        )
        missing = np.flatnonzero(answers[2] < 0)
        if len(missing):
            row = int(missing[0])
            if not np.isfinite(points[row]).all():
                raise ValueError(f"points: row {row} is not finite: {points[row].tolist()}")
            raise ValueError(
                f"points: row {row} lies too far from the mesh for Embree's float32 point query "
                f"(more than {point_query.LARGEST_COORDINATE / scene.scale:.3g} from its box)"
            )
        return answers

    def on_surface(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For each of ``points`` (m, 3) the closest point on the mesh.

        Returns ``closest`` (m, 3) float64, ``distance`` (m,) float64 and ``triangle_id`` (m,)
        int64, the index of the closest triangle (ties: module docstring)."""
        points = _as_query_points(points)
        closest, distance, triangle, _ = self._closest(points)
        return closest, distance, triangle

    def vertex(self, points) -> tuple[np.ndarray, np.ndarray]:
        """For each of ``points`` (n, 3) the nearest vertex of the mesh: ``distance`` (n,)
        float64 and ``vertex_id`` (n,) int64, as trimesh's (its KD-tree, on all cores)."""
        return self._mesh.kdtree.query(points, workers=-1)

    def signed_distance(self, points) -> np.ndarray:
        """(n,) float64 distance from each of ``points`` (n, 3) to the mesh: positive inside and
        within the tie tolerance of the surface, negative outside (module docstring)."""
        points = _as_query_points(points)
        closest, distance, triangle, interior = self._closest(points)
        signed = distance.copy()
        off_surface = distance > self._scene.tolerance
        facing = np.einsum("ij,ij->i", self._scene.normals[triangle], points - closest)
        by_face = off_surface & interior & (facing != 0)
        signed[by_face] = np.where(facing[by_face] > 0, -1.0, 1.0) * distance[by_face]
        by_rays = np.flatnonzero(off_surface & ~by_face)
        if len(by_rays):
            inside = self._rays.contains_points(points[by_rays])
            signed[by_rays] = np.where(inside, 1.0, -1.0) * distance[by_rays]
        return signed

    # -- pickling, as RayMeshIntersector: the Embree scene is rebuilt on first use ----------------

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("_cache", None)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._cache = caching.Cache(id_function=self._mesh.__hash__)
