"""Particle files on the command line: the flags that say how particles are drawn, the scene
``render`` and ``info`` make of a particle file, and ``info``'s summary of one."""

from __future__ import annotations

import argparse
import json
import math

from embree_rt.particle_extras import (
    EXTRA_OPTIONS,
    ParticleExtras,
    extras_problem,
    is_switch,
)


def color_triple(text: str) -> tuple[float, float, float]:
    """``R,G,B`` in 0..1 (sRGB)."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(0.0 <= v <= 1.0 for v in values):
        raise argparse.ArgumentTypeError(f"expected R,G,B with each in 0..1, got {text!r}")
    return values  # type: ignore[return-value]


def material_of(text: str) -> tuple[str, str]:
    """``TYPE=MATERIAL``: a type (or element) and a material's name."""
    label, sep, material = text.partition("=")
    if not sep or not label.strip() or not material.strip():
        raise argparse.ArgumentTypeError(f"expected TYPE=MATERIAL, got {text!r}")
    return label.strip(), material.strip()


def flag_name(option: str) -> str:
    """The command-line flag of a scene file's ``[[particles]]`` key: ``--bond-radius``."""
    return "--" + option.replace("_", "-")


def add_particle_flags(parser: argparse.ArgumentParser) -> None:
    """The flags of a particle file (ignored for scene and mesh files)."""
    group = parser.add_argument_group("particle files (XYZ, LAMMPS, PDB, GRO, GSD, ...)")
    group.add_argument("--topology", metavar="FILE", help="topology of a DCD/XTC/TRR trajectory")
    group.add_argument("--frame", type=int, default=0, metavar="N", help="which frame (from 0)")
    group.add_argument("--up", choices=("x", "y", "z"), default="z", help="the file's up axis")
    group.add_argument(
        "--select", metavar="EXPR", help="keep a subset (MDAnalysis selection: 'type 1 2')"
    )
    group.add_argument("--wrap", action="store_true", help="put positions into the periodic box")
    group.add_argument(
        "--color-by",
        metavar="WHAT",
        help="element, type, or a property (default: element, else type)",
    )
    group.add_argument("--colormap", default="viridis", help="matplotlib colormap for a property")
    group.add_argument(
        "--range", nargs=2, type=float, metavar=("MIN", "MAX"), help="property range of --colormap"
    )
    group.add_argument(
        "--color", type=color_triple, metavar="R,G,B", help="one sRGB colour for all"
    )
    group.add_argument("--radius", type=float, metavar="R", help="one radius for all particles")
    group.add_argument("--radius-scale", type=float, default=1.0, metavar="S", help="radii times S")
    group.add_argument(
        "--color-columns",
        nargs="+",
        metavar="COLUMN",
        help="R G B columns (or one (n, 3) array, e.g. extended XYZ's color), 0..1 or 0..255",
    )
    group.add_argument(
        "--material-of",
        action="append",
        type=material_of,
        metavar="TYPE=MATERIAL",
        help="a material for one type (repeatable; default: matte)",
    )
    for option in EXTRA_OPTIONS:
        flag = flag_name(option.name)
        if is_switch(option):
            group.add_argument(flag, action="store_true", help=option.metadata["help"])
        else:
            help, metavar = option.metadata["help"], option.metadata["metavar"]
            group.add_argument(flag, type=float, metavar=metavar, help=help)
    group.add_argument(
        "--follow",
        action="store_true",
        help="with --frames: frame each frame on its own bounds (default: the first frame's)",
    )
    group.add_argument(
        "--no-refit",
        action="store_true",
        help="a trajectory's frames: build each frame's BVH anew (default: refit while the "
        "particles stay the same)",
    )
    group.add_argument(
        "--fps",
        type=float,
        default=24.0,
        metavar="N",
        help="frames per second of a trajectory's video (-o ending in .mp4, .webm or .gif)",
    )


# The particle flags and their defaults: given for another kind of file, they are refused.
PARTICLE_FLAG_DEFAULTS = {
    "topology": None,
    "frame": 0,
    "up": "z",
    "select": None,
    "wrap": False,
    "color_by": None,
    "colormap": "viridis",
    "range": None,
    "color": None,
    "radius": None,
    "radius_scale": 1.0,
    "json": False,
    "follow": False,
    "color_columns": None,
    "material_of": None,
    "no_refit": False,
    "fps": 24.0,
    **{option.name: option.default for option in EXTRA_OPTIONS},
}


def refuse_particle_flags(args: argparse.Namespace) -> None:
    """Refuse a particle flag given for a scene or mesh file (it would change nothing)."""
    from embree_rt.cli.errors import UsageError

    for name, default in PARTICLE_FLAG_DEFAULTS.items():
        if getattr(args, name, default) != default:
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{flag}: only for particle files, and {args.scene} is not one")


