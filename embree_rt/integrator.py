"""The Whitted integrator as a wavefront: whole batches of rays per bounce, shaded with NumPy.

Per batch of camera samples, and per depth, it reads like pbrt-v4's wavefront integrator:
intersect → escaped rays take the sky → the hits' materials become columns → surfaces take
ambient + Blinn-Phong light through one shadow query a light → reflection and refraction
children form the next depth. Every geometric query goes to a ``tracer.Tracer`` (pbrt-v4's
Integrator/Aggregate split): ``SceneGeometry`` by default, ``bricks.BrickSet`` for bricks.
The seed article's recursion ``color = local·(1−r) + r·trace(reflected)`` (and for glass,
``F·trace(reflected) + (1−F)·trace(refracted)``) becomes a throughput weight carried by each ray.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from concurrent.futures import CancelledError, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from embree_rt import shading
from embree_rt.ambient_occlusion import AmbientOcclusion, open_shares
from embree_rt.batches import batch_ranges, ordered_results, worker_count
from embree_rt.camera import CameraFrame, camera_rays, sample_rays, tiled_samples
from embree_rt.closing import Closing
from embree_rt.columns import column_max, scatter_add
from embree_rt.compiled import retain_freed_memory
from embree_rt.film import Film, FilmBlock
from embree_rt.geometry import SceneGeometry, SurfaceHits
from embree_rt.materials import HitMaterials, MaterialTable
from embree_rt.scene.model import Scene
from embree_rt.tracer import Tracer

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
    # the render's seed, which ambient occlusion's directions are drawn with
    seed: int = 0


@dataclass
class RayBatch:
    """Rays in flight, one per column: ``origins``, ``directions`` (3, n) float32 (unit
    directions); ``pixel`` (n,) int64; ``weight`` (3, n) float32 throughput. Camera rays'
    origins (the eye) and unit weights are zero-stride views (``camera_batch``): every stage
    reads them as any other, and 1 · x is x, bit for bit. ``sample`` (n,) int64: camera rays'
    global sample indices (what ambient occlusion draws its directions from), carried to the
    rays spawned at hits when ambient occlusion reaches them (``AmbientOcclusion.bounces``),
    else None for those."""

    origins: np.ndarray
    directions: np.ndarray
    pixel: np.ndarray
    weight: np.ndarray
    sample: np.ndarray | None = None

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
            None
            if any(b.sample is None for b in batches)
            else np.concatenate([b.sample for b in batches]),
        )


NO_RAYS = RayBatch(
    np.zeros((3, 0), np.float32),
    np.zeros((3, 0), np.float32),
    np.zeros(0, np.int64),
    np.zeros((3, 0), np.float32),
)


@dataclass(slots=True)
class HitRays:
    """The rays of a batch that hit, as shading reads them (their surfaces hold the points):
    ``directions`` (3, k) float32 unit, ``pixel`` (k,) int64, ``weight`` (3, k) float32,
    ``sample`` (k,) int64 the camera sample indices of camera rays (``RayBatch.sample``),
    None for rays spawned at hits.

    Not a NamedTuple: its ``_replace`` (every bounce, to drop the samples) builds the fields
    as a tuple grown and cut to size, which CPython 3.11 keeps, once freed, in its free list
    of 4-tuples (up to 2000 of 72 bytes): one more a bounce, 43 kB at depth 600."""

    directions: np.ndarray
    pixel: np.ndarray
    weight: np.ndarray
    sample: np.ndarray | None


def camera_batch(
    origin: np.ndarray, directions: np.ndarray, pixel: np.ndarray, sample: np.ndarray
) -> RayBatch:
    """The ``RayBatch`` of n camera rays from one ``origin`` (3,) float32 along ``directions``
    (3, n) float32 of ``pixel`` (n,) int64 and camera sample ``sample`` (n,) int64, weighing
    one: the eye and the ones repeated by zero strides, not copied. (An orthographic camera's
    rays start on its image plane, not at ``origin``; nothing reads camera rays' origins after
    the query that made them: their hits' surfaces hold the points.)"""
    n = len(pixel)
    return RayBatch(
        np.broadcast_to(np.asarray(origin, np.float32)[:, None], (3, n)),
        directions,
        pixel,
        np.broadcast_to(np.float32(1.0), (3, n)),
        sample,
    )


def carried(sample: np.ndarray | None, rows: np.ndarray) -> np.ndarray | None:
    """The (j,) camera sample indices of the children spawned at the hits ``rows`` (j,) of
    rays whose indices are ``sample`` (k,) int64; None when the rays carry none."""
    return None if sample is None else sample[rows]


def surface_offset(scale: np.ndarray) -> np.ndarray:
    """(n,) float32 distance to push a ray origin off a surface whose hit was computed from
    coordinates no larger than ``scale`` (n,) (``SurfaceHits.scale``): relative to that size,
    as float32 rounding is (pbrt's OffsetRayOrigin bounds the error the same way)."""
    return (np.float32(RELATIVE_OFFSET) * (np.float32(1.0) + scale)).astype(np.float32, copy=False)


class Integrator(Closing):
    """The Whitted integrator of one scene: builds its BVH once, then traces and shades batches
    of camera samples (``render_image``, ``trace_batch``, ``trace_pixels``). ``embree_rt.Renderer``
    adds the public ``render`` to it; Dask workers and the browser preview use it as it is.

    ``spheres``: how spheres enter the BVH (``sphere_modes.SPHERE_MODES``); ``threads``: the worker
    threads (None: every core, ``batches.worker_count``); ``batch_size``: camera samples a batch
    traces at most.

    ``tracer`` replaces the BVH: intersection and occlusion come from it (closed with the
    integrator), shading stays here; ``spheres`` is then unused.

    ``cancelled`` is set when a render is abandoned (Ctrl-C, an error): its batches not yet
    begun are dropped, and a tracer given the same event (bricks waiting on their workers)
    stops its waits, so that the render ends now rather than once every batch has. It is
    cleared as each render begins: one render at a time.

    The scene is first held to a scene file's limits (``Scene.check``): a
    value no file could hold, a light of intensity 1e39 say, raises the ``SceneError`` the file
    would (a ValueError) instead of putting NaN in float32 shading and the image."""

    def __init__(
        self,
        scene: Scene,
        *,
        spheres: str = "analytic",
        threads: int | None = None,
        batch_size: int = DEFAULT_BATCH_SIZE,
        tracer: Tracer | None = None,
        movable: bool = False,
        cancelled: threading.Event | None = None,
    ) -> None:
        scene.check()
        if batch_size < 1:
            raise ValueError(f"batch_size: must be >= 1, got {batch_size}")
        self.scene = scene
        self.batch_size = int(batch_size)
        self.cancelled = threading.Event() if cancelled is None else cancelled
        # Parallel over batches: each worker traces and shades its own batch, calling Embree
        # through single-threaded kernels, so NumPy shading and traversal fill every core.
        self.workers = worker_count(threads)
        retain_freed_memory()
        start = time.perf_counter()
        self.geometry: Tracer = (
            SceneGeometry(scene, spheres=spheres, threads=1, movable=movable)
            if tracer is None
            else tracer
        )
        self.build_s = time.perf_counter() - start
        # Material ids are the scene's materials in order, then the floor's.
        self.materials = MaterialTable.from_materials(
            [*scene.materials.values(), *([scene.floor.material] if scene.floor else [])]
        )
        lights = scene.lights
        self.light_positions = np.array([lt.position for lt in lights], np.float32).reshape(-1, 3)
        self.light_rgb = np.array(
            [np.asarray(lt.color, np.float32) * lt.intensity for lt in lights], np.float32
        ).reshape(-1, 3)
        self.camera_sees_sky = scene.render.background == "sky"
        self.ao = scene.render.ao
        self.horizon = np.asarray(scene.background.horizon, np.float32)
        self.zenith = np.asarray(scene.background.zenith, np.float32)

    def close(self) -> None:
        self.geometry.close()

    def render_image(
        self,
        frame: CameraFrame,
        *,
        spp: int,
        max_depth: int,
        seed: int,
        progress: Callable[[int, int, RenderStats], None] | None = None,
    ) -> tuple[np.ndarray, RenderStats]:
        """The (height, width, 3) float32 linear image of the camera ``frame`` (its size is the
        image's), and what tracing it took (``build_s`` is the BVH's, built once for every
        image). ``progress(done, total, stats so far)`` counts samples."""
        if spp < 1:
            raise ValueError(f"spp: must be >= 1, got {spp}")
        if max_depth < 0:
            raise ValueError(f"max_depth: must be >= 0, got {max_depth}")
        width, height = frame.width, frame.height
        stats = RenderStats(build_s=self.build_s)
        film = Film(width, height)
        total = width * height * spp
        # Batches hold whole pixels and each batch sums into its own block, in ray order, so
        # the image is bitwise the same whatever the batch size or the number of workers.
        batches = batch_ranges(total, self.batch_size, spp, self.workers)

        def run(batch: tuple[int, int]) -> BatchWork:
            if self.cancelled.is_set():  # begun as the render was being abandoned
                raise CancelledError
            return self.trace_batch(frame, spp, seed, max_depth, *batch)

        began = time.perf_counter()
        # Workers run batches side by side (NumPy's large array operations and the Embree kernels
        # release the GIL); two more batches per worker are queued so that none waits for the
        # oldest batch to finish before starting the next.
        self.cancelled.clear()
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
                    stats.rays[kind] += n
                done += work.block.count * spp
                stats.render_s = time.perf_counter() - began
                if progress is not None:
                    progress(done, total, stats)
        except BaseException:
            self.cancelled.set()
            raise
        finally:
            # On Ctrl-C or an error, drop the batches not yet started instead of finishing them.
            pool.shutdown(wait=True, cancel_futures=True)
        return film.image(spp), stats

    def trace_pixels(
        self,
        frame: CameraFrame,
        spp: int,
        seed: int,
        sample: int,
        first: int,
        count: int,
        max_depth: int,
    ) -> FilmBlock:
        """The film block of sample ``sample`` (of ``spp``) of each of the ``count`` pixels from
        ``first``: the very rays ``render`` traces for those samples, for a preview that shows
        a render one sample per pixel at a time."""
        if not 0 <= sample < spp:
            raise ValueError(f"sample: must lie in [0, {spp}), got {sample}")
        index = np.arange(first, first + count, dtype=np.int64) * spp + sample
        origins, directions, pixel = sample_rays(frame, spp, seed, index)
        work = BatchWork(FilmBlock(first, count), seed=seed)
        rays = RayBatch(origins, directions, pixel, np.ones((3, count), np.float32), index)
        work.rays["primary"] += count
        rows, surfaces = self.geometry.intersect_compact(origins, directions, True, ids=False)
        self._trace(rays, rows, surfaces, work, max_depth)
        return work.block

    # -- one batch, all depths ----------------------------------------------------------------

    def trace_batch(
        self, frame: CameraFrame, spp: int, seed: int, max_depth: int, start: int, count: int
    ) -> BatchWork:
        """Trace and shade the camera samples ``[start, start + count)`` (whole pixels, as
        ``batch_ranges`` cuts them) through every bounce: their film block and ray counts.
        A pure function of its arguments and the scene, so any process holding the same scene
        computes the same block (``embree_rt.distributed`` runs it on Dask workers)."""
        work = BatchWork(FilmBlock(start // spp, count // spp), seed=seed)
        index, pixel = tiled_samples(frame, spp, start, count)
        # Camera rays are made inside the first query, from their sample indices.
        camera = camera_rays(frame, spp, seed)
        rows, surfaces, directions = self.geometry.intersect_camera(camera, index, ids=False)
        work.rays["primary"] += count
        rays = camera_batch(camera.origin, directions, pixel, index)
        self._trace(rays, rows, surfaces, work, max_depth)
        return work

    def _trace(
        self,
        rays: RayBatch,
        rows: np.ndarray,
        surfaces: SurfaceHits,
        work: BatchWork,
        max_depth: int,
    ) -> None:
        """Shade ``rays``, whose rays ``rows`` (k,) int64 hit ``surfaces``, and trace and
        shade their children to ``max_depth``."""
        depth = 0
        while True:
            # (camera rays that meet nothing show the sky unless the render has a background
            # of its own: the film composites that over the rays that met something)
            if len(rows) < len(rays) and (depth > 0 or self.camera_sees_sky):
                escaped = np.ones(len(rays), bool)
                escaped[rows] = False
                escaped = np.flatnonzero(escaped)
                # the sky depends on the directions' heights alone: gather only those
                sky = shading.sky_at(rays.directions[1][escaped], self.horizon, self.zenith)
                work.block.add_weighted(rays.pixel, rays.weight, sky, escaped)
            # The hits' origins are not needed again: their surfaces say where they are.
            sample = None if rays.sample is None else np.take(rays.sample, rows)
            hit_rays = HitRays(
                surfaces.incoming,
                np.take(rays.pixel, rows),
                np.take(rays.weight, rows, axis=1),
                sample,
            )
            rays = self._shade(hit_rays, surfaces, work, depth < max_depth, depth)
            depth += 1
            if not len(rays):
                return
            rows, surfaces = self.geometry.intersect_compact(
                rays.origins, rays.directions, False, ids=False
            )

    def _shade(
        self, rays: HitRays, surfaces: SurfaceHits, work: BatchWork, spawn: bool, depth: int = 0
    ) -> RayBatch:
        """Light the ``surfaces`` that ``rays`` hit at bounce ``depth``, into ``work``; returns
        their reflection and refraction children (carrying their camera samples when ambient
        occlusion reaches bounces)."""
        d = rays.directions
        normal, face_normal, entering = self.facing_the_ray(d, surfaces)
        hits = self.hit_materials(surfaces)
        if self.materials.outlined:
            self._blacken_outlines(rays.weight, d, normal, hits.outline)
        ambient_share, diffuse_share, reflect_share = hits.shares()
        self._absorb_inside(rays.weight, surfaces.t, hits.absorption, entering)
        offset = surface_offset(surfaces.scale)
        passing = self._see_through(rays, surfaces, hits.coverage, face_normal, offset, work, spawn)
        outside = np.multiply(face_normal, offset)
        outside += surfaces.position  # (position + face_normal · offset)
        radiance = ambient_share * hits.color
        radiance *= hits.occlusion  # (x · 1 is x: the bits of unoccluded hits stay)
        if self.ao.samples and rays.sample is not None:  # camera rays' hits: the open share
            radiance *= self._open_shares(
                outside, normal, hits.lit, rays.sample, work.seed, bounce=depth
            )
        self._add_direct_light(radiance, outside, normal, d, hits, diffuse_share, work)
        if self.materials.glows:
            radiance += hits.emission
        work.block.add_weighted(rays.pixel, rays.weight, radiance)
        if not spawn:
            return NO_RAYS
        if not (self.ao.samples and self.ao.bounces):
            rays = HitRays(rays.directions, rays.pixel, rays.weight, None)
        children = self._refraction_children(
            rays, surfaces, hits, normal, face_normal, entering, offset, reflect_share, work
        )
        reflected = self._reflection_children(rays, outside, normal, hits, reflect_share, work)
        children.insert(0, reflected)
        children.append(passing)
        children = [batch for batch in children if len(batch)]
        return RayBatch.concatenate(children) if children else NO_RAYS

    # -- the stages of shading --------------------------------------------------------------

    def hit_materials(self, surfaces: SurfaceHits) -> HitMaterials:
        """The ``HitMaterials`` of the ``surfaces``: their materials' columns, with what the
        hits show of their own written over them (a mesh's textures and colours, a sphere's
        own colour, the checker's colour on the floor)."""
        floor = surfaces.floor_count
        hits = HitMaterials.gather(self.materials, surfaces.material, color_from=floor)
        surfaces.looks.apply_to(hits, self.materials.glows)
        if len(surfaces.painted):
            hits.color[:, surfaces.painted] = surfaces.paint
        if floor:
            checker = self.scene.floor.checker
            shading.checker(surfaces.position[:, :floor], checker, hits.color[:, :floor])
        return hits

    def open_shares(
        self, surfaces: SurfaceHits, sample: np.ndarray, seed: int, ao: AmbientOcclusion
    ) -> np.ndarray:
        """(k,) float32 ambient occlusion of the k ``surfaces`` (``ambient_occlusion``, ``ao``
        an ``AmbientOcclusion`` with samples) seen by rays with camera sample indices
        ``sample`` (k,) int64 at ``seed``: from just off each surface, about its shading
        normal turned to the ray, as the beauty's stage computes it (the AOV's too)."""
        normal, face_normal, _ = self.facing_the_ray(surfaces.incoming, surfaces)
        outside = np.multiply(face_normal, surface_offset(surfaces.scale))
        outside += surfaces.position
        lit = ~np.take(self.materials.unlit, surfaces.material)
        return self._open_shares(outside, normal, lit, sample, seed, ao)

    def _open_shares(
        self,
        outside: np.ndarray,
        normal: np.ndarray,
        lit: np.ndarray,
        sample: np.ndarray,
        seed: int,
        ao: AmbientOcclusion | None = None,
        bounce: int = 0,
    ) -> np.ndarray:
        """Ambient occlusion's stage: one occlusion batch of ``ao`` (the render's by default)
        rays from the points ``outside`` (3, k) about ``normal`` (3, k); (k,) float32 open
        shares, 1 where not ``lit`` (k,) bool (an unlit colour is not ambient light)."""
        ao = self.ao if ao is None else ao
        occluded = self.geometry.occluded_hemispheres
        share = open_shares(occluded, outside, normal, sample, ao, seed, bounce)
        share[~lit] = np.float32(1.0)
        return share

    @staticmethod
    def _blacken_outlines(weight, d, normal, width) -> None:
        """Outlines: the hits on the outline of their material's ``width`` (k,) float32
        (``shading.on_outline`` of the rays ``d`` (3, k) against their ``normal`` (3, k)
        turned to them) show black: their ``weight`` (3, k) is zeroed in place, so they add
        nothing and spawn no children."""
        cosine = shading.dot(d, normal)
        np.negative(cosine, out=cosine)
        weight[:, shading.on_outline(cosine, width)] = np.float32(0.0)

    @staticmethod
    def _absorb_inside(weight, t, absorption, entering) -> None:
        """Beer–Lambert: a ray that reaches a glass surface from inside (not ``entering``) has
        crossed ``t`` (k,) of that glass; its ``weight`` (3, k) is multiplied in place by
        ``exp(-absorption · t)`` of the hits' (3, k) ``absorption`` per unit length."""
        inside = np.flatnonzero(~entering & (column_max(absorption) > 0))
        if len(inside) == 0:
            return
        with np.errstate(invalid="ignore"):  # inf absorption over t = 0 absorbs nothing
            optical_depth = np.take(absorption, inside, axis=1) * t[inside]
        optical_depth = np.nan_to_num(optical_depth, nan=0.0)
        weight[:, inside] *= np.exp(-optical_depth)

    @staticmethod
    def _see_through(rays, surfaces, coverage, face_normal, offset, work, spawn) -> RayBatch:
        """See-through (glTF BLEND) hits of ``coverage`` a < 1 ((k,) float32): the surface
        keeps ``a`` of each ray's weight (scaled in place, so all it shows and spawns is
        weighed by it), and ``1 − a`` goes straight on past it, as a ray started just beyond
        the surface: returned (no rays when none pass, or ``spawn`` is False)."""
        rows = np.flatnonzero(coverage < 1)
        if len(rows) == 0:
            return NO_RAYS
        covered = coverage[rows]
        weight = np.take(rays.weight, rows, axis=1)
        rays.weight[:, rows] = weight * covered
        if not spawn:
            return NO_RAYS
        weight *= np.float32(1.0) - covered
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        through = rows[keep]
        beyond = np.take(surfaces.position, through, axis=1)
        beyond -= np.take(face_normal, through, axis=1) * offset[through]
        work.rays["refraction"] += len(keep)
        return RayBatch(
            beyond,
            np.take(rays.directions, through, axis=1),
            rays.pixel[through],
            np.take(weight, keep, axis=1),
            carried(rays.sample, through),
        )

    @staticmethod
    def facing_the_ray(d: np.ndarray, surfaces: SurfaceHits):
        """Shading and geometric normals (3, k) turned to the side the ray arrived on, and (k,)
        bool whether the ray enters the object (a ray leaving a closed object is inside)."""
        entering = shading.dot(d, surfaces.face_normal) < 0
        side = entering * np.float32(2.0) - np.float32(1.0)  # +1 or -1
        normal = surfaces.normal * side
        face_normal = normal if surfaces.flat else surfaces.face_normal * side
        return normal, face_normal, entering

    @staticmethod
    def _refraction_children(
        rays, surfaces, hits, normal, face_normal, entering, offset, reflect_share, work
    ) -> list[RayBatch]:
        """Glass splits by Fresnel between reflection and refraction (total internal reflection
        reflects everything): adds the reflected share to ``reflect_share`` (k,) in place and
        returns the refracted rays, started just inside the surface, tinted by the glass."""
        transparency = hits.transparency
        glass = np.flatnonzero(transparency > 0)
        if len(glass) == 0:
            return []
        d_glass = np.take(rays.directions, glass, axis=1)
        normal_glass = np.take(normal, glass, axis=1)
        refracted, _, fresnel = shading.dielectric_split(
            d_glass, normal_glass, entering[glass], hits.ior[glass]
        )
        reflect_share[glass] += transparency[glass] * fresnel
        # Glass tints what passes through it (the green marble), not what it reflects.
        weight = np.take(rays.weight, glass, axis=1)
        weight *= transparency[glass] * (1.0 - fresnel)
        weight *= np.take(hits.color, glass, axis=1)
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        through = glass[keep]
        inside = np.take(surfaces.position, through, axis=1)
        inside -= np.take(face_normal, through, axis=1) * offset[through]
        work.rays["refraction"] += len(keep)
        if len(keep) < len(glass):  # (when every ray is kept, its arrays are the children's)
            refracted = np.take(refracted, keep, axis=1)
            weight = np.take(weight, keep, axis=1)
        sample = carried(rays.sample, through)
        return [RayBatch(inside, refracted, rays.pixel[through], weight, sample)]

    @staticmethod
    def _reflection_children(rays, outside, normal, hits, reflect_share, work) -> RayBatch:
        """Mirrors, metals and glass's Fresnel share reflect: the mirror rays whose weight can
        still show, started just outside the surface. Most hits reflect a little, so the
        weights are formed on every row and only the rows kept are gathered."""
        weight = rays.weight * reflect_share
        # Metals tint what they reflect by their colour; the rest reflect untinted. (Metals
        # are few: three row passes over them beat a tint factor formed on every row.)
        metals = np.flatnonzero(hits.metallic)
        for row in range(3):
            weight[row, metals] *= hits.color[row, metals]
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        if len(keep) == 0:
            return NO_RAYS
        work.rays["reflection"] += len(keep)
        if len(keep) == len(weight[0]):  # every hit reflects: no gathers
            reflected = shading.reflect(rays.directions, normal)
            return RayBatch(outside, reflected, rays.pixel, weight, rays.sample)
        normal_kept = np.take(normal, keep, axis=1)
        reflected = shading.reflect(
            np.take(rays.directions, keep, axis=1), normal_kept, out=normal_kept
        )
        return RayBatch(
            np.take(outside, keep, axis=1),
            reflected,
            rays.pixel[keep],
            np.take(weight, keep, axis=1),
            carried(rays.sample, keep),
        )

    def _add_direct_light(
        self, radiance, points, normal, incoming, hits: HitMaterials, diffuse, work: BatchWork
    ) -> None:
        """Add to ``radiance`` (3, n) the Blinn-Phong light from every point light that the
        ``points`` (3, n) see, toward the viewer against the ``incoming`` (3, n) rays, by the
        hits' colour, ``diffuse`` (n,) share, specular and shininess."""
        n = points.shape[1]
        if n == 0 or len(self.light_positions) == 0:
            return
        color, specular, shininess = hits.color, hits.specular, hits.shininess
        # Unlit surfaces take no light: no shadow rays for them.
        answers = self.geometry.toward_lights(points, normal, self.light_positions, hits.lit)
        for light, (visible, direction, made) in enumerate(answers):
            work.rays["shadow"] += made
            lit_count = np.count_nonzero(visible)
            if lit_count == 0:
                continue
            if lit_count > n // 2:
                # Mostly lit: shade every point, with no light where it is not seen (a zero
                # direction), cheaper than gathering seven arrays and scattering back.
                radiance += shading.blinn_phong(
                    normal,
                    incoming,
                    direction,
                    color,
                    diffuse,
                    specular,
                    shininess,
                    self.light_rgb[light],
                )
                continue
            lit = np.flatnonzero(visible)
            scatter_add(
                radiance,
                lit,
                shading.blinn_phong(
                    np.take(normal, lit, axis=1),
                    np.take(incoming, lit, axis=1),
                    np.take(direction, lit, axis=1),
                    np.take(color, lit, axis=1),
                    diffuse[lit],
                    specular[lit],
                    shininess[lit],
                    self.light_rgb[light],
                ),
            )
