"""How to show a model or a set of spheres on its own, framed on its bounds: the camera's
placement, the default rig of two lights and the floor under it, as plain numbers (a
``Staging``) that ``Scene`` turns into its camera, lights and floor. A mesh file's own camera
and lights are read into a ``Staging`` by ``model_file``; particles (``stage_spheres``) need
nothing of trimesh, so staging them here keeps trimesh out of a particle file's render."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

Point = tuple[float, float, float]
FRAMED_FOV = 40.0  # degrees, vertical
# The framed view: from the front, a little to the right and above (azimuth, elevation, degrees).
FRAMED_AZIMUTH, FRAMED_ELEVATION = 30.0, 20.0
# The default rig: a key light and a fill, as (offset from the centre in model radii, intensity).
DEFAULT_RIG = (((4.0, 7.0, 6.0), 0.8), ((-6.0, 3.0, 2.0), 0.3))
# The floor lies this far (in model diameters) below the lowest point, so that a model standing
# on y = 0 does not share its soles' plane with the floor.
FLOOR_GAP = 1e-4


class View(NamedTuple):
    """A pinhole camera's placement (``Camera``'s fields) and where it comes from."""

    position: Point
    look_at: Point
    up: Point
    fov: float
    note: str


class Light(NamedTuple):
    """A point light's fields (``PointLight``'s)."""

    position: Point
    color: Point
    intensity: float


class Staging(NamedTuple):
    """How to show a model: ``views`` in order of preference (the file's camera, when it has
    one, then the framed one: the first the camera rule accepts is taken); ``lights``;
    ``floor`` (height, checker square size); the file camera's width / height or None;
    ``notes`` on the lights and floor (``Scene.notes``)."""

    views: list[View]
    lights: list[Light]
    floor: tuple[float, float]
    aspect_ratio: float | None
    notes: list[str]


def framed_view(low: np.ndarray, high: np.ndarray, fov: float = FRAMED_FOV) -> View:
    """A camera on the ball around the box ``low``..``high``, from ``FRAMED_AZIMUTH`` and
    ``FRAMED_ELEVATION``, near enough for the ball to fill the image's height."""
    center = (low + high) / 2.0
    radius = max(float(np.linalg.norm(high - low)) / 2.0, 1e-12)
    azimuth, elevation = math.radians(FRAMED_AZIMUTH), math.radians(FRAMED_ELEVATION)
    direction = np.array(
        [
            math.sin(azimuth) * math.cos(elevation),
            math.sin(elevation),
            math.cos(azimuth) * math.cos(elevation),
        ]
    )
    distance = 1.05 * radius / math.sin(math.radians(fov) / 2.0)
    return View(
        as_point(center + distance * direction),
        as_point(center),
        (0.0, 1.0, 0.0),
        fov,
        "camera: framed from the bounds",
    )


def default_lights(low: np.ndarray, high: np.ndarray) -> list[Light]:
    """``DEFAULT_RIG`` placed around the box ``low``..``high``."""
    center = (low + high) / 2.0
    radius = max(float(np.linalg.norm(high - low)) / 2.0, 1e-12)
    return [
        Light(as_point(center + radius * np.array(offset)), (1.0, 1.0, 1.0), intensity)
        for offset, intensity in DEFAULT_RIG
    ]


def floor_under(low: np.ndarray, high: np.ndarray) -> tuple[float, float]:
    """A floor just under the box ``low``..``high``, its squares the round size (1, 2.5 or 5
    times a power of ten) nearest a quarter of the model's width: a 0.16-unit model and a
    1,100-unit one both stand on a few squares."""
    extent = float(np.max(high - low))
    size = 1.0
    if extent > 0:
        wanted = math.log10(extent / 4.0)
        decade = math.floor(wanted)
        size = min(
            (step * 10.0**power for power in (decade, decade + 1) for step in (1, 2.5, 5)),
            key=lambda candidate: abs(math.log10(candidate) - wanted),
        )
    return float(low[1]) - FLOOR_GAP * max(extent, 1e-12), size


def as_point(values: np.ndarray) -> Point:
    """(3,) ``values`` as a tuple of three floats."""
    x, y, z = (float(v) for v in values)
    return (x, y, z)


# Spheres whose bounds are summed at a time (float64 rows that stay in the cache).
BOUNDS_ROWS = 1 << 16


