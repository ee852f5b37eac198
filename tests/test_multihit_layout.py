"""The argument filter's view of Embree 4.4's structs (multihit's docstring), proved through what
it records: if RTCIntersectArguments' flags, context or filter offsets were wrong the filter
would never run (no hits recorded); wrong RTCRayN/RTCHitN words would give wrong distances,
primitives, barycentrics or cosines, each checked against float64 brute force here."""

from __future__ import annotations

import numpy as np
import pytest

from embree_rt.embree import BVH, Rays


def _two_triangles():
    vertices = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 0, 2], [4, 0, 2], [0, 4, 2.0]])
    faces = np.array([[0, 1, 2], [3, 5, 4]])
    return vertices.astype(np.float32), faces


def test_filter_records_every_hit_with_embree_fields():
    vertices, faces = _two_triangles()
    bvh = BVH(robust=True, filters=True)
    bvh.add_triangles(vertices, faces)
    bvh.commit()
    origins = np.array([[1.0, 0.5, -1], [0.5, 2.0, 5], [3.0, 3.0, -1]], np.float32)
    directions = np.array([[0.1, 0.2, 1.0], [0.0, -0.1, -1.0], [0, 0, 1.0]], np.float32)
    t, prim, u, v, cos, count, more = bvh.all_hits(Rays(origins, directions), capacity=4)
    assert count.tolist() == [2, 2, 0] and not more.any()
    for i in range(2):
        d = directions[i].astype(np.float64)
        z = np.array([0.0, 2.0])
        expected_t = (z - origins[i, 2]) / d[2]
        order = np.argsort(expected_t)
        np.testing.assert_allclose(t[i, :2], expected_t[order], rtol=1e-6)
        assert prim[i, :2].tolist() == order.tolist()
        for k in range(2):
            point = origins[i] + t[i, k] * d
            a, b, c = vertices[faces[prim[i, k]]].astype(np.float64)
            weights = np.linalg.lstsq(np.stack([b - a, c - a], axis=1), point - a, rcond=None)[0]
            np.testing.assert_allclose([u[i, k], v[i, k]], weights, atol=1e-5)
            np.testing.assert_allclose(cos[i, k], abs(d[2]) / np.linalg.norm(d), rtol=1e-5)


def test_capacity_keeps_the_nearest_and_says_more_exist():
    vertices = np.vstack([_two_triangles()[0][:3] + np.float32([0, 0, z]) for z in range(6)])
    faces = np.array([[0, 1, 2]]) + 3 * np.arange(6)[:, None]
    bvh = BVH(filters=True)
    bvh.add_triangles(vertices, faces)
    bvh.commit()
    origins = np.array([[1.0, 1.0, 10.0], [1.0, 1.0, -1.0]], np.float32)
    directions = np.array([[0, 0, -1.0], [0, 0, 1.0]], np.float32)
    t, prim, *_, count, more = bvh.all_hits(Rays(origins, directions), capacity=3)
    assert count.tolist() == [3, 3] and more.tolist() == [True, True]
    assert prim[0].tolist() == [5, 4, 3] and prim[1].tolist() == [0, 1, 2]
    np.testing.assert_allclose(t[1], [1, 2, 3])
    # tnear and tfar bound the hits as Embree's own queries do
    *_, count, _ = bvh.all_hits(Rays(origins[1:], directions[1:], tnear=1.5, tfar=4.5), capacity=8)
    assert count.tolist() == [3]


def test_filters_must_be_asked_for():
    vertices, faces = _two_triangles()
    bvh = BVH()
    bvh.add_triangles(vertices, faces)
    bvh.commit()
    with pytest.raises(RuntimeError, match="filters=True"):
        bvh.all_hits(Rays(np.zeros((1, 3)), np.ones((1, 3))))
