"""Data-parallel rendering on Dask: each worker holds some bricks of the scene, the client shades.

The client runs the integrator (camera, shading, film: the very code of a local render) with a
``BrickSet`` as its tracer. Per depth of each batch's wavefront it sends every ray only to the
bricks whose box the ray can reach, each brick answering on the worker that holds it; the
nearest hit over bricks wins (``nearest``: ties go to the lower global object id), a shadow
segment is blocked if any brick blocks it. The image is bitwise the local render's.

Where the bricks are: brick b is assigned to one worker (round robin over the workers, by
address) and made there as a Dask actor (``BrickActor``, created with a worker restriction to
it), whose methods the client calls on that worker directly: one round trip a query, not a
task's trip through the scheduler. The actor makes its brick from the scene's source: a random
field's recipe (the worker generates only that brick's spheres: ``contents.field_brick``), a
scene file's path, or a ``Scene`` scattered once to every worker. A partition whose bricks
cannot fit in their workers' memory limits is refused before anything is built
(``require_bricks_fit``). When a worker is lost, each brick it held is made again on the live
worker holding the fewest, and the calls it had not answered are made there: no pixel changes.
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import threading
import time
from collections.abc import Sequence
from concurrent.futures import CancelledError
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import distributed
import numpy as np

from embree_rt import budget
from embree_rt.api import RenderResult
from embree_rt.bricks.brick import Brick, BrickHits, brick_sphere_mode
from embree_rt.bricks.brick_set import BrickSet, IntersectRequest, OccludedRequest
from embree_rt.bricks.contents import field_brick, scene_brick
from embree_rt.bricks.partition import (
    Partition,
    field_brick_counts,
    field_partition,
    object_centers,
    split_points,
)
from embree_rt.camera import Camera, camera_frame
from embree_rt.distributed import (
    NO_WORKERS_TIMEOUT_S,
    POLL_S,
    ClusterError,
    FieldRecipe,
    FrameRenderer,
    FrameRequest,
    SceneFile,
    SceneSource,
    WorkerSceneError,
)
from embree_rt.errors import InputError
from embree_rt.integrator import Integrator, RenderStats
from embree_rt.scene.model import Scene, SettingOverrides
from embree_rt.sphere_modes import sphere_kind

if TYPE_CHECKING:
    from typing_extensions import Unpack

# Batches of camera samples the client traces at once. Each depth of a batch costs two round
# trips to the bricks (rays, then every light's shadow segments) whatever its size, and each
# call a fixed ~1-2 ms of CPU on both sides, so batches are large and only a few are in flight:
# a 1e7 field at 960x540 took 2.2 CPU-s in batches of 2^16, 1.3 in batches of 2^17 (2 workers,
# 4 client threads, this loaded machine).
DATA_PARALLEL_BATCH_SIZE = 1 << 17
# Batches the client keeps in flight (its shading threads); each waits on the workers most of
# the time, so more than the client's cores.
DEFAULT_CLIENT_THREADS = 4


@dataclass(frozen=True)
class BrickPlan:
    """What any worker needs to make a brick of one scene: the ``partition``, the ``spheres``
    mode the bricks build with (``brick_sphere_mode``) and ``counts`` (K,) the objects expected
    in each brick (exact for a scene, estimated for a random field: ``field_brick_counts``), for
    the memory budget."""

    partition: Partition
    spheres: str
    counts: tuple[int, ...]


def brick_needs(plan: BrickPlan, index: int, source_kind: str) -> dict[str, tuple[int, str]]:
    """What building brick ``index`` needs on its worker (``budget.require``'s form): its
    spheres' arrays and BVH, and a random field's generation rings or the whole scene loaded
    while the brick is cut from it (``source_kind`` "field" or "scene"; then the whole scene's
    count is the sum of ``plan.counts``; "held", a scattered ``Scene``, counts as "scene")."""
    count = plan.counts[index]
    geometry = budget.geometry_bytes(count, sphere_kind(count, plan.spheres))
    if source_kind == "field":
        made = budget.field_bytes(count)
        text = f"brick {index} of {count:,} spheres (generated from the field's recipe)"
    else:
        total = sum(plan.counts)
        made = (total + count) * budget.SCENE_BYTES_PER_SPHERE
        text = f"brick {index} of {count:,} objects (cut from the scene's {total:,})"
    return {f"brick {index}": (made + geometry, text)}


def require_bricks_fit(
    plan: BrickPlan, source_kind: str, assignment: dict[int, str], limits: dict[str, int]
) -> None:
    """Raise ``InputError`` (naming --partition) when the bricks assigned to some worker need
    more than its memory limit (``limits``: bytes by address, 0 or missing: no limit), saying
    what they would need and what would fit."""
    load: dict[str, int] = {}
    for index, worker in assignment.items():
        ((need, _),) = brick_needs(plan, index, source_kind).values()
        load[worker] = load.get(worker, 0) + need
    total = sum(load.values())
    for worker, need in sorted(load.items()):
        limit = limits.get(worker) or 0
        if limit <= 0 or need <= limit:
            continue
        bricks = sorted(index for index, held in assignment.items() if held == worker)
        workers = len(limits)
        raise InputError(
            f"--partition {plan.partition.bricks}: worker {worker} would hold brick"
            f"{'s' if len(bricks) > 1 else ''} {', '.join(map(str, bricks))}, needing "
            f"~{budget.format_bytes(need)} of memory against its limit of "
            f"{budget.format_bytes(limit)}; all {plan.partition.bricks} bricks need "
            f"~{budget.format_bytes(total)}, so {workers} worker{'s' if workers > 1 else ''} "
            f"would need limits of ~{budget.format_bytes(total / workers)} at least (with as "
            f"many bricks as workers or a multiple), or ~{math.ceil(total / limit)} workers "
            f"of this limit"
        )


# -- on the workers --------------------------------------------------------------------------


class BrickActor:
    """One brick on the worker holding it, a Dask actor: the client calls its methods on that
    worker directly, one round trip, not through the scheduler (a task's two hops and its
    bookkeeping took twice as long). Made from ``source`` on creation; a brick that cannot fit
    in the worker's memory is refused (``WorkerSceneError``) before it is made."""

    def __init__(self, source: SceneSource | Scene, plan: BrickPlan, index: int) -> None:
        kind = "field" if isinstance(source, FieldRecipe) else "scene"
        try:
            budget.require(brick_needs(plan, index, kind))
            contents = _brick_contents(source, plan.partition, index)
        except InputError as error:
            raise WorkerSceneError(f"worker cannot make brick {index}: {error}") from None
        self.brick = Brick(contents, plan.spheres)

    def bounds(self) -> np.ndarray:
        """(2, 3) float64 the brick's box."""
        return self.brick.bounds

    def intersect(self, origins: np.ndarray, directions: np.ndarray, coherent: bool) -> BrickHits:
        return self.brick.intersect(origins, directions, coherent)

    def occluded(self, segments: list[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        return self.brick.occluded(segments)

    def close(self) -> None:
        self.brick.close()


def _brick_contents(source: SceneSource | Scene, partition: Partition, index: int):
    if isinstance(source, FieldRecipe):
        return field_brick(source.plan, partition, index)
    scene = source if isinstance(source, Scene) else source.load()
    return scene_brick(scene, partition, index)


# -- on the client ---------------------------------------------------------------------------


@dataclass
class PlacedBrick:
    """Brick ``index``'s actor on ``worker``: the future that made it (Dask keeps the actor while
    it lives) and the handle its methods are called through."""

    index: int
    worker: str
    future: distributed.Future
    actor: distributed.Actor | None = None


class DaskBricks:
    """``BrickQueries`` on the workers of ``client``: brick b is a ``BrickActor`` on
    ``assignment[b]``; a brick whose worker is lost is made again on the live worker holding
    the fewest, and the calls it had not answered are made there (``moves`` counts them).

    While it holds bricks the client calls actors on their workers directly (Dask's
    ``direct_to_workers``, restored on ``close``): through the scheduler, every ray and hit
    would cross twice, and the scheduler would copy them all (a 1e7 field over 2 bricks took
    25% more CPU and 28% more time a render that way). The client must reach the workers, as
    it must for Dask's direct gathers; a brick no worker answers is an error, not a loop.

    Once ``cancelled`` is set (the render using the bricks abandoned: ``Integrator``'s event),
    every query waiting on a worker raises ``CancelledError`` instead of waiting on: the
    workers a Ctrl-C ended would otherwise be waited for up to ``no_workers_timeout_s``."""

    def __init__(
        self,
        client: distributed.Client,
        source,
        plan: BrickPlan,
        assignment: dict[int, str],
        no_workers_timeout_s: float = NO_WORKERS_TIMEOUT_S,
        cancelled: threading.Event | None = None,
    ) -> None:
        self.client = client
        self.source = source
        self.plan = plan
        self.no_workers_timeout_s = no_workers_timeout_s
        self.cancelled = threading.Event() if cancelled is None else cancelled
        self.moves = 0
        self._lock = threading.Lock()
        self.placed = {index: self._place(index, worker) for index, worker in assignment.items()}
        self._direct_before = client.direct_to_workers
        client.direct_to_workers = True

    @property
    def assignment(self) -> dict[int, str]:
        """Each brick's worker."""
        return {index: placed.worker for index, placed in self.placed.items()}

    def _place(self, index: int, worker: str) -> PlacedBrick:
        future = self.client.submit(
            BrickActor,
            self.source,
            self.plan,
            index,
            actor=True,
            workers=[worker],
            allow_other_workers=False,
            pure=False,
        )
        return PlacedBrick(index, worker, future)

    def build(self) -> np.ndarray:
        """Wait for every brick to be made on its worker: (K, 2, 3) float64 their boxes."""
        jobs = [(index, "bounds", ()) for index in range(self.plan.partition.bricks)]
        return np.array(self._run(jobs))

    def intersect(self, requests: list[IntersectRequest]) -> list[BrickHits]:
        return self._run([(b, "intersect", (o, d, coherent)) for b, o, d, coherent in requests])

    def occluded(self, requests: list[OccludedRequest]) -> list[list[np.ndarray]]:
        return self._run([(b, "occluded", (segments,)) for b, segments in requests])

    def close(self) -> None:
        """Close every brick's BVH on its worker and let the actors go."""
        with self._lock:
            placed, self.placed = list(self.placed.values()), {}
        calls = []
        for brick in placed:
            if brick.actor is not None and brick.worker in self.client.nthreads():
                calls.append(brick.actor.close())
        for call in calls:
            # a worker gone meanwhile took its bricks along
            with contextlib.suppress(OSError, TimeoutError):
                call.result(timeout=self.no_workers_timeout_s)
        del calls
        for brick in placed:
            brick.future.release()
            brick.actor = brick.future = None
        self.client.direct_to_workers = self._direct_before
        # Dask keeps an actor while any handle to it lives, and handles linger in reference
        # cycles (the closures of Dask's finished method calls): collect them, so the workers
        # free the bricks now rather than at some later collection.
        gc.collect()

    def _actor(self, index: int) -> PlacedBrick:
        """Brick ``index`` placed, its actor made (waiting for it), moved if its worker is lost."""
        while True:
            with self._lock:
                placed = self.placed[index]
            if placed.actor is not None:
                return placed
            self._raise_if_cancelled()
            try:
                actor = placed.future.result(timeout=POLL_S)
            except (TimeoutError, distributed.TimeoutError):
                self._move_if_lost(placed)
                continue
            except distributed.client.FutureCancelledError:
                self._move_if_lost(placed, lost=True)
                continue
            except distributed.scheduler.KilledWorker as error:
                raise ClusterError(
                    f"making brick {index} killed the workers that tried ({error}); is their "
                    "memory too small for it?"
                ) from None
            with self._lock:
                if self.placed[index] is placed:
                    placed.actor = actor

    def _run(self, jobs: list[tuple[int, str, tuple]]) -> list:
        """Call method ``name`` with ``arguments`` of each job's brick ``(index, name,
        arguments)``, all at once; the results in the jobs' order. A call whose brick's worker
        is lost is made again where the brick moves."""
        calls = {}
        for job, (index, name, arguments) in enumerate(jobs):
            placed = self._actor(index)
            calls[job] = (placed, getattr(placed.actor, name)(*arguments))
        results: list = [None] * len(jobs)
        for job, (index, name, arguments) in enumerate(jobs):
            placed, call = calls[job]
            unreachable = 0
            while True:
                self._raise_if_cancelled()
                try:
                    results[job] = call.result(timeout=POLL_S)
                    break
                except (TimeoutError, distributed.TimeoutError):
                    if not self._move_if_lost(placed):
                        continue
                except OSError as error:  # "Unable to contact Actor's worker"
                    unreachable += 1
                    if unreachable > len(self._live_workers()) + 1:
                        raise ClusterError(
                            f"brick {index}: no worker that made it answered this client "
                            f"({error}); data-parallel rendering calls the workers directly: "
                            "can this machine reach their addresses?"
                        ) from None
                    self._move_if_lost(placed, lost=True)
                placed = self._actor(index)
                call = getattr(placed.actor, name)(*arguments)
        return results

    def _move_if_lost(self, placed: PlacedBrick, lost: bool = False) -> bool:
        """Whether brick ``placed`` has moved (now or by another thread): when its worker is
        gone (or ``lost``), it is made again on the live worker holding the fewest bricks."""
        live = self._live_workers()
        with self._lock:
            if self.placed[placed.index] is not placed:
                return True
            if placed.worker in live and not lost:
                return False
            held = dict.fromkeys(live, 0)
            for other in self.placed.values():
                if other.worker in held:
                    held[other.worker] += 1
            worker = min(sorted(held), key=held.__getitem__)
            self.placed[placed.index] = self._place(placed.index, worker)
            self.moves += 1
        placed.future.release()
        return True

    def _live_workers(self) -> dict[str, int]:
        return live_workers(self.client, self.no_workers_timeout_s, self.cancelled)

    def _raise_if_cancelled(self) -> None:
        if self.cancelled.is_set():
            raise CancelledError("the render using the bricks was abandoned")


def live_workers(
    client: distributed.Client, timeout_s: float, cancelled: threading.Event | None = None
) -> dict[str, int]:
    """The workers present (address: threads), waiting up to ``timeout_s`` while there are
    none; then ``ClusterError``. Once ``cancelled`` is set, ``CancelledError`` instead of
    waiting on."""
    cancelled = threading.Event() if cancelled is None else cancelled
    deadline = time.perf_counter() + timeout_s
    while not (workers := client.nthreads()):
        if time.perf_counter() > deadline:
            raise ClusterError(
                f"{client.scheduler.address}: the cluster has no workers for the bricks after "
                f"waiting {timeout_s:g} s"
            )
        if cancelled.wait(POLL_S):
            raise CancelledError("the render using the bricks was abandoned")
    return workers


def assign_bricks(bricks: int, workers: Sequence[str]) -> dict[int, str]:
    """Brick b to worker ``sorted(workers)[b % len(workers)]``."""
    ordered = sorted(workers)
    return {index: ordered[index % len(ordered)] for index in range(bricks)}


class PartitionedRenderer(FrameRenderer):
    """Renders one scene on ``client``'s cluster, data-parallel: the scene cut into
    ``partition`` bricks held by the workers, shading on this process (``threads`` batches
    in flight, ``batch_size`` camera samples each). ``scene`` as for ``ClusterRenderer``: a
    ``Scene`` (scattered to every worker once), a ``SceneFile``/``FieldRecipe`` or a path.
    The bricks are built here, before the first image; ``release()`` frees them."""

    def __init__(
        self,
        scene: Scene | SceneSource | str | os.PathLike,
        client: distributed.Client,
        *,
        partition: int,
        spheres: str = "analytic",
        batch_size: int = DATA_PARALLEL_BATCH_SIZE,
        threads: int = DEFAULT_CLIENT_THREADS,
        no_workers_timeout_s: float = NO_WORKERS_TIMEOUT_S,
    ) -> None:
        if isinstance(partition, bool) or not isinstance(partition, int) or partition < 1:
            raise InputError(f"--partition: expected a number of bricks >= 1, got {partition!r}")
        if isinstance(scene, str | os.PathLike):
            scene = SceneFile(str(Path(scene).resolve()))
        self.client = client
        self.stats = RenderStats()
        started = time.perf_counter()
        self.scene, plan, kind = _plan(scene, partition, spheres)
        self.plan = plan
        self.integrator: Integrator | None = None
        self.bricks: DaskBricks | None = None
        workers = live_workers(client, no_workers_timeout_s)
        assignment = assign_bricks(partition, list(workers))
        info = client.scheduler_info(n_workers=-1)["workers"]
        limits = {
            address: int(info.get(address, {}).get("memory_limit") or 0) for address in workers
        }
        require_bricks_fit(plan, kind, assignment, limits)
        source = client.scatter(scene, broadcast=True, hash=False) if kind == "held" else scene
        # set by the integrator when it abandons a render: the bricks' waits end with it
        cancelled = threading.Event()
        try:
            self.bricks = DaskBricks(
                client, source, plan, assignment, no_workers_timeout_s, cancelled
            )
            bounds = self.bricks.build()
            self.brick_set = BrickSet(self.scene, bounds, self.bricks)
            self.integrator = Integrator(
                self.scene,
                threads=threads,
                batch_size=batch_size,
                tracer=self.brick_set,
                cancelled=cancelled,
            )
        except BaseException:
            self.release()
            raise
        self.stats.build_s = time.perf_counter() - started

    def release(self) -> None:
        """Free the workers' bricks."""
        if self.integrator is not None:
            self.integrator.close()  # and its tracer, the brick set, and so the bricks
            self.integrator = None
        elif self.bricks is not None:
            self.bricks.close()
        self.bricks = None

    def bricks_held(self) -> dict[str, int]:
        """Bricks (of any scene) held by each worker."""
        return self.client.run(bricks_held)

    def render_frames(self, request: FrameRequest) -> None:
        """Render each of the ``request``'s frames in turn and hand it to its ``on_frame``."""
        settings = request.settings
        state = request.started(workers=len(self.client.nthreads()))
        for label, camera in request.cameras:
            frame = camera_frame(camera, settings.width, settings.height)
            before = state.done

            def show(done: int, _total: int, stats: RenderStats, before=before) -> None:
                state.done = before + done
                state.stats = stats
                request.report(state)

            image, stats = self.integrator.render_image(
                frame,
                spp=settings.spp,
                max_depth=settings.max_depth,
                seed=settings.seed,
                progress=show,
            )
            for kind, count in stats.rays.items():
                self.stats.rays[kind] += count
            self.stats.render_s += stats.render_s
            state.frames_done += 1
            request.on_frame(label, image)


def _plan(source: Scene | SceneSource, bricks: int, spheres: str) -> tuple[Scene, BrickPlan, str]:
    """The scene as the client needs it (a random field's without its spheres), the bricks'
    plan, and the source's kind for the budget: "field", "scene" (a file every worker loads)
    or "held" (a ``Scene`` scattered to every worker)."""
    from embree_rt.scene import load_scene
    from embree_rt.scene.random_field import field_scene

    if isinstance(source, FieldRecipe):
        scene, kind = field_scene(source.plan), "field"
        partition = field_partition(source.plan, bricks)
        counts = field_brick_counts(source.plan, partition)
        total = source.plan.count
    else:
        scene = source if isinstance(source, Scene) else load_scene(source.path)
        kind = "held" if isinstance(source, Scene) else "scene"
        centers = object_centers(scene)
        partition = split_points(centers, bricks)
        counts = np.bincount(partition.brick_of(centers), minlength=bricks)
        total = len(scene.sphere_radii)
    plan = BrickPlan(partition, brick_sphere_mode(total, spheres), tuple(int(c) for c in counts))
    return scene, plan, kind


def bricks_held(dask_worker) -> int:
    """The ``BrickActor``s a worker holds (run on it by ``client.run``)."""
    return sum(isinstance(actor, BrickActor) for actor in dask_worker.state.actors.values())


def render(
    scene: Scene | SceneSource | str | os.PathLike,
    client: distributed.Client,
    *,
    partition: int,
    camera: Camera | None = None,
    spheres: str = "analytic",
    batch_size: int = DATA_PARALLEL_BATCH_SIZE,
    threads: int = DEFAULT_CLIENT_THREADS,
    quiet: bool = True,
    **overrides: Unpack[SettingOverrides],
) -> RenderResult:
    """``embree_rt.distributed.render``'s twin with the scene cut into ``partition`` bricks on
    the workers: the same image, bit for bit (see ``nearest`` for exact ties between bricks);
    ``overrides`` are the settings (width, height, spp, max_depth, seed). The bricks are freed
    afterwards."""
    renderer = PartitionedRenderer(
        scene, client, partition=partition, spheres=spheres, batch_size=batch_size, threads=threads
    )
    try:
        settings = renderer.scene.render.with_overrides(**overrides)
    except BaseException:
        renderer.release()
        raise
    return renderer.render_once(
        settings, renderer.scene.camera if camera is None else camera, quiet
    )
