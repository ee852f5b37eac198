"""The mesh and its rays in Embree's local frame: the mesh as ``RayMeshIntersector`` holds it
(``LocalScene``: shifted, scaled and rounded to float32 once, with the tables its float64 rules
read and working space kept from query to query), and rays and points moved into that frame in
one compiled pass, in a coherent tracing order.

Rays moved into a BVH's local frame in one compiled pass (the multi-hit query's first step):
what ``(p - shift) * scale`` rounded to float32, a cast and a row maximum cost as three NumPy
passes and their temporaries (about a tenth of an all-hits query on a small mesh).

``ordered_local_rays`` also puts the rays in a coherent tracing order (``segment_key``,
the middle of each ray's path through the mesh's box): keys in a parallel pass, a serial radix
sort (a pure function of the keys), then a parallel pass that moves each ray's float64 row to
its place and to the local frame there. Every later step of the query reads the
rays in that order, so the BVH nodes, triangles and per-triangle tables one ray touched are
still in cache for the next. Each output row is the same arithmetic on the same input row as
``local_rays``' (the order only moves rows), so no answer changes.

The tracing order. A coherent tracing order for batches of incoherent rays: a Morton code of
where each ray enters the mesh's bounding box (``morton.spread_bits``), sorted by
``morton.radix_order``.

Why: a ray's traversal reads the BVH nodes and triangles around where it goes, and on a big
mesh (a million triangles: a BVH of ~100 MB) those reads miss every cache level when
consecutive rays go to unrelated places. Traced in the order of where they enter the box,
consecutive rays mostly meet the same part of the mesh, so the nodes and triangles one ray
fetched are still in cache for the next. Measured on a 1.3M-triangle icosphere and a 1e5-triangle
height field with trimesh's benchmark rays (from a sphere around the mesh toward random points
in it), one thread: 1.25-1.6x the random order's rate; the ray's origin alone gave 1.1x, origin
and direction together 1.15-1.4x (the entry point is the nearest cheap stand-in for where the
ray hits, and ordering by the true hit point gave 1.8x). On a 2,304-triangle mesh, whose BVH
fits in cache, 1.08x: less than the sort costs.

For all hits a ray's traversal visits the nodes along its whole path through the box, not just
around its first hit, so ``segment_key`` keys it by the middle of that path: with the same rays
and the filtered all-hits traversal (``multihit.all_hits``), one thread, the middle gave
1.2-1.3x the random order's rate on the icosphere, 1.4-1.45x on the height field and 1.1x on
the 2,304-triangle torus; the entry point 1.05-1.15x, 1.15x and 1.05x; Morton codes of entry and
exit together (6-D) or of the middle and the direction fell in between.

The order changes nothing in any ray's answer: each ray is still one single-ray query of an
immutable BVH, whose result depends on that ray alone (see the callers).
"""

from __future__ import annotations

import math
import threading
from typing import NamedTuple, NoReturn

import numba
import numpy as np
import trimesh
from numba import njit, prange

from embree_rt.compiled.morton import CELLS, radix_order, spread_bits
from embree_rt.compiled.pointers import prefetch
from embree_rt.compiled.work_split import chunk_count, chunk_span, parallel_region, threads_for
from embree_rt.embree import BVH

CHUNK = 1024  # rays per parallel iteration of the ordering passes
_AHEAD = 16


@njit(inline="always")
def local_coordinate(value, shift, scale):
    """A float64 world coordinate in the local frame, float32: ``(value - shift) * scale`` in
    float64, rounded once. The one copy of the frame's rule (mesh vertices, points, rays)."""
    return np.float32((value - shift) * scale)


@njit(nogil=True, cache=True)
def _local_points(points, shift, scale, out):
    for i in range(points.shape[0]):
        for k in range(3):
            out[i, k] = local_coordinate(points[i, k], shift[k], scale)


