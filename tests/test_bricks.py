"""Data-parallel rendering in one process: bricks of a scene, rays routed to them, the nearest hit
over them; the image against one BVH's.

Why the images are bitwise equal (on any x86-64 ISA, as both renders run on the same one): a
brick is a ``SceneGeometry`` of some of the scene's objects, so each hit's t, point, normal,
material and scale are computed by the same code from the same numbers (a sphere's from the ray
and the sphere, a mesh's from the ray, its placement and its own triangle BVH, built from the
same mesh); a ray's nearest hit over the bricks is its nearest in the whole scene, and the floor
is decided by the same strict comparison; the merged columns come in the order one BVH's hit
records have (floor, sphere set, other objects, each in ray order), so shading adds every
pixel's contributions in the same order. Only where two objects in different bricks are hit at
exactly the same float32 t can the pictures differ (one BVH's traversal order picks one of them,
the bricks' rule the lower object id); the brick set counts those ties, and the tests require
the images equal where there are none.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.bricks import local_brick_set, scene_partition
from embree_rt.bricks.brick import OTHER_GROUP, SPHERE_GROUP, BrickHits
from embree_rt.bricks.contents import field_brick, scene_brick
from embree_rt.bricks.nearest import nearest_over_bricks
from embree_rt.bricks.partition import field_brick_counts, field_partition, split_points
from embree_rt.bricks.ray_boxes import boxes_reached
from embree_rt.camera import camera_frame
from embree_rt.geometry import SceneGeometry, SurfaceHits
from embree_rt.integrator import Integrator
from embree_rt.scene.random_field import add_field_spheres_where, field_scene, plan_field

SCENES = Path(__file__).resolve().parent.parent / "scenes"
SIZE = {"width": 160, "height": 90, "spp": 2}


def render_both(scene: rt.Scene, bricks: int, **overrides):
    """(one BVH's image, the bricks' image, the brick set's traffic) at a small size."""
    settings = scene.render.with_overrides(**{**SIZE, **overrides})
    frame = camera_frame(scene.camera, settings.width, settings.height)
    options = {"spp": settings.spp, "max_depth": settings.max_depth, "seed": settings.seed}
    with Integrator(scene, threads=1) as one:
        expected, _ = one.render_image(frame, **options)
    brick_set = local_brick_set(scene, scene_partition(scene, bricks))
    with Integrator(scene, threads=2, tracer=brick_set) as parts:
        image, _ = parts.render_image(frame, **options)
    return expected, image, brick_set.traffic


@pytest.mark.parametrize(
    "name", ["three_spheres", "showcase", "material_spectrum", "random_field", "mesh_and_spheres"]
)
@pytest.mark.parametrize("bricks", [2, 3])
def test_bricks_render_the_image_of_one_bvh(name: str, bricks: int) -> None:
    expected, image, traffic = render_both(rt.load_scene(SCENES / f"{name}.toml"), bricks)
    differing = int(np.any(image != expected, axis=2).sum())
    # No exact tie between bricks in these scenes, so no pixel may differ.
    assert traffic.ties == 0 and differing == 0, (traffic, differing)
    assert traffic.rays > 0 and traffic.ray_sends > 0 and traffic.segment_sends > 0


def test_bricks_of_a_field_of_1e5_spheres_render_the_image_of_one_bvh() -> None:
    expected, image, traffic = render_both(rt.random_field(100_000, seed=3), 4, spp=1)
    assert traffic.ties == 0 and np.array_equal(image, expected)


def test_every_object_is_in_exactly_one_brick_and_the_split_is_balanced() -> None:
    scene = rt.load_scene(SCENES / "mesh_and_spheres.toml")
    count = len(scene.sphere_radii) + len(scene.meshes) + sum(len(e) for e in scene.instances)
    for bricks in (1, 2, 3, 5):
        partition = scene_partition(scene, bricks)
        ids = np.concatenate([scene_brick(scene, partition, b).object_ids for b in range(bricks)])
        assert np.array_equal(np.sort(ids), np.arange(count))
    points = np.random.default_rng(0).normal(size=(10_000, 3)) * [10.0, 1.0, 3.0]
    partition = split_points(points, 7)
    sizes = np.bincount(partition.brick_of(points), minlength=7)
    # Medians: each brick holds its share of the points, to within a point or two per cut.
    assert np.abs(sizes - 10_000 / 7).max() <= 4, sizes
    assert partition.axis[0] == 0  # the longest side first
    again = split_points(points, 7)
    assert np.array_equal(again.value, partition.value)


def test_a_fields_bricks_generated_from_its_recipe_are_the_fields_spheres() -> None:
    plan = plan_field(30_000, seed=5)
    scene = rt.random_field(30_000, seed=5)
    partition = field_partition(plan, 3)
    estimate = field_brick_counts(plan, partition)
    seen = []
    for index in range(3):
        made = field_brick(plan, partition, index)
        cut = scene_brick(scene, partition, index)
        assert np.array_equal(made.object_ids, cut.object_ids)
        for name in ("sphere_centers", "sphere_radii", "sphere_materials"):
            assert np.array_equal(getattr(made.scene, name), getattr(cut.scene, name))
        # the estimate made before any sphere, from a lattice of cells: within 2 %
        assert abs(estimate[index] - len(made.object_ids)) <= 0.02 * len(made.object_ids)
        seen.append(made.object_ids)
    assert np.array_equal(np.sort(np.concatenate(seen)), np.arange(30_000))
    # A brick away from the centre of a field of 8 rings skips the rings that cannot reach it.
    plan = plan_field(2_000_000, seed=5)
    partition = field_partition(plan, 8)
    index = int(partition.brick_of(np.array([[plan.extent * 0.9, 0.0, 0.0]]))[0])
    low, high = partition.region(index)
    calls = []

    def keep(centers):
        calls.append(len(centers))
        return partition.brick_of(centers) == index

    part = rt.Scene(materials=field_scene(plan).materials)
    ids = add_field_spheres_where(part, plan, keep, within=((low[0], low[2]), (high[0], high[2])))
    assert np.array_equal(ids, field_brick(plan, partition, index).object_ids)
    assert sum(calls[1:]) < 0.9 * plan.small  # heroes first, then the rings generated
    # Planes on cell boundaries: no small sphere reaches across one.
    for axis, value in zip(partition.axis, partition.value, strict=True):
        centers, radii = scene.sphere_centers[3:, axis], scene.sphere_radii[3:]
        assert not np.any((centers - radii < value) & (centers + radii > value))


def exact_reach(origin, direction, t_far, low, high) -> bool:
    """Whether the ray meets the box for some t in [0, t_far], in exact rational arithmetic."""
    near, far = Fraction(0), Fraction(t_far) if np.isfinite(t_far) else None
    exact = [[Fraction(float(x)) for x in v] for v in (origin, direction, low, high)]
    for o, d, lo, hi in zip(*exact, strict=True):
        if d == 0:
            if not lo <= o <= hi:
                return False
            continue
        t0, t1 = sorted(((lo - o) / d, (hi - o) / d))
        near = max(near, t0)
        far = t1 if far is None else min(far, t1)
    return far is None or near <= far


def test_ray_box_test_agrees_with_exact_arithmetic() -> None:
    rng = np.random.default_rng(1)
    n = 400
    origins = rng.uniform(-4, 4, (3, n)).astype(np.float32)
    directions = rng.normal(size=(3, n)).astype(np.float32)
    directions[0, :40] = 0.0  # parallel to a slab
    t_far = np.where(np.arange(n) % 2 == 0, np.inf, rng.uniform(0.1, 3.0, n))
    low = rng.uniform(-3, 1, (5, 3))
    boxes = np.stack([low, low + rng.uniform(0.2, 2.0, (5, 3))], axis=1)
    reached = boxes_reached(origins, directions, t_far, boxes)
    for b in range(5):
        for i in range(n):
            exact = exact_reach(origins[:, i], directions[:, i], t_far[i], *boxes[b])
            assert reached[b, i] == exact, (b, i)
    assert 0 < reached.sum() < reached.size


def surfaces_of(t, material) -> SurfaceHits:
    k = len(t)
    columns = np.arange(3 * k, dtype=np.float32).reshape(3, k)
    return SurfaceHits(
        t=np.asarray(t, np.float32),
        position=columns,
        normal=columns,
        face_normal=columns,
        flat=True,
        material=np.asarray(material, np.int64),
        floor_count=0,
        scale=np.ones(k, np.float32),
        incoming=columns,
    )


def test_nearest_over_bricks_takes_the_nearest_then_the_lower_id_then_the_floor() -> None:
    # Brick A's hits (object 7, a mesh) on rays 0, 1, 2, 4; brick B's (object 3, a sphere) on
    # rays 1, 2, 3, 4; the floor on rays 2, 3, 4.
    a = BrickHits(
        np.arange(4),
        np.full(4, 7),
        np.full(4, OTHER_GROUP, np.int8),
        surfaces_of([1.0, 2.0, 5.0, 9.0], [70] * 4),
    )
    b = BrickHits(
        np.arange(4),
        np.full(4, 3),
        np.full(4, SPHERE_GROUP, np.int8),
        surfaces_of([2.0, 4.0, 6.0, 9.0], [30] * 4),
    )
    floor = surfaces_of([4.5, 5.0, 9.5], [99] * 3)
    floor.floor_count = 3
    answers = [(np.array([0, 1, 2, 4]), a), (np.array([1, 2, 3, 4]), b)]
    rays, hits, ties = nearest_over_bricks(6, (np.array([2, 3, 4]), floor), answers)
    # ray 0: only A; ray 1: a tie at t = 2 (object 3 < 7: B); ray 2: A at 5 beats B at 4? no,
    # B at 4 is nearer; ray 3: the floor at 5 beats B at 6; ray 4: A and B tie at 9 (B, the
    # lower id) and the floor at 9.5 is farther; ray 5: nothing.
    assert ties == 2
    assert hits.floor_count == 1
    # floor first, then the sphere set, then other objects, each in ray order
    assert rays.tolist() == [3, 1, 2, 4, 0]
    assert hits.material.tolist() == [99, 30, 30, 30, 70]
    assert hits.t.tolist() == [5.0, 2.0, 4.0, 9.0, 1.0]
    # the floor loses an exact tie with an object, as in one BVH's hit records
    floor.t[:] = [4.0, 6.0, 9.0]
    rays, hits, _ = nearest_over_bricks(6, (np.array([2, 3, 4]), floor), answers)
    assert rays.tolist() == [1, 2, 3, 4, 0] and hits.floor_count == 0


def test_an_exact_tie_between_bricks_goes_to_the_lower_object_id() -> None:
    # Two overlapping spheres mirrored about x = 0: a ray in that plane, along z, computes the
    # same float32 t on both (only x enters as its square), so every ray that hits is a tie.
    scene = rt.Scene(floor=None)
    scene.add_sphere((-0.5, 0.0, 0.0), 1.0, "mirror")  # object 0
    scene.add_sphere((0.5, 0.0, 0.0), 1.0, "matte")  # object 1
    partition = scene_partition(scene, 2)
    assert [scene_brick(scene, partition, b).object_ids.tolist() for b in (0, 1)] == [[0], [1]]
    y = np.linspace(-0.8, 0.8, 41, dtype=np.float32)
    origins = np.stack([np.zeros_like(y), y, np.full_like(y, -5.0)])
    directions = np.tile(np.array([[0.0], [0.0], [1.0]], np.float32), (1, len(y)))
    with local_brick_set(scene, partition) as brick_set, SceneGeometry(scene) as one:
        rays, hits = brick_set.intersect_compact(origins, directions)
        one_rays, one_hits = one.intersect_compact(origins, directions)
    assert np.array_equal(rays, one_rays) and len(rays) == len(y)
    assert np.array_equal(hits.t, one_hits.t)
    assert brick_set.traffic.ties == len(y)
    assert set(hits.material.tolist()) == {scene.material_index("mirror")}
