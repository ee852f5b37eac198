"""Instance arrays (``BVH.add_instances``) against the same placements baked into one mesh and
traced by trimesh's pure-NumPy ray-triangle test (``bvh_reference.triangle_hits``), and against
the float64 sphere quadratic for a child of analytic spheres."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from bvh_reference import (
    affine,
    assert_hits_match,
    float32_exact,
    rays_toward_box,
    sphere_hits,
    transform_points,
    triangle_hits,
    unit,
)
from tolerances import assert_close, position_atol

from embree_rt.embree import BVH, Rays
from embree_rt.embree.bvh import SPHERE_KINDS
from embree_rt.tracing.records import HitLabels, intersect_records


def placements(rng: np.random.Generator, count: int, *, uniform: bool = False) -> np.ndarray:
    """(count, 4, 4) float64: random rotations, scales in [0.4, 1.6] (per axis unless
    ``uniform``), every third one mirrored (one axis negated), on a grid 5 apart so no two
    copies of a unit-sized child overlap."""
    matrices = []
    side = int(np.ceil(np.sqrt(count)))
    for k in range(count):
        scale = rng.uniform(0.4, 1.6, size=1 if uniform else 3) * np.ones(3)
        if k % 3 == 2:
            scale[rng.integers(3)] *= -1.0 if not uniform else 1.0
            if uniform:
                scale = -scale  # a point reflection: det < 0, still a similarity
        axis = rng.normal(size=3)
        matrix = affine(
            axis,
            rng.uniform(-np.pi, np.pi),
            scale,
            [5.0 * (k % side), rng.uniform(-1, 1), 5.0 * (k // side)],
        )
        matrices.append(matrix)
    return np.asarray(matrices)


def bake(vertices, faces, matrices, child=None, children=None):
    """Every placement's copy in world space, one mesh: vertices, faces, and per baked face the
    (instance, face within the child) it came from. ``children`` [(vertices, faces)] with
    ``child`` (n,) picks each placement's mesh; else all are (vertices, faces)."""
    children = children or [(vertices, faces)]
    child = np.zeros(len(matrices), int) if child is None else child
    all_vertices, all_faces, instance, local = [], [], [], []
    offset = 0
    for k, matrix in enumerate(matrices):
        v, f = children[child[k]]
        all_vertices.append(transform_points(matrix, v))
        all_faces.append(f + offset)
        instance.append(np.full(len(f), k))
        local.append(np.arange(len(f)))
        offset += len(v)
    return (
        np.concatenate(all_vertices),
        np.concatenate(all_faces),
        np.concatenate(instance),
        np.concatenate(local),
    )


def world_rays(rng, vertices, count):
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    origins, directions = rays_toward_box(rng, count, lower, upper, np.linalg.norm(upper - lower))
    return float32_exact(origins), float32_exact(directions)


def mirrored(matrices: np.ndarray) -> np.ndarray:
    return np.linalg.det(matrices[:, :3, :3]) < 0


def reference_for(origins, directions, baked_vertices, baked_faces, instance, local, matrices):
    ref = triangle_hits(origins, directions, baked_vertices, baked_faces)
    face = np.where(ref.hit, ref.prim_id, 0)
    copy = np.where(ref.hit, instance[face], -1)
    ref.prim_id = np.where(ref.hit, local[face], -1)
    # The baked face's (v1 - v0) x (v2 - v0) turns inside out under a mirror (the winding flips
    # with it); the surface's own side is the child's normal carried by M^-T, which keeps it.
    flip = ref.hit & mirrored(matrices)[np.maximum(copy, 0)]
    ref.normal[flip] *= -1.0
    return ref, copy


