"""Shading functions (embree_rt/shading.py) against closed-form optics and scalar references.

References are written independently in float64 NumPy or plain Python ``math``: the exact
Fresnel equations, Schlick's formula, Snell's law in the form n1 sinθi = n2 sinθt, pbrt's
Refract one ray at a time, the mirror law, and a per-ray scalar Blinn-Phong (Mitsuba's
check_vectorization idea: the batched result equals the loop).

shading takes and returns (3, n) component-major vectors, one ray per column. The tests build
rays as (n, 3) rows, which suit ``np.cross`` and ``einsum``, hand them over as contiguous
(3, n) copies (``columns``) and read the results back as rows with ``.T``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from tolerances import EPS32, RTOL32, assert_close

from embree_rt import shading
from embree_rt.materials import Checker

GLASS = 1.52
CRITICAL_ANGLE = math.asin(1.0 / GLASS)  # leaving glass into air


def columns(rows: np.ndarray) -> np.ndarray:
    """The contiguous (3, n) float32 layout shading takes, from (n, 3) rows."""
    return np.ascontiguousarray(np.asarray(rows, np.float32).T)


def random_unit(rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, 3) float64 directions uniform on the sphere."""
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def at_angles(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 (n, 3) unit directions hitting the plane y = 0 from above at ``angles`` (radians)
    from the normal, and the (n, 3) normal +y (on the incident side)."""
    d = np.stack([np.sin(angles), -np.cos(angles), np.zeros_like(angles)], axis=1)
    n = np.tile([0.0, 1.0, 0.0], (len(angles), 1))
    return d.astype(np.float32), n.astype(np.float32)


def incidence(rng: np.random.Generator, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 (n, 3) random unit normals and unit directions meeting them at ``angles``."""
    n = random_unit(rng, len(angles))
    tangent = np.cross(n, random_unit(rng, len(angles)))
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    d = np.sin(angles)[:, None] * tangent - np.cos(angles)[:, None] * n
    return d.astype(np.float32), n.astype(np.float32)


# -- scalar references, written from the formulas -------------------------------------------------


def exact_fresnel(cos_i: float, n1: float, n2: float) -> float:
    """Unpolarized dielectric reflectance from the Fresnel equations (1 on TIR)."""
    sin2_t = (n1 / n2) ** 2 * (1.0 - cos_i**2)
    if sin2_t > 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin2_t)
    r_s = ((n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)) ** 2
    r_p = ((n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)) ** 2
    return 0.5 * (r_s + r_p)


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


def scalar_blinn_phong(normal, incoming, to_light, color, diffuse, specular, shininess, light):
    """One ray, plain Python floats: the model as the materials docstring states it (the
    viewer is at -incoming, against the ray that hit)."""
    n_dot_l = sum(a * b for a, b in zip(normal, to_light, strict=True))
    if n_dot_l <= 0.0:
        return [0.0, 0.0, 0.0]
    half = [a - b for a, b in zip(to_light, incoming, strict=True)]
    half_length = math.sqrt(sum(h * h for h in half))
    n_dot_h = 0.0
    if half_length > 0.0:
        n_dot_h = max(0.0, sum(a * b / half_length for a, b in zip(normal, half, strict=True)))
    highlight = specular * n_dot_h**shininess
    return [diffuse * n_dot_l * c * li + highlight * li for c, li in zip(color, light, strict=True)]


BLINN_PHONG_ARGUMENTS = (
    "normal",
    "incoming",
    "to_light",
    "color",
    "diffuse",
    "specular",
    "shininess",
    "light_rgb",
)


def blinn_phong_reference(inputs: dict[str, np.ndarray]) -> np.ndarray:
    """(n, 3) rows of ``scalar_blinn_phong`` over the columns of blinn_phong's inputs; a (3,)
    color or light_rgb is the same for every ray."""
    count = len(inputs["diffuse"])
    per_ray = []
    for name in BLINN_PHONG_ARGUMENTS:
        value = np.asarray(inputs[name])
        if name in ("color", "light_rgb") and value.ndim == 1:
            per_ray.append([value.tolist()] * count)
        elif value.ndim == 2:
            per_ray.append(value.T.tolist())
        else:
            per_ray.append(value.tolist())
    return np.array([scalar_blinn_phong(*ray) for ray in zip(*per_ray, strict=True)])


