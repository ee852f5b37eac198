"""BVH queries across geometry kinds: occlusion, mixed scenes, empty scenes, thread-count and
batch independence, a million spheres, and input validation."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from bvh_reference import (
    AMBIGUITY,
    ReferenceHits,
    affine,
    assert_hits_match,
    float32_exact,
    near_triangle_edge,
    occluded_or_below_plane,
    random_soup,
    rays_toward_box,
    sphere_hits,
    transform_points,
    triangle_heights,
    triangle_hits,
    unit,
)
from tolerances import (
    MIN_COSINE,
    RTOL32,
    assert_close,
    assert_vectors_close,
    coordinate_scale,
    position_atol,
    ray_t_atol,
)

from embree_rt.embree import BVH, Rays
from embree_rt.tracing.segments import occluded_toward, toward_lights

KINDS = ("spheres", "triangles", "instances")


class Parts:
    """One random layout of the three kinds of geometry, overlapping in a common box."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.centers = float32_exact(rng.uniform(-6, 6, size=(150, 3)))
        self.radii = float32_exact(rng.uniform(0.2, 1.0, size=150))
        vertices, self.soup_faces = random_soup(rng, 200, extent=6.0)
        self.soup_vertices = float32_exact(vertices)
        ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        self.ico_vertices = float32_exact(ico.vertices)
        self.ico_faces = ico.faces
        self.transform = affine([1, 2, 0], 0.5, [3.0, 1.5, 2.0], [0.5, -0.5, 1.0])
        self.baked = transform_points(self.transform, self.ico_vertices)
        # float32 tolerances scale with the largest coordinate
        self.extent = coordinate_scale(
            np.abs(self.centers) + self.radii[:, None], self.soup_vertices, self.baked
        )

    def build(self, kinds=KINDS, threads: int | None = None):
        """A committed BVH holding ``kinds``; returns (bvh, ids) where ids maps kind -> the
        (geom_id, inst_id) a hit on it reports. The child BVH is kept alive on ``ids``."""
        bvh = BVH(threads=threads)
        ids = {}
        if "spheres" in kinds:
            ids["spheres"] = (bvh.add_spheres(self.centers, self.radii), -1)
        if "triangles" in kinds:
            ids["triangles"] = (bvh.add_triangles(self.soup_vertices, self.soup_faces), -1)
        if "instances" in kinds:
            child = BVH(threads=threads)
            child_gid = child.add_triangles(self.ico_vertices, self.ico_faces)
            child.commit()
            ids["instances"] = (child_gid, bvh.add_instance(child, self.transform))
            ids["child"] = child
        bvh.commit()
        return bvh, ids

    def feature_size(self, ids, hits) -> np.ndarray:
        """(n,) float64 size of what each hit met: the sphere's radius or the triangle's
        smallest height (an error e in the hit point turns a normal or moves u, v by ~e / size);
        NaN on a miss."""
        size = np.full(len(hits.t), np.nan)
        for kind, radius_or_height in (
            ("spheres", self.radii),
            ("triangles", triangle_heights(self.soup_vertices, self.soup_faces)),
            ("instances", triangle_heights(self.baked, self.ico_faces)),
        ):
            if kind in ids:
                geom, inst = ids[kind]
                on = np.isfinite(hits.t) & (hits.geom_id == geom) & (hits.inst_id == inst)
                size[on] = radius_or_height[hits.prim_id[on]]
        return size

    def reference(self, kinds, ids, origins, directions, tnear=0.0, tfar=np.inf):
        """Nearest hit over ``kinds`` as the minimum of the per-kind references.

        Returns (ReferenceHits, expected geom_id (n,), expected inst_id (n,)).
        """
        per_kind = []
        for kind in kinds:
            if kind == "spheres":
                ref = sphere_hits(origins, directions, self.centers, self.radii, tnear, tfar)
            elif kind == "triangles":
                ref = triangle_hits(
                    origins, directions, self.soup_vertices, self.soup_faces, tnear, tfar
                )
            else:
                ref = triangle_hits(origins, directions, self.baked, self.ico_faces, tnear, tfar)
            per_kind.append(ref)
        n = len(origins)
        t = np.stack([ref.t for ref in per_kind])
        winner = t.argmin(axis=0)
        rows = np.arange(n)
        ordered = np.sort(t, axis=0)
        nearest = ordered[0]
        # two kinds at (nearly) the same distance, within float32's reach: either may win
        t_atol = np.stack([ref.t_atol for ref in per_kind])
        tie = np.zeros(n, bool)
        if len(per_kind) > 1:
            finite = np.isfinite(nearest)
            reach = AMBIGUITY * nearest + 2 * t_atol.max(axis=0)
            tie[finite] = ordered[1][finite] - nearest[finite] <= reach[finite]
        combined = ReferenceHits(
            t=nearest,
            prim_id=np.stack([ref.prim_id for ref in per_kind])[winner, rows],
            normal=np.stack([ref.normal for ref in per_kind])[winner, rows],
            u=np.stack([ref.u for ref in per_kind])[winner, rows],
            v=np.stack([ref.v for ref in per_kind])[winner, rows],
            ambiguous=np.any([ref.ambiguous for ref in per_kind], axis=0) | tie,
            t_atol=t_atol[winner, rows],
            uv_atol=np.stack([ref.uv_atol for ref in per_kind])[winner, rows],
        )
        geom = np.array([ids[kind][0] for kind in kinds])[winner]
        inst = np.array([ids[kind][1] for kind in kinds])[winner]
        combined.prim_id = np.where(combined.hit, combined.prim_id, -1)
        return combined, geom, inst, winner