def test_instance_array_equals_the_baked_mesh_with_mirrors_and_non_uniform_scales():
    rng = np.random.default_rng(40)
    ico = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    vertices, faces = float32_exact(ico.vertices), ico.faces
    matrices = placements(rng, 21)
    assert mirrored(matrices).sum() == 7
    baked, baked_faces, instance, local = bake(vertices, faces, matrices)
    origins, directions = world_rays(rng, baked, 3000)
    with BVH() as child, BVH() as top:
        mesh_gid = child.add_triangles(vertices, faces)
        child.commit()
        top.add_spheres([[500.0, 500.0, 500.0]], [0.5])  # so the array's id is not 0
        array_gid = top.add_instances(child, matrices)
        top.commit()
        assert array_gid != 0 and top.instance_count == 21
        hits = top.intersect(Rays(origins, directions))
    ref, copy = reference_for(origins, directions, baked, baked_faces, instance, local, matrices)
    sure = assert_hits_match(
        hits, ref, mesh_gid, array_gid, triangles=True, normal_cos=0.9995, min_hit_fraction=0.15
    )
    both = sure & ref.hit
    np.testing.assert_array_equal(hits.inst_prim_id[both], copy[both])
    assert np.all(hits.inst_prim_id[~np.isfinite(hits.t)] == -1)
    assert len(np.unique(copy[both])) >= 18  # most placements were seen
    assert mirrored(matrices)[copy[both]].sum() > 50  # and mirrored ones often
    # A closed mesh hit from outside: the normal faces the ray, mirrored copies included.
    assert np.all(np.einsum("ij,ij->i", hits.normal[both], directions[both]) < 0)


def test_hit_records_of_an_instance_array():
    """intersect_records: the hit point, the unit world normal (same as ``intersect``'s), each
    instance's own label and a coordinate bound that contains the hit."""
    rng = np.random.default_rng(41)
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    matrices = placements(rng, 12)
    baked, *_ = bake(ico.vertices, ico.faces, matrices)
    origins, directions = world_rays(rng, baked, 3000)
    labels = rng.integers(0, 1000, size=12).astype(np.int32)
    with BVH() as child, BVH() as top:
        child.add_triangles(ico.vertices, ico.faces)
        child.commit()
        array_gid = top.add_instances(child, matrices)
        top.commit()
        hits = top.intersect(Rays(origins, directions))
        table = HitLabels(
            geometry_label=np.full(top.geometry_count, -7, np.int64),
            geometry_scale=np.zeros(top.geometry_count, np.float32),
            instance_labels={array_gid: labels},
        )
        records = intersect_records(
            top, origins.T.astype(np.float32), directions.T.astype(np.float32), table
        )
        unlabelled = intersect_records(
            top,
            origins.T.astype(np.float32),
            directions.T.astype(np.float32),
            HitLabels(
                np.full(top.geometry_count, -7, np.int64), np.zeros(top.geometry_count, np.float32)
            ),
        )
    rays = records.rays
    assert len(rays) == np.isfinite(hits.t).sum() > 500
    np.testing.assert_array_equal(records.inst_prim_id, hits.inst_prim_id[rays])
    np.testing.assert_array_equal(records.label, labels[hits.inst_prim_id[rays]])
    np.testing.assert_array_equal(unlabelled.label, -7)
    np.testing.assert_allclose(records.normal.T, unit(hits.normal[rays]), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(records.normal, axis=0), 1.0, atol=1e-6)
    expected = origins[rays] + hits.t[rays, None].astype(np.float64) * directions[rays]
    assert_close(records.position.T, expected, atol=position_atol(expected, origins))
    assert np.all(records.scale >= np.abs(records.position).max(axis=0))
    # ...and bounds the placement, not the whole scene: within its copy's reach
    reach = np.abs(matrices[:, :3, 3]).max(axis=1) + 1.6 * np.sqrt(3)
    assert np.all(records.scale <= reach[records.inst_prim_id] + 1e-4)


def test_two_children_in_one_array():
    rng = np.random.default_rng(42)
    ico = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    box = trimesh.creation.box(extents=[1.6, 0.8, 1.2])
    children = [(float32_exact(ico.vertices), ico.faces), (float32_exact(box.vertices), box.faces)]
    matrices = placements(rng, 16)
    which = rng.integers(0, 2, size=16)
    baked, baked_faces, instance, local = bake(None, None, matrices, which, children)
    origins, directions = world_rays(rng, baked, 3000)
    with BVH() as first, BVH() as second, BVH() as top:
        first.add_triangles(*children[0])
        first.commit()
        second.add_triangles(*children[1])
        second.commit()
        array_gid = top.add_instances([first, second], matrices, child_index=which)
        top.commit()
        hits = top.intersect(Rays(origins, directions))
        child_of_hit = top.instance_children(hits.inst_id, hits.inst_prim_id)
    ref, copy = reference_for(origins, directions, baked, baked_faces, instance, local, matrices)
    sure = assert_hits_match(
        hits, ref, 0, array_gid, triangles=True, normal_cos=0.9995, min_hit_fraction=0.15
    )
    both = sure & ref.hit
    np.testing.assert_array_equal(hits.inst_prim_id[both], copy[both])
    np.testing.assert_array_equal(child_of_hit[both], which[copy[both]])
    assert set(which[copy[both]]) == {0, 1}


