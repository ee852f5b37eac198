"""The exact-hit pipeline: every query of ``RayMeshIntersector`` in stages over compiled
passes, each answering for a block of rays before the next runs.

- **screen** (``screened_nearest``, first hits only): Embree's nearest hit of each ray, in one
  pass with the frame change; a hit near an edge, grazing or at the origin is *suspect* and the
  ray goes through the stages below for its one nearest crossing, the others stand.
- **settle** (``settled_hits``): every hit Embree's filter recorded along each ray; a ray clear
  of edges and grazing is final here (float64 plane distances, sorted); the others are messy.
- **decide** (``decided_hits``): messy rays (traced again first if their hits overflowed), and
  rays whose origin may lie on a surface behind its float32 image (``surfaces_behind``),
  decided in float64 by ray_triangle's rule against the triangles around their doubtful hits.
- **finish** (``finished_hits``): the parts merged by ray, hits at one point made one per
  crossing, each ray cut to its nearest ``max_hits``, in trimesh's order, with the points.

``exact_hits`` runs them, one after the other in one function: screen (for the first hit only,
whose suspect rays then take the other stages), settle, decide, finish.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from trimesh import util
from trimesh.constants import tol

from embree_rt.embree import Rays
from embree_rt.embree.multihit import HitBuffers
from embree_rt.trimesh_ray.hit_passes import (
    Tolerances,
    WorldRays,
    decided_hits,
    finished_hits,
    screened_nearest,
    settled_hits,
    tolerances,
    world_rays,
)
from embree_rt.trimesh_ray.local_frame import (
    BAND_ULPS,
    EDGE_BAND_SCALE,
    EPS32,
    LocalScene,
    boxed_local_points,
    local_rays,
    ordered_local_rays,
    refuse_rays,
)

# trimesh.intersections.planes_lines: a ray and a plane with |cos| at most this do not meet.
PARALLEL_COS = 1e-5
# Hits at a smaller |cos| (float32) are decided again in float64: near PARALLEL_COS, Embree's
# float32 cosine may fall on either side.
GRAZE_COS = 1e-3
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


def _spliced(hits: FoundHits, rows: np.ndarray, again: FoundHits):
    """``hits``, a multi-hit answer in trimesh's order (every ray's first hit, rays ascending,
    then every ray's second ...), with the hits of rays ``rows`` (k,) int64 replaced by
    ``again``, the answer for those rays alone (its rays index ``rows``), in the same order.
    Returns (rays, tris, locations), as ``FoundHits`` has them."""
    keep = ~np.isin(hits.rays, rows)
    rays = np.concatenate([hits.rays[keep], rows[again.rays]])
    tris = np.concatenate([hits.tris[keep], again.tris])
    # a hit's depth: how many hits of its ray come before it (each ray's hits are in order)
    order = np.argsort(rays, kind="stable")
    starts = np.searchsorted(rays[order], rays[order])
    depth = np.empty(len(rays), np.int64)
    depth[order] = np.arange(len(rays)) - starts
    placed = np.lexsort((rays, depth))
    locations = hits.locations
    if locations is not None:
        locations = np.concatenate([locations[keep], again.locations])[placed]
    return rays[placed], tris[placed], locations


def surfaces_behind(scene: LocalScene, origins, directions, near):
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
    reach = np.float32(band / PARALLEL_COS)
    behind = scene.bvh.all_hits(Rays(local, backwards, 0.0, reach), _BEHIND_ROOM)
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


def _resolve_tnear(scene: LocalScene, magnitude: np.ndarray, tnear):
    """(near (n,) float64 world distance, inclusive): hits count at distance > near (>=
    when ``tnear`` is given, ``inclusive``); by default near is a few float32 ulps of
    ``magnitude`` (n,), each ray's largest local coordinate (its origin's or the mesh's)."""
    if tnear is None:
        return _TNEAR_ULPS * EPS32 * magnitude / scene.scale, False
    near = np.broadcast_to(np.asarray(tnear, dtype=np.float64), (len(magnitude),))
    if not np.isfinite(near).all() or (near < 0).any():
        raise ValueError("tnear: must be finite and >= 0")
    return near, True


