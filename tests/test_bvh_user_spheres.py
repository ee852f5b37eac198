"""User-geometry spheres (``add_spheres(kind="user")``) where they differ from Embree's own:
float64 robustness far from small spheres, exact window bounds, packets of every batch size
against single rays, occlusion against intersection, instances, and agreement with the native
``SPHERE_POINT`` primitive on the same rays. References: tests/bvh_reference.py (float64).

Tolerances are in float32 ulps of the coordinates involved plus a relative part, so they hold for
whichever of its SSE4.2 / AVX2 / AVX-512 kernels Embree picks.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from bvh_reference import (
    TRANSFORMS,
    assert_hits_match,
    float32_exact,
    rays_toward_box,
    sphere_hits,
    transform_points,
    unit,
)

from embree_rt.embree import BVH, Rays
from embree_rt.embree.bvh import SPHERE_KINDS

ULP = 2.0**-23  # one float32 ulp, relative


def ulps(values, count: float = 1.0) -> np.ndarray:
    """``count`` float32 ulps of ``values`` (absolute), as float64."""
    return count * np.spacing(np.abs(np.asarray(values, np.float32))).astype(np.float64)


def spheres_bvh(centers, radii, kind: str, threads: int | None = None) -> tuple[BVH, int]:
    bvh = BVH(threads=threads)
    gid = bvh.add_spheres(centers, radii, kind=kind)
    bvh.commit()
    return bvh, gid


def tangent_rays(rng, centers, radii, count: int, distance: float, spread: float):
    """``count`` rays from ``distance`` away that pass random spheres at (1 ± ``spread``) radii
    from the centre: the hardest rays for a float32 quadratic. Origins, unit directions
    (count, 3), float32-exact."""
    target = rng.integers(0, len(centers), count)
    toward = unit(rng.normal(size=(count, 3)))
    side = unit(np.cross(toward, rng.normal(size=(count, 3))))
    offset = radii[target, None] * (1 + rng.uniform(-spread, spread, (count, 1)))
    origins = centers[target] - distance * toward + offset * side
    return float32_exact(origins), float32_exact(toward)


def wrong_objects(hits, ref) -> int:
    """Rays whose nearest object (or hit/miss) differs from the float64 reference's."""
    return int(np.sum(np.where(np.isfinite(hits.t), hits.prim_id, -1) != ref.prim_id))


# -- far from small spheres -----------------------------------------------------------------------

LAYOUTS = {
    # small spheres near the origin, seen from 1500 away
    "distant-rays": (np.zeros(3), 1500.0),
    # the same spheres moved out to coordinates ~1500 (ulp 1.2e-4), seen from 40 away
    "distant-field": (np.array([1500.0, -900.0, 700.0]), 40.0),
}


@pytest.mark.parametrize("kind", SPHERE_KINDS)
@pytest.mark.parametrize("layout", LAYOUTS)
def test_distant_small_spheres_match_the_float64_quadratic(layout, kind):
    rng = np.random.default_rng(70)
    middle, distance = LAYOUTS[layout]
    centers = float32_exact(middle + rng.uniform(-8, 8, (400, 3)))
    radii = float32_exact(rng.uniform(0.3, 0.5, 400))
    origins, directions = rays_toward_box(rng, 4000, middle - 8, middle + 8, distance)
    origins, directions = float32_exact(origins), float32_exact(directions)
    bvh, gid = spheres_bvh(centers, radii, kind)
    with bvh:
        hits = bvh.intersect(Rays(origins, directions))
    # undecidable: within 8 float32 ulps of the ray-to-sphere distance of a decision, plus 8 ulps
    # of the coordinates, which both kinds store in float32
    coordinates = ulps(np.abs(middle).max() + 8, 8)
    ref = sphere_hits(origins, directions, centers, radii, ambiguity=8 * ULP, absolute=coordinates)
    # user spheres solve in float64 from the same float32 inputs: t is the reference's to
    # float32 rounding; native ones lose a few ulps of the distance to cancellation
    t_rtol = 4 * ULP if kind == "user" else 1e-4
    assert_hits_match(
        hits,
        ref,
        gid,
        t_rtol=t_rtol,
        max_ambiguous=0.03,
        min_hit_fraction=0.3,
        min_miss_fraction=0.1,
    )


