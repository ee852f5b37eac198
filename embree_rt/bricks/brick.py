"""One brick's BVH and its answers: nearest hits as records naming objects by their global ids,
and whether shadow segments are blocked.

A brick is an ordinary ``SceneGeometry`` of its own objects, so a hit on it is computed by the
very code, from the very numbers, the whole scene's BVH would use: a sphere's t, point, normal
and scale come from the ray and the sphere alone, a mesh's from the ray, its placement and its
own triangle BVH (built from the same mesh either way). Only the top level differs, which
decides nothing but which of two exactly equal hits Embree reports first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from embree_rt.aovs import hit_object_ids
from embree_rt.bricks.contents import BrickContents
from embree_rt.geometry import SceneGeometry, SurfaceHits
from embree_rt.sphere_modes import sphere_kind

# The hit records' groups (tracing.GROUPS) an object hit falls in: the top-level sphere set, or
# any other object (instances, instance arrays: meshes and tessellated spheres).
SPHERE_GROUP, OTHER_GROUP = 1, 2


@dataclass
class BrickHits:
    """The nearest hits a brick found among the rays it was sent, as little as travels back:
    ``rows`` (k,) int32 which of them hit; ``object_id`` (k,) int64 the whole scene's id of the
    object hit; ``group`` (k,) int8 ``SPHERE_GROUP`` or ``OTHER_GROUP``; ``surfaces`` their
    ``SurfaceHits`` (k columns, no floor hits) with ``material`` (k,) int32 and without what
    the asker has or cannot use: ``incoming`` (the rays' own directions) and Embree's
    ``prim_id``/``inst_id``/``inst_prim_id`` (they name this brick's own BVH, not the scene's)
    are None."""

    rows: np.ndarray
    object_id: np.ndarray
    group: np.ndarray
    surfaces: SurfaceHits


def brick_sphere_mode(total_spheres: int, spheres: str) -> str:
    """The ``spheres`` mode a brick builds with, so that its spheres enter its BVH as the
    whole scene's ``total_spheres`` would enter one BVH (``sphere_modes.sphere_kind``: beyond
    ``USER_GEOMETRY_MAX_SPHERES`` analytic spheres are Embree's point spheres, another
    intersection routine, whose t may differ in the last bit)."""
    return "point" if sphere_kind(total_spheres, spheres) == "point" else spheres


class Brick:
    """Brick ``contents.index``: the BVH of its objects, entered as ``spheres``
    (``brick_sphere_mode`` of the whole scene), queried on the calling thread. The brick takes
    the contents' spheres over: its BVH holds them, the contents' scene is left without."""

    def __init__(self, contents: BrickContents, spheres: str) -> None:
        self.index = contents.index
        ids = contents.object_ids
        # int32 where the scene's ids fit (a field of 2e8 spheres: 4 bytes a sphere saved)
        small = len(ids) == 0 or ids.max() <= np.iinfo(np.int32).max
        self.object_ids = ids.astype(np.int32) if small else ids
        del ids
        contents.object_ids = self.object_ids
        self.sphere_count = len(contents.scene.sphere_radii)
        self.spheres_as_set = spheres != "mesh"
        self.bounds = contents.bounds()
        self.geometry = SceneGeometry(contents.scene, spheres=spheres, threads=1, take_spheres=True)

    def close(self) -> None:
        self.geometry.close()

    def intersect(
        self, origins: np.ndarray, directions: np.ndarray, coherent: bool = False
    ) -> BrickHits:
        """Nearest hits of the rays ``origins``, ``directions`` (3, n) float32 among this
        brick's objects."""
        rows, surfaces = self.geometry.intersect_compact(origins, directions, coherent=coherent)
        local = hit_object_ids(surfaces, self.geometry)
        group = np.full(len(rows), OTHER_GROUP, np.int8)
        if self.spheres_as_set:
            group[local < self.sphere_count] = SPHERE_GROUP
        surfaces.prim_id = surfaces.inst_id = surfaces.inst_prim_id = None
        surfaces.incoming = None
        # material ids index the scene's few materials: int32 holds them exactly
        surfaces.material = surfaces.material.astype(np.int32)
        object_id = self.object_ids[local].astype(np.int64)
        return BrickHits(rows.astype(np.int32), object_id, group, surfaces)

    def occluded(self, segments: list[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """Per ``(points, target)`` of ``segments``, (k,) bool: whether an object of this brick
        lies on the segment from each of the ``points`` (3, k) float32 to ``target`` (3,)
        float32."""
        return [
            self.geometry.occluded_toward(
                points, np.arange(points.shape[1], dtype=np.int64), target
            )
            for points, target in segments
        ]
