"""The packet kernels (4, 8, 16 lanes) answer what the single-ray kernels answer."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from embree_rt.embree import BVH
from embree_rt.embree.bvh import SPHERE_KINDS


def _scene(kind: str) -> BVH:
    rng = np.random.default_rng(3)
    bvh = BVH()
    bvh.add_spheres(rng.uniform(-5, 5, (300, 3)), rng.uniform(0.1, 0.6, 300), kind=kind)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    bvh.add_triangles(mesh.vertices * 1.5 + [0, 6, 0], mesh.faces)
    bvh.commit()
    return bvh


@pytest.mark.parametrize("kind", SPHERE_KINDS)
@pytest.mark.parametrize("lanes", [4, 8, 16])
def test_packet_and_single_ray_queries_agree(lanes: int, kind: str) -> None:
    rng = np.random.default_rng(4)
    n = 4099  # not a multiple of 8 or of the chunk size: the last packet is partly idle
    origins = rng.uniform(-7, 7, (n, 3))
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    tfar = rng.uniform(1, 12, n)
    with _scene(kind) as bvh:
        bvh.lanes = lanes
        packet_hits = bvh.intersect(origins, directions, 0.0, tfar)
        packet_blocked = bvh.occluded(origins, directions, 0.0, tfar)
        bvh.lanes = 1
        single_hits = bvh.intersect(origins, directions, 0.0, tfar)
        single_blocked = bvh.occluded(origins, directions, 0.0, tfar)
    assert 0.1 < single_hits.hit.mean() < 0.9  # both hits and misses are exercised
    np.testing.assert_array_equal(packet_hits.geom_id, single_hits.geom_id)
    np.testing.assert_array_equal(packet_hits.prim_id, single_hits.prim_id)
    np.testing.assert_allclose(packet_hits.t, single_hits.t, rtol=1e-5)
    np.testing.assert_allclose(packet_hits.normal, single_hits.normal, rtol=1e-4, atol=1e-5)
    np.testing.assert_array_equal(packet_blocked, single_blocked)
    np.testing.assert_array_equal(single_blocked, single_hits.hit)
