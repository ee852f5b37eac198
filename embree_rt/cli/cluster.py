"""The runner of a job rendered on Dask (``--cluster local:N`` or ``--scheduler ADDRESS``):
the frames (a still is one) as tasks over the workers, or, with ``--partition K``, by K spatial
bricks each held by one worker; each frame written as it arrives, then the summary line."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from embree_rt.budget import MemoryBudgetError
from embree_rt.cli.checks import memory_key
from embree_rt.cli.errors import UsageError, signals_held
from embree_rt.cli.frames import frame_writer, plan_frames, write_transforms
from embree_rt.cli.job import Job, OnDask
from embree_rt.cli.render import describe, say_all_on_disk
from embree_rt.cli.sources import prepare_scene
from embree_rt.cli.summary import Timeline, print_summary
from embree_rt.errors import InputError, install_hint
from embree_rt.scene.model import Scene


def run(job: Job, timeline: Timeline) -> None:
    """Render ``job`` on its cluster (``job.where`` is ``OnDask``) and write its files."""
    try:
        from embree_rt import distributed
    except ImportError as error:
        raise InputError(
            f"{job.where.flag}: needs Dask's distributed ({error}): "
            + install_hint("distributed", "distributed")
        ) from None
    made = prepare_scene(job, timeline)
    plan = plan_frames(job, made.scene)
    if not plan.cameras:
        say_all_on_disk(job, plan)
        return
    where: OnDask = job.where
    settings = made.scene.render
    write = frame_writer(plan)
    try:
        with quiet_dask(), connected(distributed, where) as client:
            renderer = tasks_or_bricks(distributed, job, made, client)
            total = settings.width * settings.height * settings.spp * len(plan.cameras)
            with released(renderer), distributed.progress_bar(total, job.quiet) as show:
                renderer.render_frames(
                    distributed.FrameRequest(settings, plan.cameras, write, progress=show)
                )
            workers = len(client.nthreads())
            timeline.mark_rendered()
    except MemoryBudgetError as error:
        raise UsageError(f"{memory_key(error, job)}: {error}") from None
    if plan.animated:
        write_transforms(plan.paths, made.scene)
    if not job.quiet:
        here = f"on {workers} Dask worker{'s' if workers != 1 else ''}"
        print_summary(
            timeline,
            what=describe(made.scene, plan, here),
            made_verb=made.verb,
            setup_name="cluster",
            render_s=renderer.stats.render_s,
            rays=renderer.stats.total_rays,
            output=job.output.pattern,
        )


@contextmanager
def connected(distributed, where: OnDask) -> Iterator[object]:
    """A client on the job's cluster, closed afterwards. Ctrl-C and SIGTERM while the cluster
    starts or closes are held until it has started or closed (and then raised: once inside the
    ``with``, which closes it; after the close, unless a signal is what is closing it): a
    cluster interrupted half-way is left to Dask's exit hook, which fails on it, and a second
    Ctrl-C cutting its close was seen to leave new worker processes starting, which the
    signal ended mid-import, each with a traceback."""
    connection = distributed.connect(where.cluster, where.scheduler, timeout_s=where.timeout_s)
    with signals_held() as held:
        try:
            client = connection.__enter__()
        except Exception:
            # SIGTERM to the process group ends the worker processes starting too, and the
            # cluster fails to start of it: what ended the command is the signal.
            held.raise_held()
            raise
    try:
        held.raise_held()
        yield client
    except BaseException as error:
        if isinstance(error, KeyboardInterrupt):
            silence_teardown()
        with signals_held() as held:
            try:
                connection.__exit__(type(error), error, error.__traceback__)
            except Exception:
                # A cluster whose workers the signal ended too (SIGTERM to the process group)
                # fails to close cleanly; what ended the command is the signal, not that.
                raise error from None
        if not isinstance(error, KeyboardInterrupt):
            held.raise_held()
        raise
    else:
        with signals_held() as held:
            connection.__exit__(None, None, None)
        held.raise_held()


def silence_teardown() -> None:
    """Dask's and asyncio's complaints about a cluster closing as a signal ends the command
    (workers gone, connections reset, futures never read) off stderr for the rest of the
    process: the command's one line says what happened."""
    for name in ("distributed", "asyncio", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


@contextmanager
def released(renderer) -> Iterator[None]:
    """Free the workers' copies of the scene afterwards; when the render ended by an
    exception (a signal, say, which may have ended the workers too), a failure to reach them
    does not replace it."""
    try:
        yield
    except BaseException as error:
        if isinstance(error, KeyboardInterrupt):
            silence_teardown()
        with suppress(Exception), signals_held():  # a second Ctrl-C: the first is ending it
            renderer.release()
        raise
    renderer.release()


def tasks_or_bricks(distributed, job: Job, made, client):
    """The job's cluster renderer: tasks over the workers, or bricks with ``--partition``;
    the workers make the scene from what ``made.for_workers`` says."""
    source = made.for_workers
    if isinstance(source, Path):  # every worker loads the file itself
        source = distributed.SceneFile(str(source.resolve()))
    elif not isinstance(source, Scene):  # a FieldPlan: every worker generates the field
        source = distributed.FieldRecipe(source)
    if job.where.partition is None:
        return distributed.ClusterRenderer(source, client, spheres=job.spheres)
    from embree_rt.bricks.cluster import PartitionedRenderer

    return PartitionedRenderer(source, client, partition=job.where.partition, spheres=job.spheres)


@contextmanager
def quiet_dask() -> Iterator[None]:
    """Dask's own log lines off the command's stderr: workers starting and stopping, and the
    errors its threads log as a signal ends the workers and the command (connections reset),
    Tornado's among them (Dask's ``sync`` cancels the call a Ctrl-C cut from a callback on its
    loop, which fails when the cut came before the call began, and Tornado logs that): a
    failure that matters reaches the command as an exception of the client's calls."""
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado.application")]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)
