"""The command's renders of animations and renders on clusters: output patterns, frame ranges,
frames already on disk, and the local or Dask backend that renders the frames.

An animated scene's output is a pattern holding ``{frame}`` with any format spec
(``shots/f_{frame:04d}.png``); each frame is written atomically as it finishes, and a rerun
skips the frames whose files exist unless ``--overwrite``. Frames are independent jobs: locally
one ``Renderer`` (one BVH) renders them one after another, on a cluster they share the workers.
"""

from __future__ import annotations

import argparse
import string
import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from embree_rt.errors import InputError, install_hint
from embree_rt.scene.animation import camera_at
from embree_rt.scene.model import Scene


def output_paths(pattern: str, frames: range | None) -> dict[int | None, str]:
    """The file of each frame: ``pattern.format(frame=f)`` for an animation (``frames``), the
    pattern itself for a still (``frames`` None). Raises InputError naming ``-o``."""
    try:
        fields = {name for _, name, _, _ in string.Formatter().parse(pattern) if name is not None}
    except ValueError as error:
        raise InputError(f"-o: {pattern}: not a valid pattern: {error}") from None
    if frames is None:
        if fields:
            raise InputError(
                f"-o: {pattern}: a pattern with {{frame}} needs a scene with an [animation]"
            )
        return {None: pattern}
    if fields != {"frame"}:
        raise InputError(
            f"-o: {pattern}: the scene is animated: name the file with {{frame}} and nothing "
            "else in braces (e.g. shots/f_{frame:04d}.png), or every frame would overwrite one file"
        )
    try:
        paths = {f: pattern.format(frame=f) for f in frames}
    except (ValueError, TypeError) as error:
        raise InputError(f"-o: {pattern}: cannot format a frame number: {error}") from None
    if len(set(paths.values())) < len(paths):
        raise InputError(f"-o: {pattern}: gives two frames the same file name")
    return paths


def frame_range(text: str | None, count: int) -> range:
    """Frames ``A:B`` (``A`` to ``B - 1``, as a Python slice; either end may be left out) or
    ``A`` (one frame) of an animation of ``count`` frames. Raises InputError naming --frames."""
    if text is None:
        return range(count)
    first, colon, last = text.partition(":")
    try:
        start = int(first) if first.strip() else 0
        stop = (int(last) if last.strip() else count) if colon else start + 1
    except ValueError:
        raise InputError(f"--frames: expected A:B (frame numbers), got {text!r}") from None
    if not 0 <= start < stop <= count:
        raise InputError(
            f"--frames: {text!r} is not a non-empty range within the animation's frames 0:{count}"
        )
    return range(start, stop)


def render_frames_command(
    scene: Scene, args: argparse.Namespace, made: tuple[str, float], source
) -> None:
    """``embree-rt render|random`` for an animated scene or on a cluster (``--cluster``,
    ``--scheduler``): render the frames and write each to its file. ``source`` is what workers
    make the scene from: the scene file's path, the random field's ``FieldPlan``, or the
    ``Scene`` itself (scattered to them); ``made``
    as in the command's summary line."""
    from embree_rt.cli.checks import output_encoding
    from embree_rt.film import check_output_path, save_image

    animation = scene.animation
    if args.threads is not None and (args.cluster or args.scheduler):
        raise InputError("--threads: sets local threads; a Dask worker has its own (--nthreads)")
    if animation is None and args.frames is not None:
        raise InputError("--frames: the scene has no [animation]")
    if args.aov is not None:
        raise InputError(
            "--aov: AOVs are written for still images rendered on this machine; not with "
            "[animation] frames, --cluster or --scheduler"
        )
    frames = frame_range(args.frames, animation.frames) if animation is not None else None
    paths = output_paths(args.output, frames)
    encoding = output_encoding(args)._replace(look=scene.render.look())
    if frames is not None:  # the directories a pattern names (shots/f_{frame:04d}.png) are made
        for directory in sorted({Path(path).parent for path in paths.values()}):
            try:
                directory.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise InputError(
                    f"-o: {args.output}: cannot make the directory {directory}: "
                    f"{error.strerror or error}"
                ) from None
    for path in paths.values():
        try:
            check_output_path(path, encoding)
        except (ValueError, RuntimeError) as error:
            raise InputError(str(error)) from None
    redo = args.overwrite or frames is None
    todo = [f for f, path in paths.items() if redo or not Path(path).exists()]
    cameras = [
        (f, scene.camera if f is None else camera_at(scene.camera, animation, f)) for f in todo
    ]
    settings = scene.render

    def write(frame: int | None, image: np.ndarray) -> None:
        path = paths[frame]
        try:
            save_image(image, path, encoding)
        except OSError as error:
            raise InputError(f"{path}: cannot write: {error.strerror or error}") from None

    if not cameras:  # nothing to do: nothing is written, transforms.json included
        if not args.quiet:
            print(
                f"embree-rt: all {len(paths)} frames are on disk (--overwrite renders them "
                f"again) -> {args.output}",
                file=sys.stderr,
            )
        return
    started = time.perf_counter()
    if args.cluster is None and args.scheduler is None:
        rays, render_s, where = _render_locally(scene, args, settings, cameras, write)
    else:
        rays, render_s, where = _render_on_cluster(scene, args, settings, cameras, write, source)
    elapsed = time.perf_counter() - started
    if frames is not None:
        write_transforms(paths, scene, settings)
    if not args.quiet:
        skipped = len(paths) - len(todo)
        setup = "BVH" if where == "locally" else "cluster"
        what = "" if frames is None else f"{len(todo)} frames ({skipped} already on disk) of "
        print(
            f"embree-rt: {what}{settings.width}x{settings.height} at {settings.spp} spp {where} "
            f"in {made[1] + elapsed:.2f} s ({made[0]} {made[1]:.2f} s, {setup} "
            f"{elapsed - render_s:.2f} s, render {render_s:.2f} s): {rays:,} rays, "
            f"{rays / max(render_s, 1e-9) / 1e6:.1f} Mrays/s -> {args.output}",
            file=sys.stderr,
        )


