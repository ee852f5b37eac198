"""The word layout embree_rt's kernels and sphere callbacks assume, proved against Embree itself.

``embree_rt.embree.kernels`` names the 4-byte words of ``RTCRayHit`` / ``RTCRayHitN``
(``RAY_*``, ``HIT_*``), and ``user_spheres`` reads the callbacks' argument structs and the ray
query context by position. Here the tests call Embree's own ``rtcIntersect{1,4,8,16}`` /
``rtcOccluded{1,4,8,16}`` and ``rtcGetSceneBounds`` through ctypes on hand-filled buffers,
bypassing our query kernels, so every word is checked where Embree (for its native triangles and
points) and our callbacks (for user spheres, at every packet width Embree can hand them) write it:
hits on top-level geometry and inside an instance, a masked-off lane, a miss, the occlusion
protocol (``tfar = -inf``) and the bounds the bounds callback reports.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np
import pytest
from bvh_reference import unit

from embree_rt.embree import BVH, kernels, library

K = kernels
INVALID = library.INVALID_ID
SENTINEL = 0xDEADBEEF  # what every hit word holds before a query: no real id or float
WIDTHS = (1, 4, 8, 16)


class _Ray(ctypes.Structure):
    """``RTCRay`` transcribed from Embree 4's rtcore_ray.h."""

    _fields_ = [
        (name, ctypes.c_float)
        for name in ("org_x", "org_y", "org_z", "tnear", "dir_x", "dir_y", "dir_z", "time", "tfar")
    ] + [(name, ctypes.c_uint) for name in ("mask", "id", "flags")]


class _Hit(ctypes.Structure):
    """``RTCHit`` with RTC_MAX_INSTANCE_LEVEL_COUNT = 1 and RTC_GEOMETRY_INSTANCE_ARRAY."""

    _fields_ = [(name, ctypes.c_float) for name in ("Ng_x", "Ng_y", "Ng_z", "u", "v")] + [
        (name, ctypes.c_uint) for name in ("primID", "geomID", "instID", "instPrimID")
    ]


def test_word_constants_match_the_header_transcription():
    ray = {name: getattr(_Ray, name).offset // 4 for name, _ in _Ray._fields_}
    hit = {name: 12 + getattr(_Hit, name).offset // 4 for name, _ in _Hit._fields_}
    assert (ray["org_x"], ray["tnear"], ray["dir_x"], ray["time"], ray["tfar"]) == (
        K.RAY_ORG,
        K.RAY_TNEAR,
        K.RAY_DIR,
        K.RAY_TIME,
        K.RAY_TFAR,
    )
    assert (ray["mask"], ray["id"], ray["flags"]) == (K.RAY_MASK, K.RAY_ID, K.RAY_FLAGS)
    assert (hit["Ng_x"], hit["u"], hit["v"]) == (K.HIT_NG, K.HIT_U, K.HIT_V)
    assert (hit["primID"], hit["geomID"], hit["instID"], hit["instPrimID"]) == (
        K.HIT_PRIM_ID,
        K.HIT_GEOM_ID,
        K.HIT_INST_ID,
        K.HIT_INST_PRIM_ID,
    )
    # RTCRay is 48 bytes; RTCHit (36 bytes) is padded to 48 by its 16-byte alignment, so one
    # RTCRayHit (96 bytes) must fit in a chunk's scratch row after aligning it; a packet holds
    # 21 fields of one word a lane.
    assert ctypes.sizeof(_Ray) == 48 and K.PACKET_FIELDS == 21
    assert K.SCRATCH_WORDS * 4 >= 48 + 48 + K.PACKET_ALIGN


# -- raw queries ----------------------------------------------------------------------------------


def _function(name: str, arguments: int):
    prototype = ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * arguments))
    return prototype(library.function_address(name))


def _aligned(words: int, dtype) -> np.ndarray:
    """A zeroed (words,) 4-byte array starting on a 64-byte boundary (Embree loads packets and
    their valid masks with aligned vector loads)."""
    storage = np.zeros(words + 16, dtype)
    start = (-storage.ctypes.data % 64) // 4
    return storage[start : start + words]


