"""Rendering on Dask against rendering locally, on this machine: local threads against 1 and 2
worker processes, the per-task overhead, and the bytes a render moves.

One random field is rendered by a local ``Renderer`` on 1 and on 2 threads and by a
``ClusterRenderer`` on a ``LocalCluster`` of 1 and of 2 worker processes (one thread each),
taking turns ``--rounds`` times after a warm-up render each (the workers build their BVH in the
warm-up). Per-task overhead is measured two ways: empty tasks through the scheduler, and the
cluster's time on one worker minus the local time on one thread, over the number of batches.
Bytes: the scene as it would be scattered (pickled), the task arguments, and the float64 block
sums that come back.

    python benchmarks/distributed_scale.py                    # 1e5 spheres, 960x540, 4 spp
    python benchmarks/distributed_scale.py --count 1000000 --rounds 3

With ``--partition K`` it measures data-parallel rendering instead (``embree_rt.bricks``): the
field cut into K bricks on a ``LocalCluster`` of ``--workers`` processes, each generating and
building only its bricks, shading on the client; against a local render on 2 threads in a
process of its own, the two taking turns ``--rounds`` times so that both see the same load from
other work. Both images must be bitwise equal. Reported: render times and their ratio per turn,
the CPU seconds a render takes (the client's and the workers' together: what the load cannot
stretch), the peak resident memory of each worker, of the client and of the single process,
and the rays that crossed to the bricks (each ray is sent to every brick whose box it reaches).

    python benchmarks/distributed_scale.py --partition 2 --count 10000000 --spp 1 --rounds 2

Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import distributed
import numpy as np

from embree_rt import Renderer
from embree_rt import distributed as rd
from embree_rt.batches import batch_ranges
from embree_rt.camera import camera_frame
from embree_rt.integrator import DEFAULT_BATCH_SIZE
from embree_rt.scene import RenderSettings, random_field
from embree_rt.scene.random_field import plan_field


def empty_task(i: int) -> int:
    return i


def peak_rss_bytes() -> int:
    """This process's peak resident memory (Linux reports kilobytes)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


# The local renderer of the --partition mode, in a process of its own (its memory apart from the
# client's), kept between turns: (renderer, field seconds, build seconds).
_LOCAL: dict = {}


def cpu_seconds() -> float:
    """This process's user and system CPU time so far."""
    times = os.times()
    return times.user + times.system


def local_setup(count: int) -> None:
    """In the local process: the field made and its BVH built, for 2 threads."""
    started = time.perf_counter()
    scene = random_field(count)
    field_s = time.perf_counter() - started
    renderer = Renderer(scene, threads=2)
    _LOCAL.update(renderer=renderer, field_s=field_s, build_s=renderer.build_s)


def local_render(image: dict, keep_image: bool = False) -> tuple[float, float, np.ndarray | None]:
    """In the local process: one render's wall and CPU seconds (and its image)."""
    began, cpu = time.perf_counter(), cpu_seconds()
    result = _LOCAL["renderer"].render(**image)
    seconds, cpu = time.perf_counter() - began, cpu_seconds() - cpu
    _LOCAL["rays"] = result.stats.total_rays
    return seconds, cpu, result.image if keep_image else None


def local_facts() -> dict:
    """In the local process: its set-up times, rays per image and peak memory."""
    return {
        "field_s": _LOCAL["field_s"],
        "build_s": _LOCAL["build_s"],
        "rays": _LOCAL["rays"],
        "peak_rss": peak_rss_bytes(),
    }


