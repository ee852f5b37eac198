"""``embree-rt render`` and ``embree-rt random``: make the scene, render it, write the image
(and its AOVs), and say what it took. Animations and clusters go on to ``cli.animate``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from embree_rt.cli.checks import (
    check_library,
    check_output,
    memory_key,
    output_encoding,
    writing,
)
from embree_rt.cli.errors import UsageError


def command_render(args: argparse.Namespace) -> None:
    from embree_rt.cli.scene_input import read_scene

    check_output(args.output, args.aov, output_encoding(args))
    started = time.perf_counter()
    scene, source = read_scene(args)
    render_and_save(scene, args, ("load", time.perf_counter() - started), source)


def command_random(args: argparse.Namespace) -> None:
    from embree_rt.scene.random_field import (
        FieldParameterError,
        add_field_spheres,
        field_scene,
        plan_field,
    )
    from embree_rt.scene.writer import save_scene

    check_output(args.output, args.aov, output_encoding(args))
    if args.save_scene is not None:
        target = Path(args.save_scene)
        if target.suffix.lower() not in (".toml", ".json"):
            raise UsageError(f"--save-scene: {target}: expected a .toml or .json file name")
        if not target.parent.is_dir():
            raise UsageError(f"--save-scene: {target}: directory {target.parent} does not exist")
    from embree_rt.cli.scene_input import only_render_settings, restaged, staged
    from embree_rt.scene.model import Scene
    from embree_rt.scene.settings import apply_to_scene

    started = time.perf_counter()
    made_from = "the random field"
    # The field's seed is the render's (--seed, --set render.seed), checked as the scene's is.
    seeds = [setting for setting in args.settings if setting.key == "render.seed"]
    probe = Scene()
    apply_to_scene(probe, seeds, made_from)
    try:
        plan = plan_field(args.count, seed=probe.render.seed)
    except FieldParameterError as error:  # the flags' values, refused by the field itself
        raise UsageError(f"--{error.name}: {error.problem}") from None
    scene = field_scene(plan)
    apply_to_scene(scene, args.settings, made_from)
    mesh = None if args.instance is None else instance_mesh(args.instance)
    # A cluster's workers generate a plain field themselves, from its plan; a field of
    # instances, one to be saved, or one changed beyond its render settings is made here.
    from_plan = mesh is None and only_render_settings(args.settings) and not restaged(args)
    on_workers = bool(args.cluster or args.scheduler) and args.save_scene is None and from_plan
    if not (on_workers and args.partition):  # in bricks, each worker checks its own
        require_memory_for_field(plan.count, scene.render, args)
    if not on_workers:
        add_field_spheres(scene, plan)
    if mesh is not None:
        from embree_rt.scene.instances import spheres_to_instances

        spheres_to_instances(scene, mesh, keep=plan.heroes, seed=plan.seed)
    scene = staged(scene, args)
    generate_s = time.perf_counter() - started
    if args.save_scene is not None:
        writing(args.save_scene, lambda: save_scene(scene, args.save_scene))
    render_and_save(scene, args, ("generate", generate_s), plan if from_plan else scene)


def render_and_save(
    scene, args: argparse.Namespace, made: tuple[str, float], source: object = None
) -> None:
    """Render ``scene`` (the settings already applied) and save it; ``made`` is how the scene was
    made and the seconds it took ("generate" or "load"), for the summary line; ``source`` the
    scene file or field plan a cluster's workers make the scene from."""
    from embree_rt.api import render
    from embree_rt.budget import MemoryBudgetError

    if args.partition is not None and not (args.cluster or args.scheduler):
        raise UsageError(
            "--partition: bricks are held by Dask workers: add --cluster local:N or "
            "--scheduler ADDRESS"
        )
    if not scene.lights:
        from embree_rt.scene.errors import warn_input

        warn_input(
            f"{args.scene if getattr(args, 'scene', None) else 'the scene'}: lights: "
            "none: only the sky and ambient light show it"
        )
    check_library()
    framed = args.frames or "{frame" in args.output  # an animation's pattern, or a mistake
    animated = scene.animation is not None or args.cluster or args.scheduler or framed
    background = scene.render.background
    if background != "sky":
        if animated:  # their frames are written by the cluster's and animation's own savers
            raise UsageError(
                f"--background {background}: for a still rendered here; animations and "
                "cluster renders show the sky"
            )
        check_output(args.output, args.aov, output_encoding(args)._replace(background=background))
    if animated:
        from embree_rt.cli.animate import render_frames_command

        try:
            render_frames_command(scene, args, made, source)
        except MemoryBudgetError as error:
            raise UsageError(f"{memory_key(error, args)}: {error}") from None
        return
    settings = scene.render
    started = time.perf_counter()
    try:
        result = render(
            scene,
            threads=args.threads,
            spheres=args.spheres,
            quiet=args.quiet,
            aovs=args.aov or (),
        )
    except MemoryBudgetError as error:
        raise UsageError(f"{memory_key(error, args)}: {error}") from None
    encoding = output_encoding(args)
    check_output(args.output, args.aov, encoding)  # again: the directory may have gone meanwhile
    written: list[Path] = []
    writing(args.output, lambda: written.extend(result.save(args.output, encoding)))
    for side in written:  # the AOV files beside the image, for scripts to pick up
        print(side)
    stats = result.stats
    elapsed = made[1] + time.perf_counter() - started
    if not args.quiet:
        print(
            f"embree-rt: {settings.width}x{settings.height} at {settings.spp} spp in "
            f"{elapsed:.2f} s ({made[0]} {made[1]:.2f} s, BVH {stats.build_s:.2f} s, render "
            f"{stats.render_s:.2f} s): {stats.total_rays:,} rays, "
            f"{stats.rays_per_s / 1e6:.1f} Mrays/s -> {args.output}",
            file=sys.stderr,
        )


def require_memory_for_field(count: int, settings, args: argparse.Namespace) -> None:
    """Refuse, before a sphere is made, a field whose render cannot fit: the field's arrays,
    its BVH and the image (``render`` checks the last two again once the field exists)."""
    from embree_rt import budget
    from embree_rt.integrator import DEFAULT_BATCH_SIZE

    # --instance: the small spheres become an instance array, as --spheres mesh makes them
    spheres = "mesh" if getattr(args, "instance", None) else args.spheres
    needs = budget.render_needs(
        count, spheres, settings, batch_size=DEFAULT_BATCH_SIZE, threads=args.threads
    )
    bvh_bytes, _ = needs["spheres"]
    needs["spheres"] = (budget.field_bytes(count) + bvh_bytes, f"{count:,} spheres")
    try:
        budget.require(needs)
    except budget.MemoryBudgetError as error:
        raise UsageError(f"{memory_key(error, args)}: {error}") from None


def instance_mesh(path: str):
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
