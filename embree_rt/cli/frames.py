"""The files of a job's frames: each frame's path from the output pattern, the directories it
names made, the frames already on disk skipped (unless ``--overwrite``), each frame written
atomically as it finishes, and an animation's ``transforms.json``.

An animated scene's output is a pattern holding ``{frame}`` with any format spec
(``shots/f_{frame:04d}.png``); a still is one frame, numbered None.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from embree_rt.aovs import nerf_transforms
from embree_rt.camera import camera_frame
from embree_rt.cli.checks import check_output, output_encoding
from embree_rt.cli.frame_paths import output_paths
from embree_rt.cli.job import Job, frames_of
from embree_rt.errors import InputError
from embree_rt.film import Encoding, save_image, write_atomically
from embree_rt.scene.animation import camera_at
from embree_rt.scene.model import Scene


class FramePlan(NamedTuple):
    """``paths``: frame (None for a still) -> file; ``cameras``: (frame, Camera) of the frames
    to render, in order; ``animated``: whether the scene is; ``encoding`` the files'."""

    paths: dict[int | None, str]
    cameras: list
    animated: bool
    encoding: Encoding

    @property
    def skipped(self) -> int:
        """Frames whose files were on disk, not rendered again."""
        return len(self.paths) - len(self.cameras)


def plan_frames(job: Job, scene: Scene) -> FramePlan:
    """The frames ``job`` asks of ``scene``, their files checked (and an animation's
    directories made) before any work. Raises InputError naming ``-o`` or ``--frames``."""
    animation = scene.animation
    frames = frames_of(job, animation)
    paths = output_paths(job.output.pattern, frames)
    encoding = output_encoding(job.output)._replace(look=scene.render.look(), legend=scene.legend)
    if frames is not None:  # the directories a pattern names (shots/f_{frame:04d}.png) are made
        for directory in sorted({Path(path).parent for path in paths.values()}):
            try:
                directory.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise InputError(
                    f"-o: {job.output.pattern}: cannot make the directory {directory}: "
                    f"{error.strerror or error}"
                ) from None
    for path in paths.values():
        check_output(path, None, encoding)
    redo = job.output.overwrite or frames is None
    cameras = [
        (f, scene.camera if f is None else camera_at(scene.camera, animation, f))
        for f, path in paths.items()
        if redo or not Path(path).exists()
    ]
    return FramePlan(paths, cameras, frames is not None, encoding)


def frame_writer(plan: FramePlan) -> Callable[[int | None, np.ndarray], None]:
    """``write(frame, image)``: the frame's (height, width, 3) float32 linear image to its
    file, atomically; an OSError there is the user's (no space, no permission)."""

    def write(frame: int | None, image: np.ndarray) -> None:
        path = plan.paths[frame]
        try:
            save_image(image, path, plan.encoding)
        except OSError as error:
            raise InputError(f"{path}: cannot write: {error.strerror or error}") from None

    return write


def write_transforms(paths: dict, scene: Scene) -> Path:
    """Write ``transforms.json`` (``aovs.nerf_transforms``) for an animation's frame files
    ``paths`` (frame -> file) into the directory that holds them all; returns its path."""
    settings = scene.render
    folder = Path(os.path.commonpath([Path(path).resolve().parent for path in paths.values()]))
    views = [
        (
            Path(path).resolve(),
            camera_frame(
                camera_at(scene.camera, scene.animation, f), settings.width, settings.height
            ),
        )
        for f, path in paths.items()
    ]
    text = (json.dumps(nerf_transforms(views, folder), indent=2) + "\n").encode()
    target = folder / "transforms.json"
    if target.is_file() and target.read_bytes() == text:
        return target  # a rerun with every frame on disk touches nothing
    try:
        write_atomically([(target, lambda handle: handle.write(text))])
    except OSError as error:
        raise InputError(f"{target}: cannot write: {error.strerror or error}") from None
    return target