def our_triangle_edge_hits(hits, ids) -> np.ndarray:
    """(n,) bool: rays the BVH says hit a triangle on its edge (trimesh may see a miss there)."""
    on_triangles = np.isfinite(hits.t) & (hits.geom_id != ids.get("spheres", (-2,))[0])
    return on_triangles & near_triangle_edge(hits.u, hits.v)


@pytest.fixture(scope="module")
def parts():
    return Parts(30)


def rays(seed: int, count: int):
    origins, directions = rays_toward_box(np.random.default_rng(seed), count, [-7] * 3, [7] * 3, 25)
    return float32_exact(origins), float32_exact(directions)


KIND_SETS = [("spheres",), ("triangles",), ("instances",), KINDS]


@pytest.mark.parametrize("kinds", KIND_SETS, ids=lambda k: "+".join(k))
def test_nearest_hit_matches_reference(parts, kinds):
    origins, directions = rays(31, 2500)
    bvh, ids = parts.build(kinds)
    with bvh:
        hits = bvh.intersect(Rays(origins, directions))
    ref, geom, inst, winner = parts.reference(kinds, ids, origins, directions)
    ref.ambiguous |= our_triangle_edge_hits(hits, ids)
    sure = assert_hits_match(
        hits,
        ref,
        geom,
        inst,
        triangles=kinds != ("spheres",) and len(kinds) == 1,
        normal_cos=0.9995,
        min_hit_fraction=0.05,
        min_miss_fraction=0.02,
    )
    if len(kinds) > 1:
        # the mixed scene is a real test only if every kind wins somewhere
        won = winner[sure & ref.hit]
        assert all((won == k).sum() >= 20 for k in range(len(kinds))), np.bincount(won)
        tri = sure & ref.hit & (winner > 0)
        assert_close(hits.u[tri], ref.u[tri], atol=ref.uv_atol[tri], rtol=0.0, err_msg="u")
        assert_close(hits.v[tri], ref.v[tri], atol=ref.uv_atol[tri], rtol=0.0, err_msg="v")


