"""How to show a mesh file rendered on its own, with no scene file (``embree-rt render
model.glb``): where the camera, the lights and the floor go, as plain numbers (a ``Staging``)
that ``Scene.from_file`` and ``Scene.from_trimesh`` make the scene's camera, lights and floor of.

The scene shows the file as it is placed (glTF nodes, instancing) and, when the file has them,
from its own camera (glTF: the first camera a node uses) under its own lights
(``KHR_lights_punctual``); otherwise from a camera framed on its bounds under a default rig of
two lights. A checkered floor lies under it unless asked not to. ``Scene.notes`` says what was
found and what was chosen.

The renderer's lights are points with no falloff and no cone, so a file's lights are mapped:
a point light stays one; a spot light becomes a point light (said in a warning line); a
directional light becomes a point light so far along its direction (10^4 model radii) that
its rays are parallel to 10^-4 radians. Their strengths keep their ratios at the model's centre
(candela over squared distance; lux for a directional light), scaled to sum to
``FILE_LIGHTS_TOTAL``, since the renderer has no exposure to take physical units.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
import trimesh

from embree_rt.scene.errors import warn_input
from embree_rt.scene.gltf import FileCamera, FileLight
from embree_rt.scene.meshes import LoadedModel, mesh_parts

Point = tuple[float, float, float]
FRAMED_FOV = 40.0  # degrees, vertical
# The framed view: from the front, a little to the right and above (azimuth, elevation, degrees).
FRAMED_AZIMUTH, FRAMED_ELEVATION = 30.0, 20.0
# The default rig: a key light and a fill, as (offset from the centre in model radii, intensity).
DEFAULT_RIG = (((4.0, 7.0, 6.0), 0.8), ((-6.0, 3.0, 2.0), 0.3))
FILE_LIGHTS_TOTAL = 1.0
DISTANT_LIGHT_RADII = 1e4
# The floor lies this far (in model diameters) below the lowest point, so that a model standing
# on y = 0 does not share its soles' plane with the floor.
FLOOR_GAP = 1e-4


def model_bounds(model: LoadedModel) -> tuple[np.ndarray, np.ndarray]:
    """(3,) float64 lowest and highest world coordinates of a model's triangles (an instanced
    mesh's copies bounded by its box's corners when they are many)."""
    lows, highs = [], []
    for mesh, transform in model.parts:
        points = trimesh.transform_points(np.asarray(mesh.vertices, np.float64), transform)
        lows.append(points.min(axis=0))
        highs.append(points.max(axis=0))
    for mesh, transforms in model.instanced:
        points = np.asarray(mesh.vertices, np.float64)
        if len(points) * len(transforms) > 1_000_000:
            points = trimesh.bounds.corners(mesh.bounds)
        world = np.einsum("nij,kj->nki", transforms[:, :3, :3], points)
        world += transforms[:, None, :3, 3]
        lows.append(world.min(axis=(0, 1)))
        highs.append(world.max(axis=(0, 1)))
    return np.min(lows, axis=0), np.max(highs, axis=0)


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
        _vec(center + distance * direction),
        _vec(center),
        (0.0, 1.0, 0.0),
        fov,
        "camera: framed from the bounds",
    )


def default_lights(low: np.ndarray, high: np.ndarray) -> list[Light]:
    """``DEFAULT_RIG`` placed around the box ``low``..``high``."""
    center = (low + high) / 2.0
    radius = max(float(np.linalg.norm(high - low)) / 2.0, 1e-12)
    return [
        Light(_vec(center + radius * np.array(offset)), (1.0, 1.0, 1.0), intensity)
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


def file_view(camera: FileCamera, center: np.ndarray, radius: float, note: str) -> View:
    """A file's camera as a pinhole's placement, aimed along its view."""
    reach = max(float(np.dot(center - camera.position, camera.forward)), radius, 1e-12)
    return View(
        _vec(camera.position),
        _vec(camera.position + reach * camera.forward),
        _vec(camera.up),
        camera.yfov_degrees,
        note,
    )


def file_lights(
    path: Path, lights: list[FileLight], center: np.ndarray, radius: float
) -> list[Light]:
    """A file's lights as point lights (module docstring), warning once per spot light."""
    strengths = []
    positions = []
    for light in lights:
        if light.kind == "directional":
            positions.append(center - DISTANT_LIGHT_RADII * radius * light.direction)
            strengths.append(light.intensity)
            continue
        if light.kind == "spot":
            warn_input(
                f"{path}: {light.key}: a spot light, rendered as a point light (embree_rt's "
                f"lights have no cone; its outer cone is {light.outer_cone_degrees:g} "
                "degrees)"
            )
        positions.append(light.position)
        squared = max(float(np.sum((light.position - center) ** 2)), (1e-3 * radius) ** 2)
        strengths.append(light.intensity / squared)
    total = sum(strengths)
    scale = FILE_LIGHTS_TOTAL / total if total > 0 else 0.0
    return [
        Light(_vec(p), light.color, s * scale)
        for p, s, light in zip(positions, strengths, lights, strict=True)
    ]


def stage_model(path: Path, model: LoadedModel) -> Staging:
    """How to show the mesh file at ``path``, read as ``model`` (module docstring)."""
    low, high = model_bounds(model)
    center, radius = (low + high) / 2.0, max(float(np.linalg.norm(high - low)) / 2.0, 1e-12)
    views = [framed_view(low, high)]
    aspect = None
    if model.camera is not None:
        views.insert(
            0, file_view(model.camera, center, radius, f"camera: {model.camera.key} of {path}")
        )
        aspect = model.camera.aspect_ratio
    if model.lights:
        lights = file_lights(path, model.lights, center, radius)
        kinds = ", ".join(light.kind for light in model.lights)
        note = f"lights: the file's {len(model.lights)} (KHR_lights_punctual: {kinds})"
    else:
        lights, note = default_lights(low, high), "lights: the default rig of two"
    return Staging(views, lights, floor_under(low, high), aspect, [note])


def stage_trimesh(loaded: trimesh.Trimesh | trimesh.Scene) -> Staging:
    """How to show a trimesh.Trimesh or trimesh.Scene: from a Scene's camera when it has one
    (``trimesh.Scene.has_camera``), else framed; the default light rig."""
    low, high = model_bounds(LoadedModel(mesh_parts(loaded)))
    views = [framed_view(low, high)]
    if isinstance(loaded, trimesh.Scene) and loaded.has_camera:
        pose = np.asarray(loaded.camera_transform, np.float64)
        camera = FileCamera(
            key="camera",
            position=pose[:3, 3],
            forward=-pose[:3, 2] / np.linalg.norm(pose[:3, 2]),
            up=pose[:3, 1] / np.linalg.norm(pose[:3, 1]),
            yfov_degrees=float(loaded.camera.fov[1]),
            aspect_ratio=None,
        )
        center, radius = (low + high) / 2.0, float(np.linalg.norm(high - low)) / 2.0
        views.insert(0, file_view(camera, center, radius, "camera: the trimesh.Scene's"))
    return Staging(
        views,
        default_lights(low, high),
        floor_under(low, high),
        None,
        ["lights: the default rig of two"],
    )


def _vec(values: np.ndarray) -> Point:
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
