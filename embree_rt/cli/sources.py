"""A job's scene made from its source: a scene file read, a mesh file shown on its own, a random
field generated, with the command's settings applied; and what a cluster's workers make the
same scene from."""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from embree_rt import budget
from embree_rt.cli.checks import check_library, memory_key, writing
from embree_rt.cli.errors import UsageError
from embree_rt.cli.job import (
    Job,
    MeshFile,
    ParticleFile,
    RandomField,
    SceneFile,
    refuse_for_scene,
)
from embree_rt.integrator import DEFAULT_BATCH_SIZE
from embree_rt.scene.errors import SceneError, warn_input
from embree_rt.scene.instances import mesh_from_parts, spheres_to_instances
from embree_rt.scene.model import Scene
from embree_rt.scene.random_field import (
    FieldParameterError,
    add_field_spheres,
    field_scene,
    plan_field,
)
from embree_rt.scene.settings import Setting, apply_to_scene, load_scene_with
from embree_rt.scene.writer import save_scene
from embree_rt.transforms import affine_problem


class MadeScene(NamedTuple):
    """The job's ``scene``; how it was made (``"load"`` or ``"generate"``) and the seconds it
    took, for the summary line; and ``for_workers``, what a cluster's workers make it from:
    the scene file's ``Path`` when they can load it as it is, the random field's ``FieldPlan``
    when they can generate it, else the ``Scene`` itself (scattered to them)."""

    scene: Scene
    verb: str
    seconds: float
    for_workers: object


def prepare_scene(job: Job, timeline) -> MadeScene:
    """The job's scene made (the ``summary.Timeline`` marking when), a scene without lights
    warned of, and the Embree library loaded before any work: one that is missing, or that
    ``EMBREE_RT_LIBRARY`` names wrongly, is the installation's problem."""
    timeline.mark_scene_started()
    made = staged(make_scene(job), job)
    refuse_for_scene(job, made.scene)
    timeline.mark_scene_made()
    if not made.scene.lights:
        warn_input(f"{job.scene_name}: lights: none: only the sky and ambient light show it")
    check_library()
    return made


def make_scene(job: Job) -> MadeScene:
    """The scene ``job.source`` names, the job's settings and ``--no-floor`` applied."""
    started = time.perf_counter()
    source = job.source
    settings = list(job.settings)
    if isinstance(source, MeshFile):
        scene = Scene.from_file(source.path, floor=not job.no_floor)
        apply_to_scene(scene, settings, str(source.path))
        return MadeScene(scene, "load", time.perf_counter() - started, scene)
    if isinstance(source, SceneFile):
        if job.no_floor:
            settings.append(Setting("floor", False, "--no-floor"))
        scene = load_scene_with(source.path, settings)
        workers_load = only_render_settings(settings)
        for_workers = source.path if workers_load else scene
        return MadeScene(scene, "load", time.perf_counter() - started, for_workers)
    if isinstance(source, RandomField):
        return generate_field(job, source, started)
    if isinstance(source, ParticleFile):
        from embree_rt.cli.particles import frame_clear_of_legend, particle_scene

        scene = particle_scene(source.flags)
        apply_to_scene(scene, settings, str(source.path))
        frame_clear_of_legend(scene, scene.legend, settings)
        return MadeScene(scene, "load", time.perf_counter() - started, scene)
    raise TypeError(f"no scene is made from a {type(source).__name__}")