def local_points(points: np.ndarray, shift: np.ndarray, scale: float) -> np.ndarray:
    """(n, 3) float32: ``points`` (n, 3) float64 in the frame ``(p - shift) * scale``."""
    points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    out = np.empty(points.shape, np.float32)
    if len(points):
        _local_points(points, np.ascontiguousarray(shift, np.float64), float(scale), out)
    return out


@njit(nogil=True, cache=True)
def _boxed_local_points(points, lower, upper, shift, scale, candidates, local):
    # trimesh.bounds.contains' test (strictly inside, so NaN is out), then the frame change
    m = 0
    for i in range(points.shape[0]):
        inside = True
        for k in range(3):
            inside = inside and points[i, k] > lower[k] and points[i, k] < upper[k]
        if inside:
            candidates[m] = i
            for k in range(3):
                local[m, k] = local_coordinate(points[i, k], shift[k], scale)
            m += 1
    return m


def boxed_local_points(
    points: np.ndarray, bounds: np.ndarray, shift: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """The ``points`` (n, 3) float64 strictly inside the box ``bounds`` (2, 3) float64 (as
    ``trimesh.bounds.contains`` tests them): their rows (m,) int64, ascending, and their
    ``local_points`` (m, 3) float32, in one pass with no (n, 3) temporaries."""
    points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    lower, upper = np.asarray(bounds, np.float64)
    candidates = np.empty(len(points), np.int64)
    local = np.empty((len(points), 3), np.float32)
    m = _boxed_local_points(
        points,
        np.ascontiguousarray(lower),
        np.ascontiguousarray(upper),
        np.ascontiguousarray(shift, np.float64),
        float(scale),
        candidates,
        local,
    )
    return candidates[:m], local[:m]


class LocalRays(NamedTuple):
    """Rays in the local frame: ``origins``, ``directions`` (n, 3) float32 and ``magnitude``
    (n,) float64, each ray's largest |local coordinate| (or the mesh's extent)."""

    origins: np.ndarray
    directions: np.ndarray
    magnitude: np.ndarray


class FramedRays(NamedTuple):
    """``local_rays``' answer: ``origins``, ``directions`` (n, 3) float32 local rays,
    ``magnitude`` (n,) float64 (as ``LocalRays``'), and ``finite``: whether every local row is
    finite (if not, ``refuse_rays`` names the first bad one)."""

    origins: np.ndarray
    directions: np.ndarray
    magnitude: np.ndarray
    finite: bool


class OrderedFramedRays(NamedTuple):
    """``ordered_local_rays``' answer: ``order`` (n,) int64 (row j is ray ``order[j]``), the
    reordered world ``origins``, ``directions`` (n, 3) float64, and their ``local``
    ``FramedRays`` in that order."""

    order: np.ndarray
    origins: np.ndarray
    directions: np.ndarray
    local: FramedRays


class OrderedRays(NamedTuple):
    """Rays moved to their tracing order: the world ``origins``, ``directions`` (n, 3) float64
    and their ``LocalRays`` columns (flat: numba's parallel loops take no nested tuples)."""

    origins: np.ndarray
    directions: np.ndarray
    local_origins: np.ndarray
    local_directions: np.ndarray
    magnitude: np.ndarray


class Frame(NamedTuple):
    """The BVH's local frame: a point p is at ``(p - shift) * scale`` there (``shift`` (3,)
    float64), and ``extent`` is the mesh's largest local coordinate."""

    shift: np.ndarray
    scale: float
    extent: float


def frame(shift: np.ndarray, scale: float, extent: float) -> Frame:
    """A ``Frame`` with the kernels' types."""
    return Frame(np.ascontiguousarray(shift, np.float64), float(scale), float(extent))


@njit(inline="always")
def _to_local(origins, directions, i, frame, local, j):
    """Row i of the float64 rays into row j of the ``local`` arrays (origins, directions (n, 3)
    float32, magnitude (n,) float64). Returns whether the local row is finite."""
    shift, scale, extent = frame.shift, frame.scale, frame.extent
    local_origins, local_directions, magnitude = local.origins, local.directions, local.magnitude
    largest = extent
    finite = True
    for k in range(3):
        local = local_coordinate(origins[i, k], shift[k], scale)
        local_origins[j, k] = local
        local_directions[j, k] = np.float32(directions[i, k])
        largest = max(largest, abs(np.float64(local)))
        finite = finite and math.isfinite(local) and math.isfinite(local_directions[j, k])
    magnitude[j] = largest
    return finite


@njit(nogil=True, cache=True)
def _local_rays(origins, directions, frame, local):
    finite = True
    for i in range(origins.shape[0]):
        finite = _to_local(origins, directions, i, frame, local, i) and finite
    return finite


def local_rays(
    origins: np.ndarray, directions: np.ndarray, shift: np.ndarray, scale: float, extent: float
) -> FramedRays:
    """``origins``, ``directions`` (n, 3) float64 in the frame ``(p - shift) * scale``:
    local origins and directions (n, 3) float32 (directions only rounded), each ray's
    ``magnitude`` (n,) float64, the largest |coordinate| of its local origin or ``extent``, and
    whether every local row is finite (if not, ``refuse_rays`` names the first bad one)."""
    n = len(origins)
    local_origins = np.empty((n, 3), np.float32)
    local_directions = np.empty((n, 3), np.float32)
    magnitude = np.empty(n, np.float64)
    finite = True
    if n:
        finite = _local_rays(
            np.ascontiguousarray(origins, np.float64),
            np.ascontiguousarray(directions, np.float64),
            frame(shift, scale, extent),
            LocalRays(local_origins, local_directions, magnitude),
        )
    return FramedRays(local_origins, local_directions, magnitude, bool(finite))


def refuse_rays(
    origins: np.ndarray,
    directions: np.ndarray,
    shift: np.ndarray,
    scale: float,
    near: np.ndarray | None = None,
) -> NoReturn:
    """Raise the ``ValueError`` that names the first ray of ``origins``, ``directions`` (n, 3)
    float64, as the caller gave them, that Embree cannot trace in the frame ``(p - shift) *
    scale``: not finite, an origin beyond float32's range there (Embree works in float32), or
    a direction too long to make unit in float64, or a ``near`` (n,) float64 (world tnear)
    beyond float64's range in that frame. The row is printed as given."""
    for name, values in (("origins", origins), ("directions", directions)):
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            row = int(np.argmax(bad))
            raise ValueError(f"{name}: row {row} is not finite: {values[row].tolist()}")
    with np.errstate(over="ignore", invalid="ignore"):
        local = (origins - np.asarray(shift, np.float64)) * float(scale)
        bad = ~np.isfinite(local.astype(np.float32)).all(axis=1)
        if bad.any():
            row = int(np.argmax(bad))
            raise ValueError(
                f"origins: row {row} is {origins[row].tolist()}: beyond float32's range "
                f"(+-{float(np.finfo(np.float32).max):.3g}) in the mesh's frame (moved to its box "
                f"corner, scaled by {float(scale):.3g}), and Embree works in float32"
            )
        bad = ~np.isfinite(np.sqrt(np.einsum("ij,ij->i", directions, directions)))
        if bad.any():
            row = int(np.argmax(bad))
            raise ValueError(
                f"directions: row {row} is {directions[row].tolist()}: too long to make unit "
                "in float64"
            )
        if near is not None:
            bad = ~np.isfinite(np.asarray(near, np.float64) * float(scale))
            if bad.any():
                row = int(np.argmax(bad))
                raise ValueError(
                    f"tnear: row {row} is {float(near[row])}: too large for the mesh's frame"
                )
    # every row traceable, yet a pass flagged one: ours, not the caller's
    raise RuntimeError("rays: a row the frame pass refused is traceable")


@njit(nogil=True, cache=True)
def _key_chunk(first, stop, origins, directions, box, keys):
    for i in range(first, stop):
        keys[i] = segment_key(origins[i], directions[i], box.lower, box.upper, box.cells_per_unit)


@njit(nogil=True, cache=True)
def _inverse_chunk(first, stop, order, position):
    for j in range(first, stop):
        position[order[j]] = j


@njit(nogil=True, cache=True)
def _scatter_chunk(first, stop, position, origins, directions, frame, out, bad):
    # rows read in the given order and written to their places: scattered stores, which do not
    # stall the loop as scattered loads (a gather by `order`) do (out: OrderedRays)
    ordered_origins, ordered_directions = out.origins, out.directions
    local_origins, local_directions = out.local_origins, out.local_directions
    local = LocalRays(local_origins, local_directions, out.magnitude)
    for i in range(first, stop):
        if i + _AHEAD < stop:  # the rows written _AHEAD rays on, fetched now: overlapping
            ahead = position[i + _AHEAD]
            prefetch(ordered_origins.ctypes.data + 24 * ahead)
            prefetch(ordered_directions.ctypes.data + 24 * ahead)
            prefetch(local_origins.ctypes.data + 12 * ahead)
            prefetch(local_directions.ctypes.data + 12 * ahead)
            prefetch(out.magnitude.ctypes.data + 8 * ahead)
        j = position[i]
        for k in range(3):
            ordered_origins[j, k] = origins[i, k]
            ordered_directions[j, k] = directions[i, k]
        if not _to_local(origins, directions, i, frame, local, j):
            bad[0] = True  # the caller names the row


@njit(parallel=True, nogil=True, cache=True)
def _ordered_local_rays(origins, directions, frame, box, out, bad):
    n = origins.shape[0]
    n_chunks = chunk_count(n, CHUNK)
    keys = np.empty(n, np.uint32)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        _key_chunk(first, stop, origins, directions, box, keys)
    order = radix_order(keys)
    position = np.empty(n, np.int64)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        _inverse_chunk(first, stop, order, position)
    for c in prange(n_chunks):
        first, stop = chunk_span(c, CHUNK, n)
        _scatter_chunk(first, stop, position, origins, directions, frame, out, bad)
    return order


def ordered_local_rays(
    origins: np.ndarray,
    directions: np.ndarray,
    shift: np.ndarray,
    scale: float,
    extent: float,
    bounds: np.ndarray,
    threads: int,
) -> OrderedFramedRays:
    """``local_rays`` with the rays in tracing order (see the module docstring).

    ``origins``, ``directions`` (n, 3) float64 world rays; ``bounds`` (2, 3) float64 world box
    of the mesh; ``threads``: threads to run on. Returns ``order`` (n,) int64 (row j below is
    ray ``order[j]``), the reordered ``origins``, ``directions`` (n, 3) float64 and
    their ``FramedRays`` (an ``OrderedFramedRays``).
    """
    n = len(origins)
    out = OrderedRays(
        np.empty((n, 3), np.float64),
        np.empty((n, 3), np.float64),
        np.empty((n, 3), np.float32),
        np.empty((n, 3), np.float32),
        np.empty(n, np.float64),
    )
    if not n:
        return _ordered_answer(np.zeros(0, np.int64), out, True)
    bad = np.zeros(1, np.bool_)
    with parallel_region:
        numba.set_num_threads(threads_for(n, threads))
        order = _ordered_local_rays(
            np.ascontiguousarray(origins, np.float64),
            np.ascontiguousarray(directions, np.float64),
            frame(shift, scale, extent),
            box(bounds),
            out,
            bad,
        )
    return _ordered_answer(order, out, not bad[0])


def _ordered_answer(order: np.ndarray, out: OrderedRays, finite: bool) -> OrderedFramedRays:
    local = FramedRays(out.local_origins, out.local_directions, out.magnitude, bool(finite))
    return OrderedFramedRays(order, out.origins, out.directions, local)


# -- the tracing order --------------------------------------------------------------------


@njit(inline="always")
def _box_span(origin, direction, lower, upper):
    """(near, far): the ray's parameters where it enters (0 when it starts inside) and leaves
    the box ``lower`` .. ``upper``; near > far when it misses."""
    near, far = 0.0, math.inf
    for k in range(3):
        d = direction[k]
        if d == 0.0:
            if origin[k] < lower[k] or origin[k] > upper[k]:
                far = -1.0  # parallel to this slab and outside it
        else:
            reciprocal = 1.0 / d
            t0 = (lower[k] - origin[k]) * reciprocal
            t1 = (upper[k] - origin[k]) * reciprocal
            near = max(near, min(t0, t1))
            far = min(far, max(t0, t1))
    return near, far


@njit(inline="always")
def _point_code(origin, direction, step, lower, cells_per_unit):
    """uint32 Morton code of the point ``origin + step * direction`` clamped to the grid."""
    code = np.uint32(0)
    for k in range(3):
        cell = (origin[k] + step * direction[k] - lower[k]) * cells_per_unit[k]
        cell = min(max(cell, 0.0), float(CELLS))  # also maps nan (a non-finite ray) to 0
        code |= np.uint32(spread_bits(np.uint32(cell))) << np.uint32(k)
    return code


@njit(inline="always")
def entry_key(origin, direction, lower, upper, cells_per_unit):
    """uint32 Morton code of where the ray ``origin``, ``direction`` ((3,) float64 rows) enters
    the box ``lower`` .. ``upper`` ((3,) float64), on a grid of 1024 cells an axis
    (``cells_per_unit`` (3,): 1023 / the box's size, 0 along a flat axis); a ray starting inside
    is keyed by its origin, one that misses by its origin clamped to the box."""
    near, far = _box_span(origin, direction, lower, upper)
    step = near if near <= far else 0.0
    return _point_code(origin, direction, step, lower, cells_per_unit)


@njit(inline="always")
def segment_key(origin, direction, lower, upper, cells_per_unit):
    """uint32 Morton code of the middle of the ray's segment inside the box ``lower`` ..
    ``upper`` (arguments as ``entry_key``'s; the segment from where the ray enters, or its
    origin when it starts inside, to where it leaves), for queries that follow each ray through
    the whole box (all hits) rather than to its first hit; a ray that misses is keyed by its
    origin clamped to the box."""
    near, far = _box_span(origin, direction, lower, upper)
    step = 0.5 * (near + far) if near <= far and far < math.inf else 0.0
    return _point_code(origin, direction, step, lower, cells_per_unit)


def box_cells(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """(3,) float64 grid cells per unit length along each axis of the box ``lower`` ..
    ``upper`` for ``entry_key`` (0 along an axis where the box is flat)."""
    size = np.asarray(upper, np.float64) - np.asarray(lower, np.float64)
    with np.errstate(divide="ignore"):
        return np.where(size > 0, CELLS / np.where(size > 0, size, 1.0), 0.0)


class Box(NamedTuple):
    """The box rays are keyed in: ``lower``, ``upper`` (3,) float64 corners and
    ``cells_per_unit`` (3,) float64 (``box_cells``)."""

    lower: np.ndarray
    upper: np.ndarray
    cells_per_unit: np.ndarray


def box(bounds: np.ndarray) -> Box:
    """The ``Box`` of ``bounds`` (2, 3) float (lower and upper corners)."""
    lower, upper = np.asarray(bounds, np.float64)
    return Box(lower, upper, box_cells(lower, upper))


# -- the mesh in the local frame --------------------------------------------------------------
# The mesh as ``RayMeshIntersector`` holds it in Embree: in the local frame, with the tables its
# float64 rules read (planes, triangles, smallest altitudes, the faces around each vertex position)
# and working space kept from query to query.


class MeshTables(NamedTuple):
    """The mesh's per-triangle tables: ``planes`` (triangles, 6) float64, each triangle's first
    vertex and unit normal in one C-contiguous row (``hit_passes.plane_distances``); ``triangles``
    (triangles, 3, 3) float64; ``altitude`` (triangles,) float64 smallest local altitude (0:
    degenerate) and ``floor_altitude`` its minimum."""

    planes: np.ndarray
    triangles: np.ndarray
    altitude: np.ndarray
    floor_altitude: float


class Fans(NamedTuple):
    """The faces around each vertex position, CSR: ``canonical`` (triangles, 3) int64 each
    triangle's corners as position ids, ``starts`` (positions + 1,) int64 and ``faces``
    (3 triangles,) int64: the faces around position p are ``faces[starts[p]:starts[p + 1]]``."""

    canonical: np.ndarray
    starts: np.ndarray
    faces: np.ndarray


EPS32 = float(np.finfo(np.float32).eps)
# Embree's float32 barycentrics and distances err by a few ulps of the largest coordinate
# involved; this multiple leaves a wide margin. A hit within EDGE_BAND_SCALE * magnitude /
# altitude (barycentric) of its triangle's edge may be wrong.
BAND_ULPS = 8.0
EDGE_BAND_SCALE = BAND_ULPS * EPS32
# Meshes from this many faces up trace their rays in a coherent order (see LocalScene.bounds).
REORDER_FACES = 1 << 15
# Working arrays up to this many items are kept from query to query.
_SCRATCH_ITEMS = 1 << 22


class LocalScene:
    """The mesh in Embree: vertices shifted to the bounding box's corner and scaled by ``scale``
    (float64, then rounded to float32 once), the BVH, and what the float64 refinement needs."""

    def __init__(self, mesh: trimesh.Trimesh, scale: float) -> None:
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        self.origin = vertices.min(axis=0) if len(vertices) else np.zeros(3)
        self.scale = float(scale)
        local = local_points(vertices, self.origin, self.scale)
        self.extent = float(np.abs(local).max()) if len(local) else 0.0
        # Rays are traced in the order of where they enter the mesh's box (local_frame) on meshes
        # whose BVH outgrows the caches: 1.4-1.6x the rate on 1e5 and 1.3e6 triangles; on a
        # small mesh (2,304 triangles) the sort cost more than the order saved.
        self.bounds = (
            np.array([vertices.min(axis=0), vertices.max(axis=0)])
            if len(faces) >= REORDER_FACES
            else None
        )
        # single rays: trimesh's queries are rarely coherent, and packets of incoherent rays
        # traced 10-15% slower here
        self.bvh = BVH(lanes=1, robust=True, filters=True)
        self.bvh.add_triangles(local, faces)
        self.bvh.commit()
        self.triangles = np.asarray(mesh.triangles, dtype=np.float64)
        # each triangle's first vertex and unit normal side by side in one (k, 6) table: the
        # float64 distance of a hit reads both, and on a big mesh each read is a cache miss
        self.planes = np.hstack([self.triangles[:, 0], np.asarray(mesh.face_normals, np.float64)])
        self.faces = faces
        self.vertices = vertices
        self.face_count = len(faces)
        self.min_altitude = min_altitudes(self.triangles, np.asarray(mesh.area_faces)) * scale
        # 0 when any triangle is degenerate: then every hit's own altitude is looked up
        self.floor_altitude = float(self.min_altitude.min()) if self.face_count else 0.0
        # the same tables as the compiled float64 passes take them
        self.tables = MeshTables(
            np.ascontiguousarray(self.planes, np.float64),
            self.triangles,
            self.min_altitude,
            self.floor_altitude,
        )
        # contains_points' rays reach twice the mesh's extent
        self.contains_band = _edge_band(
            self, np.arange(self.face_count), np.full(self.face_count, 2 * self.extent)
        ).astype(np.float32)
        self._fans: Fans | None = None
        # all_hits' buffers and working space (megabytes), kept from query to query, one set a
        # thread: fresh arrays of that size come from the kernel a page fault a 4 KiB page at a
        # time (measured on the torus, 100k rays: 4,000 faults and 14 ms of system time, a
        # fifth of the query)
        self._buffers = threading.local()

    def hit_buffers(self, capacity: int) -> tuple[np.ndarray, ...] | None:
        """This thread's all_hits buffers of ``capacity`` hits a ray from its last query, or
        None."""
        kept = getattr(self._buffers, "arrays", None)
        return kept if kept is not None and kept[0].shape[1] == capacity else None

    def scratch(self, name: str, size: int, dtype) -> np.ndarray:
        """(size,) array of ``dtype``: this thread's working space ``name``, kept from query to
        query up to _SCRATCH_ITEMS (larger ones are new each time), contents undefined."""
        pool = self._buffers.__dict__.setdefault("pool", {})
        array = pool.get(name)
        if array is None or len(array) < size:
            array = np.empty(size, dtype)
            if size <= _SCRATCH_ITEMS:
                pool[name] = array
        return array[:size]

    def keep_hit_buffers(self, capacity: int, buffers: tuple[np.ndarray, ...]) -> None:
        """Keep ``buffers`` (all_hits' arrays, ``capacity`` hits a ray) for this thread's next
        query when they are at least as large as those kept."""
        kept = self.hit_buffers(capacity)
        if kept is None or len(buffers[0]) > len(kept[0]):
            self._buffers.arrays = buffers

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) float64 world points → (n, 3) float32 in the BVH's frame."""
        return local_points(points, self.origin, self.scale)

    def fans(self) -> Fans:
        """Faces around each vertex position, CSR: (canonical faces (k, 3), starts (m + 1,),
        faces (3k,)); vertices at the same position count as one (unmerged STL meshes)."""
        if self._fans is None:
            canonical = position_ids(self.vertices)[self.faces]
            flat = canonical.reshape(-1)
            order = np.argsort(flat, kind="stable")
            starts = np.searchsorted(flat[order], np.arange(flat.max() + 2 if len(flat) else 1))
            self._fans = Fans(canonical, starts, order // 3)
        return self._fans


def position_ids(vertices: np.ndarray) -> np.ndarray:
    """(m,) int64 for (m, 3) float64 ``vertices``: equal ids exactly where positions are equal
    (as ``np.unique(vertices, axis=0)`` groups them, -0.0 and 0.0 alike). A lexsort of the
    columns: 10x faster than ``np.unique``'s sort of rows as records (1.2 s on 655k vertices)."""
    if len(vertices) == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort(vertices.T[::-1])
    ordered = vertices[order]
    starts = np.ones(len(order), bool)
    starts[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    ids = np.empty(len(order), np.int64)
    ids[order] = np.cumsum(starts) - 1
    return ids


def min_altitudes(triangles: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """(k,) smallest altitude of each of (k, 3, 3) triangles of ``areas`` (k,) (0 for
    degenerate ones): twice the area over the longest side."""
    longest = np.zeros(len(triangles))
    for a, b in ((0, 1), (1, 2), (2, 0)):
        side = triangles[:, b] - triangles[:, a]
        longest = np.maximum(longest, np.sqrt(np.einsum("ij,ij->i", side, side)))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(longest > 0, 2 * areas / np.where(longest > 0, longest, 1), 0.0)


def _edge_band(scene: LocalScene, faces: np.ndarray, magnitude: np.ndarray) -> np.ndarray:
    """Barycentric distance from an edge within which Embree's float32 answer for ``faces``
    (k,) may be wrong, for rays whose coordinates reach ``magnitude`` (k,) in the local frame."""
    with np.errstate(divide="ignore"):
        return EDGE_BAND_SCALE * magnitude / scene.min_altitude[faces]
