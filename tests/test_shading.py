"""Shading functions against closed-form optics and per-element scalar references."""

from __future__ import annotations

import math

import numpy as np
import pytest

from embree_rt import shading
from embree_rt.materials import Checker

IOR = 1.52
CRITICAL = math.asin(1 / IOR)
rng = np.random.default_rng(2024)


def unit_vectors(k: int, generator: np.random.Generator = rng) -> np.ndarray:
    v = generator.normal(size=(k, 3))
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def incidence(k: int, angles: np.ndarray, generator: np.random.Generator = rng):
    """Random unit normals and unit directions meeting them at ``angles`` (from the normal)."""
    n = unit_vectors(k, generator).astype(np.float64)
    tangent = np.cross(n, unit_vectors(k, generator))
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    d = np.sin(angles)[:, None] * tangent - np.cos(angles)[:, None] * n
    return d.astype(np.float32), n.astype(np.float32)


# -- scalar references, written from the formulas -------------------------------------------


def schlick_reference(cos_i: float, n1: float, n2: float) -> float:
    if n1 == n2:
        return 0.0
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1 - cos_i * cos_i))
    if sin_t > 1:
        return 1.0
    cos = math.sqrt(1 - sin_t * sin_t) if n1 > n2 else cos_i
    return r0 + (1 - r0) * (1 - cos) ** 5


def refract_reference(d: np.ndarray, n: np.ndarray, eta: float) -> tuple[np.ndarray, bool]:
    """pbrt's Refract, one ray at a time, in float64."""
    cos_i = -float(d @ n)
    sin2_t = eta * eta * max(0.0, 1 - cos_i * cos_i)
    if sin2_t > 1:
        r = d - 2 * (d @ n) * n
        return r / np.linalg.norm(r), True
    t = eta * d + (eta * cos_i - math.sqrt(1 - sin2_t)) * n
    return t / np.linalg.norm(t), False


def blinn_phong_reference(n, v, lt, color, kd, ks, shininess, light) -> np.ndarray:
    n_dot_l = float(n @ lt)
    if n_dot_l <= 0:
        return np.zeros(3)
    h = (lt + v) / np.linalg.norm(lt + v)
    return kd * n_dot_l * color * light + ks * max(0.0, float(n @ h)) ** shininess * light


# -- Fresnel ----------------------------------------------------------------------------------


def test_fresnel_at_normal_incidence_is_r0_both_ways() -> None:
    r0 = ((IOR - 1) / (IOR + 1)) ** 2
    into = shading.fresnel_schlick(np.array([1.0], np.float32), 1.0, IOR)
    out_of = shading.fresnel_schlick(np.array([1.0], np.float32), IOR, 1.0)
    assert into.dtype == np.float32
    assert into[0] == pytest.approx(0.0426, abs=1e-4)
    assert out_of[0] == pytest.approx(0.0426, abs=1e-4)
    assert into[0] == pytest.approx(r0, rel=1e-6) and out_of[0] == pytest.approx(r0, rel=1e-6)


def test_fresnel_rises_monotonically_to_one_at_grazing() -> None:
    angles = np.linspace(0.0, math.pi / 2, 500)
    into = shading.fresnel_schlick(np.cos(angles).astype(np.float32), 1.0, IOR)
    assert (np.diff(into) >= 0).all()
    assert into[-1] == pytest.approx(1.0, abs=1e-6)
    # Leaving glass: monotone up to the critical angle, then exactly 1.
    out_of = shading.fresnel_schlick(np.cos(angles).astype(np.float32), IOR, 1.0)
    assert (np.diff(out_of) >= 0).all()
    assert (out_of[angles > CRITICAL + 1e-4] == 1.0).all()


