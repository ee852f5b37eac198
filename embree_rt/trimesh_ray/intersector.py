"""embree_rt's BVH behind trimesh's ray API: ``mesh.ray = RayMeshIntersector(mesh)``.

The same methods, arguments, return values, dtypes and hit order as
``trimesh.ray.ray_pyembree.RayMeshIntersector``, traced on all cores, with multiple hits that
are exact at any scale. ``trimesh_ray.install()`` makes every new ``trimesh.Trimesh`` use it.

How each hit is found exactly once: every ray is traced *once* with an Embree intersection
filter that records every triangle Embree's watertight test accepts and rejects it, so the
traversal continues to the end of the ray (``embree_rt.embree.multihit``). There is no second
query from the last hit, so no offset to choose and no distance rule that could drop or repeat
a hit: a triangle is reported at most once per ray whatever the scale, and the watertight
(``RTC_SCENE_FLAG_ROBUST``) test lets no ray slip between two triangles sharing an edge.

Conventions: which triangles a ray hits is ``ray_triangle``'s float64 test (trimesh's pure
NumPy backend); how they are counted is trimesh's embree backend's contract, one hit per
crossing of the surface:

- A ray through an edge or a vertex meets every triangle there that ``ray_triangle``'s float64
  test accepts (barycentrics within ``tol.zero`` of the triangle). Embree's float32 test may
  accept one or both near an edge, so every Embree hit within float32 reach of an edge
  (``local_frame``), or grazing its triangle, is decided again in float64 against the triangles
  around it (those sharing a vertex position with it) by ``ray_triangle``'s own formulas
  (``decided_hits``). Triangles meeting only at T-junctions (no shared vertex position) are not
  looked up.
- Those triangles at one point are one crossing: ``intersects_id``, ``intersects_location`` and
  ``intersects_first`` report it once, on the lowest triangle index there (``finished_hits``;
  faces in the same place, coincident sheets, are each crossed). A ray that only touches the
  surface at a silhouette edge or vertex also meets it at one point and reports it once. Where
  ``ray_triangle`` merges points by rounding them to 1e-8 absolute (at unit scale, not at 1e8),
  this holds at any scale.
- A ray meeting a triangle at |cos| <= 1e-5 (in its plane, to float64 precision) does not hit
  it, as ``trimesh.intersections.planes_lines`` rules.
- A ray hits what lies at or ahead of its origin (float64 distance >= ``tnear``, 0 by default),
  as trimesh's embree backend counts hits from ``tnear`` 0 (``ray_triangle`` even keeps hits up
  to 1e-6, absolute, *behind* it): a ray starting exactly on a surface hits that surface, as
  trimesh's own test suite expects. ``tnear=None`` skips hits within a few float32 ulps of the
  origin instead, so a ray starting on a surface (to float32 precision) does not hit it again.
- ``max_hits`` keeps each ray's nearest hits (``ray_pyembree`` keeps the first it found).

Hits come in ``ray_pyembree``'s order: every ray's first hit (rays ascending), then every
ray's second hit, and so on. Distances and locations are float64, from the ray's origin and
the hit triangle's plane, as trimesh computes them.
"""

from __future__ import annotations

import numpy as np
import trimesh
from trimesh import caching, util

from embree_rt.trimesh_ray.exact_hits import GRAZE_COS, HitQuery, exact_hits
from embree_rt.trimesh_ray.hit_passes import crossing_parity, plane_distances
from embree_rt.trimesh_ray.local_frame import LocalScene, boxed_local_points

# trimesh.ray.ray_util.contains_points's first direction, then two more for rays that pass too
# near an edge or along a face to trust their parity.
_CONTAINS_DIRECTIONS = np.array(
    [
        [0.4395064455, 0.617598629942, 0.652231566745],
        [-0.5773502691896258, 0.7071067811865476, -0.4082482904638631],
        [0.8017837257372732, -0.2672612419124244, -0.5345224838248488],
    ]
)


def _ray_arrays(ray_origins, ray_directions) -> tuple[np.ndarray, np.ndarray]:
    """Rays as given, (n, 3) float64 origins and directions (not copied when they already
    are; not unit)."""
    origins = np.asarray(ray_origins, dtype=np.float64)
    directions = np.asarray(ray_directions, dtype=np.float64)
    if origins.shape != directions.shape:
        raise ValueError("Ray origin and direction don't match!")
    if origins.ndim != 2 or (len(origins) and origins.shape[1] != 3):
        raise ValueError(f"rays: expected shape (n, 3), got {origins.shape}")
    return origins.reshape(-1, 3), directions.reshape(-1, 3)


