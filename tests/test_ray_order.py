"""Rays traced in a coherent order (embree_rt.trimesh_ray.local_frame.entry_key) get the answers
they get in the order given: the radix sort (embree_rt.compiled.morton) against NumPy's stable
argsort, and first hits traced sorted against first hits traced as given, on meshes where many
hits are suspect (edges, grazing)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from numba import njit

from embree_rt.compiled.morton import radix_order
from embree_rt.trimesh_ray import RayMeshIntersector, local_frame
from embree_rt.trimesh_ray.hit_passes import screened_nearest
from embree_rt.trimesh_ray.local_frame import box_cells, entry_key


@njit(cache=False)
def _keys(origins, directions, lower, upper, cells):
    keys = np.empty(origins.shape[0], np.uint32)
    for i in range(origins.shape[0]):
        keys[i] = entry_key(origins[i], directions[i], lower, upper, cells)
    return keys


def test_radix_order_is_numpys_stable_argsort():
    rng = np.random.default_rng(3)
    for n in (0, 1, 7, 5000):
        # few distinct values: many ties, whose order a stable sort keeps
        keys = rng.integers(0, 2**30, n, dtype=np.uint32) & np.uint32(0x3F00_F00F)
        np.testing.assert_array_equal(radix_order(keys), np.argsort(keys, kind="stable"))


def test_entry_keys_follow_where_rays_enter_the_box():
    lower, upper = np.zeros(3), np.array([2.0, 1.0, 0.0])  # flat along z
    cells = box_cells(lower, upper)
    assert cells.tolist() == [1023 / 2, 1023.0, 0.0]
    origins = np.array(
        [[-1.0, 0.0, 0.0], [-1.0, 1.0, 0.0], [1.0, 0.5, 0.0], [5.0, 5.0, 5.0], [np.nan, 0.0, 0.0]]
    )
    directions = np.array(
        [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    )
    keys = _keys(origins, directions, lower, upper, cells)
    # entering at (0, 0, 0) and (0, 1, 0): y's top cell spread to every third bit from bit 1;
    # starting inside at (1, 0.5): its own cell; missing: its origin clamped to (2, 1, 0)
    spread = sum(1 << (3 * b) for b in range(10))
    assert keys[0] == 0
    assert keys[1] == spread << 1
    x, y = int(1.0 * 1023 / 2), int(0.5 * 1023)
    assert keys[2] == sum(
        ((x >> b) & 1) << (3 * b) | ((y >> b) & 1) << (3 * b + 1) for b in range(10)
    )
    assert keys[3] == spread | spread << 1
    assert keys[4] <= 0x3FFF_FFFF  # a non-finite ray gets some key, and the caller refuses it


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e8])
def test_first_hits_in_the_traced_order_equal_those_in_the_given_order(scale, monkeypatch):
    """Bitwise: sorted or not, each ray is one rtcIntersect1 call on the same float32 fields
    against the same committed BVH, and its frame change and screening read only its own row,
    so the same arithmetic runs on the same bits on whatever ISA this is (both runs are on it)."""
    mesh = trimesh.creation.icosphere(subdivisions=4)
    mesh.apply_scale(scale)
    rng = np.random.default_rng(11)
    # half the rays aimed at vertices and edge midpoints (suspect hits, decided in float64),
    # half at random points
    targets = np.vstack(
        [
            mesh.vertices[:300],
            mesh.vertices[mesh.edges_unique[:300]].mean(1),
            rng.uniform(-scale, scale, (600, 3)),
        ]
    )
    start = rng.normal(size=(len(targets), 3))
    origins = 3 * scale * start / np.linalg.norm(start, axis=1)[:, None]
    directions = targets - origins
    monkeypatch.setattr(local_frame, "REORDER_FACES", 0)
    sorted_first = RayMeshIntersector(mesh)
    scene = sorted_first._scene  # built now (lazily), while every mesh counts as big
    monkeypatch.setattr(local_frame, "REORDER_FACES", 1 << 40)
    given_first = RayMeshIntersector(mesh)
    assert scene.bounds is not None and given_first._scene.bounds is None
    screen = dict(
        shift=scene.origin,
        scale=scene.scale,
        extent=scene.extent,
        near=None,
        near_ulps=16.0,
        altitude=scene.min_altitude,
        floor_altitude=scene.floor_altitude,
        band_ulps=8.0,
        graze=1e-3,
        near_factor=4.0,
    )
    prim_sorted, suspect_sorted = screened_nearest(
        scene.bvh, origins, directions, bounds=scene.bounds, **screen
    )
    prim_given, suspect_given = screened_nearest(
        scene.bvh, origins, directions, bounds=None, **screen
    )
    assert suspect_given.sum() > 50  # the float64 path is exercised
    np.testing.assert_array_equal(prim_sorted, prim_given)
    np.testing.assert_array_equal(suspect_sorted, suspect_given)
    np.testing.assert_array_equal(
        sorted_first.intersects_first(origins, directions),
        given_first.intersects_first(origins, directions),
    )
