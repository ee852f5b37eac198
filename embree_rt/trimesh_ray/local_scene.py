"""The mesh as ``RayMeshIntersector`` holds it in Embree: in the local frame, with the tables its
float64 rules read (planes, triangles, smallest altitudes, the faces around each vertex position)
and working space kept from query to query."""

from __future__ import annotations

import threading

import numpy as np
import trimesh

from embree_rt.embree import BVH
from embree_rt.trimesh_ray.hit_inputs import Fans, MeshTables
from embree_rt.trimesh_ray.local_frame import local_points

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
