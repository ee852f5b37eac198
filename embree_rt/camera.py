"""The camera, pinhole or orthographic: what a scene says of it (``Camera``) and the one rule
it must follow (``camera_problem``), its frame, and jittered, stratified primary rays."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from embree_rt.compiled import camera_rays as compiled_rays
from embree_rt.compiled.camera_rays import CameraRays, tile_order
from embree_rt.sampling import hash_key

Vec3 = tuple[float, float, float]


PROJECTIONS = ("perspective", "orthographic")


@dataclass
class Camera:
    """A camera at ``position`` looking at ``look_at``.

    ``projection`` "perspective" (a pinhole; ``fov`` is vertical, in degrees) or
    "orthographic": parallel rays along the view, from the plane through ``position`` facing
    ``look_at``, the image ``view_height`` world units tall. An orthographic camera without a
    ``view_height`` shows what its ``fov`` shows at ``look_at``'s distance:
    ``2 distance tan(fov / 2)`` (``view_height_of``), so switching a framed camera to
    orthographic keeps the object it looks at the same size."""

    position: Vec3 = (0.0, 1.0, 5.0)
    look_at: Vec3 = (0.0, 0.0, 0.0)
    up: Vec3 = (0.0, 1.0, 0.0)
    fov: float = 45.0
    projection: str = "perspective"
    view_height: float | None = None


# sin of the smallest angle allowed between a camera's ``up`` and its viewing direction: below
# it the camera's roll is decided by rounding error.
MIN_UP_SINE = 1e-6


def camera_problem(camera: Camera) -> tuple[str, str] | None:
    """What keeps ``camera`` from defining an image, as (field, problem), or None if nothing.

    The one rule for a camera, followed by scene files and by ``camera.camera_frame``: ``fov``
    a number of degrees strictly between 0 and 180; ``position``, ``look_at`` and ``up`` three
    finite numbers each; ``look_at`` apart from ``position``; ``up`` not zero and at least
    ``MIN_UP_SINE`` (sine of the angle) away from the viewing direction; ``projection`` one of
    ``PROJECTIONS``; ``view_height`` None or, on an orthographic camera only, a finite number
    of world units above 0.
    """
    if camera.projection not in PROJECTIONS:
        return "projection", f"expected one of {', '.join(PROJECTIONS)}, got {camera.projection!r}"
    if camera.view_height is not None:
        if camera.projection != "orthographic":
            return (
                "view_height",
                'only an orthographic camera has one (projection = "orthographic")',
            )
        try:
            height = float(camera.view_height)
        except (TypeError, ValueError):
            return "view_height", f"expected a number of world units, got {camera.view_height!r}"
        if not (math.isfinite(height) and height > 0.0 and height < 1e30):
            return "view_height", f"must be a finite number of world units > 0, got {height:g}"
    try:
        fov = float(camera.fov)
    except (TypeError, ValueError):
        return "fov", f"expected a number of degrees, got {camera.fov!r}"
    if not (math.isfinite(fov) and 0.0 < fov < 180.0):
        return "fov", f"must be > 0 and < 180 degrees, got {fov:g}"
    vectors = {}
    for name in ("position", "look_at", "up"):
        value = getattr(camera, name)
        try:
            vector = np.asarray(value, np.float64)
        except (TypeError, ValueError):
            vector = None
        if vector is None or vector.shape != (3,) or not np.isfinite(vector).all():
            return name, f"expected three finite numbers, got {value!r}"
        vectors[name] = vector
    found = view_problem(vectors["position"][None], vectors["look_at"][None], vectors["up"])
    return None if found is None else found[1:]


def view_problem(positions: np.ndarray, looks: np.ndarray, up) -> tuple[int, str, str] | None:
    """The first of n cameras at (n, 3) float64 finite ``positions`` looking at (n, 3)
    ``looks``, all with the finite (3,) ``up``, whose image ``camera_problem``'s rule refuses
    (``look_at`` at ``position``, ``up`` zero or within ``MIN_UP_SINE`` of the view), as
    (index, field, problem), or None: the rule over a whole camera path at once."""
    up = np.asarray(up, np.float64)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        view = positions - looks
        distance = np.linalg.norm(view, axis=1)
        up_length = np.linalg.norm(up)
        sine = np.linalg.norm(np.cross(up / up_length, view / distance[:, None]), axis=1)
    refused = ~(distance > 0.0) | ~(up_length > 0.0) | ~(sine >= MIN_UP_SINE)
    if not refused.any():
        return None
    i = int(np.flatnonzero(refused)[0])
    if not distance[i] > 0.0:
        return i, "look_at", f"must differ from camera.position, both are {looks[i].tolist()}"
    if not up_length > 0.0:
        return i, "up", "must not be the zero vector"
    problem = (
        f"{up.tolist()} is parallel to the viewing direction (from {positions[i].tolist()} to "
        f"{looks[i].tolist()})"
    )
    return i, "up", problem


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """A validated camera and image size, as a right-handed orthonormal basis.

    ``origin`` (3,) float64 is the eye; ``u`` (right), ``v`` (up) and ``w`` (backward: the
    camera looks along ``-w``) are (3,) float64 unit vectors. The image is ``width`` ×
    ``height`` pixels, row 0 at the top, column 0 at the left. A perspective frame's image
    plane at distance 1 spans ``[-half_width, half_width] × [-half_height, half_height]``;
    an ``orthographic`` frame's rays all run along ``-w`` from the points ``origin + x u + y v``
    of that rectangle (world units) through the eye.
    """

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    half_width: float
    half_height: float
    width: int
    height: int
    orthographic: bool = False


def _positive_integer(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ValueError(f"{name}: must be a positive integer, got {value!r}")
    return int(value)


def camera_frame(camera: Camera, width: int, height: int) -> CameraFrame:
    """Validate ``camera`` and the image size and build the frame.

    Raises ValueError naming the field when ``width`` or ``height`` is not a positive integer,
    ``camera.fov`` is not strictly between 0 and 180 degrees, a vector is not three finite
    numbers, ``camera.look_at`` equals ``camera.position``, or ``camera.up`` is zero or parallel
    to the viewing direction.
    """
    width = _positive_integer(width, "width")
    height = _positive_integer(height, "height")
    if (problem := camera_problem(camera)) is not None:
        field, text = problem
        raise ValueError(f"camera.{field}: {text}")
    fov = float(camera.fov)
    position, look_at, up = (
        np.asarray(vector, np.float64) for vector in (camera.position, camera.look_at, camera.up)
    )
    view = position - look_at
    w = view / np.linalg.norm(view)
    side = np.cross(up / np.linalg.norm(up), w)
    u = side / np.linalg.norm(side)
    v = np.cross(w, u)
    orthographic = camera.projection == "orthographic"
    if orthographic:
        half_height = view_height_of(camera) / 2.0
    else:
        half_height = math.tan(math.radians(fov) / 2.0)
    for vector in (position, u, v, w):
        vector.setflags(write=False)
    return CameraFrame(
        origin=position,
        u=u,
        v=v,
        w=w,
        half_width=half_height * width / height,
        half_height=half_height,
        width=width,
        height=height,
        orthographic=orthographic,
    )


def view_height_of(camera: Camera) -> float:
    """The world units an orthographic ``camera``'s image spans from bottom to top: its
    ``view_height``, or without one the height its ``fov`` sees at ``look_at``'s distance."""
    if camera.view_height is not None:
        return float(camera.view_height)
    distance = math.dist(camera.position, camera.look_at)
    return 2.0 * distance * math.tan(math.radians(float(camera.fov)) / 2.0)