def write_transforms(paths: dict, scene: Scene, settings) -> Path:
    """Write ``transforms.json`` (``aovs.nerf_transforms``) for an animation's frame files
    ``paths`` (frame -> file) into the directory that holds them all; returns its path."""
    import json
    import os

    from embree_rt.aovs import nerf_transforms
    from embree_rt.camera import camera_frame
    from embree_rt.film import write_atomically

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


def _render_locally(scene, args, settings, cameras, write: Callable) -> tuple[int, float, str]:
    """Render the frames one after another on one ``Renderer``: the rays traced, the seconds
    spent rendering (the rest was building the BVH), and where."""
    from embree_rt.api import Renderer, require_memory

    require_memory(scene, settings, spheres=args.spheres, threads=args.threads)
    render_s = 0.0
    rays = 0
    with Renderer(scene, spheres=args.spheres, threads=args.threads) as renderer:
        for frame, camera in cameras:
            result = renderer.render(camera=camera)
            render_s += result.stats.render_s
            rays += result.stats.total_rays
            write(frame, result.image)
    return rays, render_s, "locally"


def _render_on_cluster(
    scene, args, settings, cameras, write: Callable, source
) -> tuple[int, float, str]:
    """Render the frames on ``--cluster``/``--scheduler``: the rays traced, the seconds from the
    first batch sent to the last frame written (the workers build their BVH in it; the rest was
    starting or reaching the cluster), and where."""
    try:
        from embree_rt import distributed
    except ImportError as error:
        flag = "--cluster" if args.cluster is not None else "--scheduler"
        raise InputError(
            f"{flag}: needs Dask's distributed ({error}): "
            + install_hint("distributed", "distributed")
        ) from None
    timeout_s = args.scheduler_timeout
    connection = distributed.connect(args.cluster, args.scheduler, timeout_s=timeout_s)
    with _quiet_dask(), connection as client:
        if isinstance(source, Path):  # every worker loads the file itself
            source = distributed.SceneFile(str(source.resolve()))
        elif not isinstance(source, Scene):  # a FieldPlan: every worker generates the field
            source = distributed.FieldRecipe(source)
        if args.partition is None:
            renderer = distributed.ClusterRenderer(source, client, spheres=args.spheres)
        else:  # data-parallel: each worker holds bricks of the scene
            from embree_rt.bricks.cluster import PartitionedRenderer

            renderer = PartitionedRenderer(
                source, client, partition=args.partition, spheres=args.spheres
            )
        total = settings.width * settings.height * settings.spp * len(cameras)
        try:
            with distributed.progress_bar(total, args.quiet) as show:
                renderer.render_frames(settings, cameras, write, progress=show)
        finally:
            renderer.release()
        workers = len(client.nthreads())
    where = f"on {workers} Dask worker{'s' if workers != 1 else ''}"
    return renderer.stats.total_rays, renderer.stats.render_s, where


@contextmanager
def _quiet_dask():
    """Dask's own log lines (workers starting and stopping) off the command's stderr."""
    import logging

    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)
