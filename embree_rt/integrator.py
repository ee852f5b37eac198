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
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from embree_rt import budget, shading
from embree_rt.batches import batch_ranges, ordered_results
from embree_rt.camera import CameraFrame, camera_frame, sample_rays, tiled_samples
from embree_rt.columns import column_max, scatter, scatter_add
from embree_rt.compiled import retain_freed_memory
from embree_rt.film import Film, FilmBlock
from embree_rt.geometry import SceneGeometry, SurfaceHits, sphere_kind
from embree_rt.materials import MaterialTable
from embree_rt.scene.model import Camera, Scene

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
    """What one batch of camera samples produced: its film block and ray counts."""

    block: FilmBlock
    rays: dict[str, int] = field(default_factory=lambda: dict.fromkeys(RAY_KINDS, 0))


@dataclass
class RayBatch:
    """Rays in flight, one per column: ``origins``, ``directions`` (3, n) float32 (unit
    directions); ``pixel`` (n,) int64; ``weight`` (3, n) float32 throughput. ``origins`` is
    None for rays that have hit: their surface hits hold the points."""

    origins: np.ndarray | None
    directions: np.ndarray
    pixel: np.ndarray
    weight: np.ndarray

    def __len__(self) -> int:
        return len(self.pixel)

    @staticmethod
    def concatenate(batches: list[RayBatch]) -> RayBatch:
        if len(batches) == 1:
            return batches[0]
        return RayBatch(
            np.concatenate([b.origins for b in batches], axis=1),
            np.concatenate([b.directions for b in batches], axis=1),
            np.concatenate([b.pixel for b in batches]),
            np.concatenate([b.weight for b in batches], axis=1),
        )


NO_RAYS = RayBatch(
    np.zeros((3, 0), np.float32), np.zeros((3, 0), np.float32), np.zeros(0, np.int64),
    np.zeros((3, 0), np.float32),
)  # fmt: skip