def strata(spp: int) -> tuple[int, int, np.ndarray]:
    """The jitter grid of a pixel and the cell of each of its ``spp`` samples.

    Returns ``nx`` (columns, ``ceil(sqrt(spp))``), ``ny`` (rows, the fewest with ``nx * ny >=
    spp``) and ``cells`` (spp,) int64: sample s lies in column ``cells[s] % nx``, row ``cells[s]
    // nx`` (rows top to bottom). Cells are distinct and spread evenly over the grid; the set is
    symmetric about the pixel centre whenever that is possible (a grid with a centre cell, or
    an even number of samples), so the samples' mean position is the pixel centre and the
    image is not shifted by a fraction of a pixel (spp = 8 leaves out the centre of 3 × 3).
    """
    spp = _positive_integer(spp, "spp")
    nx = math.ceil(math.sqrt(spp))
    ny = math.ceil(spp / nx)
    total = nx * ny
    sample = np.arange(spp, dtype=np.int64)
    mirror = spp - 1 - sample
    # The first half of the samples take evenly spaced cells from the start of the grid, the
    # second half their point reflections (cell c <-> total - 1 - c).
    first_half = ((2 * np.minimum(sample, mirror) + 1) * total) // (2 * spp)
    cells = np.where(sample > mirror, total - 1 - first_half, first_half)
    return nx, ny, cells