class TracedRays(NamedTuple):
    """Rays as the stages read them, in tracing order: ``order`` (n,) int64 (row j is the
    caller's ray ``order[j]``) or None for the given order; ``world`` (``WorldRays``: origins,
    unit directions, magnitudes, near distances); ``local_origins``, ``local_directions``
    (n, 3) float32, Embree's rays; ``embree_near`` (n,) float32, the tnear Embree traces from
    (half the local near: which hits count at the origin is decided in float64)."""

    order: np.ndarray | None
    world: WorldRays
    local_origins: np.ndarray
    local_directions: np.ndarray
    embree_near: np.ndarray


def traced_rays(scene: LocalScene, query: HitQuery) -> TracedRays:
    """The rays of ``query`` (``HitQuery``: unit directions) in the local frame, in a coherent
    order with ``query.reorder`` on a big mesh (``scene.bounds``; the answers do not depend on
    it: each ray's hits are computed from its own row alone), with their near distances
    (``query.tnear``: see ``RayMeshIntersector.intersects_id``). A row Embree cannot trace is
    refused, named as the caller gave it (``query.as_given``: the directions before
    ``unitize``)."""
    n = len(query.origins)
    origins, directions, tnear = query.origins, query.directions, query.tnear
    order = None
    if query.reorder and scene.bounds is not None:
        ordered = ordered_local_rays(
            origins,
            directions,
            scene.origin,
            scene.scale,
            scene.extent,
            scene.bounds,
            scene.bvh.threads,
        )
        order, origins, directions = ordered.order, ordered.origins, ordered.directions
        local = ordered.local
        if tnear is not None and np.ndim(tnear):
            tnear = np.broadcast_to(np.asarray(tnear, np.float64), (n,))[order]
    else:
        local = local_rays(origins, directions, scene.origin, scene.scale, scene.extent)
    if not local.finite:
        written = query.directions if query.as_given is None else query.as_given
        refuse_rays(query.origins, written, scene.origin, scene.scale)
    near, inclusive = _resolve_tnear(scene, local.magnitude, tnear)
    return TracedRays(
        order,
        world_rays(origins, directions, local.magnitude, near, inclusive),
        local.origins,
        local.directions,
        (near * scene.scale * 0.5).astype(np.float32),
    )


class HitQuery(NamedTuple):
    """What ``RayMeshIntersector`` asks of the pipeline. ``origins``, ``directions`` (n, 3)
    float64 rays (unit directions, but for the first hit only: as given); ``tnear``: None, a
    scalar or (n,) (see ``RayMeshIntersector.intersects_id``); ``max_hits`` the nearest hits
    kept a ray, or None for the first hit only (its rays screened first); ``with_locations``:
    also the hit points; ``reorder``: trace big meshes' rays in a coherent order; ``room``:
    Embree hits recorded a ray (None: ``max_hits`` + 4); ``as_given``: the directions before
    ``unitize`` (n, 3), to name a bad row as the caller wrote it, or None."""

    origins: np.ndarray
    directions: np.ndarray
    tnear: float | np.ndarray | None
    max_hits: int | None
    with_locations: bool = False
    reorder: bool = False
    room: int | None = None
    as_given: np.ndarray | None = None


class FoundHits(NamedTuple):
    """The pipeline's answer in trimesh's order (every ray's first hit, rays ascending, then
    every ray's second, ...): ``rays``, ``tris`` (k,) int64 and, when asked, ``locations``
    (k, 3) float64 (else None). Each ray's hits by distance, then triangle, one hit per
    crossing of the surface (at an edge or a vertex, the lowest-index triangle there)."""

    rays: np.ndarray
    tris: np.ndarray
    locations: np.ndarray | None


