"""The frames of a particle trajectory, each an image or all one video: which frames are to be
rendered, each frame's scene read and prepared, one BVH refitted while the particles stay the
same, the reading of frame k+1 and the writing of frame k-1 overlapped with the rendering of
frame k, and contiguous runs of frames on Dask workers.

Memory stays bounded whatever the trajectory's length: at most three frames are alive at once,
one being read, one being rendered and one being written.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from embree_rt.scene.model import Scene
from embree_rt.video import DEFAULT_FPS, is_video


@dataclass
class StageSeconds:
    """The wall seconds of one stage over the frames: how many frames passed it and the sum
    over those after the first (whose time holds one-off costs: the first BVH build, numba's
    loading), kept as two numbers so that memory stays flat however many frames there are."""

    count: int = 0
    after_first_s: float = 0.0

    def add(self, seconds: float) -> None:
        if self.count:
            self.after_first_s += seconds
        self.count += 1

    def mean(self) -> float:
        """Mean seconds a frame after the first (0.0 for fewer than two frames)."""
        return self.after_first_s / (self.count - 1) if self.count > 1 else 0.0


@dataclass
class FrameStages:
    """Wall seconds of each frame's stages: ``read`` its scene, ``bvh`` (its spheres moved in
    the last frame's BVH, or a BVH built), ``render``, ``write`` (tone map, encode, file); and
    ``written``, the seconds from one frame written to the next. Overlapped (as the command
    line renders), a frame is read and written beside other frames' BVH and render, so the
    stages of a frame add up to more than the time between two frames."""

    read: StageSeconds = field(default_factory=StageSeconds)
    bvh: StageSeconds = field(default_factory=StageSeconds)
    render: StageSeconds = field(default_factory=StageSeconds)
    write: StageSeconds = field(default_factory=StageSeconds)
    written: StageSeconds = field(default_factory=StageSeconds)
    last_written_at: float | None = None

    def frame_written(self) -> None:
        """Note that a frame was written now (``time.perf_counter``)."""
        now = time.perf_counter()
        last, self.last_written_at = self.last_written_at, now
        self.written.add(0.0 if last is None else now - last)

    def steady(self) -> str | None:
        """The frames after the first as the summary line says them: the seconds between two
        frames written, and each stage's mean; None for fewer than two frames written."""
        if self.written.count < 2:
            return None
        return (
            f"{self.written.mean():.2f} s a frame after the first (a frame's BVH "
            f"{self.bvh.mean():.2f} s, render {self.render.mean():.2f} s; beside them, reading "
            f"the next {self.read.mean():.2f} s and writing the last {self.write.mean():.2f} s)"
        )


def timed(stage: StageSeconds, call: Callable, then: Callable[[], None] | None = None) -> Callable:
    """``call`` adding the wall seconds each call takes to ``stage`` (and calling ``then``
    after a call that returned)."""

    def run(*args):
        began = time.perf_counter()
        try:
            done = call(*args)
        finally:
            stage.add(time.perf_counter() - began)
        if then is not None:
            then()
        return done

    return run


@dataclass
class FrameCounts:
    """How each rendered frame got its BVH: ``refitted`` (the spheres moved in the last
    frame's BVH) or ``rebuilt`` (a BVH built for it); and the seconds its stages took
    (``stages``, on this machine; empty for frames rendered on Dask)."""

    refitted: int = 0
    rebuilt: int = 0
    stages: FrameStages = field(default_factory=FrameStages)


def same_particles(last: Scene, scene: Scene) -> bool:
    """Whether ``scene`` differs from ``last`` only in its spheres' centres (and camera), so a
    BVH of ``last``'s spheres can be refitted to it: the same count, radii, materials and
    colours, lights, floor, materials and render settings, and no other geometry."""

    def same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
        if a is None or b is None or a is b:
            return a is b
        return a.shape == b.shape and bool(np.array_equal(a, b))

    return (
        same(last.sphere_radii, scene.sphere_radii)
        and same(last.sphere_materials, scene.sphere_materials)
        and same(last.sphere_colors, scene.sphere_colors)
        and last.lights == scene.lights
        and last.floor == scene.floor
        and last.materials == scene.materials
        and last.background == scene.background
        and last.render == scene.render
        and not (scene.meshes or scene.instances or scene.curves)
        and not (last.meshes or last.instances or last.curves)
    )


