"""A set of bricks in the integrator's place of one BVH: rays routed to the bricks whose boxes
they reach, answers merged by ``nearest``.

``BrickSet`` is a ``tracer.Tracer``, what ``integrator.Integrator`` takes as its ``tracer``:
``intersect_compact`` and ``occluded_toward`` as ``SceneGeometry`` has them, every light's
shadow segments in one query (``occluded_toward_each``), and from those, through
``tracer.RaysInNumPy``, the camera rays and the segments toward the lights. Per call it
tests every ray against every brick's box (``ray_boxes``), asks each brick reached about its
rays only, and keeps the nearest hit (``nearest_over_bricks``); a shadow segment is blocked if
any brick blocks it. The floor, an analytic plane, is answered here by a BVH with no objects
and the scene's floor: its records are those the whole scene's BVH makes, and a ray that meets
the floor need not look for objects beyond it. Where the bricks live is the business of a
``BrickQueries``: ``LocalBricks`` holds them in this process; ``bricks.cluster`` on Dask
workers.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from embree_rt.ambient_occlusion import HemisphereQuery
from embree_rt.bricks.brick import Brick, BrickHits, brick_sphere_mode
from embree_rt.bricks.contents import scene_brick, without_objects
from embree_rt.bricks.nearest import nearest_over_bricks
from embree_rt.bricks.partition import Partition
from embree_rt.bricks.ray_boxes import boxes_reached, padded_boxes, rows_by_brick
from embree_rt.closing import Closing
from embree_rt.geometry import SceneGeometry, SurfaceHits
from embree_rt.scene.model import Scene
from embree_rt.tracer import RaysInNumPy

# A request to brick b: (b, origins (3, k) float32, directions (3, k) float32, coherent).
IntersectRequest = tuple[int, np.ndarray, np.ndarray, bool]
# A request to brick b: (b, [(segment start points (3, k) float32, their light (3,) float32)]).
OccludedRequest = tuple[int, list[tuple[np.ndarray, np.ndarray]]]


class BrickQueries(Protocol):
    """Where the bricks are: answers requests to several bricks at once (in any order inside,
    the answers in the requests' order)."""

    def intersect(self, requests: list[IntersectRequest]) -> list[BrickHits]: ...

    def occluded(self, requests: list[OccludedRequest]) -> list[list[np.ndarray]]: ...

    def close(self) -> None: ...


@dataclass
class BrickTraffic:
    """What crossed between the integrator and the bricks: ``rays`` asked for hits and
    ``ray_sends`` (ray, brick) pairs sent; ``segments`` shadow segments not blocked by the floor
    and ``segment_sends``; ``ties``: exact ties between bricks (``nearest``'s rule 2)."""

    rays: int = 0
    ray_sends: int = 0
    segments: int = 0
    segment_sends: int = 0
    ties: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def add(self, **counts: int) -> None:
        with self.lock:
            for name, value in counts.items():
                setattr(self, name, getattr(self, name) + value)


class BrickSet(RaysInNumPy, Closing):
    """The integrator's tracer over bricks of ``scene`` whose boxes are ``bounds`` (K, 2, 3)
    float64, answered by ``queries``. ``scene`` gives the floor (its objects are not used)."""

    def __init__(self, scene: Scene, bounds: np.ndarray, queries: BrickQueries) -> None:
        self.floor = SceneGeometry(without_objects(scene, floor=True), threads=1)
        self.boxes = padded_boxes(bounds)
        self.queries = queries
        self.traffic = BrickTraffic()

    def close(self) -> None:
        self.floor.close()
        self.queries.close()

    def intersect_compact(
        self, origins: np.ndarray, directions: np.ndarray, coherent: bool = False, ids: bool = True
    ) -> tuple[np.ndarray, SurfaceHits]:
        """``SceneGeometry.intersect_compact`` over the bricks: the (m,) int64 rays that hit
        and their ``SurfaceHits``, bitwise those of one BVH of the whole scene but for exact
        ties between bricks (``nearest``). Their Embree ids are None whatever ``ids`` asks:
        a brick's ids name its own BVH, not the scene's."""
        origins = np.ascontiguousarray(origins, np.float32)
        directions = np.ascontiguousarray(directions, np.float32)
        n = origins.shape[1]
        floor = self.floor.intersect_compact(origins, directions, coherent=coherent)
        # A ray that meets the floor looks for objects up to it, no further: beyond it they lose.
        reach = np.full(n, np.inf)
        reach[floor[0]] = floor[1].t
        routes = rows_by_brick(boxes_reached(origins, directions, reach, self.boxes))
        requests = [
            (
                brick,
                np.ascontiguousarray(origins[:, rows]),
                np.ascontiguousarray(directions[:, rows]),
                coherent,
            )
            for brick, rows in routes
        ]
        answers = self.queries.intersect(requests) if requests else []
        answered = [(rows, hits) for (_, rows), hits in zip(routes, answers, strict=True)]
        rays, surfaces, ties = nearest_over_bricks(n, floor, answered)
        surfaces.incoming = np.take(directions, rays, axis=1)
        self.traffic.add(rays=n, ray_sends=sum(len(rows) for _, rows in routes), ties=ties)
        return rays, surfaces

    def occluded_toward(
        self, points: np.ndarray, rows: np.ndarray, target: np.ndarray
    ) -> np.ndarray:
        """``SceneGeometry.occluded_toward`` over the bricks: (k,) bool whether the floor or any
        brick blocks the segment from each ``points[:, rows]`` ((3, n) float32) to ``target``."""
        return self.occluded_toward_each(points, [rows], np.reshape(target, (1, 3)))[0]

    def occluded_hemispheres(self, rays: HemisphereQuery) -> np.ndarray:
        """Refused: ambient occlusion's occlusion rays are not routed over bricks (the command
        refuses ``--ao`` with bricks before anything is built)."""
        raise NotImplementedError(
            "render.ao: ambient occlusion is not rendered over bricks; render on one BVH"
        )

    def occluded_toward_each(
        self, points: np.ndarray, rows_each: list[np.ndarray], targets: np.ndarray
    ) -> list[np.ndarray]:
        """``occluded_toward`` toward each of the ``targets`` (L, 3) from its ``rows_each[l]``
        of ``points``, in one query: each brick is asked once about every target's segments."""
        targets = np.asarray(targets, np.float32).reshape(-1, 3)
        blocked_each, open_each, sent = [], [], {}
        segments = sends = 0
        for light, (rows, target) in enumerate(zip(rows_each, targets, strict=True)):
            blocked = self.floor.occluded_toward(points, rows, target)
            open_rows = np.flatnonzero(~blocked)
            blocked_each.append(blocked)
            open_each.append(open_rows)
            if len(open_rows) == 0:
                continue
            starts = np.ascontiguousarray(np.take(points, rows[open_rows], axis=1), np.float32)
            toward = target[:, None] - starts
            reach = np.ones(len(open_rows))
            for brick, sub in rows_by_brick(boxes_reached(starts, toward, reach, self.boxes)):
                sent.setdefault(brick, []).append(
                    (light, sub, np.ascontiguousarray(starts[:, sub]))
                )
            segments += len(open_rows)
        requests = [
            (brick, [(starts, targets[light]) for light, _, starts in asked])
            for brick, asked in sent.items()
        ]
        answers = self.queries.occluded(requests) if requests else []
        for asked, answer in zip(sent.values(), answers, strict=True):
            for (light, sub, _), blocked in zip(asked, answer, strict=True):
                blocked_each[light][open_each[light][sub[blocked]]] = True
                sends += len(sub)
        self.traffic.add(segments=segments, segment_sends=sends)
        return blocked_each


class LocalBricks:
    """``BrickQueries`` on bricks held in this process (one after another on the calling
    thread): the data-parallel render without a cluster, to check it against one BVH."""

    def __init__(self, bricks: list[Brick]) -> None:
        self.bricks = {brick.index: brick for brick in bricks}

    def intersect(self, requests: list[IntersectRequest]) -> list[BrickHits]:
        return [self.bricks[b].intersect(o, d, coherent) for b, o, d, coherent in requests]

    def occluded(self, requests: list[OccludedRequest]) -> list[list[np.ndarray]]:
        return [self.bricks[b].occluded(segments) for b, segments in requests]

    def close(self) -> None:
        for brick in self.bricks.values():
            brick.close()


def local_brick_set(scene: Scene, partition: Partition, spheres: str = "analytic") -> BrickSet:
    """A ``BrickSet`` of ``scene`` cut by ``partition``, every brick built in this process."""
    mode = brick_sphere_mode(len(scene.sphere_radii), spheres)
    bricks = []
    try:
        for index in range(partition.bricks):
            bricks.append(Brick(scene_brick(scene, partition, index), mode))
    except BaseException:
        for brick in bricks:
            brick.close()
        raise
    bounds = np.array([brick.bounds for brick in bricks])
    return BrickSet(scene, bounds, LocalBricks(bricks))
