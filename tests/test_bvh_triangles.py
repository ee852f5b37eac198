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
    triangle_heights,
    triangle_hits,
    unit,
)
from tolerances import (
    RTOL32,
    assert_close,
    assert_vectors_close,
    coordinate_scale,
    position_atol,
    ray_t_atol,
)

from embree_rt.embree import BVH, Rays


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
    hits = bvh.intersect(Rays(origins, directions))
    ref = triangle_hits(origins, directions, vertices, faces)
    assert_hits_match(hits, ref, gid, triangles=True, min_hit_fraction=0.2, min_miss_fraction=0.05)


def test_matches_embreex_on_the_same_mesh(scene):
    _, vertices, faces, bvh, _, origins, directions = scene
    hits = bvh.intersect(Rays(origins, directions))
    theirs = embreex_hits(origins, directions, vertices, faces)
    ours_hit = np.isfinite(hits.t)
    assert ours_hit.mean() > 0.2
    # The same library on the same float32 data: only rays on a shared edge may differ.
    edge = near_triangle_edge(hits.u, hits.v) | near_triangle_edge(theirs.u, theirs.v)
    differ = (ours_hit != np.isfinite(theirs.t)) | (hits.prim_id != theirs.prim_id)
    assert not (differ & ~edge).any(), f"rays {np.flatnonzero(differ & ~edge)[:5]} differ"
    assert differ.mean() < 0.002
    same = ours_hit & ~differ
    # Different Embree paths (embreex builds its own BVH and triangle layout, and traces one ray
    # at a time) round differently, and differently again on another ISA: t and u, v agree to
    # float32 rounding of the coordinates, which moves u, v by the error over the height.
    t_atol = ray_t_atol(
        origins[same], directions[same], coordinate_scale(vertices), normals=hits.normal[same]
    )
    assert_close(hits.t[same], theirs.t[same], atol=t_atol, err_msg="t")
    uv_atol = (
        t_atol
        * np.linalg.norm(directions[same], axis=1)
        / triangle_heights(vertices, faces[hits.prim_id[same]])
    )
    assert_close(hits.u[same], theirs.u[same], atol=uv_atol, rtol=0.0, err_msg="u")
    assert_close(hits.v[same], theirs.v[same], atol=uv_atol, rtol=0.0, err_msg="v")
    cosine = np.einsum("ij,ij->i", unit(hits.normal[same]), unit(theirs.normal[same]))
    assert cosine.min() > 0.99999, "normal direction (sign included) differs from embreex's Ng"


def test_window_past_the_nearest_hit_finds_the_next_surface(scene):
    name, vertices, faces, bvh, gid, origins, directions = scene
    first = triangle_hits(origins, directions, vertices, faces)
    keep = first.hit & ~first.ambiguous
    o, d = origins[keep], directions[keep]
    tnear = float32_exact(first.t[keep] * (1 + 1e-4))
    hits = bvh.intersect(Rays(o, d, tnear=tnear))
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
    hits = bvh.intersect(Rays(origins, directions, tnear=tnear, tfar=tfar))
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
        a = front.intersect(Rays(origins, directions))
        b = flipped.intersect(Rays(origins, directions))
    # Exact inputs, but Embree's float32 arithmetic on them still rounds (differently per ISA):
    # t to ulps of the coordinates (up to 5 here), u, v to that over the triangle's height.
    t_atol = ray_t_atol(origins[:2], directions[:2], 5.0)
    uv_atol = position_atol(5.0) / triangle_heights(vertices, faces[:1])[0]
    assert_close(a.t[:2], [1.0, 4.0], atol=t_atol)
    assert np.isinf(a.t[2]) and a.prim_id[2] == -1, "(0.7, 0.7) lies outside the triangle"
    assert_close(a.u[:2], [0.2, 0.2], atol=uv_atol)
    assert_close(a.v[:2], [0.3, 0.3], atol=uv_atol)
    # Ng ∝ (v1 - v0) x (v2 - v0) = +z from either side; the flipped winding gives -z
    assert_vectors_close(unit(a.normal[:2]), [[0, 0, 1], [0, 0, 1]], atol=RTOL32)
    assert_vectors_close(unit(b.normal[:2]), [[0, 0, -1], [0, 0, -1]], atol=RTOL32)
    # vertices 0, 2, 1: u weighs v2 = (0, 1, 0) now
    assert_close(b.u[:2], [0.3, 0.3], atol=uv_atol)
    assert_close(b.v[:2], [0.2, 0.2], atol=uv_atol)


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
        origins = centroids + 1e-4 * normals
        hits = bvh.intersect(Rays(origins, -normals, tfar=2e-4))
    assert np.array_equal(hits.geom_id, np.r_[np.full(50, gid_a), np.full(50, gid_b)])
    assert np.array_equal(hits.prim_id, np.r_[np.arange(50), np.arange(50)])
    # t = 1e-4 on rays starting up to 12 units out: known to ulps of 12 (~1e-6), not of 1e-4.
    atol = ray_t_atol(origins, normals, coordinate_scale(vertices), normals=normals)
    assert_close(hits.t, np.full(100, 1e-4), atol=atol)
