"""The Whitted integrator as a wavefront: whole batches of rays per bounce, shaded with NumPy.

Per batch of camera samples, and per depth, it reads like pbrt-v4's wavefront integrator:
intersect → escaped rays take the sky → surfaces take ambient + Blinn-Phong light through one
batch of shadow rays for all lights → reflection and refraction children form the next depth.
The seed article's recursion ``color = local·(1−r) + r·trace(reflected)`` (and for glass,
``F·trace(reflected) + (1−F)·trace(refracted)``) becomes a throughput weight carried by each ray.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from embree_rt import shading
from embree_rt.ambient_occlusion import open_shares
from embree_rt.batches import batch_ranges, ordered_results, worker_count
from embree_rt.camera import CameraFrame, camera_rays, sample_rays, tiled_samples
from embree_rt.closing import Closing
from embree_rt.columns import column_max, scatter, scatter_add
from embree_rt.compiled import camera_rays as compiled_rays
from embree_rt.compiled import retain_freed_memory
from embree_rt.compiled.camera_rays import CameraRays
from embree_rt.film import Film, FilmBlock
from embree_rt.geometry import SceneGeometry, SurfaceHits
from embree_rt.materials import MaterialTable, shading_shares
from embree_rt.scene.loader import check_scene_values
from embree_rt.scene.model import Scene

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
    directions); ``pixel`` (n,) int64; ``weight`` (3, n) float32 throughput. ``origins`` is
    None for rays that have hit (their surface hits hold the points) and for camera rays not
    yet traced (made inside the query), whose ``directions`` are None until then and whose
    ``weight`` is None: all ones, never spread into an array (1 · x is x, bit for bit).
    ``sample`` (n,) int64: camera rays' global sample indices (what ambient occlusion draws
    its directions from), None for every other ray."""

    origins: np.ndarray | None
    directions: np.ndarray | None
    pixel: np.ndarray
    weight: np.ndarray | None
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
        )


NO_RAYS = RayBatch(
    np.zeros((3, 0), np.float32),
    np.zeros((3, 0), np.float32),
    np.zeros(0, np.int64),
    np.zeros((3, 0), np.float32),
)


def surface_offset(scale: np.ndarray) -> np.ndarray:
    """(n,) float32 distance to push a ray origin off a surface whose hit was computed from
    coordinates no larger than ``scale`` (n,) (``SurfaceHits.scale``): relative to that size,
    as float32 rounding is (pbrt's OffsetRayOrigin bounds the error the same way)."""
    return (np.float32(RELATIVE_OFFSET) * (np.float32(1.0) + scale)).astype(np.float32, copy=False)


def facing_light(
    position: np.ndarray, points: np.ndarray, normal: np.ndarray, takes_light: np.ndarray | None
) -> np.ndarray:
    """(k,) int64 the columns of ``points`` (3, n) float32 whose ``normal`` (3, n) faces the
    light at ``position`` (3,), among those that ``takes_light`` ((n,) bool; None: all)."""
    facing = shading.dot(position[:, None] - points, normal) > 0
    return np.flatnonzero(facing if takes_light is None else facing & takes_light)


class Tracer(Protocol):
    """Where the integrator's two geometric stages come from: the nearest hits of a wavefront
    (``intersect_compact``: the (k,) int64 rays that hit and their ``SurfaceHits``, floor hits
    first) and whether shadow segments are blocked (``occluded_toward``: (k,) bool for the
    segments from ``points[:, rows]`` to ``target``). ``SceneGeometry`` (one BVH of the whole
    scene) is the default; ``bricks.BrickSet`` answers from bricks of it, here or on Dask.
    A tracer may also make camera rays inside its query (``SceneGeometry.intersect_camera``)
    and shadow segments toward every light from the points that face it
    (``SceneGeometry.toward_lights``); one that does not is given camera rays as columns and
    the segments made here, for every light in one query when it answers them so
    (``occluded_toward_each(points, rows_each, targets)``: per target (L, 3), the (k,) bool of
    ``occluded_toward``), else a query a light."""

    def intersect_compact(
        self, origins: np.ndarray, directions: np.ndarray, coherent: bool = False
    ) -> tuple[np.ndarray, SurfaceHits]: ...

    def occluded_toward(
        self, points: np.ndarray, rows: np.ndarray, target: np.ndarray
    ) -> np.ndarray: ...

    def close(self) -> None: ...