def raw_query(scene: int, width: int, rays: list[tuple], valid: np.ndarray, occluded: bool):
    """Fill an ``RTCRayHitN`` (or ``RTCRayHit`` for width 1) by hand, run Embree's own query on
    it and return the (21, width) words before and after, as uint32."""
    words = _aligned(21 * width, np.uint32).reshape(21, width)
    floats = words.view(np.float32)
    words[K.HIT_NG :] = SENTINEL
    for lane, (origin, direction, tnear, tfar) in enumerate(rays):
        floats[K.RAY_ORG : K.RAY_ORG + 3, lane] = origin
        floats[K.RAY_TNEAR, lane] = tnear
        floats[K.RAY_DIR : K.RAY_DIR + 3, lane] = direction
        floats[K.RAY_TIME, lane] = 0.0
        floats[K.RAY_TFAR, lane] = tfar
        words[K.RAY_MASK, lane] = 0xFFFFFFFF
        words[K.RAY_ID, lane] = 1000 + lane
        words[K.RAY_FLAGS, lane] = 0
        words[K.HIT_GEOM_ID, lane] = INVALID
        words[K.HIT_INST_ID, lane] = INVALID
    before = words.copy()
    name = f"rtc{'Occluded' if occluded else 'Intersect'}{width}"
    if width == 1:
        # RTCRayHit for one ray is the same words with N = 1
        _function(name, 3)(scene, words.ctypes.data, None)
    else:
        mask = _aligned(width, np.int32)
        mask[:] = np.where(valid, -1, 0)
        _function(name, 4)(mask.ctypes.data, scene, words.ctypes.data, None)
    return before, words.copy()


@dataclass
class Target:
    """One ray and what Embree must write for it."""

    origin: tuple
    direction: tuple
    t: float  # np.inf: a miss
    normal: tuple  # expected direction of Ng, in the hit object's own space
    u: float
    v: float
    prim: int
    geom: int
    inst: int
    inst_prim: int


@pytest.fixture(scope="module")
def scene():
    """A top level with two far-away dummy meshes first (so ids differ from their positions),
    user spheres, point spheres and an instance of a child holding a triangle, user spheres
    and point spheres. The ids an instanced target reports differ from each other, so a swapped
    word shows."""
    far = np.array([[500.0, 500, 500], [501, 500, 500], [500, 501, 500]])
    child = BVH()
    child.add_triangles(far, [[0, 1, 2]])
    tri = child.add_triangles(
        np.r_[far, [[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 0], [6, 5, 0], [5, 6, 0]]],
        [[0, 1, 2], [0, 2, 1], [3, 4, 5], [6, 7, 8]],
    )
    user_in = child.add_spheres(
        [[0, 0, 9.0]] * 3 + [[-3, 0, 6.0], [0, 0, 9.0]], [0.1] * 3 + [1.0, 0.1], kind="user"
    )
    point_in = child.add_spheres([[9, 9, 9.0], [0, 3, 6.0]], [0.1, 1.0], kind="point")
    child.commit()
    top = BVH()
    top.add_triangles(far, [[0, 1, 2]])
    top.add_triangles(far + 10, [[0, 1, 2]])
    user_top = top.add_spheres([[-9, -9, 0.0]] * 3 + [[20.0, 0, 0]], [0.1] * 3 + [2.0])
    point_top = top.add_spheres([[-9, 9, 0.0]] * 2 + [[-20.0, 0, 0]], [0.1] * 2 + [2.0], "point")
    # object -> world: scale x by 2, then move up by 10 along z
    transform = np.array([[2.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 10], [0, 0, 0, 1]])
    inst = top.add_instance(child, transform)
    top.commit()
    assert (tri, user_in, point_in, user_top, point_top, inst) == (1, 2, 3, 2, 3, 4)
    targets = [
        # straight up +z into the instance: object-space z = world z - 10
        Target((0.2, 0.2, 0.0), (0, 0, 1), 10.0, (0, 0, 1), 0.1, 0.2, 2, tri, inst, 0),
        Target((10.4, 5.2, 1.0), (0, 0, 2), 4.5, (0, 0, 1), 0.2, 0.2, 3, tri, inst, 0),
        Target((-6.0, 0.0, -10.0), (0, 0, 1), 25.0, (0, 0, -1), 0, 0, 3, user_in, inst, 0),
        Target((0.0, 3.0, -10.0), (0, 0, 0.5), 50.0, (0, 0, -1), 0, 0, 1, point_in, inst, 0),
        # along x at the top level
        Target((0.0, 0.0, 0.0), (1, 0, 0), 18.0, (-1, 0, 0), 0, 0, 3, user_top, INVALID, INVALID),
        Target((0.0, 0, 0), (-4, 0, 0), 4.5, (1, 0, 0), 0, 0, 2, point_top, INVALID, INVALID),
        # from inside the top-level user sphere: the exit point, normal outward
        Target((20.0, 0, 0), (0, 0.5, 0), 4.0, (0, 1, 0), 0, 0, 3, user_top, INVALID, INVALID),
        # a miss
        Target((0.0, 0, -50), (0, 0, -1), np.inf, (0, 0, 0), 0, 0, 0, INVALID, INVALID, INVALID),
    ]
    yield top, targets
    top.close()
    child.close()