def surface_offset(scale: np.ndarray) -> np.ndarray:
    """(n,) float32 distance to push a ray origin off a surface whose hit was computed from
    coordinates no larger than ``scale`` (n,) (``SurfaceHits.scale``): relative to that size,
    as float32 rounding is (pbrt's OffsetRayOrigin bounds the error the same way)."""
    return (np.float32(RELATIVE_OFFSET) * (np.float32(1.0) + scale)).astype(np.float32, copy=False)


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
        retain_freed_memory()
        start = time.perf_counter()
        self.geometry = SceneGeometry(scene, spheres=spheres, threads=1)
        self.stats.build_s = time.perf_counter() - start
        # Material ids are the scene's materials in order, then the floor's.
        self.materials = table = MaterialTable.from_materials(
            [*scene.materials.values(), *([scene.floor.material] if scene.floor else [])]
        )
        # Per material: the seed article's blend of local shading, reflection and transmission.
        local = (1.0 - table.reflectivity) * (1.0 - table.transparency)
        self.material_color = np.ascontiguousarray(table.color.T)  # (3, m)
        self.ambient_share = (table.ambient * local).astype(np.float32)
        self.diffuse_share = (table.diffuse * local).astype(np.float32)
        self.reflect_share = (table.reflectivity * (1.0 - table.transparency)).astype(np.float32)
        # Which materials are metals; None when none is (nothing to tint).
        self.metallic = table.metallic if table.metallic.any() else None
        lights = scene.lights
        self.light_positions = np.array([lt.position for lt in lights], np.float32).reshape(-1, 3)
        self.light_rgb = np.array(
            [np.asarray(lt.color, np.float32) * lt.intensity for lt in lights], np.float32
        ).reshape(-1, 3)
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
        camera: Camera | None = None,
    ) -> np.ndarray:
        """The (height, width, 3) float32 linear image. ``progress(done, total)`` counts samples;
        ``camera`` (default the scene's) lets one BVH serve every frame of a camera path."""
        if spp < 1:
            raise ValueError(f"spp: must be >= 1, got {spp}")
        if max_depth < 0:
            raise ValueError(f"max_depth: must be >= 0, got {max_depth}")
        frame = camera_frame(self.scene.camera if camera is None else camera, width, height)
        film = Film(width, height)
        total = width * height * spp
        # Batches hold whole pixels and each batch sums into its own block, in ray order, so
        # the image is bitwise the same whatever the batch size or the number of workers.
        batches = batch_ranges(total, self.batch_size, spp, self.workers)

        def run(batch: tuple[int, int]) -> BatchWork:
            return self.trace_batch(frame, spp, seed, max_depth, *batch)

        began = time.perf_counter()
        # Workers run batches side by side (NumPy's large array operations and the Embree kernels
        # release the GIL); two more batches per worker are queued so that none waits for the
        # oldest batch to finish before starting the next.
        pool = ThreadPoolExecutor(max_workers=self.workers)
        try:
            done = 0
            if self.workers > 1:
                results = ordered_results(pool, run, batches, ahead=2 * self.workers)
            else:
                results = map(run, batches)
            for work in results:
                film.add_block(work.block)
                for kind, n in work.rays.items():
                    self.stats.rays[kind] += n
                done += work.block.count * spp
                self.stats.render_s = time.perf_counter() - began
                if progress is not None:
                    progress(done, total)
        finally:
            # On Ctrl-C or an error, drop the batches not yet started instead of finishing them.
            pool.shutdown(wait=True, cancel_futures=True)
        return film.image(spp)

    def trace_pixels(
        self, frame: CameraFrame, spp: int, seed: int, sample: int, first: int, count: int,
        max_depth: int,
    ) -> FilmBlock:  # fmt: skip
        """The film block of sample ``sample`` (of ``spp``) of each of the ``count`` pixels from
        ``first``: the very rays ``render`` traces for those samples, for a preview that shows
        a render one sample per pixel at a time."""
        if not 0 <= sample < spp:
            raise ValueError(f"sample: must lie in [0, {spp}), got {sample}")
        index = np.arange(first, first + count, dtype=np.int64) * spp + sample
        origins, directions, pixel = sample_rays(frame, spp, seed, index)
        work = BatchWork(FilmBlock(first, count))
        rays = RayBatch(origins, directions, pixel, np.ones((3, count), np.float32))
        work.rays["primary"] += count
        self._trace(rays, work, max_depth)
        return work.block

    # -- one batch, all depths ----------------------------------------------------------------

    def trace_batch(
        self, frame: CameraFrame, spp: int, seed: int, max_depth: int, start: int, count: int
    ) -> BatchWork:
        """Trace and shade the camera samples ``[start, start + count)`` (whole pixels, as
        ``batch_ranges`` cuts them) through every bounce: their film block and ray counts.
        A pure function of its arguments and the scene, so any process holding the same scene
        computes the same block (``embree_rt.distributed`` runs it on Dask workers)."""
        work = BatchWork(FilmBlock(start // spp, count // spp))
        origins, directions, pixel = sample_rays(
            frame, spp, seed, tiled_samples(frame, spp, start, count)
        )
        rays = RayBatch(origins, directions, pixel, np.ones((3, count), np.float32))
        work.rays["primary"] += count
        self._trace(rays, work, max_depth)
        work.block.settle()  # in this worker thread, not in the one adding blocks to the film
        return work

    def _trace(self, rays: RayBatch, work: BatchWork, max_depth: int) -> None:
        depth = 0
        while len(rays):
            rows, surfaces = self.geometry.intersect_compact(
                rays.origins, rays.directions, coherent=depth == 0
            )
            if len(rows) < len(rays):
                escaped = np.ones(len(rays), bool)
                escaped[rows] = False
                escaped = np.flatnonzero(escaped)
                sky = shading.sky(np.take(rays.directions, escaped, axis=1), self.horizon,
                                  self.zenith)  # fmt: skip
                work.block.add(rays.pixel[escaped], np.take(rays.weight, escaped, axis=1) * sky)
            # The hits' origins are not needed again: their surfaces say where they are.
            hit_rays = RayBatch(
                None,
                surfaces.incoming,
                np.take(rays.pixel, rows),
                np.take(rays.weight, rows, axis=1),
            )
            rays = self._shade(hit_rays, surfaces, work, spawn=depth < max_depth)
            depth += 1

    def _shade(
        self, rays: RayBatch, surfaces: SurfaceHits, work: BatchWork, spawn: bool
    ) -> RayBatch:
        """Light the ``surfaces`` that ``rays`` (directions, pixels, weights; no origins) hit,
        into ``work``; returns their reflection and refraction children."""
        d = rays.directions
        normal, face_normal, entering = self.facing_the_ray(d, surfaces)
        color = self.surface_color(surfaces)
        offset = surface_offset(surfaces.scale)
        outside = surfaces.position + face_normal * offset
        material = surfaces.material
        radiance = np.take(self.ambient_share, material) * color
        self._add_direct_light(radiance, outside, normal, -d, color, material, work)
        work.block.add(rays.pixel, rays.weight * radiance)
        if not spawn:
            return NO_RAYS
        reflect_share = np.take(self.reflect_share, material)
        children = self._refraction_children(
            rays, surfaces, normal, face_normal, entering, color, offset, reflect_share, work
        )
        reflected = self._reflection_children(
            rays, outside, normal, color, reflect_share, material, work
        )
        children.insert(0, reflected)
        children = [batch for batch in children if len(batch)]
        return RayBatch.concatenate(children) if children else NO_RAYS

    # -- the stages of shading --------------------------------------------------------------

    @staticmethod
    def facing_the_ray(d: np.ndarray, surfaces: SurfaceHits):
        """Shading and geometric normals (3, k) turned to the side the ray arrived on, and (k,)
        bool whether the ray enters the object (a ray leaving a closed object is inside)."""
        entering = shading.dot(d, surfaces.face_normal) < 0
        side = entering * np.float32(2.0) - np.float32(1.0)  # +1 or -1
        normal = surfaces.normal * side
        face_normal = normal if surfaces.flat else surfaces.face_normal * side
        return normal, face_normal, entering

    def surface_color(self, surfaces: SurfaceHits) -> np.ndarray:
        """(3, k) float32 colour of each hit: its material's, the checker's on the floor."""
        color = np.take(self.material_color, surfaces.material, axis=1)
        if surfaces.colored is not None:  # mesh looks: textures, vertex colours per hit
            scatter(color, surfaces.colored, surfaces.color)
        floor = slice(0, surfaces.floor_count)
        if surfaces.floor_count:
            color[:, floor] = shading.checker(surfaces.position[:, floor], self.scene.floor.checker)
        return color

    def _refraction_children(
        self, rays, surfaces, normal, face_normal, entering, color, offset, reflect_share, work
    ) -> list[RayBatch]:
        """Glass splits by Fresnel between reflection and refraction (total internal reflection
        reflects everything): adds the reflected share to ``reflect_share`` (k,) in place and
        returns the refracted rays, started just inside the surface, tinted by the glass."""
        table = self.materials
        material = surfaces.material
        transparency = np.take(table.transparency, material)
        glass = np.flatnonzero(transparency > 0)
        if len(glass) == 0:
            return []
        d_glass = np.take(rays.directions, glass, axis=1)
        normal_glass = np.take(normal, glass, axis=1)
        ior = table.ior[material[glass]]
        entering_glass = entering[glass]
        n1 = np.where(entering_glass, np.float32(1.0), ior)
        n2 = np.where(entering_glass, ior, np.float32(1.0))
        refracted, total_internal = shading.refract(d_glass, normal_glass, n1 / n2)
        cos_incident = np.clip(-shading.dot(d_glass, normal_glass), 0.0, 1.0)
        fresnel = shading.fresnel_schlick(cos_incident, n1, n2)
        fresnel[total_internal] = 1.0
        reflect_share[glass] += transparency[glass] * fresnel
        # Glass tints what passes through it (the green marble), not what it reflects.
        weight = np.take(rays.weight, glass, axis=1)
        weight *= transparency[glass] * (1.0 - fresnel)
        weight *= np.take(color, glass, axis=1)
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        through = glass[keep]
        inside = np.take(surfaces.position, through, axis=1)
        inside -= np.take(face_normal, through, axis=1) * offset[through]
        work.rays["refraction"] += len(keep)
        return [
            RayBatch(
                inside,
                np.take(refracted, keep, axis=1),
                rays.pixel[through],
                np.take(weight, keep, axis=1),
            )
        ]

    def _reflection_children(
        self, rays, outside, normal, color, reflect_share, material, work
    ) -> RayBatch:
        """Mirrors, metals and glass's Fresnel share reflect: the mirror rays whose weight can
        still show, started just outside the surface. Most hits reflect a little, so the
        weights are formed on every row and only the rows kept are gathered."""
        weight = rays.weight * reflect_share
        if self.metallic is not None:
            # Metals tint what they reflect by their colour; the rest reflect untinted. (Metals
            # are few: three row passes over them beat a tint factor formed on every row.)
            metals = np.flatnonzero(np.take(self.metallic, material))
            for row in range(3):
                weight[row, metals] *= color[row, metals]
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        if len(keep) == 0:
            return NO_RAYS
        reflected = shading.reflect(
            np.take(rays.directions, keep, axis=1), np.take(normal, keep, axis=1)
        )
        work.rays["reflection"] += len(keep)
        return RayBatch(
            np.take(outside, keep, axis=1),
            reflected,
            rays.pixel[keep],
            np.take(weight, keep, axis=1),
        )

    def _add_direct_light(
        self, radiance, points, normal, to_viewer, color, material, work: BatchWork
    ) -> None:
        """Add to ``radiance`` (3, n) the Blinn-Phong light from every point light that the
        ``points`` (3, n) see."""
        n = points.shape[1]
        if n == 0 or len(self.light_positions) == 0:
            return
        # Shadow rays only where the light is in front of the surface: the segment from the
        # point to the light, which the Embree layer builds from the points' columns.
        diffuse = np.take(self.diffuse_share, material)
        specular = np.take(self.materials.specular, material)
        shininess = np.take(self.materials.shininess, material)
        for light, position in enumerate(self.light_positions):
            to_light = position[:, None] - points
            facing = np.flatnonzero(shading.dot(to_light, normal) > 0)
            visible = ~self.geometry.occluded_toward(points, facing, position)
            work.rays["shadow"] += len(facing)
            lit = facing[visible]
            if len(lit) == 0:
                continue
            if len(lit) > n // 2:
                # Mostly lit: shade every point, with no light where it is not seen (a zero
                # direction), cheaper than gathering seven arrays and scattering back.
                seen = np.zeros(n, np.float32)
                seen[facing] = visible
                length = np.sqrt(shading.dot(to_light, to_light))
                direction = to_light * (seen / np.maximum(length, np.float32(1e-30)))
                radiance += shading.blinn_phong(
                    normal, to_viewer, direction, color, diffuse, specular, shininess,
                    self.light_rgb[light],
                )  # fmt: skip
                continue
            scatter_add(
                radiance,
                lit,
                shading.blinn_phong(
                    np.take(normal, lit, axis=1),
                    np.take(to_viewer, lit, axis=1),
                    shading.normalize(np.take(to_light, lit, axis=1)),
                    np.take(color, lit, axis=1),
                    diffuse[lit],
                    specular[lit],
                    shininess[lit],
                    self.light_rgb[light],
                ),
            )


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
    aovs: list[str] | tuple[str, ...] | None = None,
) -> np.ndarray | tuple[np.ndarray, dict[str, np.ndarray]]:
    """Render ``scene`` to a (height, width, 3) float32 linear image.

    Arguments left as None come from ``scene.render``. With ``quiet=False`` a progress bar runs
    on stderr (when it is a terminal). Pass a ``RenderStats`` to receive ray counts and timings.
    With ``aovs`` (names from ``embree_rt.aovs.AOV_NAMES``) it returns the image, bitwise the
    same, and a dict of those AOVs (``embree_rt.aovs.render_aovs``).
    """
    if aovs is not None:
        from embree_rt.aovs import aov_bytes, check_aov_names

        aovs = check_aov_names(aovs)
    settings = scene.render
    width = settings.width if width is None else width
    height = settings.height if height is None else height
    spp = settings.spp if spp is None else spp
    max_depth = settings.max_depth if max_depth is None else max_depth
    seed = settings.seed if seed is None else seed
    # Refuse what cannot fit before building or allocating anything (MemoryBudgetError).
    count = len(scene.sphere_radii)
    needs = budget.render_needs(
        count, sphere_kind(count, spheres), width, height, spp, batch_size,
        workers=threads or os.cpu_count() or 1,
    )  # fmt: skip
    if aovs:
        size, text = needs["image"]
        needs["image"] = (size + aov_bytes(width, height, aovs), f"{text} with AOVs")
    budget.require(needs)
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
        if aovs is None:
            return image
        from embree_rt.aovs import render_aovs

        began = time.perf_counter()
        layers = render_aovs(renderer, width=width, height=height, names=aovs)
        if stats is not None:
            stats.rays["aov"] = width * height  # one pixel-centre ray per pixel
            stats.render_s += time.perf_counter() - began
    return image, layers
