"""What a command line asks for, decided once: where the scene comes from, where it renders
(this machine, a Dask cluster's tasks, bricks held by Dask workers), what is written (a still
or an animation's frames), and which combinations of flags are refused.

``job_from_args`` turns the parsed flags into a ``Job`` and refuses, before any work, what no
scene could make sense of; ``frames_of`` decides, once the scene is read, whether it is a
still or frames. The runners (``cli.render``, ``cli.cluster``) do what the job says and decide
nothing of it again.

A new kind of input (a particle file, say) is a new ``Source`` kind here, chosen in
``source_of``, and its reading in ``cli.sources.make_scene``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from embree_rt.cli.checks import check_output, check_saved_scene, output_encoding
from embree_rt.cli.errors import UsageError
from embree_rt.cli.frame_paths import frame_range
from embree_rt.cli.particles import refuse_particle_flags
from embree_rt.scene.errors import SceneError
from embree_rt.scene.mesh_formats import MESH_SUFFIXES

SCENE_SUFFIXES = (".toml", ".json")
AOVS_ONLY_STILLS_HERE = (
    "--aov: AOVs are written for still images rendered on this machine; not with [animation] "
    "frames, --cluster or --scheduler"
)


class SceneFile(NamedTuple):
    """A scene file (.toml or .json)."""

    path: Path


class MeshFile(NamedTuple):
    """A mesh file rendered on its own, from its own camera and lights or framed by default."""

    path: Path


class RandomField(NamedTuple):
    """``embree-rt random``: a field of ``count`` spheres, their small ones replaced by the mesh
    file ``instance`` when given, the generated scene also written to ``save_scene``."""

    count: int
    instance: str | None
    save_scene: str | None


class ParticleFile(NamedTuple):
    """A simulation's particle file (XYZ, LAMMPS, PDB, GRO, GSD, ...), drawn as the particle
    flags in ``flags`` say (``cli.particles``)."""

    path: Path
    flags: argparse.Namespace


Source = SceneFile | MeshFile | RandomField | ParticleFile


class OnThisMachine(NamedTuple):
    """Rendered here, on ``threads`` worker threads (None: all cores)."""

    threads: int | None


class OnDask(NamedTuple):
    """Rendered on ``--cluster local:N`` or the ``--scheduler`` at an address (one of them set),
    as tasks, or, with ``partition`` K, by K spatial bricks each held by one worker."""

    cluster: str | None
    scheduler: str | None
    timeout_s: float
    partition: int | None

    @property
    def flag(self) -> str:
        """The flag that named the cluster, for messages."""
        return "--cluster" if self.cluster is not None else "--scheduler"


Where = OnThisMachine | OnDask


class Staging(NamedTuple):
    """What the command changes of the scene once it is made (``cli.sources``): its camera
    turned to the standard ``view`` of its bounds (``scene.views``; None: its own camera),
    ``orthographic`` unless ``--perspective`` came last of the projection flags, and a white
    ``headlight`` at the camera. A still's camera only: an animation's moves."""

    view: str | None = None
    orthographic: bool = True
    headlight: bool = False

    @property
    def restages(self) -> bool:
        """Whether the scene is changed after it is made: then a cluster's workers are given
        the scene itself, not its file or recipe."""
        return self.view is not None or self.headlight


class Output(NamedTuple):
    """What is written: ``pattern`` (a file, or an animation's ``{frame}`` pattern), the AOVs
    beside it, the bits and quality of its encoding, the frames asked for (``--frames``) and
    whether frames on disk are rendered again."""

    pattern: str
    aovs: tuple[str, ...] | None
    bit_depth: int
    quality: int | None
    frames: str | None
    overwrite: bool

    @property
    def framed(self) -> bool:
        """Whether the flags alone ask for frames (a ``{frame}`` pattern or ``--frames``)."""
        return self.frames is not None or "{frame" in self.pattern


@dataclass(frozen=True)
class Job:
    """One command line's request: ``source`` made into a scene with ``settings`` (and without
    its floor if ``no_floor``), rendered ``where``, written as ``output`` (None: ``info``,
    which writes nothing); ``spheres`` how
    spheres enter the BVH; ``quiet`` no progress bar or summary; ``staging`` what the command
    changes of the made scene; ``scene_name`` what messages call the scene ("the random field"
    for one)."""

    source: Source
    settings: tuple
    no_floor: bool
    where: Where
    output: Output | None
    spheres: str
    quiet: bool
    staging: Staging

    @property
    def scene_name(self) -> str:
        if isinstance(self.source, RandomField):
            return "the random field"
        return str(self.source.path)

    @property
    def on_dask(self) -> bool:
        return isinstance(self.where, OnDask)

    @property
    def reads_trajectory(self) -> bool:
        """Whether a particle file's frames are each an image (``cli.particles``)."""
        from embree_rt.video import is_video

        return (
            isinstance(self.source, ParticleFile)
            and self.output is not None
            and (self.output.framed or is_video(self.output.pattern))
        )


