"""The nearest hit over bricks, and the tie rule.

Each brick answers a ray with its own nearest hit; the ray's hit is the nearest of those and of
the floor. The rule, applied per ray:

1. the smallest t wins;
2. between bricks whose hits have exactly the same t (float32), the object with the lower
   global object id wins (``Scene.object_id_starts``: spheres in scene order, then mesh
   placements, then instance copies); within one brick Embree's traversal decides, as it does
   in the whole scene's BVH;
3. the floor wins only when strictly nearer than every object (the hit records' rule: an
   object exactly at the floor's t is taken).

Ties of rule 2 are where the picture may differ from one BVH's, whose traversal order picks
among exactly equal hits; they are counted. The columns come out as one BVH's hit records lay
them out (floor, then the sphere set, then other objects, each in ray order), so shading sums
every pixel's contributions in the same order and the image is bitwise the local one.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from embree_rt.bricks.brick import OTHER_GROUP, SPHERE_GROUP, BrickHits
from embree_rt.geometry import SurfaceHits
from embree_rt.mesh_attributes import HitLooks

NO_OBJECT = np.iinfo(np.int64).max
# Fields of SurfaceHits that are not one column per hit.
_NOT_COLUMNS = {"flat", "floor_count", "looks", "painted", "paint"}


def nearest_over_bricks(
    count: int,
    floor: tuple[np.ndarray, SurfaceHits],
    answers: list[tuple[np.ndarray, BrickHits]],
) -> tuple[np.ndarray, SurfaceHits, int]:
    """The nearest hit of each of ``count`` rays: ``floor`` the (k,) int64 rays that meet the
    floor and their floor-only ``SurfaceHits``; ``answers`` per brick asked, the (j,) int64 rays
    sent to it and its ``BrickHits`` (whose ``rows`` index those). Returns the (m,) int64 rays
    that hit something, their ``SurfaceHits`` (floor first, then the sphere set, then other
    objects, each in ray order; ``incoming`` None, as the bricks send it: the caller has the
    rays) and the number of exact ties between bricks (rule 2)."""
    best_t = np.full(count, np.inf, np.float32)
    best_id = np.full(count, NO_OBJECT, np.int64)
    source = np.full(count, -1, np.int64)  # which answer (len(answers): the floor)
    column = np.zeros(count, np.int64)
    group = np.zeros(count, np.int8)
    ties = 0
    for index, (sent, hits) in enumerate(answers):
        rays = sent[hits.rows]
        t = hits.surfaces.t
        current = best_t[rays]
        tie = t == current
        ties += int(np.count_nonzero(tie))
        better = np.flatnonzero((t < current) | (tie & (hits.object_id < best_id[rays])))
        won = rays[better]
        best_t[won] = t[better]
        best_id[won] = hits.object_id[better]
        source[won] = index
        column[won] = better
        group[won] = hits.group[better]
    floor_rays, floor_hits = floor
    nearer = np.flatnonzero(floor_hits.t < best_t[floor_rays])
    won = floor_rays[nearer]
    source[won] = len(answers)
    column[won] = nearer
    group[won] = 0
    hit = source >= 0
    rays = np.concatenate(
        [np.flatnonzero(hit & (group == g)) for g in (0, SPHERE_GROUP, OTHER_GROUP)]
    )
    parts = [hits.surfaces for _, hits in answers] + [floor_hits]
    surfaces = gather_surfaces(parts, source[rays], column[rays], len(won))
    return rays, surfaces, ties


def gather_surfaces(
    parts: list[SurfaceHits], source: np.ndarray, column: np.ndarray, floor_count: int
) -> SurfaceHits:
    """One ``SurfaceHits`` whose column j is column ``column[j]`` of ``parts[source[j]]``
    ((m,) int64 each), its first ``floor_count`` columns floor hits. Every per-hit field is
    gathered (whatever fields ``SurfaceHits`` has), in the widest of the parts' dtypes; a field
    some part lacks (None) is None. Of the parts' looks, their colours are kept."""
    picks = [np.flatnonzero(source == index) for index in range(len(parts))]
    m = len(source)
    values = {}
    for field in dataclasses.fields(SurfaceHits):
        name = field.name
        if name in _NOT_COLUMNS:
            continue
        arrays = [getattr(part, name) for part in parts]
        if any(array is None for array in arrays):
            values[name] = None
            continue
        first = arrays[0]
        # (a brick's int32 material ids, the floor's intp: the wider type holds both)
        out = np.empty((*first.shape[:-1], m), np.result_type(*arrays))
        for array, pick in zip(arrays, picks, strict=True):
            if len(pick):
                out[..., pick] = np.take(array, column[pick], axis=-1)
        values[name] = out
    flat = all(part.flat for part, pick in zip(parts, picks, strict=True) if len(pick))
    if flat:
        values["face_normal"] = values["normal"]
    colored, color = _gathered_rows(
        parts, picks, column, lambda part: (part.looks.rows, part.looks.color)
    )
    painted, paint = _gathered_rows(parts, picks, column, lambda part: (part.painted, part.paint))
    values.update(painted=painted, paint=paint)
    looks = HitLooks(colored, color)
    return SurfaceHits(**values, flat=flat, floor_count=floor_count, looks=looks)


def _gathered_rows(parts, picks, column, rows_of) -> tuple[np.ndarray, np.ndarray]:
    """The (j,) int64 gathered columns and (3, j) float32 values of a per-row field of the
    ``parts`` (``rows_of(part)``: its rows and their (3, r) values), for the columns that
    ``picks``/``column`` take from each part (as ``gather_surfaces``)."""
    rows, values = [], []
    for part, pick in zip(parts, picks, strict=True):
        part_rows, part_values = rows_of(part)
        if not len(part_rows) or not len(pick):
            continue
        place = np.full(len(part.t), -1, np.int64)
        place[column[pick]] = pick
        kept = place[part_rows] >= 0
        rows.append(place[part_rows][kept])
        values.append(part_values[:, kept])
    return (
        np.concatenate(rows) if rows else np.zeros(0, np.int64),
        np.concatenate(values, axis=1) if values else np.zeros((3, 0), np.float32),
    )