def test_total_internal_reflection_starts_at_the_critical_angle() -> None:
    angles = np.array([CRITICAL - 1e-3, CRITICAL + 1e-3])
    d, n = incidence(2, angles)
    directions, tir = shading.refract(d, n, IOR)
    assert tir.tolist() == [False, True]
    reflectance = shading.fresnel_schlick(np.cos(angles).astype(np.float32), IOR, 1.0)
    assert 0.0 < reflectance[0] < 1.0
    assert reflectance[1] == 1.0
    # The refracted ray just below the critical angle skims the surface: about 90 degrees.
    assert math.degrees(math.acos(-float(directions[0] @ n[0]))) > 85
    np.testing.assert_allclose(directions[1], shading.reflect(d, n)[1], atol=1e-6)


def test_fresnel_matches_a_scalar_loop_with_per_ray_indices() -> None:
    k = 400
    cos_i = rng.random(k).astype(np.float32)
    n1 = rng.choice([1.0, 1.33, 1.52, 2.4], k).astype(np.float32)
    n2 = rng.choice([1.0, 1.33, 1.52, 2.4], k).astype(np.float32)
    batched = shading.fresnel_schlick(cos_i, n1, n2)
    expected = [
        schlick_reference(float(c), float(a), float(b))
        for c, a, b in zip(cos_i, n1, n2, strict=True)
    ]
    np.testing.assert_allclose(batched, expected, rtol=1e-5, atol=1e-6)
    assert (n1 == n2).any() and (batched[n1 == n2] == 0.0).all()


# -- refraction and reflection ----------------------------------------------------------------


@pytest.mark.parametrize("eta", [1 / IOR, IOR, 1 / 1.33, 1.33])
def test_refraction_obeys_snell_in_the_plane_of_incidence(eta: float) -> None:
    k = 300
    limit = math.asin(min(1.0, 1 / eta)) - 1e-3
    angles = rng.uniform(0, min(limit, math.radians(89.9)), k)
    d, n = incidence(k, angles)
    t, tir = shading.refract(d, n, eta)
    assert t.dtype == np.float32 and not tir.any()
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
    sin_i = np.linalg.norm(np.cross(d, n), axis=1)
    sin_t = np.linalg.norm(np.cross(t, n), axis=1)
    # n1 sin(theta_i) = n2 sin(theta_t) with eta = n1 / n2.
    np.testing.assert_allclose(eta * sin_i, sin_t, atol=3e-5)
    coplanar = np.einsum("ij,ij->i", np.cross(d, n), t)
    np.testing.assert_allclose(coplanar, 0.0, atol=3e-6)
    assert (np.einsum("ij,ij->i", t, n) < 0).all()  # carried on through the surface
    # Bent toward the normal going into the denser medium, away from it coming out.
    if eta < 1:
        assert (sin_t <= sin_i + 1e-6).all()
    else:
        assert (sin_t >= sin_i - 1e-6).all()


def test_refraction_matches_a_scalar_loop_including_total_internal_reflection() -> None:
    k = 400
    angles = rng.uniform(0, math.pi / 2, k)
    d, n = incidence(k, angles)
    eta = rng.choice([1 / IOR, IOR, 1.0, 2.4], k).astype(np.float32)
    batched, tir = shading.refract(d, n, eta)
    assert tir.any() and not tir.all()
    for i in range(k):
        expected, expected_tir = refract_reference(
            d[i].astype(float), n[i].astype(float), float(eta[i])
        )
        if abs(np.sin(angles[i]) * eta[i] - 1) > 1e-4:  # leave the knife edge to the next test
            assert tir[i] == expected_tir
            np.testing.assert_allclose(batched[i], expected, atol=2e-5)


