"""Spheres moved between frames (``BVH.move_spheres``, ``Renderer.update_spheres``): a refitted
BVH answers as a BVH freshly built on the moved spheres does, and exact ties go one way in any
tree.

Why bitwise: the user-geometry callbacks compute a hit from the sphere's own float32 data and
the ray alone (the same float64 arithmetic whatever tree called them), and of several spheres
met at one float32 distance the lowest ids take the hit (``user_spheres``), so the nearest hit
is the least (t, ids) over the spheres a ray meets: a function of the spheres, not the tree.
Embree's point spheres compute their own hits the same way in any tree of the same ISA.
"""

from __future__ import annotations

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.embree import Rays
from embree_rt.embree.bvh import BVH

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


def test_exact_ties_go_to_the_lowest_index_in_any_tree() -> None:
    # every sphere twice (same centre, same radius): each hit is an exact tie of two spheres;
    # the stored order (and so the tree) differs with the order given, the winner must not
    centers, radii = moving_spheres(1, count=200)
    origins, directions = camera_rays()
    doubled_centers = np.concatenate([centers[0], centers[0]])
    doubled_radii = np.concatenate([radii, radii])
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
