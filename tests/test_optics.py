"""Closed-form optics, the camera's contract, and the film's atomic writes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from embree_rt import Camera, Scene, film, shading
from embree_rt.camera import camera_frame, primary_rays
from embree_rt.integrator import surface_offset
from embree_rt.shapes import SceneGeometry

IOR = 1.52


def incident(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions hitting the plane y = 0 from above at ``angles`` from the normal."""
    d = np.stack([np.sin(angles), -np.cos(angles), np.zeros_like(angles)], axis=1)
    n = np.tile([0.0, 1.0, 0.0], (len(angles), 1))
    return d.astype(np.float32), n.astype(np.float32)


def test_fresnel_at_normal_incidence_both_ways() -> None:
    r0 = ((IOR - 1) / (IOR + 1)) ** 2
    assert r0 == pytest.approx(0.0426, abs=1e-4)
    entering = shading.fresnel_schlick(np.array([1.0]), 1.0, IOR)
    leaving = shading.fresnel_schlick(np.array([1.0]), IOR, 1.0)
    assert entering[0] == pytest.approx(r0, rel=1e-5)
    assert leaving[0] == pytest.approx(r0, rel=1e-5)


def test_fresnel_grows_to_one_at_grazing_and_is_one_past_the_critical_angle() -> None:
    cosines = np.linspace(1.0, 0.0, 200)
    entering = shading.fresnel_schlick(cosines, 1.0, IOR)
    assert np.all(np.diff(entering) >= -1e-7)
    assert entering[-1] == pytest.approx(1.0)
    critical = math.asin(1 / IOR)
    below = shading.fresnel_schlick(np.array([math.cos(critical - 1e-3)]), IOR, 1.0)
    beyond = shading.fresnel_schlick(np.array([math.cos(critical + 1e-3)]), IOR, 1.0)
    assert below[0] < 1.0
    assert beyond[0] == 1.0


def test_refraction_obeys_snell_and_total_internal_reflection_starts_at_the_critical_angle() -> (
    None
):
    angles = np.linspace(0.0, math.radians(89), 300)
    d, n = incident(angles)
    refracted, tir = shading.refract(d, n, 1.0 / IOR)
    assert not tir.any()
    sin_t = np.linalg.norm(np.cross(refracted, n), axis=1)
    np.testing.assert_allclose(np.sin(angles), IOR * sin_t, atol=2e-5)
    np.testing.assert_allclose(np.linalg.norm(refracted, axis=1), 1.0, atol=1e-5)
    assert (refracted[:, 1] < 0).all()  # carried on through the surface
    np.testing.assert_allclose(refracted[:, 2], 0.0, atol=1e-6)  # in the plane of incidence

    critical = math.asin(1 / IOR)
    inside = np.array([critical - 1e-3, critical + 1e-3])
    d, n = incident(inside)
    out, tir = shading.refract(d, n, IOR)
    assert tir.tolist() == [False, True]
    np.testing.assert_allclose(out[1], shading.reflect(d, n)[1], atol=1e-6)
    assert np.isfinite(out).all()


def test_reflection_keeps_the_angle_and_is_an_involution() -> None:
    rng = np.random.default_rng(0)
    d = shading.normalize(rng.normal(size=(500, 3)).astype(np.float32))
    n = shading.normalize(rng.normal(size=(500, 3)).astype(np.float32))
    r = shading.reflect(d, n)
    np.testing.assert_allclose(shading.dot(r, n), -shading.dot(d, n), atol=1e-5)
    np.testing.assert_allclose(shading.reflect(r, n), d, atol=1e-5)