def _check_range(start: object, count: object, total: int, units: str, image: str) -> None:
    """Raise ValueError unless ``start`` and ``count`` are non-negative integers with
    ``start + count <= total``; the message counts ``units`` of the ``image`` it describes."""
    if isinstance(start, bool) or not isinstance(start, numbers.Integral) or start < 0:
        raise ValueError(f"start: must be a non-negative integer, got {start!r}")
    if isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 0:
        raise ValueError(f"count: must be a non-negative integer, got {count!r}")
    if start + count > total:
        raise ValueError(f"{units} {start}..{start + count} run past the image's {total} ({image})")


# Camera rays are traced in tiles of TILE_WIDTH x TILE_HEIGHT pixels: one 8-ray packet then
# covers a 4x2 block instead of 8 pixels of one row, and on the 1e6-sphere field Embree traced
# such packets 1.18x faster (1e5: the same speed).
TILE_WIDTH = 4
TILE_HEIGHT = 2


def tiled_samples(
    frame: CameraFrame, spp: int, start: int, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """The global sample indices ``[start, start + count)`` (whole pixels, as ``batch_ranges``
    cuts them) reordered pixel by pixel into tiles of ``TILE_WIDTH`` x ``TILE_HEIGHT`` pixels:
    tiles left to right along each pair of rows, inside a tile row-major, each pixel's samples
    together in sample order. Returns the (count,) int64 indices and (count,) int64 pixels.

    The order is the global tile order restricted to these pixels, so any two samples keep the
    same relative order however the image is cut into batches: the film sums each pixel's
    samples in the same order whatever the batch size.
    """
    size = f"{frame.width}x{frame.height}"
    _check_range(start, count, frame.width * frame.height * spp, "samples", f"{size} at {spp} spp")
    if start % spp or count % spp:
        raise ValueError(f"samples {start}..{start + count} do not cover whole pixels at {spp} spp")
    first, stop = start // spp, (start + count) // spp
    return tile_order(frame.width, spp, TILE_WIDTH, TILE_HEIGHT, first, stop)


def camera_rays(frame: CameraFrame, spp: int, seed: int) -> CameraRays:
    """What the ray of each camera sample of a render at ``spp`` samples per pixel and ``seed``
    depends on besides its index, for the compiled code that makes the rays."""
    nx, ny, cells = strata(spp)
    u, v, w, origin = (
        np.ascontiguousarray(axis, np.float32) for axis in (frame.u, frame.v, frame.w, frame.origin)
    )
    return CameraRays(
        origin,
        u,
        v,
        w,
        2.0 * frame.half_width / frame.width,
        float(frame.half_width),
        2.0 * frame.half_height / frame.height,
        float(frame.half_height),
        frame.width,
        spp,
        nx,
        ny,
        cells,
        hash_key(seed, 0),
        frame.orthographic,
    )


def sample_rays(
    frame: CameraFrame, spp: int, seed: int, index: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera rays for the (n,) int64 global sample indices ``index`` (any order, each below
    ``width * height * spp``).

    Sample i belongs to pixel ``i // spp`` (row-major, row 0 at the top, column 0 at the left)
    and is sample ``s = i % spp`` of it, placed in cell ``strata(spp)[2][s]`` of the pixel's
    jitter grid and jittered inside it by ``sampling.uniform_pair(seed, i, 0)``: sample i of a
    render is the same ray whichever call, batch or order makes it. The point on the image
    plane is worked out in float64 (the jitter must survive being added to a column number in
    the thousands) and rounded once to float32; the direction ``u x + v y - w`` and its
    normalisation are float32 (``compiled.camera_rays.sample_direction``). An orthographic
    frame's rays run along ``-w`` from that point of the image plane, ``eye + (u x + v y)`` in
    float32 (``compiled.camera_rays.sample_origin``). Returns origins (3, n) float32, unit
    directions (3, n) float32 and pixel (n,) int64."""
    index = np.ascontiguousarray(index, np.int64)
    spp = _positive_integer(spp, "spp")
    origins, directions = compiled_rays.sample_rays(camera_rays(frame, spp, seed), index)
    return origins, directions, index // spp


def pixel_center_rays(
    frame: CameraFrame, start: int, count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One camera ray through the centre of each pixel ``start .. start + count - 1``
    (row-major, as ``sample_rays`` numbers them), with no jitter: the rays of the AOVs.
    Returns origins (3, count) float32, unit directions (3, count) float32 and pixel (count,)
    int64, as ``sample_rays`` does."""
    size = f"{frame.width}x{frame.height}"
    _check_range(start, count, frame.width * frame.height, "pixels", size)
    pixel = np.arange(start, start + count, dtype=np.int64)
    row = pixel // frame.width
    col = pixel % frame.width
    return _rays_through(frame, col + 0.5, row + 0.5, pixel)


def _rays_through(
    frame: CameraFrame, column: np.ndarray, row: np.ndarray, pixel: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays from the eye through the image points at (n,) float64 ``column``, ``row`` (in
    pixels, from the top left corner), for ``pixel_center_rays``."""
    # Screen coordinates, x = (2 column / width - 1) half_width and y = (1 - 2 row / height)
    # half_height, in float64: the jitter must survive being added to a column number in the
    # thousands.
    screen_x = (column * (2.0 * frame.half_width / frame.width) - frame.half_width).astype(
        np.float32
    )
    screen_y = (frame.half_height - row * (2.0 * frame.half_height / frame.height)).astype(
        np.float32
    )
    u, v, w = (axis.astype(np.float32)[:, None] for axis in (frame.u, frame.v, frame.w))
    origins = np.empty((3, len(pixel)), np.float32)
    origins[:] = frame.origin.astype(np.float32)[:, None]
    if frame.orthographic:
        origins += u * screen_x + v * screen_y
        return origins, np.repeat(-w, len(pixel), axis=1), pixel
    directions = u * screen_x + v * screen_y - w  # (3, count) float32
    directions /= np.sqrt(directions[0] ** 2 + directions[1] ** 2 + directions[2] ** 2)
    return origins, directions, pixel


# -- the camera as dataset tools take it ------------------------------------------------------

# OpenCV's camera axes (x right, y down, z forward) in OpenGL's / Blender's (x right, y up, z
# backward): the two world-to-camera matrices differ by this flip of y and z.
OPENCV_FROM_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


def intrinsics(frame: CameraFrame) -> np.ndarray:
    """(3, 3) float64 K of ``frame`` in OpenCV's pixel convention: a camera-space point
    (x, y, z) (OpenCV axes) lands, through a pinhole, at column ``fx x / z + cx``, row
    ``fy y / z + cy``; through an orthographic frame K is affine, the point lands at
    ``K @ (x, y, 1)`` whatever its z (fx, fy then pixels per world unit). The centre of pixel
    (column c, row r) is at (c, r), so ``cx = width / 2 - 1/2``. (Tools that put pixel centres
    at c + 1/2, as NeRF's and Blender's do, take ``cx + 1/2``, ``cy + 1/2``.)"""
    fx = frame.width / (2.0 * frame.half_width)
    fy = frame.height / (2.0 * frame.half_height)
    return np.array(
        [[fx, 0.0, frame.width / 2.0 - 0.5], [0.0, fy, frame.height / 2.0 - 0.5], [0.0, 0.0, 1.0]]
    )


def world_to_camera_opengl(frame: CameraFrame) -> np.ndarray:
    """(4, 4) float64 world-to-camera matrix with OpenGL's and Blender's camera axes: x right,
    y up, the camera looking down -z."""
    rotation = np.stack([frame.u, frame.v, frame.w])
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = -rotation @ frame.origin
    return matrix


def world_to_camera_opencv(frame: CameraFrame) -> np.ndarray:
    """(4, 4) float64 world-to-camera matrix with OpenCV's camera axes: x right, y down, the
    camera looking down +z (what ``intrinsics`` projects)."""
    return OPENCV_FROM_OPENGL @ world_to_camera_opengl(frame)


def camera_to_world_opengl(frame: CameraFrame) -> np.ndarray:
    """(4, 4) float64 camera-to-world matrix in OpenGL's convention: the columns are the
    camera's right, up and backward axes and its position (NeRF's ``transform_matrix``)."""
    matrix = np.eye(4)
    matrix[:3, :3] = np.stack([frame.u, frame.v, frame.w], axis=1)
    matrix[:3, 3] = frame.origin
    return matrix
