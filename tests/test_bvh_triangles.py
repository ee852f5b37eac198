"""Triangle meshes in the BVH against trimesh's NumPy intersector and embreex's own API."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from bvh_reference import (
    affine,
    assert_hits_match,
    embreex_hits,
    face_normals,
    float32_exact,
    near_triangle_edge,
    random_soup,
    rays_toward_box,
    transform_points,
    triangle_hits,
    unit,
)

from embree_rt.embree import BVH


def icosphere():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    return mesh.vertices + np.array([0.5, -0.3, 0.2]), mesh.faces


def soup():
    return random_soup(np.random.default_rng(10), 300)


def box():
    mesh = trimesh.creation.box(extents=(2.0, 3.0, 4.0))
    tilt = affine([1, 1, 0], 0.4, [1, 1, 1], [0.3, 0, -0.2])
    return transform_points(tilt, mesh.vertices), mesh.faces


MESHES = {"icosphere": icosphere, "soup": soup, "box": box}


@pytest.fixture(scope="module", params=sorted(MESHES))
def scene(request):
    """(name, vertices float32-exact, faces, bvh, gid, origins, directions) for one mesh."""
    vertices, faces = MESHES[request.param]()
    vertices = float32_exact(vertices)
    faces = np.asarray(faces, np.int64)
    bvh = BVH()
    gid = bvh.add_triangles(vertices, faces)
    bvh.commit()
    rng = np.random.default_rng(11)
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    margin = 0.1 * (upper - lower)
    origins, directions = rays_toward_box(
        rng, 2000, lower - margin, upper + margin, 3.0 * np.linalg.norm(upper - lower)
    )
    origins, directions = float32_exact(origins), float32_exact(directions)
    yield request.param, vertices, faces, bvh, gid, origins, directions
    bvh.close()


def test_matches_trimesh(scene):
    _, vertices, faces, bvh, gid, origins, directions = scene
    hits = bvh.intersect(origins, directions)
    ref = triangle_hits(origins, directions, vertices, faces)
    assert_hits_match(hits, ref, gid, triangles=True, min_hit_fraction=0.2, min_miss_fraction=0.05)


def test_matches_embreex_on_the_same_mesh(scene):
    _, vertices, faces, bvh, _, origins, directions = scene
    hits = bvh.intersect(origins, directions)
    theirs = embreex_hits(origins, directions, vertices, faces)
    ours_hit = np.isfinite(hits.t)
    assert ours_hit.mean() > 0.2
    # The same library on the same float32 data: only rays on a shared edge may differ.
    edge = near_triangle_edge(hits.u, hits.v) | near_triangle_edge(theirs.u, theirs.v)
    differ = (ours_hit != np.isfinite(theirs.t)) | (hits.prim_id != theirs.prim_id)
    assert not (differ & ~edge).any(), f"rays {np.flatnonzero(differ & ~edge)[:5]} differ"
    assert differ.mean() < 0.002
    same = ours_hit & ~differ
    np.testing.assert_allclose(hits.t[same], theirs.t[same], rtol=1e-5)
    # Both round u, v in float32 at ~5e-5 from the float64 truth here (embreex builds its own
    # BVH, with its own triangle layout), so they agree to about twice that.
    np.testing.assert_allclose(hits.u[same], theirs.u[same], atol=2e-4)
    np.testing.assert_allclose(hits.v[same], theirs.v[same], atol=2e-4)
    cosine = np.einsum("ij,ij->i", unit(hits.normal[same]), unit(theirs.normal[same]))
    assert cosine.min() > 0.99999, "normal direction (sign included) differs from embreex's Ng"


def test_window_past_the_nearest_hit_finds_the_next_surface(scene):
    name, vertices, faces, bvh, gid, origins, directions = scene
    first = triangle_hits(origins, directions, vertices, faces)
    keep = first.hit & ~first.ambiguous
    o, d = origins[keep], directions[keep]
    tnear = float32_exact(first.t[keep] * (1 + 1e-4))
    hits = bvh.intersect(o, d, tnear=tnear)
    ref = triangle_hits(o, d, vertices, faces, tnear=tnear)
    # closed meshes: every ray entering leaves again through a back face
    expect_hits = 0.9 if name != "soup" else 0.05
    assert_hits_match(hits, ref, gid, triangles=True, min_hit_fraction=expect_hits)
    if name != "soup":
        # the geometric normal is not flipped toward the ray: leaving rays see it point along them
        hit = np.isfinite(hits.t)
        assert np.all(np.einsum("ij,ij->i", hits.normal[hit], d[hit]) > 0)


def test_scalar_window(scene):
    _, vertices, faces, bvh, gid, origins, directions = scene
    span = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
    # origins sit 3 spans from the centre; directions are 0.2..5 long
    tnear, tfar = 2.8 * span / 5.0, 3.1 * span / 0.5
    hits = bvh.intersect(origins, directions, tnear=tnear, tfar=tfar)
    ref = triangle_hits(origins, directions, vertices, faces, tnear=tnear, tfar=tfar)
    assert_hits_match(hits, ref, gid, triangles=True, min_hit_fraction=0.05, min_miss_fraction=0.2)


@pytest.mark.parametrize("index_dtype", [np.int64, np.int32, np.uint32])
def test_one_triangle_closed_form(index_dtype):
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]])
    faces = np.array([[0, 1, 2], [0, 2, 1]], index_dtype)
    with BVH() as front, BVH() as flipped:
        front.add_triangles(vertices, faces[:1])
        flipped.add_triangles(vertices, faces[1:])
        front.commit()
        flipped.commit()
        origins = np.array([[0.2, 0.3, 1.0], [0.2, 0.3, -2.0], [0.7, 0.7, 1.0]])
        directions = np.array([[0, 0, -1.0], [0, 0, 0.5], [0, 0, -1.0]])
        a = front.intersect(origins, directions)
        b = flipped.intersect(origins, directions)
    np.testing.assert_allclose(a.t[:2], [1.0, 4.0], rtol=1e-6)
    assert np.isinf(a.t[2]) and a.prim_id[2] == -1, "(0.7, 0.7) lies outside the triangle"
    np.testing.assert_allclose(a.u[:2], [0.2, 0.2], atol=1e-6)
    np.testing.assert_allclose(a.v[:2], [0.3, 0.3], atol=1e-6)
    # Ng ∝ (v1 - v0) x (v2 - v0) = +z from either side; the flipped winding gives -z
    np.testing.assert_allclose(unit(a.normal[:2]), [[0, 0, 1], [0, 0, 1]], atol=1e-6)
    np.testing.assert_allclose(unit(b.normal[:2]), [[0, 0, -1], [0, 0, -1]], atol=1e-6)
    # vertices 0, 2, 1: u weighs v2 = (0, 1, 0) now
    np.testing.assert_allclose(b.u[:2], [0.3, 0.3], atol=1e-6)
    np.testing.assert_allclose(b.v[:2], [0.2, 0.2], atol=1e-6)


def test_two_meshes_report_their_own_geometry_ids():
    vertices_a, faces_a = random_soup(np.random.default_rng(12), 50, extent=2.0)
    vertices_b = vertices_a + np.array([10.0, 0, 0])
    with BVH() as bvh:
        gid_a = bvh.add_triangles(vertices_a, faces_a)
        gid_b = bvh.add_triangles(vertices_b, faces_a[::-1])  # reversed face order
        bvh.commit()
        assert gid_a != gid_b
        vertices = np.r_[vertices_a, vertices_b]
        faces = np.r_[faces_a, faces_a[::-1] + len(vertices_a)]
        centroids = vertices[faces].mean(axis=1)
        normals = face_normals(vertices, faces)
        # a short ray onto each centroid along its normal: nothing else can be in between
        hits = bvh.intersect(centroids + 1e-4 * normals, -normals, tfar=2e-4)
    assert np.array_equal(hits.geom_id, np.r_[np.full(50, gid_a), np.full(50, gid_b)])
    assert np.array_equal(hits.prim_id, np.r_[np.arange(50), np.arange(50)])
    np.testing.assert_allclose(hits.t, 1e-4, rtol=1e-2)