def source_of(args: argparse.Namespace) -> Source:
    """The scene the flags name: the ``random`` field, or a scene, mesh or particle file by its
    extension (an extension that is none of theirs is refused naming the lists); particle
    flags given for another kind of file are refused."""
    if args.command == "random":
        return RandomField(args.count, args.instance, args.save_scene)
    path = Path(args.scene)
    suffix = path.suffix.lower()
    if suffix in SCENE_SUFFIXES:
        refuse_particle_flags(args)
        return SceneFile(path)
    from embree_rt.scene.particles.read import PARTICLE_SUFFIXES, is_particle_file

    if suffix in MESH_SUFFIXES:
        refuse_particle_flags(args)
        return MeshFile(path)
    if is_particle_file(path):
        return ParticleFile(path, args)
    raise SceneError(
        path,
        "(file)",
        f"expected a scene file ({', '.join(SCENE_SUFFIXES)}), "
        f"a mesh file ({', '.join(MESH_SUFFIXES)}) or "
        f"a particle file ({', '.join(PARTICLE_SUFFIXES)})",
    )


def where_of(args: argparse.Namespace) -> Where:
    """Where the flags ask the render to happen; refuses what only one place takes."""
    if args.cluster is None and args.scheduler is None:
        if args.partition is not None:
            raise UsageError(
                "--partition: bricks are held by Dask workers: add --cluster local:N or "
                "--scheduler ADDRESS"
            )
        return OnThisMachine(args.threads)
    if args.threads is not None:
        raise UsageError("--threads: sets local threads; a Dask worker has its own (--nthreads)")
    if args.aov is not None:
        raise UsageError(AOVS_ONLY_STILLS_HERE)
    return OnDask(args.cluster, args.scheduler, args.scheduler_timeout, args.partition)


def staging_of(args: argparse.Namespace) -> Staging:
    """``--view``, the projection flags (the last one given wins) and ``--headlight``."""
    projections = [s.value for s in args.settings if s.key == "camera.projection"]
    return Staging(
        view=getattr(args, "view", None),
        orthographic=not projections or projections[-1] == "orthographic",
        headlight=bool(getattr(args, "headlight", False)),
    )


def refuse_for_scene(job: Job, scene) -> None:
    """Refuse what the made ``scene`` makes of the job impossible: a background other than the
    sky beyond a still rendered here (its alpha pass is ``api.Renderer``'s), and ambient
    occlusion over bricks (their workers answer no occlusion rays)."""
    background = scene.render.background
    if job.output is not None and background != "sky":
        if job.on_dask or job.output.framed or scene.animation is not None:
            raise UsageError(
                f"--background {background}: for a still rendered here; animations and "
                "cluster renders show the sky"
            )
        encoding = output_encoding(job.output)._replace(background=background)
        check_output(job.output.pattern, job.output.aovs, encoding)
    if scene.render.ao.samples and job.on_dask and job.where.partition is not None:
        raise UsageError(
            "--ao: ambient occlusion is rendered on one BVH, not over bricks (--partition)"
        )


def job_from_args(args: argparse.Namespace) -> Job:
    """The ``Job`` of ``render`` or ``random``'s flags, with everything checked that needs no
    scene: the combinations of flags, the output path (before any work), ``--save-scene``."""
    source = source_of(args)
    where = where_of(args)
    output = Output(
        args.output, args.aov, args.bit_depth, args.quality, args.frames, args.overwrite
    )
    if output.aovs is not None and output.framed:
        raise UsageError(AOVS_ONLY_STILLS_HERE)
    from embree_rt.video import is_video

    if not (isinstance(source, ParticleFile) and is_video(output.pattern)):  # cli.trajectory's
        check_output(output.pattern, output.aovs, output_encoding(output))
    if isinstance(source, RandomField) and source.save_scene is not None:
        target = Path(source.save_scene)
        if target.suffix.lower() not in SCENE_SUFFIXES:
            raise UsageError(f"--save-scene: {target}: expected a .toml or .json file name")
        check_saved_scene(target, meshes=0 if source.instance is None else 1)
    return Job(
        source=source,
        settings=tuple(args.settings),
        no_floor=args.no_floor,
        where=where,
        output=output,
        spheres=args.spheres,
        quiet=args.quiet,
        staging=staging_of(args),
    )


def info_job(args: argparse.Namespace) -> Job:
    """The ``Job`` of ``info``'s flags: a scene made as a render's would be, written nowhere."""
    return Job(
        source=source_of(args),
        settings=tuple(args.settings),
        no_floor=args.no_floor,
        where=OnThisMachine(None),
        output=None,
        spheres=args.spheres,
        quiet=True,
        staging=staging_of(args),
    )


def frames_of(job: Job, animation) -> range | None:
    """The frames to render of a scene whose ``[animation]`` is ``animation`` (None: a still),
    as ``--frames`` asks; None for a still. Refuses frames of a still."""
    if animation is None:
        if job.output.frames is not None:
            raise UsageError("--frames: the scene has no [animation]")
        return None
    if job.output.aovs is not None:
        raise UsageError(AOVS_ONLY_STILLS_HERE)
    return frame_range(job.output.frames, animation.frames)