@pytest.mark.parametrize("kinds", KIND_SETS, ids=lambda k: "+".join(k))
def test_occluded_agrees_with_reference_and_intersect(parts, kinds):
    origins, directions = rays(32, 2500)
    rng = np.random.default_rng(33)
    bvh, ids = parts.build(kinds)
    with bvh:
        first, *_ = parts.reference(kinds, ids, origins, directions)
        # per-ray windows around the first hit, so about half the rays are blocked
        reach = np.where(first.hit, first.t, 60.0 / np.linalg.norm(directions, axis=1))
        tnear = float32_exact(reach * rng.uniform(0.0, 0.4, len(reach)))
        tfar = float32_exact(reach * rng.uniform(0.5, 1.5, len(reach)))
        blocked = bvh.occluded(Rays(origins, directions, tnear=tnear, tfar=tfar))
        hits = bvh.intersect(Rays(origins, directions, tnear=tnear, tfar=tfar))
        # origins lie 25 from the centre and directions are 0.2..5 long: tfar = 8 cuts the box
        scalar_blocked = bvh.occluded(Rays(origins, directions, tfar=8.0))
        scalar_hits = bvh.intersect(Rays(origins, directions, tfar=8.0))
    ref, *_ = parts.reference(kinds, ids, origins, directions, tnear, tfar)
    sure = ~(ref.ambiguous | our_triangle_edge_hits(hits, ids))
    assert sure.mean() > 0.99
    # a real test: about half the rays that meet something are blocked within their window
    assert 0.3 < blocked[sure & first.hit].mean() < 0.7
    assert (sure & first.hit).sum() > 100
    assert blocked.dtype == np.bool_ and blocked.shape == (len(origins),)
    wrong = sure & (blocked != ref.hit)
    assert not wrong.any(), f"occluded wrong on rays {np.flatnonzero(wrong)[:5]}"
    assert np.array_equal(blocked[sure], np.isfinite(hits.t)[sure])
    scalar_ref, *_ = parts.reference(kinds, ids, origins, directions, 0.0, 8.0)
    sure = ~(scalar_ref.ambiguous | our_triangle_edge_hits(scalar_hits, ids))
    assert 0.02 < scalar_ref.hit[sure].mean() < 0.95
    assert np.array_equal(scalar_blocked[sure], scalar_ref.hit[sure])
    assert np.array_equal(scalar_blocked[sure], np.isfinite(scalar_hits.t)[sure])


@pytest.mark.parametrize("lanes", [1, 8])
@pytest.mark.parametrize("threads", [1, 2])
def test_occluded_toward_answers_what_occluded_answers_on_the_same_segments(parts, lanes, threads):
    """Segments from points (picked by index, with repeats) to one target, the ground plane
    y = -4 included, against ``occluded`` on the rays spelled out (origin p, direction
    target - p, t in [0, 1]) and against the float64 reference. One ray a query: bitwise the
    same answers (the same float32 rays through the same single-ray kernel). Packets: the
    kernel drops plane-blocked segments from its packets, so packets are cut elsewhere and
    only rays float64 cannot decide may go either way."""
    rng = np.random.default_rng(40)
    points = float32_exact(rng.uniform(-8.0, 8.0, (3, 4000)))
    rows = rng.integers(0, points.shape[1], 3000)
    target = np.float32([4.0, 9.0, -3.0])
    bvh, ids = parts.build(threads=threads)
    with bvh:
        bvh.lanes = lanes
        blocked = occluded_toward(bvh, points, rows, target, plane_y=-4.0)
        origins = points[:, rows].T.copy()
        directions = (target[:, None] - points[:, rows]).T.copy()
        expected = occluded_or_below_plane(bvh, origins, directions, 0.0, 1.0, -4.0)
        hits = bvh.intersect(Rays(origins, directions, 0.0, 1.0))
    below = origins[:, 1] < -4.0  # these cross the plane on their way up to the target
    assert 0.1 < below.mean() < 0.3 and blocked[below].all()
    assert 0.2 < blocked[~below].mean() < 0.8  # both answers are exercised
    if lanes == 1:
        assert np.array_equal(blocked, expected)
    ref, *_ = parts.reference(KINDS, ids, origins, directions, 0.0, 1.0)
    sure = ~(ref.ambiguous | our_triangle_edge_hits(hits, ids))
    assert sure.mean() > 0.99
    assert np.array_equal(blocked[sure], (ref.hit | below)[sure])
    assert np.array_equal(blocked[sure], expected[sure])


