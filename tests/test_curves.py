"""Round tubes (Embree's round linear curves): hits against a float64 reference of the same
shape, their ids and materials in the AOVs, and the scene file's ``[[curves]]``.

The reference: a segment of a round linear curve is the convex hull of the spheres at its two
ends (a cone touching both, capped by them); a polyline is the union of its segments. Its
exact signed distance (the "round cone" distance, in closed form) is marched along each ray
in float64 until it is below 1e-12 of the scene's size, which finds the first crossing; the
normal is the distance's gradient there (central differences).
"""

from __future__ import annotations

import numpy as np
import pytest
from tolerances import position_atol

from embree_rt import Camera, PointLight, Scene, render
from embree_rt.embree import BVH, Rays
from embree_rt.scene.errors import SceneError
from embree_rt.scene.loader import load_scene
from embree_rt.scene.writer import save_scene


def round_cone_distance(p: np.ndarray, a, b, ra: float, rb: float) -> np.ndarray:
    """(n,) float64 signed distance from the (n, 3) points ``p`` to the convex hull of the
    spheres (a, ra) and (b, rb) (neither inside the other)."""
    ba = np.subtract(b, a)
    l2 = ba @ ba
    rr = ra - rb
    a2 = l2 - rr * rr
    pa = p - a
    y = pa @ ba
    z = y - l2
    x2 = np.sum((pa * l2 - np.outer(y, ba)) ** 2, axis=1)
    y2 = y * y * l2
    z2 = z * z * l2
    k = np.sign(rr) * rr * rr * x2
    return np.where(
        np.sign(z) * a2 * z2 > k,
        np.sqrt(x2 + z2) / l2 - rb,
        np.where(
            np.sign(y) * a2 * y2 < k,
            np.sqrt(x2 + y2) / l2 - ra,
            (np.sqrt(x2 * a2 / l2) + y * rr) / l2 - ra,
        ),
    )


def polyline_distance(p: np.ndarray, points: np.ndarray, radii: np.ndarray) -> np.ndarray:
    return np.min(
        [
            round_cone_distance(p, points[i], points[i + 1], radii[i], radii[i + 1])
            for i in range(len(points) - 1)
        ],
        axis=0,
    )


def march(origins, directions, points, radii, scale):
    """(n,) float64 first crossing t of each ray (inf: none within 100 scales)."""
    t = np.zeros(len(origins))
    live = np.ones(len(origins), bool)
    for _ in range(4000):
        d = polyline_distance(origins[live] + t[live, None] * directions[live], points, radii)
        t[live] += d
        done = d < 1e-12 * scale
        gone = t[live] > 100 * scale
        index = np.flatnonzero(live)
        t[index[gone]] = np.inf
        live[index[done | gone]] = False
        if not live.any():
            break
    t[live] = np.nan  # not settled: ambiguous (grazing), left out
    return t


def random_polyline(rng):
    points = np.cumsum(rng.normal(size=(5, 3)), axis=0)
    radii = rng.uniform(0.15, 0.4, size=5)
    return points, radii


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_curve_hits_match_a_float64_round_cone_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    points, radii = random_polyline(rng)
    center = points.mean(axis=0)
    scale = float(np.abs(points).max() + radii.max())
    n = 3000
    # rays from a ball around the polyline toward points near it: hits, misses and grazes
    origins = center + _on_sphere(rng, n) * 4 * scale
    targets = points[rng.integers(0, 5, n)] + rng.normal(size=(n, 3)) * 0.4
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    with BVH(threads=1) as bvh:
        bvh.add_curves(points, radii, np.arange(4))
        bvh.commit()
        hits = bvh.intersect(Rays(origins.astype(np.float32), directions.astype(np.float32)))
    o64 = origins.astype(np.float32).astype(np.float64)
    d64 = directions.astype(np.float32).astype(np.float64)
    reference = march(o64, d64, points.astype(np.float32), radii.astype(np.float32), scale)
    settled = ~np.isnan(reference)
    assert settled.mean() > 0.95
    hit = np.isfinite(reference)
    # Embree solves the cone in float32 with the hit refined along the ray: measured on AVX2,
    # its t lay within 9.5e-6 of the reference at 4 scales' distance (10 ulps of the origins);
    # 64 ulps leave room for other ISAs and stay far below a wrong radius or cap (~1e-2).
    atol = position_atol(origins, ulps=64)
    both = settled & hit & (hits.geom_id >= 0)
    assert 0.3 * n < both.sum()
    # hit or miss may differ only where a ray grazes the surface, decided by rounding
    assert (settled & (hit != (hits.geom_id >= 0))).sum() < 0.01 * n
    np.testing.assert_allclose(hits.t[both], reference[both], atol=atol, rtol=0)
    # Embree's geometric normal of a round curve is the surface's (unnormalised)
    normal = hits.normal[both] / np.linalg.norm(hits.normal[both], axis=1)[:, None]
    at = o64[both] + reference[both, None] * d64[both]
    h = 1e-6 * scale
    gradient = np.stack(
        [
            polyline_distance(at + h * e, points, radii)
            - polyline_distance(at - h * e, points, radii)
            for e in np.eye(3)
        ],
        axis=1,
    )
    gradient /= np.linalg.norm(gradient, axis=1)[:, None]
    cosine = np.sum(normal * gradient, axis=1)
    assert np.quantile(cosine, 0.99) > 1 - 1e-5 and cosine.min() > 0.999


