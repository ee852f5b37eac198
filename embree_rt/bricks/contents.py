"""What one brick holds: its objects as a scene of their own, and their ids in the whole scene.

A brick's scene keeps the whole scene's materials, in order (material ids are indices into
them, and shading reads them by those ids), and has no floor: the floor is an analytic plane
every ray meets the same way, answered once by the client (``brick_set``). Objects keep their
order within each kind, so a brick's object ``i`` (in ``Scene.object_id_starts`` order) is
object ``object_ids[i]`` of the whole scene.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from embree_rt.bricks.partition import Partition, object_bounds, placed_bounds
from embree_rt.compiled.heap import release_freed_memory
from embree_rt.scene.model import Scene


@dataclass
class BrickContents:
    """Brick ``index``'s objects: ``scene`` (no floor, no lights) and ``object_ids`` (m,) int64,
    the whole scene's id of each of its objects in its own object-id order."""

    index: int
    scene: Scene
    object_ids: np.ndarray

    def bounds(self) -> np.ndarray:
        """(2, 3) float64 low and high corners of the box around every object of the brick
        (low > high when it holds none)."""
        box = np.array([[np.inf] * 3, [-np.inf] * 3])
        scene = self.scene
        if len(scene.sphere_radii):  # in float32, as stored (ray_boxes pads far beyond it)
            radii = scene.sphere_radii[:, None]
            box[0] = np.minimum(box[0], (scene.sphere_centers - radii).min(axis=0))
            box[1] = np.maximum(box[1], (scene.sphere_centers + radii).max(axis=0))
        low, high = object_bounds(scene, spheres=False)
        if len(low):
            box[0] = np.minimum(box[0], low.min(axis=0))
            box[1] = np.maximum(box[1], high.max(axis=0))
        return box


def without_objects(scene: Scene, floor: bool = False) -> Scene:
    """``scene`` with no objects: its materials, lights, camera and background, and its floor
    when ``floor`` (a brick's scene before its objects go in: no floor)."""
    empty = np.zeros((0, 3), np.float32), np.zeros(0, np.float32), np.zeros(0, np.int32)
    return replace(
        scene,
        floor=scene.floor if floor else None,
        sphere_centers=empty[0],
        sphere_radii=empty[1],
        sphere_materials=empty[2],
        sphere_colors=None,
        meshes=[],
        instances=[],
        curves=[],
        animation=None,
        notes=[],
    )


def scene_brick(scene: Scene, partition: Partition, index: int) -> BrickContents:
    """Brick ``index`` of ``partition`` cut from ``scene``: the spheres whose centre, and the
    mesh placements, instance copies and curve sets whose world box's centre, lie in it."""
    ids = []
    mine = np.flatnonzero(partition.brick_of(scene.sphere_centers) == index)
    ids.append(mine.astype(np.int64))
    part = without_objects(scene)
    if len(mine):
        part.add_spheres(
            scene.sphere_centers[mine],
            scene.sphere_radii[mine],
            scene.sphere_materials[mine],
            colors=None if scene.sphere_colors is None else scene.sphere_colors[mine],
            copy=False,
        )
    mesh_ids, instance_starts = scene.object_id_starts()
    for placement, object_id in zip(scene.meshes, mesh_ids, strict=True):
        low, high = placed_bounds(placement.mesh.bounds, placement.transform[None])
        if partition.brick_of((low + high) / 2)[0] == index:
            part.meshes.append(placement)
            ids.append(np.array([object_id], np.int64))
    for entry, first_id in zip(scene.instances, instance_starts, strict=True):
        low, high = placed_bounds(entry.mesh.bounds, entry.transforms)
        copies = np.flatnonzero(partition.brick_of((low + high) / 2) == index)
        if len(copies):
            part.instances.append(
                replace(
                    entry, transforms=entry.transforms[copies], materials=entry.materials[copies]
                )
            )
            ids.append(first_id + copies.astype(np.int64))
    # a curve set, whole, where its box's centre lies (the brick's box then reaches all of it)
    for curves, object_id in zip(scene.curves, scene.curve_ids(), strict=True):
        radii = np.asarray(curves.radii, np.float64)[:, None]
        low = (curves.points - radii).min(axis=0)
        high = (curves.points + radii).max(axis=0)
        if partition.brick_of(((low + high) / 2)[None])[0] == index:
            part.curves.append(curves)
            ids.append(np.array([object_id], np.int64))
    return BrickContents(index, part, np.concatenate(ids))


def field_brick(plan, partition: Partition, index: int) -> BrickContents:
    """Brick ``index`` of a random field (a ``FieldPlan``), generated from its recipe: only this
    brick's spheres are ever held (``add_field_spheres_where``), and only the rings of the field
    that reach the brick's region are generated."""
    from embree_rt.scene.random_field import add_field_spheres_where, field_scene

    part = without_objects(field_scene(plan))
    low, high = partition.region(index)
    ids = add_field_spheres_where(
        part,
        plan,
        lambda centers: partition.brick_of(centers) == index,
        within=((low[0], low[2]), (high[0], high[2])),
    )
    # The rings generated and let go sit in the generating threads' heaps, as much again as
    # the brick's spheres: back to the kernel before the BVH is built beside them.
    release_freed_memory()
    return BrickContents(index, part, ids)
