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
  (``local_scene``), or grazing its triangle, is decided again in float64 against the triangles
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
from trimesh.constants import tol

from embree_rt.compiled.work_split import parallel_region
from embree_rt.embree.multihit import HitBuffers, crossing_parity
from embree_rt.trimesh_ray.decided_hits import decided_hits
from embree_rt.trimesh_ray.finished_hits import finished_hits
from embree_rt.trimesh_ray.hit_inputs import tolerances, world_rays
from embree_rt.trimesh_ray.local_frame import (
    boxed_local_points,
    local_rays,
    ordered_local_rays,
    refuse_rays,
)
from embree_rt.trimesh_ray.local_scene import BAND_ULPS, EDGE_BAND_SCALE, EPS32, LocalScene
from embree_rt.trimesh_ray.plane_distances import plane_distances
from embree_rt.trimesh_ray.screened_nearest import screened_nearest
from embree_rt.trimesh_ray.settled_hits import settled_hits

# trimesh.ray.ray_util.contains_points's first direction, then two more for rays that pass too
# near an edge or along a face to trust their parity.
_CONTAINS_DIRECTIONS = np.array(
    [
        [0.4395064455, 0.617598629942, 0.652231566745],
        [-0.5773502691896258, 0.7071067811865476, -0.4082482904638631],
        [0.8017837257372732, -0.2672612419124244, -0.5345224838248488],
    ]
)
# trimesh.intersections.planes_lines: a ray and a plane with |cos| at most this do not meet.
_PARALLEL_COS = 1e-5
# Hits at a smaller |cos| (float32) are decided again in float64: near _PARALLEL_COS, Embree's
# float32 cosine may fall on either side.
_GRAZE_COS = 1e-3
# Embree's float32 distances err by a few ulps of the largest coordinate involved: hits within
# this many of the origin are decided in float64.
_TNEAR_ULPS = 16.0
# Embree counts no hit behind a ray's origin, so a surface through the origin, which its float32
# rounding may put a little behind it, can go unseen: rays whose origin lies within this many
# float32 ulps of the mesh's extent of its box are also traced backwards that far, and the
# triangles found there join their float64 decision.
_BEHIND_ULPS = 16.0
_BEHIND_ROOM = 8  # triangles recorded behind an origin (their fans are tested: a vertex's worth)
# Rays traced per call, and rays x room for hits: bounded memory, reused from block to block.
_BLOCK_RAYS = 1 << 17  # 21 MB of hit buffers at 8 hits a ray, kept by the scene
FIRST_ROOM = 8  # hits of room a ray on the first trace (rays that overflow it are traced again)
_BLOCK_HITS = 1 << 21


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


def _plane_distance(scene, origins, directions, rays, tris):
    """float64 distance along each ray to its triangle's plane, and |cos| of the angle between
    ray and normal, trimesh's planes_lines formula (compiled: ``plane_distances``)."""
    return plane_distances(scene.planes, origins, directions, rays, tris)


def _spliced(hits, rows, again):
    """``hits``: a multi-hit answer ``(rays (m,) int64, tris (m,) int64, locations (m, 3)
    float64 or None)`` in trimesh's order (every ray's first hit, rays ascending, then every
    ray's second ...), with the hits of rays ``rows`` (k,) int64 replaced by ``again``, the
    answer for those rays alone (its rays index ``rows``), in the same order."""
    rays, tris, locations = hits
    keep = ~np.isin(rays, rows)
    rays = np.concatenate([rays[keep], rows[again[0]]])
    tris = np.concatenate([tris[keep], again[1]])
    # a hit's depth: how many hits of its ray come before it (each ray's hits are in order)
    order = np.argsort(rays, kind="stable")
    starts = np.searchsorted(rays[order], rays[order])
    depth = np.empty(len(rays), np.int64)
    depth[order] = np.arange(len(rays)) - starts
    placed = np.lexsort((rays, depth))
    if locations is not None:
        locations = np.concatenate([locations[keep], again[2]])[placed]
    return rays[placed], tris[placed], locations