@dataclass(frozen=True)
class FrameRendering:
    """How the frames are rendered: ``spheres`` and ``threads`` as ``Renderer`` takes them;
    ``refit`` moves the spheres of the last frame's BVH when the particles are the same
    (analytic spheres only); ``overlap`` reads and writes in threads beside the render."""

    spheres: str = "analytic"
    threads: int | None = None
    refit: bool = True
    overlap: bool = True


def render_frames(
    numbers: Sequence[int],
    read: Callable[[int], Scene],
    write: Callable[[int, object], None],
    how: FrameRendering = FrameRendering(),
) -> FrameCounts:
    """Render frame ``read(n)`` for each of ``numbers`` in order and hand its
    ``api.RenderResult`` to ``write(n, result)``; returns how many frames were refitted and
    rebuilt. With ``how.overlap``, frame k+1 is read and frame k-1 written (each in a thread of
    its own) while frame k renders: the images are the same as without, and at most three
    frames are alive. An error in any stage is raised here, after the other stages stop."""
    from embree_rt.api import Renderer, require_memory

    counts = FrameCounts()
    stages = counts.stages
    read = timed(stages.read, read)
    write = timed(stages.write, write, stages.frame_written)
    renderer: Renderer | None = None
    refit = how.refit and how.spheres == "analytic"

    def render(scene: Scene):
        nonlocal renderer
        began = time.perf_counter()
        if renderer is not None and refit and same_particles(renderer.scene, scene):
            renderer.update_spheres(scene.sphere_centers, scene.sphere_radii)
            counts.refitted += 1
        else:
            if renderer is not None:
                renderer.close()
                renderer = None
            require_memory(scene, scene.render, spheres=how.spheres, threads=how.threads)
            renderer = Renderer(scene, spheres=how.spheres, threads=how.threads, movable=refit)
            counts.rebuilt += 1
        built = time.perf_counter()
        stages.bvh.add(built - began)
        result = renderer.render(camera=scene.camera)
        stages.render.add(time.perf_counter() - built)
        return result

    try:
        if not how.overlap:
            for number in numbers:
                write(number, render(read(number)))
            return counts
        with (
            ThreadPoolExecutor(1, thread_name_prefix="frame-read") as reader,
            ThreadPoolExecutor(1, thread_name_prefix="frame-write") as writer,
        ):
            reading: Future | None = reader.submit(read, numbers[0]) if numbers else None
            written: Future | None = None
            try:
                for index, number in enumerate(numbers):
                    scene = reading.result()
                    following = index + 1 < len(numbers)
                    reading = reader.submit(read, numbers[index + 1]) if following else None
                    result = render(scene)
                    del scene
                    if written is not None:
                        written.result()  # frame k-1 on disk before frame k is handed over
                    written = writer.submit(write, number, result)
                    del result
                if written is not None:
                    written.result()
            finally:
                # The frame read ahead is dropped; a frame already rendered is still written
                # (the executor waits for it), as it would be without overlap.
                if reading is not None:
                    reading.cancel()
        return counts
    finally:
        if renderer is not None:
            renderer.close()


def prepared_frame(args: argparse.Namespace, number: int, staged: Scene | None) -> Scene:
    """The scene of frame ``number`` of the particle file ``args.scene`` as the flags draw it,
    with the camera, lights and floor of ``staged`` (the first frame's) unless ``--follow``,
    and ``-D`` settings applied."""
    from embree_rt.cli.particles import particle_scene
    from embree_rt.scene.settings import apply_to_scene

    frame_args = copy.copy(args)
    frame_args.frame = number
    own_view = staged is None or args.follow
    frame_args.legend = False  # (the first frame's legend is the one drawn)
    scene = particle_scene(frame_args, stage=own_view)
    if not own_view:
        scene.camera, scene.lights, scene.floor = staged.camera, staged.lights, staged.floor
    apply_to_scene(scene, list(args.settings), str(args.scene))
    return scene