def test_grazing_and_exact_critical_incidence_stay_finite() -> None:
    # d·n = 0 exactly, both ways through the surface.
    d = np.array([[1.0, 0.0, 0.0]] * 2, np.float32)
    n = np.array([[0.0, 1.0, 0.0]] * 2, np.float32)
    directions, tir = shading.refract(d, n, np.array([1 / IOR, IOR], np.float32))
    assert np.isfinite(directions).all()
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-6)
    assert tir.tolist() == [False, True]
    # sin(theta_i) = 1 / eta to float32 precision: refraction or TIR, either way a unit vector.
    cos_critical = np.float32(math.sqrt(1 - 1 / IOR**2))
    d = np.array([[1 / IOR, -cos_critical, 0.0]], np.float32)
    directions, _ = shading.refract(d, n[:1], IOR)
    assert np.isfinite(directions).all()
    assert np.linalg.norm(directions) == pytest.approx(1.0, abs=1e-6)
    edge_cases = np.array([0.0, 1.0, cos_critical, np.nextafter(cos_critical, 0)], np.float32)
    for n1, n2 in ((1.0, IOR), (IOR, 1.0), (1.0, 1.0)):
        reflectance = shading.fresnel_schlick(edge_cases, n1, n2)
        assert np.isfinite(reflectance).all()
        assert ((reflectance >= 0) & (reflectance <= 1)).all()


def test_reflection_keeps_angle_and_length_in_the_plane_of_incidence() -> None:
    k = 500
    n = unit_vectors(k)
    d = (unit_vectors(k) * rng.uniform(0.1, 10, (k, 1))).astype(np.float32)
    r = shading.reflect(d, n)
    assert r.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), np.linalg.norm(d, axis=1), rtol=1e-5)
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", r, n), -np.einsum("ij,ij->i", d, n), rtol=1e-4, atol=1e-5
    )
    np.testing.assert_allclose(np.einsum("ij,ij->i", np.cross(d, n), r), 0.0, atol=1e-4)
    expected = [d[i] - 2 * float(d[i] @ n[i]) * n[i] for i in range(k)]
    np.testing.assert_allclose(r, expected, rtol=1e-5, atol=1e-5)


