"""The command's checks of what the user gave it: output paths before any work, the Embree
library, writes of the user's files, and the input to blame when memory cannot hold a render."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from embree_rt.aovs import aov_paths
from embree_rt.cli.errors import UsageError
from embree_rt.embree import EmbreeError
from embree_rt.embree.library import load_library
from embree_rt.film import Encoding, check_image_name, check_output_path
from embree_rt.scene.paths import not_a_file_problem, os_error_problem
from embree_rt.scene.writer import mesh_file, spheres_file


def output_encoding(output):
    """The ``film.Encoding`` of ``--bit-depth`` and ``--quality`` (``output``: a
    ``cli.job.Output``)."""
    return Encoding(bit_depth=output.bit_depth, quality=output.quality)


def check_output(path: str, aovs: tuple[str, ...] | None = None, encoding=None) -> None:
    """The image path's checks (``film.check_output_path``, with the ``film.Encoding``), and
    those of the AOV files beside it, as bad input: every ValueError it raises is about the
    path, its RuntimeError about OpenEXR missing for ``.exr``."""
    try:
        if "{frame" in path or "{view" in path:  # directories made once the frames are known
            check_image_name(path, encoding or Encoding())
            return
        check_output_path(path, encoding or Encoding())
        sides = []
        if aovs:
            sides = list(aov_paths(path, aovs).values())
            for side in sides:
                check_output_path(side)
        for target in (path, *sides):  # a FIFO, a device, a loop of links is not replaced
            if (problem := not_a_file_problem(target)) is not None:
                raise ValueError(f"{target}: {problem}")
    except (ValueError, RuntimeError) as error:
        raise UsageError(str(error)) from None


def check_saved_scene(target: Path, meshes: int) -> None:
    """``--save-scene``'s file, before any work, as bad input: its directory there and
    writable, and nothing but a file (a directory, a FIFO that would block the write, a loop of
    links, a name too long) where it or the files written beside it (its spheres and
    ``meshes`` meshes) go. ``target``'s suffix is checked by the caller."""
    where = f"--save-scene: {target}"
    directory = target.parent
    try:
        # os.stat, not is_dir: a loop of links or a file in the path is said as what it is
        if not stat.S_ISDIR(os.stat(directory).st_mode):
            raise UsageError(f"{where}: {directory} is not a directory")
    except FileNotFoundError:
        raise UsageError(f"{where}: directory {directory} does not exist") from None
    except OSError as error:
        raise UsageError(f"{where}: {os_error_problem(error, directory)}") from None
    if not os.access(directory, os.W_OK | os.X_OK):
        raise UsageError(f"{where}: directory {directory} is not writable")
    written = [target, spheres_file(target), *(mesh_file(target, i) for i in range(meshes))]
    for path in written:
        if (problem := not_a_file_problem(path)) is not None:
            raise UsageError(f"--save-scene: {path}: {problem}")


def check_library() -> None:
    """Load Embree before any work: a library that is missing, or that ``EMBREE_RT_LIBRARY``
    names wrongly, is the installation's problem, not a bug (later Embree errors are bugs)."""
    try:
        load_library()
    except EmbreeError as error:
        raise UsageError(str(error)) from None


def writing(path: str, write) -> None:
    """Run ``write()``, which writes the user's file ``path``: an OSError there (no space, no
    permission) is the user's to fix."""
    try:
        write()
    except OSError as error:
        raise UsageError(f"{path}: cannot write: {error.strerror or error}") from None


def memory_key(error, job) -> str:
    """The input to blame for a ``MemoryBudgetError`` of ``job`` (a ``cli.job.Job``): the
    flags or the scene file's keys."""
    scene_file = getattr(job.source, "path", None)  # a random field has none
    if error.largest == "samples":  # at least one pixel's samples in a batch
        flags = [setting.origin for setting in job.settings if setting.key == "render.spp"]
        if flags:
            return ", ".join(flags)
        return "--spp" if scene_file is None else f"{scene_file}: render.spp"
    if error.largest == "image":
        size = ("render.width", "render.height")
        flags = [setting.origin for setting in job.settings if setting.key in size]
        if flags:
            return ", ".join(flags)
        if scene_file is None:
            return "--width, --height"
        return f"{scene_file}: render.width, render.height"
    return "--count" if scene_file is None else f"{scene_file}: spheres"
