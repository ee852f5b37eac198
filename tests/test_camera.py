"""The camera's contract: where rays point, how a pixel's samples are spread, what is refused.

Ray directions are checked against a pinhole model written out independently in this file.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from embree_rt.camera import camera_frame, primary_rays
from embree_rt.scene.model import Camera


def reference_basis(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, forward) unit vectors of a right-handed pinhole camera."""
    forward = np.subtract(camera.look_at, camera.position).astype(float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return right, up, forward


def image_position(
    camera: Camera, width: int, height: int, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (column, row) in pixels where each ray crosses the image (0, 0 = top left)."""
    right, up, forward = reference_basis(camera)
    d = directions.astype(float)
    depth = d @ forward
    tan_half = math.tan(math.radians(camera.fov) / 2)
    x = (d @ right) / depth / (tan_half * width / height)  # -1 at the left edge, +1 right
    y = (d @ up) / depth / tan_half  # +1 at the top edge
    return (x + 1) / 2 * width, (1 - y) / 2 * height


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


ODD_CAMERA = Camera(position=(3.0, 2.0, 7.0), look_at=(-1.0, 0.5, 0.0), up=(0, 1, 0), fov=50.0)


def test_rays_have_the_documented_shapes_dtypes_and_origin() -> None:
    frame = camera_frame(ODD_CAMERA, 6, 4)
    origins, directions, pixel = primary_rays(frame, 3, 0, 5, 40)
    assert origins.shape == directions.shape == (40, 3)
    assert origins.dtype == directions.dtype == np.float32
    assert pixel.shape == (40,) and pixel.dtype == np.int64
    np.testing.assert_array_equal(origins, np.tile(np.float32(ODD_CAMERA.position), (40, 1)))
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(pixel, np.arange(5, 45) // 3)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("width, height", [(9, 7), (1, 1), (21, 5)])
def test_the_centre_pixel_looks_at_look_at(seed: int, width: int, height: int) -> None:
    frame = camera_frame(ODD_CAMERA, width, height)
    centre = (height // 2) * width + width // 2
    _, directions, pixel = primary_rays(frame, 1, seed, centre, 1)
    assert pixel[0] == centre
    # The jitter stays inside the pixel: within half its diagonal of the view axis.
    pixel_angle = ODD_CAMERA.fov / height
    to_target = np.subtract(ODD_CAMERA.look_at, ODD_CAMERA.position)
    assert angle_between(directions[0], to_target) <= pixel_angle * math.hypot(0.5, 0.5) + 1e-4


def test_vertical_extent_is_the_fov_and_horizontal_follows_the_aspect() -> None:
    camera = Camera(position=(0, 0, 0), look_at=(0, 0, -1), fov=60.0)
    width, height = 151, 101
    frame = camera_frame(camera, width, height)
    _, directions, _ = primary_rays(frame, 1, 0, 0, width * height)
    rays = directions.reshape(height, width, 3)
    pixel_angle = camera.fov / height
    top, bottom = rays[0, width // 2], rays[-1, width // 2]
    assert angle_between(top, bottom) == pytest.approx(camera.fov, abs=2 * pixel_angle)
    horizontal = 2 * math.degrees(math.atan(math.tan(math.radians(30)) * width / height))
    left, right = rays[height // 2, 0], rays[height // 2, -1]
    assert angle_between(left, right) == pytest.approx(horizontal, abs=2 * pixel_angle)
    # No ray leaves the frustum.
    slope_y = np.abs(directions[:, 1] / directions[:, 2])
    slope_x = np.abs(directions[:, 0] / directions[:, 2])
    assert slope_y.max() <= math.tan(math.radians(30)) * (1 + 1e-6)
    assert slope_x.max() <= math.tan(math.radians(30)) * width / height * (1 + 1e-6)


def test_image_is_right_handed_row_zero_on_top_column_zero_left() -> None:
    camera = Camera(position=(0, 0, 5), look_at=(0, 0, 0), up=(0, 1, 0), fov=40.0)
    frame = camera_frame(camera, 4, 2)
    _, directions, _ = primary_rays(frame, 1, 0, 0, 8)
    top_left, bottom_right = directions[0], directions[7]
    assert top_left[0] < 0 and top_left[1] > 0  # world -x is image left, +y is up
    assert bottom_right[0] > 0 and bottom_right[1] < 0
    assert (directions[:, 2] < 0).all()  # looking down -z
    # Looking along +x with z up: right is -y (right-handed: right = forward × up).
    side = Camera(position=(0, 0, 0), look_at=(1, 0, 0), up=(0, 0, 1), fov=40.0)
    _, directions, _ = primary_rays(camera_frame(side, 4, 2), 1, 0, 0, 8)
    assert directions[3][1] < 0 and directions[3][2] > 0  # top right
    assert directions[4][1] > 0 and directions[4][2] < 0  # bottom left


@pytest.mark.parametrize("spp", [1, 2, 3, 4, 5, 7, 8, 9, 10, 16])
def test_samples_land_in_their_pixel_one_per_stratum(spp: int) -> None:
    width, height = 7, 5
    frame = camera_frame(ODD_CAMERA, width, height)
    _, directions, pixel = primary_rays(frame, spp, 12, 0, width * height * spp)
    column, row = image_position(ODD_CAMERA, width, height, directions)
    tolerance = 1e-4  # pixels: float32 directions
    within_x = (column >= pixel % width - tolerance) & (column <= pixel % width + 1 + tolerance)
    within_y = (row >= pixel // width - tolerance) & (row <= pixel // width + 1 + tolerance)
    assert within_x.all() and within_y.all()

    nx = math.ceil(math.sqrt(spp))
    ny = math.ceil(spp / nx)
    assert nx * ny >= spp
    cell_x = np.clip(np.floor((column - pixel % width) * nx), 0, nx - 1).astype(int)
    cell_y = np.clip(np.floor((row - pixel // width) * ny), 0, ny - 1).astype(int)
    cells = (cell_y * nx + cell_x).reshape(width * height, spp)
    for per_pixel in cells:
        assert len(set(per_pixel.tolist())) == spp
    # Same strata in every pixel (the pattern is per sample number, not per pixel).
    assert (np.sort(cells, axis=1) == np.sort(cells[0])).all()
    if (nx * ny) % 2 == 1 or spp % 2 == 0:
        # A centrally symmetric choice exists, and was made: the image is not shifted.
        used = set(cells[0].tolist())
        assert used == {nx * ny - 1 - c for c in used}


def test_jitter_spreads_over_the_whole_pixel() -> None:
    frame = camera_frame(ODD_CAMERA, 64, 48)
    _, directions, pixel = primary_rays(frame, 1, 5, 0, 64 * 48)
    column, row = image_position(ODD_CAMERA, 64, 48, directions)
    fx, fy = column - pixel % 64, row - pixel // 64
    for f in (fx, fy):
        assert f.mean() == pytest.approx(0.5, abs=0.03)
        assert f.min() < 0.01 and f.max() > 0.99
    assert abs(np.corrcoef(fx, fy)[0, 1]) < 0.06
    _, other, _ = primary_rays(frame, 1, 6, 0, 64 * 48)
    assert not np.array_equal(directions, other)  # the seed matters


@pytest.mark.parametrize("spp", [1, 3, 8])
def test_any_split_into_batches_gives_the_same_rays(spp: int) -> None:
    frame = camera_frame(ODD_CAMERA, 11, 6)
    total = 11 * 6 * spp
    whole = primary_rays(frame, spp, 9, 0, total)
    for cuts in ([1], [spp], [total // 2 + 1], [5, 6, 40, total - 1]):
        bounds = [0, *cuts, total]
        parts = [primary_rays(frame, spp, 9, a, b - a) for a, b in itertools.pairwise(bounds)]
        for k in range(3):
            np.testing.assert_array_equal(np.concatenate([p[k] for p in parts]), whole[k])


def test_sample_ranges_outside_the_image_are_refused() -> None:
    frame = camera_frame(ODD_CAMERA, 4, 3)
    assert len(primary_rays(frame, 2, 0, 24, 0)[2]) == 0
    with pytest.raises(ValueError, match="run past"):
        primary_rays(frame, 2, 0, 20, 5)
    with pytest.raises(ValueError, match="start"):
        primary_rays(frame, 2, 0, -1, 2)
    with pytest.raises(ValueError, match="spp"):
        primary_rays(frame, 0, 0, 0, 1)


NAN = float("nan")
INF = float("inf")


@pytest.mark.parametrize(
    "camera, width, height, field",
    [
        (Camera(), 0, 8, "width"),
        (Camera(), -3, 8, "width"),
        (Camera(), 8.0, 8, "width"),
        (Camera(), 8, 2.5, "height"),
        (Camera(), True, 8, "width"),
        (Camera(fov=0.0), 8, 8, "camera.fov"),
        (Camera(fov=180.0), 8, 8, "camera.fov"),
        (Camera(fov=-30.0), 8, 8, "camera.fov"),
        (Camera(fov=NAN), 8, 8, "camera.fov"),
        (Camera(fov=INF), 8, 8, "camera.fov"),
        (Camera(fov="wide"), 8, 8, "camera.fov"),
        (Camera(position=(1, 2, 3), look_at=(1, 2, 3)), 8, 8, "camera.look_at"),
        (Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=(0, 1, 0)), 8, 8, "camera.up"),
        (Camera(position=(0, 0, 0), look_at=(0, -2, 0), up=(0, 3, 0)), 8, 8, "camera.up"),
        (Camera(position=(0, 5, 0), look_at=(0, 0, 0), up=(1e-9, 1, 0)), 8, 8, "camera.up"),
        (Camera(up=(0, 0, 0)), 8, 8, "camera.up"),
        (Camera(position=(NAN, 0, 5)), 8, 8, "camera.position"),
        (Camera(look_at=(0, INF, 0)), 8, 8, "camera.look_at"),
        (Camera(up=(0, NAN, 0)), 8, 8, "camera.up"),
        (Camera(position=(0, 1)), 8, 8, "camera.position"),
    ],
)
def test_degenerate_cameras_raise_value_error_naming_the_field(
    camera: Camera, width, height, field: str
) -> None:
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        camera_frame(camera, width, height)


def test_an_almost_vertical_view_is_still_accepted() -> None:
    # 0.5 degrees off the up vector: a valid, if unusual, camera.
    tilt = math.tan(math.radians(0.5))
    camera = Camera(position=(0, 5, 0), look_at=(5 * tilt, 0, 0), up=(0, 1, 0))
    frame = camera_frame(camera, 3, 3)
    _, directions, _ = primary_rays(frame, 1, 0, 4, 1)
    assert angle_between(directions[0], np.subtract(camera.look_at, camera.position)) < 45 / 3