def test_user_spheres_are_no_less_robust_than_native_far_away():
    """Rays from 1500 away that pass spheres of radius ~0.4 within ±0.1% of their radius: count
    the rays that report another object than the float64 quadratic (none left out)."""
    rng = np.random.default_rng(71)
    centers = float32_exact(rng.uniform(-20, 20, (500, 3)))
    radii = float32_exact(rng.uniform(0.3, 0.5, 500))
    origins, directions = tangent_rays(rng, centers, radii, 3000, 1500.0, 1e-3)
    ref = sphere_hits(origins, directions, centers, radii, ambiguity=0.0)
    wrong = {}
    for kind in SPHERE_KINDS:
        bvh, _ = spheres_bvh(centers, radii, kind)
        with bvh:
            wrong[kind] = wrong_objects(bvh.intersect(Rays(origins, directions)), ref)
    # a float32 quadratic errs on ~ulp(1500) / 0.4 of these rays: the sample must be that hard
    # to show anything (native SPHERE_POINT solves in float32)
    assert wrong["point"] >= 10, f"sample too easy: native wrong on {wrong['point']} rays"
    assert wrong["user"] <= wrong["point"], wrong
    # float64 from float32 inputs is as exact as the reference; only Embree's float32 box
    # tests could still cull a grazing ray
    assert wrong["user"] <= 0.002 * len(origins), wrong