def staged(made: MadeScene, job: Job) -> MadeScene:
    """``made`` with its scene changed as ``job.staging`` says: the camera turned to the
    standard view of the scene's bounds (``scene.views.standard_view``), then a headlight, a
    white point light of intensity 1 at the camera (lights have no fall-off, so it lights what
    faces the camera evenly). A restaged scene is given to a cluster's workers as it is."""
    staging = job.staging
    if not staging.restages:
        return made
    scene = made.scene
    if scene.animation is not None:
        flag = f"--view {staging.view}" if staging.view is not None else "--headlight"
        raise SceneError(
            job.scene_name,
            "animation",
            f"{flag}: the animation moves the camera; place a light or a camera in the scene",
        )
    if staging.view is not None:
        from embree_rt.scene.views import scene_bounds, standard_view

        bounds = scene_bounds(scene)
        if bounds is None:
            raise SceneError(
                job.scene_name, "(file)", f"--view {staging.view}: the scene has nothing to frame"
            )
        aspect = scene.render.width / scene.render.height
        kept = 0.0
        if scene.legend is not None:  # the legend's corner kept clear
            from embree_rt.legend import legend_room

            kept = legend_room(scene.legend, scene.render.height)
        scene.camera = standard_view(
            scene.camera, *bounds, staging.view, aspect, staging.orthographic, kept
        )
        if not staging.orthographic:  # a perspective view moved clear of the legend's corner
            from embree_rt.scene.views import clear_of_legend

            scene.camera = clear_of_legend(scene, scene.legend)
    if staging.headlight:
        from embree_rt.scene.model import PointLight

        scene.lights.append(PointLight(position=tuple(scene.camera.position)))
    return made._replace(for_workers=scene)


def only_render_settings(settings) -> bool:
    """Whether ``settings`` change the render settings alone (which travel with the frames to
    a cluster's workers), so workers can make the scene themselves."""
    return all(setting.key.startswith("render.") for setting in settings)


def generate_field(job: Job, field: RandomField, started: float) -> MadeScene:
    """The random field of ``field``, refused before a sphere is made when it cannot fit."""
    made_from = "the random field"
    # The field's seed is the render's (--seed, --set render.seed), checked as the scene's is.
    seeds = [setting for setting in job.settings if setting.key == "render.seed"]
    probe = Scene()
    apply_to_scene(probe, seeds, made_from)
    try:
        plan = plan_field(field.count, seed=probe.render.seed)
    except FieldParameterError as error:  # the flags' values, refused by the field itself
        raise UsageError(f"--{error.name}: {error.problem}") from None
    scene = field_scene(plan)
    apply_to_scene(scene, list(job.settings), made_from)
    if job.no_floor:
        scene.floor = None
    mesh = None if field.instance is None else instance_mesh(field.instance)
    # A cluster's workers generate a plain field themselves, from its plan; a field of
    # instances, one to be saved, or one changed beyond its render settings (or staged) is
    # made here.
    from_plan = (
        mesh is None
        and not job.no_floor
        and only_render_settings(job.settings)
        and not job.staging.restages
    )
    on_workers = job.on_dask and field.save_scene is None and from_plan
    if not (on_workers and job.where.partition):  # in bricks, each worker checks its own
        require_memory_for_field(plan.count, scene.render, job, instanced=mesh is not None)
    if not on_workers:
        add_field_spheres(scene, plan)
    if mesh is not None:
        spheres_to_instances(scene, mesh, keep=plan.heroes, seed=plan.seed)
    seconds = time.perf_counter() - started
    if field.save_scene is not None:
        writing(field.save_scene, lambda: save_scene(scene, field.save_scene))
    return MadeScene(scene, "generate", seconds, plan if from_plan else scene)


def require_memory_for_field(count: int, settings, job: Job, *, instanced: bool) -> None:
    """Refuse, before a sphere is made, a field whose render cannot fit: the field's arrays,
    its BVH and the image (``render`` checks the last two again once the field exists)."""
    # --instance: the small spheres become an instance array, as --spheres mesh makes them
    spheres = "mesh" if instanced else job.spheres
    threads = getattr(job.where, "threads", None)
    needs = budget.render_needs(
        count, spheres, settings, batch_size=DEFAULT_BATCH_SIZE, threads=threads
    )
    bvh_bytes, _ = needs["spheres"]
    needs["spheres"] = (budget.field_bytes(count) + bvh_bytes, f"{count:,} spheres")
    try:
        budget.require(needs)
    except budget.MemoryBudgetError as error:
        raise UsageError(f"{memory_key(error, job)}: {error}") from None


def instance_mesh(path: str):
    """The mesh file of ``--instance`` as one Trimesh (a multi-node file baked into one)."""
    from embree_rt.scene.meshes import load_mesh_parts  # trimesh: ~1 s to import

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
