"""Which brick each object belongs to: a k-d split of space into K boxes by object centres.

A ``Partition`` is a k-d tree of K leaves (the bricks): each node splits along one axis at one
value, objects whose centre lies below it going left. Membership is decided by the centre
alone, by one compiled rule (``brick_of``) on the centres as the scene stores them, so any
process holding the scene (or generating a random field from its recipe) puts every object in
the same brick without being told, and every object is in exactly one brick.

The planes come from points standing for the objects: the centres themselves for a scene in
memory (``scene_partition``: a median split of the longest side of the node's box, the node's
bricks shared out in proportion), or, for a random field, a lattice of its grid's cells, with
planes on cell boundaries (``field_partition``): a field's sphere never leaves its cell, so no
small sphere straddles a plane, and no field need be generated to split it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from embree_rt.scene.model import Scene

# A random field is split on a lattice of about this many of its cells (every m-th row and
# column): enough to place the planes within a fraction of a percent of the true medians.
FIELD_SAMPLE_CELLS = 400_000


@dataclass(frozen=True)
class Partition:
    """K bricks as the leaves of a k-d tree.

    ``bricks`` is K; per split node (m = K - 1 of them, node 0 the root): ``axis`` (m,) int64,
    ``value`` (m,) float64 (centres with ``centre[axis] < value`` go left), ``left`` and
    ``right`` (m,) int64 children: a node's index when >= 0, else brick ``-1 - child``.
    """

    bricks: int
    axis: np.ndarray
    value: np.ndarray
    left: np.ndarray
    right: np.ndarray

    def brick_of(self, centers: np.ndarray) -> np.ndarray:
        """(n,) int32 brick of each of the (n, 3) ``centers`` (float32 as scenes store them,
        or float64)."""
        centers = np.asarray(centers)
        if self.bricks == 1:
            return np.zeros(len(centers), np.int32)
        if centers.dtype not in (np.float32, np.float64):
            centers = centers.astype(np.float64)
        return _brick_of(
            np.ascontiguousarray(centers), self.axis, self.value, self.left, self.right
        )

    def region(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(3,) float64 low and high corners of brick ``index``'s region of space (-inf, inf
        where the tree leaves it open): every centre in the brick lies in it."""
        low, high = np.full(3, -np.inf), np.full(3, np.inf)
        target = -1 - index
        path = _path_to(self, 0, target) if self.bricks > 1 else []
        for node, went_left in path:
            axis, value = self.axis[node], self.value[node]
            if went_left:
                high[axis] = min(high[axis], value)
            else:
                low[axis] = max(low[axis], value)
        return low, high


def _path_to(partition: Partition, node: int, target: int) -> list[tuple[int, bool]]:
    """The (node, went left) steps from ``node`` down to leaf ``target`` (empty: not below)."""
    for went_left, child in ((True, partition.left[node]), (False, partition.right[node])):
        if child == target:
            return [(node, went_left)]
        if child >= 0 and (path := _path_to(partition, int(child), target)):
            return [(node, went_left), *path]
    return []


@njit(nogil=True, cache=True)
def _brick_of(centers, axis, value, left, right):
    out = np.empty(len(centers), np.int32)
    for i in range(len(centers)):
        node = 0
        while node >= 0:
            # float32 centres compared as float64: exactly the value each process stores
            node = left[node] if np.float64(centers[i, axis[node]]) < value[node] else right[node]
        out[i] = -1 - node
    return out


def split_points(points: np.ndarray, bricks: int, snap: float = 0.0) -> Partition:
    """The k-d split of (n, 3) float64 ``points`` into ``bricks`` leaves: each node cuts the
    longest side of its points' box at the rank that gives its two halves points in proportion
    to their bricks (``bricks // 2`` left). ``snap`` > 0 moves each plane down to a multiple of
    ``snap`` (a random field's cell boundaries). Deterministic: the same points, the same tree.
    Points are only stand-ins: a brick of a tree cut among equal coordinates may stay empty."""
    if bricks < 1:
        raise ValueError(f"bricks: must be >= 1, got {bricks}")
    points = np.asarray(points, np.float64).reshape(-1, 3)
    axis: list[int] = []
    value: list[float] = []
    left: list[int] = []
    right: list[int] = []
    leaves = iter(range(bricks))

    def build(rows: np.ndarray, k: int) -> int:
        if k == 1:
            return -1 - next(leaves)
        node = len(axis)
        axis.append(0)
        value.append(0.0)
        left.append(0)
        right.append(0)
        k_left = k // 2
        chosen, plane = _cut(points[rows], k_left / k, snap)
        below = points[rows, chosen] < plane
        axis[node], value[node] = chosen, plane
        left[node] = build(rows[below], k_left)
        right[node] = build(rows[~below], k - k_left)
        return node

    build(np.arange(len(points)), bricks)
    return Partition(
        bricks,
        np.asarray(axis, np.int64),
        np.asarray(value, np.float64),
        np.asarray(left, np.int64),
        np.asarray(right, np.int64),
    )


