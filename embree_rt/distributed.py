"""Rendering on a Dask cluster (``pip install 'embree-rt[distributed]'``), bit for bit as locally.

The work is cut exactly as the local renderer cuts it: ``batches.batch_ranges`` batches of
whole pixels, each traced and shaded by ``Integrator.trace_batch`` into its own ``FilmBlock``. A
batch is a Dask task; the client adds the returned float64 block sums into a ``Film`` with
``Film.add_block``. Every pixel's sum is formed inside one block, by the same code on the same
scene, and added once onto zero, so the image is bitwise the one ``embree_rt.render`` makes
(given the same CPU: on another instruction set Embree may pick other kernels, see README).

A worker builds a scene's ``Integrator`` once (its BVH holds Embree pointers and cannot travel):
``SceneRendererPlugin``, registered under a name made from a hash of the scene, so that several
scenes share a cluster, and sent by the scheduler to workers that join later. How the scene
reaches a worker (``SceneSource``): a scene file travels as its path (every worker must read it
at that path), a random field as its parameters, any other ``Scene`` is scattered once to every
worker with ``broadcast=True`` and tasks refer to it by its future, never carrying it themselves.
Tasks are pure, so when a worker dies the scheduler reruns its batches elsewhere and the image
does not change.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import os
import pickle
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from multiprocessing import resource_tracker
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import dask
import distributed
import numpy as np

from embree_rt import budget
from embree_rt.api import Progress, RenderResult, progress_bar
from embree_rt.batches import batch_ranges
from embree_rt.camera import Camera, CameraFrame, camera_frame
from embree_rt.errors import InputError
from embree_rt.film import Film
from embree_rt.integrator import DEFAULT_BATCH_SIZE, RenderStats
from embree_rt.scene.model import RenderSettings, Scene, SettingOverrides
from embree_rt.scene.random_field import FieldPlan

if TYPE_CHECKING:
    from typing_extensions import Unpack

# How long a render (a brick too) waits with no worker at all (lost, or not yet joined) before
# giving up.
NO_WORKERS_TIMEOUT_S = 30.0
# How long ``--scheduler`` may take to answer as a Dask scheduler (``--scheduler-timeout``).
SCHEDULER_TIMEOUT_S = 10.0
# ``--cluster local:N``: worker processes a core, at most.
LOCAL_WORKERS_PER_CORE = 4
# How often the client looks at the cluster (workers present, progress) while it waits.
POLL_S = 0.25


class ClusterError(InputError):
    """The cluster cannot do the work: unreachable, every worker lost, a worker killed by the
    tasks. Reported as one line (exit code 2): the user's deployment, not embree_rt, is at fault.
    """


class WorkerSceneError(InputError):
    """A worker could not load the scene (a file it cannot read at that path, say). One message
    argument, so that it pickles back to the client whole."""


# -- how a scene reaches the workers ---------------------------------------------------------


@dataclass(frozen=True)
class SceneFile:
    """A scene file, by absolute path: each worker loads it itself."""

    path: str

    def load(self) -> Scene:
        """The scene, loaded on a worker with its warnings (the file's ``InputWarning``s, the
        libraries') silenced: the command and ``render`` load the file on the client first,
        where they are said (by the command as one line each), and a local cluster's workers
        write to the command's stderr, where each worker's copy would appear again, in Python's
        raw two-line form."""
        from embree_rt.scene import load_scene

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return load_scene(self.path)

    def digest(self) -> bytes:
        """The path, the file's bytes, and the path, size and modification time of each data
        file it names: a sphere array or mesh replaced under a running cluster makes a new key,
        so the workers load the scene again instead of rendering the old one. The files a mesh
        names in turn (an OBJ's materials and textures, a glTF's buffers and images) are
        stamped the same way."""
        from embree_rt.scene.loader import SceneReader, read_document
        from embree_rt.scene.mesh_companions import companion_files

        path = Path(self.path)
        parts = [self.path.encode(), path.read_bytes()]
        files = SceneReader(path, read_document(path)).named_files()
        files += [companion for named in files for companion in companion_files(named)]
        for named in dict.fromkeys(files):
            try:
                stat = named.stat()
            except OSError:  # the workers report what they cannot read, naming the key
                parts.append(f"{named}: missing".encode())
                continue
            parts.append(f"{named}: {stat.st_size} bytes, {stat.st_mtime_ns} ns".encode())
        return b"\0".join(parts)


@dataclass(frozen=True)
class FieldRecipe:
    """A random field, by its parameters: each worker generates it (bit-identical everywhere,
    see ``scene.random_field``) instead of receiving 20 bytes a sphere."""

    plan: FieldPlan

    def load(self) -> Scene:
        from embree_rt.scene.random_field import add_field_spheres, field_scene

        scene = field_scene(self.plan)
        add_field_spheres(scene, self.plan)
        return scene

    def digest(self) -> bytes:
        return repr(self.plan).encode()


SceneSource = SceneFile | FieldRecipe


def scene_digest(scene: Scene) -> bytes:
    """A digest of everything in ``scene``: its sphere arrays hashed in place (no copy of a
    hundred million spheres), the rest pickled."""
    digest = hashlib.sha256()
    arrays = [scene.sphere_centers, scene.sphere_radii, scene.sphere_materials]
    for array in [*arrays, *([] if scene.sphere_colors is None else [scene.sphere_colors])]:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        if array.size:  # a memoryview with a zero in its shape cannot be cast to bytes
            digest.update(memoryview(array).cast("B"))
    empty = replace(
        scene,
        sphere_centers=scene.sphere_centers[:0],
        sphere_radii=scene.sphere_radii[:0],
        sphere_materials=scene.sphere_materials[:0],
        sphere_colors=None,
    )
    digest.update(pickle.dumps(empty, protocol=pickle.HIGHEST_PROTOCOL))
    return digest.digest()


def scene_key(source: SceneSource | Scene, spheres: str) -> str:
    """The name a scene's renderer goes by on the workers: a hash of the scene and how its
    spheres enter the BVH."""
    body = scene_digest(source) if isinstance(source, Scene) else source.digest()
    kind = type(source).__name__.encode()
    return hashlib.sha256(kind + b"\0" + spheres.encode() + b"\0" + body).hexdigest()[:16]


def plugin_name(key: str) -> str:
    return f"embree-rt-scene-{key}"


# -- on the workers --------------------------------------------------------------------------


class SceneRendererPlugin(distributed.WorkerPlugin):
    """Holds one scene's ``Integrator`` on a worker, built on the first batch that needs it (in a
    task thread, not the worker's event loop) and closed when the plugin is removed.

    ``builds`` counts the builds on this worker (one, however many batches and frames)."""

    def __init__(self, key: str, spheres: str) -> None:
        self.key = key
        self.spheres = spheres

    def setup(self, worker: distributed.Worker) -> None:
        self._lock = threading.Lock()
        self.integrator = None
        self.builds = 0
        self.build_s = 0.0

    def teardown(self, worker: distributed.Worker) -> None:
        if self.integrator is not None:
            self.integrator.close()
            self.integrator = None

    def integrator_for(self, source: SceneSource | Scene):
        """The integrator, built from ``source`` (a ``SceneSource``, or the scattered ``Scene``
        itself) the first time. A scene too big for this worker's memory is refused before it is
        generated or built (``budget``, as a local render is), not left to kill the worker."""
        from embree_rt.integrator import Integrator

        with self._lock:
            if self.integrator is None:
                started = time.perf_counter()
                try:
                    if isinstance(source, FieldRecipe):
                        self._require_memory(source.plan.count, budget.field_bytes)
                    scene = source if isinstance(source, Scene) else source.load()
                    self._require_memory(len(scene.sphere_radii))
                except InputError as error:
                    raise WorkerSceneError(f"worker cannot load the scene: {error}") from None
                # One thread: the worker runs as many batches side by side as it has threads.
                self.integrator = Integrator(scene, spheres=self.spheres, threads=1)
                self.builds += 1
                self.build_s = time.perf_counter() - started
            return self.integrator

    def _require_memory(self, count: int, scene_bytes: Callable[[int], int] | None = None) -> None:
        """Raise ``MemoryBudgetError`` unless this machine can hold the BVH of ``count``
        spheres (and, with ``scene_bytes``, the scene's own arrays, not made yet)."""
        needs = budget.bvh_needs(count, self.spheres)
        if scene_bytes is not None:
            needs["field"] = (scene_bytes(count), f"a field of {count:,} spheres")
        budget.require(needs)


@dataclass(frozen=True)
class BatchResult:
    """What a batch task returns: its block's pixels ``[first, first + count)``, their (3, count)
    float64 ``sums``, and ray counts by kind."""

    first: int
    count: int
    sums: np.ndarray
    rays: dict[str, int]


def render_batch(
    key: str,
    source: SceneSource | Scene,
    frame: CameraFrame,
    spp: int,
    seed: int,
    max_depth: int,
    start: int,
    count: int,
) -> BatchResult:
    """The Dask task: camera samples ``[start, start + count)`` of ``frame`` on this worker's
    renderer for scene ``key``. Pure: the same arguments give the same bits on any worker."""
    worker = distributed.get_worker()
    plugin = worker.plugins.get(plugin_name(key))
    if plugin is None:  # released (ClusterRenderer.release) while another render still ran
        raise ClusterError(f"worker {worker.address} holds no renderer for scene {key}")
    work = plugin.integrator_for(source).trace_batch(frame, spp, seed, max_depth, start, count)
    return BatchResult(work.block.first, work.block.count, work.block.sums, dict(work.rays))


# -- on the client ---------------------------------------------------------------------------


@dataclass
class ClusterProgress(Progress):
    """What the client knows mid-render (``api.Progress``: samples done of ``total``, the
    workers present, ``stats``), and the frames done."""

    workers: int = 0
    frames_done: int = 0


class FrameRequest(NamedTuple):
    """What a cluster renderer's ``render_frames`` is asked: each ``(label, camera)`` of
    ``cameras`` rendered with ``settings`` and handed to ``on_frame(label, image)`` (a (height,
    width, 3) float32 linear image) when it is done; ``progress``, if given, called with the
    render's ``ClusterProgress`` as batches come in."""

    settings: RenderSettings
    cameras: Sequence[tuple[object, Camera]]
    on_frame: Callable[[object, np.ndarray], None]
    progress: Callable[[ClusterProgress], None] | None = None

    @property
    def frame_samples(self) -> int:
        """Camera samples of one frame."""
        return self.settings.width * self.settings.height * self.settings.spp

    def started(self, workers: int = 0) -> ClusterProgress:
        """The progress of a render of every frame that has not begun."""
        return ClusterProgress(total=self.frame_samples * len(self.cameras), workers=workers)

    def report(self, state: ClusterProgress) -> None:
        """Show ``state`` to ``progress``, if there is one."""
        if self.progress is not None:
            self.progress(state)


@dataclass
class _Frame:
    """One image in flight: its label, its film and the batches not yet added."""

    label: object
    film: Film
    pending: int


class FrameRenderer:
    """What the cluster renderers (``ClusterRenderer``, ``bricks.PartitionedRenderer``) build on
    their own ``render_frames(request)``, which renders each ``(label, camera)`` of a
    ``FrameRequest`` and calls its ``on_frame(label, image)``, their ``release()``, which frees
    what the workers hold, and their ``stats``, the frames' ``RenderStats`` added up."""

    def render(
        self,
        settings: RenderSettings,
        camera: Camera,
        progress: Callable[[ClusterProgress], None] | None = None,
    ) -> np.ndarray:
        """One (height, width, 3) float32 linear image seen by ``camera``."""
        images = []
        self.render_frames(
            FrameRequest(settings, [(0, camera)], lambda _, image: images.append(image), progress)
        )
        return images[0]

    def render_once(
        self, settings: RenderSettings, camera: Camera, quiet: bool = True
    ) -> RenderResult:
        """``render`` with a progress bar (unless ``quiet``), then ``release``: the one image
        of ``embree_rt.distributed.render`` and its bricks twin, as a ``RenderResult``."""
        try:
            with progress_bar(settings.width * settings.height * settings.spp, quiet) as show:
                image = self.render(settings, camera, show)
        finally:
            self.release()
        stats = RenderStats(
            rays=dict(self.stats.rays), build_s=self.stats.build_s, render_s=self.stats.render_s
        )
        return RenderResult(image, {}, stats)


class ClusterRenderer(FrameRenderer):
    """Renders one scene on ``client``'s cluster: frames (one camera each) share the workers'
    renderers; ``render_frames`` keeps a few frames in flight so no worker idles between them.

    ``scene`` is a ``Scene`` (scattered to every worker once), a ``SceneFile``/``FieldRecipe``
    (sent as such), or a path to a scene file (a ``SceneFile``).
    """

    def __init__(
        self,
        scene: Scene | SceneSource | str | os.PathLike,
        client: distributed.Client,
        *,
        spheres: str = "analytic",
        batch_size: int = DEFAULT_BATCH_SIZE,
        no_workers_timeout_s: float = NO_WORKERS_TIMEOUT_S,
    ) -> None:
        if batch_size < 1:
            raise ValueError(f"batch_size: must be >= 1, got {batch_size}")
        if isinstance(scene, str | os.PathLike):
            scene = SceneFile(str(Path(scene).resolve()))
        self.client = client
        self.batch_size = int(batch_size)
        self.no_workers_timeout_s = no_workers_timeout_s
        self.key = scene_key(scene, spheres)
        self.stats = RenderStats()
        self.bytes_returned = 0
        name = plugin_name(self.key)
        # Another renderer of the same scene may have registered it: share its workers' BVHs.
        self.registered = not client.run_on_scheduler(_has_worker_plugin, name=name)
        if self.registered:
            client.register_plugin(SceneRendererPlugin(self.key, spheres), name=name)
        if isinstance(scene, Scene):
            # Once to every worker now; a worker that joins later fetches it from a peer once.
            self.source = client.scatter(scene, broadcast=True, hash=False)
        else:
            self.source = scene

    def release(self) -> None:
        """Free the workers' renderers of this scene (and the scattered scene), if this
        renderer registered them: a long-lived cluster otherwise keeps every scene's BVH."""
        if self.registered:
            self.client.unregister_worker_plugin(plugin_name(self.key))
            self.registered = False
        self.source = None

    def builds(self) -> dict[str, int]:
        """Renderer builds per worker address (each worker that has taken a batch: 1)."""
        return self.client.run(_plugin_builds, name=plugin_name(self.key))

    def render_frames(self, request: FrameRequest) -> None:
        """Render each of the ``request``'s frames and hand it to its ``on_frame`` as each
        finishes (in any order). On any exception, Ctrl-C included, the batches not done are
        cancelled."""
        settings = request.settings
        frames = [
            (label, camera_frame(camera, settings.width, settings.height))
            for label, camera in request.cameras
        ]
        state = request.started()
        workers = self._wait_for_workers(state)
        threads = sum(workers.values())
        batches = batch_ranges(request.frame_samples, self.batch_size, settings.spp, threads)
        # The next frame's batches are queued while the last of this one's run, so no worker
        # waits between frames; no more than that (memory: a film per frame in flight).
        queued = 4 * threads
        queue = iter(frames)
        in_flight: dict[distributed.Future, _Frame] = {}
        began = time.perf_counter()

        submitted = 0

        def top_up() -> None:
            """Submit frames until ``queued`` batches are in flight or none are left."""
            nonlocal submitted
            while len(in_flight) < queued and (item := next(queue, None)) is not None:
                submit(*item)
                submitted += 1

        def submit(label: object, frame: CameraFrame) -> None:
            image = _Frame(label, Film(settings.width, settings.height), len(batches))
            n = len(batches)
            # One graph for the frame's batches; earlier frames first.
            futures = self.client.map(
                render_batch,
                [self.key] * n,
                [self.source] * n,
                [frame] * n,
                [settings.spp] * n,
                [settings.seed] * n,
                [settings.max_depth] * n,
                [start for start, _ in batches],
                [count for _, count in batches],
                pure=False,
                priority=-submitted,
            )
            in_flight.update(dict.fromkeys(futures, image))

        try:
            top_up()
            last_check = 0.0
            while in_flight:
                done = self._wait_some(list(in_flight))
                now = time.perf_counter()
                if now - last_check > 1.0 or not done:
                    state.workers = len(self._wait_for_workers(state))
                    last_check = now
                # All finished batches' results in one round trip, not one each.
                for future, result in zip(done, _results(self.client, done), strict=True):
                    image = in_flight.pop(future)
                    future.release()
                    image.film.add_block(result)  # a BatchResult reads as a FilmBlock
                    self.bytes_returned += result.sums.nbytes
                    for kind, n in result.rays.items():
                        self.stats.rays[kind] += n
                        state.stats.rays[kind] += n
                    state.done += result.count * settings.spp
                    image.pending -= 1
                    if image.pending == 0:
                        request.on_frame(image.label, image.film.image(settings.spp))
                        state.frames_done += 1
                top_up()
                state.stats.render_s = self.stats.render_s = time.perf_counter() - began
                request.report(state)
        finally:
            if in_flight:
                self.client.cancel(list(in_flight), force=True)

    def _wait_some(self, futures: list) -> list:
        """Futures among ``futures`` that have finished, waiting at most ``POLL_S`` for one."""
        try:
            done, _ = distributed.wait(futures, timeout=POLL_S, return_when="FIRST_COMPLETED")
        except distributed.TimeoutError:
            return []
        return list(done)

    def _wait_for_workers(self, state: ClusterProgress) -> dict[str, int]:
        """The workers' thread counts by address, waiting up to ``no_workers_timeout_s`` while
        there are none; then ``ClusterError``."""
        deadline = time.perf_counter() + self.no_workers_timeout_s
        while True:
            workers = self.client.nthreads()
            if workers:
                return workers
            if time.perf_counter() > deadline:
                lost = " (all lost mid-render)" if state.done else ""
                raise ClusterError(
                    f"{self.client.scheduler.address}: the cluster has no workers{lost} "
                    f"after waiting {self.no_workers_timeout_s:g} s"
                )
            time.sleep(POLL_S)


def _results(client: distributed.Client, futures: list) -> list[BatchResult]:
    """The futures' results; a task that killed workers one after another is the cluster's
    problem (out of memory, say), not a bug."""
    if not futures:
        return []
    try:
        return client.gather(futures)
    except distributed.client.FutureCancelledError as error:
        raise ClusterError(f"a batch was cancelled on the cluster: {error}") from None
    except distributed.scheduler.KilledWorker as error:
        raise ClusterError(
            f"batches killed the workers that ran them ({error}); is their memory too small "
            "for the scene?"
        ) from None


def _has_worker_plugin(dask_scheduler, name: str) -> bool:
    return name in dask_scheduler.worker_plugins


def _plugin_builds(dask_worker, name: str) -> int:
    plugin = dask_worker.plugins.get(name)
    return 0 if plugin is None else plugin.builds


def render(
    scene: Scene | SceneSource | str | os.PathLike,
    client: distributed.Client,
    *,
    camera: Camera | None = None,
    spheres: str = "analytic",
    batch_size: int = DEFAULT_BATCH_SIZE,
    quiet: bool = True,
    **overrides: Unpack[SettingOverrides],
) -> RenderResult:
    """``embree_rt.render`` on ``client``'s cluster: the same (height, width, 3) float32 image,
    bit for bit (no AOVs: they are rendered locally). ``scene`` is a ``Scene`` (scattered once
    to every worker) or the path of a scene file every worker can read. ``overrides`` (width,
    height, spp, max_depth, seed) as ``embree_rt.render`` takes them. The workers' renderers
    are freed afterwards; for several images or frames of one scene use a ``ClusterRenderer``,
    which builds once per worker for all of them.
    """
    local = scene if isinstance(scene, Scene) else _local_view(scene)
    if local.render.background != "sky":  # its alpha pass is made by ``api.Renderer`` alone
        raise ValueError(
            f"render.background = {local.render.background!r}: render it locally "
            "(embree_rt.render); a cluster's images show the sky"
        )
    settings = local.render.with_overrides(**overrides)
    renderer = ClusterRenderer(scene, client, spheres=spheres, batch_size=batch_size)
    # one image: nothing to keep (a ClusterRenderer keeps its BVHs)
    return renderer.render_once(settings, local.camera if camera is None else camera, quiet)


def _local_view(source: SceneSource | str | os.PathLike) -> Scene:
    """The scene as the client needs it: its camera and render settings (and, for a file,
    the file checked before any worker reads it)."""
    from embree_rt.scene import load_scene
    from embree_rt.scene.random_field import field_scene

    if isinstance(source, FieldRecipe):
        return field_scene(source.plan)
    return load_scene(source.path if isinstance(source, SceneFile) else source)


# -- clusters for the command ----------------------------------------------------------------

# Dask's statistical profiler takes the GIL every 10 ms to sample every worker thread's stack;
# a batch shades in NumPy between GIL-free Embree calls, and ran 1.35-1.5x slower in a Dask task
# with it on (a 1e5-sphere field, 960x540 at 4 spp: 3.5-3.9 s against 2.5-2.6 s with it off,
# and 2.6 s on a local thread). Workers this module starts run without it; give a cluster of
# your own DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False.
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}


def local_cluster(workers: int, **options) -> distributed.LocalCluster:
    """A ``LocalCluster`` of ``workers`` processes of one thread each, with ``WORKER_CONFIG``
    and no memory limit unless ``memory_limit`` is given (the BVH is memory Dask does not
    manage: a limit would have the nanny kill a worker for holding a big scene; data-parallel
    bricks are checked against it before they are made), whose processes never take Ctrl-C
    (``sigint_blocked_in_new_threads``); ``options`` go to ``LocalCluster``.

    With no dashboard the scheduler still serves its health routes over HTTP, by default on
    port 8787, warning when another cluster holds it: here on any free port of 127.0.0.1."""
    scheduler_options = {"dashboard_address": "127.0.0.1:0", **options.pop("scheduler_kwargs", {})}
    # the nannies hand the config to their worker processes
    with dask.config.set(WORKER_CONFIG), sigint_blocked_in_new_threads():
        return distributed.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            memory_limit=options.pop("memory_limit", 0),
            scheduler_kwargs=scheduler_options,
            **options,
        )


