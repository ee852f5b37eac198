"""End-to-end render throughput on random sphere fields, against bare Embree traversal.

For each sphere count it renders the random field once (peak memory is read after it), once
more recording every ray query, then ``--repeat`` times, each render followed at once by a
replay of the recorded rays through the bare BVH queries (no shading) on as many threads.
``efficiency`` is the median over those pairs of replay time / render time, i.e. rays/s end to
end over raw rays/s: pairs taken close together keep the ratio fair on a noisy shared machine.
``render_s`` and ``raw_rays_per_s`` are the best of their runs.

``stages`` is where one more render's time goes, rendered on one worker thread so that the
stages add up to its ``render_s``: ``camera`` (the batches' tile order and the camera rays,
which are made inside the first query: their share is timed apart by making the same rays
again), ``traversal`` (Embree's nearest-hit queries), ``records`` (hit records and surface
normals and looks around them), ``shadow`` (the shadow-segment queries, the segments made
inside them), ``film`` (sums into the film and the final image) and ``shading`` (the rest:
NumPy shading and the wavefront's bookkeeping). The instruments cost a few microseconds a call.

    python benchmarks/render_scale.py                       # 1e3..1e6 spheres, 1920x1080, 1 spp
    python benchmarks/render_scale.py --counts 1000000 --threads 1

Prints one JSON object per count on stdout.
"""

from __future__ import annotations

import argparse
import json
import resource
import threading
import time
from contextlib import contextmanager

import numpy as np

from embree_rt import Renderer, film, integrator
from embree_rt.compiled.camera_rays import sample_rays
from embree_rt.embree import Rays, kernels
from embree_rt.integrator import DEFAULT_BATCH_SIZE
from embree_rt.scene import random_field
from embree_rt.tracing import camera_query, segments

STAGES = ("camera", "traversal", "records", "shading", "shadow", "film")


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class RecordingGeometry:
    """Stands in for a renderer's ``SceneGeometry`` and records every query it forwards, as
    (kind, origins, directions, tfar, coherent) with rays as (3, n) columns."""

    def __init__(self, geometry) -> None:
        self.geometry = geometry
        self.log: list = []
        self._lock = threading.Lock()

    def __getattr__(self, name: str):
        return getattr(self.geometry, name)

    def intersect_compact(self, origins, directions, coherent=False, ids=True):
        with self._lock:
            self.log.append(("intersect", origins, directions, np.inf, coherent))
        return self.geometry.intersect_compact(origins, directions, coherent, ids)

    def intersect_camera(self, camera, index, ids=True):
        rows, surfaces, directions = self.geometry.intersect_camera(camera, index, ids)
        # The camera rays, made inside the query, as the rays they are.
        origins = np.repeat(camera.origin[:, None], directions.shape[1], axis=1)
        with self._lock:
            self.log.append(("intersect", origins, directions, np.inf, True))
        return rows, surfaces, directions

    def toward_lights(self, points, normals, targets, takes):
        # The shadow segments the kernel makes: from each point facing the light (and taking
        # light) to the light, t in [0, 1], as occluded_toward's below.
        for target, answer in zip(
            targets, self.geometry.toward_lights(points, normals, targets, takes), strict=True
        ):
            to_light = np.asarray(target, np.float32)[:, None] - points
            facing = (to_light[0] * normals[0] + to_light[1] * normals[1]) + to_light[2] * normals[
                2
            ] > 0
            rows = np.flatnonzero(facing & takes)
            with self._lock:
                self.log.append(("occluded", points[:, rows], to_light[:, rows], 1.0, False))
            yield answer

    def occluded_toward(self, points, rows, target):
        # The shadow segments as the rays they are: from each point to the target, t in [0, 1].
        origins = np.take(points, rows, axis=1)
        directions = np.asarray(target, np.float32)[:, None] - origins
        with self._lock:
            self.log.append(("occluded", origins, directions, 1.0, False))
        return self.geometry.occluded_toward(points, rows, target)