def _as_rays(ray_origins, ray_directions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, 3) float64 origins, unit directions (trimesh's ``unitize``) and the directions as
    given (to name a bad row as the caller wrote it)."""
    origins, directions = _ray_arrays(ray_origins, ray_directions)
    # A non-finite direction is refused when the rays are traced, naming its row; unitize
    # would only warn.
    with np.errstate(invalid="ignore", over="ignore"):
        return origins, util.unitize(directions), directions


class RayMeshIntersector:
    """Ray queries on a ``trimesh.Trimesh`` through embree_rt's BVH (see the module docstring).

    ``scale_to_box``: as trimesh's, move and scale the mesh to a box about 100 units wide before
    rounding it to Embree's float32, so huge and tiny meshes keep their precision.
    """

    def __init__(self, geometry: trimesh.Trimesh, scale_to_box: bool = True) -> None:
        self.mesh = geometry
        self._scale_to_box = scale_to_box
        self._cache = caching.Cache(id_function=self.mesh.__hash__)

    @property
    def _scale(self) -> float:
        if self._scale_to_box:
            return 100.0 / self.mesh.scale
        return 1.0

    @caching.cache_decorator
    def _scene(self) -> LocalScene:
        return LocalScene(self.mesh, self._scale)

    # -- queries ------------------------------------------------------------------------------

    def intersects_id(
        self,
        ray_origins,
        ray_directions,
        multiple_hits: bool = True,
        max_hits: int = 100,
        return_locations: bool = False,
        *,
        tnear=0.0,
    ):
        """Triangles hit by rays: ``(index_tri, index_ray)`` (m,) int64, and with
        ``return_locations`` also ``locations`` (m, 3) float64.

        ``ray_origins``, ``ray_directions`` (n, 3) float (directions need not be unit);
        ``multiple_hits``: every hit along each ray (up to its nearest ``max_hits``; 100 by
        default, as in trimesh 5's embree backend) or only the first; ``tnear`` (scalar or
        (n,), world units): report hits at distance >= tnear (0 by default, as trimesh's embree
        backend: a ray starting exactly on a surface hits it); None: hits beyond a few float32
        ulps of the origin, so a ray starting on a surface does not hit it. Order: all
        first hits by ray, then all second hits, ... (as trimesh's embree backend). One hit per
        crossing of the surface: where a ray meets several triangles at one point (an edge, a
        vertex) the lowest index of them stands for the point (module docstring).
        """
        if not multiple_hits:
            origins, given_directions = _ray_arrays(ray_origins, ray_directions)
            first = exact_hits(self._scene, HitQuery(origins, given_directions, tnear, None))
            rays, tris = first.rays, first.tris
            if not return_locations:
                return tris, rays
            directions = util.unitize(given_directions[rays])
            # float64, trimesh's planes_lines formula
            distance, _ = plane_distances(
                self._scene.planes, origins[rays], directions, np.arange(len(rays)), tris
            )
            return tris, rays, origins[rays] + directions * distance[:, None]
        origins, directions, given_directions = _as_rays(ray_origins, ray_directions)
        query = HitQuery(
            origins,
            directions,
            tnear,
            max(1, int(max_hits)),
            with_locations=return_locations,
            reorder=True,
            as_given=given_directions,
        )
        rays, tris, locations = exact_hits(self._scene, query)
        if return_locations:
            return tris, rays, locations
        return tris, rays

    def intersects_location(
        self, ray_origins, ray_directions, multiple_hits: bool = True, *, tnear=0.0
    ):
        """Where rays hit: ``(locations (m, 3) float64, index_ray (m,) int64, index_tri (m,)
        int64)``, one per crossing of the surface (see ``intersects_id``)."""
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins,
            ray_directions,
            multiple_hits=multiple_hits,
            return_locations=True,
            tnear=tnear,
        )
        return locations, index_ray, index_tri

    def intersects_first(self, ray_origins, ray_directions, *, tnear=0.0) -> np.ndarray:
        """(n,) int32 (as trimesh's embree backend): the first triangle each ray hits, -1 for
        none (on an edge, the lowest index of the triangles there)."""
        origins, directions = _ray_arrays(ray_origins, ray_directions)
        found = exact_hits(self._scene, HitQuery(origins, directions, tnear, None))
        first = np.full(len(origins), -1, np.int32)
        first[found.rays] = found.tris
        return first

    def intersects_any(self, ray_origins, ray_directions, *, tnear=0.0) -> np.ndarray:
        """(n,) bool: whether each ray hits the mesh."""
        return self.intersects_first(ray_origins, ray_directions, tnear=tnear) != -1

    def contains_points(self, points) -> np.ndarray:
        """(n,) bool: which of ``points`` (n, 3) lie inside the (closed) mesh.

        The parity of the exact count of triangles a ray crosses, on one ray a point; a ray that
        passes within float32 reach of an edge or along a face (whose count could be off by one)
        is cast again in another direction, up to three, and a point none of whose rays is
        clear takes the majority of the three parities. Points outside the bounding box are
        outside; on the surface, either answer may come.
        """
        points = np.asanyarray(points, dtype=np.float64)
        if not util.is_shape(points, (-1, 3)):
            raise ValueError("points must be (n,3)")
        contains = np.zeros(len(points), dtype=bool)
        if self.mesh.bounds is None:
            return contains
        scene = self._scene
        candidates, local = boxed_local_points(points, self.mesh.bounds, scene.origin, scene.scale)
        if not len(candidates):
            return contains
        band = scene.contains_band
        votes = np.zeros(len(candidates), np.int64)
        pending = np.arange(len(candidates))
        for k, direction in enumerate(_CONTAINS_DIRECTIONS):
            # the points are finite (inside the box), so Embree is called directly; every ray
            # of a pass shares its direction (a broadcast row, no (n, 3) copy)
            origins = local if k == 0 else local[pending]
            directions = np.broadcast_to(direction.astype(np.float32), (len(pending), 3))
            odd, clear = crossing_parity(scene.bvh, origins, directions, band, GRAZE_COS)
            last = k == len(_CONTAINS_DIRECTIONS) - 1
            votes[pending] += odd
            settled = clear | last
            answer = odd if not last else np.where(clear, odd, votes[pending] >= 2)
            contains[candidates[pending[settled]]] = answer[settled]
            pending = pending[~settled]
            if not len(pending):
                break
        return contains

    # -- pickling and copying, as trimesh's ------------------------------------------------------

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("_cache", None)  # the BVH is rebuilt on first use
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._cache = caching.Cache(id_function=self.mesh.__hash__)

    def __deepcopy__(self, *args) -> RayMeshIntersector:
        return self.__copy__()

    def __copy__(self, *args) -> RayMeshIntersector:
        return RayMeshIntersector(geometry=self.mesh, scale_to_box=self._scale_to_box)
