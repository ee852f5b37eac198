"""The runner of a job rendered on this machine: a still (with its AOVs) or an animation's
frames, all views of one BVH, each file written as it finishes, then the summary line."""

from __future__ import annotations

import sys
from pathlib import Path

from embree_rt.api import Renderer, RenderResult, render, require_memory
from embree_rt.budget import MemoryBudgetError
from embree_rt.cli.checks import check_output, memory_key, output_encoding, writing
from embree_rt.cli.errors import UsageError
from embree_rt.cli.frames import FramePlan, frame_writer, plan_frames, write_transforms
from embree_rt.cli.job import Job
from embree_rt.cli.sources import prepare_scene
from embree_rt.cli.summary import Timeline, print_summary


def run(job: Job, timeline: Timeline) -> None:
    """Render ``job`` here (``job.where`` is ``OnThisMachine``) and write its files."""
    made = prepare_scene(job, timeline)
    plan = plan_frames(job, made.scene)
    result = None
    try:
        if plan.animated:
            if not plan.cameras:
                say_all_on_disk(job, plan)
                return
            rays, render_s = render_frames(job, made.scene, plan)
        else:
            result = render_still(job, made.scene)
            rays, render_s = result.stats.total_rays, result.stats.render_s
    except MemoryBudgetError as error:
        raise UsageError(f"{memory_key(error, job)}: {error}") from None
    timeline.mark_rendered()
    if plan.animated:
        write_transforms(plan.paths, made.scene)
    else:
        write_still(job, made.scene, result)
    if not job.quiet:
        print_summary(
            timeline,
            what=describe(made.scene, plan, "locally" if plan.animated else ""),
            made_verb=made.verb,
            setup_name="BVH",
            render_s=render_s,
            rays=rays,
            output=job.output.pattern,
        )


def render_still(job: Job, scene) -> RenderResult:
    """Render the still (with its AOVs); the summary line's output phase is its writing."""
    return render(
        scene,
        threads=job.where.threads,
        spheres=job.spheres,
        quiet=job.quiet,
        aovs=job.output.aovs or (),
    )


def write_still(job: Job, scene, result: RenderResult) -> None:
    """Write the still and its AOVs (their paths printed, for scripts to pick up)."""
    encoding = output_encoding(job.output)._replace(legend=scene.legend)
    path = job.output.pattern
    check_output(path, job.output.aovs, encoding)  # again: the directory may have gone meanwhile
    written: list[Path] = []
    writing(path, lambda: written.extend(result.save(path, encoding)))
    for side in written:
        print(side)


def render_frames(job: Job, scene, plan: FramePlan) -> tuple[int, float]:
    """Render the plan's frames one after another on one ``Renderer``, each written as it
    finishes: the rays traced and the seconds spent rendering."""
    threads = job.where.threads
    require_memory(scene, scene.render, spheres=job.spheres, threads=threads)
    write = frame_writer(plan)
    render_s = 0.0
    rays = 0
    with Renderer(scene, spheres=job.spheres, threads=threads) as renderer:
        for frame, camera in plan.cameras:
            result = renderer.render(camera=camera)
            render_s += result.stats.render_s
            rays += result.stats.total_rays
            write(frame, result.image)
    return rays, render_s


def describe(scene, plan: FramePlan, where: str) -> str:
    """What was rendered, for the summary line: "[N frames (K already on disk) of ]WxH at S
    spp[ where]"."""
    settings = scene.render
    what = f"{settings.width}x{settings.height} at {settings.spp} spp"
    if plan.animated:
        what = f"{len(plan.cameras)} frames ({plan.skipped} already on disk) of {what}"
    return f"{what} {where}" if where else what


def say_all_on_disk(job: Job, plan: FramePlan) -> None:
    """Nothing to render: nothing is written, transforms.json included."""
    if not job.quiet:
        print(
            f"embree-rt: all {len(plan.paths)} frames are on disk (--overwrite renders them "
            f"again) -> {job.output.pattern}",
            file=sys.stderr,
        )
