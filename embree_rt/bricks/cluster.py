"""Data-parallel rendering on Dask: each worker holds some bricks of the scene, the client shades.

The client runs the integrator (camera, shading, film: the very code of a local render) with a
``BrickSet`` as its tracer. Per depth of each batch's wavefront it sends every ray only to the
bricks whose box the ray can reach, each brick answering on the worker that holds it; the
nearest hit over bricks wins (``nearest``: ties go to the lower global object id), a shadow
segment is blocked if any brick blocks it. The image is bitwise the local render's.

Where the bricks are: brick b is assigned to one worker (round robin over the workers, by
address) and its tasks carry Dask worker restrictions to it. The worker builds it on the first
task that needs it, in ``BrickHolderPlugin`` (registered under a key made from the scene, the
sphere mode and the partition), from the scene's source: a random field's recipe (the worker
generates only that brick's spheres: ``contents.field_brick``), a scene file's path, or a
``Scene`` scattered once to every worker. A partition whose bricks cannot fit in their workers'
memory limits is refused before anything is built (``require_bricks_fit``). When a worker is
lost, each brick it held is assigned to the live worker holding the fewest, which builds it again
on its first task, and the brick's pending tasks are submitted there: no pixel changes.
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

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
    POLL_S,
    ClusterError,
    ClusterProgress,
    FieldRecipe,
    SceneFile,
    SceneSource,
    WorkerSceneError,
    progress_bar,
    scene_key,
)
from embree_rt.errors import InputError
from embree_rt.geometry import sphere_kind
from embree_rt.integrator import Integrator, RenderStats
from embree_rt.scene.model import RenderSettings, Scene

# Batches of camera samples the client traces at once: smaller than a local render's, so that
# several are in flight and the workers trace one batch's rays while the client shades another's.
DATA_PARALLEL_BATCH_SIZE = 1 << 15
# Batches the client keeps in flight (its shading threads); each waits on the workers most of
# the time, so more than the client's cores.
DEFAULT_CLIENT_THREADS = 4
# How long a brick may wait with no worker at all before the render gives up.
NO_WORKERS_TIMEOUT_S = 30.0


@dataclass(frozen=True)
class BrickPlan:
    """What any worker needs to make a brick of one scene: ``key`` (the plugin's), the
    ``partition``, the ``spheres`` mode the bricks build with (``brick_sphere_mode``) and
    ``counts`` (K,) the objects expected in each brick (exact for a scene, estimated for a
    random field: ``field_brick_counts``), for the memory budget."""

    key: str
    partition: Partition
    spheres: str
    counts: tuple[int, ...]


def plugin_name(key: str) -> str:
    return f"embree-rt-bricks-{key}"


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
        (need, _), = brick_needs(plan, index, source_kind).values()  # fmt: skip
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


class BrickHolderPlugin(distributed.WorkerPlugin):
    """The bricks of one scene that a worker holds, each built on the first task that needs
    it (in a task thread) and closed when the plugin is removed. ``builds`` counts builds."""

    def __init__(self, key: str) -> None:
        self.key = key

    def setup(self, worker: distributed.Worker) -> None:
        self._lock = threading.Lock()
        self.bricks: dict[int, Brick] = {}
        self.builds = 0

    def teardown(self, worker: distributed.Worker) -> None:
        for brick in self.bricks.values():
            brick.close()
        self.bricks = {}

    def brick(self, source: SceneSource | Scene, plan: BrickPlan, index: int) -> Brick:
        """Brick ``index``, made from ``source`` the first time; one that cannot fit in this
        machine's memory is refused (``WorkerSceneError``) before it is made."""
        with self._lock:
            if index not in self.bricks:
                kind = "field" if isinstance(source, FieldRecipe) else "scene"
                try:
                    budget.require(brick_needs(plan, index, kind))
                    contents = _brick_contents(source, plan.partition, index)
                except InputError as error:
                    raise WorkerSceneError(f"worker cannot make brick {index}: {error}") from None
                self.bricks[index] = Brick(contents, plan.spheres)
                self.builds += 1
            return self.bricks[index]


def _brick_contents(source: SceneSource | Scene, partition: Partition, index: int):
    if isinstance(source, FieldRecipe):
        return field_brick(source.plan, partition, index)
    scene = source if isinstance(source, Scene) else source.load()
    return scene_brick(scene, partition, index)


def _holder(key: str) -> BrickHolderPlugin:
    worker = distributed.get_worker()
    plugin = worker.plugins.get(plugin_name(key))
    if plugin is None:  # released while a render of the scene still ran
        raise ClusterError(f"worker {worker.address} holds no bricks of scene {key}")
    return plugin


def build_brick(source, plan: BrickPlan, index: int) -> np.ndarray:
    """The Dask task that makes brick ``index`` on its worker: its (2, 3) float64 box."""
    return _holder(plan.key).brick(source, plan, index).bounds


def brick_intersect(source, plan: BrickPlan, index: int, origins, directions, coherent):
    """The Dask task: brick ``index``'s ``BrickHits`` for rays (3, k) float32."""
    return _holder(plan.key).brick(source, plan, index).intersect(origins, directions, coherent)


def brick_occluded(source, plan: BrickPlan, index: int, points, target) -> np.ndarray:
    """The Dask task: (k,) bool whether brick ``index`` blocks each segment."""
    return _holder(plan.key).brick(source, plan, index).occluded(points, target)


# -- on the client ---------------------------------------------------------------------------


class DaskBricks:
    """``BrickQueries`` on the workers of ``client``: brick b's tasks go to
    ``assignment[b]``; a brick whose worker is lost moves to a live one, and its tasks with it
    (``moves`` counts the moves)."""

    def __init__(
        self,
        client: distributed.Client,
        source,
        plan: BrickPlan,
        assignment: dict[int, str],
        no_workers_timeout_s: float = NO_WORKERS_TIMEOUT_S,
    ) -> None:
        self.client = client
        self.source = source
        self.plan = plan
        self.assignment = dict(assignment)
        self.no_workers_timeout_s = no_workers_timeout_s
        self.moves = 0
        self._lock = threading.Lock()

    def build(self) -> np.ndarray:
        """Make every brick on its worker: (K, 2, 3) float64 their boxes."""
        jobs = [(index, ()) for index in range(self.plan.partition.bricks)]
        return np.array(self._run(build_brick, jobs))

    def intersect(self, requests: list[IntersectRequest]) -> list[BrickHits]:
        return self._run(brick_intersect, [(b, (o, d, coherent)) for b, o, d, coherent in requests])

    def occluded(self, requests: list[OccludedRequest]) -> list[np.ndarray]:
        return self._run(brick_occluded, [(b, (points, target)) for b, points, target in requests])

    def close(self) -> None:
        pass

    def _submit(self, function: Callable, index: int, arguments: tuple) -> distributed.Future:
        return self.client.submit(
            function, self.source, self.plan, index, *arguments,
            workers=[self.assignment[index]], allow_other_workers=False, pure=False,
        )  # fmt: skip

    def _run(self, function: Callable, jobs: list[tuple[int, tuple]]) -> list:
        """``function`` on each job's brick, with its arguments, on the brick's worker; the
        results in the jobs' order. A job whose worker is lost is run again where its brick
        moves."""
        results: list = [None] * len(jobs)
        # each future's job and the worker it was sent to
        pending = {}
        for job, (index, arguments) in enumerate(jobs):
            worker = self.assignment[index]
            pending[self._submit(function, index, arguments)] = (job, worker)
        try:
            while pending:
                try:
                    done, _ = distributed.wait(
                        list(pending), timeout=POLL_S, return_when="FIRST_COMPLETED"
                    )
                except distributed.TimeoutError:
                    done = set()
                finished = [future for future in done if future.status == "finished"]
                for future, value in zip(finished, _gather(self.client, finished), strict=True):
                    results[pending.pop(future)[0]] = value
                for future in done:
                    if future.status == "error":
                        _raise_task_error(future)
                if len(finished) < len(done) or not done:  # cancelled, or nothing yet
                    self._resubmit_lost(pending, function, jobs)
        finally:
            if pending:
                self.client.cancel(list(pending), force=True)
        return results

    def _resubmit_lost(self, pending: dict, function: Callable, jobs: list) -> None:
        """Submit again the pending jobs sent to a worker that is gone (or whose task was
        cancelled), their brick moved to a live worker."""
        live = self._live_workers()
        for future, (job, worker) in list(pending.items()):
            if worker in live and future.status != "cancelled":
                continue
            index, arguments = jobs[job]
            self._move(index, live)
            del pending[future]
            future.cancel()
            with self._lock:
                worker = self.assignment[index]
            pending[self._submit(function, index, arguments)] = (job, worker)

    def _move(self, index: int, live: dict[str, int]) -> None:
        with self._lock:
            if self.assignment[index] in live:  # another thread moved it already
                return
            held = {worker: 0 for worker in live}
            for worker in self.assignment.values():
                if worker in held:
                    held[worker] += 1
            self.assignment[index] = min(sorted(held), key=held.__getitem__)
            self.moves += 1

    def _live_workers(self) -> dict[str, int]:
        return live_workers(self.client, self.no_workers_timeout_s)


def live_workers(client: distributed.Client, timeout_s: float) -> dict[str, int]:
    """The workers present (address: threads), waiting up to ``timeout_s`` while there are
    none; then ``ClusterError``."""
    deadline = time.perf_counter() + timeout_s
    while not (workers := client.nthreads()):
        if time.perf_counter() > deadline:
            raise ClusterError(
                f"{client.scheduler.address}: the cluster has no workers for the bricks after "
                f"waiting {timeout_s:g} s"
            )
        time.sleep(POLL_S)
    return workers


def _gather(client: distributed.Client, futures: list) -> list:
    if not futures:
        return []
    try:
        return client.gather(futures)
    except distributed.client.FutureCancelledError:
        raise ClusterError("a brick's task was cancelled on the cluster") from None


def _raise_task_error(future: distributed.Future) -> None:
    error = future.exception()
    if isinstance(error, distributed.scheduler.KilledWorker):
        raise ClusterError(
            f"a brick's tasks killed the workers that ran them ({error}); is their memory too "
            "small for the brick?"
        ) from None
    raise error


def assign_bricks(bricks: int, workers: Sequence[str]) -> dict[int, str]:
    """Brick b to worker ``sorted(workers)[b % len(workers)]``."""
    ordered = sorted(workers)
    return {index: ordered[index % len(ordered)] for index in range(bricks)}


class PartitionedRenderer:
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
        self.registered = False
        self.integrator: Integrator | None = None
        workers = live_workers(client, no_workers_timeout_s)
        assignment = assign_bricks(partition, list(workers))
        info = client.scheduler_info(n_workers=-1)["workers"]
        limits = {address: int(info.get(address, {}).get("memory_limit") or 0)
                  for address in workers}  # fmt: skip
        require_bricks_fit(plan, kind, assignment, limits)
        name = plugin_name(plan.key)
        self.registered = not client.run_on_scheduler(_has_worker_plugin, name=name)
        if self.registered:
            client.register_plugin(BrickHolderPlugin(plan.key), name=name)
        source = client.scatter(scene, broadcast=True, hash=False) if kind == "held" else scene
        self.bricks = DaskBricks(client, source, plan, assignment, no_workers_timeout_s)
        try:
            bounds = self.bricks.build()
            self.brick_set = BrickSet(self.scene, bounds, self.bricks)
            self.integrator = Integrator(
                self.scene, threads=threads, batch_size=batch_size, tracer=self.brick_set
            )
        except BaseException:
            self.release()
            raise
        self.stats.build_s = time.perf_counter() - started

    def release(self) -> None:
        """Free the workers' bricks of this scene (if this renderer made them)."""
        if self.integrator is not None:
            self.integrator.close()
            self.integrator = None
        if self.registered:
            self.client.unregister_worker_plugin(plugin_name(self.plan.key))
            self.registered = False

    def builds(self) -> dict[str, int]:
        """Bricks built per worker address."""
        return self.client.run(_plugin_builds, name=plugin_name(self.plan.key))

    def render(
        self,
        settings: RenderSettings,
        camera: Camera,
        progress: Callable[[ClusterProgress], None] | None = None,
    ) -> np.ndarray:
        """One (height, width, 3) float32 linear image seen by ``camera``."""
        images = []
        self.render_frames(settings, [(0, camera)], lambda _, image: images.append(image), progress)
        return images[0]

    def render_frames(
        self,
        settings: RenderSettings,
        cameras: Sequence[tuple[object, Camera]],
        on_frame: Callable[[object, np.ndarray], None],
        progress: Callable[[ClusterProgress], None] | None = None,
    ) -> None:
        """Render each ``(label, camera)`` in turn and call ``on_frame(label, image)``."""
        total = settings.width * settings.height * settings.spp
        state = ClusterProgress(total=total * len(cameras), workers=len(self.client.nthreads()))
        for label, camera in cameras:
            frame = camera_frame(camera, settings.width, settings.height)
            before = state.done

            def show(done: int, _total: int, stats: RenderStats, before=before) -> None:
                state.done = before + done
                state.stats = stats
                if progress is not None:
                    progress(state)

            image, stats = self.integrator.render_image(
                frame, spp=settings.spp, max_depth=settings.max_depth, seed=settings.seed,
                progress=show,
            )  # fmt: skip
            for kind, count in stats.rays.items():
                self.stats.rays[kind] += count
            self.stats.render_s += stats.render_s
            state.frames_done += 1
            on_frame(label, image)


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
    mode = brick_sphere_mode(total, spheres)
    digest = hashlib.sha256(scene_key(source, mode).encode())
    for array in (partition.axis, partition.value, partition.left, partition.right):
        digest.update(array.tobytes())
    key = digest.hexdigest()[:16]
    plan = BrickPlan(key, partition, mode, tuple(int(c) for c in counts))
    return scene, plan, kind


def _has_worker_plugin(dask_scheduler, name: str) -> bool:
    return name in dask_scheduler.worker_plugins


def _plugin_builds(dask_worker, name: str) -> int:
    plugin = dask_worker.plugins.get(name)
    return 0 if plugin is None else plugin.builds


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
    **overrides: int | None,
) -> RenderResult:
    """``embree_rt.distributed.render`` with the scene cut into ``partition`` bricks on the
    workers: the same image, bit for bit (see ``nearest`` for exact ties between bricks);
    ``overrides`` are the settings (width, height, spp, max_depth, seed). The bricks are freed
    afterwards."""
    renderer = PartitionedRenderer(scene, client, partition=partition, spheres=spheres,
                                   batch_size=batch_size, threads=threads)  # fmt: skip
    try:
        settings = renderer.scene.render.with_overrides(**overrides)
        view = renderer.scene.camera if camera is None else camera
        with progress_bar(settings.width * settings.height * settings.spp, quiet) as show:
            image = renderer.render(settings, view, show)
    finally:
        renderer.release()
    stats = RenderStats(rays=dict(renderer.stats.rays), build_s=renderer.stats.build_s,
                        render_s=renderer.stats.render_s)  # fmt: skip
    return RenderResult(image, {}, stats)
