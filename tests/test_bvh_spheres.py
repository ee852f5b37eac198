"""Analytic spheres in the BVH against the float64 ray–sphere quadratic (tests/bvh_reference.py).

Every test runs on both kinds of sphere ``BVH.add_spheres`` offers: ``user`` (user geometry with
compiled callbacks, the default) and ``point`` (Embree's own ``SPHERE_POINT``). The user kind's
own edge cases (distant spheres, exact window bounds, packets) are in test_bvh_user_spheres.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from bvh_reference import (
    assert_hits_match,
    float32_exact,
    rays_toward_box,
    sphere_hits,
    unit,
)
from tolerances import assert_close, position_atol, ray_t_atol

from embree_rt.embree import BVH, Rays
from embree_rt.embree.bvh import SPHERE_KINDS


def sphere_field(rng: np.random.Generator, count: int, extent: float = 10.0):
    """Random overlapping spheres in a cube: centers (count, 3), radii (count,), float32-exact."""
    centers = float32_exact(rng.uniform(-extent, extent, size=(count, 3)))
    radii = float32_exact(rng.uniform(0.2, 1.8, size=count))
    return centers, radii


def spheres_bvh(centers: np.ndarray, radii: np.ndarray, kind: str, threads: int | None = None):
    bvh = BVH(threads=threads)
    gid = bvh.add_spheres(centers, radii, kind=kind)
    bvh.commit()
    return bvh, gid


@pytest.fixture(params=SPHERE_KINDS)
def kind(request) -> str:
    return request.param


@pytest.fixture(scope="module", params=SPHERE_KINDS)
def field(request):
    rng = np.random.default_rng(1)
    centers, radii = sphere_field(rng, 400)
    bvh, gid = spheres_bvh(centers, radii, request.param)
    origins, directions = rays_toward_box(rng, 5000, [-12] * 3, [12] * 3, 40.0)
    origins, directions = float32_exact(origins), float32_exact(directions)
    yield centers, radii, bvh, gid, origins, directions
    bvh.close()


def test_hits_layout_and_dtypes(field):
    _, _, bvh, gid, origins, directions = field
    hits = bvh.intersect(Rays(origins[:10], directions[:10]))
    assert isinstance(gid, int)
    for name in ("t", "u", "v"):
        assert getattr(hits, name).shape == (10,)
        assert getattr(hits, name).dtype == np.float32, name
    for name in ("geom_id", "prim_id", "inst_id"):
        assert getattr(hits, name).shape == (10,)
        assert getattr(hits, name).dtype == np.int32, name
    assert hits.normal.shape == (10, 3)
    assert hits.normal.dtype == np.float32


def test_random_overlapping_field_matches_quadratic(field):
    centers, radii, bvh, gid, origins, directions = field
    hits = bvh.intersect(Rays(origins, directions))
    ref = sphere_hits(origins, directions, centers, radii)
    assert_hits_match(hits, ref, gid, min_hit_fraction=0.3, min_miss_fraction=0.05)


def test_normals_point_outward_from_the_centre(field):
    centers, radii, bvh, _, origins, directions = field
    hits = bvh.intersect(Rays(origins, directions))
    hit = np.isfinite(hits.t)
    point = origins[hit] + hits.t[hit, None].astype(np.float64) * directions[hit]
    outward = unit(point - centers[hits.prim_id[hit]])
    cosine = np.einsum("ij,ij->i", unit(hits.normal[hit]), outward)
    assert cosine.min() > 0.999
    # the hit point lies on the sphere it names
    distance = np.linalg.norm(point - centers[hits.prim_id[hit]], axis=1)
    np.testing.assert_allclose(distance, radii[hits.prim_id[hit]], rtol=1e-3, atol=1e-4)


def test_nested_spheres_from_inside_hit_the_far_side_outward(kind):
    # Three concentric spheres and one off-centre sphere inside the largest.
    centers = float32_exact([[0, 0, 0], [0, 0, 0], [0, 0, 0], [2.0, 0.5, 0]])
    radii = float32_exact([1.0, 2.0, 3.0, 0.4])
    rng = np.random.default_rng(2)
    with BVH() as bvh:
        gid = bvh.add_spheres(centers, radii, kind=kind)
        bvh.commit()

        # From the common centre: closed form t = 1 / |d| on the innermost sphere, normal ∝ d.
        directions = float32_exact(unit(rng.normal(size=(500, 3))) * rng.uniform(0.3, 3, (500, 1)))
        origins = np.zeros_like(directions)
        hits = bvh.intersect(Rays(origins, directions))
        assert np.all(hits.prim_id == 0)
        assert np.all(hits.geom_id == gid)
        # float32 rounding of coordinates up to the outer radius 3 (the rays leave radially)
        assert_close(
            hits.t,
            1.0 / np.linalg.norm(directions, axis=1),
            atol=ray_t_atol(origins, directions, 3.0),
        )
        cosine = np.einsum("ij,ij->i", unit(hits.normal), unit(directions))
        assert cosine.min() > 0.9999, "an exit hit must report the outward normal"

        # From random points inside the shells, in random directions, against the reference.
        inside = unit(rng.normal(size=(3000, 3))) * rng.uniform(0, 2.95, (3000, 1))
        origins = float32_exact(inside)
        directions = float32_exact(unit(rng.normal(size=(3000, 3))))
        hits = bvh.intersect(Rays(origins, directions))
        ref = sphere_hits(origins, directions, centers, radii)
        assert ref.hit.all(), "every ray starts inside the largest sphere"
        assert_hits_match(hits, ref, gid)
        leaving = np.einsum("ij,ij->i", unit(hits.normal), directions) > 0
        assert leaving.mean() > 0.3, "many of these rays should be exit hits"


@pytest.mark.parametrize("offset", [-1e-2, -1e-3, -2e-4, 2e-4, 1e-3, 1e-2])
def test_grazing_rays(offset, kind):
    """Rays passing the centre at (1 + offset) radii hit exactly when offset < 0."""
    rng = np.random.default_rng(3)
    count = 2000
    center = np.array([2.0, -1.0, 0.5])
    radius = 1.3
    # A random direction, and a random perpendicular one to displace the ray sideways.
    direction = unit(rng.normal(size=(count, 3)))
    side = unit(np.cross(direction, rng.normal(size=(count, 3))))
    impact = radius * (1.0 + offset)
    back = rng.uniform(3, 30, size=(count, 1))
    origins = float32_exact(center + impact * side - back * direction)
    directions = float32_exact(direction)
    with BVH() as bvh:
        gid = bvh.add_spheres(center[None], [radius], kind=kind)
        bvh.commit()
        hits = bvh.intersect(Rays(origins, directions))
    ref = sphere_hits(origins, directions, center[None], np.array([radius]), ambiguity=0.0)
    assert np.all(ref.hit == (offset < 0))
    agree = np.isfinite(hits.t) == ref.hit
    # the outermost band is a few float32 ulps of the distance wide: tolerate a tiny fraction
    allowed = 0.01 if abs(offset) < 1e-3 else 0.0
    assert 1.0 - agree.mean() <= allowed, f"{(~agree).sum()} of {count} grazing rays disagree"
    both = agree & ref.hit
    np.testing.assert_allclose(hits.t[both], ref.t[both], rtol=1e-4)
    assert np.all(hits.geom_id[both] == gid)


def test_exactly_tangent_rays_hit_at_the_touching_point_if_at_all(kind):
    rng = np.random.default_rng(4)
    count = 1000
    center = np.array([0.0, 0.0, 0.0])
    direction = unit(rng.normal(size=(count, 3)))
    side = unit(np.cross(direction, rng.normal(size=(count, 3))))
    origins = float32_exact(side - 5.0 * direction)
    with BVH() as bvh:
        bvh.add_spheres(center[None], [1.0], kind=kind)
        bvh.commit()
        hits = bvh.intersect(Rays(origins, float32_exact(direction)))
    hit = np.isfinite(hits.t)
    # touching point at t = 5; a float32 ulp sideways moves the root by ~sqrt(ulp) ~ 1e-3
    np.testing.assert_allclose(hits.t[hit], 5.0, atol=2e-3)


def test_window_on_a_row_of_spheres_finds_the_next_hit(kind):
    # Spheres of radius 1 at x = 5, 10, 15, 20; a ray along +x from the origin meets their
    # surfaces at 4, 6, 9, 11, 14, 16, 19, 21.
    centers = np.array([[5.0, 0, 0], [10, 0, 0], [15, 0, 0], [20, 0, 0]])
    radii = np.ones(4)
    surfaces = [(4, 0, -1), (6, 0, 1), (9, 1, -1), (11, 1, 1), (14, 2, -1), (16, 2, 1)]
    with BVH() as bvh:
        gid = bvh.add_spheres(centers, radii, kind=kind)
        bvh.commit()
        origin = np.zeros((1, 3))
        for direction_length in (1.0, 0.25, 4.0):
            direction = np.array([[direction_length, 0, 0]])
            for t, prim, side in surfaces:
                t = t / direction_length
                hits = bvh.intersect(Rays(origin, direction, tnear=t - 0.5 / direction_length))
                assert_close(hits.t, [t], atol=ray_t_atol(origin, direction, 21.0))
                assert hits.prim_id[0] == prim and hits.geom_id[0] == gid
                assert np.sign(hits.normal[0, 0]) == side and hits.normal[0, 0] != 0
                assert abs(hits.normal[0, 1]) + abs(hits.normal[0, 2]) < 1e-4
            # tfar just short of the first surface: nothing
            hits = bvh.intersect(Rays(origin, direction, tfar=3.9 / direction_length))
            assert np.isinf(hits.t[0]) and hits.prim_id[0] == -1 and hits.geom_id[0] == -1
            # a window between two spheres: nothing
            hits = bvh.intersect(
                Rays(origin, direction, tnear=6.5 / direction_length, tfar=8.5 / direction_length)
            )
            assert np.isinf(hits.t[0]) and hits.prim_id[0] == -1
        # the window is inclusive of interior hits on both sides: [3.9, 4.1] holds t = 4
        hits = bvh.intersect(Rays(origin, np.array([[1.0, 0, 0]]), tnear=3.9, tfar=4.1))
        assert_close(hits.t, [4.0], atol=position_atol(21.0))


def test_scalar_window_skips_the_nearest_hit(field):
    centers, radii, bvh, gid, origins, directions = field
    tnear = 6.0  # origins are 40 away, directions 0.2..5 long: the window cuts through the field
    hits = bvh.intersect(Rays(origins, directions, tnear=tnear, tfar=25.0))
    ref = sphere_hits(origins, directions, centers, radii, tnear=tnear, tfar=25.0)
    assert_hits_match(hits, ref, gid, min_hit_fraction=0.1, min_miss_fraction=0.1)


def test_per_ray_window_excluding_the_nearest_hit_finds_the_next_one(field):
    centers, radii, bvh, gid, origins, directions = field
    first = sphere_hits(origins, directions, centers, radii)
    hit = first.hit & ~first.ambiguous
    o, d = origins[hit], directions[hit]
    # tnear just past the first hit: the next surface (the same sphere's far side, or another)
    tnear = float32_exact(first.t[hit] * (1 + 1e-3))
    tfar = float32_exact(first.t[hit] * np.random.default_rng(5).uniform(1.0, 1.5, hit.sum()))
    hits = bvh.intersect(Rays(o, d, tnear=tnear, tfar=tfar))
    ref = sphere_hits(o, d, centers, radii, tnear=tnear, tfar=tfar)
    assert_hits_match(hits, ref, gid, min_hit_fraction=0.3, min_miss_fraction=0.05)
    assert np.all(hits.t[np.isfinite(hits.t)] >= tnear[np.isfinite(hits.t)])
    # per-ray tfar before the first hit: everything misses
    hits = bvh.intersect(Rays(o, d, tfar=float32_exact(first.t[hit] * 0.99)))
    assert np.all(np.isinf(hits.t)) and np.all(hits.geom_id == -1)


def test_prim_and_geom_ids_identify_each_sphere(kind):
    # Two sphere sets on a 2D grid; one vertical ray per sphere straight down onto its centre.
    grid = np.stack(np.meshgrid(np.arange(12.0), np.arange(10.0), indexing="ij"), -1).reshape(-1, 2)
    first = np.c_[grid[:60], np.zeros(60)]
    second = np.c_[grid[60:], np.full(60, 0.5)]
    radii_first = np.linspace(0.1, 0.4, 60)
    radii_second = np.linspace(0.4, 0.2, 60)
    with BVH() as bvh:
        gid_a = bvh.add_spheres(first, radii_first, kind=kind)
        gid_b = bvh.add_spheres(second, radii_second, kind=kind)
        bvh.commit()
        assert gid_a != gid_b
        tops = np.r_[first, second] + [0.0, 0.0, 3.0]
        down = np.tile([0.0, 0.0, -1.0], (120, 1))
        hits = bvh.intersect(Rays(tops, down))
    assert np.array_equal(hits.geom_id, np.r_[np.full(60, gid_a), np.full(60, gid_b)])
    assert np.array_equal(hits.prim_id, np.r_[np.arange(60), np.arange(60)])
    assert np.all(hits.inst_id == -1)
    assert_close(hits.t, 3.0 - np.r_[radii_first, radii_second], atol=ray_t_atol(tops, down, 12.0))
    np.testing.assert_allclose(unit(hits.normal), np.tile([0.0, 0.0, 1.0], (120, 1)), atol=1e-5)


def test_float64_float32_and_integer_inputs_agree(kind):
    centers = np.array([[0, 0, 0], [3, 0, 0]])
    radii = np.array([1, 2])
    with BVH() as a, BVH() as b:
        a.add_spheres(centers, radii, kind=kind)
        b.add_spheres(centers.astype(np.float32), radii.astype(np.float32), kind=kind)
        a.commit()
        b.commit()
        origins = np.array([[-5, 0, 0], [3, 0, 10]])
        directions = np.array([[1, 0, 0], [0, 0, -1]])
        ha = a.intersect(Rays(origins, directions))
        hb = b.intersect(Rays(origins.astype(np.float32), directions.astype(np.float32)))
    # Bitwise, on any ISA: float64 and integer inputs are rounded to the same float32 values
    # before Embree sees them, and the same kernel traces them.
    np.testing.assert_array_equal(ha.t, hb.t)
    assert_close(ha.t, [4.0, 8.0], atol=ray_t_atol(origins, directions, 10.0))
    np.testing.assert_array_equal(ha.prim_id, [0, 1])


def test_coordinate_bound_is_the_farthest_reach_of_any_sphere(kind):
    """``coordinate_bound`` (the size instances and surface offsets scale their rounding
    error by) is max over spheres of max(|x|, |y|, |z|) + r, over every set added: checked
    against NumPy on float32 values (exact: a max of float32 sums), with the farthest sphere
    in each set somewhere else and a transposed (3, n) view as input."""
    rng = np.random.default_rng(4)
    first = float32_exact(rng.uniform(-50.0, 50.0, size=(3, 500))).T  # a strided view
    first[123] = [-80.0, 2.0, 3.0]
    second = float32_exact(rng.uniform(-20.0, 20.0, size=(300, 3)))
    second[7] = [1.0, 1.0, 95.5]
    radii_first = float32_exact(rng.uniform(0.1, 2.0, 500))
    radii_second = float32_exact(rng.uniform(0.1, 2.0, 300))
    with BVH() as bvh:
        assert bvh.coordinate_bound == 0.0
        bvh.add_spheres(first, radii_first, kind=kind)
        after_first = bvh.coordinate_bound
        bvh.add_spheres(second, radii_second, kind=kind)
        after_second = bvh.coordinate_bound

    def reach(centers, radii):
        c = np.asarray(centers, np.float32)
        return float((np.abs(c).max(axis=1) + np.asarray(radii, np.float32)).max())

    assert after_first == reach(first, radii_first)
    assert after_first == np.float32(80.0) + np.float32(radii_first[123])
    assert after_second == max(after_first, reach(second, radii_second))
    assert after_second == np.float32(95.5) + np.float32(radii_second[7])


@pytest.mark.parametrize(("quality", "compact"), [("low", False), ("high", True), ("low", True)])
def test_build_quality_and_compact_change_the_tree_not_the_answers(kind, quality, compact):
    """Every Embree build variant finds the same nearest sphere at the same t (to float32
    rounding: Embree's point-sphere leaves differ between variants), and the same shadow
    answers: the tree differs, the geometry does not."""
    rng = np.random.default_rng(9)
    centers, radii = sphere_field(rng, 3000, extent=40.0)
    origins, directions = rays_toward_box(rng, 4000, [-42] * 3, [42] * 3, 120.0)
    reference, _ = spheres_bvh(centers, radii, kind)
    other = BVH(build_quality=quality, compact=compact)
    other.add_spheres(centers, radii, kind=kind)
    other.commit()
    with reference, other:
        expected = reference.intersect(Rays(origins, directions))
        got = other.intersect(Rays(origins, directions))
        np.testing.assert_array_equal(got.prim_id, expected.prim_id)
        np.testing.assert_allclose(got.t, expected.t, rtol=2.0**-20, atol=0.0)  # inf == inf
        np.testing.assert_array_equal(
            other.occluded(Rays(origins, directions, 0.0, 60.0)),
            reference.occluded(Rays(origins, directions, 0.0, 60.0)),
        )


def test_an_unknown_build_quality_is_refused():
    with pytest.raises(ValueError, match="build_quality"):
        BVH(build_quality="best")