def record_queries(renderer: Renderer, image: dict) -> list:
    """Every ray query one render of ``image`` makes."""
    geometry = renderer.geometry
    renderer.geometry = recorder = RecordingGeometry(geometry)
    try:
        renderer.render(**image)
    finally:
        renderer.geometry = geometry
    return recorder.log


def replay(renderer: Renderer, log: list, threads: int | None = None) -> float:
    """Seconds the bare BVH takes to answer every query of ``log`` again (Embree's traversal
    and nothing else: no hit records, no floor plane), on ``threads`` threads (by default as
    many as the render had)."""
    bvh = renderer.geometry.bvh
    render_threads = bvh.threads  # the renderer's own (1: its workers query side by side)
    bvh.threads = renderer.workers if threads is None else threads
    try:
        return _replay(bvh, log)
    finally:
        bvh.threads = render_threads


def _replay(bvh, log: list) -> float:
    # Compile and warm the kernels this thread count uses, outside the timing.
    # (numba compiles per memory layout: these are Fortran-ordered (n, 3) views, as logged.)
    _, origins, directions, _, _ = log[0]
    origins, directions = (
        np.ascontiguousarray(origins[:, :64]),
        np.ascontiguousarray(directions[:, :64]),
    )
    bvh.intersect(Rays(origins.T, directions.T))
    bvh.intersect(Rays(origins.T, directions.T), coherent=True)
    bvh.occluded(Rays(origins.T, directions.T))
    elapsed = 0.0
    for kind, origins, directions, tfar, coherent in log:
        start = time.perf_counter()
        # The log holds rays as (3, n) columns; the BVH takes (n, 3) views of them.
        if kind == "intersect":
            bvh.intersect(Rays(origins.T, directions.T), coherent=coherent)
        else:
            bvh.occluded(Rays(origins.T, directions.T, 0.0, tfar))
        elapsed += time.perf_counter() - start
    return elapsed


class StageClock:
    """Seconds spent per stage by wrapped functions, each call's time less that of the wrapped
    calls it makes (a records pass that calls the traversal kernel counts only its own time).
    One thread at a time."""

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(STAGES, 0.0)
        self._inner: list[float] = []

    def wrap(self, stage: str, function):
        def timed(*args, **kwargs):
            self._inner.append(0.0)
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - start
                inner = self._inner.pop()
                self.seconds[stage] += elapsed - inner
                if self._inner:
                    self._inner[-1] += elapsed

        return timed


@contextmanager
def patched(targets: list[tuple[object, str, object]]):
    """Set each (owner, name, value) for the duration, then put the originals back."""
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in targets]
    try:
        for owner, name, value in targets:
            setattr(owner, name, value)
        yield
    finally:
        for owner, name, value in saved:
            setattr(owner, name, value)