def lanes_for(width: int, targets: list[Target], shift: int) -> list[Target]:
    return [targets[(shift + lane) % len(targets)] for lane in range(width)]


@pytest.mark.parametrize("width", WIDTHS)
def test_intersect_writes_each_field_in_its_word(scene, width):
    top, targets = scene
    # width 1: one query per target; wider: every target in every lane position across calls
    for shift in range(len(targets)):
        lanes = lanes_for(width, targets, shift)
        valid = np.ones(width, bool)
        if width > 1:
            valid[shift % width] = False  # a masked-off lane must be left untouched
        rays = [(t.origin, t.direction, 0.0, np.inf) for t in lanes]
        before, after = raw_query(top._live_scene(), width, rays, valid, occluded=False)
        floats = after.view(np.float32)
        for lane, target in enumerate(lanes):
            if not valid[lane]:
                np.testing.assert_array_equal(after[:, lane], before[:, lane])
                continue
            # the ray words stay as they were, except tfar
            unchanged = [w for w in range(12) if w != K.RAY_TFAR]
            np.testing.assert_array_equal(after[unchanged, lane], before[unchanged, lane])
            if target.t == np.inf:
                assert floats[K.RAY_TFAR, lane] == np.inf
                assert after[K.HIT_GEOM_ID, lane] == INVALID
                continue
            # every t here is exact in float32 arithmetic (integers over powers of two)
            assert floats[K.RAY_TFAR, lane] == pytest.approx(target.t, rel=1e-6)
            ids = after[[K.HIT_PRIM_ID, K.HIT_GEOM_ID, K.HIT_INST_ID, K.HIT_INST_PRIM_ID], lane]
            assert ids.tolist() == [target.prim, target.geom, target.inst, target.inst_prim], (
                f"lane {lane}: ids {ids.tolist()} for {target}"
            )
            normal = floats[K.HIT_NG : K.HIT_NG + 3, lane].astype(np.float64)
            np.testing.assert_allclose(unit(normal[None])[0], target.normal, atol=1e-6)
            assert floats[K.HIT_U, lane] == pytest.approx(target.u, abs=1e-6)
            assert floats[K.HIT_V, lane] == pytest.approx(target.v, abs=1e-6)