@pytest.mark.parametrize("threads", [1, 2])
def test_toward_lights_traces_the_facing_segments_and_gives_numpys_unit_directions(parts, threads):
    """Per light, the points whose normal faces it (and that take light) are the segments
    made; each is visible exactly when ``occluded_toward`` says the same segment is clear, and
    its direction is ``(target - p) / |target - p|`` formed as NumPy forms it (float32
    subtraction, products summed x + y then z, sqrt, 1 / max(length, 1e-30), one product per
    axis): IEEE operations in the same order, no fused multiply-add (numba does not contract
    without fastmath), so the bits agree on every x86-64 ISA. Single-ray queries, so the
    answers cannot depend on how packets are cut."""
    rng = np.random.default_rng(41)
    points = rng.uniform(-8.0, 8.0, (3, 3000)).astype(np.float32)
    normals = unit(rng.normal(size=(3000, 3))).T.astype(np.float32)
    takes = rng.random(3000) < 0.8
    targets = np.float32([[4.0, 9.0, -3.0], [-6.0, 12.0, 5.0]])
    bvh, _ = parts.build(threads=threads)
    with bvh:
        bvh.lanes = 1
        answers = list(toward_lights(bvh, points, normals, targets, takes, plane_y=-4.0))
        assert len(answers) == 2
        for target, (visible, directions, made) in zip(targets, answers, strict=True):
            to_light = target[:, None] - points
            facing = (to_light[0] * normals[0] + to_light[1] * normals[1]) + to_light[2] * normals[
                2
            ] > 0
            rows = np.flatnonzero(facing & takes)
            assert made == len(rows) and 0.2 < len(rows) / 3000 < 0.6
            expected = np.zeros(3000, bool)
            expected[rows] = ~occluded_toward(bvh, points, rows, target, plane_y=-4.0)
            assert np.array_equal(visible, expected) and 0.1 < visible.mean() < 0.5
            length = np.sqrt((to_light[0] ** 2 + to_light[1] ** 2) + to_light[2] ** 2)
            unit_toward = to_light * (np.float32(1.0) / np.maximum(length, np.float32(1e-30)))
            assert np.array_equal(directions[:, visible], unit_toward[:, visible])
            assert not directions[:, ~visible].any()
        # where every point takes light, every facing point makes a segment
        _, _, made = next(toward_lights(bvh, points, normals, targets[:1], np.ones(3000, bool)))
        to_light = targets[0][:, None] - points
        facing = (to_light[0] * normals[0] + to_light[1] * normals[1]) + to_light[2] * normals[2]
        assert made == np.count_nonzero(facing > 0)


def test_toward_lights_refuses_bad_points_normals_and_takes(parts):
    bvh, _ = parts.build(("spheres",))
    points = np.zeros((3, 5), np.float32)
    normals = np.ones((3, 5), np.float32)
    takes = np.ones(5, bool)
    with bvh:
        with pytest.raises(ValueError, match=r"normals: expected shape \(3, n\)"):
            next(toward_lights(bvh, points, normals[:, :4], [0, 1, 0], takes))
        with pytest.raises(ValueError, match=r"takes: expected \(5,\) bool"):
            next(toward_lights(bvh, points, normals, [0, 1, 0], np.ones(5)))
        normals[2, 1] = np.inf
        with pytest.raises(ValueError, match="normals: row 1 is not finite"):
            next(toward_lights(bvh, points, normals, [0, 1, 0], takes))


def test_occluded_toward_refuses_bad_points_and_rows(parts):
    bvh, _ = parts.build(("spheres",))
    points = np.zeros((3, 5), np.float32)
    with bvh:
        assert occluded_toward(bvh, points, np.zeros(0, np.int64), [0, 1, 0]).shape == (0,)
        with pytest.raises(ValueError, match=r"rows: row 1 is 5, outside \[0, 5\)"):
            occluded_toward(bvh, points, [0, 5], [0, 1, 0])
        with pytest.raises(ValueError, match="rows: row 0 is -1"):
            occluded_toward(bvh, points, [-1], [0, 1, 0])
        with pytest.raises(ValueError, match="rows: expected"):
            occluded_toward(bvh, points, [0.5], [0, 1, 0])
        with pytest.raises(ValueError, match=r"points: expected shape \(3, n\)"):
            occluded_toward(bvh, points.T, [0], [0, 1, 0])
        points[1, 3] = np.nan
        with pytest.raises(ValueError, match="points: row 3 is not finite"):
            occluded_toward(bvh, points, [0], [0, 1, 0])
        with pytest.raises(ValueError, match="target: row 0 is not finite"):
            occluded_toward(bvh, points[:, :3], [0], [0, np.inf, 0])