def render_trajectory(args: argparse.Namespace) -> None:
    """``embree-rt render TRAJECTORY -o shots/f_{frame:04d}.png [--frames A:B[:STEP]]``: each
    frame an image, on this machine, the camera, lights and floor of the first frame unless
    ``--follow``; frames on disk skipped unless ``--overwrite``; the BVH refitted between
    frames of the same particles unless ``--no-refit``."""
    from embree_rt.cli.checks import check_library, output_encoding, writing
    from embree_rt.cli.errors import UsageError
    from embree_rt.cli.frame_paths import output_paths
    from embree_rt.cli.particles import particle_scene, trajectory_range
    from embree_rt.film import check_output_path
    from embree_rt.scene.particles import read_particles

    on_dask = args.cluster is not None or args.scheduler is not None
    if on_dask and is_video(args.output):
        raise UsageError("--cluster, --scheduler: a video is encoded on this machine: write PNGs")
    if args.aov is not None:
        raise UsageError("--aov: AOVs are written for still images, not trajectory frames")
    count = read_particles(args.scene, frame=0, topology=args.topology).frame_count
    frames = trajectory_range(args.scene, args.frames, count)
    first = copy.copy(args)
    first.frame = frames[0]
    staged = particle_scene(first)
    if staged.legend is not None and staged.legend.is_bar and args.range is None:
        # One legend for every frame: each frame coloured on the range it shows, the first's.
        args = copy.copy(args)
        args.range = list(staged.legend.value_range)
    how = FrameRendering(spheres=args.spheres, threads=args.threads, refit=not args.no_refit)
    if is_video(args.output):
        counts = render_video(args, frames, staged, how)
        todo, paths = list(frames), dict.fromkeys(frames, args.output)
    else:
        if args.fps != DEFAULT_FPS:
            raise UsageError("--fps: only for a video (-o ending in .mp4, .webm or .gif)")
        paths = output_paths(args.output, frames)
        encoding = output_encoding(args)._replace(legend=staged.legend)
        for directory in sorted({Path(path).parent for path in paths.values()}):
            try:
                directory.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise UsageError(f"-o: cannot make the directory {directory}: {error}") from None
        for path in paths.values():
            try:
                check_output_path(path, encoding)
            except (ValueError, RuntimeError) as error:
                raise UsageError(str(error)) from None
        todo = [f for f, path in paths.items() if args.overwrite or not Path(path).exists()]
        check_library()

        if on_dask:
            counts = render_on_dask(args, todo, staged, paths, encoding)
        else:

            def write(number: int, result) -> None:
                path = paths[number]
                writing(path, lambda: result.save(path, encoding))

            counts = render_frames(todo, lambda n: prepared_frame(args, n, staged), write, how)
    if not args.quiet:
        steady = counts.stages.steady()
        print(
            f"embree-rt: {len(todo)} frames ({counts.refitted} refitted, {counts.rebuilt} "
            f"rebuilt; {len(paths) - len(todo)} already on disk) of {args.scene}"
            f"{'' if steady is None else ', ' + steady} -> {args.output}",
            file=sys.stderr,
        )