@pytest.mark.parametrize("width", WIDTHS)
def test_occluded_sets_tfar_to_minus_infinity_and_nothing_else(scene, width):
    top, targets = scene
    for shift in range(len(targets)):
        lanes = lanes_for(width, targets, shift)
        valid = np.ones(width, bool)
        if width > 1:
            valid[(shift + 1) % width] = False
        # tfar just short of each hit for half of the lanes: those must stay unblocked
        short = [(lane + shift) % 2 == 1 for lane in range(width)]
        rays = [
            (t.origin, t.direction, 0.0, t.t * 0.99 if cut else np.inf)
            for t, cut in zip(lanes, short, strict=True)
        ]
        before, after = raw_query(top._live_scene(), width, rays, valid, occluded=True)
        floats = after.view(np.float32)
        for lane, target in enumerate(lanes):
            expected = before[:, lane].copy()
            if valid[lane] and np.isfinite(target.t) and not short[lane]:
                expected.view(np.float32)[K.RAY_TFAR] = -np.inf
            np.testing.assert_array_equal(after[:, lane], expected, err_msg=f"lane {lane}")
            assert (floats[K.RAY_TFAR, lane] == -np.inf) == (
                bool(valid[lane]) and np.isfinite(target.t) and not short[lane]
            )


def test_bounds_callback_reports_each_spheres_box():
    """rtcGetSceneBounds of user spheres only is the union of what the bounds callback wrote:
    the tightest float32 box strictly outside centre -/+ radius (exact in float64, and float32
    rounding is the same on every ISA)."""
    rng = np.random.default_rng(60)
    centers = rng.uniform(-100, 100, (37, 3)).astype(np.float32)
    radii = rng.uniform(0.1, 5, 37).astype(np.float32)
    with BVH() as bvh:
        bvh.add_spheres(centers, radii, kind="user")
        bvh.commit()
        box = _aligned(8, np.float32)
        _function("rtcGetSceneBounds", 2)(bvh._live_scene(), box.ctypes.data)
    exact = centers.astype(np.float64), radii.astype(np.float64)[:, None]
    low, high = (exact[0] - exact[1]).min(axis=0), (exact[0] + exact[1]).max(axis=0)
    assert np.all(box[:3] < low) and np.all(np.nextafter(box[:3], np.float32(np.inf)) >= low)
    assert np.all(box[4:7] > high) and np.all(np.nextafter(box[4:7], np.float32(-np.inf)) <= high)


def test_each_spheres_box_is_the_tightest_float32_box_strictly_outside_it():
    """Sphere by sphere (a BVH of one each): every face is the float32 next to centre -/+
    radius on the outside, computed exactly in float64, for spheres whose faces rounded to
    nearest would land inside, outside or exactly on the sphere."""
    rng = np.random.default_rng(61)
    centers = rng.uniform(-1e3, 1e3, (48, 3)).astype(np.float32)
    centers[:16] = rng.uniform(-1, 1, (16, 3)).astype(np.float32)
    radii = rng.uniform(1e-3, 50, 48).astype(np.float32)
    radii[8:16] = 0.5  # centres near 0: sums exact in float32, faces on the sphere itself
    bounds = _function("rtcGetSceneBounds", 2)
    lows, highs = [], []
    for k in range(len(centers)):
        with BVH() as bvh:
            bvh.add_spheres(centers[k : k + 1], radii[k : k + 1], kind="user")
            bvh.commit()
            box = _aligned(8, np.float32)
            bounds(bvh._live_scene(), box.ctypes.data)
        lows.append(box[:3].copy())
        highs.append(box[4:7].copy())
    low, high = np.array(lows), np.array(highs)
    exact_low = centers.astype(np.float64) - radii.astype(np.float64)[:, None]
    exact_high = centers.astype(np.float64) + radii.astype(np.float64)[:, None]
    assert np.all(low < exact_low) and np.all(high > exact_high)
    assert np.all(np.nextafter(low, np.float32(np.inf)) >= exact_low)
    assert np.all(np.nextafter(high, np.float32(-np.inf)) <= exact_high)
    nearest = (centers - radii[:, None], centers + radii[:, None])
    assert np.any(nearest[0] > exact_low) and np.any(nearest[1] < exact_high), "some inside"
    assert np.any(nearest[0] == exact_low), "some faces on the sphere"