def _cut(points: np.ndarray, share: float, snap: float) -> tuple[int, float]:
    """The axis (the longest side of ``points``' box, ties to the lower axis) and the plane
    below which about ``share`` of ``points`` (k, 3) fall."""
    if len(points) == 0:
        return 0, 0.0
    low, high = points.min(axis=0), points.max(axis=0)
    axis = int(np.argmax(high - low))
    coordinate = points[:, axis]
    rank = min(int(len(points) * share), len(points) - 1)
    plane = float(np.partition(coordinate, rank)[rank])
    if snap > 0:
        plane = math.floor(plane / snap) * snap
    return axis, plane


def object_centers(scene: Scene) -> np.ndarray:
    """(n, 3) float64 centre of each object of ``scene`` in object-id order
    (``Scene.object_id_starts``): each sphere's centre, each mesh placement's and each
    instance copy's world bounding box's centre."""
    low, high = object_bounds(scene, spheres=False)
    meshes = (low + high) / 2
    return np.concatenate([np.asarray(scene.sphere_centers, np.float64), meshes])


def object_bounds(scene: Scene, spheres: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float64 low and high corners of each object's world bounding box in object-id
    order (without the spheres when ``spheres`` is False: the meshes' placements and copies,
    then the curve sets)."""
    parts_low, parts_high = [], []
    if spheres:
        centers = np.asarray(scene.sphere_centers, np.float64)
        radii = np.asarray(scene.sphere_radii, np.float64)[:, None]
        parts_low.append(centers - radii)
        parts_high.append(centers + radii)
    for placement in scene.meshes:
        low, high = placed_bounds(placement.mesh.bounds, placement.transform[None])
        parts_low.append(low)
        parts_high.append(high)
    for entry in scene.instances:
        low, high = placed_bounds(entry.mesh.bounds, entry.transforms)
        parts_low.append(low)
        parts_high.append(high)
    for curves in scene.curves:  # a curve set is one object
        radii = np.asarray(curves.radii, np.float64)[:, None]
        points = np.asarray(curves.points, np.float64)
        parts_low.append((points - radii).min(axis=0)[None])
        parts_high.append((points + radii).max(axis=0)[None])
    if not parts_low:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate(parts_low), np.concatenate(parts_high)


def placed_bounds(bounds: np.ndarray, transforms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float64 low and high corners of the world box around a mesh of (2, 3) ``bounds``
    placed by each of (n, 4, 4) ``transforms`` (its eight corners moved)."""
    low, high = np.asarray(bounds, np.float64)
    corners = np.array(
        [[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])]
    )
    transforms = np.asarray(transforms, np.float64)
    world = np.einsum("cj,nij->nci", corners, transforms[:, :3, :3]) + transforms[:, None, :3, 3]
    return world.min(axis=1), world.max(axis=1)


def scene_partition(scene: Scene, bricks: int) -> Partition:
    """``split_points`` of ``scene``'s object centres into ``bricks`` bricks."""
    return split_points(object_centers(scene), bricks)


def field_cells_sample(plan) -> np.ndarray:
    """(s, 3) float64 centres (y = 0) of a lattice of a random field's grid cells (a
    ``FieldPlan``: every m-th row and column inside its disc, the heroes' clear rings left
    out), about ``FIELD_SAMPLE_CELLS`` of them: stand-ins for its spheres."""
    from embree_rt.scene.random_field import HERO_CLEARANCE, HERO_RADIUS, HEROES

    spacing, extent = plan.spacing, plan.extent
    reach = math.ceil(extent / spacing) + 1
    stride = max(1, math.ceil(math.sqrt(max(plan.small, 1) / FIELD_SAMPLE_CELLS)))
    index = np.arange(-reach, reach + 1, stride, dtype=np.int64)
    x = (index[:, None] + 0.5) * spacing + np.zeros(len(index))[None, :]
    z = (index[None, :] + 0.5) * spacing + np.zeros(len(index))[:, None]
    x, z = x.reshape(-1), z.reshape(-1)
    keep = x * x + z * z < extent * extent
    keep_out = (HERO_RADIUS + HERO_CLEARANCE * spacing) ** 2
    for (hx, hz), _ in HEROES[: plan.heroes]:
        keep &= (x - hx) ** 2 + (z - hz) ** 2 > keep_out
    x, z = x[keep], z[keep]
    return np.column_stack([x, np.zeros(len(x)), z])


def field_partition(plan, bricks: int) -> Partition:
    """The k-d split of a random field (a ``FieldPlan``) into ``bricks`` bricks, on its
    ``field_cells_sample`` with planes on cell boundaries."""
    return split_points(field_cells_sample(plan), bricks, snap=plan.spacing)


def field_brick_counts(plan, partition: Partition) -> np.ndarray:
    """(K,) int64 estimate of the spheres each brick of a random field holds (its share of the
    sample's cells, and the heroes it holds), before any sphere is made."""
    from embree_rt.scene.random_field import HERO_RADIUS, HEROES

    sample = field_cells_sample(plan)
    share = np.bincount(partition.brick_of(sample), minlength=partition.bricks) / max(
        len(sample), 1
    )
    counts = np.ceil(share * plan.small).astype(np.int64)
    heroes = np.array([[x, HERO_RADIUS, z] for (x, z), _ in HEROES[: plan.heroes]]).reshape(-1, 3)
    counts += np.bincount(partition.brick_of(heroes), minlength=partition.bricks)
    return counts
