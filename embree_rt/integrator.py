"""The Whitted integrator as a wavefront: whole batches of rays per bounce, shaded with NumPy.

Per batch of camera samples, and per depth, it reads like pbrt-v4's wavefront integrator:
intersect → escaped rays take the sky → surfaces take ambient + Blinn-Phong light through one
batch of shadow rays for all lights → reflection and refraction children form the next depth.
The seed article's recursion ``color = local·(1−r) + r·trace(reflected)`` (and for glass,
``F·trace(reflected) + (1−F)·trace(refracted)``) becomes a throughput weight carried by each ray.
"""

from __future__ import annotations

import os
import sys
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, TimeoutError
from dataclasses import dataclass, field

import numpy as np

from embree_rt import shading
from embree_rt.camera import camera_frame, primary_rays
from embree_rt.film import Film, FilmBlock
from embree_rt.scene.model import Scene
from embree_rt.shapes import SceneGeometry

DEFAULT_BATCH_SIZE = 1 << 18
# A child whose every channel weighs less than half an 8-bit step cannot change the picture.
MIN_WEIGHT = 1.0 / 512.0
# Secondary rays start this far (relative to the hit's coordinates) off the surface.
RELATIVE_OFFSET = 2.0**-18
RAY_KINDS = ("primary", "shadow", "reflection", "refraction")


@dataclass
class RenderStats:
    """What a render did: ray counts by kind, seconds spent building and rendering."""

    rays: dict[str, int] = field(default_factory=lambda: dict.fromkeys(RAY_KINDS, 0))
    build_s: float = 0.0
    render_s: float = 0.0

    @property
    def total_rays(self) -> int:
        return sum(self.rays.values())

    @property
    def rays_per_s(self) -> float:
        return self.total_rays / self.render_s if self.render_s > 0 else 0.0


@dataclass
class BatchWork:
    """What one batch of camera samples produced: its film block, ray counts, and (for the
    benchmark) the queries it made."""

    block: FilmBlock
    logging: bool = False
    rays: dict[str, int] = field(default_factory=lambda: dict.fromkeys(RAY_KINDS, 0))
    log: list | None = None

    def __post_init__(self) -> None:
        if self.logging:
            self.log = []


@dataclass
class RayBatch:
    """Rays in flight: ``origins``, ``directions`` (n, 3) float32 (unit directions); ``pixel``
    (n,) int64; ``weight`` (n, 3) float32 throughput; ``kind`` the counter they are counted in."""

    origins: np.ndarray
    directions: np.ndarray
    pixel: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return len(self.pixel)

    def take(self, rows: np.ndarray) -> RayBatch:
        # np.take gathers rows several times faster than fancy indexing.
        return RayBatch(
            np.take(self.origins, rows, axis=0),
            np.take(self.directions, rows, axis=0),
            np.take(self.pixel, rows),
            np.take(self.weight, rows, axis=0),
        )


