"""Camera paths: a scene's ``[animation]``, the camera of each frame, and its file table
(``animation_file`` reads and checks it).

Two kinds of path, both about the scene's ``[camera]``:

- ``orbit``: the camera turns ``orbit`` degrees about the line through ``look_at`` along ``up``
  over the shot, frame ``f`` at ``orbit · f / frames`` (so a 360° orbit loops without repeating
  a frame); ``look_at``, ``up`` and ``fov`` stay.
- ``keyframes``: ``{frame, position, look_at, fov}`` (a missing field keeps the previous
  keyframe's value, the first's the camera's). ``position`` and ``look_at`` follow a Catmull-Rom
  spline through the keyframes (cubic Hermite pieces whose tangent at a keyframe is the chord of
  its neighbours over their frame span, one-sided at the ends): smooth and through every key.
  ``fov`` follows a monotone cubic (PCHIP, Fritsch-Carlson), which never leaves the range of the
  keyframes' values, so a valid fov stays valid. Frames before the first keyframe or after the
  last hold it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from embree_rt.camera import Camera, Vec3

# The loader checks the camera of every frame of a path (arrays of this length): a million
# frames is 11.6 hours at 24 frames a second.
MAX_FRAMES = 1_000_000


@dataclass
class Keyframe:
    """The camera at ``frame``: where it is, what it looks at, its vertical fov in degrees."""

    frame: int
    position: Vec3
    look_at: Vec3
    fov: float


@dataclass
class Animation:
    """``frames`` frames (numbered from 0) of a camera path: an ``orbit`` in degrees, or
    ``keyframes`` in increasing frame order (exactly one of the two)."""

    frames: int
    orbit: float | None = None
    keyframes: list[Keyframe] = field(default_factory=list)


def camera_at(camera: Camera, animation: Animation, frame: int) -> Camera:
    """The camera of ``frame`` (0 <= frame < animation.frames) on the path from ``camera``."""
    if animation.orbit is not None:
        angle = math.radians(animation.orbit * frame / animation.frames)
        center = np.asarray(camera.look_at, np.float64)
        offset = _rotate(np.asarray(camera.position, np.float64) - center, camera.up, angle)
        return replace(camera, position=_vec(center + offset))
    return cameras_on_keyframes(camera, animation.keyframes, [frame])[0]


def frame_cameras(camera: Camera, animation: Animation) -> list[Camera]:
    """The camera of every frame, in order."""
    if animation.orbit is not None:
        return [camera_at(camera, animation, f) for f in range(animation.frames)]
    return cameras_on_keyframes(camera, animation.keyframes, range(animation.frames))


def cameras_on_keyframes(camera: Camera, keys: list[Keyframe], frames) -> list[Camera]:
    """Cameras at ``frames`` (ints) interpolated through ``keys`` (see the module's note)."""
    positions, looks, fovs = keyframe_paths(keys, frames)
    return [
        replace(camera, position=_vec(p), look_at=_vec(a), fov=float(f))
        for p, a, f in zip(positions, looks, fovs, strict=True)
    ]


def keyframe_paths(keys: list[Keyframe], frames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At ``frames`` (n ints), interpolated through ``keys`` (see the module's note): (n, 3)
    float64 positions, (n, 3) float64 look_at points and (n,) float64 fovs."""
    frames = np.asarray(frames, np.float64)
    knots = np.array([key.frame for key in keys], np.float64)
    inside = np.clip(frames, knots[0], knots[-1])
    if len(keys) == 1:
        positions = np.repeat([keys[0].position], len(frames), axis=0)
        looks = np.repeat([keys[0].look_at], len(frames), axis=0)
        fovs = np.full(len(frames), keys[0].fov)
    else:
        from scipy.interpolate import CubicHermiteSpline, PchipInterpolator

        def catmull_rom(values: np.ndarray) -> np.ndarray:
            slopes = np.empty_like(values)
            slopes[1:-1] = (values[2:] - values[:-2]) / (knots[2:] - knots[:-2])[:, None]
            slopes[0] = (values[1] - values[0]) / (knots[1] - knots[0])
            slopes[-1] = (values[-1] - values[-2]) / (knots[-1] - knots[-2])
            return CubicHermiteSpline(knots, values, slopes, axis=0)(inside)

        positions = catmull_rom(np.array([key.position for key in keys], np.float64))
        looks = catmull_rom(np.array([key.look_at for key in keys], np.float64))
        fovs = PchipInterpolator(knots, np.array([key.fov for key in keys], np.float64))(inside)
        # A frame on a keyframe (or held before the first, after the last) is that keyframe
        # exactly, not the spline's value rounded there.
        at = np.minimum(np.searchsorted(knots, inside), len(keys) - 1)
        for i in np.flatnonzero(knots[at] == inside):
            key = keys[at[i]]
            positions[i], looks[i], fovs[i] = key.position, key.look_at, key.fov
    return positions, looks, fovs


def _rotate(vector: np.ndarray, axis, angle: float) -> np.ndarray:
    """``vector`` (3,) turned by ``angle`` radians about ``axis`` (Rodrigues' formula)."""
    k = np.asarray(axis, np.float64)
    k = k / np.linalg.norm(k)
    cos, sin = math.cos(angle), math.sin(angle)
    return vector * cos + np.cross(k, vector) * sin + k * np.dot(k, vector) * (1.0 - cos)


def _vec(values) -> Vec3:
    return (float(values[0]), float(values[1]), float(values[2]))


# -- scene files -----------------------------------------------------------------------------


def animation_document(animation: Animation) -> dict:
    """The ``[animation]`` table of a scene file for ``animation``."""
    if animation.orbit is not None:
        return {"frames": animation.frames, "orbit": float(animation.orbit)}
    return {
        "frames": animation.frames,
        "keyframes": [
            {
                "frame": key.frame,
                "position": list(key.position),
                "look_at": list(key.look_at),
                "fov": float(key.fov),
            }
            for key in animation.keyframes
        ],
    }
