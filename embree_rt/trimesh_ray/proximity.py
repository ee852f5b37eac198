"""embree_rt's point queries behind trimesh's proximity API: ``ProximityQuery(mesh)`` answers as
``trimesh.proximity.ProximityQuery`` does, on Embree's point query on all cores.

- ``on_surface(points)``: the closest point on the mesh, its distance and its triangle, found by
  ``rtcPointQuery`` with a compiled callback and computed in float64 relative to the mesh's box
  corner, so the answers hold at any scale and any distance from the origin
  (``closest_triangles``). Ties follow trimesh's rule, made scale-free: triangles whose
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
"""

from __future__ import annotations

import numba
import numpy as np
import trimesh
from trimesh import caching

from embree_rt.embree import BVH, point_query
from embree_rt.trimesh_ray.closest_triangles import closest_points, triangle_table
from embree_rt.trimesh_ray.intersector import RayMeshIntersector

# trimesh's tol.merge (1e-8), relative to the mesh's size (its bounding box's diagonal)
TIE_TOLERANCE = 1e-8
# Embree's frame: the mesh about 100 units wide, as RayMeshIntersector's
_LOCAL_SIZE = 100.0


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
            scene.bvh.scene_address(),
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
