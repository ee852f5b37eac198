"""The counter-based sampler (embree_rt/sampling.py) and the pinhole camera (embree_rt/camera.py).

Camera rays are checked by projecting their directions back onto the image plane with a basis
built here from the Camera's fields (vertical field of view, square pixels, row 0 at the top),
and by angles measured between rays, which need no basis at all.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from embree_rt import Camera
from embree_rt.camera import camera_frame, primary_rays
from embree_rt.sampling import uniform

# -- sampling -------------------------------------------------------------------------------------


def test_uniform_is_float32_in_the_unit_interval_with_the_right_moments() -> None:
    n = 1_000_000
    x = uniform(3, np.arange(n), 0)
    assert x.dtype == np.float32 and x.shape == (n,)
    assert x.min() >= 0.0 and x.max() < 1.0
    x64 = x.astype(np.float64)
    # Standard errors: mean sqrt(1/12/n) ≈ 2.9e-4, variance sqrt(1/180/n) ≈ 7.5e-5.
    assert abs(x64.mean() - 0.5) < 5 * math.sqrt(1 / 12 / n)
    assert abs(x64.var() - 1 / 12) < 5 * math.sqrt(1 / 180 / n)
    # 100 equal bins: chi-square with 99 degrees of freedom (mean 99, sd 14).
    counts = np.bincount((x64 * 100).astype(np.int64), minlength=100)
    chi2 = ((counts - n / 100) ** 2 / (n / 100)).sum()
    assert chi2 < 99 + 5 * 14
    # Not stuck on a coarse grid: nearly every sample is distinct at 24-bit resolution.
    assert len(np.unique(x)) > 0.97 * n


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.astype(np.float64), b.astype(np.float64))[0, 1])


def test_dimensions_seeds_and_neighbouring_indices_are_uncorrelated() -> None:
    n = 200_000
    index = np.arange(n)
    limit = 5 / math.sqrt(n)  # five standard errors of a correlation coefficient
    base = uniform(0, index, 0)
    assert abs(correlation(base, uniform(0, index, 1))) < limit
    assert abs(correlation(base, uniform(0, index, 2))) < limit
    assert abs(correlation(base, uniform(1, index, 0))) < limit
    assert abs(correlation(base, uniform(12345, index, 1))) < limit
    assert abs(correlation(base[:-1], base[1:])) < limit
    # Jointly uniform in 2D (the camera's jitter uses dimensions 0 and 1 together): 10x10 cells,
    # chi-square with 99 degrees of freedom.
    y = uniform(0, index, 1)
    cells = (base * 10).astype(np.int64) * 10 + (y * 10).astype(np.int64)
    counts = np.bincount(cells, minlength=100)
    chi2 = ((counts - n / 100) ** 2 / (n / 100)).sum()
    assert chi2 < 99 + 5 * 14
    # Different streams are different numbers, not shifted copies at the same index.
    assert np.mean(base == uniform(1, index, 0)) < 1e-3
    assert np.mean(base == uniform(0, index, 1)) < 1e-3


def test_uniform_does_not_depend_on_how_indices_are_batched() -> None:
    whole = uniform(7, np.arange(10_000), 1)
    for k in (1, 37, 4096, 9999):
        parts = np.concatenate([uniform(7, np.arange(k), 1), uniform(7, np.arange(k, 10_000), 1)])
        np.testing.assert_array_equal(parts, whole)
    shuffled = np.random.default_rng(0).permutation(10_000)
    np.testing.assert_array_equal(uniform(7, shuffled, 1), whole[shuffled])
    np.testing.assert_array_equal(uniform(7, np.arange(10_000, dtype=np.int32), 1), whole)
    np.testing.assert_array_equal(uniform(7, np.arange(10_000), 1), whole)  # deterministic
    # Far indices (a 1e6-sphere 4K render at many spp) still give distinct uniform values.
    far = uniform(7, np.arange(2**40, 2**40 + 100_000), 1)
    assert far.min() >= 0.0 and far.max() < 1.0
    assert abs(far.astype(np.float64).mean() - 0.5) < 5 * math.sqrt(1 / 12 / 100_000)


# -- camera ---------------------------------------------------------------------------------------


def image_plane(camera: Camera, width: int, height: int, directions: np.ndarray) -> np.ndarray:
    """(n, 2) float64 continuous pixel coordinates (column, row; row 0 at the top, pixel (c, r)
    spans [c, c+1) x [r, r+1)) where the rays through the camera position cross the image plane.
    Built from the Camera fields here: vertical field of view, square pixels."""
    position = np.asarray(camera.position, np.float64)
    forward = np.asarray(camera.look_at, np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(camera.up, np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = directions.astype(np.float64)
    depth = d @ forward
    assert np.all(depth > 0), "every ray must point into the scene"
    tan_half = math.tan(math.radians(camera.fov) / 2)
    x = (d @ right) / depth / (tan_half * width / height)  # -1 .. 1 across the image
    y = (d @ up) / depth / tan_half  # -1 at the bottom .. 1 at the top
    return np.stack([(x + 1) / 2 * width, (1 - y) / 2 * height], axis=1)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    a = a.astype(np.float64) / np.linalg.norm(a)
    b = b.astype(np.float64) / np.linalg.norm(b)
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))


def all_rays(camera: Camera, width: int, height: int, spp: int, seed: int = 0):
    frame = camera_frame(camera, width, height)
    return primary_rays(frame, spp, seed, 0, width * height * spp)


TILTED = Camera(position=(3.0, 2.0, 7.0), look_at=(-1.0, 0.5, 1.0), up=(0.0, 1.0, 0.0), fov=40.0)


def test_the_centre_ray_of_an_odd_image_points_at_look_at() -> None:
    width, height = 41, 31
    origins, directions, pixel = all_rays(TILTED, width, height, spp=1)
    centre = (height // 2) * width + width // 2
    assert pixel[centre] == centre
    toward = np.subtract(TILTED.look_at, TILTED.position)
    pixel_size = 2 * math.tan(math.radians(TILTED.fov) / 2) / height  # at unit distance
    half_diagonal = math.degrees(math.atan(pixel_size * math.sqrt(2) / 2))
    assert angle(directions[centre], toward) <= half_diagonal
    np.testing.assert_array_equal(origins, np.tile(np.float32(TILTED.position), (len(pixel), 1)))
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-6)
    # Row 0 is the top of the image and column 0 its left side.
    top, bottom = directions[width // 2], directions[(height - 1) * width + width // 2]
    assert top[1] > bottom[1]
    left, right = directions[centre - width // 2], directions[centre + width // 2]
    right_of_view = np.cross(toward, TILTED.up)
    assert float(left @ right_of_view) < 0 < float(right @ right_of_view)


@pytest.mark.parametrize("fov", [10.0, 45.0, 90.0, 150.0])
def test_top_to_bottom_row_spans_the_vertical_field_of_view(fov: float) -> None:
    width, height = 3, 401
    camera = Camera(position=(0.5, -2.0, 1.0), look_at=(4.0, 1.0, -3.0), up=(0, 0, 1), fov=fov)
    _, directions, _ = all_rays(camera, width, height, spp=1)
    top, bottom = directions[1], directions[(height - 1) * width + 1]
    # Centres of the outer rows sit half a pixel inside the frame edges; jitter adds up to half
    # a pixel each way: allow two pixels' worth of angle.
    pixel_angle = fov / height * 2
    assert angle(top, bottom) == pytest.approx(fov, abs=pixel_angle)


@pytest.mark.parametrize("width, height", [(301, 101), (101, 301), (200, 200)])
def test_horizontal_extent_follows_the_aspect_ratio(width: int, height: int) -> None:
    fov = 30.0
    camera = Camera(position=(0, 1, 5), look_at=(0, 1, 0), up=(0, 1, 0), fov=fov)
    _, directions, _ = all_rays(camera, width, height, spp=1)
    row = height // 2
    left, right = directions[row * width], directions[row * width + width - 1]
    expected = 2 * math.degrees(math.atan(math.tan(math.radians(fov / 2)) * width / height))
    pixel_angle = expected / width * 2
    assert angle(left, right) == pytest.approx(expected, abs=pixel_angle)
    top, bottom = directions[width // 2], directions[(height - 1) * width + width // 2]
    assert angle(top, bottom) == pytest.approx(fov, abs=fov / height * 2)


@pytest.mark.parametrize("spp", [1, 3, 4])
def test_primary_rays_do_not_depend_on_batch_boundaries(spp: int) -> None:
    width, height = 7, 5
    frame = camera_frame(TILTED, width, height)
    total = width * height * spp
    whole = primary_rays(frame, spp, 9, 0, total)
    for k in (1, 2, spp, total // 2, total - 1):
        first = primary_rays(frame, spp, 9, 0, k)
        rest = primary_rays(frame, spp, 9, k, total - k)
        assert all(len(part) == k for part in first)
        for a, b, expected in zip(first, rest, whole, strict=True):
            np.testing.assert_array_equal(np.concatenate([a, b]), expected)
    # Three uneven pieces too.
    cuts = [0, 13, 14, total]
    pieces = [primary_rays(frame, spp, 9, a, b - a) for a, b in itertools.pairwise(cuts)]
    for part, expected in enumerate(whole):
        np.testing.assert_array_equal(np.concatenate([p[part] for p in pieces]), expected)
    # The seed changes the jitter, not the pixels.
    other = primary_rays(frame, spp, 10, 0, total)
    np.testing.assert_array_equal(other[2], whole[2])
    assert not np.array_equal(other[1], whole[1])


@pytest.mark.parametrize("spp", [1, 2, 4, 5, 9, 16])
def test_each_pixels_samples_lie_in_its_footprint_in_distinct_strata(spp: int) -> None:
    width, height = 12, 9
    _, directions, pixel = all_rays(TILTED, width, height, spp, seed=4)
    index = np.arange(len(pixel))
    np.testing.assert_array_equal(pixel, index // spp)
    xy = image_plane(TILTED, width, height, directions)
    column, row = pixel % width, pixel // width
    fx, fy = xy[:, 0] - column, xy[:, 1] - row  # position inside the own pixel
    eps = 1e-4
    assert np.all((fx > -eps) & (fx < 1 + eps)), "sample outside its pixel horizontally"
    assert np.all((fy > -eps) & (fy < 1 + eps)), "sample outside its pixel vertically"
    # Stratified on an nx x ny grid over the pixel (nx = ceil(sqrt(spp))): no two samples of one
    # pixel share a cell.
    nx = math.ceil(math.sqrt(spp))
    ny = math.ceil(spp / nx)
    cx = np.clip(np.floor(fx * nx), 0, nx - 1).astype(np.int64)
    cy = np.clip(np.floor(fy * ny), 0, ny - 1).astype(np.int64)
    cell = pixel * (nx * ny) + cy * nx + cx
    assert len(np.unique(cell)) == len(cell)
    # Jittered inside the cells, not placed at their centres: the offsets fill the cell.
    ox, oy = fx * nx - cx, fy * ny - cy
    for offsets in (ox, oy):
        assert offsets.min() < 0.1 and offsets.max() > 0.9
        assert abs(offsets.mean() - 0.5) < 0.1


def test_samples_cover_the_image_evenly() -> None:
    width, height, spp = 8, 6, 64
    _, directions, _ = all_rays(TILTED, width, height, spp, seed=1)
    xy = image_plane(TILTED, width, height, directions)
    assert xy[:, 0].min() >= -1e-4 and xy[:, 0].max() <= width + 1e-4
    assert xy[:, 1].min() >= -1e-4 and xy[:, 1].max() <= height + 1e-4
    # 64 spp stratify each pixel 8 x 8, so every quarter-pixel square holds 4 samples.
    bins = np.floor(xy * 4).astype(np.int64)
    counts = np.bincount(bins[:, 1] * (4 * width) + bins[:, 0], minlength=16 * width * height)
    np.testing.assert_array_equal(counts, 4)
    # Inside its 1/8-pixel cell, each sample's jitter is uniform in 2D: x and y independent.
    jitter = xy * 8 - np.floor(xy * 8)
    n = len(jitter)
    assert abs(np.corrcoef(jitter[:, 0], jitter[:, 1])[0, 1]) < 5 / math.sqrt(n)
    quadrant = (jitter[:, 0] >= 0.5).astype(np.int64) * 2 + (jitter[:, 1] >= 0.5)
    quarter = np.bincount(quadrant, minlength=4) / n
    np.testing.assert_allclose(quarter, 0.25, atol=5 * math.sqrt(0.25 * 0.75 / n))


@pytest.mark.parametrize(
    "camera, width, height",
    [
        (Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 8, 8),
        (Camera(position=(0, -5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 8, 8),
        (Camera(position=(1, 2, 3), look_at=(2, 4, 6), up=(-2, -4, -6)), 8, 8),
        (Camera(up=(0, 0, 0)), 8, 8),
        (Camera(fov=0.0), 8, 8),
        (Camera(fov=180.0), 8, 8),
        (Camera(fov=float("nan")), 8, 8),
        (Camera(fov=float("inf")), 8, 8),
        (Camera(fov=-30.0), 8, 8),
        (Camera(position=(1, 1, 1), look_at=(1, 1, 1)), 8, 8),
        (Camera(position=(float("nan"), 0, 5)), 8, 8),
        (Camera(look_at=(0, float("inf"), 0)), 8, 8),
        (Camera(up=(0, 1)), 8, 8),
        (Camera(), 0, 8),
        (Camera(), 8, -1),
        (Camera(), 2.5, 8),
        (Camera(), 8, True),
    ],
    ids=[
        "up-parallel",
        "up-antiparallel",
        "up-along-view",
        "up-zero",
        "fov-0",
        "fov-180",
        "fov-nan",
        "fov-inf",
        "fov-negative",
        "position-is-look_at",
        "position-nan",
        "look_at-inf",
        "up-two-numbers",
        "width-0",
        "height-minus-1",
        "width-fraction",
        "height-bool",
    ],
)
def test_degenerate_cameras_are_value_errors(camera: Camera, width, height) -> None:
    with pytest.raises(ValueError):
        camera_frame(camera, width, height)


def test_nearly_degenerate_but_valid_cameras_still_work() -> None:
    # Slightly off vertical, a tiny and a wide field of view, a 1x1 image: all well defined.
    for camera, width, height in [
        (Camera(position=(0.01, 5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 4, 4),
        (Camera(fov=0.5), 5, 3),
        (Camera(fov=179.0), 5, 3),
        (Camera(), 1, 1),
    ]:
        frame = camera_frame(camera, width, height)
        _, directions, _ = primary_rays(frame, 2, 0, 0, width * height * 2)
        assert np.isfinite(directions).all()
        xy = image_plane(camera, width, height, directions)
        assert np.all((xy > -1e-3) & (xy < np.array([width, height]) + 1e-3))
