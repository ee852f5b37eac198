"""Bare BVH traversal throughput: analytic spheres, instanced tessellated spheres, and embreex.

For each sphere count it lays out a field (spheres on a jittered grid standing on a ground quad),
looks across it with a pinhole camera, and times, on 1 thread and on all threads:

- ``spheres``: the spheres as analytic ``SPHERE_POINT`` geometry (``BVH.add_spheres``);
- ``instanced-mesh``: one shared icosphere mesh BVH placed once per sphere by a scale+translate
  ``BVH.add_instance``;
- ``baked-mesh``: the same icosphere triangles baked into ONE world-space mesh, in our BVH and in
  embreex's own ``EmbreeScene.run`` (only while the mesh has fewer than ``--max-baked`` triangles);

The tessellation defaults to the one embree_rt itself renders spheres with (``--spheres mesh``:
an icosphere of 3 subdivisions, 1280 triangles, within 1.3% of the radius): the equivalent
geometry. Reports build seconds, primary rays/s (``intersect``) and shadow rays/s
(``occluded`` from the primary hits toward a point light). Rows on triangles carry
``vs_embreex``: their primary rays/s over embreex's on the same baked mesh, the same rays and
the same number of threads (embreex's ``run`` is single-threaded; on all threads it is called
from one Python thread per core, as it releases the GIL). embreex is asked for full hit
records (``output=1``), as ``intersect`` gives.

The analytic BVH is built once per thread count, as ``BVH(threads=1)`` and ``BVH(threads=None)``.
The instanced scene costs one ``add_instance`` call per sphere, so it is built once, as
``BVH(threads=None)``, and its 1-thread row sets the BVH's ``threads`` attribute to 1 instead of
rebuilding (its build time is reported in both rows, split into the add loop and the commit).

    python benchmarks/traversal.py                           # 1e3..1e6 spheres, 1M rays
    python benchmarks/traversal.py --counts 1000 100000 --rays 2000000 --subdivisions 1

Prints one JSON object ``{"config": ..., "rows": [...]}`` on stdout and a markdown table on stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
import trimesh

from embree_rt.embree import BVH
from embree_rt.geometry import ICOSPHERE_SUBDIVISIONS

ALL_THREADS = numba.config.NUMBA_NUM_THREADS


# -- the field, the camera and the light ----------------------------------------------------------


def sphere_field(count: int, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """``count`` spheres standing on z = 0, one per cell of a jittered unit grid.

    Returns centers (count, 3) float64, radii (count,) float64 in [0.2, 0.45] (so neighbours
    never overlap) and the side of the square region.
    """
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(count))
    cell = np.arange(count)
    radii = rng.uniform(0.2, 0.45, count)
    play = 0.5 - radii
    x = cell // side + 0.5 + rng.uniform(-1, 1, count) * play
    y = cell % side + 0.5 + rng.uniform(-1, 1, count) * play
    return np.c_[x, y, radii], radii, float(side)


def ground(side: float) -> tuple[np.ndarray, np.ndarray]:
    """A quad under the whole field, as vertices (4, 3) and faces (2, 3), facing up."""
    pad = 0.5 * side + 1.0
    lo, hi = -pad, side + pad
    vertices = np.array([[lo, lo, 0], [hi, lo, 0], [hi, hi, 0], [lo, hi, 0]], float)
    return vertices, np.array([[0, 1, 2], [0, 2, 3]])


def camera_rays(side: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """About ``count`` primary rays of a 16:9 pinhole camera above one corner of the field,
    looking across it. Returns origins, unit directions, (n, 3) float32, row-major pixels."""
    height = max(1, round(math.sqrt(count * 9 / 16)))
    width = max(1, round(count / height))
    eye = np.array([-0.05 * side, -0.05 * side, 0.3 * side + 3.0])
    target = np.array([0.55 * side, 0.55 * side, 0.0])
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = math.tan(math.radians(45.0) / 2)
    xs = ((np.arange(width) + 0.5) / width * 2 - 1) * half * width / height
    ys = (1 - (np.arange(height) + 0.5) / height * 2) * half
    directions = forward + xs[None, :, None] * right + ys[:, None, None] * up
    directions = directions.reshape(-1, 3)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.broadcast_to(eye, directions.shape)
    return np.ascontiguousarray(origins, np.float32), directions.astype(np.float32)


def shadow_rays(origins, directions, hits, light: np.ndarray):
    """Rays from each primary hit toward the light: origins (h, 3) float32 nudged off the
    surface along the normal, directions (h, 3) float32 reaching the light at t = 1, tfar (h,)."""
    hit = np.isfinite(hits.t)
    point = origins[hit].astype(np.float64) + hits.t[hit, None] * directions[hit]
    normal = hits.normal[hit].astype(np.float64)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    # face the side the ray came from; offset by an amount that scales with the coordinates
    normal *= -np.sign(np.einsum("ij,ij->i", normal, directions[hit]))[:, None]
    start = point + normal * (1e-4 * (1.0 + np.abs(point).max(axis=1, keepdims=True)))
    return (
        start.astype(np.float32),
        (light - start).astype(np.float32),
        np.full(len(start), 1.0 - 1e-4, np.float32),
    )


# -- timing ---------------------------------------------------------------------------------------


def best_seconds(call, repeat: int) -> tuple[float, object]:
    """Smallest wall time of ``repeat`` calls (a shared machine only ever adds time)."""
    best, result = math.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = call()
        best = min(best, time.perf_counter() - start)
    return best, result


def measure(bvh: BVH, origins, directions, light, repeat: int) -> dict:
    """Primary and shadow throughput of a committed BVH. Returns a partial row."""
    bvh.intersect(origins[:64], directions[:64])  # compile / warm the kernels outside the clock
    bvh.occluded(origins[:64], directions[:64])
    seconds, hits = best_seconds(lambda: bvh.intersect(origins, directions), repeat)
    s_origins, s_directions, s_tfar = shadow_rays(origins, directions, hits, light)
    s_seconds, blocked = best_seconds(
        lambda: bvh.occluded(s_origins, s_directions, 0.0, s_tfar), repeat
    )
    return {
        "primary_mrays_s": len(origins) / seconds / 1e6,
        "shadow_mrays_s": len(s_origins) / s_seconds / 1e6 if len(s_origins) else None,
        "hit_fraction": float(np.isfinite(hits.t).mean()),
        "shadowed_fraction": float(blocked.mean()) if len(blocked) else None,
        "_hits": hits,
    }


def embreex_run(vertices, faces, origins, directions, threads: int, repeat: int) -> dict:
    """embreex's own build and ``EmbreeScene.run(..., output=1)`` on one baked mesh."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices.astype(np.float32), faces.astype(np.int32))
    scene.run(origins[:64], directions[:64], output=1)  # embreex builds on the first query
    build = time.perf_counter() - start
    chunks = [
        (np.ascontiguousarray(o), np.ascontiguousarray(d))
        for o, d in zip(
            np.array_split(origins, threads), np.array_split(directions, threads), strict=True
        )
    ]
    with ThreadPoolExecutor(threads) as pool:

        def run_all():
            parts = list(pool.map(lambda od: scene.run(od[0], od[1], output=1), chunks))
            return np.concatenate([p["primID"] for p in parts]), np.concatenate(
                [np.where(p["geomID"] >= 0, p["tfar"], np.inf) for p in parts]
            )

        seconds, (prim, t) = best_seconds(run_all, repeat)
    return {
        "build_s": build,
        "primary_mrays_s": len(origins) / seconds / 1e6,
        "hit_fraction": float(np.isfinite(t).mean()),
        "_prim": prim,
        "_t": t,
    }