# -- Fresnel --------------------------------------------------------------------------------------


@pytest.mark.parametrize("n1, n2", [(1.0, GLASS), (GLASS, 1.0)], ids=["entering", "leaving"])
def test_fresnel_at_normal_incidence_is_the_classic_four_percent(n1: float, n2: float) -> None:
    expected = ((1.52 - 1.0) / 2.52) ** 2
    assert expected == pytest.approx(0.0426, abs=1e-4)
    r = shading.fresnel_schlick(np.array([1.0], np.float32), n1, n2)
    assert r.dtype == np.float32 and r.shape == (1,)
    assert r[0] == pytest.approx(0.0426, abs=1e-4)
    assert r[0] == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("n1, n2", [(1.0, GLASS), (GLASS, 1.0)], ids=["entering", "leaving"])
def test_fresnel_is_one_at_grazing_and_monotone_in_angle(n1: float, n2: float) -> None:
    angles = np.linspace(0.0, math.pi / 2, 2001)
    r = shading.fresnel_schlick(np.cos(angles).astype(np.float32), n1, n2)
    assert r[-1] == pytest.approx(1.0, abs=1e-6)
    assert np.all(np.diff(r) >= 0.0), "reflectance must grow with angle"
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


def test_fresnel_matches_a_scalar_loop_with_per_ray_indices() -> None:
    rng = np.random.default_rng(1)
    k = 400
    indices = [1.0, 1.33, 1.52, 2.4]
    # Four rays worked out by hand, then random ones against the scalar formula.
    cos_i = np.concatenate([[1.0, 1.0, 0.2, 0.2], rng.random(k)]).astype(np.float32)
    n1 = np.concatenate([[1.0, 2.0, 1.0, 1.33], rng.choice(indices, k)]).astype(np.float32)
    n2 = np.concatenate([[2.0, 1.0, 1.33, 1.0], rng.choice(indices, k)]).astype(np.float32)
    r = shading.fresnel_schlick(cos_i, n1, n2)
    assert r.dtype == np.float32 and r.shape == (k + 4,)
    assert r[0] == pytest.approx(1.0 / 9.0, rel=1e-5)
    assert r[1] == pytest.approx(1.0 / 9.0, rel=1e-5)
    r0 = (0.33 / 2.33) ** 2
    assert r[2] == pytest.approx(r0 + (1 - r0) * 0.8**5, rel=1e-5)
    assert r[3] == 1.0  # sin θt = 1.33 * sqrt(1 - 0.04) > 1
    expected = [
        schlick_reference(float(c), float(a), float(b))
        for c, a, b in zip(cos_i, n1, n2, strict=True)
    ]
    np.testing.assert_allclose(r, expected, rtol=1e-5, atol=1e-6)
    assert (n1 == n2).any() and (r[n1 == n2] == 0.0).all()


# -- refraction and reflection --------------------------------------------------------------------