class Integrator(Closing):
    """The Whitted integrator of one scene: builds its BVH once, then traces and shades batches
    of camera samples (``render_image``, ``trace_batch``, ``trace_pixels``). ``embree_rt.Renderer``
    adds the public ``render`` to it; Dask workers and the browser preview use it as it is.

    ``spheres``: how spheres enter the BVH (``geometry.SPHERE_MODES``); ``threads``: the worker
    threads (None: every core, ``batches.worker_count``); ``batch_size``: camera samples a batch
    traces at most.

    ``tracer`` replaces the BVH: intersection and occlusion come from it (closed with the
    integrator), shading stays here; ``spheres`` is then unused.

    The scene is first held to a scene file's limits (``scene.loader.check_scene_values``): a
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
    ) -> None:
        check_scene_values(scene)
        if batch_size < 1:
            raise ValueError(f"batch_size: must be >= 1, got {batch_size}")
        self.scene = scene
        self.batch_size = int(batch_size)
        # Parallel over batches: each worker traces and shades its own batch, calling Embree
        # through single-threaded kernels, so NumPy shading and traversal fill every core.
        self.workers = worker_count(threads)
        retain_freed_memory()
        start = time.perf_counter()
        self.geometry: Tracer = tracer
        self._own_geometry = tracer is None
        if tracer is None:
            self.geometry = SceneGeometry(scene, spheres=spheres, threads=1)
        self.build_s = time.perf_counter() - start
        # Material ids are the scene's materials in order, then the floor's.
        self.materials = table = MaterialTable.from_materials(
            [*scene.materials.values(), *([scene.floor.material] if scene.floor else [])]
        )
        # Per material: the seed article's blend of local shading, reflection and transmission.
        self.material_color = np.ascontiguousarray(table.color.T)  # (3, m)
        self.ambient_share, self.diffuse_share, self.reflect_share = shading_shares(
            table.ambient, table.diffuse, table.reflectivity, table.transparency
        )
        # Which materials are metals; None when none is (nothing to tint).
        self.metallic = table.metallic if table.metallic.any() else None
        self.specular = table.specular
        self.transparency = table.transparency
        # Unlit materials show their colour alone: all of it as "ambient", nothing else, and
        # no shadow rays (``lit``: None when every material is lit).
        self.lit = None
        if table.unlit.any():
            self.lit = ~table.unlit
            self.ambient_share = np.where(table.unlit, 1.0, self.ambient_share).astype(np.float32)
            for name in ("diffuse_share", "reflect_share", "specular", "transparency"):
                setattr(
                    self, name, np.where(table.unlit, 0.0, getattr(self, name)).astype(np.float32)
                )
        # (3, m) glow and Beer–Lambert absorption per unit length; None when no material has any.
        self.emission = np.ascontiguousarray(table.emission.T) if table.emission.any() else None
        absorbs = (table.absorption > 0).any()
        self.absorption = np.ascontiguousarray(table.absorption.T) if absorbs else None
        lights = scene.lights
        self.light_positions = np.array([lt.position for lt in lights], np.float32).reshape(-1, 3)
        self.light_rgb = np.array(
            [np.asarray(lt.color, np.float32) * lt.intensity for lt in lights], np.float32
        ).reshape(-1, 3)
        self.camera_sees_sky = scene.render.background == "sky"
        self.ao = scene.render.ao
        if self.ao.samples and not hasattr(self.geometry, "occluded_rays"):
            raise ValueError(
                "render.ao: ambient occlusion needs a tracer that answers occlusion rays "
                "(one BVH: not bricks)"
            )
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
                    stats.rays[kind] += n
                done += work.block.count * spp
                stats.render_s = time.perf_counter() - began
                if progress is not None:
                    progress(done, total, stats)
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
        sample = index if self.ao.samples else None  # (what ambient occlusion draws from)
        rays = RayBatch(origins, directions, pixel, np.ones((3, count), np.float32), sample)
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
        work = BatchWork(FilmBlock(start // spp, count // spp), seed=seed)
        index, pixel = tiled_samples(frame, spp, start, count)
        # Camera rays are made inside the first query, from their sample indices.
        rays = RayBatch(None, None, pixel, None, index if self.ao.samples else None)
        work.rays["primary"] += count
        self._trace(rays, work, max_depth, (camera_rays(frame, spp, seed), index))
        return work

    def _trace(
        self,
        rays: RayBatch,
        work: BatchWork,
        max_depth: int,
        camera: tuple[CameraRays, np.ndarray] | None = None,
    ) -> None:
        """Trace ``rays`` and their children to ``max_depth``; with ``camera`` (its
        ``CameraRays`` and the (n,) sample indices of ``rays``), ``rays`` are those camera
        samples and their origins and directions (None) are made inside the first query."""
        depth = 0
        while len(rays):
            if depth == 0 and camera is not None:
                rows, surfaces, rays.directions = self._camera_hits(*camera)
            else:
                rows, surfaces = self.geometry.intersect_compact(
                    rays.origins, rays.directions, coherent=depth == 0, **self._without_ids()
                )
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
            # (camera rays' unit weights stay None: 1 · x is x, bit for bit)
            weight = None if rays.weight is None else np.take(rays.weight, rows, axis=1)
            sample = None if rays.sample is None else np.take(rays.sample, rows)
            hit_rays = RayBatch(None, surfaces.incoming, np.take(rays.pixel, rows), weight, sample)
            rays = self._shade(hit_rays, surfaces, work, spawn=depth < max_depth)
            depth += 1

    def _camera_hits(
        self, camera: CameraRays, index: np.ndarray
    ) -> tuple[np.ndarray, SurfaceHits, np.ndarray]:
        """The camera samples ``index``' hits (``SceneGeometry.intersect_camera``: rays that
        hit, their surfaces, all (3, n) directions), made inside the query when the tracer can
        (a tracer of bricks is asked for the same rays as columns)."""
        intersect_camera = getattr(self.geometry, "intersect_camera", None)
        if intersect_camera is not None:
            return intersect_camera(camera, index, **self._without_ids())
        origins, directions = compiled_rays.sample_rays(camera, index)
        rows, surfaces = self.geometry.intersect_compact(origins, directions, coherent=True)
        return rows, surfaces, directions

    def _without_ids(self) -> dict:
        """What asks the integrator's own ``SceneGeometry`` to leave Embree's ids of each hit
        out of its records (shading never reads them; they name objects for the AOVs); a
        tracer given to the integrator is asked plainly."""
        return {"ids": False} if self._own_geometry else {}

    def _shade(
        self, rays: RayBatch, surfaces: SurfaceHits, work: BatchWork, spawn: bool
    ) -> RayBatch:
        """Light the ``surfaces`` that ``rays`` (directions, pixels, weights; no origins) hit,
        into ``work``; returns their reflection and refraction children."""
        d = rays.directions
        normal, face_normal, entering = self.facing_the_ray(d, surfaces)
        material = surfaces.material
        if rays.weight is None and (
            self.absorption is not None
            or (surfaces.looks is not None and surfaces.looks.coverage is not None)
        ):
            rays.weight = np.ones((3, len(rays)), np.float32)  # weighed in place below
        if self.absorption is not None:
            self._absorb_inside(rays.weight, surfaces.t, material, entering)
        color = self.surface_color(surfaces)
        offset = surface_offset(surfaces.scale)
        passing = self._see_through(rays, surfaces, face_normal, offset, work, spawn)
        outside = np.multiply(face_normal, offset)
        outside += surfaces.position  # (position + face_normal · offset)
        radiance = self._per_hit(self.ambient_share, surfaces, "ambient_share") * color
        if surfaces.looks is not None and surfaces.looks.occlusion is not None:
            radiance[:, surfaces.looks.rows] *= surfaces.looks.occlusion  # glTF occlusion maps
        if self.ao.samples and rays.sample is not None:  # camera rays' hits: the open share
            radiance *= self._open_shares(outside, normal, surfaces, rays.sample, work.seed)
        self._add_direct_light(radiance, outside, normal, d, color, surfaces, work)
        self._add_emission(radiance, surfaces)
        work.block.add_weighted(rays.pixel, rays.weight, radiance)
        if not spawn:
            return NO_RAYS
        reflect_share = self._per_hit(self.reflect_share, surfaces, "reflect_share")
        children = self._refraction_children(
            rays, surfaces, normal, face_normal, entering, color, offset, reflect_share, work
        )
        reflected = self._reflection_children(
            rays, outside, normal, color, reflect_share, surfaces, work
        )
        children.insert(0, reflected)
        children.append(passing)
        children = [batch for batch in children if len(batch)]
        return RayBatch.concatenate(children) if children else NO_RAYS

    # -- the stages of shading --------------------------------------------------------------

    def open_shares(self, surfaces: SurfaceHits, sample: np.ndarray, seed: int, ao) -> np.ndarray:
        """(k,) float32 ambient occlusion of the k ``surfaces`` (``ambient_occlusion``, ``ao``
        an ``AmbientOcclusion`` with samples) seen by rays with camera sample indices
        ``sample`` (k,) int64 at ``seed``: from just off each surface, about its shading
        normal turned to the ray, as the beauty's stage computes it (the AOV's too)."""
        normal, face_normal, _ = self.facing_the_ray(surfaces.incoming, surfaces)
        outside = np.multiply(face_normal, surface_offset(surfaces.scale))
        outside += surfaces.position
        return self._open_shares(outside, normal, surfaces, sample, seed, ao)

    def _open_shares(self, outside, normal, surfaces, sample, seed, ao=None) -> np.ndarray:
        """Ambient occlusion's stage: one occlusion batch of ``ao`` (the render's by default)
        rays from the points ``outside`` (3, k) about ``normal`` (3, k); (k,) float32 open
        shares, 1 on unlit materials (their colour is not ambient light)."""
        ao = self.ao if ao is None else ao
        share = open_shares(self.geometry.occluded_rays, outside, normal, sample, ao, seed)
        if self.lit is not None:
            share[~self.lit[surfaces.material]] = np.float32(1.0)
        return share

    @staticmethod
    def _per_hit(table: np.ndarray, surfaces: SurfaceHits, name: str) -> np.ndarray:
        """(k,) values of a per-material ``table`` at the hits' materials, with the hits'
        own where a mesh's textures vary it (``HitLooks.shading[name]``)."""
        values = np.take(table, surfaces.material)
        looks = surfaces.looks
        if looks is not None and looks.shading is not None:
            values[looks.rows[looks.shading_at]] = looks.shading[name]
        return values

    def _absorb_inside(self, weight, t, material, entering) -> None:
        """Beer–Lambert: a ray that reaches a glass surface from inside (not ``entering``) has
        crossed ``t`` (k,) of that glass; its ``weight`` (3, k) is multiplied in place by
        ``exp(-absorption · t)`` of the material's (3, m) absorption per unit length."""
        absorption = np.take(self.absorption, material, axis=1)
        inside = np.flatnonzero(~entering & (column_max(absorption) > 0))
        if len(inside) == 0:
            return
        with np.errstate(invalid="ignore"):  # inf absorption over t = 0 absorbs nothing
            optical_depth = np.take(absorption, inside, axis=1) * t[inside]
        optical_depth = np.nan_to_num(optical_depth, nan=0.0)
        weight[:, inside] *= np.exp(-optical_depth)

    def _add_emission(self, radiance, surfaces: SurfaceHits) -> None:
        """Add to ``radiance`` (3, k) the light the surfaces give off themselves: their
        material's ``emission``, or per hit a mesh's emissive texture's."""
        if self.emission is None:
            return
        emission = np.take(self.emission, surfaces.material, axis=1)
        looks = surfaces.looks
        if looks is not None and looks.emission is not None:
            scatter(emission, looks.rows, looks.emission)
        radiance += emission

    def _see_through(self, rays, surfaces, face_normal, offset, work, spawn) -> RayBatch:
        """See-through (glTF BLEND) hits of coverage a: the surface keeps ``a`` of each ray's
        weight (scaled in place, so all it shows and spawns is weighed by it), and ``1 − a``
        goes straight on past it, as a ray started just beyond the surface: returned (no rays
        when none pass, or ``spawn`` is False)."""
        looks = surfaces.looks
        if looks is None or looks.coverage is None:
            return NO_RAYS
        rows = looks.rows
        weight = np.take(rays.weight, rows, axis=1)
        rays.weight[:, rows] = weight * looks.coverage
        if not spawn:
            return NO_RAYS
        weight *= np.float32(1.0) - looks.coverage
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

    def surface_color(self, surfaces: SurfaceHits) -> np.ndarray:
        """(3, k) float32 colour of each hit: its material's, the checker's on the floor."""
        floor = surfaces.floor_count
        color = np.empty((3, len(surfaces)), np.float32)
        # the materials' colours gathered for the hits off the floor alone, straight into
        # place (mode "clip": an ``out`` is not copied first, and the ids are all in range)
        material = surfaces.material[floor:]
        for row, table in zip(color, self.material_color, strict=True):
            np.take(table, material, out=row[floor:], mode="clip")
        if surfaces.colored is not None:  # mesh looks: textures, vertex colours per hit
            scatter(color, surfaces.colored, surfaces.color)
        if floor:
            shading.checker(
                surfaces.position[:, :floor], self.scene.floor.checker, color[:, :floor]
            )
        return color

    def _refraction_children(
        self, rays, surfaces, normal, face_normal, entering, color, offset, reflect_share, work
    ) -> list[RayBatch]:
        """Glass splits by Fresnel between reflection and refraction (total internal reflection
        reflects everything): adds the reflected share to ``reflect_share`` (k,) in place and
        returns the refracted rays, started just inside the surface, tinted by the glass."""
        table = self.materials
        material = surfaces.material
        transparency = self._per_hit(self.transparency, surfaces, "transparency")
        glass = np.flatnonzero(transparency > 0)
        if len(glass) == 0:
            return []
        d_glass = np.take(rays.directions, glass, axis=1)
        normal_glass = np.take(normal, glass, axis=1)
        refracted, _, fresnel = shading.dielectric_split(
            d_glass, normal_glass, entering[glass], table.ior[material[glass]]
        )
        reflect_share[glass] += transparency[glass] * fresnel
        # Glass tints what passes through it (the green marble), not what it reflects.
        if rays.weight is None:
            weight = np.ones((3, len(glass)), np.float32)
        else:
            weight = np.take(rays.weight, glass, axis=1)
        weight *= transparency[glass] * (1.0 - fresnel)
        weight *= np.take(color, glass, axis=1)
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        through = glass[keep]
        inside = np.take(surfaces.position, through, axis=1)
        inside -= np.take(face_normal, through, axis=1) * offset[through]
        work.rays["refraction"] += len(keep)
        if len(keep) < len(glass):  # (when every ray is kept, its arrays are the children's)
            refracted = np.take(refracted, keep, axis=1)
            weight = np.take(weight, keep, axis=1)
        return [RayBatch(inside, refracted, rays.pixel[through], weight)]

    def _reflection_children(
        self, rays, outside, normal, color, reflect_share, surfaces, work
    ) -> RayBatch:
        """Mirrors, metals and glass's Fresnel share reflect: the mirror rays whose weight can
        still show, started just outside the surface. Most hits reflect a little, so the
        weights are formed on every row and only the rows kept are gathered."""
        if rays.weight is None:
            weight = np.repeat(reflect_share[None, :], 3, axis=0)
        else:
            weight = rays.weight * reflect_share
        looks = surfaces.looks
        if self.metallic is not None or (looks is not None and looks.shading is not None):
            # Metals tint what they reflect by their colour; the rest reflect untinted. (Metals
            # are few: three row passes over them beat a tint factor formed on every row.)
            metallic = self.metallic if self.metallic is not None else self.materials.metallic
            metals = np.flatnonzero(self._per_hit(metallic, surfaces, "metallic"))
            for row in range(3):
                weight[row, metals] *= color[row, metals]
        keep = np.flatnonzero(column_max(weight) >= MIN_WEIGHT)
        if len(keep) == 0:
            return NO_RAYS
        work.rays["reflection"] += len(keep)
        if len(keep) == len(weight[0]):  # every hit reflects: no gathers
            return RayBatch(outside, shading.reflect(rays.directions, normal), rays.pixel, weight)
        normal_kept = np.take(normal, keep, axis=1)
        reflected = shading.reflect(
            np.take(rays.directions, keep, axis=1), normal_kept, out=normal_kept
        )
        return RayBatch(
            np.take(outside, keep, axis=1),
            reflected,
            rays.pixel[keep],
            np.take(weight, keep, axis=1),
        )

    def _add_direct_light(
        self, radiance, points, normal, incoming, color, surfaces, work: BatchWork
    ) -> None:
        """Add to ``radiance`` (3, n) the Blinn-Phong light from every point light that the
        ``points`` (3, n) see, toward the viewer against the ``incoming`` (3, n) rays."""
        n = points.shape[1]
        if n == 0 or len(self.light_positions) == 0:
            return
        material = surfaces.material
        diffuse = self._per_hit(self.diffuse_share, surfaces, "diffuse_share")
        specular = self._per_hit(self.specular, surfaces, "specular")
        # Unlit surfaces take no light: no shadow rays for them.
        takes_light = None if self.lit is None else np.take(self.lit, material)
        shininess = self._per_hit(self.materials.shininess, surfaces, "shininess")
        for light, (visible, direction, made) in enumerate(
            self._toward_lights(points, normal, takes_light)
        ):
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

    def _toward_lights(self, points, normal, takes_light):
        """Per light, what the ``points`` (3, n) with facing unit normals ``normal`` (3, n) see
        of it: (n,) bool visible, (3, n) float32 unit directions toward it where visible (zero
        elsewhere), and the shadow rays traced: one segment from each point that faces the
        light and takes light (``takes_light`` (n,) bool, None: all). The tracer's
        ``toward_lights`` when it has one (shadow rays made in its kernel), else the same
        segments made here for its ``occluded_toward``."""
        toward_lights = getattr(self.geometry, "toward_lights", None)
        if toward_lights is not None:
            yield from toward_lights(points, normal, self.light_positions, takes_light)
            return
        facing_each = [
            facing_light(position, points, normal, takes_light) for position in self.light_positions
        ]
        for position, facing, blocked in zip(
            self.light_positions,
            facing_each,
            self._blocked_each(points, facing_each),
            strict=True,
        ):
            visible = np.zeros(points.shape[1], bool)
            visible[facing] = ~blocked
            direction = shading.normalize(position[:, None] - points)
            direction *= visible  # (x · 1 is x: the visible columns' bits stay)
            yield visible, direction, len(facing)

    def _blocked_each(self, points: np.ndarray, facing_each: list[np.ndarray]) -> list[np.ndarray]:
        """Per light, (k,) bool whether the segment from each of the ``points`` (3, n) at its
        rows ``facing_each[light]`` to the light is blocked: in one query when the tracer
        answers every light at once (``occluded_toward_each``: a tracer of bricks on other
        machines pays a round trip a query), else a query a light."""
        each = getattr(self.geometry, "occluded_toward_each", None)
        if each is not None:
            return each(points, facing_each, self.light_positions)
        return [
            self.geometry.occluded_toward(points, facing, position)
            for facing, position in zip(facing_each, self.light_positions, strict=True)
        ]
