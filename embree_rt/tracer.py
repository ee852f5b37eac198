"""``Tracer``: every geometric query the integrator asks, and the NumPy way to answer two of them.

pbrt-v4 splits the integrator (what light does) from the aggregate (what a ray meets); this is
that split. ``SceneGeometry`` (one BVH of the whole scene) answers every query in compiled
kernels: camera rays made inside the query, shadow segments toward each light made inside the
query. ``bricks.BrickSet`` answers rays given as columns and segments to one target from bricks
here or on Dask workers; ``RaysInNumPy`` makes the camera rays and the shadow segments for it
in NumPy, the very rays and segments the kernels make (bitwise: the kernels form them with the
same float32 operations).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol

import numpy as np

from embree_rt import shading
from embree_rt.ambient_occlusion import HemisphereQuery
from embree_rt.compiled.camera_rays import CameraRays, sample_rays
from embree_rt.geometry import SurfaceHits

# Per light: (n,) bool which points see it, (3, n) float32 unit directions toward it where
# visible (zero elsewhere), and how many shadow segments were traced.
LightAnswer = tuple[np.ndarray, np.ndarray, int]


class Tracer(Protocol):
    """The geometric queries of the integrator, each over a whole wavefront of rays."""

    def intersect_compact(
        self, origins: np.ndarray, directions: np.ndarray, coherent: bool = False, ids: bool = True
    ) -> tuple[np.ndarray, SurfaceHits]:
        """The nearest hits of n rays ``origins``, ``directions`` (3, n) float32 (unit
        directions): the (k,) int64 rays that hit and their ``SurfaceHits``, floor hits first.
        ``coherent``: the rays are runs of neighbouring camera rays (the same answers, found
        faster); ``ids``: whether the hits carry Embree's ids (``prim_id``, ``inst_id``,
        ``inst_prim_id``), which name objects (the AOVs) and which shading never reads."""
        ...

    def intersect_camera(
        self, camera: CameraRays, index: np.ndarray, ids: bool = True
    ) -> tuple[np.ndarray, SurfaceHits, np.ndarray]:
        """``intersect_compact`` of the camera rays of samples ``index`` (n,) int64
        (``camera.sample_rays``' rays, coherent): the (k,) rays that hit, their
        ``SurfaceHits`` and the (3, n) float32 unit directions of all n rays."""
        ...

    def toward_lights(
        self, points: np.ndarray, normals: np.ndarray, targets: np.ndarray, takes: np.ndarray
    ) -> Iterator[LightAnswer]:
        """Per light of ``targets`` (L, 3) float32, in turn, what the ``points`` (3, n) float32
        with unit ``normals`` (3, n) float32 see of it (``LightAnswer``), the floor included:
        one shadow segment ``p + t (target - p)``, t in [0, 1], from each point whose normal
        faces the light (``(target - p) · normal > 0``) and that ``takes`` ((n,) bool) light."""
        ...

    def occluded_toward(
        self, points: np.ndarray, rows: np.ndarray, target: np.ndarray
    ) -> np.ndarray:
        """(k,) bool: whether any surface, the floor included, lies on the segment from each of
        the ``points`` (3, n) float32 at ``rows`` (k,) int64 to ``target`` (3,)."""
        ...

    def occluded_hemispheres(self, rays: HemisphereQuery) -> np.ndarray:
        """(n,) bool: whether any surface, the floor included, lies within ``rays.distance``
        (inf: any) on each of ambient occlusion's n = k * samples ``rays``
        (``HemisphereQuery``: their points, frames and local directions), each direction
        formed in float32 as it is traced. A tracer that cannot answer them (bricks) raises
        ``NotImplementedError``."""
        ...

    def close(self) -> None: ...


def facing_light(
    position: np.ndarray, points: np.ndarray, normals: np.ndarray, takes: np.ndarray
) -> np.ndarray:
    """(k,) int64 the columns of ``points`` (3, n) float32 whose ``normals`` (3, n) face the
    light at ``position`` (3,) float32, among those that ``takes`` ((n,) bool) light."""
    return np.flatnonzero((shading.dot(position[:, None] - points, normals) > 0) & takes)


class RaysInNumPy:
    """``Tracer.intersect_camera`` and ``Tracer.toward_lights`` for a tracer that answers rays
    given as columns (``intersect_compact``) and segments toward several targets in one query
    (``occluded_toward_each(points, rows_each, targets)``: per target of ``targets`` (L, 3),
    ``occluded_toward`` of its ``rows_each[l]``), as the class it is mixed into has them: the
    camera rays and the shadow segments made in NumPy."""

    def intersect_camera(
        self, camera: CameraRays, index: np.ndarray, ids: bool = True
    ) -> tuple[np.ndarray, SurfaceHits, np.ndarray]:
        origins, directions = sample_rays(camera, np.ascontiguousarray(index, np.int64))
        rows, surfaces = self.intersect_compact(origins, directions, coherent=True, ids=ids)
        return rows, surfaces, directions

    def toward_lights(
        self, points: np.ndarray, normals: np.ndarray, targets: np.ndarray, takes: np.ndarray
    ) -> Iterator[LightAnswer]:
        targets = np.asarray(targets, np.float32).reshape(-1, 3)
        facing_each = [facing_light(target, points, normals, takes) for target in targets]
        blocked_each = self.occluded_toward_each(points, facing_each, targets)
        for target, facing, blocked in zip(targets, facing_each, blocked_each, strict=True):
            visible = np.zeros(points.shape[1], bool)
            visible[facing] = ~blocked
            direction = shading.normalize(target[:, None] - points)
            direction *= visible  # (x · 1 is x: the visible columns' bits stay)
            yield visible, direction, len(facing)
