"""OVITO's standard views: a camera framing a box along an axis of the scene's up convention.

The scene's up is its camera's ``up`` snapped to the nearest world axis (y for the default
scenes, z for a Z-up model). With ``right`` the next axis round (x unless up is x, then y),
the viewer's back is ``right × up``: +z for y-up (the front view looks down -z, as OpenGL's
does) and -y for z-up (OVITO's front view looks down +y). "top" looks down the up axis with
the front at the image's bottom, "iso" from the front, right and above at once.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from embree_rt.camera import Camera
from embree_rt.choices import STANDARD_VIEWS
from embree_rt.legend import Legend, legend_box
from embree_rt.scene.model import Scene
from embree_rt.scene.staging import View, clear_of_corner

# The framed box fills this share of the image's height or width, whichever it reaches first.
FILL = 1.0 / 1.08


def scene_bounds(scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """(3,) float64 low and high corners of everything in ``scene`` but the floor, or None
    when it is empty."""
    lows, highs = [], []
    if len(scene.sphere_radii):
        radius = scene.sphere_radii[:, None]
        lows.append((scene.sphere_centers - radius).min(axis=0))
        highs.append((scene.sphere_centers + radius).max(axis=0))
    for placement in scene.meshes:
        corners = placement.mesh.bounds
        box = np.array(
            [[x, y, z, 1.0] for x in corners[:, 0] for y in corners[:, 1] for z in corners[:, 2]]
        )
        world = box @ placement.transform.T
        lows.append(world[:, :3].min(axis=0))
        highs.append(world[:, :3].max(axis=0))
    for entry in scene.instances:
        corners = entry.mesh.bounds
        box = np.array(
            [[x, y, z] for x in corners[:, 0] for y in corners[:, 1] for z in corners[:, 2]]
        )
        world = np.einsum("nij,kj->nki", entry.transforms[:, :3, :3], box)
        world += entry.transforms[:, None, :3, 3]
        lows.append(world.min(axis=(0, 1)))
        highs.append(world.max(axis=(0, 1)))
    for curves in scene.curves:
        radius = curves.radii[:, None]
        lows.append((curves.points - radius).min(axis=0))
        highs.append((curves.points + radius).max(axis=0))
    if not lows:
        return None
    return np.min(lows, axis=0), np.max(highs, axis=0)


def view_axes(up: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(3,) float64 unit ``right``, ``up`` and ``back`` world axes of the scene whose camera's
    ``up`` (3 numbers, not zero) is given: up snapped to its largest component's axis."""
    up = np.asarray(up, np.float64)
    axis = int(np.argmax(np.abs(up)))
    snapped = np.zeros(3)
    snapped[axis] = math.copysign(1.0, up[axis])
    right = np.zeros(3)
    right[1 if axis == 0 else 0] = 1.0
    return right, snapped, np.cross(right, snapped)


def standard_view(
    camera: Camera,
    low: np.ndarray,
    high: np.ndarray,
    name: str,
    aspect: float,
    orthographic: bool = True,
    kept_below: float = 0.0,
) -> Camera:
    """``camera`` turned to the standard view ``name`` (one of ``STANDARD_VIEWS``) of the box
    ``low``..``high`` ((3,) float64 corners), for an image ``aspect`` = width / height wide.

    The camera looks at the box's centre along the view's axis from outside the box (its
    near plane, for an orthographic camera, clear of the box by a tenth of its diagonal); an
    orthographic camera's ``view_height`` fits the box's outline, a perspective one keeps its
    ``fov`` and stands back until every corner of the box is in the picture. An orthographic
    view keeps the bottom ``kept_below`` share of the image's height clear of the box (room
    for a legend there), the box framed in the rows above it."""
    if name not in STANDARD_VIEWS:
        raise ValueError(f"view: expected one of {', '.join(STANDARD_VIEWS)}, got {name!r}")
    right, up, back = view_axes(camera.up)
    toward, image_up = {
        "front": (back, up),
        "back": (-back, up),
        "right": (right, up),
        "left": (-right, up),
        "top": (up, -back),
        "bottom": (-up, back),
        "iso": ((right + up + back) / math.sqrt(3.0), up),
    }[name]
    low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
    center = (low + high) / 2.0
    radius = max(float(np.linalg.norm(high - low)) / 2.0, 1e-9)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    corners = low + corners * (high - low) - center
    side = np.cross(image_up, toward)
    side /= np.linalg.norm(side)
    screen_up = np.cross(toward, side)
    across = 2.0 * np.abs(corners @ side).max()
    tall = 2.0 * np.abs(corners @ screen_up).max()
    if orthographic:
        distance = 1.1 * radius
        height = max(tall / (1.0 - kept_below), across / aspect, 1e-9) / FILL
        # the box's centre at the centre of the rows above the kept share
        center = center - kept_below * height / 2.0 * screen_up
    else:
        # back until every corner is inside the image: a corner ``toward`` by z from the
        # centre and off the axis by x, y needs the eye at least z + |x| / tan(half width) away
        tall_tan = math.tan(math.radians(float(camera.fov)) / 2.0) * FILL
        along = corners @ toward
        off_axis = np.maximum(
            np.abs(corners @ side) / (tall_tan * aspect), np.abs(corners @ screen_up) / tall_tan
        )
        distance = max(float(np.max(along + off_axis)), 1e-9)
        height = None
    return replace(
        camera,
        position=tuple(float(c) for c in center + distance * toward),
        look_at=tuple(float(c) for c in center),
        up=tuple(float(c) for c in image_up),
        projection="orthographic" if orthographic else "perspective",
        view_height=height,
    )


def clear_of_legend(scene: Scene, legend: Legend | None) -> Camera:
    """``scene``'s camera moved so that the bottom-right corner ``legend`` takes (the scene's,
    or a trajectory's first frame's; ``legend.legend_box`` at the render's size) shows none of
    the scene's bounds
    (``staging.clear_of_corner``): a perspective camera looking at the centre of the bounds,
    as the framed view and the perspective standard views do. The camera as it is without a
    legend, without bounds, or when it is orthographic (an orthographic standard view keeps
    the legend's rows clear itself: ``standard_view``'s ``kept_below``)."""
    bounds = scene_bounds(scene)
    camera = scene.camera
    if legend is None or bounds is None or camera.projection != "perspective":
        return camera
    width, height = scene.render.width, scene.render.height
    columns, rows = legend_box(legend, width, height)
    view = View(camera.position, camera.look_at, camera.up, float(camera.fov), "")
    moved = clear_of_corner(view, *bounds, width / height, (columns / width, rows / height))
    return replace(camera, position=moved.position, look_at=moved.look_at)
