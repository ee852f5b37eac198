"""How to show a mesh file rendered on its own, with no scene file (``embree-rt render
model.glb``): where the camera, the lights and the floor go, as plain numbers (a ``Staging``,
framed as ``staging`` frames any box) that ``Scene.from_file`` and ``Scene.from_trimesh`` make
the scene's camera, lights and floor of.

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

from pathlib import Path

import numpy as np
import trimesh

from embree_rt.scene.errors import warn_input
from embree_rt.scene.gltf import FileCamera, FileLight
from embree_rt.scene.meshes import LoadedModel, mesh_parts
from embree_rt.scene.staging import (
    Light,
    Staging,
    View,
    as_point,
    default_lights,
    floor_under,
    framed_view,
)

FILE_LIGHTS_TOTAL = 1.0
DISTANT_LIGHT_RADII = 1e4


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


def file_view(camera: FileCamera, center: np.ndarray, radius: float, note: str) -> View:
    """A file's camera as a pinhole's placement, aimed along its view."""
    reach = max(float(np.dot(center - camera.position, camera.forward)), radius, 1e-12)
    return View(
        as_point(camera.position),
        as_point(camera.position + reach * camera.forward),
        as_point(camera.up),
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
        Light(as_point(p), light.color, s * scale)
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