def _surfaces_behind(scene: LocalScene, origins, directions, near):
    """The rays whose origin may lie on a surface Embree's forward trace cannot see (within
    float32 reach behind it): ``origins``, ``directions`` (n, 3) float64 world rays
    (directions need not be unit), ``near`` (n,) float64 world distances from which hits count
    (at or beyond). Returns their rows (k,) int64, ascending, and the triangles behind each
    whose planes pass within ``_BEHIND_ULPS`` float32 ulps of the mesh's extent of its origin
    (``HitBuffers`` of k rays, traced backwards from the float32 origins the forward trace
    uses)."""
    band = _BEHIND_ULPS * EPS32 * scene.extent
    if not scene.face_count:
        return np.zeros(0, np.int64), None
    lower, upper = scene.vertices.min(axis=0), scene.vertices.max(axis=0)
    reach = band / scene.scale
    widened = np.array([lower - reach, upper + reach])
    rows, local = boxed_local_points(origins, widened, scene.origin, scene.scale)
    close = near[rows] * scene.scale < band  # else no hit that near counts anyway
    rows, local = rows[close], local[close]
    if not len(rows):
        return rows, None
    with np.errstate(invalid="ignore", over="ignore"):
        backwards = -util.unitize(directions[rows]).astype(np.float32)
    # a surface at float32 reach of the origin lies that far behind it across its plane, and
    # up to 1 / |cos| times that along a ray near its plane (down to the |cos| at which a ray
    # no longer meets a plane)
    reach = np.float32(band / _PARALLEL_COS)
    behind = scene.bvh.all_hits(local, backwards, 0.0, reach, _BEHIND_ROOM)
    with np.errstate(invalid="ignore", over="ignore"):  # slots past a ray's count are unset
        close = (np.arange(_BEHIND_ROOM)[None, :] < behind.count[:, None]) & (
            behind.t.astype(np.float64) * behind.cos <= band
        )
    found = close.any(axis=1)
    first = np.argsort(~close[found], axis=1, kind="stable")  # the close ones, in order
    return rows[found], HitBuffers(
        *(np.take_along_axis(field[found], first, axis=1) for field in behind[:5]),
        close[found].sum(axis=1),
        np.asarray(behind.more[found]),
    )


def _with_surfaces_behind(forward: HitBuffers, behind: HitBuffers) -> HitBuffers:
    """``forward``'s hits of k rays followed by the triangles ``behind`` them, marked for the
    float64 test (barycentric 0: as if on an edge, so the triangles around each are tested)."""
    k, room = forward.prim.shape
    extra = behind.prim.shape[1]
    shape = (k, room + extra)
    t = np.zeros(shape, np.float32)
    prim = np.full(shape, -1, np.int32)
    u = np.zeros(shape, np.float32)
    v = np.zeros(shape, np.float32)
    cos = np.ones(shape, np.float32)
    for target, source in ((t, forward.t), (prim, forward.prim), (u, forward.u), (v, forward.v)):
        target[:, :room] = source
    cos[:, :room] = forward.cos
    count = np.minimum(forward.count, room)
    columns = count[:, None] + np.arange(extra)[None, :]
    valid = np.arange(extra)[None, :] < np.minimum(behind.count, extra)[:, None]
    ray = np.broadcast_to(np.arange(k)[:, None], valid.shape)
    prim[ray[valid], columns[valid]] = behind.prim[valid]
    return HitBuffers(
        t, prim, u, v, cos, count + np.minimum(behind.count, extra), np.asarray(forward.more)
    )


