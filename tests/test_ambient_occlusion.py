"""Ambient occlusion against closed forms: the open share of a cosine-weighted hemisphere is 1
over an open plane, 1/2 at the foot of an infinite wall (by symmetry: the wall blocks exactly
the half of the hemisphere facing it, and cos θ is symmetric about the wall's normal), 0 inside
a closed sphere; and the image with it bitwise the same for any threads or batch size.

Sampling error: the estimate at the wall's foot averages n = points x samples independent
Bernoulli(1/2) rays, standard deviation 0.5 / sqrt(n); the test allows 4 of them (a false
failure once in ~16,000 runs, and these rays are fixed by the hash: the test is deterministic).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from embree_rt import Camera, PointLight, Scene, render
from embree_rt.ambient_occlusion import (
    AmbientOcclusion,
    HemisphereFrames,
    HemisphereQuery,
    cosine_local_directions,
    open_shares,
    orthonormal_frames,
)
from embree_rt.embree import Rays
from embree_rt.geometry import SceneGeometry
from embree_rt.tracing import hemisphere


def shares(scene: Scene, points, normals, samples: int, distance: float = math.inf) -> np.ndarray:
    points = np.asarray(points, np.float32)
    normals = np.asarray(normals, np.float32)
    with SceneGeometry(scene, threads=1) as geometry:
        return open_shares(
            geometry.occluded_hemispheres,
            points,
            normals,
            np.arange(points.shape[1], dtype=np.int64),
            AmbientOcclusion(samples, distance),
            seed=3,
        )


def up_normals(k: int) -> np.ndarray:
    return np.tile(np.array([[0.0], [1.0], [0.0]], np.float32), (1, k))


def numpy_hemisphere_rays(
    points: np.ndarray, normal: np.ndarray, sample_index: np.ndarray, samples: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(3, n) float32 origins and directions of the hemisphere rays as NumPy forms them: each
    point's frame gathered to its rays, ``t x + b y + n z`` and divided by its length (what
    the tracer forms inside its query, bit for bit)."""
    local = cosine_local_directions(sample_index, samples, seed)
    tangent, bitangent = orthonormal_frames(normal)
    repeat = np.repeat(np.arange(normal.shape[1]), samples)
    x, y, z = local
    directions = tangent[:, repeat] * x + bitangent[:, repeat] * y + normal[:, repeat] * z
    directions /= np.sqrt(np.sum(directions * directions, axis=0))
    return np.repeat(points, samples, axis=1), directions


def test_directions_are_unit_in_the_hemisphere_and_cosine_weighted() -> None:
    rng = np.random.default_rng(1)
    normal = rng.normal(size=(3, 50)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=0)
    samples = 400
    _, directions = numpy_hemisphere_rays(normal, normal, np.arange(50), samples, seed=9)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=0), 1.0, atol=1e-6)
    cosine = np.sum(directions * np.repeat(normal, samples, axis=1), axis=0)
    assert cosine.min() > -1e-6
    # cosine-weighted: cos θ has density 2 cos θ on [0, 1], mean 2/3, E[cos²] = 1/2
    n = cosine.size
    assert abs(cosine.mean() - 2 / 3) < 4 * math.sqrt(1 / 2 - 4 / 9) / math.sqrt(n)
    # uniform in azimuth about the normal: no preferred tangent direction
    assert np.abs(directions.mean(axis=1) - normal.mean(axis=1) * 2 / 3).max() < 0.02
    # the frames are orthonormal and right-handed (float64 products)
    tangent, bitangent = (f.astype(np.float64) for f in orthonormal_frames(normal))
    unit = normal.astype(np.float64)
    for u, v in ((tangent, bitangent), (tangent, unit), (bitangent, unit)):
        np.testing.assert_allclose(np.sum(u * v, axis=0), 0.0, atol=1e-6)
    np.testing.assert_allclose(np.cross(tangent.T, bitangent.T).T, unit, atol=1e-6)


@pytest.mark.parametrize("distance", [math.inf, 0.8])
@pytest.mark.parametrize("threads", [1, 2])
def test_the_query_answers_what_embree_answers_for_the_rays_numpy_forms(distance, threads):
    """The tracer forms each ray inside its query: its answers are ``BVH.occluded``'s (the same
    packets) for the rays NumPy forms, with the floor's test added, for spheres, a mesh, curves
    and the floor. Equal on every ISA: the directions are formed with the same float32
    operations in the same order (no fused multiply-add: numba's default contracts none), and
    the same rays in the same packets get the same answers from Embree."""
    scene = ao_scene()
    scene.add_mesh(trimesh.creation.box(extents=(1.0, 1.0, 1.0)), "matte")
    rng = np.random.default_rng(4)
    k, samples = 3000, 8
    points = np.c_[rng.uniform(-3, 3, k), rng.uniform(0.01, 1.6, k), rng.uniform(-3, 2, k)]
    points = points.T.astype(np.float32)
    normal = rng.normal(size=(3, k)).astype(np.float32)
    normal /= np.sqrt(np.sum(normal * normal, axis=0))
    index = rng.integers(0, 1 << 40, k)
    with SceneGeometry(scene, threads=threads) as geometry:
        origins, directions = numpy_hemisphere_rays(points, normal, index, samples, seed=5)
        expected = geometry.bvh.occluded(Rays(origins.T, directions.T, 0.0, np.float32(distance)))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (np.float32(geometry.labels.plane_y) - origins[1]) / directions[1]
        expected |= (t > 0) & (t <= np.float32(distance))
        local = cosine_local_directions(index, samples, seed=5)
        frames = HemisphereFrames(*orthonormal_frames(normal), normal)
        blocked = geometry.occluded_hemispheres(HemisphereQuery(points, frames, local, distance))
    np.testing.assert_array_equal(blocked, expected)
    assert 0.05 < blocked.mean() < 0.95  # both answers occur


