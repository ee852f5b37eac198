"""The ``[animation]`` table of a scene file, read and checked (see ``scene.animation``)."""

from __future__ import annotations

from dataclasses import replace

from embree_rt.camera import Camera, camera_problem
from embree_rt.scene.animation import Animation, Keyframe, frame_cameras
from embree_rt.scene.fields import Table


def read_animation(table: Table, camera: Camera) -> Animation:
    """The ``[animation]`` table, checked: every frame's camera must define an image (the rule
    of ``camera.camera_problem``). Raises ``SceneError`` naming the key."""
    table.require("frames")
    frames = table.integer("frames", low=1)
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
    # The spline may pass through a camera no keyframe has (look_at meeting position).
    for number, between in enumerate(frame_cameras(camera, animation)):
        if (problem := camera_problem(between)) is not None:
            name, text = problem
            raise table.error("keyframes", f"frame {number}'s interpolated camera: {name} {text}")
    return animation
