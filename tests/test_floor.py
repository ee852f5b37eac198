"""The analytic floor plane in SceneGeometry's queries, against the closed-form crossing.

A ray o + t d meets the plane y = h at t = (h - o_y) / d_y; it is a hit when that t is finite,
in front of the origin and inside the query's [tnear, tfar] window. Rays going up, down, and
parallel to the plane, with finite and infinite windows.
"""

from __future__ import annotations

import numpy as np
import pytest
from bvh_reference import occluded_or_below_plane
from tolerances import RTOL32, assert_close, position_atol, ray_t_atol

from embree_rt import Scene
from embree_rt.geometry import SceneGeometry
from embree_rt.scene.model import Floor
from embree_rt.tracing.records import intersect_records

HEIGHT = -1.5


def random_rays(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(3, count) float32 origins above and below the plane, unit directions; a tenth of the
    rays run parallel to the plane."""
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-20, 20, (3, count)).astype(np.float32)
    directions = rng.normal(size=(3, count))
    directions[1, : count // 10] = 0.0
    directions /= np.linalg.norm(directions, axis=0)
    return origins, directions.astype(np.float32)


def crossing(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(n,) float64 distance to the plane, inf where the ray never meets it ahead."""
    o = origins[1].astype(np.float64)
    d = directions[1].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (HEIGHT - o) / d
    return np.where((d != 0) & (t >= 0), t, np.inf)


def occluded(geometry: SceneGeometry, origins, directions, tnear, tfar) -> np.ndarray:
    """The scene's BVH with its floor, on rays given as (3, n) columns."""
    return occluded_or_below_plane(
        geometry.bvh, origins.T, directions.T, tnear, tfar, geometry.labels.plane_y
    )


def nearest(geometry: SceneGeometry, origins, directions, tnear, tfar):
    """The hit records of the scene's nearest-hit query inside [tnear, tfar]."""
    return intersect_records(geometry.bvh, origins, directions, geometry.labels, tnear, tfar)


@pytest.fixture(scope="module")
def floor_only():
    with SceneGeometry(Scene(floor=Floor(height=HEIGHT))) as geometry:
        yield geometry


@pytest.mark.parametrize("tnear, tfar", [(0.0, np.inf), (0.0, 10.0), (2.0, np.inf), (5.0, 30.0)])
def test_floor_hits_and_occlusion_match_the_closed_form(floor_only, tnear, tfar) -> None:
    origins, directions = random_rays(20000, seed=int(tfar if np.isfinite(tfar) else 99) + 7)
    t = crossing(origins, directions)
    expected = np.isfinite(t) & (t >= tnear) & (t <= tfar)
    # float32 t = (h - o_y) / d_y is known to ulps of the coordinates over |d_y| (the cosine of
    # incidence), however small t is; rays that close to a window's end may go either way.
    up = np.tile([[0.0], [1.0], [0.0]], (1, origins.shape[1]))
    atol = ray_t_atol(origins.T, directions.T, abs(HEIGHT), normals=up.T)
    slack = atol + RTOL32 * np.where(np.isfinite(t), t, 0.0)
    clear = ~(np.abs(t - tnear) <= slack)
    if np.isfinite(tfar):
        clear &= ~(np.abs(t - tfar) <= slack)
    assert expected[clear].any() and (~expected[clear]).any()

    blocked = occluded(floor_only, origins, directions, tnear, tfar)
    np.testing.assert_array_equal(blocked[clear], expected[clear])

    records = nearest(floor_only, origins, directions, tnear, tfar)
    hit = np.zeros(origins.shape[1], bool)
    hit[records.rays] = True
    np.testing.assert_array_equal(hit[clear], expected[clear])
    assert records.counts[0] == len(records.rays)  # every hit is on the plane
    both = clear[records.rays]
    assert_close(records.t[both], t[records.rays][both], atol=atol[records.rays][both])
    # o_y + t d_y lands on the plane to rounding of coordinates up to 20
    assert_close(records.position[1], HEIGHT, atol=position_atol(origins))


def test_rays_away_from_or_along_the_floor_are_never_blocked_by_it(floor_only) -> None:
    # One ray per column: up from above, along the plane in it, down from below the plane.
    origins = np.array([[0.0, 3.0, -2.0], [2.0, HEIGHT, -3.0], [0.0, -4.0, 1.0]], np.float32).T
    directions = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]], np.float32).T
    for tfar in (np.inf, 100.0):
        assert not occluded(floor_only, origins, directions, 0.0, tfar).any()
        assert len(nearest(floor_only, origins, directions, 0.0, tfar).rays) == 0


def test_a_floor_alone_is_answered_bitwise_as_embree_answers_it_beside_an_object() -> None:
    # A BVH with no objects answers every ray as a miss without calling Embree (the plane is
    # the records' own); beside a sphere out of every ray's reach Embree is called and misses
    # too, and the records, made by the same compiled pass from the same misses, are the same.
    origins, directions = random_rays(20000, seed=3)
    far = Scene(floor=Floor(height=HEIGHT))
    far.add_spheres(np.array([[1e6, 1e6, 1e6]], np.float32), np.array([1.0], np.float32), "matte")
    with (
        SceneGeometry(Scene(floor=Floor(height=HEIGHT))) as alone,
        SceneGeometry(far) as beside,
    ):
        assert alone.bvh.geometry_count == 0 and beside.bvh.geometry_count == 1
        for tfar in (np.inf, 10.0):
            hits = nearest(alone, origins, directions, 0.0, tfar)
            hits_beside = nearest(beside, origins, directions, 0.0, tfar)
            assert 0 < len(hits.rays) < origins.shape[1] and hits.counts[0] == len(hits.rays)
            np.testing.assert_array_equal(hits.rays, hits_beside.rays)
            for name in ("t", "position", "normal", "scale", "incoming"):
                np.testing.assert_array_equal(getattr(hits, name), getattr(hits_beside, name))