class _HitList:
    """The multi-hit query's hits, part after part, in arrays lent by the scene (grown as
    needed): (rays, tris) int64 and distance float64, so that no part is copied twice."""

    def __init__(self, scene: LocalScene, size: int) -> None:
        self._scene = scene
        self._arrays = self._lent(max(size, 1))
        self._count = 0

    def _lent(self, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return tuple(
            self._scene.scratch(f"hits_{k}", size, dtype)
            for k, dtype in enumerate((np.int64, np.int64, np.float64))
        )

    def room(self, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Views of the next ``size`` places, to write a part into (then ``filled``)."""
        if self._count + size > len(self._arrays[0]):
            grown = tuple(np.empty(2 * (self._count + size), array.dtype) for array in self._arrays)
            for old, new in zip(self._arrays, grown, strict=True):
                new[: self._count] = old[: self._count]
            self._arrays = grown
        return tuple(array[self._count : self._count + size] for array in self._arrays)

    def filled(self, size: int) -> None:
        """The next ``size`` places now hold a part."""
        self._count += size

    def append(self, part: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Copy a part (rays, tris, distance) in."""
        for target, source in zip(self.room(len(part[0])), part, strict=True):
            target[:] = source
        self.filled(len(part[0]))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rays, tris, distance) of every part so far."""
        return tuple(array[: self._count] for array in self._arrays)


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

    @staticmethod
    def _resolve_tnear(scene, magnitude, tnear):
        """(near (n,) float64 world distance, inclusive): hits count at distance > near (>=
        when ``tnear`` is given, ``inclusive``); by default near is a few float32 ulps of
        ``magnitude`` (n,), each ray's largest local coordinate (its origin's or the mesh's)."""
        if tnear is None:
            return _TNEAR_ULPS * EPS32 * magnitude / scene.scale, False
        near = np.broadcast_to(np.asarray(tnear, dtype=np.float64), (len(magnitude),))
        if not np.isfinite(near).all() or (near < 0).any():
            raise ValueError("tnear: must be finite and >= 0")
        return near, True

    def _hits(
        self,
        origins,
        directions,
        max_hits,
        tnear,
        reorder=False,
        with_locations=False,
        room=None,
        as_given=None,
    ):
        """Every ray's nearest ``max_hits`` hits in trimesh's order (every ray's first hit, rays
        ascending, then every ray's second, ...): ``(rays, triangles)`` (k,) int64 and, with
        ``with_locations``, the points (k, 3) float64 (else None); each ray's hits by distance,
        then triangle, one hit per crossing of the surface (at an edge or a vertex, the
        lowest-index triangle there: ``finished_hits``).

        With ``reorder`` (and a big mesh: ``scene.bounds``) the rays are traced, and every step
        but the last run, in a coherent order (``local_frame.ordered_local_rays``); each ray's
        hits are computed from its own row alone, so they are the same in any order.

        ``room``: Embree hits recorded a ray (default ``max_hits`` + 4). Hits at one point
        become one crossing, so a ray whose recorded hits overflowed it and gave fewer than
        ``max_hits`` crossings (a ray through a vertex many triangles share) may have more:
        such rays are traced again with four times the room. ``as_given``: the directions as
        the caller gave them (before ``unitize``), to name a bad row as written."""
        scene = self._scene
        n = len(origins)
        given_origins, given_directions, given_tnear = origins, directions, tnear
        traced_order = None
        if reorder and scene.bounds is not None:
            (
                traced_order,
                origins,
                directions,
                local_origins,
                local_directions,
                magnitude,
                finite,
            ) = ordered_local_rays(
                origins,
                directions,
                scene.origin,
                scene.scale,
                scene.extent,
                scene.bounds,
                scene.bvh.threads,
            )
            if tnear is not None and np.ndim(tnear):
                tnear = np.broadcast_to(np.asarray(tnear, np.float64), (n,))[traced_order]
        else:
            local_origins, local_directions, magnitude, finite = local_rays(
                origins, directions, scene.origin, scene.scale, scene.extent
            )
        if not finite:  # named by its row as given
            written = given_directions if as_given is None else as_given
            refuse_rays(given_origins, written, scene.origin, scene.scale)
        near, inclusive = self._resolve_tnear(scene, magnitude, tnear)
        capacity = max(1, int(max_hits))
        # room for hits the float64 rules below drop (at the origin, along a face) and for edge
        # pairs, so that the nearest `capacity` survive
        room = capacity + 4 if room is None else room
        truncated = []  # positions of rays whose final trace had more hits than its room
        # Most rays hit a few triangles: trace with a little room first and again, with all of
        # it, only the rays that overflowed (so the hit arrays stay small).
        first_room = min(room, FIRST_ROOM)
        block = max(1, min(_BLOCK_RAYS, _BLOCK_HITS // first_room))
        buffers = scene.hit_buffers(first_room)
        hits, pending_parts = _HitList(scene, 2 * n), []
        rules = tolerances(EDGE_BAND_SCALE, _GRAZE_COS, _PARALLEL_COS, tol.zero)
        world = world_rays(origins, directions, magnitude, near, inclusive)
        for first in range(0, n, block):
            rows = slice(first, min(n, first + block))
            # Embree from the local frame's tnear (inclusive, a little short of ours): which
            # hits count as at the origin is decided below in float64.
            block_near = (near[rows] * scene.scale * 0.5).astype(np.float32)
            result = scene.bvh.all_hits(
                local_origins[rows],
                local_directions[rows],
                block_near,
                np.inf,
                first_room,
                out=buffers,
            )
            scene.keep_hit_buffers(first_room, result)
            buffers = result
            # rays clear of edges and grazing settled in one compiled pass; the others go to the
            # float64 path below, those that overflowed `first_room` traced again first
            recorded = int(result[5].sum())
            rays, tris, distance, messy = settled_hits(
                result,
                room > first_room,
                world_rays(origins[rows], directions[rows], magnitude[rows], near[rows], inclusive),
                scene.tables,
                rules,
                scene.bvh.threads,
                tuple(
                    scene.scratch(f"settle_{k}", recorded, dtype)
                    for k, dtype in enumerate((np.int64, np.int64, np.float64))
                ),
                hits.room(recorded),
                first,
            )
            hits.filled(len(rays))
            # Messy rays whose hits all fit are complete: decided in float64 now, from the
            # buffers as traced (a second trace with more room records the same hits in the same
            # order); the others are traced again first.
            overflowed = result[6] if room > first_room else np.zeros(len(messy), bool)
            if room <= first_room:
                truncated.append(first + np.flatnonzero(messy & result[6]))
            complete_rows = np.flatnonzero(messy & ~overflowed)
            hits.append(self._decided(complete_rows, first + complete_rows, result, world, rules))
            pending_parts.append(first + np.flatnonzero(messy & overflowed))
        pending = np.concatenate(pending_parts) if pending_parts else np.zeros(0, np.int64)
        block = max(1, min(_BLOCK_RAYS, _BLOCK_HITS // room))
        for first in range(0, len(pending), block):
            which = pending[first : first + block]
            block_near = (near[which] * scene.scale * 0.5).astype(np.float32)
            result = scene.bvh.all_hits(
                local_origins[which], local_directions[which], block_near, np.inf, room
            )
            hits.append(self._decided(np.arange(len(which)), which, result, world, rules))
            truncated.append(which[result[6]])
        rays, tris, distance = hits.arrays()
        if inclusive:
            # rays starting on a surface Embree's forward trace may have missed: decided again
            # in float64 with the triangles just behind their origins
            surface_rows, behind = _surfaces_behind(scene, origins, directions, near)
            if len(surface_rows):
                forward = scene.bvh.all_hits(
                    local_origins[surface_rows],
                    local_directions[surface_rows],
                    (near[surface_rows] * scene.scale * 0.5).astype(np.float32),
                    np.inf,
                    room,
                )
                again = self._decided(
                    np.arange(len(surface_rows)),
                    surface_rows,
                    _with_surfaces_behind(forward, behind),
                    world,
                    rules,
                )
                keep = ~np.isin(rays, surface_rows)
                rays, tris, distance = (
                    np.concatenate([part[keep], new])
                    for part, new in zip((rays, tris, distance), again, strict=True)
                )
                truncated.append(surface_rows[forward.more])
        finished = finished_hits(
            rays,
            tris,
            distance,
            traced_order,
            n,
            capacity,
            scene.fans()[0],
            scene.planes,
            scene.extent / scene.scale,
            _PARALLEL_COS,
            given_origins,
            given_directions,
            with_locations,
            scene.scratch,
            scene.bvh.threads,
        )
        truncated = np.concatenate(truncated) if truncated else np.zeros(0, np.int64)
        if traced_order is not None:
            truncated = traced_order[truncated]
        short = truncated[np.bincount(finished[0], minlength=n)[truncated] < capacity]
        if not len(short):
            return finished
        if given_tnear is not None and np.ndim(given_tnear):
            given_tnear = np.broadcast_to(given_tnear, (n,))[short]
        again = self._hits(
            given_origins[short],
            given_directions[short],
            capacity,
            given_tnear,
            with_locations=with_locations,
            room=4 * room,
        )
        return _spliced(finished, short, again)

    def _decided(self, rows, positions, result, world, rules):
        """Hits near an edge, a vertex or along a face decided in float64 as ray_triangle
        decides them, against all the triangles around them (``decided_hits``)."""
        scene = self._scene
        if not len(rows):
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        return decided_hits(
            rows, positions, result, world, scene.tables, rules, scene.fans(), scene.bvh.threads
        )

    def _first_hits(self, origins, directions, tnear) -> np.ndarray:
        """(n,) int64: the first triangle each of the rays ``origins``, ``directions`` (n, 3)
        float64 (directions not necessarily unit) hits, -1 for none. Embree's nearest-hit query
        answers, in one compiled pass with the frame change, every ray whose hit lies clear of
        edges, of grazing and of the origin (``screened_nearest``; on big meshes in the order
        of where the rays enter the mesh's box, which changes no answer, see
        ``embree_rt.trimesh_ray.screened_nearest``); the others (under 1% on the benchmark's meshes)
        go through ``_hits``, which decides them in float64."""
        scene = self._scene
        near = None
        if tnear is not None:
            near = np.broadcast_to(np.asarray(tnear, dtype=np.float64), (len(origins),))
            if not np.isfinite(near).all() or (near < 0).any():
                raise ValueError("tnear: must be finite and >= 0")
        prim, suspect = screened_nearest(
            scene.bvh,
            origins,
            directions,
            shift=scene.origin,
            scale=scene.scale,
            extent=scene.extent,
            bounds=scene.bounds,
            near=near,
            near_ulps=_TNEAR_ULPS,
            altitude=scene.min_altitude,
            floor_altitude=scene.floor_altitude,
            band_ulps=BAND_ULPS,
            graze=_GRAZE_COS,
            near_factor=4.0,
        )
        if near is not None:
            suspect[_surfaces_behind(scene, origins, directions, near)[0]] = True
        first = prim.astype(np.int64)
        again = np.flatnonzero(suspect)
        if len(again):
            more = self._hits(
                origins[again],
                util.unitize(directions[again]),
                1,
                None if near is None else near[again],
            )
            first[again] = -1
            first[again[more[0]]] = more[1]
        return first

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
            first = self._first_hits(origins, given_directions, tnear)
            rays = np.flatnonzero(first >= 0)
            tris = first[rays]
            if not return_locations:
                return tris, rays
            directions = util.unitize(given_directions[rays])
            distance = _plane_distance(
                self._scene, origins[rays], directions, np.arange(len(rays)), tris
            )[0]
            return tris, rays, origins[rays] + directions * distance[:, None]
        origins, directions, given_directions = _as_rays(ray_origins, ray_directions)
        rays, tris, locations = self._hits(
            origins,
            directions,
            max_hits,
            tnear,
            reorder=True,
            with_locations=return_locations,
            as_given=given_directions,
        )
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
        return self._first_hits(origins, directions, tnear).astype(np.int32)

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
            with parallel_region:
                odd, clear = crossing_parity(
                    scene.bvh.committed_scene(),
                    origins,
                    directions,
                    band,
                    _GRAZE_COS,
                    scene.bvh.threads,
                )
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
