"""The compiled camera rays and film against the NumPy code they replaced, bit for bit.

Camera rays (``compiled.camera_rays``, and inside the first query ``tracing.camera_query``) and
the film's sums and mean (``compiled.film_sums``) must give exactly the bits the NumPy
expressions gave (``camera_reference``; ``np.bincount``; ``np.divide``), so that no image
changes; so must the shadow segments' facing test and unit directions toward a light
(``tracing.segments``, against NumPy in ``test_bvh_queries``). Why that holds on every x86-64
ISA (SSE2, AVX2, AVX-512), and is not luck on this machine: both sides use only IEEE 754
operations that are correctly rounded whatever the vector width (+, -, *, /, sqrt, conversions
between int64, float32 and float64), in the same order and precision; NumPy runs each ufunc as
its own pass, so it never fuses a multiply and an add; numba compiles without ``fastmath``, so
LLVM may neither contract a multiply and an add into an FMA nor reassociate a sum. The last two
tests check those premises of the compiled side on the code itself: no fastmath option, no FMA
instruction in the machine code.
"""

from __future__ import annotations

import re

import llvmlite.binding as llvm
import numba
import numpy as np
import pytest
import trimesh
from camera_reference import sample_rays as reference_rays
from camera_reference import tiled_samples as reference_order

from embree_rt import Camera, Scene, random_field, render
from embree_rt.camera import camera_frame, camera_rays, sample_rays, tiled_samples
from embree_rt.compiled import camera_rays as camera_module
from embree_rt.compiled import film_sums
from embree_rt.embree import BVH, kernels
from embree_rt.film import Film, FilmBlock
from embree_rt.geometry import SceneGeometry
from embree_rt.tracing import camera_query, segments