def particle_scene(args: argparse.Namespace, stage: bool = True):
    """The ``Scene`` of the particle file ``args.scene`` drawn as the flags say (framed unless
    ``stage`` is False: ``Scene.from_particles``)."""
    from embree_rt.errors import InputError
    from embree_rt.scene.model import Scene
    from embree_rt.scene.particles.look import ParticleLook
    from embree_rt.scene.particles.to_scene import extras_arguments

    sizes = (("--radius", args.radius), ("--radius-scale", args.radius_scale))
    for flag, value in sizes:
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"{flag}: expected a positive number, got {value:g}")
    extras = ParticleExtras(**{option.name: getattr(args, option.name) for option in EXTRA_OPTIONS})
    if (problem := extras_problem(extras, flag_name)) is not None:
        option, text = problem
        raise InputError(f"{flag_name(option)}: {text}")
    look = ParticleLook(
        color_by=args.color_by,
        color=args.color,
        colormap=args.colormap,
        value_range=tuple(args.range) if args.range else None,
        radius=args.radius,
        radius_scale=args.radius_scale,
        color_columns=tuple(args.color_columns) if args.color_columns else None,
    )
    try:
        return Scene.from_particles(
            args.scene,
            frame=args.frame,
            topology=args.topology,
            look=look,
            up=args.up,
            select=args.select,
            wrap=args.wrap,
            floor=not args.no_floor,
            materials=dict(args.material_of or ()),
            **extras_arguments(extras),
            stage=stage,
        )
    except ValueError as error:
        if isinstance(error, InputError):
            raise
        raise InputError(f"{args.scene}: {error}") from None


def frame_clear_of_legend(scene, legend, settings) -> None:
    """A particle file's framed ``scene`` (its settings applied) with its camera moved so the
    corner ``legend`` takes stays clear (``scene.views.clear_of_legend``); left as it is
    without a legend, or where ``settings`` (``scene.settings.Setting``) place the camera."""
    if legend is None or any(setting.key.split(".")[0] == "camera" for setting in settings):
        return
    from embree_rt.scene.views import clear_of_legend

    scene.camera = clear_of_legend(scene, legend)


def trajectory_range(path: str, text: str | None, count: int) -> range:
    """Frames ``A:B[:STEP]`` (B excluded; either end may be left out) or ``A`` of a file of
    ``count`` frames; ``ParticleFileError`` naming the file for a range past its end."""
    from embree_rt.cli.errors import UsageError
    from embree_rt.scene.particles import ParticleFileError

    if text is None:
        return range(count)
    parts = text.split(":")
    try:
        numbers = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise UsageError(f"--frames: expected A:B[:STEP] (frame numbers), got {text!r}") from None
    if len(numbers) > 3 or (len(numbers) == 3 and (numbers[2] or 1) < 1):
        raise UsageError(f"--frames: expected A:B[:STEP] with STEP >= 1, got {text!r}")
    start = numbers[0] or 0
    stop = (numbers[1] if numbers[1] is not None else count) if len(numbers) > 1 else start + 1
    step = (numbers[2] or 1) if len(numbers) == 3 else 1
    if not 0 <= start < stop <= count:
        raise ParticleFileError(
            path, "--frames", f"{text!r} is not a non-empty range within its frames 0:{count}"
        )
    return range(start, stop, step)


def particle_summary(frame) -> dict:
    """What ``info`` says of a ``ParticleFrame``: count, kinds with their counts, bounds,
    frames, box."""
    kind, labelled = frame.label_codes()
    names, counts = labelled.names, labelled.counts()
    summary = {
        "file": frame.path,
        "particles": len(frame),
        "frames": frame.frame_count,
        "frame": frame.frame,
        "labelled_by": kind,
        kind + "s": {str(n): int(c) for n, c in zip(names, counts, strict=True)},
        "bounds": [frame.positions.min(axis=0).tolist(), frame.positions.max(axis=0).tolist()],
        "box": None if frame.box is None else frame.box.tolist(),
        "box_origin": None if frame.box is None else frame.origin.tolist(),
        "radii": None
        if frame.radii is None
        else [float(frame.radii.min()), float(frame.radii.max())],
        "properties": sorted(frame.properties),
    }
    if kind == "element" and frame.type_labels is not None:
        names, counts = frame.type_labels.names, frame.type_labels.counts()
        summary["types"] = {str(n): int(c) for n, c in zip(names, counts, strict=True)}
    return summary


def command_particle_info(args: argparse.Namespace) -> None:
    """``embree-rt info FILE [--json]`` of a particle file."""
    from embree_rt.scene.particles import read_particles

    frame = read_particles(args.scene, frame=args.frame, topology=args.topology)
    summary = particle_summary(frame)
    if args.json:
        print(json.dumps(summary))
        return
    for key, value in summary.items():
        print(f"{key + ':':<12}{value}")