# -- one sphere count -----------------------------------------------------------------------------


def bench_count(count: int, args: argparse.Namespace, rows: list[dict]) -> None:
    centers, radii, side = sphere_field(count, args.seed)
    ground_vertices, ground_faces = ground(side)
    origins, directions = camera_rays(side, args.rays)
    light = np.array([0.3 * side, 0.7 * side, 0.6 * side + 5.0])
    thread_counts = (1, ALL_THREADS)
    base = {"count": count, "rays": len(origins)}

    def log(message: str) -> None:
        print(f"[{count:>8}] {message}", file=sys.stderr, flush=True)

    # analytic spheres, one BVH per thread count
    analytic_hits = None
    for threads in thread_counts:
        start = time.perf_counter()
        bvh = BVH(threads=None if threads == ALL_THREADS else threads)
        bvh.add_spheres(centers, radii)
        bvh.add_triangles(ground_vertices, ground_faces)
        bvh.commit()
        build = time.perf_counter() - start
        with bvh:
            row = measure(bvh, origins, directions, light, args.repeat)
        analytic_hits = row.pop("_hits")
        rows.append({**base, "geometry": "spheres", "engine": "embree_rt", "threads": threads,
                     "triangles": 2, "build_s": build, **row})  # fmt: skip
        log(f"spheres        threads={threads}: {row['primary_mrays_s']:.2f} Mrays/s")

    # one shared icosphere, instanced per sphere
    ico = trimesh.creation.icosphere(subdivisions=args.subdivisions, radius=1.0)
    transforms = np.zeros((count, 4, 4))
    transforms[:, [0, 1, 2], [0, 1, 2]] = radii[:, None]
    transforms[:, :3, 3] = centers
    transforms[:, 3, 3] = 1.0
    start = time.perf_counter()
    child = BVH()
    child.add_triangles(ico.vertices, ico.faces)
    child.commit()
    top = BVH(threads=None)
    for matrix in transforms:
        top.add_instance(child, matrix)
    top.add_triangles(ground_vertices, ground_faces)
    added = time.perf_counter()
    top.commit()
    committed = time.perf_counter()
    build = {"build_s": committed - start, "add_s": added - start, "commit_s": committed - added}
    instanced = {}
    with top, child:
        for threads in reversed(thread_counts):
            top.threads = threads  # see the module docstring: one build, two thread counts
            row = measure(top, origins, directions, light, args.repeat)
            hits = row.pop("_hits")
            # sanity: tessellated spheres hit where the analytic ones do, bar the silhouettes
            row["hit_agreement_vs_spheres"] = float(
                (np.isfinite(hits.t) == np.isfinite(analytic_hits.t)).mean()
            )
            instanced[threads] = row
            rows.append({**base, "geometry": "instanced-mesh", "engine": "embree_rt",
                         "threads": threads, "triangles": len(ico.faces) * count + 2,
                         **build, **row})  # fmt: skip
            log(f"instanced-mesh threads={threads}: {row['primary_mrays_s']:.2f} Mrays/s")

    # the same triangles baked into one mesh: ours and embreex
    baked_triangles = len(ico.faces) * count + 2
    if baked_triangles > args.max_baked:
        log(f"baked-mesh skipped: {baked_triangles} triangles > --max-baked {args.max_baked:g}")
        return
    vertices = (ico.vertices[None] * radii[:, None, None] + centers[:, None]).reshape(-1, 3)
    faces = (ico.faces[None] + len(ico.vertices) * np.arange(count)[:, None, None]).reshape(-1, 3)
    vertices = np.r_[vertices, ground_vertices]
    faces = np.r_[faces, ground_faces + len(vertices) - 4]
    e_origins, e_directions = origins[: args.embreex_rays], directions[: args.embreex_rays]
    for threads in thread_counts:
        theirs = embreex_run(vertices, faces, e_origins, e_directions, threads, args.repeat)
        their_prim, their_t = theirs.pop("_prim"), theirs.pop("_t")
        rows.append({**base, "rays": len(e_origins), "geometry": "baked-mesh", "engine": "embreex",
                     "threads": threads, "triangles": baked_triangles, **theirs})  # fmt: skip
        log(f"embreex        threads={threads}: {theirs['primary_mrays_s']:.2f} Mrays/s")

        start = time.perf_counter()
        bvh = BVH(threads=None if threads == ALL_THREADS else threads)
        bvh.add_triangles(vertices, faces)
        bvh.commit()
        build = time.perf_counter() - start
        with bvh:
            ours = measure(bvh, e_origins, e_directions, light, args.repeat)
        hits = ours.pop("_hits")
        ours["prim_agreement_vs_embreex"] = float(
            np.mean((hits.prim_id == their_prim) | (~np.isfinite(hits.t) & ~np.isfinite(their_t)))
        )
        ours["vs_embreex"] = ours["primary_mrays_s"] / theirs["primary_mrays_s"]
        rows.append({**base, "rays": len(e_origins), "geometry": "baked-mesh",
                     "engine": "embree_rt", "threads": threads, "triangles": baked_triangles,
                     "build_s": build, **ours})  # fmt: skip
        # the instanced scene against embreex (same rays when --embreex-rays >= --rays)
        if len(e_origins) == len(origins):
            for row in rows:
                key = (row["count"], row["geometry"], row["threads"])
                if key == (count, "instanced-mesh", threads):
                    row["vs_embreex"] = row["primary_mrays_s"] / theirs["primary_mrays_s"]
        log(f"baked-mesh     threads={threads}: {ours['primary_mrays_s']:.2f} Mrays/s")