@pytest.mark.parametrize("kind", SPHERE_KINDS)
def test_rays_from_inside_distant_spheres_exit_with_the_outward_normal(kind):
    rng = np.random.default_rng(72)
    # a 4 x 4 x 4 block of separate spheres at coordinates ~1500
    grid = np.stack(np.meshgrid(*[np.arange(4.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centers = float32_exact([1500.0, -700.0, 300.0] + 2.0 * grid)
    radii = float32_exact(rng.uniform(0.3, 0.5, len(centers)))
    count = 3000
    which = rng.integers(0, len(centers), count)
    inside = unit(rng.normal(size=(count, 3))) * rng.uniform(0, 0.95, (count, 1))
    origins = float32_exact(centers[which] + inside * radii[which, None])
    directions = float32_exact(unit(rng.normal(size=(count, 3))) * rng.uniform(0.5, 2, (count, 1)))
    bvh, gid = spheres_bvh(centers, radii, kind)
    with bvh:
        hits = bvh.intersect(Rays(origins, directions))
    ref = sphere_hits(origins, directions, centers, radii, ambiguity=8 * ULP)
    assert np.array_equal(ref.prim_id, which), "the reference exits the sphere it starts in"
    assert np.array_equal(hits.prim_id, which) and np.all(hits.geom_id == gid)
    t_rtol = 4 * ULP if kind == "user" else 1e-4
    # t ~ 0.5: an absolute part of a few ulps of the coordinates (1500) over |d|
    t_atol = ulps(1500.0, 4) / np.linalg.norm(directions, axis=1)
    assert np.all(np.abs(hits.t - ref.t) <= t_rtol * ref.t + t_atol)
    normal = unit(hits.normal)
    assert np.einsum("ij,ij->i", normal, ref.normal).min() > 0.9999
    assert np.all(np.einsum("ij,ij->i", normal, directions) > 0), "exit hits face the way out"


# -- window bounds --------------------------------------------------------------------------------


def exact_root_rays():
    """Rays whose two sphere crossings t0 < t1 are exact in float32 *and* in float64 arithmetic
    (integers over powers of two, along lines through the centre), one sphere per ray, each in
    its own plane z = 40 i so no ray meets another's sphere. Returns origins, directions,
    centers (n, 3), radii (n,) float64 and t0, t1 (n,).

    No slope is along an axis: such a ray enters the sphere's bounding box exactly where it
    meets the sphere, and Embree's float32 box test may then cull the box when tfar = t0.
    """
    slopes = [(3.0, 4.0, 0.0), (-4.0, 3.0, 0.0), (2.0, 3.0, 6.0), (6.0, -2.0, -3.0)]
    origins, directions, centers, radii, t0, t1 = [], [], [], [], [], []
    for i in range(24):
        slope = np.array(slopes[i % 4])
        scale = 2.0 ** (i % 5 - 2)
        origin = np.array([i - 7.0, 3.0 - i, 40.0 * i])
        steps = 2 + i % 6  # the centre at origin + steps * slope
        length = np.linalg.norm(slope)  # 5 or 7
        radius = length * (0.5 if i % 2 else 1.0)
        origins.append(origin)
        directions.append(slope * scale)
        centers.append(origin + steps * slope)
        radii.append(radius)
        t0.append((steps - radius / length) / scale)
        t1.append((steps + radius / length) / scale)
    return tuple(np.array(v) for v in (origins, directions, centers, radii, t0, t1))


def up(values) -> np.ndarray:
    return np.nextafter(np.asarray(values, np.float32), np.float32(np.inf)).astype(np.float64)


def down(values) -> np.ndarray:
    return np.nextafter(np.asarray(values, np.float32), np.float32(-np.inf)).astype(np.float64)


@pytest.mark.parametrize("lanes", [1, 4, 8, 16])
def test_hits_exactly_on_the_window_bounds_count(lanes):
    """Embree's rule is tnear <= t <= tfar: a root equal to either bound is a hit, one float32
    ulp outside is not. (User spheres only: native ones compute t in float32 with Embree's own
    reciprocal, which need not land exactly on these roots.)"""
    origins, directions, centers, radii, t0, t1 = exact_root_rays()
    bvh, gid = spheres_bvh(centers, radii, "user")
    bvh.lanes = lanes
    inf = np.full(len(t0), np.inf)
    cases = [
        # (tnear, tfar, expected t)
        (t0, inf, t0),
        (up(t0), inf, t1),  # past the entry: the exit point of the same sphere
        (np.zeros_like(t0), t0, t0),
        (np.zeros_like(t0), down(t0), inf),
        (t1, inf, t1),
        (up(t1), inf, inf),
        (up(t0), t1, t1),
        (up(t0), down(t1), inf),
    ]
    if lanes == 1:
        # A window of one point. Embree's packet traversal enters a leaf only while tfar >
        # the box's entry distance (strictly: bvh_intersector_hybrid.cpp), so [t, t] never
        # reaches the callback in a packet: that is Embree's rule, not the sphere's.
        cases.append((t0, t0, t0))
    with bvh:
        for tnear, tfar, expected in cases:
            hits = bvh.intersect(Rays(origins, directions, tnear, tfar))
            np.testing.assert_array_equal(hits.t, expected)
            hit = np.isfinite(expected)
            assert np.array_equal(hits.prim_id, np.where(hit, np.arange(len(t0)), -1))
            assert np.all(hits.geom_id[hit] == gid)
            np.testing.assert_array_equal(bvh.occluded(Rays(origins, directions, tnear, tfar)), hit)


@pytest.mark.parametrize("kind", SPHERE_KINDS)
def test_reported_t_always_lies_inside_the_window(kind):
    rng = np.random.default_rng(73)
    centers = float32_exact(rng.uniform(-6, 6, (300, 3)))
    radii = float32_exact(rng.uniform(0.2, 0.9, 300))
    origins, directions = rays_toward_box(rng, 4000, [-7] * 3, [7] * 3, 25.0)
    origins, directions = float32_exact(origins), float32_exact(directions)
    bvh, _ = spheres_bvh(centers, radii, kind)
    with bvh:
        first = bvh.intersect(Rays(origins, directions))
        hit = np.isfinite(first.t)
        # windows that start or end right at (one ulp around) the first hit, and random ones
        t = np.where(hit, first.t, 30.0)
        tnear = np.select(
            [rng.random(4000) < 0.25, rng.random(4000) < 0.33], [up(t), t], rng.uniform(0, 30, 4000)
        )
        tfar = np.select([rng.random(4000) < 0.3, rng.random(4000) < 0.4], [down(t), t], tnear + 8)
        hits = bvh.intersect(Rays(origins, directions, tnear, tfar))
        blocked = bvh.occluded(Rays(origins, directions, tnear, tfar))
    inside = np.isfinite(hits.t)
    assert 0.2 < inside.mean() < 0.8
    t32 = hits.t[inside]
    assert np.all(t32 >= tnear.astype(np.float32)[inside])
    assert np.all(t32 <= tfar.astype(np.float32)[inside])
    # the windows one ulp around a root are undecidable by design; the random ones are not
    ref = sphere_hits(origins, directions, centers, radii, tnear, tfar)
    sure = ~ref.ambiguous
    assert np.array_equal(inside[sure], ref.hit[sure]) and sure.mean() > 0.3
    assert np.array_equal(blocked[sure], ref.hit[sure])


# -- packets, batch sizes, threads ----------------------------------------------------------------


class Field:
    """Spheres of one kind at the top level and inside two instances, over a triangle quad."""

    def __init__(self, kind: str, seed: int = 74) -> None:
        rng = np.random.default_rng(seed)
        self.centers = float32_exact(rng.uniform(-5, 5, (250, 3)))
        self.radii = float32_exact(rng.uniform(0.1, 0.7, 250))
        self.inner_centers = float32_exact(rng.uniform(-1, 1, (30, 3)))
        self.inner_radii = float32_exact(rng.uniform(0.1, 0.4, 30))
        self.kind = kind
        self.transforms = TRANSFORMS[:2]
        self.child = BVH()
        self.child.add_triangles([[90.0, 90, 90], [91, 90, 90], [90, 91, 90]], [[0, 1, 2]])
        self.inner_gid = self.child.add_spheres(self.inner_centers, self.inner_radii, kind=kind)
        self.child.commit()
        rays = rays_toward_box(rng, 1100, [-6] * 3, [6] * 3, 20.0)
        self.origins, self.directions = (float32_exact(v) for v in rays)
        self.tfar = float32_exact(rng.uniform(10, 30, 1100))

    def build(self, threads: int | None) -> BVH:
        bvh = BVH(threads=threads)
        self.quad_gid = bvh.add_triangles(
            [[-9.0, -6, -9], [9, -6, -9], [9, -6, 9], [-9, -6, 9]], [[0, 1, 2], [0, 2, 3]]
        )
        self.gid = bvh.add_spheres(self.centers, self.radii, kind=self.kind)
        self.inst_gids = [bvh.add_instance(self.child, m) for m in self.transforms]
        bvh.commit()
        return bvh

    def reference(self, rows: slice, tnear=0.0, tfar=np.inf) -> SimpleNamespace:
        """Float64 reference over the spheres (top level and instanced): prim, geom, inst per
        ray and which rays float32 may decide either way. The quad is left out: rays that
        reach it are marked as ``quad`` (the reference has nothing there)."""
        o, d = self.origins[rows], self.directions[rows]
        parts = [(sphere_hits(o, d, self.centers, self.radii, tnear, tfar), self.gid, -1)]
        for matrix, inst in zip(self.transforms, self.inst_gids, strict=True):
            inverse = np.linalg.inv(matrix)
            local = sphere_hits(
                transform_points(inverse, o),
                d @ inverse[:3, :3].T,
                self.inner_centers,
                self.inner_radii,
                tnear,
                tfar,
            )
            parts.append((local, self.inner_gid, inst))
        t = np.stack([p.t for p, _, _ in parts])
        winner = t.argmin(axis=0)
        rows_ = np.arange(len(o))
        ordered = np.sort(t, axis=0)
        hit = np.isfinite(ordered[0])
        ambiguous = np.any([p.ambiguous for p, _, _ in parts], axis=0)
        ambiguous[hit] |= ordered[1][hit] - ordered[0][hit] <= 1e-5 * ordered[0][hit]
        return SimpleNamespace(
            t=ordered[0],
            hit=hit,
            prim=np.where(hit, np.stack([p.prim_id for p, _, _ in parts])[winner, rows_], -1),
            geom=np.where(hit, np.array([g for _, g, _ in parts])[winner], -1),
            inst=np.where(hit, np.array([i for _, _, i in parts])[winner], -1),
            ambiguous=ambiguous,
        )


@pytest.fixture(scope="module", params=SPHERE_KINDS)
def packet_field(request):
    field = Field(request.param)
    single = field.build(threads=1)
    single.lanes = 1
    baseline = single.intersect(Rays(field.origins, field.directions, 0.0, field.tfar))
    baseline_blocked = single.occluded(Rays(field.origins, field.directions, 0.0, field.tfar))
    yield field, single, baseline, baseline_blocked
    single.close()
    field.child.close()


def test_single_ray_baseline_matches_the_reference(packet_field):
    field, _, baseline, blocked = packet_field
    ref = field.reference(slice(None), 0.0, field.tfar)
    on_quad = baseline.geom_id == field.quad_gid
    sure = ~ref.ambiguous & ~on_quad
    assert sure.mean() > 0.7 and ref.hit[sure].mean() > 0.3 and on_quad.mean() > 0.02
    for name, ours, theirs in (
        ("hit", np.isfinite(baseline.t), ref.hit),
        ("prim", baseline.prim_id, ref.prim),
        ("geom", baseline.geom_id, ref.geom),
        ("inst", baseline.inst_id, ref.inst),
    ):
        assert np.array_equal(ours[sure], theirs[sure]), f"{name} differs from the reference"
    assert len(set(baseline.inst_id[sure & (ref.inst >= 0)])) == 2, "both instances are hit"
    np.testing.assert_allclose(baseline.t[sure & ref.hit], ref.t[sure & ref.hit], rtol=1e-4)
    assert np.array_equal(blocked, np.isfinite(baseline.t)), "occluded agrees with intersect"


# odd sizes and offsets: partial packets (masked lanes) at both ends of a chunk
BATCHES = [(0, 1), (5, 3), (0, 8), (3, 9), (11, 17), (2, 255), (1, 257), (0, 1100)]


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("lanes", [1, 4, 8, 16])
def test_every_batch_size_answers_like_single_rays(packet_field, lanes, threads):
    field, _, baseline, baseline_blocked = packet_field
    bvh = field.build(threads=threads)
    bvh.lanes = lanes
    compared = 0
    with bvh:
        for start, size in BATCHES:
            rows = slice(start, start + size)
            o, d, tfar = field.origins[rows], field.directions[rows], field.tfar[rows]
            hits = bvh.intersect(Rays(o, d, 0.0, tfar))
            blocked = bvh.occluded(Rays(o, d, 0.0, tfar))
            expected = SimpleNamespace(
                **{
                    name: getattr(baseline, name)[rows]
                    for name in ("t", "prim_id", "geom_id", "inst_id", "normal")
                }
            )
            # only rays float32 cannot decide may differ between traversal kernels
            differ = (hits.prim_id != expected.prim_id) | (hits.geom_id != expected.geom_id)
            differ |= (hits.inst_id != expected.inst_id) | (blocked != baseline_blocked[rows])
            if differ.any():
                ref = field.reference(rows, 0.0, tfar)
                assert ref.ambiguous[differ].all(), f"batch {start}+{size}: rays differ"
            same = ~differ & np.isfinite(hits.t)
            np.testing.assert_allclose(hits.t[same], expected.t[same], rtol=1e-5)
            cosine = np.einsum("ij,ij->i", unit(hits.normal[same]), unit(expected.normal[same]))
            assert np.all(cosine > 0.99999)
            if field.kind == "user":
                # The callback is one piece of scalar code run on the very float32 numbers of
                # the caller's ray whatever the packet width, so a top-level sphere hit has the
                # same t and normal bit for bit (on any ISA: nothing here is ISA-dependent).
                top = same & (hits.geom_id == field.gid) & (hits.inst_id == -1)
                compared += top.sum()
                np.testing.assert_array_equal(hits.t[top], expected.t[top])
                np.testing.assert_array_equal(hits.normal[top], expected.normal[top])
    assert field.kind != "user" or compared > 500


@pytest.mark.parametrize("lanes", [1, 4, 8, 16])
def test_occluded_agrees_with_intersect_on_many_windows(packet_field, lanes):
    field = packet_field[0]
    rng = np.random.default_rng(75)
    bvh = field.build(threads=None)
    bvh.lanes = lanes
    with bvh:
        for _ in range(3):
            tnear = float32_exact(rng.uniform(0, 20, len(field.origins)))
            tfar = float32_exact(tnear + rng.exponential(4, len(field.origins)))
            hits = bvh.intersect(Rays(field.origins, field.directions, tnear, tfar))
            blocked = bvh.occluded(Rays(field.origins, field.directions, tnear, tfar))
            assert 0.1 < blocked.mean() < 0.9
            differ = blocked != np.isfinite(hits.t)
            if differ.any():
                ref = field.reference(slice(None), tnear, tfar)
                assert ref.ambiguous[differ].all(), f"{differ.sum()} rays differ"


# -- instances ------------------------------------------------------------------------------------


@pytest.mark.parametrize("lanes", [1, 4, 8, 16])
def test_instanced_user_spheres_report_instance_prim_and_world_normal(lanes):
    rng = np.random.default_rng(76)
    centers = float32_exact(rng.uniform(-1.5, 1.5, (40, 3)))
    radii = float32_exact(rng.uniform(0.2, 0.5, 40))
    with BVH() as child, BVH() as top:
        child.add_triangles([[50.0, 50, 50], [51, 50, 50], [50, 51, 50]], [[0, 1, 2]])
        gid = child.add_spheres(centers, radii, kind="user")
        child.commit()
        top.add_spheres([[300.0, 0, 0]], [1.0], kind="user")  # so no instance has gid 0
        inst_gids = [top.add_instance(child, matrix) for matrix in TRANSFORMS]
        top.commit()
        top.lanes = lanes
        assert gid == 1 and 0 not in inst_gids
        boxes = np.concatenate(
            [transform_points(m, np.r_[centers - 0.5, centers + 0.5]) for m in TRANSFORMS]
        )
        origins, directions = rays_toward_box(rng, 3000, boxes.min(0), boxes.max(0), 25.0)
        origins, directions = float32_exact(origins), float32_exact(directions)
        hits = top.intersect(Rays(origins, directions))
    # the reference per instance in object space, then the nearest over instances
    per_instance = []
    for matrix in TRANSFORMS:
        inverse = np.linalg.inv(matrix)
        ref = sphere_hits(
            transform_points(inverse, origins), directions @ inverse[:3, :3].T, centers, radii
        )
        ref.normal = unit(ref.normal @ inverse[:3, :3])  # (M^-T n) as rows: world space
        per_instance.append(ref)
    t = np.stack([ref.t for ref in per_instance])
    which = t.argmin(axis=0)
    rows = np.arange(len(origins))
    ref = per_instance[0]
    ordered = np.sort(t, axis=0)
    ref.t = ordered[0]
    ref.prim_id = np.stack([r.prim_id for r in per_instance])[which, rows]
    ref.normal = np.stack([r.normal for r in per_instance])[which, rows]
    ref.ambiguous = np.any([r.ambiguous for r in per_instance], axis=0)
    hit = np.isfinite(ordered[0])
    ref.ambiguous[hit] |= ordered[1][hit] - ordered[0][hit] <= 1e-5 * ordered[0][hit]
    expected_inst = np.asarray(inst_gids)[which]
    assert_hits_match(hits, ref, gid, expected_inst, normal_cos=0.9999, min_miss_fraction=0.05)
    assert len(np.unique(hits.inst_id[np.isfinite(hits.t)])) == len(TRANSFORMS)


# -- user against native -------------------------------------------------------------------------


@pytest.mark.parametrize("distance", [25.0, 1500.0])
def test_user_and_native_spheres_agree_on_the_same_rays(distance):
    rng = np.random.default_rng(77)
    centers = float32_exact(rng.uniform(-6, 6, (500, 3)))
    radii = float32_exact(rng.uniform(0.2, 0.8, 500))
    origins, directions = rays_toward_box(rng, 5000, [-7] * 3, [7] * 3, distance)
    origins, directions = float32_exact(origins), float32_exact(directions)
    answers = {}
    for kind in SPHERE_KINDS:
        bvh, _ = spheres_bvh(centers, radii, kind)
        with bvh:
            answers[kind] = bvh.intersect(Rays(origins, directions))
    user, point = answers["user"], answers["point"]
    differ = user.prim_id != point.prim_id
    # the documented exception: rays that graze a sphere or meet two at nearly the same t, to
    # within 8 ulps of the distance: there the float32 quadratic may go either way
    ref = sphere_hits(origins, directions, centers, radii, ambiguity=8 * ULP)
    assert ref.ambiguous[differ].all(), f"{(differ & ~ref.ambiguous).sum()} clear rays differ"
    assert differ.mean() <= 0.002, f"{differ.sum()} of {len(differ)} rays differ"
    both = ~differ & np.isfinite(user.t) & ~ref.ambiguous
    assert both.mean() > 0.3
    # native t: float32 cancellation costs a few ulps of the distance
    scale = distance + np.abs(centers).max()
    tolerance = 1e-5 * user.t[both] + ulps(scale, 16) / np.linalg.norm(directions[both], axis=1)
    assert np.all(np.abs(user.t[both] - point.t[both]) <= tolerance)
    cosine = np.einsum("ij,ij->i", unit(user.normal[both]), unit(point.normal[both]))
    assert cosine.min() > 0.9999


# -- storage order ------------------------------------------------------------------------------


def test_spatial_order_is_a_stable_permutation_along_the_morton_curve():
    from embree_rt.embree.spatial_order import morton_codes, spatial_order

    rng = np.random.default_rng(11)
    centers = rng.uniform(-50, 50, (5000, 3)).astype(np.float32)
    centers[::7] = centers[3]  # repeated centres: equal codes must keep their input order
    order = spatial_order(centers)
    assert order.dtype == np.int32
    assert np.array_equal(np.sort(order), np.arange(len(centers)))
    codes = morton_codes(centers)[order].astype(np.int64)
    assert np.all(np.diff(codes) >= 0)
    ties = np.diff(codes) == 0
    assert np.all(np.diff(order)[ties] > 0)
    # neighbours along the order are near in space: far nearer than random pairs
    step = np.linalg.norm(np.diff(centers[order], axis=0), axis=1)
    assert np.median(step) < 0.25 * np.median(np.linalg.norm(centers[1:] - centers[:-1], axis=1))


def test_storage_order_never_shows_in_the_answers():
    """The same spheres given in two orders answer every ray alike, with each sphere named by
    its index in the order given. Bitwise: a hit's t and normal come from the one sphere's own
    float64 arithmetic, whatever slot it is stored in (the same compiled code on this machine,
    whichever ISA it is)."""
    rng = np.random.default_rng(12)
    count = 3000
    centers = rng.uniform(-40, 40, (count, 3))
    radii = rng.uniform(0.3, 1.5, count)
    origins, directions = rays_toward_box(rng, 4000, np.full(3, -45.0), np.full(3, 45.0), 120.0)
    shuffle = rng.permutation(count)
    first, _ = spheres_bvh(centers, radii, "user")
    second, _ = spheres_bvh(centers[shuffle], radii[shuffle], "user")
    a = first.intersect(Rays(origins, directions))
    b = second.intersect(Rays(origins, directions))
    hit = np.isfinite(a.t)
    assert 0.2 < hit.mean() < 0.95
    assert np.array_equal(a.t, b.t, equal_nan=True)
    assert np.array_equal(a.prim_id[hit], shuffle[b.prim_id[hit]])
    assert np.array_equal(a.normal[hit], b.normal[hit])
    assert np.array_equal(
        first.occluded(Rays(origins, directions)), second.occluded(Rays(origins, directions))
    )


# -- grazing along the box's faces ----------------------------------------------------------------


def box_face_rays(rng, centers, radii, count: int, distance: float, tilt: float):
    """Rays from ``distance`` away along an axis (turned by up to ``tilt`` radians toward
    another) that graze a sphere where it touches its bounding box's face, 1e-7 of the radius
    inside or outside the silhouette: where Embree's float32 box test and the float64 sphere
    test could disagree. Origins, unit directions (count, 3), float32-exact."""
    target = rng.integers(0, len(centers), count)
    axis = rng.integers(0, 3, count)
    across = np.eye(3)[(axis + 1) % 3] * np.where(rng.random(count) < 0.5, -1.0, 1.0)[:, None]
    along = unit(np.eye(3)[axis] + tilt * rng.uniform(-1, 1, (count, 1)) * np.eye(3)[axis - 1])
    offset = radii[target, None] * (1 + rng.uniform(-1e-7, 1e-7, (count, 1)))
    origins = centers[target] - distance * along + offset * across
    return float32_exact(origins), float32_exact(along)


@pytest.mark.parametrize("lanes", [1, 8])
def test_rays_grazing_along_box_faces_miss_no_sure_hit(lanes):
    """Each sphere's box lies strictly outside it (the tightest float32 box that does), so
    Embree's box test culls no ray the float64 quadratic hits: every hit a float64 reference is
    sure of (its undecidable band shrunk to 1e-9 of the distance, far below the 1e-7 grazing
    offsets and float32's rounding of the origins) is found, by the sphere the reference
    names, and no sure miss is hit. Rays along an axis whose float32 origin lies exactly one
    radius from a centre touch that sphere on its box's face (a zero discriminant, exact in
    float64 for an axis direction): each of them hits. Boxes rounded to nearest answered 399
    of these 3004 sure rays wrongly and missed 42 of the 287 tangent ones."""
    rng = np.random.default_rng(90)
    centers = float32_exact(rng.uniform(-10, 10, (400, 3)))
    radii = float32_exact(rng.uniform(0.2, 0.9, 400))
    straight = box_face_rays(rng, centers, radii, 2000, 40.0, 0.0)
    parts = [
        straight,
        box_face_rays(rng, centers, radii, 1000, 40.0, 1e-3),
        box_face_rays(rng, centers, radii, 1000, 40.0, 0.3),
    ]
    origins = np.concatenate([p[0] for p in parts])
    directions = np.concatenate([p[1] for p in parts])
    ref = sphere_hits(origins, directions, centers, radii, ambiguity=1e-9)
    # The reference's own test for grazing rays cancels (|o - c|^2 against (d.(o - c))^2 with
    # the root taken from it): rays passing any sphere within 1e-9 of the distance, by the
    # cross product's distance from the centre, are left out too.
    offset = origins[:, None, :] - centers[None]
    off_axis = np.linalg.norm(np.cross(offset, directions[:, None, :]), axis=2)
    grazing = np.abs(off_axis - radii[None]) <= 1e-9 * np.linalg.norm(offset, axis=2)
    sure = ~ref.ambiguous & ~grazing.any(axis=1)
    assert sure.mean() > 0.7
    # a straight ray's offset from the sphere it was aimed at is exact in float64 (one
    # coordinate differs from the centre's)
    tangent = np.zeros(len(origins), bool)
    tangent[: len(straight[0])] = (off_axis[: len(straight[0])] == radii[None]).any(axis=1)
    assert tangent.sum() > 100
    with BVH(lanes=lanes) as bvh:
        bvh.add_spheres(centers, radii, kind="user")
        bvh.commit()
        hits = bvh.intersect(Rays(origins, directions))
        blocked = bvh.occluded(Rays(origins, directions))
    assert 0.3 < ref.hit[sure].mean() < 0.95
    found = np.where(np.isfinite(hits.t), hits.prim_id, -1)
    assert np.array_equal(found[sure], ref.prim_id[sure])
    assert np.array_equal(blocked[sure], ref.hit[sure])
    assert np.all(np.isfinite(hits.t[tangent])) and np.all(blocked[tangent])