def random_frames(seed: int, count: int):
    """``count`` (frame, spp, render seed) of random cameras, sizes up to 2000 pixels wide
    (column numbers in the thousands, where float32 rounding of the jitter would show)."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        width, height = int(rng.integers(1, 2000)), int(rng.integers(1, 1200))
        camera = Camera(
            position=tuple(rng.normal(size=3) * 50.0),
            look_at=tuple(rng.normal(size=3)),
            fov=float(rng.uniform(1.0, 175.0)),
        )
        spp = int(rng.choice([1, 2, 3, 8, 9, 16]))
        yield camera_frame(camera, width, height), spp, int(rng.integers(0, 2**63))


def test_camera_rays_equal_the_numpy_rays_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    for frame, spp, seed in random_frames(1, 25):
        pixels = frame.width * frame.height
        first = int(rng.integers(0, pixels))
        stop = int(rng.integers(first + 1, min(pixels, first + 5000) + 1))
        index, pixel = tiled_samples(frame, spp, first * spp, (stop - first) * spp)
        assert np.array_equal(index, reference_order(frame, spp, first * spp, (stop - first) * spp))
        assert np.array_equal(pixel, index // spp)
        ours, theirs = sample_rays(frame, spp, seed, index), reference_rays(frame, spp, seed, index)
        for a, b in zip(ours, theirs, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("threads", [1, 2])
def test_camera_rays_made_inside_the_query_are_the_numpy_rays_and_hit_the_same(threads) -> None:
    scene = random_field(300, seed=4)
    frame = camera_frame(scene.camera, 173, 97)
    spp, seed = 3, 11
    index, _ = tiled_samples(frame, spp, 0, frame.width * frame.height * spp)
    origins, directions, _ = reference_rays(frame, spp, seed, index)
    with SceneGeometry(scene, threads=threads) as geometry:
        rows, surfaces, made = geometry.intersect_camera(camera_rays(frame, spp, seed), index)
        expected_rows, expected = geometry.intersect_compact(origins, directions, coherent=True)
    assert made.tobytes() == directions.tobytes()
    assert np.array_equal(rows, expected_rows) and 0 < len(rows) < len(index)
    for name in ("t", "position", "normal", "face_normal", "material", "scale", "incoming"):
        assert getattr(surfaces, name).tobytes() == getattr(expected, name).tobytes(), name
    assert surfaces.floor_count == expected.floor_count > 0


def test_records_without_ids_are_the_records_with_them_less_the_ids() -> None:
    """Shading asks for hit records without Embree's ids (the AOVs' object names): the same
    rows and fields, bit for bit, and no ids; a scene with meshes keeps them (its smooth
    normals and looks read them)."""
    scene = random_field(300, seed=6)
    frame = camera_frame(scene.camera, 97, 61)
    index, _ = tiled_samples(frame, 1, 0, frame.width * frame.height)
    camera = camera_rays(frame, 1, 3)
    origins, directions, _ = reference_rays(frame, 1, 3, index)
    with SceneGeometry(scene, threads=1) as geometry:
        assert not geometry.has_meshes
        for with_ids, without in (
            (
                geometry.intersect_camera(camera, index),
                geometry.intersect_camera(camera, index, ids=False),
            ),
            (
                geometry.intersect_compact(origins, directions),
                geometry.intersect_compact(origins, directions, ids=False),
            ),
        ):
            assert np.array_equal(with_ids[0], without[0]) and 0 < len(without[0]) < len(index)
            full, bare = with_ids[1], without[1]
            for name in ("t", "position", "normal", "face_normal", "material", "scale", "incoming"):
                assert getattr(full, name).tobytes() == getattr(bare, name).tobytes(), name
            assert full.prim_id is not None and (full.prim_id >= 0).any()
            assert bare.prim_id is None and bare.inst_id is None and bare.inst_prim_id is None
    meshes = Scene(camera=scene.camera)
    meshes.add_mesh(trimesh.creation.icosphere(), material="matte")
    with SceneGeometry(meshes, threads=1) as geometry:
        assert geometry.has_meshes
        _, surfaces = geometry.intersect_compact(origins, directions, ids=False)
        on_mesh = surfaces.inst_id[surfaces.floor_count :]
        assert len(on_mesh) and (on_mesh >= 0).all()


def test_film_block_sums_equal_one_bincount_per_channel_bit_for_bit() -> None:
    rng = np.random.default_rng(2)
    first, count = 40, 300
    block = FilmBlock(first, count)
    pixels, values = [], []
    for _ in range(5):  # as the wavefront adds them: a few runs of samples, weighted or not
        n = int(rng.integers(0, 4000))
        pixel = rng.integers(first, first + count, n)
        rgb = rng.lognormal(0.0, 3.0, (3, n)).astype(np.float32)
        if rng.random() < 0.5:
            block.add(pixel, rgb)
            pixels.append(pixel), values.append(rgb)
            continue
        weight = rng.random((3, n + 7), dtype=np.float32)
        columns = np.sort(rng.choice(n + 7, n, replace=False))
        wide = rng.integers(first, first + count, n + 7)
        block.add_weighted(wide, weight, rgb, columns)
        pixels.append(wide[columns]), values.append(weight[:, columns] * rgb)
    block.add_weighted(pixel, np.broadcast_to(np.float32(1.0), (3, len(pixel))), rgb)  # camera's
    pixels.append(pixel), values.append(rgb)
    local = np.concatenate(pixels) - first
    rgb = np.concatenate(values, axis=1)
    expected = np.stack([np.bincount(local, rgb[c], minlength=count) for c in range(3)])
    assert block.sums.tobytes() == expected.tobytes()


def test_film_block_refuses_a_pixel_outside_it_and_adds_nothing() -> None:
    block = FilmBlock(10, 5)
    with pytest.raises(ValueError, match=r"pixel 15 is outside the block's pixels 10\.\.14"):
        block.add(np.array([10, 15]), np.ones((3, 2), np.float32))
    with pytest.raises(ValueError, match="pixel 9 is outside"):
        block.add_weighted(
            np.array([9, 10]),
            np.ones((3, 2), np.float32),
            np.ones((3, 1), np.float32),
            np.array([0]),
        )
    assert not block.sums.any()


@pytest.mark.parametrize("spp", [1, 7, 8, 12, 64])
def test_film_image_is_the_float64_mean_rounded_once(spp) -> None:
    """Divided in float64 (multiplied by 1 / spp when spp is a power of two: the same real
    number, so the same rounding) and rounded once to float32, as NumPy's divide; sums that
    round to float32 subnormals, zero and infinity included."""
    film = Film(37, 23)
    block = FilmBlock(0, 37 * 23)
    rng = np.random.default_rng(3)
    block.add(rng.integers(0, 37 * 23, 9000), rng.lognormal(0.0, 4.0, (3, 9000)).astype(np.float32))
    # means that are float32 subnormals, beyond float32 (inf), a float64 subnormal sum
    block.sums[:, :4] = [1e-44 * spp, 3e-39 * spp, 2.4e40 * spp, 5e-324]
    film.add_block(block)
    expected = np.empty((37 * 23, 3), np.float32)
    with np.errstate(over="ignore"):
        np.divide(block.sums.T, spp, out=expected, casting="same_kind")
    image = film.image(spp)
    assert image.tobytes() == expected.reshape(23, 37, 3).tobytes()
    assert (image.reshape(-1, 3)[0] > 0).all() and np.isinf(image.reshape(-1, 3)[2]).all()


def test_images_are_the_same_on_one_and_two_threads() -> None:
    scene = random_field(200, seed=8)
    settings = dict(width=91, height=53, spp=2, max_depth=4, seed=5, batch_size=1500)
    one = render(scene, threads=1, **settings).image
    assert one.tobytes() == render(scene, threads=2, **settings).image.tobytes()


COMPILED = [
    camera_module.sample_rays,
    camera_module.write_directions,
    camera_query.intersect_camera_chunk,
    film_sums.add_weighted,
    film_sums.mean_image,
    film_sums.mean_into,
    segments.toward_light_chunk,
]


def test_compiled_camera_and_film_code_is_built_without_fastmath() -> None:
    for function in COMPILED:
        assert not function.targetoptions.get("fastmath", False), function


def test_compiled_camera_and_film_code_has_no_fused_multiply_add() -> None:
    # The kernels' code comes from numba's disk cache, which keeps no assembly: compile their
    # Python source again, with the same options, for the arguments a render gives them
    # (sample_direction is inlined into write_directions), and read the machine code.
    frame = camera_frame(Camera(), 64, 48)
    ortho_frame = camera_frame(Camera(projection="orthographic", view_height=3.0), 64, 48)
    bvh = BVH(threads=1)
    index, pixel = tiled_samples(frame, 4, 0, 64 * 48 * 4)
    rgb = np.ones((3, len(index)), np.float32)
    ones = np.broadcast_to(np.float32(1.0), rgb.shape)  # camera rays' weights
    calls = [
        (
            camera_module.write_directions,
            (
                camera_rays(frame, 4, 1),
                index,
                0,
                len(index),
                np.empty((3, len(index)), np.float32),
                None,
            ),
        ),
        (camera_module.sample_rays, (camera_rays(ortho_frame, 4, 1), index)),
        (film_sums.add_weighted, (np.zeros((3, 64 * 48)), 0, pixel, rgb, rgb, None)),
        (film_sums.add_weighted, (np.zeros((3, 64 * 48)), 0, pixel, ones, rgb, index)),
        (film_sums.mean_into, (np.empty((64 * 48, 3), np.float32), 0, np.zeros((3, 64 * 48)), 4)),
        (film_sums.mean_into, (np.empty((64 * 48, 3), np.float32), 0, np.zeros((3, 64 * 48)), 3)),
        (segments.toward_light_chunk, light_chunk_arguments(bvh)),
    ]
    fused = re.compile(r"\bv?f(n?)m(add|sub)\d", re.IGNORECASE)
    if "fma" in llvm.get_host_cpu_features().flatten():  # the pattern does see a contraction
        contracted = numba.njit(fastmath=True)(lambda a, b, c: a * b + c)
        contracted(np.float32(1.0), np.float32(2.0), np.float32(3.0))
        assert fused.search(next(iter(contracted.inspect_asm().values())))
    for function, arguments in calls:
        fresh = numba.njit(nogil=True)(function.py_func)
        fresh(*arguments)
        (code,) = fresh.inspect_asm().values()
        assert "ret" in code and not fused.search(code), function
    bvh.close()


def light_chunk_arguments(bvh: BVH) -> tuple:
    """Arguments of ``segments.toward_light_chunk`` (the shadow segments toward one light,
    with their facing test and unit directions) as a query on one thread passes them, on
    ``bvh``, a committed BVH of one sphere."""
    bvh.add_spheres(np.zeros((1, 3), np.float32), np.ones(1, np.float32))
    bvh.commit()
    points = np.ones((3, 16), np.float32) * 3
    light = segments.LightSegments(
        points, points / 3, np.zeros(0, bool), np.float32([9, 9, 9]), True, np.float32(0.0)
    )
    query = kernels.Query(bvh.committed_scene(), kernels.query_arguments(False), bvh.lanes)
    words = np.empty(kernels.SCRATCH_WORDS, np.uint32)
    return words, 0, 16, query, light, np.zeros(16, bool), np.zeros((3, 16), np.float32)