@contextmanager
def sigint_blocked_in_new_threads() -> Iterator[None]:
    """SIGINT blocked in this thread while inside, and so in every thread started meanwhile
    (a thread starts with its creator's signal mask) and every process those threads start (a
    child keeps the mask of the thread that forked it, through exec): a ``LocalCluster`` made
    inside has its event loop's thread start the worker processes, which then never take
    SIGINT, not even while Python starts up and imports. A terminal's Ctrl-C reaches every
    process of the command's group; the command alone ends the render, cancelling the batches
    and closing the cluster, where each worker would die of it printing its own traceback.
    This thread's own mask is restored on leaving (a mask is a thread's own), so it takes the
    Ctrl-C that came meanwhile then; SIGTERM, which the nannies close their workers with, is
    never blocked.

    multiprocessing's resource tracker, started by the first lock a nanny makes (in the event
    loop's thread), unblocks SIGINT in the thread that starts it: it is started here first."""
    if threading.current_thread() is not threading.main_thread():  # Python's signals go there
        yield
        return
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextmanager
def local_client(workers: int) -> Iterator[distributed.Client]:
    """A client on a ``local_cluster`` of ``workers``, closed afterwards. A Ctrl-C while the
    cluster starts is held until it has (and is then closed again): interrupted half-way, it
    would be left to Dask's exit hook, which fails on it with a traceback."""
    held: list[int] = []
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))

    def take_held() -> None:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        if held:
            raise KeyboardInterrupt

    try:
        # Not even errors: as a signal ends the command, workers log their peers' lost
        # connections; a failure that matters reaches the client as an exception.
        cluster = local_cluster(workers, silence_logs=logging.CRITICAL + 1)
    except BaseException:
        take_held()
        raise
    with cluster:
        take_held()
        with distributed.Client(cluster) as client:
            yield client


