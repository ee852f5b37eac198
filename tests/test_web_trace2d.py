"""The 2D demo's tracer against closed-form optics in float64: hit points on the circles, the
law of reflection, Snell's law, total internal reflection past the critical angle, and the
Fresnel split of the light each child carries."""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import pytest

from embree_rt.materials import PRESETS
from embree_rt.web.trace2d import (
    GLASS,
    INTERNAL,
    LIGHT,
    MATTE,
    MIRROR,
    REFLECTION,
    REFRACTION,
    Layout,
    trace_layout,
)

BOX = (960.0, 600.0)
IOR = PRESETS["glass"].ior
TRANSPARENCY = PRESETS["glass"].transparency
# Points are float32 inside the tracer: a few ulps of coordinates up to ~1000, plus the offset
# that starts a child off the surface (2^-18 of the coordinates' size).
POINT_TOLERANCE = 1e-2
ANGLE_TOLERANCE = 1e-4  # radians: directions of unit float32 vectors from such points


@dataclass
class Path:
    points: np.ndarray
    weights: np.ndarray
    kinds: np.ndarray


def traced(layout: Layout) -> list[Path]:
    """The layout's light paths one by one, unpacked from ``LightPaths``."""
    packed = trace_layout(layout)
    bounds = packed.starts
    return [
        Path(packed.points[a:b], packed.weights[a - k : b - k - 1], packed.kinds[a - k : b - k - 1])
        for k, (a, b) in enumerate(pairwise(bounds))
    ]


def layout(circles, materials, light, rays=1, spread=0.0, aim=0.0) -> Layout:
    return Layout(
        np.asarray(circles, float).reshape(-1, 3),
        np.asarray(materials),
        light,
        rays,
        spread,
        aim,
        *BOX,
    )


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def cross(a, b) -> float:
    """The z component of the cross product of two 2D vectors."""
    return float(a[0] * b[1] - a[1] * b[0])


def schlick(cos_i: float, n1: float, n2: float) -> float:
    """Reference Schlick reflectance, with the transmitted cosine when leaving the denser side."""
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1 - cos_i**2))
    if sin_t >= 1:
        return 1.0
    cos = math.sqrt(1 - sin_t**2) if n1 > n2 else cos_i
    return r0 + (1 - r0) * (1 - cos) ** 5


def test_light_fan_is_evenly_spread_and_leaves_the_box_without_circles():
    lines = traced(layout([], [], (300.0, 200.0), rays=12, spread=360.0))
    assert len(lines) == 12
    for k, line in enumerate(lines):
        assert line.kinds.tolist() == [LIGHT] and line.weights.tolist() == [1.0]
        start, end = line.points
        assert np.allclose(start, (300, 200))
        angle = math.radians(360 * ((k + 0.5) / 12 - 0.5))
        assert np.allclose(unit(end - start), (math.cos(angle), math.sin(angle)), atol=1e-5)
        on_edge = np.isclose(end, 0, atol=1e-3) | np.isclose(end, BOX, atol=1e-3)
        assert on_edge.any()


def test_mirror_reflects_at_equal_angles_with_the_mirror_weight():
    center, radius = np.array([500.0, 300.0]), 100.0
    light = (200.0, 340.0)  # the ray along +x hits the circle 40 units off its axis
    (line,) = traced(layout([[*center, radius]], [MIRROR], light))
    assert line.kinds.tolist() == [LIGHT, REFLECTION]
    hit = line.points[1]
    expected_hit = (center[0] - math.sqrt(radius**2 - 40.0**2), 340.0)
    assert np.allclose(hit, expected_hit, atol=POINT_TOLERANCE)
    normal = unit(hit - center)
    incoming = np.array([1.0, 0.0])
    mirrored = incoming - 2 * incoming.dot(normal) * normal
    assert np.allclose(unit(line.points[2] - hit), mirrored, atol=ANGLE_TOLERANCE)
    assert line.weights[1] == pytest.approx(PRESETS["mirror"].reflectivity, rel=1e-6)


def test_matte_absorbs():
    (line,) = traced(layout([[500, 300, 100]], [MATTE], (200.0, 300.0)))
    assert line.kinds.tolist() == [LIGHT]
    assert np.allclose(line.points[1], (400, 300), atol=POINT_TOLERANCE)


