"""Spheres moved between frames (``BVH.move_spheres``, ``Renderer.update_spheres``): a refitted
BVH answers as a BVH freshly built on the moved spheres does, and exact ties go one way in any
tree.

Why bitwise: the user-geometry callbacks compute a hit from the sphere's own float32 data and
the ray alone (the same float64 arithmetic whatever tree called them), and of several spheres
met at one float32 distance the lowest ids take the hit (``user_spheres``; a scene's spheres by
their index in the scene, whatever Morton rank the BVH holds them at), so the nearest hit is the
least (t, ids) over the spheres a ray meets: a function of the spheres, not the tree.
Embree's point spheres compute their own hits the same way in any tree of the same ISA.
"""

from __future__ import annotations

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.embree import Rays
from embree_rt.embree.bvh import BVH
from embree_rt.geometry import SceneGeometry

SIZE = {"width": 48, "height": 32, "spp": 1, "max_depth": 3, "seed": 2}


def moving_spheres(frames: int, count: int = 400, seed: int = 3):
    """(frames, count, 3) float32 centres drifting frame to frame, (count,) radii."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(-4.0, 4.0, (count, 3))
    velocity = rng.normal(0.0, 0.3, (count, 3))
    centers = np.stack([start + velocity * k for k in range(frames)]).astype(np.float32)
    radii = rng.uniform(0.05, 0.3, count).astype(np.float32)
    return centers, radii


def camera_rays(count: int = 4000, seed: int = 5):
    rng = np.random.default_rng(seed)
    origins = np.tile(np.float32([0.0, 0.0, -15.0]), (count, 1))
    directions = rng.normal(0.0, 0.25, (count, 3)).astype(np.float32)
    directions[:, 2] = 1.0
    return origins, directions


def fresh_hits(centers, radii, kind, origins, directions):
    with BVH() as fresh:
        fresh.add_spheres(centers, radii, kind)
        fresh.commit()
        return fresh.intersect(Rays(origins, directions))


@pytest.mark.parametrize("kind", ["user", "point"])
def test_refitted_bvh_answers_as_a_fresh_build_over_a_trajectory(kind: str) -> None:
    centers, radii = moving_spheres(6)
    origins, directions = camera_rays()
    with BVH(movable=True) as moving:
        geom_id = moving.add_spheres(centers[0], radii, kind)
        moving.commit()
        for frame in range(1, len(centers)):
            moving.move_spheres(geom_id, centers[frame], radii)
            hits = moving.intersect(Rays(origins, directions))
            expected = fresh_hits(centers[frame], radii, kind, origins, directions)
            for name in ("t", "prim_id", "geom_id", "normal"):
                np.testing.assert_array_equal(getattr(hits, name), getattr(expected, name))
            assert 0.05 < hits.hit.mean() < 0.95  # the rays see spheres and sky
            occluded = moving.occluded(Rays(origins, directions))
            np.testing.assert_array_equal(occluded, hits.hit)


@pytest.mark.parametrize("kind", ["user", "point"])
def test_spheres_moved_in_an_order_of_their_own_are_the_spheres_moved(kind: str) -> None:
    # The caller holds each frame's spheres shuffled (row j is sphere shuffle[j]) and says
    # where each sphere is (``order``): the BVH must answer as one built on the spheres in the
    # order first given. User spheres are stored in a spatial order of their own, so ``order``
    # is composed with it there; point spheres are stored as given.
    centers, radii = moving_spheres(4)
    origins, directions = camera_rays()
    shuffle = np.random.default_rng(11).permutation(len(radii))
    where = np.argsort(shuffle).astype(np.int32)  # the row of the shuffled arrays of sphere k
    with BVH(movable=True) as moving:
        geom_id = moving.add_spheres(centers[0], radii, kind)
        moving.commit()
        for frame in range(1, len(centers)):
            mine = centers[frame][shuffle], radii[shuffle]
            moving.move_spheres(geom_id, *mine, order=where)
            hits = moving.intersect(Rays(origins, directions))
            expected = fresh_hits(centers[frame], radii, kind, origins, directions)
            for name in ("t", "prim_id", "geom_id", "normal"):
                np.testing.assert_array_equal(getattr(hits, name), getattr(expected, name))
            assert 0.05 < hits.hit.mean() < 0.95
        outside = where.copy()
        outside[3] = 400
        with pytest.raises(ValueError, match="order: row 3 is 400"):
            moving.move_spheres(geom_id, *mine, order=outside)
        with pytest.raises(ValueError, match=r"order: expected shape \(400,\)"):
            moving.move_spheres(geom_id, *mine, order=where[:-1])


def twin_spheres(count: int) -> tuple[np.ndarray, np.ndarray]:
    """(2 count, 3) centres and (2 count,) radii: ``count`` spheres of the first frame, then
    each again (sphere i + count is sphere i's twin: every hit on one is an exact tie)."""
    centers, radii = moving_spheres(1, count=count)
    return np.concatenate([centers[0], centers[0]]), np.concatenate([radii, radii])


def test_exact_ties_go_to_the_lowest_index_in_any_tree() -> None:
    # every sphere twice (same centre, same radius): each hit is an exact tie of two spheres;
    # the stored order (and so the tree) differs with the order given, the winner must not
    doubled_centers, doubled_radii = twin_spheres(200)
    origins, directions = camera_rays()
    for permutation_seed in range(3):
        order = np.random.default_rng(permutation_seed).permutation(len(doubled_radii))
        hits = fresh_hits(doubled_centers[order], doubled_radii[order], "user", origins, directions)
        hit = hits.hit
        assert hit.mean() > 0.05
        winners = order[hits.prim_id[hit]]  # the index each winning sphere had before shuffling
        twins = np.where(winners < 200, winners + 200, winners - 200)
        position = np.argsort(order)  # where each sphere went
        # the winner is the one of the two twins given the lower index after shuffling
        assert np.all(position[winners] < position[twins])


def test_tie_keys_decide_exact_ties_whatever_order_the_spheres_come_in() -> None:
    # every sphere twice, shuffled, each keyed by its index before shuffling: every tie goes
    # to the twin with the lower key (the first copy), whichever index it was given
    doubled_centers, doubled_radii = twin_spheres(200)
    origins, directions = camera_rays()
    for permutation_seed in range(3):
        order = np.random.default_rng(permutation_seed).permutation(len(doubled_radii))
        with BVH() as bvh:
            bvh.add_spheres(doubled_centers[order], doubled_radii[order], tie_keys=order)
            bvh.commit()
            hits = bvh.intersect(Rays(origins, directions))
        assert hits.hit.mean() > 0.05
        assert np.all(order[hits.prim_id[hits.hit]] < 200)


def test_tie_keys_are_checked() -> None:
    centers, radii = moving_spheres(1, count=10)
    with BVH() as bvh:
        with pytest.raises(ValueError, match=r"tie_keys: expected shape \(10,\)"):
            bvh.add_spheres(centers[0], radii, tie_keys=np.arange(9))
        with pytest.raises(ValueError, match="tie_keys: row 4 is -1"):
            bvh.add_spheres(centers[0], radii, tie_keys=np.where(np.arange(10) == 4, -1, 0))
        with pytest.raises(ValueError, match="tie_keys: only user spheres"):
            bvh.add_spheres(centers[0], radii, kind="point", tie_keys=np.arange(10))


def tangent_pairs_scene(flip: bool, count: int = 40):
    """Pairs of spheres a ray enters at one point, exact in float32: sphere A (r = |s|) 2
    steps along the slope s from the ray's origin, sphere B (r = 2|s|) 3 steps along, both
    entered one step along (t = 1, direction s), so each ray's hit is an exact tie. With
    ``flip`` every pair lies the other way (-s), which swaps A's and B's Morton order. Pair i
    in its own plane z = 60 i; A is sphere 2i and B 2i + 1 for even i, the other way round for
    odd i. Returns the scene, origins and directions (count, 3) float32."""
    slopes = [(3.0, 4.0, 0.0), (-4.0, 3.0, 0.0), (2.0, 3.0, 6.0), (6.0, -2.0, -3.0)]
    centers, radii, origins, directions = [], [], [], []
    for i in range(count):
        slope = np.array(slopes[i % 4]) * (-1.0 if flip else 1.0)
        origin = np.array([i - 9.0, 5.0 - i, 60.0 * i])
        pair = [
            (origin + 2 * slope, np.linalg.norm(slope)),
            (origin + 3 * slope, 2 * np.linalg.norm(slope)),
        ]
        if i % 2:
            pair.reverse()
        centers += [pair[0][0], pair[1][0]]
        radii += [pair[0][1], pair[1][1]]
        origins.append(origin)
        directions.append(slope)
    scene = rt.Scene()
    scene.add_spheres(np.array(centers), np.array(radii), "matte")
    return scene, np.float32(origins), np.float32(directions)


def test_a_refitted_scene_breaks_exact_ties_as_a_fresh_build_does() -> None:
    # The scene's spheres reach the BVH in Morton order; a refitted BVH keeps frame 0's, a
    # fresh one takes the moved spheres'. Ties must go by the scene's own index in both.
    before, _, _ = tangent_pairs_scene(flip=False)
    after, origins, directions = tangent_pairs_scene(flip=True)
    with (
        SceneGeometry(before, movable=True) as moving,
        SceneGeometry(after) as fresh,
    ):
        rank_before = np.argsort(moving.sphere_index)  # each scene sphere's Morton rank
        rank_after = np.argsort(fresh.sphere_index)
        swapped = (rank_before[0::2] < rank_before[1::2]) != (rank_after[0::2] < rank_after[1::2])
        assert swapped.sum() >= 10, "the case swaps the Morton order of many pairs"
        moving.move_spheres(after.sphere_centers, after.sphere_radii)
        refitted = moving.bvh.intersect(Rays(origins, directions))
        expected = fresh.bvh.intersect(Rays(origins, directions))
        np.testing.assert_array_equal(refitted.t, np.ones(len(origins), np.float32))
        np.testing.assert_array_equal(expected.t, refitted.t)
        np.testing.assert_array_equal(refitted.normal, expected.normal)
        winner = moving.scene_sphere(refitted.prim_id)
        np.testing.assert_array_equal(winner, fresh.scene_sphere(expected.prim_id))
        np.testing.assert_array_equal(winner, 2 * np.arange(len(origins)))  # the lower index


def test_move_spheres_refuses_what_it_cannot_do() -> None:
    centers, radii = moving_spheres(2, count=10)
    with BVH() as fixed:
        geom_id = fixed.add_spheres(centers[0], radii)
        fixed.commit()
        with pytest.raises(RuntimeError, match="movable"):
            fixed.move_spheres(geom_id, centers[1], radii)
    with BVH(movable=True) as moving:
        geom_id = moving.add_spheres(centers[0], radii)
        with pytest.raises(RuntimeError):
            moving.move_spheres(geom_id, centers[1], radii)  # not committed yet
        moving.commit()
        with pytest.raises(ValueError, match="holds 10 spheres"):
            moving.move_spheres(geom_id, centers[1][:9], radii[:9])
        with pytest.raises(ValueError):
            moving.move_spheres(geom_id, centers[1], -radii)
        with pytest.raises(ValueError, match="not a set of spheres"):
            moving.move_spheres(geom_id + 1, centers[1], radii)


def field_scene(centers: np.ndarray, radii: np.ndarray) -> rt.Scene:
    scene = rt.Scene(camera=rt.Camera(position=(0.0, 2.0, -14.0), look_at=(0.0, 0.0, 0.0)))
    scene.lights.append(rt.PointLight(position=(3.0, 8.0, -6.0)))
    for k, (center, radius) in enumerate(zip(centers, radii, strict=True)):
        scene.add_sphere(tuple(center), float(radius), ("matte", "mirror", "glass")[k % 3])
    return scene


def test_renderer_frames_after_update_spheres_equal_fresh_renders() -> None:
    centers, radii = moving_spheres(3, count=120)
    with rt.Renderer(field_scene(centers[0], radii), movable=True) as renderer:
        for frame in range(1, len(centers)):
            renderer.update_spheres(centers[frame], radii)
            image = renderer.render(**SIZE).image
            alone = rt.render(field_scene(centers[frame], radii), **SIZE).image
            np.testing.assert_array_equal(image, alone)
        assert np.array_equal(renderer.scene.sphere_centers, centers[-1])
    with (
        rt.Renderer(field_scene(centers[0], radii), spheres="mesh") as meshes,
        pytest.raises(ValueError, match="no analytic spheres"),
    ):
        meshes.update_spheres(centers[1], radii)