def render_video(
    args: argparse.Namespace, frames: range, staged: Scene, how: FrameRendering
) -> FrameCounts:
    """The frames of ``args.scene`` as one video at ``args.output`` (``video.VideoWriter``,
    ``--fps``, ``--quality``), checked before any frame renders; an existing video is kept
    unless ``--overwrite``."""
    from embree_rt.cli.checks import check_library, writing
    from embree_rt.cli.errors import UsageError
    from embree_rt.legend import draw_legend
    from embree_rt.scene.settings import apply_to_scene
    from embree_rt.video import VideoWriter, check_video

    path = Path(args.output)
    if args.bit_depth != 8:
        raise UsageError(f"--bit-depth: {path.suffix} frames are 8 bits a channel")
    if path.exists() and not args.overwrite:
        raise UsageError(f"-o: {path} exists (--overwrite to replace it)")
    if not path.parent.is_dir():
        raise UsageError(f"-o: {path}: no directory {path.parent}")
    sized = copy.copy(staged)
    apply_to_scene(sized, list(args.settings), str(args.scene))
    try:
        check_video(path, sized.render.width, sized.render.height, args.fps, args.quality)
    except ValueError as error:
        raise UsageError(str(error)) from None
    check_library()

    legend = staged.legend  # the first frame's, whose range colours every frame

    def make() -> FrameCounts:
        with VideoWriter(path, args.fps, args.quality) as video:

            def add(number: int, result) -> None:
                pixels = result.to_srgb8()
                video.add(pixels if legend is None else draw_legend(pixels, legend))

            return render_frames(frames, lambda n: prepared_frame(args, n, staged), add, how)

    counts = FrameCounts()

    def run() -> None:
        nonlocal counts
        counts = make()

    writing(str(path), run)
    return counts


def render_on_dask(
    args: argparse.Namespace, numbers: list[int], staged: Scene, paths: dict, encoding
) -> FrameCounts:
    """Frames ``numbers`` on the cluster of ``--cluster``/``--scheduler``: one contiguous run
    of frames a worker (``render_run``), so each keeps its BVH, refitted, from frame to frame,
    the particle file read and the images written by the worker (the paths resolved here: a
    ``--scheduler``'s workers must see this machine's files). The images are those of a run on
    this machine: a frame's image depends on its scene alone."""
    from embree_rt.cli.cluster import connected, quiet_dask
    from embree_rt.cli.job import where_of

    where = where_of(args)
    view = Scene(camera=staged.camera, lights=staged.lights, floor=staged.floor)
    on_worker = copy.copy(args)
    on_worker.scene = str(Path(args.scene).resolve())
    if args.topology is not None:
        on_worker.topology = str(Path(args.topology).resolve())
    files = {n: str(Path(paths[n]).resolve()) for n in numbers}
    counts = FrameCounts()
    if not numbers:
        return counts
    from embree_rt import distributed

    with quiet_dask(), connected(distributed, where) as client:
        workers = max(1, len(client.nthreads()))
        runs = [list(run) for run in np.array_split(numbers, workers) if len(run)]
        futures = [
            client.submit(
                render_run,
                on_worker,
                [int(n) for n in run],
                view,
                {int(n): files[int(n)] for n in run},
                encoding,
                pure=False,
            )
            for run in runs
        ]
        for done in client.gather(futures):
            counts.refitted += done.refitted
            counts.rebuilt += done.rebuilt
    return counts


def render_run(
    args: argparse.Namespace, numbers: list[int], view: Scene, files: dict[int, str], encoding
) -> FrameCounts:
    """On a Dask worker: frames ``numbers`` of ``args.scene`` (read here), seen as ``view``'s
    camera, lights and floor (unless ``--follow``), each written to ``files[n]``; one BVH
    refitted along the run unless ``--no-refit``; the worker's own threads."""
    from embree_rt.cli.checks import writing

    try:
        import distributed

        threads = max(1, int(getattr(distributed.get_worker().state, "nthreads", 1)))
    except (ImportError, ValueError, AttributeError):
        threads = 1

    def write(number: int, result) -> None:
        path = files[number]
        writing(path, lambda: result.save(path, encoding))

    how = FrameRendering(spheres=args.spheres, threads=threads, refit=not args.no_refit)
    return render_frames(numbers, lambda n: prepared_frame(args, n, view), write, how)