def data_parallel(args: argparse.Namespace) -> dict:
    """The ``--partition`` mode: see the module docstring."""
    from embree_rt.bricks.cluster import PartitionedRenderer

    image = {"width": args.width, "height": args.height, "spp": args.spp, "max_depth": 6, "seed": 0}
    settings = RenderSettings(args.width, args.height, args.spp, max_depth=6, seed=0)
    recipe = rd.FieldRecipe(plan_field(args.count))
    local_times, local_cpu, times, cpu = [], [], [], []
    with (
        ProcessPoolExecutor(
            max_workers=1,
            mp_context=get_context("spawn"),
            initializer=local_setup,
            initargs=(args.count,),
        ) as local,
        rd.local_cluster(args.workers, silence_logs=50) as cluster,
        distributed.Client(cluster) as client,
    ):
        local.submit(local_render, image).result()  # the field, the BVH, a warm-up render
        client.wait_for_workers(args.workers)
        started = time.perf_counter()
        renderer = PartitionedRenderer(recipe, client, partition=args.partition)
        setup_s = time.perf_counter() - started
        try:
            camera = renderer.scene.camera
            renderer.render(settings, camera)  # warms the client's kernels
            for turn in range(args.rounds):  # turns: both see the same load from other work
                seconds, seconds_cpu, local_image = local.submit(
                    local_render, image, turn == args.rounds - 1
                ).result()
                local_times.append(seconds)
                local_cpu.append(seconds_cpu)
                began, before = (
                    time.perf_counter(),
                    cpu_seconds() + sum(client.run(cpu_seconds).values()),
                )
                picture = renderer.render(settings, camera)
                times.append(time.perf_counter() - began)
                cpu.append(cpu_seconds() + sum(client.run(cpu_seconds).values()) - before)
            traffic = renderer.brick_set.traffic
            workers_peak = client.run(peak_rss_bytes)
        finally:
            renderer.release()
        facts = local.submit(local_facts).result()
    names = ("rays", "ray_sends", "segments", "segment_sends", "ties")
    per_image = {name: getattr(traffic, name) // (args.rounds + 1) for name in names}
    ratios = [t / local_t for t, local_t in zip(times, local_times, strict=True)]
    gb = 1e-9
    return {
        "count": args.count,
        "image": f"{args.width}x{args.height} at {args.spp} spp",
        "bricks": args.partition,
        "workers": args.workers,
        "load_average": os.getloadavg(),
        "bitwise_equal": bool(np.array_equal(picture, local_image)),
        "local_2_threads": {
            "field_s": round(facts["field_s"], 2),
            "build_s": round(facts["build_s"], 2),
            "render_s": [round(t, 3) for t in local_times],
            "render_cpu_s": [round(t, 3) for t in local_cpu],
            "peak_rss_gb": round(facts["peak_rss"] * gb, 3),
        },
        "data_parallel": {
            "setup_s_field_and_bricks": round(setup_s, 2),
            "render_s": [round(t, 3) for t in times],
            "render_cpu_s_client_and_workers": [round(t, 3) for t in cpu],
            "peak_rss_gb_per_worker": sorted(round(v * gb, 3) for v in workers_peak.values()),
            "peak_rss_gb_client": round(peak_rss_bytes() * gb, 3),
        },
        "data_parallel_over_local_per_turn": [round(r, 2) for r in ratios],
        "data_parallel_over_local": round(statistics.median(ratios), 3),
        "cpu_over_local": round(statistics.median(cpu) / statistics.median(local_cpu), 3),
        "worker_peak_over_single_process": round(max(workers_peak.values()) / facts["peak_rss"], 3),
        "traffic_per_image": per_image,
        "sends_per_ray": round(per_image["ray_sends"] / max(per_image["rays"], 1), 3),
        "sends_per_segment": round(per_image["segment_sends"] / max(per_image["segments"], 1), 3),
        "rays_per_image": facts["rays"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=100_000, help="spheres")
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--batch-size", type=int, default=DEFAULT_BATCH_SIZE)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--empty-tasks", type=int, default=500)
    parser.add_argument("--partition", type=int, help="data-parallel mode: bricks")
    parser.add_argument("--workers", type=int, default=2, help="data-parallel mode: workers")
    args = parser.parse_args()
    if args.partition is not None:
        print(json.dumps(data_parallel(args), indent=2))
        return

    settings = RenderSettings(args.width, args.height, args.spp, max_depth=6, seed=0)
    image = {"width": args.width, "height": args.height, "spp": args.spp, "max_depth": 6, "seed": 0}
    scene = random_field(args.count)
    recipe = rd.FieldRecipe(plan_field(args.count))
    times: dict[str, list[float]] = {"local_1": [], "local_2": [], "dask_1": [], "dask_2": []}

    with Renderer(scene, threads=1) as one, Renderer(scene, threads=2) as two:
        rays = one.render(**image).stats.total_rays
        two.render(**image)
        clusters = {}
        try:
            for workers in (1, 2):
                cluster = rd.local_cluster(workers, silence_logs=50)
                client = distributed.Client(cluster)
                client.wait_for_workers(workers)
                renderer = rd.ClusterRenderer(recipe, client, batch_size=args.batch_size)
                started = time.perf_counter()
                renderer.render(settings, scene.camera)  # workers generate the field, build
                clusters[workers] = (cluster, client, renderer, time.perf_counter() - started)
            for _ in range(args.rounds):
                for name, render in (
                    ("local_1", lambda: one.render(**image)),
                    ("local_2", lambda: two.render(**image)),
                    ("dask_1", lambda: clusters[1][2].render(settings, scene.camera)),
                    ("dask_2", lambda: clusters[2][2].render(settings, scene.camera)),
                ):
                    started = time.perf_counter()
                    render()
                    times[name].append(time.perf_counter() - started)
            client = clusters[1][1]
            started = time.perf_counter()
            client.gather(client.map(empty_task, range(args.empty_tasks), pure=False))
            empty_s = (time.perf_counter() - started) / args.empty_tasks
            started = time.perf_counter()
            scattered = client.scatter(scene, broadcast=True, hash=False)
            scatter_s = time.perf_counter() - started
            del scattered
            first_s = {w: round(c[3], 3) for w, c in clusters.items()}
            returned = clusters[2][2].bytes_returned // (args.rounds + 1)
        finally:
            for cluster, client, _, _ in clusters.values():
                client.close()
                cluster.close()

    total = args.width * args.height * args.spp
    batches = batch_ranges(total, args.batch_size, args.spp, 2)
    frame = camera_frame(scene.camera, args.width, args.height)
    task_args = len(pickle.dumps(("0" * 16, recipe, frame, args.spp, 0, 6, 0, 1)))
    median = {name: statistics.median(values) for name, values in times.items()}
    result = {
        "count": args.count,
        "image": f"{args.width}x{args.height} at {args.spp} spp",
        "rays_per_image": rays,
        "batches_per_image": len(batches),
        "render_s_median": {k: round(v, 3) for k, v in median.items()},
        "render_s_all": {k: [round(x, 3) for x in v] for k, v in times.items()},
        "speedup_vs_local_1_thread": {
            k: round(median["local_1"] / v, 2) for k, v in median.items()
        },
        "dask_2_over_local_2": round(median["dask_2"] / median["local_2"], 3),
        "first_render_s_with_field_and_bvh": first_s,
        "empty_task_s": round(empty_s, 5),
        "overhead_per_batch_s": round((median["dask_1"] - median["local_1"]) / len(batches), 4),
        "bytes": {
            "scene_pickled_for_scatter": len(pickle.dumps(scene, protocol=5)),
            "scene_as_field_recipe": len(pickle.dumps(recipe)),
            "scatter_broadcast_s": round(scatter_s, 3),
            "task_arguments_each": task_args,
            "block_sums_returned_per_image": returned,
            "image_float32": args.width * args.height * 3 * 4,
        },
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
