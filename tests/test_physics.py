"""Shading functions (embree_rt/shading.py) against closed-form optics and scalar references.

References are written independently in float64 NumPy or plain Python ``math``: the exact
Fresnel equations, Snell's law in the form n1 sinθi = n2 sinθt, the mirror law, and a per-ray
scalar Blinn-Phong (Mitsuba's check_vectorization idea: the batched result equals the loop).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from embree_rt import shading
from embree_rt.materials import Checker

GLASS = 1.52
CRITICAL_ANGLE = math.asin(1.0 / GLASS)  # leaving glass into air


def random_unit(rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, 3) float64 directions uniform on the sphere."""
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def at_angles(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 unit directions hitting the plane y = 0 from above at ``angles`` (radians) from
    the normal, and the (n, 3) normal +y (on the incident side)."""
    d = np.stack([np.sin(angles), -np.cos(angles), np.zeros_like(angles)], axis=1)
    n = np.tile([0.0, 1.0, 0.0], (len(angles), 1))
    return d.astype(np.float32), n.astype(np.float32)


def exact_fresnel(cos_i: float, n1: float, n2: float) -> float:
    """Unpolarized dielectric reflectance from the Fresnel equations (1 on TIR)."""
    sin2_t = (n1 / n2) ** 2 * (1.0 - cos_i**2)
    if sin2_t > 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin2_t)
    r_s = ((n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)) ** 2
    r_p = ((n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)) ** 2
    return 0.5 * (r_s + r_p)


# -- Fresnel --------------------------------------------------------------------------------------


@pytest.mark.parametrize("n1, n2", [(1.0, GLASS), (GLASS, 1.0)], ids=["entering", "leaving"])
def test_fresnel_at_normal_incidence_is_the_classic_four_percent(n1: float, n2: float) -> None:
    expected = ((1.52 - 1.0) / 2.52) ** 2
    assert expected == pytest.approx(0.0426, abs=1e-4)
    r = shading.fresnel_schlick(np.array([1.0], np.float32), n1, n2)
    assert r.dtype == np.float32 and r.shape == (1,)
    assert r[0] == pytest.approx(0.0426, abs=1e-4)
    assert r[0] == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("n1, n2", [(1.0, GLASS), (GLASS, 1.0)], ids=["entering", "leaving"])
def test_fresnel_is_one_at_grazing_and_monotone_in_angle(n1: float, n2: float) -> None:
    angles = np.linspace(0.0, math.pi / 2, 2001)
    r = shading.fresnel_schlick(np.cos(angles).astype(np.float32), n1, n2)
    assert r[-1] == pytest.approx(1.0, abs=1e-6)
    assert np.all(np.diff(r.astype(np.float64)) >= -1e-6), "reflectance must grow with angle"
    assert np.all((r >= 0.0) & (r <= 1.0))


def test_fresnel_leaving_glass_is_exactly_one_past_the_critical_angle() -> None:
    beyond = np.linspace(CRITICAL_ANGLE + 1e-4, math.pi / 2, 500)
    r = shading.fresnel_schlick(np.cos(beyond).astype(np.float32), GLASS, 1.0)
    assert np.all(r == 1.0)
    below = np.linspace(0.0, CRITICAL_ANGLE - 1e-4, 500)
    r = shading.fresnel_schlick(np.cos(below).astype(np.float32), GLASS, 1.0)
    assert np.all(r < 1.0)
    # Entering glass there is no critical angle: below 1 everywhere short of grazing.
    r = shading.fresnel_schlick(np.cos(beyond[:-1]).astype(np.float32), 1.0, GLASS)
    assert np.all(r < 1.0)


@pytest.mark.parametrize("n1, n2", [(1.0, GLASS), (GLASS, 1.0)], ids=["entering", "leaving"])
def test_schlick_stays_close_to_the_exact_fresnel_equations(n1: float, n2: float) -> None:
    # Schlick's approximation is within 0.035 of the exact reflectance for glass both ways, as
    # long as the cosine on the rarer side is used; the incident cosine on the way out would be
    # off by up to 0.96 near the critical angle.
    cosines = np.linspace(0.0, 1.0, 1001)
    r = shading.fresnel_schlick(cosines.astype(np.float32), n1, n2)
    exact = np.array([exact_fresnel(c, n1, n2) for c in cosines])
    np.testing.assert_allclose(r, exact, atol=0.04)


def test_fresnel_takes_per_ray_indices() -> None:
    cosines = np.array([1.0, 1.0, 0.2, 0.2], np.float32)
    n1 = np.array([1.0, 2.0, 1.0, 1.33], np.float32)
    n2 = np.array([2.0, 1.0, 1.33, 1.0], np.float32)
    r = shading.fresnel_schlick(cosines, n1, n2)
    assert r[0] == pytest.approx(1.0 / 9.0, rel=1e-5)
    assert r[1] == pytest.approx(1.0 / 9.0, rel=1e-5)
    r0 = (0.33 / 2.33) ** 2
    assert r[2] == pytest.approx(r0 + (1 - r0) * 0.8**5, rel=1e-5)
    assert r[3] == 1.0  # sin θt = 1.33 * sqrt(1 - 0.04) > 1


# -- refraction and reflection --------------------------------------------------------------------


def incident_pairs(seed: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Random float32 unit directions d and unit normals n with d·n < 0 (n on the incident side)."""
    rng = np.random.default_rng(seed)
    n = random_unit(rng, count)
    d = random_unit(rng, count)
    d *= -np.sign(np.einsum("ij,ij->i", d, n))[:, None]
    return d.astype(np.float32), n.astype(np.float32)


@pytest.mark.parametrize("n1, n2", [(1.0, GLASS), (GLASS, 1.0), (1.0, 2.4), (1.33, 1.0)], ids=str)
def test_refraction_obeys_snell_and_flags_total_internal_reflection(n1: float, n2: float) -> None:
    d, n = incident_pairs(seed=int(n1 * 100 + n2 * 10), count=4000)
    t, tir = shading.refract(d, n, n1 / n2)
    assert t.dtype == np.float32 and t.shape == d.shape and tir.dtype == bool

    d64, n64, t64 = d.astype(np.float64), n.astype(np.float64), t.astype(np.float64)
    cos_i = -np.einsum("ij,ij->i", d64, n64)
    sin_i = np.sqrt(np.maximum(0.0, 1.0 - cos_i**2))
    sin_t_closed_form = n1 / n2 * sin_i
    # TIR exactly where the closed-form sin θt exceeds 1 (away from float32 rounding at 1).
    clear = np.abs(sin_t_closed_form - 1.0) > 1e-5
    assert clear.mean() > 0.99
    np.testing.assert_array_equal(tir[clear], sin_t_closed_form[clear] > 1.0)
    if n1 < n2:
        assert not tir.any()
    else:
        assert tir.sum() > 100  # the sample reaches past the critical angle

    np.testing.assert_allclose(np.linalg.norm(t64, axis=1), 1.0, atol=1e-6)
    # Coplanar with d and n: no component along d × n.
    np.testing.assert_allclose(np.einsum("ij,ij->i", t64, np.cross(d64, n64)), 0.0, atol=1e-5)

    ok = ~tir
    sin_t = np.linalg.norm(np.cross(t64[ok], n64[ok]), axis=1)
    np.testing.assert_allclose(n1 * sin_i[ok], n2 * sin_t, atol=2e-5)
    assert np.all(np.einsum("ij,ij->i", t64[ok], n64[ok]) < 0.0)  # carries on through
    # Snell in vector form: the tangential component scales by n1/n2, same side of the normal.
    tangent_d = d64 - np.einsum("ij,ij->i", d64, n64)[:, None] * n64
    tangent_t = t64 - np.einsum("ij,ij->i", t64, n64)[:, None] * n64
    np.testing.assert_allclose(tangent_t[ok], n1 / n2 * tangent_d[ok], atol=2e-5)

    mirror = d64 - 2.0 * np.einsum("ij,ij->i", d64, n64)[:, None] * n64
    np.testing.assert_allclose(t64[tir], mirror[tir], atol=1e-6)


def test_refraction_at_normal_incidence_goes_straight_through() -> None:
    d, n = at_angles(np.zeros(3))
    for eta in (1.0 / GLASS, GLASS, 1.0):
        t, tir = shading.refract(d, n, eta)
        assert not tir.any()
        np.testing.assert_allclose(t, d, atol=1e-7)


def test_refraction_takes_per_ray_eta() -> None:
    angles = np.full(2, math.radians(50.0))
    d, n = at_angles(angles)
    t, tir = shading.refract(d, n, np.array([1.0 / GLASS, GLASS], np.float32))
    assert tir.tolist() == [False, True]  # 50° is past asin(1/1.52) ≈ 41.1° only going out
    assert math.hypot(t[0, 0], t[0, 2]) == pytest.approx(math.sin(angles[0]) / GLASS, abs=1e-6)
    np.testing.assert_allclose(t[1], [d[1, 0], -d[1, 1], 0.0], atol=1e-6)


def test_reflection_keeps_length_and_angle_and_is_an_involution() -> None:
    rng = np.random.default_rng(5)
    n = random_unit(rng, 1000).astype(np.float32)
    # Not unit on purpose: reflection is an isometry whatever the length.
    d = (random_unit(rng, 1000) * rng.uniform(0.1, 10.0, (1000, 1))).astype(np.float32)
    r = shading.reflect(d, n)
    assert r.dtype == np.float32 and r.shape == d.shape
    d64, n64, r64 = d.astype(np.float64), n.astype(np.float64), r.astype(np.float64)
    length = np.linalg.norm(d64, axis=1)
    np.testing.assert_allclose(np.linalg.norm(r64, axis=1), length, rtol=1e-5)
    # Same angle to the normal on the other side (cosines, so every length weighs the same).
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", r64, n64) / length,
        -np.einsum("ij,ij->i", d64, n64) / length,
        atol=1e-6,
    )
    # The tangential part is unchanged, and reflecting twice gives d back.
    tangent_d = d64 - np.einsum("ij,ij->i", d64, n64)[:, None] * n64
    tangent_r = r64 - np.einsum("ij,ij->i", r64, n64)[:, None] * n64
    np.testing.assert_allclose(tangent_r / length[:, None], tangent_d / length[:, None], atol=1e-6)
    twice = shading.reflect(r, n).astype(np.float64)
    np.testing.assert_allclose(twice / length[:, None], d64 / length[:, None], atol=2e-6)


