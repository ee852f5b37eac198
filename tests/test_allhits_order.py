"""The all-hits query's coherent tracing order and its parallel passes change no answer: rays
traced sorted (embree_rt.trimesh_ray.local_frame, its segment_key) against rays traced as
given, the settling, float64 and finishing passes on one thread against two, and the keys
against their definition."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from numba import njit
from trimesh.constants import tol

from embree_rt.embree import Rays
from embree_rt.trimesh_ray import RayMeshIntersector, exact_hits, local_frame
from embree_rt.trimesh_ray.hit_passes import (
    decided_hits,
    finished_hits,
    settled_hits,
    tolerances,
    world_rays,
)
from embree_rt.trimesh_ray.local_frame import box_cells, local_rays, ordered_local_rays, segment_key


@njit(cache=False)
def _keys(origins, directions, lower, upper, cells):
    keys = np.empty(origins.shape[0], np.uint32)
    for i in range(origins.shape[0]):
        keys[i] = segment_key(origins[i], directions[i], lower, upper, cells)
    return keys


def _spread(cell: int) -> int:
    return sum(((cell >> b) & 1) << (3 * b) for b in range(10))


def test_segment_keys_follow_the_middle_of_each_rays_path_through_the_box():
    lower, upper = np.zeros(3), np.array([2.0, 1.0, 1.0])
    cells = box_cells(lower, upper)
    origins = np.array(
        [[-1.0, 0.5, 0.5], [1.0, 0.5, 0.5], [1.0, -3.0, 0.25], [5.0, 5.0, 5.0], [0.5, 0.5, 0.5]]
    )
    directions = np.array(
        [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    )
    keys = _keys(origins, directions, lower, upper, cells).tolist()

    def key(x, y, z):
        return _spread(int(x)) | _spread(int(y)) << 1 | _spread(int(z)) << 2

    # through the box along x: its middle (1, .5, .5); from inside at x = 1: (1.5, .5, .5);
    # up through y: (1, .5, .25); missing: the origin clamped; no direction: the origin
    assert keys[0] == key(1023 / 2, 1023 / 2, 1023 / 2)
    assert keys[1] == key(1.5 * 1023 / 2, 1023 / 2, 1023 / 2)
    assert keys[2] == key(1023 / 2, 1023 / 2, 0.25 * 1023)
    assert keys[3] == key(1023, 1023, 1023)
    assert keys[4] == key(0.5 * 1023 / 2, 1023 / 2, 1023 / 2)


def test_ordered_local_rays_are_local_rays_moved_to_their_order():
    """Bitwise: each output row is the same arithmetic on the same input row, only moved."""
    rng = np.random.default_rng(4)
    origins = rng.normal(size=(5000, 3)) * 50 + 7
    directions = trimesh.util.unitize(rng.normal(size=(5000, 3)))
    shift, scale, extent = np.array([1.0, -2.0, 3.0]), 0.37, 80.0
    bounds = np.array([[-20.0, -20, -20], [30.0, 30, 30]])
    order, ordered_origins, ordered_directions, local = ordered_local_rays(
        origins, directions, shift, scale, extent, bounds, 2
    )
    assert local.finite
    assert sorted(order.tolist()) == list(range(5000))
    cells = box_cells(bounds[0], bounds[1])
    keys = _keys(origins, directions, bounds[0], bounds[1], cells)
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))
    np.testing.assert_array_equal(ordered_origins, origins[order])
    np.testing.assert_array_equal(ordered_directions, directions[order])
    for ordered, given in zip(
        local[:3], local_rays(origins, directions, shift, scale, extent)[:3], strict=True
    ):
        np.testing.assert_array_equal(ordered, given[order])


def _hard_rays(mesh: trimesh.Trimesh, scale: float, n_random: int, seed: int):
    """Rays at vertices and edge midpoints (decided in float64), and at random points."""
    rng = np.random.default_rng(seed)
    targets = np.vstack(
        [
            mesh.vertices[:300],
            mesh.vertices[mesh.edges_unique[:300]].mean(1),
            rng.uniform(-scale, scale, (n_random, 3)),
        ]
    )
    start = rng.normal(size=(len(targets), 3))
    origins = 3 * scale * start / np.linalg.norm(start, axis=1)[:, None]
    return origins, targets - origins


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e8])
def test_all_hits_in_the_traced_order_equal_those_in_the_given_order(scale, monkeypatch):
    """Bitwise: sorted or not, each ray is one rtcIntersect1 call with the recording filter on
    the same float32 fields against the same committed BVH, and every later step of ray i reads
    only its own row and the mesh, so the same arithmetic runs on the same bits on whatever ISA
    this is (both runs are on it)."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.apply_scale(scale)
    # a second shell inside: more hits a ray than the first trace has room for on some rays
    inner = trimesh.creation.icosphere(subdivisions=3)
    inner.apply_scale(0.5 * scale)
    mesh = trimesh.util.concatenate([mesh, inner])
    origins, directions = _hard_rays(mesh, scale, 1400, seed=11)
    monkeypatch.setattr(local_frame, "REORDER_FACES", 0)
    ordered = RayMeshIntersector(mesh)
    assert ordered._scene.bounds is not None  # built now (lazily), while every mesh is big
    monkeypatch.setattr(local_frame, "REORDER_FACES", 1 << 40)
    given = RayMeshIntersector(mesh)
    assert given._scene.bounds is None
    monkeypatch.setattr(exact_hits, "FIRST_ROOM", 2)  # overflowing rays traced again
    for kwargs in ({}, {"max_hits": 3}, {"tnear": 0.0}, {"return_locations": True}):
        a = ordered.intersects_id(origins, directions, **kwargs)
        b = given.intersects_id(origins, directions, **kwargs)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    assert len(a[1]) > 2 * len(origins)


