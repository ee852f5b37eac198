"""The pinhole camera (embree_rt/camera.py): frame, jittered stratified primary rays.

``sample_rays`` (here through ``camera_samples.primary_rays``) returns one ray per column:
origins and directions (3, count) float32, pixel (count,) int64. Ray directions are checked by
projecting them back onto the image plane with a basis built here from the Camera's fields
(vertical field of view, square pixels, row 0 at the top), and by angles measured between rays,
which need no basis at all.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from camera_samples import primary_rays

from embree_rt.camera import Camera, camera_frame, pixel_center_rays, sample_rays

# -- camera: an independent pinhole model ---------------------------------------------------------


def reference_basis(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, forward) unit vectors of a right-handed pinhole camera."""
    forward = np.subtract(camera.look_at, camera.position).astype(np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(camera.up, np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return right, up, forward


def image_position(
    camera: Camera, width: int, height: int, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (column, row) in pixels where each ray (a column of the (3, n) ``directions``)
    crosses the image plane; pixel (c, r) spans [c, c+1) x [r, r+1), row 0 at the top."""
    right, up, forward = reference_basis(camera)
    d = directions.astype(np.float64)
    depth = forward @ d
    assert np.all(depth > 0), "every ray must point into the scene"
    tan_half = math.tan(math.radians(camera.fov) / 2)
    x = (right @ d) / depth / (tan_half * width / height)  # -1 at the left edge, +1 right
    y = (up @ d) / depth / tan_half  # +1 at the top edge, -1 at the bottom
    return (x + 1) / 2 * width, (1 - y) / 2 * height


def angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle in degrees between two (3,) vectors."""
    a = np.asarray(a, np.float64) / np.linalg.norm(a)
    b = np.asarray(b, np.float64) / np.linalg.norm(b)
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))


def all_rays(camera: Camera, width: int, height: int, spp: int, seed: int = 0):
    frame = camera_frame(camera, width, height)
    return primary_rays(frame, spp, seed, 0, width * height * spp)


ODD_CAMERA = Camera(position=(3.0, 2.0, 7.0), look_at=(-1.0, 0.5, 0.0), up=(0, 1, 0), fov=50.0)


# -- camera: layout, orientation, extent ----------------------------------------------------------


def test_rays_have_the_documented_shapes_dtypes_and_origin() -> None:
    frame = camera_frame(ODD_CAMERA, 6, 4)
    origins, directions, pixel = primary_rays(frame, 3, 0, 5, 40)
    # One ray per column: (3, count) float32 vectors, (count,) int64 pixel indices.
    assert origins.shape == directions.shape == (3, 40)
    assert origins.dtype == directions.dtype == np.float32
    assert pixel.shape == (40,) and pixel.dtype == np.int64
    expected_origins = np.tile(np.float32(ODD_CAMERA.position)[:, None], (1, 40))
    np.testing.assert_array_equal(origins, expected_origins)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=0), 1.0, atol=1e-6)
    np.testing.assert_array_equal(pixel, np.arange(5, 45) // 3)
    # An empty batch keeps the layout.
    origins, directions, pixel = primary_rays(frame, 3, 0, 72, 0)
    assert origins.shape == directions.shape == (3, 0)
    assert origins.dtype == directions.dtype == np.float32
    assert pixel.shape == (0,) and pixel.dtype == np.int64


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("width, height", [(9, 7), (1, 1), (21, 5), (41, 31)])
def test_the_centre_pixel_looks_at_look_at(seed: int, width: int, height: int) -> None:
    frame = camera_frame(ODD_CAMERA, width, height)
    centre = (height // 2) * width + width // 2
    _, directions, pixel = primary_rays(frame, 1, seed, centre, 1)
    assert pixel[0] == centre
    # The jitter stays inside the pixel: within half its diagonal of the view axis.
    pixel_size = 2 * math.tan(math.radians(ODD_CAMERA.fov) / 2) / height  # at unit distance
    half_diagonal = math.degrees(math.atan(pixel_size * math.sqrt(2) / 2))
    to_target = np.subtract(ODD_CAMERA.look_at, ODD_CAMERA.position)
    assert angle(directions[:, 0], to_target) <= half_diagonal


def test_image_is_right_handed_row_zero_on_top_column_zero_left() -> None:
    camera = Camera(position=(0, 0, 5), look_at=(0, 0, 0), up=(0, 1, 0), fov=40.0)
    _, directions, _ = all_rays(camera, 4, 2, spp=1)
    top_left, bottom_right = directions[:, 0], directions[:, 7]
    assert top_left[0] < 0 and top_left[1] > 0  # world -x is image left, +y is up
    assert bottom_right[0] > 0 and bottom_right[1] < 0
    assert (directions[2] < 0).all()  # looking down -z
    # Looking along +x with z up: right is -y (right-handed: right = forward × up).
    side = Camera(position=(0, 0, 0), look_at=(1, 0, 0), up=(0, 0, 1), fov=40.0)
    _, directions, _ = all_rays(side, 4, 2, spp=1)
    assert directions[1, 3] < 0 and directions[2, 3] > 0  # top right
    assert directions[1, 4] > 0 and directions[2, 4] < 0  # bottom left
    # An oblique view: row 0 is the top of the image and column 0 its left side.
    width, height = 41, 31
    _, directions, _ = all_rays(ODD_CAMERA, width, height, spp=1)
    centre = (height // 2) * width + width // 2
    top, bottom = directions[:, width // 2], directions[:, (height - 1) * width + width // 2]
    assert top[1] > bottom[1]
    left, right = directions[:, centre - width // 2], directions[:, centre + width // 2]
    toward = np.subtract(ODD_CAMERA.look_at, ODD_CAMERA.position)
    right_of_view = np.cross(toward, ODD_CAMERA.up)
    assert float(left @ right_of_view) < 0 < float(right @ right_of_view)


@pytest.mark.parametrize("fov", [10.0, 45.0, 90.0, 150.0])
def test_top_to_bottom_row_spans_the_vertical_field_of_view(fov: float) -> None:
    width, height = 3, 401
    camera = Camera(position=(0.5, -2.0, 1.0), look_at=(4.0, 1.0, -3.0), up=(0, 0, 1), fov=fov)
    _, directions, _ = all_rays(camera, width, height, spp=1)
    top, bottom = directions[:, 1], directions[:, (height - 1) * width + 1]
    # Centres of the outer rows sit half a pixel inside the frame edges; jitter adds up to half
    # a pixel each way: allow two pixels' worth of angle.
    pixel_angle = fov / height * 2
    assert angle(top, bottom) == pytest.approx(fov, abs=pixel_angle)


@pytest.mark.parametrize(
    "fov, width, height", [(30.0, 301, 101), (30.0, 101, 301), (30.0, 200, 200), (60.0, 151, 101)]
)
def test_horizontal_extent_follows_the_aspect_ratio_and_no_ray_leaves_the_frustum(
    fov: float, width: int, height: int
) -> None:
    camera = Camera(position=(0, 1, 5), look_at=(0, 1, 0), up=(0, 1, 0), fov=fov)
    _, directions, _ = all_rays(camera, width, height, spp=1)
    row = height // 2
    left, right = directions[:, row * width], directions[:, row * width + width - 1]
    expected = 2 * math.degrees(math.atan(math.tan(math.radians(fov / 2)) * width / height))
    pixel_angle = expected / width * 2
    assert angle(left, right) == pytest.approx(expected, abs=pixel_angle)
    top, bottom = directions[:, width // 2], directions[:, (height - 1) * width + width // 2]
    assert angle(top, bottom) == pytest.approx(fov, abs=fov / height * 2)
    # No ray leaves the frustum (the camera looks down -z with +y up).
    tan_half = math.tan(math.radians(fov / 2))
    slope_y = np.abs(directions[1] / directions[2])
    slope_x = np.abs(directions[0] / directions[2])
    assert slope_y.max() <= tan_half * (1 + 1e-6)
    assert slope_x.max() <= tan_half * width / height * (1 + 1e-6)


# -- camera: where a pixel's samples go -----------------------------------------------------------


@pytest.mark.parametrize("spp", [1, 2, 3, 4, 5, 7, 8, 9, 10, 16])
def test_each_pixels_samples_lie_in_its_footprint_in_distinct_strata(spp: int) -> None:
    width, height = 12, 9
    _, directions, pixel = all_rays(ODD_CAMERA, width, height, spp, seed=4)
    np.testing.assert_array_equal(pixel, np.arange(width * height * spp) // spp)
    x, y = image_position(ODD_CAMERA, width, height, directions)
    fx, fy = x - pixel % width, y - pixel // width  # position inside the own pixel
    eps = 1e-4  # pixels: float32 directions
    assert np.all((fx >= -eps) & (fx <= 1 + eps)), "sample outside its pixel horizontally"
    assert np.all((fy >= -eps) & (fy <= 1 + eps)), "sample outside its pixel vertically"
    # Stratified on an nx x ny grid over the pixel (nx = ceil(sqrt(spp))): no two samples of one
    # pixel share a cell.
    nx = math.ceil(math.sqrt(spp))
    ny = math.ceil(spp / nx)
    assert nx * ny >= spp
    cx = np.clip(np.floor(fx * nx), 0, nx - 1).astype(np.int64)
    cy = np.clip(np.floor(fy * ny), 0, ny - 1).astype(np.int64)
    cells = (cy * nx + cx).reshape(width * height, spp)
    for per_pixel in cells:
        assert len(set(per_pixel.tolist())) == spp
    # Same strata in every pixel (the pattern is per sample number, not per pixel).
    assert (np.sort(cells, axis=1) == np.sort(cells[0])).all()
    if (nx * ny) % 2 == 1 or spp % 2 == 0:
        # A centrally symmetric choice exists, and was made: the image is not shifted.
        used = set(cells[0].tolist())
        assert used == {nx * ny - 1 - c for c in used}
    # Jittered inside the cells, not placed at their centres: the offsets fill the cell.
    ox, oy = fx * nx - cx, fy * ny - cy
    for offsets in (ox, oy):
        assert offsets.min() < 0.1 and offsets.max() > 0.9
        assert abs(offsets.mean() - 0.5) < 0.1


def test_jitter_spreads_over_the_whole_pixel() -> None:
    width, height = 64, 48
    _, directions, pixel = all_rays(ODD_CAMERA, width, height, spp=1, seed=5)
    column, row = image_position(ODD_CAMERA, width, height, directions)
    fx, fy = column - pixel % width, row - pixel // width
    for f in (fx, fy):
        assert f.mean() == pytest.approx(0.5, abs=0.03)
        assert f.min() < 0.01 and f.max() > 0.99
    assert abs(np.corrcoef(fx, fy)[0, 1]) < 0.06


def test_samples_cover_the_image_evenly() -> None:
    width, height, spp = 8, 6, 64
    _, directions, _ = all_rays(ODD_CAMERA, width, height, spp, seed=1)
    column, row = image_position(ODD_CAMERA, width, height, directions)
    assert column.min() >= -1e-4 and column.max() <= width + 1e-4
    assert row.min() >= -1e-4 and row.max() <= height + 1e-4
    # 64 spp stratify each pixel 8 x 8, so every quarter-pixel square holds 4 samples.
    bin_x = np.floor(column * 4).astype(np.int64)
    bin_y = np.floor(row * 4).astype(np.int64)
    counts = np.bincount(bin_y * (4 * width) + bin_x, minlength=16 * width * height)
    np.testing.assert_array_equal(counts, 4)
    # Inside its 1/8-pixel cell, each sample's jitter is uniform in 2D: x and y independent.
    jitter_x = column * 8 - np.floor(column * 8)
    jitter_y = row * 8 - np.floor(row * 8)
    n = len(jitter_x)
    assert abs(np.corrcoef(jitter_x, jitter_y)[0, 1]) < 5 / math.sqrt(n)
    quadrant = (jitter_x >= 0.5).astype(np.int64) * 2 + (jitter_y >= 0.5)
    quarter = np.bincount(quadrant, minlength=4) / n
    np.testing.assert_allclose(quarter, 0.25, atol=5 * math.sqrt(0.25 * 0.75 / n))


# -- camera: batches and ranges -------------------------------------------------------------------


@pytest.mark.parametrize("spp", [1, 3, 4, 8])
def test_any_split_into_batches_gives_the_same_rays(spp: int) -> None:
    width, height = 11, 6
    frame = camera_frame(ODD_CAMERA, width, height)
    total = width * height * spp
    whole = primary_rays(frame, spp, 9, 0, total)
    half = total // 2
    for cuts in ([1], [2], [spp], [half], [half + 1], [total - 1], [13, 14], [5, 6, 40, total - 1]):
        bounds = [0, *cuts, total]
        parts = [primary_rays(frame, spp, 9, a, b - a) for a, b in itertools.pairwise(bounds)]
        for part, (a, b) in zip(parts, itertools.pairwise(bounds), strict=True):
            assert part[0].shape == part[1].shape == (3, b - a)
            assert part[2].shape == (b - a,)
        for k in range(3):
            np.testing.assert_array_equal(np.concatenate([p[k] for p in parts], axis=-1), whole[k])
    # The seed changes the jitter, not the pixels.
    other = primary_rays(frame, spp, 10, 0, total)
    np.testing.assert_array_equal(other[2], whole[2])
    assert not np.array_equal(other[1], whole[1])


def test_pixel_ranges_outside_the_image_are_refused() -> None:
    frame = camera_frame(ODD_CAMERA, 4, 3)
    assert len(pixel_center_rays(frame, 12, 0)[2]) == 0
    with pytest.raises(ValueError, match="run past"):
        pixel_center_rays(frame, 10, 5)
    with pytest.raises(ValueError, match="start"):
        pixel_center_rays(frame, -1, 2)
    with pytest.raises(ValueError, match="spp"):
        sample_rays(frame, 0, 0, np.arange(1))


# -- camera: degenerate and nearly degenerate cameras ---------------------------------------------

NAN = float("nan")
INF = float("inf")


@pytest.mark.parametrize(
    "camera, width, height, field",
    [
        (Camera(), 0, 8, "width"),
        (Camera(), -3, 8, "width"),
        (Camera(), 8.0, 8, "width"),
        (Camera(), 2.5, 8, "width"),
        (Camera(), True, 8, "width"),
        (Camera(), 8, -1, "height"),
        (Camera(), 8, 2.5, "height"),
        (Camera(), 8, True, "height"),
        (Camera(fov=0.0), 8, 8, "camera.fov"),
        (Camera(fov=180.0), 8, 8, "camera.fov"),
        (Camera(fov=-30.0), 8, 8, "camera.fov"),
        (Camera(fov=NAN), 8, 8, "camera.fov"),
        (Camera(fov=INF), 8, 8, "camera.fov"),
        (Camera(fov="wide"), 8, 8, "camera.fov"),
        (Camera(position=(1, 2, 3), look_at=(1, 2, 3)), 8, 8, "camera.look_at"),
        # up antiparallel, parallel, and antiparallel off the axes to the viewing direction
        (Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 8, 8, "camera.up"),
        (Camera(position=(0, -5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 8, 8, "camera.up"),
        (Camera(position=(1, 2, 3), look_at=(2, 4, 6), up=(-2, -4, -6)), 8, 8, "camera.up"),
        (Camera(position=(0, 0, 0), look_at=(0, -2, 0), up=(0, 3, 0)), 8, 8, "camera.up"),
        (Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=(1e-9, 1, 0)), 8, 8, "camera.up"),
        (Camera(up=(0, 0, 0)), 8, 8, "camera.up"),
        (Camera(position=(NAN, 0, 5)), 8, 8, "camera.position"),
        (Camera(look_at=(0, INF, 0)), 8, 8, "camera.look_at"),
        (Camera(up=(0, NAN, 0)), 8, 8, "camera.up"),
        (Camera(position=(0, 1)), 8, 8, "camera.position"),
        (Camera(up=(0, 1)), 8, 8, "camera.up"),
    ],
)
def test_degenerate_cameras_raise_value_error_naming_the_field(
    camera: Camera, width, height, field: str
) -> None:
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        camera_frame(camera, width, height)


def test_nearly_degenerate_but_valid_cameras_still_work() -> None:
    # Slightly off vertical (0.11 and 0.5 degrees), a tiny and a wide field of view, a 1x1
    # image: all well defined, and every sample lands in its own pixel.
    tilt = math.tan(math.radians(0.5))
    for camera, width, height in [
        (Camera(position=(0.01, 5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 4, 4),
        (Camera(position=(0, 5, 0), look_at=(5 * tilt, 0, 0), up=(0, 1, 0)), 3, 3),
        (Camera(fov=0.5), 5, 3),
        (Camera(fov=179.0), 5, 3),
        (Camera(), 1, 1),
    ]:
        _, directions, pixel = all_rays(camera, width, height, spp=2)
        assert np.isfinite(directions).all()
        column, row = image_position(camera, width, height, directions)
        fx, fy = column - pixel % width, row - pixel // width
        assert np.all((fx > -1e-3) & (fx < 1 + 1e-3)), camera
        assert np.all((fy > -1e-3) & (fy < 1 + 1e-3)), camera


def test_batches_trace_their_samples_in_tiles_of_four_by_two_pixels() -> None:
    from embree_rt.camera import TILE_HEIGHT, TILE_WIDTH, tiled_samples

    width, height, spp = 10, 7, 3  # a width the tiles do not divide, an odd height
    frame = camera_frame(Camera(position=(0, 0, 0), look_at=(0, 0, -1)), width, height)
    total = width * height * spp
    whole, whole_pixel = tiled_samples(frame, spp, 0, total)
    assert np.array_equal(np.sort(whole), np.arange(total))
    assert np.array_equal(whole_pixel, whole // spp)
    pixel = whole[::spp] // spp
    # each pixel's samples together, in sample order
    assert np.array_equal(whole.reshape(-1, spp), pixel[:, None] * spp + np.arange(spp))
    # the first tile: columns 0-3 of rows 0 and 1, row by row
    first = [0, 1, 2, 3, width, width + 1, width + 2, width + 3]
    assert pixel[: TILE_WIDTH * TILE_HEIGHT].tolist() == first
    # pixels of one tile are consecutive: tile numbers never decrease along the order
    row, column = pixel // width, pixel % width
    tile = (row // TILE_HEIGHT) * width + column // TILE_WIDTH
    assert np.all(np.diff(tile) >= 0)
    # any cut into batches of whole pixels keeps the same relative order
    rank = np.empty(total, np.int64)
    rank[whole] = np.arange(total)
    for bounds in ([0, 9, 31, 70], [0, 1, 2, 69, 70], [0, 35, 70]):
        for a, b in itertools.pairwise(bounds):
            part, part_pixel = tiled_samples(frame, spp, a * spp, (b - a) * spp)
            assert np.array_equal(part_pixel, part // spp)
            assert np.array_equal(np.sort(part), np.arange(a * spp, b * spp))
            assert np.all(np.diff(rank[part]) > 0)
    with pytest.raises(ValueError, match="whole pixels"):
        tiled_samples(frame, spp, 1, spp)