# -- output ---------------------------------------------------------------------------------------


def markdown(rows: list[dict]) -> str:
    def number(value, digits=2):
        return "" if value is None else f"{value:.{digits}f}"

    lines = [
        "| spheres | geometry | engine | threads | triangles | build s | primary Mrays/s "
        "| shadow Mrays/s | hit % | vs embreex |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        lines.append(
            f"| {row['count']:,} | {row['geometry']} | {row['engine']} | {row['threads']} "
            f"| {row['triangles']:,} | {number(row.get('build_s'), 3)} "
            f"| {number(row.get('primary_mrays_s'))} | {number(row.get('shadow_mrays_s'))} "
            f"| {number(100 * row['hit_fraction'], 1)} | {number(row.get('vs_embreex'))} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", type=lambda s: int(float(s)), nargs="+",
                        default=[1_000, 10_000, 30_000, 100_000, 1_000_000])  # fmt: skip
    parser.add_argument(
        "--rays",
        type=lambda s: int(float(s)),
        default=1_000_000,
        help="primary rays per query (a 16:9 image of about this many pixels)",
    )
    parser.add_argument(
        "--embreex-rays",
        type=lambda s: int(float(s)),
        default=None,
        help="primary rays given to the baked-mesh runs (default: --rays)",
    )
    parser.add_argument(
        "--max-baked",
        type=float,
        default=5e7,
        help="skip the baked-mesh runs above this many triangles",
    )
    parser.add_argument(
        "--subdivisions",
        type=int,
        default=ICOSPHERE_SUBDIVISIONS,
        help="icosphere subdivisions of the tessellated spheres (default: what embree_rt renders "
        "with --spheres mesh, 3: 1280 faces)",
    )
    parser.add_argument("--repeat", type=int, default=2, help="best of this many timed calls")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)  # fmt: skip
    args.embreex_rays = min(args.embreex_rays or args.rays, args.rays)

    rows: list[dict] = []
    start = time.perf_counter()
    for count in args.counts:
        bench_count(count, args, rows)
    config = {
        "rays": args.rays, "embreex_rays": args.embreex_rays, "subdivisions": args.subdivisions,
        "repeat": args.repeat, "all_threads": ALL_THREADS, "cpu_count": os.cpu_count(),
        "seconds": time.perf_counter() - start,
    }  # fmt: skip
    print(json.dumps({"config": config, "rows": rows}, indent=1))
    print(markdown(rows), file=sys.stderr)


if __name__ == "__main__":
    main()