def test_glass_refracts_by_snell_and_splits_by_fresnel():
    center, radius, offset = np.array([500.0, 300.0]), 100.0, 60.0
    lines = traced(layout([[*center, radius]], [GLASS], (200.0, 300.0 + offset)))
    main = lines[0]  # the refracted ray carries most of the light: it continues the path
    assert main.kinds[:3].tolist() == [LIGHT, REFRACTION, REFRACTION]
    hit = main.points[1]
    normal = unit(hit - center)
    cos_i = -np.array([1.0, 0.0]).dot(normal)
    sin_i = math.sqrt(1 - cos_i**2)
    inside = unit(main.points[2] - hit)
    sin_t = abs(cross(normal, inside))
    assert IOR * sin_t == pytest.approx(sin_i, abs=1e-4)  # Snell: n1 sin i = n2 sin t
    fresnel = schlick(cos_i, 1.0, IOR)
    assert main.weights[1] == pytest.approx(TRANSPARENCY * (1 - fresnel), rel=1e-5)
    # The other child of the first split, reflected off the outside, starts its own path.
    reflected = [line for line in lines[1:] if np.allclose(line.points[0], hit, atol=1e-3)]
    assert len(reflected) == 1
    assert reflected[0].kinds[0] == REFLECTION
    assert reflected[0].weights[0] == pytest.approx(TRANSPARENCY * fresnel, rel=1e-5)
    # Leaving the glass, the ray bends back: it leaves parallel to how it arrived rotated
    # about the circle, so its exit angle equals its entry angle.
    exit_point = main.points[2]
    exit_normal = unit(exit_point - center)
    out = unit(main.points[3] - exit_point)
    assert abs(cross(exit_normal, out)) == pytest.approx(sin_i, abs=1e-4)


@pytest.mark.parametrize("distance", [30.0, 85.0])
def test_total_internal_reflection_past_the_critical_angle(distance):
    """A light inside a glass circle, ``distance`` from its centre, shines along the chord
    perpendicular to that radius: the angle of incidence is asin(distance / r). At 85 of 100 it
    is past the critical angle (41.1 degrees), at 30 it is not."""
    center, radius = np.array([500.0, 300.0]), 100.0
    light = (500.0, 300.0 + distance)
    (line, *others) = traced(layout([[*center, radius]], [GLASS], light))
    incidence = math.asin(distance / radius)
    critical = math.asin(1 / IOR)
    hit = line.points[1]
    assert np.linalg.norm(hit - center) == pytest.approx(radius, abs=POINT_TOLERANCE)
    if incidence > critical:
        assert line.kinds[1] == INTERNAL
        assert line.weights[1] == pytest.approx(TRANSPARENCY, rel=1e-6)
        assert not any(REFRACTION in other.kinds[:1] for other in others)
        # The reflected ray stays inside, at the same angle to the next normal.
        nxt = line.points[2]
        assert np.linalg.norm(nxt - center) == pytest.approx(radius, abs=POINT_TOLERANCE)
    else:
        assert line.kinds[1] == REFRACTION
        fresnel = schlick(math.cos(incidence), IOR, 1.0)
        assert line.weights[1] == pytest.approx(TRANSPARENCY * (1 - fresnel), rel=1e-5)


def test_paths_are_continuous_and_stop_at_the_depth_limit():
    circles = [[300, 200, 60], [600, 350, 90], [450, 450, 50], [700, 150, 40]]
    lines = traced(
        layout(circles, [GLASS, MIRROR, GLASS, MIRROR], (100.0, 300.0), rays=90, spread=360.0)
    )
    for line in lines:
        assert len(line.points) == len(line.weights) + 1
        assert len(line.weights) <= 7  # the light's segment and 6 bounces
        assert (line.weights >= 1 / 512).all() and (line.weights <= 1).all()
    # Each bounce's point lies on some circle (up to float32 rounding and the surface offset).
    centers = np.asarray(circles, float)
    for line in lines:
        for point in line.points[1:-1]:
            gap = np.abs(np.linalg.norm(centers[:, :2] - point, axis=1) - centers[:, 2]).min()
            assert gap < POINT_TOLERANCE
