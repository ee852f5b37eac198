"""The pinhole camera: its frame, and jittered, stratified primary rays."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from embree_rt.sampling import uniform
from embree_rt.scene.model import Camera


@dataclass(frozen=True)
class CameraFrame:
    """Orthonormal camera basis: ``u`` right, ``v`` up, looking along ``-w``; the image plane at
    distance 1 spans ``half_width`` × ``half_height``."""

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    half_width: float
    half_height: float
    width: int
    height: int


def _vector(value, name: str) -> np.ndarray:
    array = np.asarray(value, np.float64)
    if array.shape != (3,) or not np.isfinite(array).all():
        raise ValueError(f"camera.{name}: expected three finite numbers, got {value!r}")
    return array


def camera_frame(camera: Camera, width: int, height: int) -> CameraFrame:
    """Validate ``camera`` and the image size, and build the frame."""
    for name, size in (("width", width), ("height", height)):
        if isinstance(size, bool) or int(size) != size or size < 1:
            raise ValueError(f"{name}: must be a positive integer, got {size!r}")
    fov = float(camera.fov)
    if not (math.isfinite(fov) and 0.0 < fov < 180.0):
        raise ValueError(f"camera.fov: must lie strictly between 0 and 180 degrees, got {fov}")
    position = _vector(camera.position, "position")
    look_at = _vector(camera.look_at, "look_at")
    up = _vector(camera.up, "up")
    view = position - look_at
    if np.linalg.norm(view) < 1e-12:
        raise ValueError("camera.look_at: must differ from camera.position")
    w = view / np.linalg.norm(view)
    side = np.cross(up, w)
    if np.linalg.norm(up) < 1e-12 or np.linalg.norm(side) < 1e-6 * np.linalg.norm(up):
        raise ValueError("camera.up: must not be parallel to the viewing direction")
    u = side / np.linalg.norm(side)
    v = np.cross(w, u)
    half_height = math.tan(math.radians(fov) / 2)
    return CameraFrame(
        origin=position,
        u=u,
        v=v,
        w=w,
        half_width=half_height * width / height,
        half_height=half_height,
        width=int(width),
        height=int(height),
    )


def primary_rays(
    frame: CameraFrame, spp: int, seed: int, start: int, count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera rays for global sample indices ``start .. start + count``.

    Sample i belongs to pixel ``i // spp`` (row-major, row 0 at the top) and is sample
    ``i % spp`` of it, placed in its own cell of an nx × ny grid over the pixel and jittered
    inside it. Returns origins (count, 3) float32, unit directions (count, 3) float32 and
    pixel (count,) int64.
    """
    index = np.arange(start, start + count, dtype=np.int64)
    pixel = index // spp
    sample = index % spp
    nx = math.ceil(math.sqrt(spp))
    ny = math.ceil(spp / nx)
    row = pixel // frame.width
    col = pixel % frame.width
    jx = uniform(seed, index, 0)
    jy = uniform(seed, index, 1)
    x = (col + ((sample % nx) + jx) / nx) / frame.width
    y = (row + ((sample // nx) + jy) / ny) / frame.height
    sx = (2.0 * x - 1.0) * frame.half_width
    sy = (1.0 - 2.0 * y) * frame.half_height
    directions = sx[:, None] * frame.u + sy[:, None] * frame.v - frame.w
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.broadcast_to(frame.origin.astype(np.float32), (count, 3)).copy()
    return origins, directions.astype(np.float32), pixel