def test_normalize_and_dot() -> None:
    v = rng.normal(size=(200, 3)).astype(np.float32) * 100
    v[7] = 0
    unit = shading.normalize(v)
    assert unit.dtype == np.float32
    np.testing.assert_array_equal(unit[7], 0.0)
    rows = np.delete(np.arange(200), 7)
    np.testing.assert_allclose(np.linalg.norm(unit[rows], axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(
        unit[rows], v[rows] / np.linalg.norm(v[rows], axis=1)[:, None], rtol=1e-6
    )
    w = rng.normal(size=(200, 3)).astype(np.float32)
    np.testing.assert_allclose(
        shading.dot(v, w), [float(a @ b) for a, b in zip(v, w, strict=True)], rtol=1e-5
    )


# -- Blinn-Phong --------------------------------------------------------------------------------


def random_surface(k: int):
    color = rng.random((k, 3)).astype(np.float32)
    diffuse = rng.random(k).astype(np.float32)
    specular = rng.random(k).astype(np.float32)
    specular[::4] = 0.0
    shininess = rng.uniform(1, 256, k).astype(np.float32)
    light = rng.uniform(0, 3, (k, 3)).astype(np.float32)
    return color, diffuse, specular, shininess, light


def test_blinn_phong_matches_a_scalar_loop() -> None:
    k = 400
    normal, viewer, to_light = unit_vectors(k), unit_vectors(k), unit_vectors(k)
    color, kd, ks, shininess, light = random_surface(k)
    batched = shading.blinn_phong(normal, viewer, to_light, color, kd, ks, shininess, light)
    assert batched.shape == (k, 3) and batched.dtype == np.float32
    for i in range(k):
        expected = blinn_phong_reference(
            normal[i], viewer[i], to_light[i], color[i], kd[i], ks[i], shininess[i], light[i]
        )
        np.testing.assert_allclose(batched[i], expected, rtol=2e-4, atol=1e-6)


def test_blinn_phong_is_never_negative_and_dark_behind_the_surface() -> None:
    k = 1000
    normal, viewer, to_light = unit_vectors(k), unit_vectors(k), unit_vectors(k)
    color, kd, ks, shininess, light = random_surface(k)
    radiance = shading.blinn_phong(normal, viewer, to_light, color, kd, ks, shininess, light)
    assert np.isfinite(radiance).all() and (radiance >= 0).all()
    behind = np.einsum("ij,ij->i", normal, to_light) <= 0
    assert behind.any()
    np.testing.assert_array_equal(radiance[behind], 0.0)
    assert (radiance[~behind].sum(axis=1) > 0).any()


def test_blinn_phong_peaks_when_light_normal_and_viewer_align() -> None:
    k = 2000
    color, kd, ks, shininess, light = random_surface(1)
    args = (np.tile(color, (k, 1)), np.repeat(kd, k), np.repeat(ks, k), np.repeat(shininess, k))
    lights = np.tile(light, (k, 1))
    normal = np.tile(np.float32([0, 0, 1]), (k, 1))
    peak = shading.blinn_phong(normal, normal, normal, *args, lights)
    np.testing.assert_allclose(peak[0], kd[0] * color[0] * light[0] + ks[0] * light[0], rtol=1e-6)
    elsewhere = shading.blinn_phong(normal, unit_vectors(k), unit_vectors(k), *args, lights)
    assert (elsewhere <= peak + 1e-6).all()


def test_blinn_phong_is_finite_for_opposite_light_and_viewer() -> None:
    # L = -V makes the half vector zero; N·L = 0 is the grazing edge of the lit side.
    normal = np.float32([[0, 1, 0], [0, 1, 0]])
    to_light = np.float32([[1, 0, 0], [0.6, 0.8, 0]])
    viewer = -to_light
    ones = np.ones(2, np.float32)
    radiance = shading.blinn_phong(
        normal, viewer, to_light, np.ones((2, 3), np.float32), ones, ones, ones * 32, np.ones(3)
    )
    assert np.isfinite(radiance).all()
    np.testing.assert_array_equal(radiance[0], 0.0)
    np.testing.assert_allclose(radiance[1], 0.8, rtol=1e-6)  # diffuse only, no highlight


# -- sky and checker ------------------------------------------------------------------------------


def test_sky_blends_horizon_to_zenith() -> None:
    horizon, zenith = (0.8, 0.88, 1.0), (0.25, 0.45, 0.9)
    directions = unit_vectors(300)
    directions[:3] = [[0, 1, 0], [1, 0, 0], [0, -1, 0]]
    colors = shading.sky(directions, horizon, zenith)
    assert colors.shape == (300, 3) and colors.dtype == np.float32
    np.testing.assert_allclose(colors[0], zenith, rtol=1e-6)
    np.testing.assert_allclose(colors[1], horizon, rtol=1e-6)
    np.testing.assert_allclose(colors[2], horizon, rtol=1e-6)
    for direction, color in zip(directions, colors, strict=True):
        t = min(max(float(direction[1]), 0.0), 1.0)
        expected = [(1 - t) * h + t * z for h, z in zip(horizon, zenith, strict=True)]
        np.testing.assert_allclose(color, expected, rtol=1e-5)


@pytest.mark.parametrize("size", [1.0, 0.37, 5.0])
def test_checker_matches_floor_parity(size: float) -> None:
    pattern = Checker(color_a=(1.0, 0.5, 0.0), color_b=(0.0, 0.25, 1.0), size=size)
    points = rng.uniform(-20, 20, (400, 3)).astype(np.float32)
    points[:4] = [
        [0.5 * size, 0, 0.5 * size],
        [-0.5 * size, 0, 0.5 * size],
        [0, 0, 0],
        [-1e-3, 0, 0],
    ]
    colors = shading.checker(points, pattern)
    assert colors.shape == (400, 3) and colors.dtype == np.float32
    for point, color in zip(points, colors, strict=True):
        parity = math.floor(float(point[0]) / size) + math.floor(float(point[2]) / size)
        expected = pattern.color_a if parity % 2 == 0 else pattern.color_b
        np.testing.assert_array_equal(color, np.float32(expected))
    np.testing.assert_array_equal(colors[0], np.float32(pattern.color_a))
    np.testing.assert_array_equal(colors[1], np.float32(pattern.color_b))  # across x = 0
    np.testing.assert_array_equal(colors[2], np.float32(pattern.color_a))
    np.testing.assert_array_equal(colors[3], np.float32(pattern.color_b))