def stage_breakdown(renderer: Renderer, image: dict) -> dict:
    """Seconds per stage (``STAGES``) of one render of ``image`` on one worker thread, and its
    ``render_s``."""
    clock = StageClock()
    camera_batches = []
    make_camera, make_order = integrator.camera_rays, integrator.tiled_samples

    def camera_rays(frame, spp, seed):
        camera = make_camera(frame, spp, seed)
        camera_batches.append(camera)
        return camera

    def tiled_samples(*args):
        index, pixel = make_order(*args)
        camera_batches.append(index)
        return index, pixel

    geometry = renderer.geometry
    wrap = clock.wrap
    targets = [
        (integrator, "tiled_samples", wrap("camera", tiled_samples)),
        (integrator, "camera_rays", wrap("camera", camera_rays)),
        (
            camera_query,
            "intersect_camera_chunk",
            wrap("traversal", camera_query.intersect_camera_chunk),
        ),
        (kernels, "intersect_chunk", wrap("traversal", kernels.intersect_chunk)),
        (geometry, "intersect_camera", wrap("records", geometry.intersect_camera)),
        (geometry, "intersect_compact", wrap("records", geometry.intersect_compact)),
        (geometry, "occluded_toward", wrap("shadow", geometry.occluded_toward)),
        (segments, "toward_light_chunk", wrap("shadow", segments.toward_light_chunk)),
        (film.FilmBlock, "add", wrap("film", film.FilmBlock.add)),
        (film.FilmBlock, "add_weighted", wrap("film", film.FilmBlock.add_weighted)),
        (film.Film, "add_block", wrap("film", film.Film.add_block)),
        (film.Film, "image", wrap("film", film.Film.image)),
    ]
    workers, renderer.workers = renderer.workers, 1
    try:
        with patched(targets):
            render_s = renderer.render(**image).stats.render_s
    finally:
        renderer.workers = workers
        for owner, name, _ in targets:  # instance attributes: back to the class's methods
            if owner is geometry:
                vars(geometry).pop(name, None)
    # The camera rays were made inside the traversal kernel: make them again, timed, and move
    # that time from traversal to camera.
    indices, cameras = camera_batches[0::2], camera_batches[1::2]
    sample_rays(cameras[0], indices[0][:1])  # loaded (or compiled) outside the timing
    start = time.perf_counter()
    for camera, index in zip(cameras, indices, strict=True):
        sample_rays(camera, index)
    rays_s = time.perf_counter() - start
    seconds = clock.seconds
    seconds["camera"] += rays_s
    seconds["traversal"] -= rays_s
    seconds["shading"] = render_s - sum(v for k, v in seconds.items() if k != "shading")
    return {"render_s": round(render_s, 4), **{k: round(seconds[k], 4) for k in STAGES}}


def run(count: int, args: argparse.Namespace) -> dict:
    scene = random_field(count, seed=args.seed)
    image = dict(
        width=args.width, height=args.height, spp=args.spp, max_depth=args.max_depth, seed=args.seed
    )
    with Renderer(scene, threads=args.threads, batch_size=args.batch_size) as renderer:
        # Compile and warm the kernels on a tiny image so the timed render measures rendering.
        renderer.render(width=16, height=9, spp=1, max_depth=args.max_depth, seed=args.seed)
        stats = renderer.render(**image).stats
        peak_rss = peak_rss_mb()  # before the log below holds every ray in memory
        rays_by_kind = dict(stats.rays)
        render_s = [stats.render_s]
        # Once more, logging every query (not timed).
        log = record_queries(renderer, image)
        # Timed renders, each followed at once by a replay of its rays: the machine's load
        # changes slowly, so each pair's ratio is a fair one even when the load does change.
        raw_s = []
        for _ in range(args.repeat):
            render_s.append(renderer.render(**image).stats.render_s)
            raw_s.append(replay(renderer, log))
        efficiency = float(np.median(np.divide(raw_s, render_s[1:])))
        stages = stage_breakdown(renderer, image)
        best_s = min(render_s)
        rays = sum(rays_by_kind.values())
        return {
            "count": count,
            "width": args.width,
            "height": args.height,
            "spp": args.spp,
            "max_depth": args.max_depth,
            "threads": renderer.workers,
            "batch_size": renderer.batch_size,
            "build_s": round(stats.build_s, 4),
            "render_s": round(best_s, 3),
            "render_s_all": [round(x, 3) for x in render_s],
            "rays": rays_by_kind,
            "rays_per_s": round(rays / best_s),
            "raw_rays_per_s": round(rays / min(raw_s)),
            "raw_s_all": [round(x, 3) for x in raw_s],
            "efficiency": round(efficiency, 3),
            "peak_rss_mb": round(peak_rss, 1),
            "repeat": args.repeat,
            "stages_one_thread": stages,
        }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[1000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--max-depth", type=int, default=6)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch-size", type=int, default=DEFAULT_BATCH_SIZE)
    parser.add_argument("--repeat", type=int, default=3, help="best of this many renders/replays")
    args = parser.parse_args()
    for count in args.counts:
        print(json.dumps(run(count, args)), flush=True)


if __name__ == "__main__":
    main()