def test_blinn_phong_matches_a_scalar_loop() -> None:
    rng = np.random.default_rng(1)
    k = 300
    unit = lambda: shading.normalize(rng.normal(size=(k, 3)).astype(np.float32))  # noqa: E731
    normal, viewer, light = unit(), unit(), unit()
    color = rng.random((k, 3), dtype=np.float32)
    diffuse, specular = rng.random(k, dtype=np.float32), rng.random(k, dtype=np.float32)
    specular[::3] = 0
    shininess = rng.uniform(1, 100, k).astype(np.float32)
    light_rgb = np.array([0.9, 0.8, 0.7], np.float32)
    batched = shading.blinn_phong(
        normal, viewer, light, color, diffuse, specular, shininess, light_rgb
    )
    for i in range(k):
        n_dot_l = float(np.dot(normal[i], light[i]))
        expected = np.zeros(3)
        if n_dot_l > 0:
            half = (light[i] + viewer[i]) / np.linalg.norm(light[i] + viewer[i])
            highlight = specular[i] * max(0.0, float(np.dot(normal[i], half))) ** shininess[i]
            expected = diffuse[i] * n_dot_l * color[i] * light_rgb + highlight * light_rgb
        np.testing.assert_allclose(batched[i], expected, rtol=1e-4, atol=1e-6)
    assert (batched >= 0).all()


@pytest.mark.parametrize(
    "camera, width, height",
    [
        (Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 8, 8),
        (Camera(fov=0.0), 8, 8),
        (Camera(fov=180.0), 8, 8),
        (Camera(fov=float("nan")), 8, 8),
        (Camera(position=(1, 1, 1), look_at=(1, 1, 1)), 8, 8),
        (Camera(), 0, 8),
        (Camera(), 8, -1),
    ],
)
def test_degenerate_cameras_are_value_errors(camera: Camera, width: int, height: int) -> None:
    with pytest.raises(ValueError):
        camera_frame(camera, width, height)


def test_primary_rays_cover_the_field_of_view_and_split_into_batches() -> None:
    camera = Camera(position=(0, 0, 5), look_at=(0, 0, 0), fov=60)
    frame = camera_frame(camera, 9, 9)
    _, directions, pixel = primary_rays(frame, 4, 3, 0, 9 * 9 * 4)
    centre = directions[pixel == 40]
    # All four samples of the centre pixel point within half a pixel of look_at.
    angle_of_pixel = math.radians(60) / 9
    assert (np.arccos(np.clip(-centre[:, 2], -1, 1)) < angle_of_pixel).all()
    vertical = np.degrees(np.arcsin(np.abs(directions[:, 1]))).max() * 2
    assert 60 * 8 / 9 < vertical <= 60.0 + 1e-3
    _, again, _ = primary_rays(frame, 4, 3, 100, 50)
    np.testing.assert_array_equal(again, directions[100:150])


def test_a_failed_write_leaves_the_old_image_untouched(tmp_path: Path, monkeypatch) -> None:
    target = tmp_path / "image.png"
    film.save_image(np.full((2, 2, 3), 0.5, np.float32), target)
    before = target.read_bytes()

    def broken_writer(image, handle) -> None:
        handle.write(b"half an image")
        raise KeyboardInterrupt

    monkeypatch.setitem(film.WRITERS, ".png", broken_writer)
    with pytest.raises(KeyboardInterrupt):
        film.save_image(np.zeros((2, 2, 3), np.float32), target)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["image.png"]


@pytest.mark.parametrize("spheres", ["analytic", "mesh"])
@pytest.mark.parametrize("radius, distance", [(1e-3, 1.0), (1.0, 100.0), (1e2, 1e4)])
def test_rays_leaving_a_sphere_never_hit_it_again(spheres, radius, distance) -> None:
    """pbrt's re-intersection property, with the renderer's own hit points and offsets."""
    scene = Scene(floor=None)
    center = np.array([distance, distance * 0.5, -distance], np.float32)
    scene.add_sphere(tuple(center), radius)
    rng = np.random.default_rng(7)
    directions = shading.normalize(rng.normal(size=(2000, 3)).astype(np.float32))
    origins = (center - directions * radius * 3).astype(np.float32)
    with SceneGeometry(scene, spheres=spheres) as geometry:
        hits = geometry.intersect(origins, directions)
        assert hits.hit.mean() > 0.99
        points = hits.position[hits.hit]
        normals = hits.face_normal[hits.hit]
        offset = surface_offset(points, hits.scale[hits.hit])[:, None]
        outward = shading.normalize(rng.normal(size=points.shape).astype(np.float32))
        outward *= np.sign(shading.dot(outward, normals))[:, None]
        again = geometry.intersect(points + normals * offset, outward)
        assert not again.hit.any()
        inward = -outward
        through = geometry.intersect(points - normals * offset, inward)
        assert through.hit.all()  # from inside, every ray meets the far side