@contextmanager
def connect(
    cluster: str | None, scheduler: str | None, *, timeout_s: float = SCHEDULER_TIMEOUT_S
) -> Iterator[distributed.Client]:
    """A client on ``--cluster local:N`` (a ``LocalCluster`` of N worker processes of one thread
    each, closed afterwards) or on the running scheduler at ``--scheduler ADDRESS``, which must
    answer as a Dask scheduler within ``timeout_s`` (``check_scheduler``). Bad values and
    unreachable or silent schedulers are ``InputError``s naming the flag."""
    if cluster is not None:
        with local_client(local_worker_count(cluster)) as client:
            yield client
        return
    check_scheduler(scheduler, timeout_s)
    try:
        client = distributed.Client(scheduler, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError) as error:
        raise ClusterError(f"--scheduler: {scheduler}: cannot connect: {error}") from None
    with client:
        yield client


def check_scheduler(address: str | None, timeout_s: float) -> None:
    """Raise ``ClusterError`` unless a Dask scheduler at ``address`` answers an identity request
    within ``timeout_s`` seconds, all told. Dask's client would wait forever on a socket that
    accepts and never answers, and read another protocol's reply (an HTTP server's) as a frame
    length to allocate: neither is left to it."""
    if not address or not address.strip():
        raise ClusterError(
            f"--scheduler: expected a scheduler address (tcp://HOST:PORT), got {address!r}"
        )

    async def identity():
        comm = await distributed.comm.connect(address, timeout=timeout_s)
        try:
            await comm.write({"op": "identity"})
            return await comm.read()
        finally:
            comm.abort()

    where = f"--scheduler: {address}"
    try:
        reply = asyncio.run(asyncio.wait_for(identity(), timeout_s))
    except TimeoutError:
        raise ClusterError(
            f"{where}: no answer within {timeout_s:g} s (--scheduler-timeout sets the wait)"
        ) from None
    except (OSError, ValueError) as error:
        raise ClusterError(f"{where}: cannot connect: {error}") from None
    except Exception as error:  # any reply Dask cannot decode: another protocol's
        raise ClusterError(
            f"{where}: does not speak Dask's protocol (its reply fails to decode: "
            f"{type(error).__name__})"
        ) from None
    kind = reply.get("type") if isinstance(reply, dict) else type(reply).__name__
    if kind != "Scheduler":
        raise ClusterError(f"{where}: answers, but as a {kind}, not a Dask scheduler")


def local_worker_count(text: str) -> int:
    """The N of ``--cluster local:N``: at least 1, at most ``LOCAL_WORKERS_PER_CORE`` a core
    (each worker is a process of its own; ten thousand would swamp the machine)."""
    kind, _, count = text.partition(":")
    if kind != "local" or not count.isdigit() or int(count) < 1:
        raise InputError(f"--cluster: expected local:N with N >= 1 workers, got {text!r}")
    cores = os.cpu_count() or 1
    most = LOCAL_WORKERS_PER_CORE * cores
    if int(count) > most:
        raise InputError(
            f"--cluster: {text} would start {int(count):,} worker processes; this machine's "
            f"{cores} cores take at most {most} ({LOCAL_WORKERS_PER_CORE} a core)"
        )
    return int(count)