@pytest.mark.parametrize("kind", SPHERE_KINDS)
def test_a_child_of_analytic_spheres(kind):
    """Similarities (rotation, uniform scale, translation; some point reflections) map spheres
    to spheres, so the world reference is the float64 quadratic on the moved spheres."""
    rng = np.random.default_rng(43)
    centers = float32_exact(rng.uniform(-1.0, 1.0, size=(6, 3)))
    radii = float32_exact(rng.uniform(0.2, 0.5, size=6))
    matrices = placements(rng, 16, uniform=True)
    assert mirrored(matrices).any()
    world_centers = np.concatenate([transform_points(m, centers) for m in matrices])
    scales = np.abs(np.cbrt(np.linalg.det(matrices[:, :3, :3])))
    world_radii = np.concatenate([s * radii for s in scales])
    origins, directions = world_rays(rng, world_centers, 4000)
    with BVH() as child, BVH() as top:
        spheres_gid = child.add_spheres(centers, radii, kind=kind)
        child.commit()
        array_gid = top.add_instances(child, matrices)
        top.commit()
        hits = top.intersect(Rays(origins, directions))
    ref = sphere_hits(origins, directions, world_centers, world_radii)
    copy = np.where(ref.hit, ref.prim_id // len(radii), -1)
    ref.prim_id = np.where(ref.hit, ref.prim_id % len(radii), -1)
    sure = assert_hits_match(
        hits, ref, spheres_gid, array_gid, normal_cos=0.9995, min_hit_fraction=0.1
    )
    both = sure & ref.hit
    np.testing.assert_array_equal(hits.inst_prim_id[both], copy[both])
    assert mirrored(matrices)[copy[both]].any()


def test_arrays_beside_single_instances_and_top_level_geometry():
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    with BVH() as child, BVH() as top:
        child.add_triangles(ico.vertices, ico.faces)
        child.commit()
        spheres = top.add_spheres([[0.0, 0.0, -10.0]], [1.0])
        single = top.add_instance(child, affine([0, 1, 0], 0.3, [1, 1, 1], [0.0, 0.0, 10.0]))
        moves = np.tile(np.eye(4), (2, 1, 1))
        moves[:, 0, 3] = [10.0, 20.0]
        array_gid = top.add_instances(child, moves)
        top.commit()
        origins = np.array([[0, 0, -20], [0, 0, 20], [10, 0, 20], [20, 0, 20], [50, 0, 20.0]])
        directions = np.array([[0, 0, 1], [0, 0, -1], [0, 0, -1], [0, 0, -1], [0, 0, -1.0]])
        hits = top.intersect(Rays(origins, directions))
    np.testing.assert_array_equal(hits.geom_id, [spheres, 0, 0, 0, -1])
    np.testing.assert_array_equal(hits.inst_id, [-1, single, array_gid, array_gid, -1])
    np.testing.assert_array_equal(hits.inst_prim_id, [-1, -1, 0, 1, -1])


@pytest.mark.parametrize(
    "transforms, child_index, message",
    [
        (np.eye(4), None, "expected shape (n, 4, 4)"),
        (np.zeros((0, 4, 4)), None, "at least one placement"),
        (np.stack([np.eye(4), np.diag([1.0, np.nan, 1.0, 1.0])]), None, "row 1: expected a 4x4"),
        (np.stack([np.eye(4), np.diag([1.0, 1.0, 0.0, 1.0])]), None, "row 1: must be invertible"),
        (np.stack([np.eye(4), np.diag([1.0, 1.0, 1.0, 2.0])]), None, "row 1: must be affine"),
        (np.stack([np.eye(4)] * 2), [0, 2], "child_index: row 1 is 2"),
    ],
)
def test_bad_arrays_are_refused_with_the_row(transforms, child_index, message):
    with BVH() as child, BVH() as top:
        child.add_spheres([[0.0, 0.0, 0.0]], [1.0])
        child.commit()
        with pytest.raises(ValueError) as error:
            top.add_instances(
                [child, child],
                transforms,
                child_index if child_index is not None else [0] * len(transforms),
            )
        assert message in str(error.value)


def test_a_child_must_be_committed():
    with BVH() as child, BVH() as top:
        child.add_spheres([[0.0, 0.0, 0.0]], [1.0])
        with pytest.raises(ValueError, match="commit each child"):
            top.add_instances(child, np.eye(4)[None])
