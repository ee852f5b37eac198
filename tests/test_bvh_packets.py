"""The packet kernels (4, 8, 16 lanes) answer what the single-ray kernels answer: the same
object on every ray that float32 can decide, the same distance and normal to float32 rounding."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from bvh_reference import float32_exact, near_triangle_edge, sphere_hits, triangle_hits
from tolerances import assert_close, assert_vectors_close, coordinate_scale, ray_t_atol

from embree_rt.embree import BVH, Rays
from embree_rt.embree.bvh import SPHERE_KINDS

RNG = np.random.default_rng(3)
CENTERS = float32_exact(RNG.uniform(-5, 5, (300, 3)))
RADII = float32_exact(RNG.uniform(0.1, 0.6, 300))
_ICO = trimesh.creation.icosphere(subdivisions=2)
VERTICES = float32_exact(_ICO.vertices * 1.5 + [0, 6, 0])
FACES = _ICO.faces


def _scene(kind: str) -> tuple[BVH, int]:
    """The committed BVH and the geometry id of its mesh."""
    bvh = BVH()
    bvh.add_spheres(CENTERS, RADII, kind=kind)
    mesh_gid = bvh.add_triangles(VERTICES, FACES)
    bvh.commit()
    return bvh, mesh_gid


def _rays(pattern: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """origins, unit directions (n, 3) and tfar (n,), float32: "random" rays from anywhere in
    the scene, or "camera" rays from one eye through a grid, in rows (coherent packets)."""
    n = 4099  # not a multiple of 8 or of the chunk size: the last packet is partly idle
    rng = np.random.default_rng(4)
    if pattern == "random":
        origins = rng.uniform(-7, 7, (n, 3))
        directions = rng.normal(size=(n, 3))
        tfar = rng.uniform(1, 12, n)
    else:
        pixel = np.arange(n)
        x, y = pixel % 64 / 64 - 0.5, pixel // 64 / 64 - 0.5
        origins = np.broadcast_to([0.0, 2.0, -16.0], (n, 3))
        directions = np.stack([x, y - 0.05, np.ones(n)], axis=1)
        tfar = np.full(n, 40.0)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    return float32_exact(origins), float32_exact(directions), float32_exact(tfar)


@pytest.mark.parametrize("kind", SPHERE_KINDS)
@pytest.mark.parametrize("lanes", [4, 8, 16])
@pytest.mark.parametrize(
    ("pattern", "coherent"), [("random", False), ("random", True), ("camera", True)]
)
def test_packet_and_single_ray_queries_agree(
    lanes: int, kind: str, pattern: str, coherent: bool
) -> None:
    # Embree's coherent query takes another traversal (a frustum per packet): it must find
    # what the plain one finds, also when the rays are not coherent at all.
    origins, directions, tfar = _rays(pattern)
    n = len(origins)
    bvh, mesh_gid = _scene(kind)
    with bvh:
        bvh.lanes = lanes
        packet_hits = bvh.intersect(Rays(origins, directions, 0.0, tfar), coherent=coherent)
        packet_blocked = bvh.occluded(Rays(origins, directions, 0.0, tfar), coherent=coherent)
        bvh.lanes = 1
        single_hits = bvh.intersect(Rays(origins, directions, 0.0, tfar))
        single_blocked = bvh.occluded(Rays(origins, directions, 0.0, tfar))
    assert 0.1 < single_hits.hit.mean() < 0.9  # both hits and misses are exercised

    # The two paths run different Embree code, which rounds differently again on each ISA: a
    # ray that grazes a sphere, meets a triangle edge, ends at tfar right on a surface or
    # meets two surfaces at the same distance may go either way. The float64 references say
    # which rays those are; every other ray must get the same answer.
    spheres = sphere_hits(origins, directions, CENTERS, RADII, 0.0, tfar)
    mesh = triangle_hits(origins, directions, VERTICES, FACES, 0.0, tfar)
    both = spheres.hit & mesh.hit
    tie = np.zeros(n, bool)
    tie[both] = np.abs(spheres.t[both] - mesh.t[both]) <= spheres.t_atol[both] + mesh.t_atol[both]
    on_edge = np.zeros(n, bool)
    for hits in (packet_hits, single_hits):
        on_edge |= hits.hit & (hits.geom_id == mesh_gid) & near_triangle_edge(hits.u, hits.v)
    sure = ~(spheres.ambiguous | mesh.ambiguous | tie | on_edge)
    assert sure.mean() > 0.99
    for name in ("geom_id", "prim_id"):
        np.testing.assert_array_equal(
            getattr(packet_hits, name)[sure], getattr(single_hits, name)[sure]
        )
    np.testing.assert_array_equal(packet_blocked[sure], single_blocked[sure])
    np.testing.assert_array_equal(single_blocked[sure], single_hits.hit[sure])

    # They agree to float32 rounding of the coordinates, not of t itself (t can be 1e-3 on a ray
    # starting 7 units out), over the cosine the ray meets the surface at.
    hit = sure & single_hits.hit
    extent = coordinate_scale(np.abs(CENTERS) + RADII[:, None], VERTICES)
    atol = ray_t_atol(origins, directions, extent, normals=single_hits.normal)
    assert_close(packet_hits.t[hit], single_hits.t[hit], atol=atol[hit], err_msg="t")
    assert np.isinf(packet_hits.t[sure & ~single_hits.hit]).all()
    # A sphere's normal is hit point - centre, as uncertain as the hit point (t's tolerance
    # times |d| = 1); a triangle's is an edge cross product, known to float32 rounding.
    assert_vectors_close(
        packet_hits.normal[hit], single_hits.normal[hit], atol=atol[hit], err_msg="normal"
    )