def test_non_finite_rays_traced_in_order_are_refused_naming_their_row(monkeypatch):
    """The row as given, not its place in the tracing order (which sorts a NaN ray first)."""
    monkeypatch.setattr(local_frame, "REORDER_FACES", 0)
    ours = RayMeshIntersector(trimesh.creation.icosphere(subdivisions=2))
    origins = np.tile([0.0, 0.0, -5.0], (3000, 1))
    directions = np.tile([0.0, 0.0, 1.0], (3000, 1))
    origins[1234, 1] = np.nan
    with pytest.raises(ValueError, match="origins: row 1234 is not finite"):
        ours.intersects_location(origins, directions)
    origins[1234, 1] = 0.0
    directions[2345, 2] = np.inf
    with pytest.raises(ValueError, match="directions: row 2345 is not finite"):
        ours.intersects_id(origins, directions)


def test_settled_decided_and_finished_hits_are_the_same_on_one_thread_and_two():
    """Bitwise: each chunk of rays writes its own range, the ranges are placed by a prefix sum
    of their counts, and a hit's arithmetic reads only its ray and triangle."""
    mesh = trimesh.creation.icosphere(subdivisions=5)
    ours = RayMeshIntersector(mesh)
    scene = ours._scene
    origins, directions = _hard_rays(mesh, 1.0, 6000, seed=3)
    directions = trimesh.util.unitize(directions)
    local_origins, local_directions, magnitude, _finite = local_rays(
        origins, directions, scene.origin, scene.scale, scene.extent
    )
    near = 16 * np.finfo(np.float32).eps * magnitude / scene.scale
    result = scene.bvh.all_hits(
        Rays(
            local_origins, local_directions, (near * scene.scale * 0.5).astype(np.float32), np.inf
        ),
        4,
    )
    rays = world_rays(origins, directions, magnitude, near, False)
    rules = tolerances(8 * np.finfo(np.float32).eps, 1e-3, 1e-5, tol.zero)
    answers = [settled_hits(result, True, rays, scene.tables, rules, threads) for threads in (1, 2)]
    assert answers[0][3].sum() > 100  # messy rays (left to the float64 pass) in the batch
    assert len(answers[0][0]) > len(origins)
    for x, y in zip(*answers, strict=True):
        np.testing.assert_array_equal(x, y)
    messy = np.flatnonzero(answers[0][3])
    decided = [
        decided_hits(messy, messy, result, rays, scene.tables, rules, scene.fans(), threads)
        for threads in (1, 2)
    ]
    assert len(decided[0][0]) > len(messy)
    for x, y in zip(*decided, strict=True):
        np.testing.assert_array_equal(x, y)
    parts = [np.concatenate(arrays) for arrays in zip(answers[0][:3], decided[0], strict=True)]
    order = np.random.default_rng(5).permutation(len(origins))  # as if traced in that order
    finished = [
        finished_hits(
            *parts,
            order,
            len(origins),
            3,
            scene.fans()[0],
            scene.planes,
            1.0,
            1e-5,
            origins,
            directions,
            True,
            None,
            threads,
        )
        for threads in (1, 2)
    ]
    assert len(finished[0][0]) > len(origins)
    for x, y in zip(*finished, strict=True):
        np.testing.assert_array_equal(x, y)


def test_a_query_does_not_overwrite_the_answers_of_the_one_before():
    """The scene keeps and reuses its working buffers from query to query: what a query returned
    must be the caller's, not a view of them (a second query, bigger and in another order,
    would otherwise rewrite it)."""
    mesh = trimesh.creation.icosphere(subdivisions=6)  # 81,920 faces: the ordered path
    ours = RayMeshIntersector(mesh)
    rng = np.random.default_rng(7)
    origins = rng.normal(size=(3000, 3)) * 3
    directions = rng.uniform(-0.5, 0.5, (3000, 3)) - origins  # toward the middle: two hits
    answers = {
        "location": ours.intersects_location(origins, directions),
        "id": ours.intersects_id(origins, directions, return_locations=True),
        "first": (ours.intersects_first(origins, directions),),
    }
    kept = {name: [np.copy(part) for part in parts] for name, parts in answers.items()}
    more_origins = np.vstack([origins[::-1], origins]) * 1.5
    more_directions = np.vstack([directions[::-1], directions])
    ours.intersects_location(more_origins, more_directions)
    ours.intersects_id(more_origins, more_directions, return_locations=True)
    ours.intersects_first(more_origins, more_directions)
    assert len(kept["location"][0]) > 1.5 * len(origins)
    for name, parts in answers.items():
        for part, copy in zip(parts, kept[name], strict=True):
            np.testing.assert_array_equal(part, copy, err_msg=name)