def exact_hits(scene: LocalScene, query: HitQuery) -> FoundHits:
    """The hits ``query`` (a ``HitQuery``) asks for, stage after stage (module docstring):
    screen (the first hit only) -> settle -> decide -> finish.

    ``query.room`` hits are recorded a ray. Hits at one point become one crossing, so a ray
    whose recorded hits overflowed it and gave fewer than ``max_hits`` crossings (a ray
    through a vertex many triangles share) may have more: such rays are traced again with four
    times the room."""
    n = len(query.origins)
    if query.max_hits is None:
        # screen: Embree's nearest hits stand where clear of doubt; the suspect rays (under
        # 1% on the benchmark's meshes) take the stages below for their one nearest crossing
        first, suspect, near = _screen(scene, query)
        again = np.flatnonzero(suspect)
        if len(again):
            more = exact_hits(
                scene,
                HitQuery(
                    query.origins[again],
                    util.unitize(query.directions[again]),
                    None if near is None else near[again],
                    max_hits=1,
                ),
            )
            first[again] = -1
            first[again[more.rays]] = more.tris
        rays = np.flatnonzero(first >= 0)
        return FoundHits(rays, first[rays], None)
    capacity = max(1, int(query.max_hits))
    # room for hits the float64 rules drop (at the origin, along a face) and for edge pairs,
    # so that the nearest `capacity` survive
    room = capacity + 4 if query.room is None else query.room
    rays = traced_rays(scene, query)
    rules = tolerances(EDGE_BAND_SCALE, GRAZE_COS, PARALLEL_COS, tol.zero)
    hits = _HitList(scene, 2 * n)
    truncated = []  # positions of rays whose final trace had more hits than its room
    # Most rays hit a few triangles: trace with a little room first and again, with all of
    # it, only the rays that overflowed (so the hit arrays stay small).
    first_room = min(room, FIRST_ROOM)
    block = max(1, min(_BLOCK_RAYS, _BLOCK_HITS // first_room))
    pending = []
    for first in range(0, n, block):
        rows = slice(first, min(n, first + block))
        recorded = _trace(scene, rays, rows, first_room)
        # settle: rays clear of edges and grazing are final here; the others are messy
        messy = _settle(scene, rays, rows, recorded, room > first_room, rules, hits)
        # decide: messy rays whose hits all fit, from the buffers as traced (a second trace
        # with more room records the same hits in the same order); the others are traced
        # again first, below
        overflowed = recorded.more if room > first_room else np.zeros(len(messy), bool)
        if room <= first_room:
            truncated.append(first + np.flatnonzero(messy & recorded.more))
        complete = np.flatnonzero(messy & ~overflowed)
        hits.append(_decide(scene, rays, complete, first + complete, recorded, rules))
        pending.append(first + np.flatnonzero(messy & overflowed))
    pending = np.concatenate(pending) if pending else np.zeros(0, np.int64)
    block = max(1, min(_BLOCK_RAYS, _BLOCK_HITS // room))
    for first in range(0, len(pending), block):
        rows = pending[first : first + block]
        recorded = _trace(scene, rays, rows, room, keep=False)
        hits.append(_decide(scene, rays, np.arange(len(rows)), rows, recorded, rules))
        truncated.append(rows[recorded.more])
    parts = hits.arrays()
    if rays.world.inclusive:
        parts, more = _decide_surfaces_behind(scene, rays, room, rules, parts)
        truncated.append(more)
    # finish: one hit per crossing, each ray cut to its nearest `capacity`, in trimesh's order
    finished = _finish(scene, rays, parts, capacity, query)
    truncated = np.concatenate(truncated) if truncated else np.zeros(0, np.int64)
    if rays.order is not None:
        truncated = rays.order[truncated]
    short = truncated[np.bincount(finished.rays, minlength=n)[truncated] < capacity]
    if not len(short):
        return finished
    tnear = query.tnear
    if tnear is not None and np.ndim(tnear):
        tnear = np.broadcast_to(tnear, (n,))[short]
    again = exact_hits(
        scene,
        HitQuery(
            query.origins[short],
            query.directions[short],
            tnear,
            capacity,
            with_locations=query.with_locations,
            room=4 * room,
        ),
    )
    return FoundHits(*_spliced(finished, short, again))


def _screen(scene: LocalScene, query: HitQuery) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Stage screen: (n,) int64 the nearest triangle each ray of ``query`` hits as Embree
    finds it (-1: none), (n,) bool which of those are suspect (near an edge, grazing, at the
    origin, or starting on a surface behind it: ``surfaces_behind``), and the rays' near
    distances (n,) float64 (None: the default, a few float32 ulps)."""
    origins, directions = query.origins, query.directions
    near = None
    if query.tnear is not None:
        near = np.broadcast_to(np.asarray(query.tnear, dtype=np.float64), (len(origins),))
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
        graze=GRAZE_COS,
        near_factor=4.0,
    )
    if near is not None:
        suspect[surfaces_behind(scene, origins, directions, near)[0]] = True
    return prim.astype(np.int64), suspect, near


def _trace(
    scene: LocalScene, rays: TracedRays, rows: slice | np.ndarray, room: int, keep: bool = True
) -> HitBuffers:
    """Every hit Embree's filter records along rays ``rows`` (a slice, or (k,) int64), up to
    ``room`` a ray
    (``multihit.all_hits``), in buffers kept by the scene from query to query with ``keep``."""
    buffers = scene.hit_buffers(room) if keep else None
    recorded = scene.bvh.all_hits(
        Rays(rays.local_origins[rows], rays.local_directions[rows], rays.embree_near[rows], np.inf),
        room,
        out=buffers,
    )
    if keep:
        scene.keep_hit_buffers(room, recorded)
    return recorded


def _settle(
    scene: LocalScene,
    rays: TracedRays,
    rows: slice,
    recorded: HitBuffers,
    retrace_more: bool,
    rules: Tolerances,
    hits: _HitList,
) -> np.ndarray:
    """Stage settle: the final hits of the rays ``rows`` (a slice) clear of edges and
    grazing, from their ``recorded`` hits, into ``hits``; returns (k,) bool which are messy
    (with ``retrace_more``, those that overflowed too)."""
    count = int(recorded.count.sum())
    world = rays.world
    settled_rays, _, _, messy = settled_hits(
        recorded,
        retrace_more,
        world_rays(
            world.origins[rows],
            world.directions[rows],
            world.magnitude[rows],
            world.near[rows],
            world.inclusive,
        ),
        scene.tables,
        rules,
        scene.bvh.threads,
        tuple(
            scene.scratch(f"settle_{k}", count, dtype)
            for k, dtype in enumerate((np.int64, np.int64, np.float64))
        ),
        hits.room(count),
        rows.start,
    )
    hits.filled(len(settled_rays))
    return messy


def _decide(
    scene: LocalScene,
    rays: TracedRays,
    rows: np.ndarray,
    positions: np.ndarray,
    recorded: HitBuffers,
    rules: Tolerances,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage decide: the hits of the rays in rows ``rows`` of ``recorded`` (rays
    ``positions``) near an edge, a vertex or along a face decided in float64 as ray_triangle
    decides them, against all the triangles around them (``decided_hits``)."""
    if not len(rows):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return decided_hits(
        rows,
        positions,
        recorded,
        rays.world,
        scene.tables,
        rules,
        scene.fans(),
        scene.bvh.threads,
    )


def _decide_surfaces_behind(
    scene: LocalScene,
    rays: TracedRays,
    room: int,
    rules: Tolerances,
    parts: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """Stage decide, for rays starting on a surface Embree's forward trace may have missed:
    their hits in ``parts`` (rays, tris, distance) replaced by a float64 decision that also
    tests the triangles just behind their origins (``surfaces_behind``). Returns the parts and
    the rays (positions) whose trace overflowed ``room``."""
    world = rays.world
    surface_rows, behind = surfaces_behind(scene, world.origins, world.directions, world.near)
    if not len(surface_rows):
        return parts, np.zeros(0, np.int64)
    forward = _trace(scene, rays, surface_rows, room, keep=False)
    again = _decide(
        scene,
        rays,
        np.arange(len(surface_rows)),
        surface_rows,
        _with_surfaces_behind(forward, behind),
        rules,
    )
    keep = ~np.isin(parts[0], surface_rows)
    parts = tuple(np.concatenate([part[keep], new]) for part, new in zip(parts, again, strict=True))
    return parts, surface_rows[forward.more]


def _finish(
    scene: LocalScene,
    rays: TracedRays,
    parts: tuple[np.ndarray, np.ndarray, np.ndarray],
    capacity: int,
    query: HitQuery,
) -> FoundHits:
    """Stage finish: ``finished_hits`` of the hits ``parts`` (rays, tris, distance) of the
    rays of ``query``, as the caller gave them."""
    found_rays, found_tris, distance = parts
    return FoundHits(
        *finished_hits(
            rays=found_rays,
            tris=found_tris,
            distance=distance,
            order=rays.order,
            ray_count=len(query.origins),
            capacity=capacity,
            canonical=scene.fans().canonical,
            planes=scene.planes,
            size=scene.extent / scene.scale,
            parallel_cos=PARALLEL_COS,
            origins=query.origins,
            directions=query.directions,
            with_locations=query.with_locations,
            scratch=scene.scratch,
            threads=scene.bvh.threads,
        )
    )