def _on_sphere(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_curves_ids_and_materials_in_the_aovs_and_their_normals() -> None:
    scene = Scene(
        floor=None,
        camera=Camera(position=(0.0, 0.0, 10.0), look_at=(0.0, 0.0, 0.0), fov=40.0),
    )
    scene.add_sphere((0.0, 2.0, 0.0), 0.8, "glossy")
    scene.add_curves([[-3.0, 0.0, 0.0], [3.0, 0.0, 0.0]], 0.5, "metal")
    tube = scene.add_curves([[-3.0, -2.0, 0.0], [3.0, -2.0, 0.0]], 0.5, color=(0.2, 0.4, 0.9))
    result = render(
        scene, width=64, height=64, spp=1, aovs=("object_id", "material_id", "normal", "albedo")
    )
    ids, materials = result.aovs["object_id"], result.aovs["material_id"]
    names = scene.material_names
    # the centre column: sphere (row ~19), the first tube (32), the coloured tube (45)
    column = 32
    assert ids[19, column] == 0 and names[materials[19, column]] == "glossy"
    assert ids[32, column] == 1 and names[materials[32, column]] == "metal"
    assert ids[45, column] == 2 and names[materials[45, column]] == tube.material
    np.testing.assert_allclose(result.aovs["albedo"][45, column], (0.2, 0.4, 0.9), rtol=1e-6)
    assert list(np.unique(ids)) == [-1, 0, 1, 2]
    # the normal across the tube at x = 0: (0, y - 0, z) / r of the cylinder's point there
    rows = np.flatnonzero(ids[:, column] == 1)
    normals = result.aovs["normal"][rows, column]
    assert normals[0, 1] > 0.5 and normals[-1, 1] < -0.5  # top edge up, bottom edge down
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(normals[:, 0], 0.0, atol=1e-3)


def test_scene_files_read_and_write_curves(tmp_path) -> None:
    path = tmp_path / "tubes.toml"
    path.write_text(
        "[[curves]]\npoints = [[0, 0, 0], [1, 0, 0], [1, 1, 0]]\nradii = [0.1, 0.2, 0.1]\n"
        'material = "metal"\n\n[[curves]]\npoints = [[0, 0, 1], [0, 2, 1]]\nradius = 0.05\n'
        "color = [1, 0, 0]\n"
    )
    scene = load_scene(path)
    assert len(scene.curves) == 2
    np.testing.assert_array_equal(scene.curves[0].starts, [0, 1])
    np.testing.assert_allclose(scene.curves[0].radii, [0.1, 0.2, 0.1])
    assert scene.materials[scene.curves[1].material].color == (1.0, 0.0, 0.0)
    # bonds: separate segments, written one polyline each and read back the same
    scene.add_curves(np.arange(12.0).reshape(4, 3), 0.3, starts=[0, 2])
    save_scene(scene, tmp_path / "again.toml")
    again = load_scene(tmp_path / "again.toml")
    assert len(again.curves) == 4
    np.testing.assert_array_equal(again.curves[2].points, np.arange(6.0).reshape(2, 3))
    np.testing.assert_array_equal(again.curves[3].points, np.arange(6.0, 12.0).reshape(2, 3))
    assert again.curves[1].material == scene.curves[1].material
    bad = {
        "points = [[0, 0, 0]]\nradius = 1\n": "at least two",
        "points = [[0, 0, 0], [1, 1]]\nradius = 1\n": "row 1",
        "points = [[0, 0, 0], [1, 1, 1]]\n": "give radius",
        "points = [[0, 0, 0], [1, 1, 1]]\nradii = [1]\n": "expected 2 numbers",
        "points = [[0, 0, 0], [1, 1, 1]]\nradius = 0\n": "radius",
        'points = [[0, 0, 0], [1, 1, 1]]\nradius = 1\nmaterial = "gold"\n': "undefined material",
    }
    for text, problem in bad.items():
        path.write_text("[[curves]]\n" + text)
        with pytest.raises(SceneError, match=problem):
            load_scene(path)


def test_bricks_hold_curve_sets_and_render_the_image_of_one_bvh() -> None:
    from embree_rt.bricks import local_brick_set, scene_partition
    from embree_rt.bricks.contents import scene_brick
    from embree_rt.camera import camera_frame
    from embree_rt.integrator import Integrator

    scene = Scene(camera=Camera(position=(0.0, 4.0, 12.0), look_at=(0.0, 0.5, 0.0)))
    scene.lights.append(PointLight(position=(3.0, 8.0, 6.0)))
    rng = np.random.default_rng(4)
    for x in np.linspace(-4, 4, 6):
        points = np.c_[np.full(6, x), np.linspace(0.2, 2.5, 6), rng.normal(size=6) * 0.5]
        scene.add_curves(points, rng.uniform(0.1, 0.3, 6), "glossy")
    scene.add_spheres(
        rng.uniform(-4, 4, (20, 3)) * [1, 0, 1] + [0, 0.4, 0], np.full(20, 0.4), "matte"
    )
    partition = scene_partition(scene, 3)
    held = [scene_brick(scene, partition, k) for k in range(3)]
    # every curve set in exactly one brick, under its own object id
    curve_ids = np.concatenate([b.object_ids[len(b.scene.sphere_radii) :] for b in held])
    assert sorted(curve_ids) == list(scene.curve_ids())
    assert (
        sum(len(b.scene.curves) for b in held) == 6 and max(len(b.scene.curves) for b in held) < 6
    )
    frame = camera_frame(scene.camera, 96, 64)
    options = {"spp": 1, "max_depth": 3, "seed": 0}
    with Integrator(scene, threads=1) as one:
        expected, _ = one.render_image(frame, **options)
    with Integrator(scene, threads=1, tracer=local_brick_set(scene, partition)) as parts:
        image, _ = parts.render_image(frame, **options)
    assert image.tobytes() == expected.tobytes()