def incident_pairs(seed: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Random float32 (n, 3) unit directions d and unit normals n with d·n < 0 (n on the
    incident side)."""
    rng = np.random.default_rng(seed)
    n = random_unit(rng, count)
    d = random_unit(rng, count)
    d *= -np.sign(np.einsum("ij,ij->i", d, n))[:, None]
    return d.astype(np.float32), n.astype(np.float32)


@pytest.mark.parametrize(
    "n1, n2", [(1.0, GLASS), (GLASS, 1.0), (1.0, 1.33), (1.33, 1.0), (1.0, 2.4)], ids=str
)
def test_refraction_obeys_snell_and_flags_total_internal_reflection(n1: float, n2: float) -> None:
    d, n = incident_pairs(seed=int(n1 * 100 + n2 * 10), count=4000)
    t, tir = shading.refract(columns(d), columns(n), n1 / n2)
    assert t.dtype == np.float32 and t.shape == (3, len(d))
    assert tir.dtype == bool and tir.shape == (len(d),)

    d64, n64, t64 = d.astype(np.float64), n.astype(np.float64), t.T.astype(np.float64)
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
    np.testing.assert_allclose(np.einsum("ij,ij->i", t64, np.cross(d64, n64)), 0.0, atol=3e-6)

    ok = ~tir
    sin_t = np.linalg.norm(np.cross(t64[ok], n64[ok]), axis=1)
    np.testing.assert_allclose(n1 * sin_i[ok], n2 * sin_t, atol=2e-5)
    assert np.all(np.einsum("ij,ij->i", t64[ok], n64[ok]) < 0.0)  # carries on through
    # Bent toward the normal going into the denser medium, away from it coming out.
    sin_i_ok = np.linalg.norm(np.cross(d64[ok], n64[ok]), axis=1)
    if n1 < n2:
        assert np.all(sin_t <= sin_i_ok + 1e-6)
    else:
        assert np.all(sin_t >= sin_i_ok - 1e-6)
    # Snell in vector form: the tangential component scales by n1/n2, same side of the normal.
    tangent_d = d64 - np.einsum("ij,ij->i", d64, n64)[:, None] * n64
    tangent_t = t64 - np.einsum("ij,ij->i", t64, n64)[:, None] * n64
    np.testing.assert_allclose(tangent_t[ok], n1 / n2 * tangent_d[ok], atol=2e-5)

    mirror = d64 - 2.0 * np.einsum("ij,ij->i", d64, n64)[:, None] * n64
    np.testing.assert_allclose(t64[tir], mirror[tir], atol=1e-6)


def test_refraction_matches_a_scalar_loop_with_per_ray_eta_and_total_internal_reflection() -> None:
    rng = np.random.default_rng(2)
    k = 400
    angles = rng.uniform(0, math.pi / 2, k)
    d, n = incidence(rng, angles)
    eta = rng.choice([1 / GLASS, GLASS, 1.0, 2.4], k).astype(np.float32)
    batched, tir = shading.refract(columns(d), columns(n), eta)
    assert batched.shape == (3, k)
    assert tir.any() and not tir.all()
    for i in range(k):
        expected, expected_tir = refract_reference(
            d[i].astype(float), n[i].astype(float), float(eta[i])
        )
        # The knife edge sin θt = 1 is left to the test at the onset of total internal reflection.
        if abs(np.sin(angles[i]) * eta[i] - 1) > 1e-4:
            assert tir[i] == expected_tir
            np.testing.assert_allclose(batched[:, i], expected, atol=2e-5)


def test_refraction_at_normal_incidence_goes_straight_through() -> None:
    d, n = at_angles(np.zeros(3))
    for eta in (1.0 / GLASS, GLASS, 1.0):
        t, tir = shading.refract(columns(d), columns(n), eta)
        assert not tir.any()
        np.testing.assert_allclose(t.T, d, atol=1e-7)


def test_reflection_keeps_length_and_angle_and_is_an_involution() -> None:
    rng = np.random.default_rng(5)
    n = random_unit(rng, 1000).astype(np.float32)
    # Not unit on purpose: reflection is an isometry whatever the length.
    d = (random_unit(rng, 1000) * rng.uniform(0.1, 10.0, (1000, 1))).astype(np.float32)
    r = shading.reflect(columns(d), columns(n))
    assert r.dtype == np.float32 and r.shape == (3, 1000)
    d64, n64, r64 = d.astype(np.float64), n.astype(np.float64), r.T.astype(np.float64)
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
    twice = shading.reflect(r, columns(n)).T.astype(np.float64)
    np.testing.assert_allclose(twice / length[:, None], d64 / length[:, None], atol=2e-6)


def test_normalize_and_dot() -> None:
    rng = np.random.default_rng(3)
    v = rng.normal(size=(200, 3)).astype(np.float32) * 100
    v[7] = 0
    unit = shading.normalize(columns(v))
    assert unit.dtype == np.float32 and unit.shape == (3, 200)
    unit = unit.T
    np.testing.assert_array_equal(unit[7], 0.0)
    rows = np.delete(np.arange(200), 7)
    np.testing.assert_allclose(np.linalg.norm(unit[rows], axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(
        unit[rows], v[rows] / np.linalg.norm(v[rows], axis=1)[:, None], rtol=1e-6
    )
    w = rng.normal(size=(200, 3)).astype(np.float32)
    dots = shading.dot(columns(v), columns(w))
    assert dots.dtype == np.float32 and dots.shape == (200,)
    # float64 reference (a float32 ``a @ b`` goes through BLAS, whose kernels differ per ISA);
    # a float32 dot product is known to rounding of its largest terms, not of itself (it can
    # cancel to near zero).
    v64, w64 = v.astype(np.float64), w.astype(np.float64)
    terms = np.abs(v64 * w64).sum(axis=1)
    assert_close(dots, np.einsum("ij,ij->i", v64, w64), atol=RTOL32 * terms, rtol=0.0)


# -- Blinn-Phong ----------------------------------------------------------------------------------


def blinn_phong_inputs(seed: int, count: int) -> dict[str, np.ndarray]:
    """Random blinn_phong arguments, vectors and colors as (3, count) columns."""
    rng = np.random.default_rng(seed)
    specular = rng.uniform(0.0, 1.0, count)
    specular[rng.random(count) < 0.3] = 0.0  # matte rows take the no-highlight path
    return {
        "normal": columns(random_unit(rng, count)),
        "incoming": columns(random_unit(rng, count)),
        "to_light": columns(random_unit(rng, count)),
        "color": columns(rng.uniform(0.0, 1.0, (count, 3))),
        "diffuse": rng.uniform(0.0, 1.0, count).astype(np.float32),
        "specular": specular.astype(np.float32),
        "shininess": rng.choice([1.0, 8.0, 32.0, 64.0, 256.0], count).astype(np.float32),
        "light_rgb": columns(rng.uniform(0.0, 3.0, (count, 3))),
    }


# NumPy's vectorised float32 log and exp (AVX2, AVX-512; they differ in the last bits per ISA)
# are within 4 ulps, libm's within 1. An error of k ulps in ln x becomes k·eps·|s ln x| once
# multiplied by s, and exp turns that absolute error into a relative one, so exp(s ln x) is
# within about (1 + |s ln x|)·k float32 epsilons of x^s. Measured: 2.1 on AVX2, 1.0 with libm.
POWER_ULPS = 8


def power_tolerance(exact: np.ndarray) -> np.ndarray:
    """The absolute error allowed for a float32 power whose exact float64 value is ``exact``:
    ``POWER_ULPS`` epsilons per unit of (1 + |s ln x|) = (1 + |ln exact|), relative, plus the
    smallest normal float32 (a subnormal result may be flushed to zero)."""
    exact = np.asarray(exact, np.float64)
    with np.errstate(divide="ignore"):
        log_size = np.abs(np.log(np.where(exact > 0, exact, 1.0)))
    return POWER_ULPS * EPS32 * (1.0 + log_size) * exact + np.finfo(np.float32).tiny


def test_power_matches_the_exact_power_and_clamps_negative_bases() -> None:
    rng = np.random.default_rng(21)
    base = rng.uniform(-0.2, 1.0, 5000).astype(np.float32)
    base[:3] = [0.0, 1.0, -0.0]
    exponent = rng.choice([1.0, 8.0, 64.0, 128.0, 256.0, 1000.0], 5000).astype(np.float32)
    exact = np.maximum(base.astype(np.float64), 0.0) ** exponent.astype(np.float64)
    result = shading.power(base, exponent)
    assert result.dtype == np.float32
    # exp(s ln x) loses accuracy in proportion to |s ln x| (see POWER_ULPS): a few millionths
    # where the power is visible at all, and never more than 1e-6 in absolute terms.
    assert_close(result, exact, atol=power_tolerance(exact), rtol=0.0)
    visible = exact > 1e-6
    assert_close(result[visible], exact[visible], atol=0.0, rtol=2e-5)
    assert_close(result, exact, atol=1e-6, rtol=0.0)
    assert result[0] == 0.0 and result[1] == 1.0 and result[2] == 0.0
    assert (result[base < 0] == 0).all()
    cubes = shading.power(base, np.float32(3.0))
    exact_cubes = np.maximum(base.astype(np.float64), 0.0) ** 3
    assert_close(cubes, exact_cubes, atol=power_tolerance(exact_cubes), rtol=0.0)


def test_blinn_phong_matches_a_scalar_loop() -> None:
    inputs = blinn_phong_inputs(seed=11, count=400)
    batched = shading.blinn_phong(**inputs)
    assert batched.dtype == np.float32 and batched.shape == (3, 400)
    reference = blinn_phong_reference(inputs)
    lit = shading.dot(inputs["normal"], inputs["to_light"]) > 0
    assert 100 < lit.sum() < 300  # both branches are exercised
    assert (reference[lit & (inputs["specular"] > 0)] > 0).any()
    np.testing.assert_allclose(batched.T, reference, rtol=2e-4, atol=1e-6)


def test_blinn_phong_with_one_light_color_for_all_rays() -> None:
    inputs = blinn_phong_inputs(seed=12, count=50)
    inputs["light_rgb"] = np.array([0.5, 1.0, 2.0], np.float32)
    batched = shading.blinn_phong(**inputs)
    assert batched.shape == (3, 50)
    np.testing.assert_allclose(batched.T, blinn_phong_reference(inputs), rtol=2e-4, atol=2e-6)


@pytest.mark.parametrize("light", ["per ray", "shared"])
@pytest.mark.parametrize(
    "mostly, few", [(340, 60), (201, 200)], ids=["far from half", "either side of half"]
)
def test_blinn_phong_is_the_same_with_most_or_few_rays_glossy(
    mostly: int, few: int, light: str
) -> None:
    # blinn_phong computes highlights over every column when more than half of them are glossy
    # (lit, with a specular term) and over a gathered subset otherwise. Two calls that differ
    # only in which rays have a specular term take one path each; both must match the scalar
    # loop, and the rays glossy in both must come out the same.
    count = 400
    assert mostly > count // 2 >= few
    rng = np.random.default_rng(18)
    normal = random_unit(rng, count)
    # Lights well above the surface (N·L >= 0.25) and viewers near their mirror direction
    # (N·V > 0), so every glossy ray has a highlight that shows.
    to_light = normal + 0.6 * random_unit(rng, count)
    to_light /= np.linalg.norm(to_light, axis=1, keepdims=True)
    mirror = 2 * np.einsum("ij,ij->i", normal, to_light)[:, None] * normal - to_light
    to_viewer = mirror + 0.2 * random_unit(rng, count)
    to_viewer /= np.linalg.norm(to_viewer, axis=1, keepdims=True)
    order = rng.permutation(count)
    glossy_mostly, glossy_few = order[:mostly], order[:few]  # the few are among the most
    # Rays that are not glossy in the first call: half are unlit despite a specular term.
    unlit = order[mostly:][::2]
    to_light[unlit] *= -1
    lit = np.einsum("ij,ij->i", normal, to_light) > 0
    assert lit.sum() == count - len(unlit)

    specular = rng.uniform(0.2, 1.0, count).astype(np.float32)
    inputs = {
        "normal": columns(normal),
        "incoming": columns(-to_viewer),
        "to_light": columns(to_light),
        "color": columns(rng.uniform(0.0, 1.0, (count, 3))),
        "diffuse": rng.uniform(0.0, 1.0, count).astype(np.float32),
        "specular": specular,
        "shininess": rng.uniform(1.0, 64.0, count).astype(np.float32),
        "light_rgb": (
            columns(rng.uniform(0.0, 3.0, (count, 3)))
            if light == "per ray"
            else np.array([0.5, 1.0, 2.0], np.float32)
        ),
    }
    results = {}
    for name, glossy in (("mostly", glossy_mostly), ("few", glossy_few)):
        specular = np.zeros(count, np.float32)
        specular[glossy] = inputs["specular"][glossy]
        specular[unlit] = inputs["specular"][unlit]
        case = {**inputs, "specular": specular}
        assert np.count_nonzero(lit & (specular > 0)) == len(glossy)
        radiance = shading.blinn_phong(**case)
        assert radiance.dtype == np.float32 and radiance.shape == (3, count)
        np.testing.assert_allclose(
            radiance.T, blinn_phong_reference(case), rtol=2e-4, atol=1e-6, err_msg=name
        )
        np.testing.assert_array_equal(radiance[:, unlit], 0.0)
        results[name] = radiance

    matte = shading.blinn_phong(**{**inputs, "specular": np.zeros(count, np.float32)})
    assert np.all(results["few"][:, glossy_few] > matte[:, glossy_few])  # highlights count
    # Both paths take the same float32 power, of differently laid out arrays: allow each its
    # power error (see POWER_ULPS) at the largest |s ln(N·H)| among these rays.
    half = (to_light + to_viewer)[glossy_few]
    n_dot_h = np.einsum("ij,ij->i", normal[glossy_few], half) / np.linalg.norm(half, axis=1)
    log_size = np.abs(inputs["shininess"][glossy_few] * np.log(n_dot_h)).max()
    assert_close(
        results["few"][:, glossy_few],
        results["mostly"][:, glossy_few],
        atol=0.0,
        rtol=2 * POWER_ULPS * EPS32 * (1.0 + log_size),
    )
    only_mostly = order[few:mostly]
    np.testing.assert_array_equal(results["few"][:, only_mostly], matte[:, only_mostly])


def test_blinn_phong_is_non_negative_and_dark_when_the_light_is_behind() -> None:
    inputs = blinn_phong_inputs(seed=13, count=2000)
    radiance = shading.blinn_phong(**inputs)
    assert np.isfinite(radiance).all() and np.all(radiance >= 0.0)
    behind = shading.dot(inputs["normal"], inputs["to_light"]) <= 0
    assert behind.any()
    np.testing.assert_array_equal(radiance[:, behind], 0.0)
    assert (radiance[:, ~behind].sum(axis=0) > 0).any()

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
        columns(normal),
        columns(normal),
        columns(light),
        np.ones((3, count), np.float32),
        np.ones(count, np.float32),
        np.ones(count, np.float32),
        np.full(count, 2.0, np.float32),
        np.ones((3, count), np.float32),
    )
    assert np.all(radiance == 0.0)


def test_blinn_phong_peaks_when_light_normal_and_viewer_coincide() -> None:
    rng = np.random.default_rng(15)
    count = 3000
    color = np.array([0.9, 0.5, 0.1], np.float32)
    light_rgb = np.array([2.0, 1.0, 0.5], np.float32)
    diffuse, specular, shininess = 0.7, 0.4, 16.0
    expected = diffuse * color * light_rgb + specular * light_rgb

    def shade(normal: np.ndarray, to_viewer: np.ndarray, to_light: np.ndarray) -> np.ndarray:
        return shading.blinn_phong(
            columns(normal),
            columns(-to_viewer),
            columns(to_light),
            columns(np.tile(color, (len(normal), 1))),
            np.full(len(normal), diffuse, np.float32),
            np.full(len(normal), specular, np.float32),
            np.full(len(normal), shininess, np.float32),
            light_rgb,
        ).T

    # Along an axis every product is exact; along a random normal, to float32 rounding.
    axis = np.tile(np.float32([0, 0, 1]), (count, 1))
    np.testing.assert_allclose(shade(axis, axis, axis), np.tile(expected, (count, 1)), rtol=1e-6)
    normal = np.tile(random_unit(rng, 1), (count, 1)).astype(np.float32)
    peak = shade(normal, normal, normal)
    np.testing.assert_allclose(peak, np.tile(expected, (count, 1)), rtol=1e-5)
    others = shade(normal, random_unit(rng, count), random_unit(rng, count))
    assert np.all(others <= expected * (1 + 1e-5))
    assert (others > 0).any()


def test_blinn_phong_is_finite_for_opposite_light_and_viewer() -> None:
    # L = -V makes the half vector zero; N·L = 0 is the grazing edge of the lit side.
    normal = np.float32([[0, 1, 0], [0, 1, 0]])
    to_light = np.float32([[1, 0, 0], [0.6, 0.8, 0]])
    incoming = to_light  # the viewer at -incoming = -L
    ones = np.ones(2, np.float32)
    radiance = shading.blinn_phong(
        columns(normal),
        columns(incoming),
        columns(to_light),
        np.ones((3, 2), np.float32),
        ones,
        ones,
        ones * 32,
        np.ones(3, np.float32),
    )
    assert np.isfinite(radiance).all()
    np.testing.assert_array_equal(radiance[:, 0], 0.0)
    np.testing.assert_allclose(radiance[:, 1], 0.8, rtol=1e-6)  # diffuse only, no highlight


# -- sky and checker ------------------------------------------------------------------------------


def test_sky_blends_from_horizon_to_zenith_by_height() -> None:
    horizon = (1.0, 0.5, 0.25)
    zenith = (0.0, 0.25, 1.0)
    s = math.sqrt(0.5)
    worked = np.array(
        [[1, 0, 0], [0, 1, 0], [0, -1, 0], [s, s, 0], [0, -s, s], [0.8, 0.6, 0]], np.float32
    )
    rng = np.random.default_rng(4)
    directions = np.concatenate([worked, random_unit(rng, 300).astype(np.float32)])
    colors = shading.sky(columns(directions), horizon, zenith)
    assert colors.dtype == np.float32 and colors.shape == (3, len(directions))
    colors = colors.T
    expected = [
        horizon,
        zenith,
        horizon,  # below the horizon the sky stays at the horizon color
        [(1 - s) * 1.0, (1 - s) * 0.5 + s * 0.25, (1 - s) * 0.25 + s * 1.0],
        horizon,
        [0.4, 0.4 * 0.5 + 0.6 * 0.25, 0.4 * 0.25 + 0.6],
    ]
    np.testing.assert_allclose(colors[: len(worked)], np.array(expected), atol=1e-6)
    for direction, color in zip(directions, colors, strict=True):
        t = min(max(float(direction[1]), 0.0), 1.0)
        blend = [(1 - t) * h + t * z for h, z in zip(horizon, zenith, strict=True)]
        np.testing.assert_allclose(color, blend, rtol=1e-5)


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
    colors = shading.checker(columns(points), pattern)
    assert colors.dtype == np.float32 and colors.shape == (3, len(points))
    np.testing.assert_array_equal(colors.T, np.array(expected))


@pytest.mark.parametrize("size", [1.0, 0.37, 0.75, 5.0])
def test_checker_matches_a_scalar_floor_parity(size: float) -> None:
    pattern = Checker(color_a=(1.0, 0.5, 0.0), color_b=(0.0, 0.25, 1.0), size=size)
    rng = np.random.default_rng(16)
    points = rng.uniform(-20, 20, (3000, 3)).astype(np.float32)
    points[:4] = [
        [0.5 * size, 0, 0.5 * size],
        [-0.5 * size, 0, 0.5 * size],
        [0, 0, 0],
        [-1e-3, 0, 0],
    ]
    colors = shading.checker(columns(points), pattern)
    assert colors.shape == (3, 3000) and colors.dtype == np.float32
    colors = colors.T
    for point, color in zip(points, colors, strict=True):
        parity = math.floor(float(point[0]) / size) + math.floor(float(point[2]) / size)
        expected = pattern.color_a if parity % 2 == 0 else pattern.color_b
        np.testing.assert_array_equal(color, np.float32(expected))
    np.testing.assert_array_equal(colors[0], np.float32(pattern.color_a))
    np.testing.assert_array_equal(colors[1], np.float32(pattern.color_b))  # across x = 0
    np.testing.assert_array_equal(colors[2], np.float32(pattern.color_a))
    np.testing.assert_array_equal(colors[3], np.float32(pattern.color_b))


# -- finite at the edges --------------------------------------------------------------------------


def test_everything_stays_finite_at_grazing_incidence() -> None:
    rng = np.random.default_rng(17)
    n = random_unit(rng, 500)
    d = random_unit(rng, 500)
    d -= np.einsum("ij,ij->i", d, n)[:, None] * n  # d·n = 0 (to float rounding)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # And two rays with d·n = 0 exactly.
    d = np.concatenate([d, [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]]).astype(np.float32)
    n = np.concatenate([n, [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]]).astype(np.float32)
    assert np.all(np.einsum("ij,ij->i", d[-2:], n[-2:]) == 0.0)
    count = len(d)
    for eta in (1.0 / GLASS, 1.0, GLASS):
        t, tir = shading.refract(columns(d), columns(n), eta)
        assert np.isfinite(t).all()
        np.testing.assert_allclose(np.linalg.norm(t, axis=0), 1.0, atol=1e-6)
        if eta > 1.0:
            assert tir.all()  # grazing from inside glass always reflects
        else:
            assert not tir.any()
    cos = np.abs(np.einsum("ij,ij->i", d, n))
    for n1, n2 in ((1.0, GLASS), (GLASS, 1.0)):
        r = shading.fresnel_schlick(cos, n1, n2)
        assert np.isfinite(r).all()
        np.testing.assert_allclose(r, 1.0, atol=1e-5)
    r = shading.fresnel_schlick(np.zeros(1, np.float32), 1.0, GLASS)
    assert r[0] == pytest.approx(1.0, abs=1e-7)
    # Fresnel at the ends of the range and on either side of the critical cosine, also across
    # an index-matched interface, stays a reflectance.
    cos_critical = np.float32(math.sqrt(1 - 1 / GLASS**2))
    edge_cases = np.array([0.0, 1.0, cos_critical, np.nextafter(cos_critical, 0)], np.float32)
    for n1, n2 in ((1.0, GLASS), (GLASS, 1.0), (1.0, 1.0)):
        r = shading.fresnel_schlick(edge_cases, n1, n2)
        assert np.isfinite(r).all()
        assert ((r >= 0) & (r <= 1)).all()
    assert np.isfinite(shading.reflect(columns(d), columns(n))).all()
    # Light and viewer both grazing, and light exactly opposite the viewer (zero half vector).
    ones = np.ones(count, np.float32)
    white = np.ones((3, count), np.float32)
    for to_viewer in (d, -d):
        radiance = shading.blinn_phong(
            columns(n), columns(-to_viewer), columns(d), white, ones, ones, ones * 64, ones[:3]
        )
        assert np.isfinite(radiance).all() and (radiance >= 0).all()
    lit = (n + d) / np.float32(math.sqrt(2))
    radiance = shading.blinn_phong(
        columns(n), columns(lit), columns(lit), white, ones, ones, ones * 64, ones[:3]
    )
    assert np.isfinite(radiance).all()
    sky = shading.sky(columns(d * np.array([1, 0, 1], np.float32)), (1, 1, 1), (0, 0, 1))
    np.testing.assert_array_equal(sky, np.ones((3, count)))


def test_everything_stays_finite_across_the_onset_of_total_internal_reflection() -> None:
    # Every float32 cosine within a few thousand ulps of the critical one, so that whatever the
    # rounding, the exact switch to TIR (sin θt = 1) is among them.
    critical_cos = np.float32(math.cos(CRITICAL_ANGLE))
    steps = np.arange(-3000, 3001)
    cos = (critical_cos.view(np.int32) + steps).astype(np.int32).view(np.float32)
    sin = np.sqrt(1.0 - cos.astype(np.float64) ** 2)
    d = np.stack([sin, -cos.astype(np.float64), np.zeros_like(sin)], axis=1).astype(np.float32)
    n = np.tile(np.array([0.0, 1.0, 0.0], np.float32), (len(d), 1))
    t, tir = shading.refract(columns(d), columns(n), GLASS)
    t = t.T
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


def test_odd_integers_is_fmod_by_two_bit_for_bit() -> None:
    rng = np.random.default_rng(6)
    values = np.concatenate(
        [
            np.floor(rng.normal(size=20_000) * 10.0 ** rng.integers(0, 20, 20_000)),
            np.arange(-5.0, 6.0),
            [2.0**53 - 1, 2.0**53, 2.0**53 + 2, -(2.0**53) + 1, 1e308, -1e308, -0.0],
            [np.inf, -np.inf, np.nan],
        ]
    )
    with np.errstate(invalid="ignore"):
        expected = np.fmod(values, 2.0) != 0.0
    assert np.array_equal(shading.odd_integers(values), expected)
    assert expected[-3:].all() and expected.any() and not expected.all()