def sphere_bounds(centers: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3,) float64 lowest and highest corners of the spheres ``centers`` (n, 3) and ``radii``
    (n,) (any real dtype), each sum formed in float64; ``BOUNDS_ROWS`` at a time in buffers
    made once and laid out as columns (a minimum of minima is the minimum): no (n, 3) float64
    copy, and no fresh memory a slice (which the kernel would fault in page by page)."""
    low, high = np.full(3, np.inf), np.full(3, -np.inf)
    rows = min(BOUNDS_ROWS, len(radii))
    wide, reach, ends = np.empty((3, rows)), np.empty(rows), np.empty((3, rows))
    for start in range(0, len(radii), rows):
        count = min(rows, len(radii) - start)
        part, size, end = wide[:, :count], reach[:count], ends[:, :count]
        part[...] = centers[start : start + count].T
        size[...] = radii[start : start + count]
        low = np.minimum(low, np.subtract(part, size, out=end).min(axis=1))
        high = np.maximum(high, np.add(part, size, out=end).max(axis=1))
    return low, high


def stage_spheres(centers: np.ndarray, radii: np.ndarray) -> Staging:
    """How to show spheres on their own (a particle file): ``centers`` (n, 3), ``radii`` (n,);
    framed on their bounds, under the default rig."""
    low, high = sphere_bounds(centers, radii)
    return Staging(
        [framed_view(low, high)],
        default_lights(low, high),
        floor_under(low, high),
        None,
        ["lights: the default rig of two"],
    )


# The share of the image's half width and height a view moved beside a legend may fill at the
# edges the legend leaves free: the framed ball's own margin (``framed_view``).
FILL_BESIDE = 1.0 / 1.05


def clear_of_corner(
    view: View, low: np.ndarray, high: np.ndarray, aspect: float, corner: tuple[float, float]
) -> View:
    """``view`` (a pinhole looking at the box ``low``..``high``, (3,) float64 corners) moved so
    that the box's outline in an image ``aspect`` = width / height wide keeps out of the
    bottom-right ``corner`` (its share of the image's width, of its height): a legend's.

    The outline is the bounding rectangle of the box's eight corners as projected (the box is
    convex and in front of the camera, so whatever lies in it projects inside). A view whose
    outline already keeps out is returned as it is. Else the camera keeps its direction and
    field of view and is moved within its image plane (by a, b) and back along its view (to
    a distance D from the point it then looks at, never nearer than before), so the outline
    lies left of the corner or above it, within the image less ``1 - FILL_BESIDE`` of its half
    width and height at the free edges: whichever of the two stands back least, then moves
    least. With the corner's width or height the whole image (nothing left beside it), the
    view is returned as it is.

    In the camera's frame (right u, image up v, forward f, from ``camera.camera_frame``'s rule),
    a corner at x, y, z from the old look-at point is at (x - a, y - b) across and z + D deep:
    inside [u0, u1] across when u0 (z + D) <= x - a <= u1 (z + D) for every corner, linear in a
    and D, so the least D for which some a fits is closed-form, and so is the range of a."""
    position = np.asarray(view.position, np.float64)
    look = np.asarray(view.look_at, np.float64)
    back = position - look
    distance = float(np.linalg.norm(back))
    w = back / distance
    u = np.cross(np.asarray(view.up, np.float64), w)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    tall = math.tan(math.radians(view.fov) / 2.0)
    wide = tall * aspect
    box = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    relative = low + box * (high - low) - look
    x, y, z = relative @ u, relative @ v, -(relative @ w)
    legend_left = wide * (1.0 - 2.0 * corner[0])
    legend_top = tall * (-1.0 + 2.0 * corner[1])
    depth = z + distance
    if np.all(x / depth <= legend_left) or np.all(y / depth >= legend_top):
        return view
    wide_in, tall_in = FILL_BESIDE * wide, FILL_BESIDE * tall
    placements = []
    for across, upward in (
        ((-wide_in, legend_left), (-tall_in, tall_in)),  # left of the corner
        ((-wide_in, wide_in), (legend_top, tall_in)),  # above it
    ):
        if not (across[0] < across[1] and upward[0] < upward[1]):
            continue
        stand = max(distance, least_distance(x, z, *across), least_distance(y, z, *upward))
        shift = (nearest_shift(x, z + stand, *across), nearest_shift(y, z + stand, *upward))
        placements.append((stand, abs(shift[0]) + abs(shift[1]), shift))
    if not placements:
        return view
    stand, _, (a, b) = min(placements, key=lambda placement: placement[:2])
    target = look + a * u + b * v
    return view._replace(
        position=as_point(target + stand * w),
        look_at=as_point(target),
    )


def least_distance(x: np.ndarray, z: np.ndarray, low: float, high: float) -> float:
    """The least D for which one shift a puts every (x - a) / (z + D) within [low, high]
    (``low < high``), for points at x across and z deep (k,) float64 from a look-at point."""
    return float((np.max(x - high * z) - np.min(x - low * z)) / (high - low))


def nearest_shift(x: np.ndarray, depth: np.ndarray, low: float, high: float) -> float:
    """The shift a nearest 0 that puts every (x - a) / depth within [low, high], for points
    at x across and ``depth`` (k,) float64 deep (one exists: ``least_distance``)."""
    least, most = float(np.max(x - high * depth)), float(np.min(x - low * depth))
    return min(max(0.0, least), most)