def test_empty_scene_misses_everything():
    origins, directions = rays(34, 100)
    with BVH() as bvh:
        bvh.commit()
        hits = bvh.intersect(Rays(origins, directions))
        blocked = bvh.occluded(Rays(origins, directions))
    assert np.all(np.isinf(hits.t)) and np.all(hits.t > 0)
    for name in ("geom_id", "prim_id", "inst_id"):
        assert np.all(getattr(hits, name) == -1), name
    assert not blocked.any()


def test_zero_rays(parts):
    bvh, _ = parts.build()
    with bvh:
        hits = bvh.intersect(Rays(np.zeros((0, 3)), np.zeros((0, 3))))
        blocked = bvh.occluded(Rays(np.zeros((0, 3)), np.zeros((0, 3))))
    assert hits.t.shape == (0,) and hits.prim_id.shape == (0,) and hits.normal.shape == (0, 3)
    assert blocked.shape == (0,)


def test_one_thread_and_two_threads_give_identical_results(parts):
    origins, directions = rays(35, 20000)
    tnear = float32_exact(np.random.default_rng(36).uniform(0, 3, len(origins)))
    results = []
    for threads in (1, 2):
        bvh, _ = parts.build(threads=threads)
        with bvh:
            hits = bvh.intersect(Rays(origins, directions, tnear=tnear))
            blocked = bvh.occluded(Rays(origins, directions, tnear=tnear, tfar=8.0))
        results.append((hits, blocked))
    (a, blocked_a), (b, blocked_b) = results
    hit = np.isfinite(a.t)
    assert 0.2 < hit.mean() < 0.95
    # Bitwise, on any ISA: the thread count only decides which thread traces a chunk of rays.
    # Each ray meets the same Embree kernel (packets are cut at the same offsets of the ray
    # array) with the same float32 inputs, so the same operations in the same order. The bits
    # may differ from one machine to another, never between thread counts on one machine.
    for name in ("t", "geom_id", "prim_id", "inst_id"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("normal", "u", "v"):
        assert np.array_equal(getattr(a, name)[hit], getattr(b, name)[hit]), name
    assert np.array_equal(blocked_a, blocked_b)


def test_batch_equals_one_ray_at_a_time(parts):
    origins, directions = rays(37, 40)
    tnear = float32_exact(np.random.default_rng(38).uniform(0, 2, 40))
    bvh, ids = parts.build()
    with bvh:
        batch = bvh.intersect(Rays(origins, directions, tnear=tnear))
        batch_blocked = bvh.occluded(Rays(origins, directions, tnear=tnear, tfar=30.0))
        assert 5 < np.isfinite(batch.t).sum() < 38
        for i in range(len(origins)):
            one = bvh.intersect(Rays(origins[i : i + 1], directions[i : i + 1], tnear=tnear[i]))
            blocked = bvh.occluded(Rays(origins[i : i + 1], directions[i : i + 1], tnear[i], 30.0))
            for name in ("geom_id", "prim_id", "inst_id"):
                assert getattr(one, name)[0] == getattr(batch, name)[i], (name, i)
            assert blocked[0] == batch_blocked[i], i
            # A lone ray may take Embree's single-ray path and a batch its packet path (and
            # both differ from one ISA to another): they agree to float32 rounding of the
            # coordinates, the hit point, and through it u, v on a triangle of this size.
            if np.isfinite(one.t[0]):
                atol = ray_t_atol(
                    origins[i : i + 1], directions[i : i + 1], parts.extent, normals=one.normal
                )
                assert_close(one.t, batch.t[i : i + 1], atol=atol, err_msg=f"t of ray {i}")
                # the hit point's uncertainty over the size of the sphere or triangle it is on
                turn = atol * np.linalg.norm(directions[i]) / parts.feature_size(ids, one)
                assert_vectors_close(
                    unit(one.normal),
                    unit(batch.normal[i : i + 1]),
                    atol=turn,
                    err_msg=f"normal of ray {i}",
                )
                if one.geom_id[0] != ids["spheres"][0]:
                    assert_close(
                        [one.u[0], one.v[0]],
                        [batch.u[i], batch.v[i]],
                        atol=turn[0],
                        err_msg=f"u, v of ray {i}",
                    )
            else:
                assert np.isinf(batch.t[i]), i


def test_scalar_window_equals_the_same_window_per_ray(parts):
    origins, directions = rays(39, 3000)
    bvh, _ = parts.build()
    with bvh:
        scalar = bvh.intersect(Rays(origins, directions, tnear=1.5, tfar=9.0))
        per_ray = bvh.intersect(
            Rays(origins, directions, tnear=np.full(3000, 1.5), tfar=np.full(3000, 9.0))
        )
        blocked = bvh.occluded(Rays(origins, directions, tnear=1.5, tfar=9.0))
        blocked_per_ray = bvh.occluded(
            Rays(origins, directions, tnear=np.full(3000, 1.5), tfar=np.full(3000, 9.0))
        )
    # Bitwise, on any ISA: a scalar window is broadcast to the very float32 values the per-ray
    # arrays hold, and the rays go through the same kernel either way.
    for name in ("t", "geom_id", "prim_id", "inst_id"):
        assert np.array_equal(getattr(scalar, name), getattr(per_ray, name)), name
    assert np.array_equal(blocked, blocked_per_ray)


def test_context_manager_and_close():
    with BVH() as bvh:
        assert isinstance(bvh, BVH)
        bvh.add_spheres([[0.0, 0.0, 0.0]], [1.0])
        bvh.commit()
        t = bvh.intersect(Rays([[0.0, 0.0, 5.0]], [[0.0, 0.0, -1.0]])).t
        assert_close(t, [4.0], atol=position_atol(5.0))
    other = BVH(threads=1)
    other.add_spheres([[0.0, 0.0, 0.0]], [1.0])
    other.commit()
    assert other.occluded(Rays([[0.0, 0.0, 5.0]], [[0.0, 0.0, -1.0]]))[0]
    other.close()


# -- a million spheres ----------------------------------------------------------------------------

SIDE = 1000  # SIDE x SIDE spheres, one per unit cell, each inside its cell seen from above


@pytest.fixture(scope="module")
def million():
    rng = np.random.default_rng(40)
    radii = float32_exact(rng.uniform(0.15, 0.4, SIDE * SIDE))
    i, j = np.divmod(np.arange(SIDE * SIDE), SIDE)
    play = 0.49 - radii  # keep every sphere inside its cell in x and y
    centers = np.c_[
        i + 0.5 + rng.uniform(-1, 1, SIDE * SIDE) * play,
        j + 0.5 + rng.uniform(-1, 1, SIDE * SIDE) * play,
        rng.uniform(-0.2, 0.2, SIDE * SIDE),
    ]
    centers = float32_exact(centers)
    bvh = BVH()
    gid = bvh.add_spheres(centers, radii)
    bvh.commit()
    yield centers, radii, bvh, gid
    bvh.close()


def test_million_spheres_vertical_rays_closed_form(million):
    """100k rays straight down: only the sphere of the cell below can be hit, so the answer
    is closed-form for every ray."""
    centers, radii, bvh, gid = million
    rng = np.random.default_rng(41)
    count = 100_000
    xy = float32_exact(rng.uniform(0, SIDE, size=(count, 2)))
    origins = np.c_[xy, np.full(count, 5.0)]
    directions = np.tile([0.0, 0.0, -1.0], (count, 1))
    hits = bvh.intersect(Rays(origins, directions))
    blocked = bvh.occluded(Rays(origins, directions, tfar=4.0))

    cell = np.floor(xy).astype(np.int64)
    index = cell[:, 0] * SIDE + cell[:, 1]
    offset = np.linalg.norm(xy - centers[index, :2], axis=1)
    r = radii[index]
    hit = offset < r
    t = np.where(hit, 5.0 - centers[index, 2] - np.sqrt(np.maximum(r * r - offset**2, 0)), np.inf)
    sure = np.abs(offset - r) > 1e-4
    assert sure.mean() > 0.99 and 0.2 < hit.mean() < 0.8
    assert np.array_equal(np.isfinite(hits.t)[sure], hit[sure])
    both = sure & hit
    # float32 against the float64 closed form: the hit point is known to rounding of the
    # coordinates (up to 1000 here), over the cosine of the angle the ray meets the sphere at
    # (offset / r is the sine of it).
    cosine = np.sqrt(np.maximum(1.0 - (offset / r) ** 2, 0.0))
    atol = ray_t_atol(origins, directions, SIDE) / np.maximum(cosine, MIN_COSINE)
    assert_close(hits.t[both], t[both], atol=atol[both], rtol=RTOL32)
    assert np.array_equal(hits.prim_id[both], index[both])
    assert np.all(hits.geom_id[both] == gid)
    # every sphere top lies below z = 0.6, i.e. t >= 4.4: nothing is within tfar = 4
    assert not blocked.any()
    assert np.array_equal(bvh.occluded(Rays(origins, directions, tfar=10.0))[sure], hit[sure])


def test_million_spheres_oblique_rays_brute_force(million):
    """100k steep oblique rays; 200 of them checked against all 1M spheres in float64."""
    centers, radii, bvh, gid = million
    rng = np.random.default_rng(42)
    count = 100_000
    targets = np.c_[rng.uniform(0, SIDE, size=(count, 2)), np.zeros(count)]
    origins = float32_exact(
        targets + np.c_[rng.uniform(-60, 60, size=(count, 2)), np.full(count, 150.0)]
    )
    directions = float32_exact((targets - origins) / 150.0)
    hits = bvh.intersect(Rays(origins, directions))
    assert 0.2 < np.isfinite(hits.t).mean() < 0.95
    subset = rng.choice(count, 200, replace=False)
    ref = sphere_hits(origins[subset], directions[subset], centers, radii, ambiguity=1e-6)
    names = ("t", "geom_id", "prim_id", "inst_id", "normal", "u", "v")
    picked = SimpleNamespace(**{name: getattr(hits, name)[subset] for name in names})
    assert_hits_match(
        picked, ref, gid, max_ambiguous=0.03, min_hit_fraction=0.15, min_miss_fraction=0.05
    )


# -- validation -----------------------------------------------------------------------------------

BAD_ROW = 13  # rows 0..19; no shape or bound in the messages should read "13"


def good(count: int = 20) -> np.ndarray:
    return np.random.default_rng(50).uniform(-1, 1, size=(count, 3))


def with_bad_row(values: np.ndarray, bad) -> np.ndarray:
    values = np.array(values, dtype=np.result_type(values, type(bad)))
    values[BAD_ROW] = bad
    return values


def expect_error(call, argument: str, row: int | None = BAD_ROW) -> None:
    with pytest.raises(ValueError) as caught:
        call()
    message = str(caught.value)
    assert argument in message, f"{message!r} does not name {argument!r}"
    if row is not None:
        assert re.search(rf"\b{row}\b", message), f"{message!r} does not name row {row}"


def spheres_call(centers=None, radii=None):
    centers = good() if centers is None else centers
    radii = np.full(20, 0.1) if radii is None else radii
    return lambda: BVH().add_spheres(centers, radii)


GOOD_FACES = np.arange(60).reshape(20, 3) % 30  # 20 faces into 30 vertices


def triangles_call(vertices=None, faces=None):
    vertices = good(30) if vertices is None else vertices
    faces = GOOD_FACES if faces is None else faces
    return lambda: BVH().add_triangles(vertices, faces)


@pytest.mark.parametrize(
    "call, argument, row",
    [
        (spheres_call(centers=good()[:, :2]), "centers", None),
        (spheres_call(centers=good()[None]), "centers", None),
        (spheres_call(radii=np.full(19, 0.1)), "radii", None),
        (spheres_call(radii=np.full((20, 1), 0.1)), "radii", None),
        (spheres_call(centers=with_bad_row(good(), np.nan)), "centers", BAD_ROW),
        (spheres_call(centers=with_bad_row(good(), np.inf)), "centers", BAD_ROW),
        (spheres_call(radii=with_bad_row(np.full(20, 0.1), -0.5)), "radii", BAD_ROW),
        (spheres_call(radii=with_bad_row(np.full(20, 0.1), 0.0)), "radii", BAD_ROW),
        (spheres_call(radii=with_bad_row(np.full(20, 0.1), np.nan)), "radii", BAD_ROW),
        (triangles_call(vertices=good(30)[:, :2]), "vertices", None),
        (triangles_call(vertices=with_bad_row(good(30), -np.inf)), "vertices", BAD_ROW),
        (triangles_call(faces=np.arange(80).reshape(20, 4) % 30), "faces", None),
        (triangles_call(faces=with_bad_row(GOOD_FACES, 30)), "faces", BAD_ROW),
        (triangles_call(faces=with_bad_row(GOOD_FACES, -1)), "faces", BAD_ROW),
    ],
    ids=lambda value: value if isinstance(value, str) else "",
)
def test_geometry_validation(call, argument, row):
    expect_error(call, argument, row)


def instance_call(transform):
    def call():
        child = BVH()
        child.add_spheres([[0.0, 0.0, 0.0]], [1.0])
        child.commit()
        BVH().add_instance(child, transform)

    return call


def matrix_with(row: int, column: int, value: float) -> np.ndarray:
    matrix = affine([0, 0, 1], 0.3, [1, 2, 3], [1, 1, 1])
    matrix[row, column] = value
    return matrix


@pytest.mark.parametrize(
    "transform",
    [
        np.eye(4)[:3],
        np.eye(3),
        matrix_with(1, 2, np.nan),
        matrix_with(0, 3, np.inf),
        matrix_with(3, 0, 0.5),
    ],
    ids=["3x4", "3x3", "nan", "inf", "projective"],
)
def test_transform_validation(transform):
    expect_error(instance_call(transform), "transform", None)


@pytest.fixture(scope="module")
def small_bvh():
    bvh = BVH()
    bvh.add_spheres([[0.0, 0.0, 0.0]], [1.0])
    bvh.commit()
    yield bvh
    bvh.close()


@pytest.mark.parametrize("method", ["intersect", "occluded"])
@pytest.mark.parametrize(
    "arguments, argument, row",
    [
        ({"origins": good()[:, :2]}, "origins", None),
        ({"origins": with_bad_row(good(), np.nan)}, "origins", BAD_ROW),
        ({"directions": with_bad_row(good(), np.inf)}, "directions", BAD_ROW),
        ({"directions": with_bad_row(good(), np.nan)}, "directions", BAD_ROW),
        ({"directions": good(19)}, "directions", None),
        ({"tnear": np.zeros(19)}, "tnear", None),
        ({"tfar": np.ones((20, 1))}, "tfar", None),
        ({"tnear": with_bad_row(np.zeros(20), np.nan)}, "tnear", BAD_ROW),
    ],
    ids=lambda value: value if isinstance(value, str) else "",
)
def test_ray_validation(small_bvh, method, arguments, argument, row):
    call_arguments = {"origins": good() + np.array([0, 0, 5]), "directions": good(), **arguments}
    expect_error(lambda: getattr(small_bvh, method)(Rays(**call_arguments)), argument, row)


def test_window_with_tnear_beyond_tfar_is_empty(parts):
    origins, directions = rays(43, 500)
    bvh, _ = parts.build()
    with bvh:
        hits = bvh.intersect(Rays(origins, directions, tnear=5.0, tfar=4.0))
        blocked = bvh.occluded(Rays(origins, directions, tnear=5.0, tfar=4.0))
        assert np.isfinite(bvh.intersect(Rays(origins, directions, tnear=4.0, tfar=50.0)).t).any()
    assert np.all(np.isinf(hits.t)) and np.all(hits.geom_id == -1) and not blocked.any()


def test_strided_and_fortran_ordered_inputs_give_the_same_answers(parts):
    origins, directions = rays(44, 3000)
    tnear = np.random.default_rng(45).uniform(0, 2, 6000)
    bvh, _ = parts.build()
    with bvh:
        expected = bvh.intersect(Rays(origins[::2], directions[::2], tnear=tnear[::2][::2].copy()))
        # every other row of a C array, columns of a Fortran array, a strided tnear
        layouts = bvh.intersect(
            Rays(origins[::2], np.asfortranarray(directions[::2]), tnear=tnear[::2][::2])
        )
        assert np.isfinite(expected.t).mean() > 0.1
        # Bitwise, on any ISA: the layouts are copied into the same contiguous float32 rays
        # before Embree sees them, so the same kernel gets the same bits.
        for name in ("t", "geom_id", "prim_id", "inst_id"):
            assert np.array_equal(getattr(expected, name), getattr(layouts, name)), name
        blocked = bvh.occluded(Rays(origins[::2], np.asfortranarray(directions[::2]), tfar=8.0))
        assert np.array_equal(
            blocked, bvh.occluded(Rays(origins[::2].copy(), directions[::2].copy(), tfar=8.0))
        )