@pytest.mark.parametrize("distance", [math.inf, 9.0])
def test_rays_probed_first_in_a_dense_packing_get_embree_s_answers(distance) -> None:
    """A cube of overlapping spheres (the particle benchmark's density, 0.8 a unit volume,
    radius 0.5), points on and inside its faces: the rays that run far inside the box are
    first asked over a probe (``hemisphere.scene_probe``) and again in full when it is open.
    Their answers are ``BVH.occluded``'s for the whole rays: bitwise on every ISA, as above
    (the rays are the same float32 rays; a probe is one of them with a shorter tfar). The
    test checks each path is taken: rays the probe blocks, rays the probe leaves open that
    the whole ray finds blocked, rays too short or too near the box's side to be probed."""
    rng = np.random.default_rng(11)
    side = (4000 / 0.8) ** (1 / 3)
    scene = Scene(camera=Camera(position=(0.0, 0.0, 3 * side), look_at=(0.0, 0.0, 0.0)))
    scene.add_spheres(rng.uniform(-side / 2, side / 2, (4000, 3)), np.full(4000, 0.5), "matte")
    scene.floor = None
    k, samples = 2000, 12
    points = rng.uniform(-side / 2, side / 2, (3, k)).astype(np.float32)
    points[2, : k // 2] = side / 2 + 0.5  # half on the face toward the camera
    normal = rng.normal(size=(3, k)).astype(np.float32)
    normal /= np.sqrt(np.sum(normal * normal, axis=0))
    index = rng.integers(0, 1 << 40, k)
    with SceneGeometry(scene, threads=2) as geometry:
        origins, directions = numpy_hemisphere_rays(points, normal, index, samples, seed=2)
        expected = geometry.bvh.occluded(Rays(origins.T, directions.T, 0.0, np.float32(distance)))
        probe = hemisphere.scene_probe(*geometry.bvh.bounds())
        by_probe = geometry.bvh.occluded(Rays(origins.T, directions.T, 0.0, probe.length))
        reach = origins + probe.reach * directions
        inside = (reach > probe.lower[:, None]) & (reach < probe.upper[:, None])
        probed = inside.all(axis=0)
        local = cosine_local_directions(index, samples, seed=2)
        frames = HemisphereFrames(*orthonormal_frames(normal), normal)
        blocked = geometry.occluded_hemispheres(HemisphereQuery(points, frames, local, distance))
    np.testing.assert_array_equal(blocked, expected)
    assert probe.length < distance
    assert (probed & by_probe).sum() > 1000
    assert (probed & ~by_probe & expected).sum() > 10
    assert (~probed & expected).sum() > 100 and (~probed & ~expected).sum() > 1000


def test_the_probe_is_a_share_of_the_box_diagonal_and_none_for_an_empty_box() -> None:
    """``BVH.bounds`` holds every sphere (Embree's box of their boxes); the probe is
    ``PROBE_SHARE`` of its diagonal; an empty BVH's box (lower > upper) gives no probe."""
    scene = Scene()
    scene.add_spheres([[0.0, 0.0, 0.0], [3.0, 4.0, 12.0]], [1.0, 0.5], "matte")
    with SceneGeometry(scene, threads=1) as geometry:
        lower, upper = geometry.bvh.bounds()
    assert np.all(lower <= [-1.0, -1.0, -1.0]) and np.all(upper >= [3.5, 4.5, 12.5])
    assert np.all(lower > [-1.001, -1.001, -1.001]) and np.all(upper < [3.501, 4.501, 12.501])
    probe = hemisphere.scene_probe(lower, upper)
    diagonal = math.dist(lower.tolist(), upper.tolist())
    assert probe.length == pytest.approx(diagonal * hemisphere.PROBE_SHARE, rel=1e-6)
    assert probe.reach == pytest.approx(probe.length * hemisphere.PROBED_REACH, rel=1e-6)
    empty = hemisphere.scene_probe(np.full(3, np.inf, np.float32), np.full(3, -np.inf, np.float32))
    assert empty.length == np.inf


def test_an_open_plane_has_ambient_occlusion_one() -> None:
    scene = Scene()  # the floor at y = 0 alone
    k = 300
    points = np.stack([np.linspace(-50, 50, k), np.full(k, 1e-4), np.linspace(3, -7, k)])
    np.testing.assert_array_equal(shares(scene, points, up_normals(k), 16), 1.0)


def test_the_foot_of_an_infinite_wall_has_ambient_occlusion_one_half() -> None:
    scene = Scene()  # floor y = 0, a wall x = 0 far larger than the points' distance to it
    wall = trimesh.Trimesh(
        vertices=[[0, 0, -1e4], [0, 0, 1e4], [0, 1e4, 1e4], [0, 1e4, -1e4]],
        faces=[[0, 1, 2], [0, 2, 3]],
    )
    scene.add_mesh(wall, "matte", smooth=False)
    k, samples = 400, 64
    points = np.stack([np.full(k, 1e-3), np.full(k, 1e-3), np.linspace(-5, 5, k)])
    share = shares(scene, points, up_normals(k), samples)
    sigma = 0.5 / math.sqrt(k * samples)
    assert abs(share.mean() - 0.5) < 4 * sigma
    # and half of that far from the wall's foot, on a wall's own face: a point on the wall
    # facing +x sees the floor block the lower half of its hemisphere
    on_wall = np.stack([np.full(k, 1e-3), np.full(k, 1e-3), np.linspace(-5, 5, k)])
    normals = np.tile(np.array([[1.0], [0.0], [0.0]], np.float32), (1, k))
    assert abs(shares(scene, on_wall, normals, samples).mean() - 0.5) < 4 * sigma


def test_inside_a_closed_sphere_ambient_occlusion_is_zero_and_distance_limits_it() -> None:
    scene = Scene(floor=None)
    scene.add_sphere((0.0, 0.0, 0.0), 2.0, "matte")
    rng = np.random.default_rng(2)
    k = 200
    points = (rng.uniform(-0.5, 0.5, size=(3, k))).astype(np.float32)
    normals = rng.normal(size=(3, k)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=0)
    np.testing.assert_array_equal(shares(scene, points, normals, 16), 0.0)
    # nothing lies within 1 of a point at most 0.87 from the centre of a sphere of radius 2
    np.testing.assert_array_equal(shares(scene, points, normals, 16, distance=1.0), 1.0)


def ao_scene() -> Scene:
    scene = Scene(camera=Camera(position=(0.0, 3.0, 7.0), look_at=(0.0, 0.5, 0.0)))
    scene.lights.append(PointLight(position=(3.0, 6.0, 4.0)))
    rng = np.random.default_rng(5)
    centers = np.c_[rng.uniform(-3, 3, 40), rng.uniform(0.2, 1.5, 40), rng.uniform(-3, 2, 40)]
    scene.add_spheres(centers, rng.uniform(0.2, 0.5, 40), "matte")
    scene.add_curves([[-3, 0.2, 1.5], [0, 1.2, 1.0], [3, 0.2, 1.5]], 0.15, "glossy")
    scene.render.ao = AmbientOcclusion(samples=6, distance=2.0)
    return scene


@pytest.mark.parametrize("threads, batch_size", [(2, 1000), (3, 777)])
def test_images_with_ambient_occlusion_are_bitwise_the_same_for_any_threads_or_batch(
    threads: int, batch_size: int
) -> None:
    """Each hit's rays are drawn from its camera sample's global index alone, each ray's answer
    is Embree's occlusion of that one ray (whatever packet or thread traces it), and a pixel's
    samples are summed in one order: so the bits cannot depend on the split, on any ISA."""
    scene = ao_scene()
    settings = {"width": 64, "height": 40, "spp": 2, "max_depth": 2}
    one = render(scene, threads=1, **settings).image
    assert (
        one.tobytes()
        == render(scene, threads=threads, batch_size=batch_size, **settings).image.tobytes()
    )
    # and AO changed the picture: darker than without it, nowhere brighter
    scene.render.ao = AmbientOcclusion()
    plain = render(scene, threads=1, **settings).image
    assert (one <= plain).all() and (one < plain).any()


def test_the_ao_aov_is_one_on_a_lone_convex_object_and_zero_inside_a_closed_one() -> None:
    lone = Scene(floor=None, camera=Camera(position=(0.0, 0.0, 6.0), look_at=(0.0, 0.0, 0.0)))
    lone.add_sphere((0.0, 0.0, 0.0), 1.5, "matte")
    aovs = render(lone, width=32, height=24, spp=1, aovs=("ao", "object_id")).aovs
    assert (aovs["object_id"] == 0).sum() > 100
    np.testing.assert_array_equal(aovs["ao"], 1.0)  # sphere and sky alike
    inside = Scene(floor=None, camera=Camera(position=(0.0, 0.0, 0.5), look_at=(0.0, 0.0, 0.0)))
    inside.add_sphere((0.0, 0.0, 0.0), 3.0, "matte")
    inside.render.ao = AmbientOcclusion(samples=8)
    aovs = render(inside, width=32, height=24, spp=1, aovs=("ao",)).aovs
    np.testing.assert_array_equal(aovs["ao"], 0.0)
    # limited to a distance shorter than the sphere's far side, some rays get out
    inside.render.ao = AmbientOcclusion(samples=8, distance=3.0)
    limited = render(inside, width=32, height=24, spp=1, aovs=("ao",)).aovs["ao"]
    assert 0.0 < limited.mean() < 1.0