def surface_offset(points: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """(n,) float32 distance to push a ray origin off a surface at ``points`` (n, 3): relative
    to the size of the numbers the hit was computed from, as float32 rounding is (pbrt's
    OffsetRayOrigin bounds the error the same way). ``scale`` (n,) is that size where it exceeds
    the point's own coordinates (``SurfaceHits.scale``: a big object seen near the origin)."""
    size = row_max(np.abs(points))
    if scale is not None:
        size = np.maximum(size, scale)
    return (RELATIVE_OFFSET * (1.0 + size)).astype(np.float32, copy=False)


class Renderer:
    """Renders one scene: builds its BVH once, then ``render()`` traces the image in batches."""

    def __init__(
        self,
        scene: Scene,
        *,
        spheres: str = "analytic",
        threads: int | None = None,
        batch_size: int = DEFAULT_BATCH_SIZE,
    ) -> None:
        if batch_size < 1:
            raise ValueError(f"batch_size: must be >= 1, got {batch_size}")
        self.scene = scene
        self.batch_size = int(batch_size)
        if threads is not None and (int(threads) != threads or threads < 1):
            raise ValueError(f"threads: must be a positive integer, got {threads!r}")
        # Parallel over batches: each worker traces and shades its own batch, calling Embree
        # through single-threaded kernels, so NumPy shading and traversal fill every core.
        self.workers = int(threads) if threads is not None else (os.cpu_count() or 1)
        self.stats = RenderStats()
        start = time.perf_counter()
        self.geometry = SceneGeometry(scene, spheres=spheres, threads=1)
        self.stats.build_s = time.perf_counter() - start
        self.materials = self.geometry.materials
        lights = scene.lights
        self.light_positions = np.array([lt.position for lt in lights], np.float32).reshape(-1, 3)
        self.light_rgb = np.array(
            [np.asarray(lt.color, np.float32) * lt.intensity for lt in lights], np.float32
        ).reshape(-1, 3)
        # When a list, every query is appended as (kind, origins, directions, tfar): the
        # benchmark replays them through the bare BVH to measure pure traversal.
        self.trace_log: list[tuple[str, np.ndarray, np.ndarray, np.ndarray | None]] | None = None
        self.horizon = np.asarray(scene.background.horizon, np.float32)
        self.zenith = np.asarray(scene.background.zenith, np.float32)

    def close(self) -> None:
        self.geometry.close()

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def render(
        self,
        *,
        width: int,
        height: int,
        spp: int,
        max_depth: int,
        seed: int,
        progress: Callable[[int, int], None] | None = None,
    ) -> np.ndarray:
        """The (height, width, 3) float32 linear image. ``progress(done, total)`` counts samples."""
        if spp < 1:
            raise ValueError(f"spp: must be >= 1, got {spp}")
        if max_depth < 0:
            raise ValueError(f"max_depth: must be >= 0, got {max_depth}")
        frame = camera_frame(self.scene.camera, width, height)
        film = Film(width, height)
        total = width * height * spp
        # Batches hold whole pixels and each batch sums into its own block, in ray order, so
        # the image is bitwise the same whatever the batch size or the number of workers.
        step = max(1, self.batch_size // spp) * spp
        starts = range(0, total, step)

        def run(start: int) -> BatchWork:
            count = min(step, total - start)
            work = BatchWork(FilmBlock(start // spp, count // spp), self.trace_log is not None)
            origins, directions, pixel = primary_rays(frame, spp, seed, start, count)
            rays = RayBatch(origins, directions, pixel, np.ones((count, 3), np.float32))
            work.rays["primary"] += count
            self._trace(rays, work, max_depth)
            return work

        began = time.perf_counter()
        # One batch in flight per worker; NumPy's large array operations and the Embree
        # kernels release the GIL, so the workers run side by side.
        pool = ThreadPoolExecutor(max_workers=self.workers)
        try:
            done = 0
            if self.workers > 1:
                results = _ordered_results(pool, run, starts, ahead=self.workers)
            else:
                results = map(run, starts)
            for work in results:
                film.add_block(work.block)
                for kind, n in work.rays.items():
                    self.stats.rays[kind] += n
                if self.trace_log is not None:
                    self.trace_log.extend(work.log)
                done += work.block.count * spp
                self.stats.render_s = time.perf_counter() - began
                if progress is not None:
                    progress(done, total)
        finally:
            # On Ctrl-C or an error, drop the batches not yet started instead of finishing them.
            pool.shutdown(wait=True, cancel_futures=True)
        return film.image(spp)

    # -- one batch, all depths ----------------------------------------------------------------

    def _trace(self, rays: RayBatch, work: BatchWork, max_depth: int) -> None:
        depth = 0
        while len(rays):
            rows, surfaces = self.geometry.intersect_compact(rays.origins, rays.directions)
            if work.log is not None:
                work.log.append(("intersect", rays.origins, rays.directions, None))
            if len(rows) < len(rays):
                escaped = np.ones(len(rays), bool)
                escaped[rows] = False
                sky = shading.sky(rays.directions[escaped], self.horizon, self.zenith)
                work.block.add(rays.pixel[escaped], rays.weight[escaped] * sky)
            rays = self._shade(rays.take(rows), surfaces, work, spawn=depth < max_depth)
            depth += 1

    def _shade(self, rays: RayBatch, surfaces, work: BatchWork, spawn: bool) -> RayBatch:
        table = self.materials
        material = surfaces.material
        position = surfaces.position
        d = rays.directions
        # Shade the side the ray arrived on; a ray leaving a closed object comes from inside.
        entering = shading.dot(d, surfaces.face_normal) < 0
        side = np.where(entering, np.float32(1.0), np.float32(-1.0))[:, None]
        normal = surfaces.normal * side
        face_normal = surfaces.face_normal * side

        color = table.color[material]
        on_floor = np.flatnonzero(surfaces.floor)
        if len(on_floor):
            color[on_floor] = shading.checker(position[on_floor], self.scene.floor.checker)
        reflectivity = table.reflectivity[material]
        transparency = table.transparency[material]
        local = (1.0 - reflectivity) * (1.0 - transparency)

        offset = surface_offset(position, surfaces.scale)[:, None]
        outside = position + face_normal * offset
        radiance = (table.ambient[material] * local)[:, None] * color
        radiance += self._direct_light(
            outside, normal, -d, color, table.diffuse[material] * local, material, work
        )
        work.block.add(rays.pixel, rays.weight * radiance)
        if not spawn:
            return rays.take(np.zeros(0, np.int64))

        reflect_share = reflectivity * (1.0 - transparency)
        children = []
        # Glass splits by Fresnel between reflection and refraction; TIR reflects everything.
        glass = np.flatnonzero(transparency > 0)
        if len(glass):
            d_g, normal_g = np.take(d, glass, axis=0), np.take(normal, glass, axis=0)
            ior = table.ior[material[glass]]
            n1 = np.where(entering[glass], np.float32(1.0), ior)
            n2 = np.where(entering[glass], ior, np.float32(1.0))
            refracted, total_internal = shading.refract(d_g, normal_g, n1 / n2)
            cos_incident = np.clip(-shading.dot(d_g, normal_g), 0.0, 1.0)
            fresnel = shading.fresnel_schlick(cos_incident, n1, n2)
            fresnel[total_internal] = 1.0
            reflect_share[glass] += transparency[glass] * fresnel
            # Glass tints what passes through it (the green marble), not what it reflects.
            weight = np.take(rays.weight, glass, axis=0)
            weight *= (transparency[glass] * (1.0 - fresnel))[:, None] * np.take(
                color, glass, axis=0
            )
            keep = np.flatnonzero(row_max(weight) >= MIN_WEIGHT)
            inside = np.take(position - face_normal * offset, glass, axis=0)
            children.append(
                RayBatch(
                    np.take(inside, keep, axis=0),
                    np.take(refracted, keep, axis=0),
                    rays.pixel[glass[keep]],
                    np.take(weight, keep, axis=0),
                )
            )
            work.rays["refraction"] += len(keep)

        mirrors = np.flatnonzero(reflect_share > 0)
        if len(mirrors):
            weight = np.take(rays.weight, mirrors, axis=0) * reflect_share[mirrors, None]
            metallic = table.metallic[material[mirrors]]
            if metallic.any():
                weight[metallic] *= color[mirrors][metallic]  # metals tint what they reflect
            keep = mirrors[row_max(weight) >= MIN_WEIGHT]
            weight = weight[row_max(weight) >= MIN_WEIGHT]
            reflected = shading.reflect(np.take(d, keep, axis=0), np.take(normal, keep, axis=0))
            origins = np.take(outside, keep, axis=0)
            children.insert(0, RayBatch(origins, reflected, rays.pixel[keep], weight))
            work.rays["reflection"] += len(keep)

        if not children:
            return rays.take(np.zeros(0, np.int64))
        if len(children) == 1:
            return children[0]
        return RayBatch(
            *(np.concatenate([getattr(c, name) for c in children])
              for name in ("origins", "directions", "pixel", "weight"))
        )  # fmt: skip

    def _direct_light(
        self, origins, normal, to_viewer, color, diffuse, material, work: BatchWork
    ) -> np.ndarray:
        """(n, 3) Blinn-Phong light from every point light that the point sees."""
        n = len(origins)
        result = np.zeros((n, 3), np.float32)
        if n == 0 or len(self.light_positions) == 0:
            return result
        # Shadow rays only where the light is in front of the surface; all lights' rays go to
        # Embree as one batch, light-major so each light's rays stay coherent.
        per_light = []
        for position in self.light_positions:
            to_light = position - origins
            distance = np.sqrt(shading.dot(to_light, to_light))
            direction = to_light / np.maximum(distance, 1e-30)[:, None]
            facing = np.flatnonzero(shading.dot(direction, normal) > 0)
            per_light.append((facing, np.take(direction, facing, axis=0), distance[facing]))
        shadow_origins = np.concatenate(
            [np.take(origins, rows, axis=0) for rows, _, _ in per_light]
        )
        shadow_directions = np.concatenate([dirs for _, dirs, _ in per_light])
        shadow_distance = np.concatenate([dist for _, _, dist in per_light])
        blocked = self.geometry.occluded(shadow_origins, shadow_directions, 0.0, shadow_distance)
        if work.log is not None:
            work.log.append(("occluded", shadow_origins, shadow_directions, shadow_distance))
        work.rays["shadow"] += len(blocked)

        table = self.materials
        specular = table.specular[material]
        shininess = table.shininess[material]
        first = 0
        for light, (rows, directions, _) in enumerate(per_light):
            lit = ~blocked[first : first + len(rows)]
            first += len(rows)
            rows, directions = rows[lit], np.take(directions, np.flatnonzero(lit), axis=0)
            if len(rows) == 0:
                continue
            if len(rows) > n // 2:
                # Mostly lit: shade every row with the light switched off where it is not seen,
                # cheaper than gathering five arrays.
                light_rgb = np.zeros((n, 3), np.float32)
                light_rgb[rows] = self.light_rgb[light]
                all_directions = np.zeros((n, 3), np.float32)
                all_directions[rows] = directions
                result += shading.blinn_phong(
                    normal, to_viewer, all_directions, color, diffuse, specular, shininess,
                    light_rgb,
                )  # fmt: skip
                continue
            result[rows] += shading.blinn_phong(
                np.take(normal, rows, axis=0),
                np.take(to_viewer, rows, axis=0),
                directions,
                np.take(color, rows, axis=0),
                diffuse[rows],
                specular[rows],
                shininess[rows],
                self.light_rgb[light],
            )
        return result


def _ordered_results(pool: ThreadPoolExecutor, function, items, ahead: int):
    """``function(item)`` for each item, in order, with at most ``ahead`` extra items running.

    Waits in short slices: a thread blocked on a future without a timeout would not see the
    Ctrl-C that Python delivers to the main thread.
    """
    pending: deque[Future] = deque()
    items = iter(items)
    for item in items:
        pending.append(pool.submit(function, item))
        if len(pending) > ahead:
            yield _wait(pending.popleft())
    while pending:
        yield _wait(pending.popleft())


def _wait(future: Future):
    while True:
        try:
            return future.result(timeout=0.05)
        except TimeoutError:
            continue


def row_max(values: np.ndarray) -> np.ndarray:
    """(n,) largest of each row of an (n, 3) array (column arithmetic: faster than max(axis=1))."""
    return np.maximum(np.maximum(values[:, 0], values[:, 1]), values[:, 2])


def render(
    scene: Scene,
    *,
    width: int | None = None,
    height: int | None = None,
    spp: int | None = None,
    max_depth: int | None = None,
    seed: int | None = None,
    threads: int | None = None,
    spheres: str = "analytic",
    batch_size: int = DEFAULT_BATCH_SIZE,
    quiet: bool = True,
    stats: RenderStats | None = None,
) -> np.ndarray:
    """Render ``scene`` to a (height, width, 3) float32 linear image.

    Arguments left as None come from ``scene.render``. With ``quiet=False`` a progress bar runs
    on stderr (when it is a terminal). Pass a ``RenderStats`` to receive ray counts and timings.
    """
    settings = scene.render
    width = settings.width if width is None else width
    height = settings.height if height is None else height
    spp = settings.spp if spp is None else spp
    max_depth = settings.max_depth if max_depth is None else max_depth
    seed = settings.seed if seed is None else seed
    with Renderer(scene, spheres=spheres, threads=threads, batch_size=batch_size) as renderer:
        bar = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm

            bar = tqdm(total=width * height * spp, unit="sample", unit_scale=True, file=sys.stderr)

        def progress(done: int, total: int) -> None:
            if bar is not None:
                bar.update(done - bar.n)
                bar.set_postfix_str(f"{renderer.stats.rays_per_s / 1e6:.1f} Mrays/s", refresh=False)

        try:
            image = renderer.render(
                width=width, height=height, spp=spp, max_depth=max_depth, seed=seed,
                progress=progress,
            )  # fmt: skip
        finally:
            if bar is not None:
                bar.close()
        if stats is not None:
            stats.rays = dict(renderer.stats.rays)
            stats.build_s = renderer.stats.build_s
            stats.render_s = renderer.stats.render_s
    return image
