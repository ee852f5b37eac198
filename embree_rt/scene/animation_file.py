"""The ``[animation]`` table of a scene file, read and checked (see ``scene.animation``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from embree_rt.camera import Camera, camera_problem, view_problem
from embree_rt.scene.animation import MAX_FRAMES, Animation, Keyframe, keyframe_paths
from embree_rt.scene.fields import Table


def read_animation(table: Table, camera: Camera) -> Animation:
    """The ``[animation]`` table, checked: every frame's camera must define an image (the rule
    of ``camera.camera_problem``). Raises ``SceneError`` naming the key."""
    table.require("frames")
    frames = table.integer("frames", low=1, high=MAX_FRAMES)
    keyframe_tables = table.tables("keyframes")
    if table.has("orbit") == bool(keyframe_tables):
        raise table.error("orbit", "give either orbit (degrees) or a list of keyframes")
    if table.has("orbit"):
        animation = Animation(frames, orbit=table.number("orbit"))
        table.finish()
        return animation  # turning about up keeps the angle between up and the view
    keys: list[Keyframe] = []
    previous = Keyframe(-1, tuple(camera.position), tuple(camera.look_at), float(camera.fov))
    for key_table in keyframe_tables:
        key_table.require("frame")
        number = key_table.integer("frame", low=0)
        if number >= frames:
            raise key_table.error("frame", f"must be < animation.frames ({frames}), got {number}")
        if number <= previous.frame:
            raise key_table.error(
                "frame", f"must be greater than the previous keyframe's ({previous.frame})"
            )
        key = Keyframe(
            frame=number,
            position=key_table.vector("position", previous.position),
            look_at=key_table.vector("look_at", previous.look_at),
            fov=key_table.number("fov", previous.fov),
        )
        key_table.finish()
        at_key = replace(camera, position=key.position, look_at=key.look_at, fov=key.fov)
        if (problem := camera_problem(at_key)) is not None:
            name, text = problem
            raise key_table.error(name if name != "up" else "look_at", text)
        keys.append(key)
        previous = key
    table.finish()
    animation = Animation(frames, keyframes=keys)
    # The spline may pass through a camera no keyframe has (look_at meeting position); frames
    # outside the keyframes hold the first or the last, checked above.
    first = keys[0].frame
    positions, looks, fovs = keyframe_paths(keys, np.arange(first, keys[-1].frame + 1))
    found = view_problem(positions, looks, camera.up)
    bad_fov = np.flatnonzero(~((fovs > 0.0) & (fovs < 180.0)))  # PCHIP keeps to the keys' range
    if len(bad_fov) and (found is None or bad_fov[0] < found[0]):
        found = int(bad_fov[0]), "fov", f"must be > 0 and < 180 degrees, got {fovs[bad_fov[0]]:g}"
    if found is not None:
        index, name, text = found
        raise table.error(
            "keyframes", f"frame {first + index}'s interpolated camera: {name} {text}"
        )
    return animation