# -- Blinn-Phong ----------------------------------------------------------------------------------


def scalar_blinn_phong(normal, to_viewer, to_light, color, diffuse, specular, shininess, light):
    """One ray, plain Python floats: the model as the materials docstring states it."""
    n_dot_l = sum(a * b for a, b in zip(normal, to_light, strict=True))
    if n_dot_l <= 0.0:
        return [0.0, 0.0, 0.0]
    half = [a + b for a, b in zip(to_light, to_viewer, strict=True)]
    half_length = math.sqrt(sum(h * h for h in half))
    n_dot_h = 0.0
    if half_length > 0.0:
        n_dot_h = max(0.0, sum(a * b / half_length for a, b in zip(normal, half, strict=True)))
    highlight = specular * n_dot_h**shininess
    return [diffuse * n_dot_l * c * li + highlight * li for c, li in zip(color, light, strict=True)]


def blinn_phong_inputs(seed: int, count: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    specular = rng.uniform(0.0, 1.0, count)
    specular[rng.random(count) < 0.3] = 0.0  # matte rows take the no-highlight path
    return {
        "normal": random_unit(rng, count).astype(np.float32),
        "to_viewer": random_unit(rng, count).astype(np.float32),
        "to_light": random_unit(rng, count).astype(np.float32),
        "color": rng.uniform(0.0, 1.0, (count, 3)).astype(np.float32),
        "diffuse": rng.uniform(0.0, 1.0, count).astype(np.float32),
        "specular": specular.astype(np.float32),
        "shininess": rng.choice([1.0, 8.0, 32.0, 64.0, 256.0], count).astype(np.float32),
        "light_rgb": rng.uniform(0.0, 3.0, (count, 3)).astype(np.float32),
    }


def test_blinn_phong_matches_a_scalar_loop() -> None:
    inputs = blinn_phong_inputs(seed=11, count=400)
    batched = shading.blinn_phong(**inputs)
    assert batched.dtype == np.float32 and batched.shape == (400, 3)
    columns = [inputs[k].tolist() for k in inputs]
    reference = np.array([scalar_blinn_phong(*row) for row in zip(*columns, strict=True)])
    lit = np.einsum("ij,ij->i", inputs["normal"], inputs["to_light"]) > 0
    assert 100 < lit.sum() < 300  # both branches are exercised
    assert (reference[lit & (inputs["specular"] > 0)] > 0).any()
    np.testing.assert_allclose(batched, reference, rtol=2e-4, atol=2e-6)


def test_blinn_phong_with_one_light_color_for_all_rays() -> None:
    inputs = blinn_phong_inputs(seed=12, count=50)
    light = np.array([0.5, 1.0, 2.0], np.float32)
    inputs["light_rgb"] = light
    batched = shading.blinn_phong(**inputs)
    columns = [inputs[k].tolist() for k in inputs if k != "light_rgb"]
    reference = np.array(
        [scalar_blinn_phong(*row, light.tolist()) for row in zip(*columns, strict=True)]
    )
    np.testing.assert_allclose(batched, reference, rtol=2e-4, atol=2e-6)


def test_blinn_phong_is_non_negative_and_dark_when_the_light_is_behind() -> None:
    inputs = blinn_phong_inputs(seed=13, count=2000)
    radiance = shading.blinn_phong(**inputs)
    assert np.all(radiance >= 0.0)

    # Light behind or in the tangent plane, viewer straight along the normal: the half vector
    # still leans toward N (N·H > 0), so only the N·L <= 0 guard keeps the highlight away.
    rng = np.random.default_rng(14)
    normal = random_unit(rng, 200)
    light = random_unit(rng, 200)
    light -= np.einsum("ij,ij->i", light, normal)[:, None] * normal  # tangent
    light[100:] -= rng.uniform(0.01, 2.0, (100, 1)) * normal[100:]  # strictly behind
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    normal, light = normal.astype(np.float32), light.astype(np.float32)
    # Rounding leaves the tangent rows a hair off the plane: keep the ones at or below it.
    light[np.einsum("ij,ij->i", normal, light) > 0] *= -1
    # And rows with N·L exactly 0 in float32.
    axes = np.eye(3, dtype=np.float32)
    normal = np.concatenate([normal, axes, axes])
    light = np.concatenate([light, np.roll(axes, 1, axis=0), -np.roll(axes, 2, axis=0)])
    assert np.all(np.einsum("ij,ij->i", normal, light) <= 0)
    assert (np.einsum("ij,ij->i", normal, light) == 0).sum() >= 6
    half = light + normal
    assert np.all(np.einsum("ij,ij->i", normal, half) > 0)
    count = len(normal)
    radiance = shading.blinn_phong(
        normal,
        normal.copy(),
        light,
        np.ones((count, 3), np.float32),
        np.ones(count, np.float32),
        np.ones(count, np.float32),
        np.full(count, 2.0, np.float32),
        np.ones((count, 3), np.float32),
    )
    assert np.all(radiance == 0.0)


def test_blinn_phong_peaks_when_light_normal_and_viewer_coincide() -> None:
    rng = np.random.default_rng(15)
    count = 3000
    normal = np.tile(random_unit(rng, 1), (count, 1)).astype(np.float32)
    color = np.array([0.9, 0.5, 0.1], np.float32)
    light_rgb = np.array([2.0, 1.0, 0.5], np.float32)
    diffuse, specular, shininess = 0.7, 0.4, 16.0

    def shade(to_viewer: np.ndarray, to_light: np.ndarray) -> np.ndarray:
        return shading.blinn_phong(
            normal,
            to_viewer,
            to_light,
            np.tile(color, (len(normal), 1)),
            np.full(len(normal), diffuse, np.float32),
            np.full(len(normal), specular, np.float32),
            np.full(len(normal), shininess, np.float32),
            light_rgb,
        )

    peak = shade(normal, normal)
    expected = diffuse * color * light_rgb + specular * light_rgb
    np.testing.assert_allclose(peak, np.tile(expected, (count, 1)), rtol=1e-5)
    others = shade(
        random_unit(rng, count).astype(np.float32), random_unit(rng, count).astype(np.float32)
    )
    assert np.all(others <= expected * (1 + 1e-5))
    assert (others > 0).any()


# -- sky and checker ------------------------------------------------------------------------------


def test_sky_blends_from_horizon_to_zenith_by_height() -> None:
    horizon = (1.0, 0.5, 0.25)
    zenith = (0.0, 0.25, 1.0)
    s = math.sqrt(0.5)
    directions = np.array(
        [[1, 0, 0], [0, 1, 0], [0, -1, 0], [s, s, 0], [0, -s, s], [0.8, 0.6, 0]], np.float32
    )
    colors = shading.sky(directions, horizon, zenith)
    assert colors.dtype == np.float32 and colors.shape == (6, 3)
    expected = [
        horizon,
        zenith,
        horizon,  # below the horizon the sky stays at the horizon color
        [(1 - s) * 1.0, (1 - s) * 0.5 + s * 0.25, (1 - s) * 0.25 + s * 1.0],
        horizon,
        [0.4, 0.4 * 0.5 + 0.6 * 0.25, 0.4 * 0.25 + 0.6],
    ]
    np.testing.assert_allclose(colors, np.array(expected), atol=1e-6)


def test_checker_cells_alternate_including_negative_coordinates() -> None:
    pattern = Checker(color_a=(1.0, 0.0, 0.0), color_b=(0.0, 0.0, 1.0), size=2.0)
    a, b = [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]
    points = np.array(
        [
            [0.5, 0.0, 0.5],  # cell (0, 0)
            [2.5, 0.0, 0.5],  # cell (1, 0)
            [-0.5, 0.0, 0.5],  # cell (-1, 0)
            [-0.5, 0.0, -0.5],  # cell (-1, -1)
            [-2.5, 0.0, 0.5],  # cell (-2, 0)
            [-4.5, 7.0, -2.5],  # cell (-3, -2): height does not matter
            [2.0, 0.0, 0.0],  # on a line: belongs to the cell above it, (1, 0)
            [-2.0, 0.0, -2.0],  # corner: cell (-1, -1)
            [1001.0, 0.0, -999.0],  # cell (500, -500)
        ],
        np.float32,
    )
    expected = [a, b, b, a, a, b, b, a, a]
    np.testing.assert_array_equal(shading.checker(points, pattern), np.array(expected))


def test_checker_matches_a_scalar_floor_parity_on_a_grid() -> None:
    pattern = Checker(color_a=(0.9, 0.9, 0.9), color_b=(0.1, 0.2, 0.3), size=0.75)
    rng = np.random.default_rng(16)
    points = rng.uniform(-20, 20, (3000, 3)).astype(np.float32)
    colors = shading.checker(points, pattern)
    for point, color in zip(points.tolist(), colors.tolist(), strict=True):
        parity = (math.floor(point[0] / 0.75) + math.floor(point[2] / 0.75)) % 2
        expected = pattern.color_a if parity == 0 else pattern.color_b
        assert color == pytest.approx(expected, abs=1e-7)


# -- finite at the edges --------------------------------------------------------------------------


def test_everything_stays_finite_at_grazing_incidence() -> None:
    rng = np.random.default_rng(17)
    n = random_unit(rng, 500)
    d = random_unit(rng, 500)
    d -= np.einsum("ij,ij->i", d, n)[:, None] * n  # d·n = 0 (to float rounding)
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    n = n.astype(np.float32)
    for eta in (1.0 / GLASS, 1.0, GLASS):
        t, tir = shading.refract(d, n, eta)
        assert np.isfinite(t).all()
        np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
        if eta > 1.0:
            assert tir.all()  # grazing from inside glass always reflects
    cos = np.abs(np.einsum("ij,ij->i", d, n))
    for n1, n2 in ((1.0, GLASS), (GLASS, 1.0)):
        r = shading.fresnel_schlick(cos, n1, n2)
        assert np.isfinite(r).all()
        np.testing.assert_allclose(r, 1.0, atol=1e-5)
    r = shading.fresnel_schlick(np.zeros(1, np.float32), 1.0, GLASS)
    assert r[0] == pytest.approx(1.0, abs=1e-7)
    assert np.isfinite(shading.reflect(d, n)).all()
    # Light and viewer both grazing, and light exactly opposite the viewer (zero half vector).
    ones = np.ones(500, np.float32)
    for to_viewer in (d, -d):
        radiance = shading.blinn_phong(
            n, to_viewer, d, np.ones((500, 3)), ones, ones, ones * 64, 1.0
        )
        assert np.isfinite(radiance).all() and (radiance >= 0).all()
    lit = (n + d).astype(np.float32) / np.float32(math.sqrt(2))
    radiance = shading.blinn_phong(n, -lit, lit, np.ones((500, 3)), ones, ones, ones * 64, 1.0)
    assert np.isfinite(radiance).all()
    sky = shading.sky(d * np.array([1, 0, 1], np.float32), (1, 1, 1), (0, 0, 1))
    np.testing.assert_array_equal(sky, np.ones((500, 3)))


def test_everything_stays_finite_across_the_onset_of_total_internal_reflection() -> None:
    # Every float32 cosine within a few thousand ulps of the critical one, so that whatever the
    # rounding, the exact switch to TIR (sin θt = 1) is among them.
    critical_cos = np.float32(math.cos(CRITICAL_ANGLE))
    steps = np.arange(-3000, 3001)
    cos = (critical_cos.view(np.int32) + steps).astype(np.int32).view(np.float32)
    sin = np.sqrt(1.0 - cos.astype(np.float64) ** 2)
    d = np.stack([sin, -cos.astype(np.float64), np.zeros_like(sin)], axis=1).astype(np.float32)
    n = np.tile(np.array([0.0, 1.0, 0.0], np.float32), (len(d), 1))
    t, tir = shading.refract(d, n, GLASS)
    assert np.isfinite(t).all()
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-6)
    assert tir.any() and not tir.all()
    # Cosines ascend with the steps (angles descend): TIR on one side of a single switch.
    switch = np.flatnonzero(np.diff(tir.astype(np.int8)))
    assert len(switch) == 1 and tir[0] and not tir[-1]
    # Just short of TIR the transmitted ray is nearly tangent; on TIR it is the mirror ray.
    np.testing.assert_allclose(t[tir], d[tir] * np.array([1, -1, 1], np.float32), atol=1e-6)
    assert np.all(np.abs(t[~tir][:10, 1]) < 0.01)
    r = shading.fresnel_schlick(cos, GLASS, 1.0)
    assert np.isfinite(r).all() and np.all(r <= 1.0)
    assert np.all(r[tir] == 1.0)
    assert np.all(r[~tir][:10] > 0.99)  # continuous: reflectance reaches 1 at the switch
