"""Instances in the BVH against the same geometry baked into world space."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from bvh_reference import (
    TRANSFORMS,
    affine,
    assert_hits_match,
    float32_exact,
    random_soup,
    rays_toward_box,
    sphere_hits,
    transform_points,
    triangle_hits,
    unit,
)
from tolerances import assert_close, ray_t_atol

from embree_rt.embree import BVH, Rays
from embree_rt.embree.bvh import SPHERE_KINDS


def mesh_kinds():
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    return {
        "icosphere": (ico.vertices, ico.faces),
        "soup": random_soup(np.random.default_rng(20), 120, extent=1.5),
    }


def world_rays(rng, vertices, count=2500):
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    span = np.linalg.norm(upper - lower)
    origins, directions = rays_toward_box(rng, count, lower, upper, 2.0 * span)
    return float32_exact(origins), float32_exact(directions)


@pytest.mark.parametrize("kind", ["icosphere", "soup"])
@pytest.mark.parametrize("which", range(len(TRANSFORMS)))
def test_one_instance_equals_the_baked_mesh(kind, which):
    vertices, faces = mesh_kinds()[kind]
    vertices = float32_exact(vertices)
    matrix = TRANSFORMS[which]
    baked = transform_points(matrix, vertices)
    with BVH() as child, BVH() as top:
        mesh_gid = child.add_triangles(vertices, faces)
        child.commit()
        top.add_spheres([[100.0, 100.0, 100.0]], [0.5])  # so the instance's gid is not 0
        inst_gid = top.add_instance(child, matrix)
        top.commit()
        assert inst_gid != 0
        origins, directions = world_rays(np.random.default_rng(21 + which), baked)
        hits = top.intersect(Rays(origins, directions))
    ref = triangle_hits(origins, directions, baked, faces)
    # the reference normal is the baked face's (v1 - v0) x (v2 - v0): sign included
    assert_hits_match(
        hits, ref, mesh_gid, inst_gid, triangles=True, normal_cos=0.9995, min_miss_fraction=0.05
    )


def test_many_instances_of_one_mesh_report_which_instance():
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    vertices, faces = float32_exact(ico.vertices), ico.faces
    with BVH() as child, BVH() as top:
        mesh_gid = child.add_triangles(vertices, faces)
        child.commit()
        inst_gids = [top.add_instance(child, matrix) for matrix in TRANSFORMS]
        top.commit()
        assert len(set(inst_gids)) == len(TRANSFORMS)
        baked = np.concatenate([transform_points(m, vertices) for m in TRANSFORMS])
        baked_faces = np.concatenate([faces + k * len(vertices) for k in range(len(TRANSFORMS))])
        origins, directions = world_rays(np.random.default_rng(22), baked, 4000)
        hits = top.intersect(Rays(origins, directions))
    ref = triangle_hits(origins, directions, baked, baked_faces)
    copy = np.where(ref.hit, ref.prim_id // len(faces), 0)
    ref.prim_id = np.where(ref.hit, ref.prim_id % len(faces), -1)
    expected_inst = np.asarray(inst_gids)[copy]
    assert_hits_match(
        hits, ref, mesh_gid, expected_inst, triangles=True, normal_cos=0.9995, min_hit_fraction=0.15
    )
    assert len(np.unique(hits.inst_id[np.isfinite(hits.t)])) == len(TRANSFORMS)


@pytest.mark.parametrize("kind", SPHERE_KINDS)
@pytest.mark.parametrize("which", range(len(TRANSFORMS)))
def test_instanced_spheres_become_ellipsoids(which, kind):
    """A sphere set under a non-uniform scale: trace the rays in object space (t is invariant
    under an affine map of the ray) and bring the normal back with the inverse transpose."""
    rng = np.random.default_rng(23)
    centers = float32_exact(rng.uniform(-1.5, 1.5, size=(20, 3)))
    radii = float32_exact(rng.uniform(0.2, 0.6, size=20))
    matrix = TRANSFORMS[which]
    inverse = np.linalg.inv(matrix)
    with BVH() as child, BVH() as top:
        spheres_gid = child.add_spheres(centers, radii, kind=kind)
        child.commit()
        inst_gid = top.add_instance(child, matrix)
        top.commit()
        world_box = transform_points(matrix, np.r_[centers - 0.6, centers + 0.6])
        origins, directions = world_rays(rng, world_box, 3000)
        hits = top.intersect(Rays(origins, directions))
    local_origins = transform_points(inverse, origins)
    local_directions = directions @ inverse[:3, :3].T
    ref = sphere_hits(local_origins, local_directions, centers, radii)
    ref.normal = unit(ref.normal @ inverse[:3, :3])  # (M^-T n) as rows
    assert_hits_match(hits, ref, spheres_gid, inst_gid, normal_cos=0.9995, min_hit_fraction=0.1)


@pytest.mark.parametrize("kind", SPHERE_KINDS)
def test_child_with_two_geometries_reports_the_inner_geometry_id(kind):
    ico = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    with BVH() as child, BVH() as top:
        sphere_gid = child.add_spheres([[0.0, 0.0, 0.0]], [1.0], kind=kind)
        mesh_gid = child.add_triangles(ico.vertices + np.array([5.0, 0, 0]), ico.faces)
        child.commit()
        assert sphere_gid != mesh_gid
        move = affine([0, 0, 1], 0.0, [1, 1, 1], [0.0, 0.0, 10.0])
        direct_gid = top.add_spheres([[0.0, 0.0, -10.0]], [1.0], kind=kind)
        inst_gid = top.add_instance(child, move)
        top.commit()
        origins = np.array([[0.0, 0.0, 20.0], [5.1, 0.05, 20.0], [0.0, 0.0, -20.0]])
        directions = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
        hits = top.intersect(Rays(origins, directions))
    np.testing.assert_array_equal(hits.geom_id, [sphere_gid, mesh_gid, direct_gid])
    np.testing.assert_array_equal(hits.inst_id, [inst_gid, inst_gid, -1])
    assert_close(
        hits.t[[0, 2]], [9.0, 9.0], atol=ray_t_atol(origins[[0, 2]], directions[[0, 2]], 20.0)
    )
    assert 8.999 < hits.t[1] < 9.3  # the faceted top lies a little inside the unit sphere
    np.testing.assert_allclose(unit(hits.normal[[0, 2]]), [[0, 0, 1], [0, 0, -1]], atol=1e-5)


def test_top_level_keeps_its_instanced_bvh_alive():
    """Dropping the caller's last reference to the child must not free what the top level uses."""
    import gc

    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)

    def build_top() -> tuple[BVH, int, int]:
        child = BVH()
        mesh_gid = child.add_triangles(ico.vertices, ico.faces)
        child.commit()
        top = BVH()
        gid = top.add_instance(child, TRANSFORMS[0])
        top.commit()
        return top, mesh_gid, gid

    top, mesh_gid, inst_gid = build_top()
    gc.collect()
    baked = transform_points(TRANSFORMS[0], float32_exact(ico.vertices))
    origins, directions = world_rays(np.random.default_rng(24), baked, 1000)
    with top:
        hits = top.intersect(Rays(origins, directions))
    ref = triangle_hits(origins, directions, baked, ico.faces)
    assert_hits_match(hits, ref, mesh_gid, inst_gid, triangles=True, normal_cos=0.9995)
