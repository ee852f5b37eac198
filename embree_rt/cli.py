"""The ``embree-rt`` command: render a scene file, render a random field, describe a scene."""

from __future__ import annotations

import argparse
import sys
import time
import traceback
from pathlib import Path

import numpy as np

from embree_rt.errors import InputError

EXIT_BUG = 1
# geometry.SPHERE_MODES, spelled out so that --help does not load Embree and numba.
SPHERE_CHOICES = ("analytic", "point", "mesh")
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
BUG_REPORT = (
    "embree-rt: internal error: this is a bug in embree_rt, not a problem with your input; "
    "please report it with the traceback above"
)


class UsageError(InputError):
    """Bad input found by the command itself; printed as one line, exit code 2."""


def _check_output(path: str, aovs: tuple[str, ...] | None = None) -> None:
    """The image path's checks (``film.check_output_path``), and those of the AOV files beside
    it, as bad input: every ValueError it raises is about the path, its RuntimeError about
    OpenEXR missing for ``.exr``."""
    from embree_rt.film import check_output_path

    try:
        check_output_path(path)
        if aovs:
            from embree_rt.aovs import aov_paths

            for side in aov_paths(path, aovs).values():
                check_output_path(side)
    except (ValueError, RuntimeError) as error:
        raise UsageError(str(error)) from None


def _check_library() -> None:
    """Load Embree before any work: a library that is missing, or that ``EMBREE_RT_LIBRARY``
    names wrongly, is the installation's problem, not a bug (later Embree errors are bugs)."""
    from embree_rt.embree import EmbreeError
    from embree_rt.embree.library import load_library

    try:
        load_library()
    except EmbreeError as error:
        raise UsageError(str(error)) from None


