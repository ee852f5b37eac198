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