def _writing(path: str, write) -> None:
    """Run ``write()``, which writes the user's file ``path``: an OSError there (no space, no
    permission) is the user's to fix."""
    try:
        write()
    except OSError as error:
        raise UsageError(f"{path}: cannot write: {error.strerror or error}") from None


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        message = message.removeprefix("argument ")
        print(f"embree-rt: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


def _int_at_least(low: int):
    # argparse prefixes the message with the flag ("argument --width: ..."), so it is not repeated.
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {value}")
        return value

    return parse


def _positive_int():
    return _int_at_least(1)


def _non_negative_int():
    return _int_at_least(0)


def _aov_list(text: str) -> tuple[str, ...]:
    from embree_rt.aovs import parse_aov_list

    try:
        return parse_aov_list(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _add_render_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "-o", "--output", required=True, help="image to write: .png, .npy, .npz or .exr"
    )
    parser.add_argument(
        "--aov",
        type=_aov_list,
        metavar="NAMES",
        help="also write AOVs, any of depth,normal,albedo,object_id,material_id: in the .npz or "
        ".exr, or one file each beside a .png or .npy",
    )
    parser.add_argument("--width", type=_positive_int())
    parser.add_argument("--height", type=_positive_int())
    parser.add_argument("--spp", type=_positive_int(), help="samples per pixel")
    parser.add_argument("--max-depth", type=_non_negative_int())
    parser.add_argument("--seed", type=_non_negative_int())
    parser.add_argument("--threads", type=_positive_int(), help="default: all cores")
    parser.add_argument(
        "--spheres",
        choices=SPHERE_CHOICES,
        default="analytic",
        help="analytic spheres (compiled user geometry), Embree's own point spheres, or "
        "tessellated icospheres",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    cluster = parser.add_mutually_exclusive_group()  # embree_rt/distributed.py
    cluster.add_argument("--cluster", metavar="local:N", help="render on N local Dask workers")
    cluster.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="render on a Dask cluster")
    parser.add_argument("--frames", metavar="A:B", help="an animation's frames A to B-1 only")
    parser.add_argument("--overwrite", action="store_true", help="render frames already on disk")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="embree-rt",
        description="Whitted-style ray tracing of scenes with very many objects, on Embree.",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    render = commands.add_parser("render", help="render a scene file (TOML or JSON)")
    render.add_argument("scene", help="scene file")
    _add_render_flags(render)
    random = commands.add_parser("random", help="render a random sphere field of N spheres")
    random.add_argument("--count", type=_positive_int(), required=True)
    random.add_argument("--save-scene", help="also write the generated scene to this file")
    random.add_argument(
        "--instance", metavar="MESHFILE",
        help="replace every small sphere by this mesh (fitted into the sphere, resting on the "
        "floor, turned at random about y), all through one Embree instance array",
    )  # fmt: skip
    _add_render_flags(random)
    info = commands.add_parser("info", help="describe a scene: objects, bounds, build time")
    info.add_argument("scene", help="scene file")
    info.add_argument("--spheres", choices=SPHERE_CHOICES, default="analytic")
    serve = commands.add_parser("serve", help="the 2D ray demo and a live preview in a browser")
    serve.add_argument("scene", nargs="?", help="scene file (default: the showcase)")
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on")
    serve.add_argument("--port", type=_non_negative_int(), default=8000, help="0: any free port")
    return parser


def _apply_overrides(scene, args: argparse.Namespace) -> None:
    settings = scene.render
    for name in ("width", "height", "spp", "max_depth", "seed"):
        value = getattr(args, name)
        if value is not None:
            setattr(settings, name, value)


def _render_and_save(
    scene, args: argparse.Namespace, made: tuple[str, float], source: object = None
) -> None:
    """Render ``scene`` with the flags' overrides and save it; ``made`` is how the scene was
    made and the seconds it took ("generate" or "load"), for the summary line; ``source`` the
    scene file or field plan a cluster's workers make the scene from."""
    from embree_rt.budget import MemoryBudgetError
    from embree_rt.film import save_image
    from embree_rt.integrator import RenderStats, render

    _apply_overrides(scene, args)
    _check_library()
    framed = args.frames or "{frame" in args.output  # an animation's pattern, or a mistake
    if scene.animation is not None or args.cluster or args.scheduler or framed:
        from embree_rt.frames import render_command

        try:
            render_command(scene, args, made, source)
        except MemoryBudgetError as error:
            raise UsageError(f"{_memory_key(error, args)}: {error}") from None
        return
    settings = scene.render
    stats = RenderStats()
    started = time.perf_counter()
    try:
        image = render(
            scene,
            threads=args.threads,
            spheres=args.spheres,
            quiet=args.quiet,
            stats=stats,
            aovs=args.aov,
        )
    except MemoryBudgetError as error:
        raise UsageError(f"{_memory_key(error, args)}: {error}") from None
    _check_output(args.output, args.aov)  # again: the directory may have gone meanwhile
    if args.aov is None:
        _writing(args.output, lambda: save_image(image, args.output))
    else:
        from embree_rt.aovs import save_with_aovs

        beauty, layers = image
        written: list[Path] = []
        _writing(args.output, lambda: written.extend(save_with_aovs(beauty, layers, args.output)))
        for side in written:  # the AOV files beside the image, for scripts to pick up
            print(side)
    elapsed = made[1] + time.perf_counter() - started
    if not args.quiet:
        print(
            f"embree-rt: {settings.width}x{settings.height} at {settings.spp} spp in "
            f"{elapsed:.2f} s ({made[0]} {made[1]:.2f} s, BVH {stats.build_s:.2f} s, render "
            f"{stats.render_s:.2f} s): {stats.total_rays:,} rays, "
            f"{stats.rays_per_s / 1e6:.1f} Mrays/s -> {args.output}",
            file=sys.stderr,
        )


def _command_render(args: argparse.Namespace) -> None:
    from embree_rt.scene import load_scene

    _check_output(args.output, args.aov)
    started = time.perf_counter()
    scene = load_scene(args.scene)
    _render_and_save(scene, args, ("load", time.perf_counter() - started), Path(args.scene))


def _memory_key(error, args: argparse.Namespace) -> str:
    """The input to blame for a ``MemoryBudgetError``: the flags or the scene file's keys."""
    scene_file = getattr(args, "scene", None)
    if error.largest == "image":
        if scene_file is None or args.width is not None or args.height is not None:
            return "--width, --height"
        return f"{scene_file}: render.width, render.height"
    return "--count" if scene_file is None else f"{scene_file}: spheres"


def _require_memory_for_field(count: int, settings, args: argparse.Namespace) -> None:
    """Refuse, before a sphere is made, a field whose render cannot fit: the field's arrays,
    its BVH and the image (``render`` checks the last two again once the field exists)."""
    import os

    from embree_rt import budget
    from embree_rt.geometry import sphere_kind
    from embree_rt.integrator import DEFAULT_BATCH_SIZE

    # --instance: the small spheres become an instance array, as --spheres mesh makes them
    spheres = "mesh" if getattr(args, "instance", None) else args.spheres
    needs = budget.render_needs(
        count, sphere_kind(count, spheres), settings.width, settings.height, settings.spp,
        DEFAULT_BATCH_SIZE, workers=args.threads or os.cpu_count() or 1,
    )  # fmt: skip
    bvh_bytes, _ = needs["spheres"]
    needs["spheres"] = (budget.field_bytes(count) + bvh_bytes, f"{count:,} spheres")
    try:
        budget.require(needs)
    except budget.MemoryBudgetError as error:
        raise UsageError(f"{_memory_key(error, args)}: {error}") from None


def _command_random(args: argparse.Namespace) -> None:
    from embree_rt.scene.random_field import (
        FieldParameterError,
        add_field_spheres,
        field_scene,
        plan_field,
    )

    _check_output(args.output, args.aov)
    if args.save_scene is not None:
        target = Path(args.save_scene)
        if target.suffix.lower() not in (".toml", ".json"):
            raise UsageError(f"--save-scene: {target}: expected a .toml or .json file name")
        if not target.parent.is_dir():
            raise UsageError(f"--save-scene: {target}: directory {target.parent} does not exist")
    started = time.perf_counter()
    try:
        plan = plan_field(args.count, seed=0 if args.seed is None else args.seed)
    except FieldParameterError as error:  # the flags' values, refused by the field itself
        raise UsageError(f"--{error.name}: {error.problem}") from None
    scene = field_scene(plan)
    _apply_overrides(scene, args)
    mesh = None if args.instance is None else _instance_mesh(args.instance)
    _require_memory_for_field(plan.count, scene.render, args)
    # A cluster's workers generate a plain field themselves, from its plan; a field of
    # instances, or one to be saved, is made here.
    on_workers = bool(args.cluster or args.scheduler) and args.save_scene is None and mesh is None
    if not on_workers:
        add_field_spheres(scene, plan)
    if mesh is not None:
        from embree_rt.scene.instances import spheres_to_instances

        spheres_to_instances(scene, mesh, keep=plan.heroes, seed=plan.seed)
    generate_s = time.perf_counter() - started
    if args.save_scene is not None:
        _writing(args.save_scene, lambda: scene.save(args.save_scene))
    _render_and_save(scene, args, ("generate", generate_s), None if mesh is not None else plan)


def _instance_mesh(path: str):
    """The mesh file of ``--instance`` as one Trimesh (a multi-node file baked into one)."""
    from embree_rt.scene import SceneError
    from embree_rt.scene.instances import mesh_from_parts
    from embree_rt.scene.meshes import load_mesh_parts
    from embree_rt.transforms import affine_problem

    try:
        parts = load_mesh_parts(Path(path), "--instance", "mesh")
    except SceneError as error:
        raise UsageError(f"--instance: {error.problem}") from None
    for _, node_transform in parts:
        if (problem := affine_problem(node_transform)) is not None:
            raise UsageError(f"--instance: {path}: a node {problem}")
    mesh = mesh_from_parts(parts)
    if not np.ptp(np.asarray(mesh.vertices), axis=0).max() > 0:
        raise UsageError(f"--instance: {path}: all its vertices are one point")
    return mesh


def _command_info(args: argparse.Namespace) -> None:
    from embree_rt.geometry import SceneGeometry
    from embree_rt.scene import load_scene

    scene = load_scene(args.scene)
    _check_library()
    resident_before = _resident_bytes()
    started = time.perf_counter()
    with SceneGeometry(scene, spheres=args.spheres) as geometry:
        build_s = time.perf_counter() - started
        resident_growth = _resident_bytes() - resident_before
        floor_material = geometry.floor_material
        triangles = geometry.triangle_count
        instances = geometry.instance_count
        in_arrays = geometry.bvh.instance_count
        arrays = geometry.bvh.array_count
    objects = [*scene.meshes, *scene.instances]
    distinct = {id(o.mesh): o.mesh for o in objects}.values()
    unique_triangles = sum(len(mesh.faces) for mesh in distinct)
    placements = len(scene.meshes) + sum(len(entry) for entry in scene.instances)
    spheres = len(scene.sphere_radii)
    bounds = _bounds(scene)
    # Embree's own footprint is not exposed; estimate from the primitive buffers and BVH nodes
    # (an instance array: 48 bytes of transform and ~80 of Embree's, measured at 1e6).
    estimate = (spheres * (16 + 64) + unique_triangles * (12 + 12 + 64)
                + (instances - in_arrays) * 256 + in_arrays * 128)  # fmt: skip
    print(f"scene:      {args.scene}")
    print(f"spheres:    {spheres:,}")
    print(f"meshes:     {placements:,} placements of {len(distinct):,} distinct meshes")
    print(f"triangles:  {unique_triangles:,} stored, {triangles:,} placed")
    print(f"instances:  {instances:,}")
    print(f"arrays:     {arrays:,} instance arrays holding {in_arrays:,} instances")
    print(f"lights:     {len(scene.lights)}")
    print(f"materials:  {len(scene.materials)}")
    floor = f"y = {scene.floor.height:g}" if scene.floor else "none"
    print(f"floor:      {floor}")
    if bounds is None:
        print("bounds:     empty")
    else:
        low, high = bounds
        print(f"bounds:     {np.round(low, 3).tolist()} .. {np.round(high, 3).tolist()}")
    print(f"BVH build:  {build_s:.3f} s")
    print(f"memory:     ~{estimate / 2**20:.1f} MiB (estimate), "
          f"{resident_growth / 2**20:.1f} MiB measured (resident set growth while building)")
    from embree_rt.aovs import id_listing

    for line in id_listing(scene, floor_material):
        print(line)


def _resident_bytes() -> int:
    """This process's resident set in bytes (Linux), or 0 where /proc is missing."""
    import resource

    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * resource.getpagesize()
    except OSError:
        return 0


def _bounds(scene) -> tuple[np.ndarray, np.ndarray] | None:
    lows, highs = [], []
    if len(scene.sphere_radii):
        radius = scene.sphere_radii[:, None]
        lows.append((scene.sphere_centers - radius).min(axis=0))
        highs.append((scene.sphere_centers + radius).max(axis=0))
    for placement in scene.meshes:
        corners = placement.mesh.bounds
        box = np.array(
            [[x, y, z, 1.0] for x in corners[:, 0] for y in corners[:, 1] for z in corners[:, 2]]
        )
        world = box @ placement.transform.T
        lows.append(world[:, :3].min(axis=0))
        highs.append(world[:, :3].max(axis=0))
    for entry in scene.instances:
        corners = entry.mesh.bounds
        box = np.array([[x, y, z] for x in corners[:, 0] for y in corners[:, 1]
                        for z in corners[:, 2]])  # fmt: skip
        world = np.einsum("nij,kj->nki", entry.transforms[:, :3, :3], box)
        world += entry.transforms[:, None, :3, 3]
        lows.append(world.min(axis=(0, 1)))
        highs.append(world.max(axis=(0, 1)))
    if not lows:
        return None
    return np.min(lows, axis=0), np.max(highs, axis=0)


def _command_serve(args: argparse.Namespace) -> None:
    import importlib.util

    if any(importlib.util.find_spec(name) is None for name in ("starlette", "uvicorn",
                                                               "websockets")):  # fmt: skip
        raise UsageError("serve needs the web extra: pip install 'embree-rt[web]'")
    _check_library()
    from embree_rt.web.serve import serve

    serve(args.scene, args.host, args.port)


COMMANDS = {
    "render": _command_render,
    "random": _command_random,
    "info": _command_info,
    "serve": _command_serve,
}


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    try:
        COMMANDS[args.command](args)
    except KeyboardInterrupt:
        print("embree-rt: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except InputError as error:  # scene files, flags, the user's files: one line
        print(f"embree-rt: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception:  # anything else is ours to fix: say so, with what a report needs
        traceback.print_exc()
        print(BUG_REPORT, file=sys.stderr)
        return EXIT_BUG
    return 0


if __name__ == "__main__":
    sys.exit(main())
