"""AOVs (arbitrary output variables) for dataset makers: depth, normals, albedo, object and
material ids, from one extra ray through each pixel centre.

The beauty image is rendered as always (jittered samples, every bounce); the AOVs come from a
separate pass of one unjittered camera ray per pixel, so ids are exact and edges crisp (as
Mitsuba's ``aov`` integrator and pbrt-v4's ``GBufferFilm`` do). That pass goes through the
renderer's own geometry and shading stages — the hit records of ``SceneGeometry``, the
integrator's surface colour and its normal facing the ray — so an AOV cannot disagree with
what the beauty shades.

- ``depth`` (h, w) float32: distance from the camera position to the first hit along the
  pixel-centre ray; inf where the ray escapes.
- ``z_depth`` (h, w) float32: planar depth, the hit's distance along the camera's viewing
  axis (``depth`` times the cosine of the ray's angle to the axis), what a depth sensor and
  OpenCV's projection take; inf where the ray escapes.
- ``position`` (h, w, 3) float32: the world-space hit point; inf where the ray escapes.
- ``uv`` (h, w, 2) float32: the texture coordinates (u, v) of the hit, interpolated as the
  mesh's base-colour texture is read there; inf where the ray escapes and on hits that have
  none (spheres, the floor, meshes without a texture or shown in a scene material).
- ``normal`` (h, w, 3) float32: unit world-space shading normal, turned to face the camera;
  zero where the ray escapes.
- ``albedo`` (h, w, 3) float32 linear: the surface colour (material colour, a mesh's texture
  or vertex colours, the checker on the floor); zero where the ray escapes.
- ``object_id`` (h, w) int32: spheres numbered in scene order from 0, then each mesh
  placement in scene order; ``FLOOR_ID`` (-2) on the floor, ``NOTHING_ID`` (-1) where the ray
  escapes.
- ``material_id`` (h, w) int32: the scene's materials in order (presets first, as
  ``Scene.materials`` holds them), then the floor's; -1 where the ray escapes.
- ``ao`` (h, w) float32: ambient occlusion, the open share of the hit's cosine-weighted
  hemisphere (1 = unoccluded, and where the ray escapes), with the render's ``ao`` settings
  (``DEFAULT_AO_SAMPLES`` rays when the render has none).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

import numpy as np

from embree_rt import film
from embree_rt.batches import batch_ranges, ordered_results
from embree_rt.camera import (
    camera_rays,
    camera_to_world_opengl,
    intrinsics,
    pixel_center_rays,
    tiled_samples,
    world_to_camera_opencv,
    world_to_camera_opengl,
)
from embree_rt.choices import AOV_NAMES
from embree_rt.columns import scatter
from embree_rt.compiled.camera_rays import sample_rays as sample_ray_columns

if TYPE_CHECKING:
    from embree_rt.camera import CameraFrame
    from embree_rt.geometry import SceneGeometry, SurfaceHits
    from embree_rt.integrator import Integrator
    from embree_rt.scene.model import Scene

NOTHING_ID = -1
FLOOR_ID = -2
# Bytes a pixel of every AOV holds (float32 depths, positions, UVs, normals and albedo, int32 ids),
# for the budget.
AOV_BYTES = {
    "depth": 4,
    "z_depth": 4,
    "position": 12,
    "uv": 8,
    "normal": 12,
    "albedo": 12,
    "object_id": 4,
    "material_id": 4,
    "ao": 4,
}
# The EXR channels of each AOV, in the order of the array's last axis.
EXR_CHANNELS = {
    "depth": ("depth.Z",),
    "z_depth": ("z_depth.Z",),
    "position": ("position.X", "position.Y", "position.Z"),
    "uv": ("uv.U", "uv.V"),
    "normal": ("normal.X", "normal.Y", "normal.Z"),
    "albedo": ("albedo.R", "albedo.G", "albedo.B"),
    "object_id": ("object_id.id",),
    "material_id": ("material_id.id",),
    "ao": ("ao.Y",),
}
# Rays a hit of the ``ao`` AOV when the render has no ambient occlusion of its own.
DEFAULT_AO_SAMPLES = 16
# Output formats that hold every AOV in the one file; the others get one file per AOV beside it.
SINGLE_FILE_SUFFIXES = (".npz", ".exr")


def check_aov_names(names: object) -> tuple[str, ...]:
    """The AOV ``names`` (an iterable of strings from ``AOV_NAMES``) as a tuple without repeats,
    in the order given. Raises ValueError naming the first unknown name, TypeError for a lone
    string (``"depth"`` is not ``["depth"]``) or a non-string."""
    if isinstance(names, str):
        raise TypeError(f"aovs: expected a list of names, got the string {names!r}")
    chosen: list[str] = []
    for name in names:  # type: ignore[attr-defined]
        if not isinstance(name, str):
            raise TypeError(f"aovs: expected names, got {type(name).__name__}")
        if name not in AOV_NAMES:
            raise ValueError(f"unknown AOV {name!r}; choose from {', '.join(AOV_NAMES)}")
        if name not in chosen:
            chosen.append(name)
    return tuple(chosen)


def parse_aov_list(text: str) -> tuple[str, ...]:
    """The names in a comma-separated list such as ``"depth,normal"`` (``check_aov_names``)."""
    names = [part.strip() for part in text.split(",")]
    if "" in names:
        raise ValueError(f"expected names separated by commas, got {text!r}")
    return check_aov_names(names)


def aov_pixel_bytes(names: tuple[str, ...]) -> int:
    """Memory a pixel of the arrays of the AOVs ``names`` takes (``budget.render_needs``)."""
    return sum(AOV_BYTES[name] for name in names)


# -- ids --------------------------------------------------------------------------------------


def hit_object_ids(surfaces: SurfaceHits, geometry: SceneGeometry) -> np.ndarray:
    """(k,) int32 object id of each of the k ``surfaces`` (floor hits first): ``FLOOR_ID`` on
    the floor, the sphere's index in the scene on the sphere set (no instance), and on an
    instance its geometry's first id from ``geometry.object_start`` (by top-level geometry id)
    plus the copy's number in an instance array."""
    object_start = geometry.object_start
    ids = np.empty(len(surfaces), np.int32)
    ids[: surfaces.floor_count] = FLOOR_ID
    rest = slice(surfaces.floor_count, None)
    inst = surfaces.inst_id[rest]
    copy = np.maximum(surfaces.inst_prim_id[rest], 0)
    ids[rest] = np.where(
        inst >= 0,
        np.take(object_start, np.maximum(inst, 0)) + copy,
        geometry.scene_sphere(np.where(inst >= 0, 0, surfaces.prim_id[rest])),
    )
    return ids


# -- the pass ---------------------------------------------------------------------------------


def empty_aovs(names: tuple[str, ...], pixels: int) -> dict[str, np.ndarray]:
    """The AOV arrays of ``pixels`` pixels where every ray escapes: depth (pixels,) inf,
    position (pixels, 3) and uv (pixels, 2) inf, normal and albedo (pixels, 3) zero, ids
    (pixels,) -1."""
    empty = {
        "depth": lambda: np.full(pixels, np.inf, np.float32),
        "z_depth": lambda: np.full(pixels, np.inf, np.float32),
        "position": lambda: np.full((pixels, 3), np.inf, np.float32),
        "uv": lambda: np.full((pixels, 2), np.inf, np.float32),
        "normal": lambda: np.zeros((pixels, 3), np.float32),
        "albedo": lambda: np.zeros((pixels, 3), np.float32),
        "object_id": lambda: np.full(pixels, NOTHING_ID, np.int32),
        "material_id": lambda: np.full(pixels, NOTHING_ID, np.int32),
        "ao": lambda: np.ones(pixels, np.float32),
    }
    return {name: empty[name]() for name in names}


def render_aovs(
    integrator: Integrator, frame: CameraFrame, names: tuple[str, ...], seed: int = 0
) -> dict[str, np.ndarray]:
    """The AOVs ``names`` of ``integrator``'s scene seen through the camera ``frame``: name ->
    (height, width), (height, width, 2) or (height, width, 3) array (see the module's
    docstring for each).

    One ray through each pixel centre, in the integrator's batches and on its workers; each
    batch fills its own pixels, so the result does not depend on the batch size or thread count.
    """
    names = check_aov_names(names)
    width, height = frame.width, frame.height
    if not names:
        return {}
    ao_settings = integrator.scene.render.ao
    if not ao_settings.samples:
        ao_settings = replace(ao_settings, samples=DEFAULT_AO_SAMPLES)
    flat = empty_aovs(names, width * height)

    def fill_vectors(name: str, batch: tuple[int, int], hit: np.ndarray, values) -> None:
        # A batch is a run of pixels: its block of the pixel-major (pixels, c) array, seen as
        # (c, count) columns, takes c cheap 1-D scatters (no transposed copy at the end).
        start, count = batch
        scatter(flat[name][start : start + count].T, hit - start, values)

    def run(batch: tuple[int, int]) -> None:
        origins, directions, pixel = pixel_center_rays(frame, *batch)
        rows, surfaces = integrator.geometry.intersect_compact(origins, directions, coherent=True)
        hit = pixel[rows]
        if "depth" in flat:
            # The rays start at the camera position with unit directions: t is the distance.
            flat["depth"][hit] = surfaces.t
        if "z_depth" in flat:  # t times the cosine to the viewing axis (-w)
            cosine = -(frame.w.astype(np.float32) @ np.take(directions, rows, axis=1))
            flat["z_depth"][hit] = surfaces.t * cosine
        if "position" in flat:
            fill_vectors("position", batch, hit, surfaces.position)
        if "uv" in flat and surfaces.looks.uv is not None:
            # The coordinates the texture lookup used (inf on the untextured among them).
            fill_vectors("uv", batch, hit[surfaces.looks.rows], surfaces.looks.uv)
        # The integrator's own stages, not copies of them: the normal it shades with, turned
        # to the side the ray came from, and the colour it lights.
        if "normal" in flat:
            normal, _, _ = integrator.facing_the_ray(surfaces.incoming, surfaces)
            fill_vectors("normal", batch, hit, normal)
        if "albedo" in flat:
            fill_vectors("albedo", batch, hit, integrator.hit_materials(surfaces).color)
        if "material_id" in flat:
            flat["material_id"][hit] = surfaces.material
        if "object_id" in flat:
            flat["object_id"][hit] = hit_object_ids(surfaces, integrator.geometry)
        if "ao" in flat and len(hit):
            # the beauty's own stage, with the pixel's number as its sample's
            flat["ao"][hit] = integrator.open_shares(surfaces, hit, seed, ao_settings)

    workers = integrator.workers
    batches = batch_ranges(width * height, integrator.batch_size, 1, workers)
    # As the beauty runs its batches: side by side, waiting in slices so Ctrl-C gets through,
    # and on an error or Ctrl-C the batches not yet started are dropped.
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        if workers > 1:
            done = ordered_results(pool, run, batches, ahead=2 * workers)
        else:
            done = map(run, batches)
        for _ in done:
            pass
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return {name: values.reshape(height, width, *values.shape[1:]) for name, values in flat.items()}


def render_coverage(integrator: Integrator, frame: CameraFrame, spp: int, seed: int) -> np.ndarray:
    """(height, width) float32 share of each pixel's ``spp`` camera samples (the very rays the
    beauty traces at ``seed``) that meet something, floor included: the alpha of a render
    with a background of its own. In the integrator's batches; each pixel's count is formed
    inside one batch, so the result does not depend on the batch size or thread count."""
    width, height = frame.width, frame.height
    hits = np.zeros(width * height, np.int64)
    camera = camera_rays(frame, spp, seed)

    def run(batch: tuple[int, int]) -> None:
        start, count = batch
        index, pixel = tiled_samples(frame, spp, start, count)
        origins, directions = sample_ray_columns(camera, index)
        rows, _ = integrator.geometry.intersect_compact(origins, directions, coherent=True)
        first = start // spp
        hits[first : first + count // spp] = np.bincount(
            pixel[rows] - first, minlength=count // spp
        )

    batches = batch_ranges(width * height * spp, integrator.batch_size, spp, integrator.workers)
    workers = integrator.workers
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        done = (
            ordered_results(pool, run, batches, ahead=2 * workers)
            if workers > 1
            else map(run, batches)
        )
        for _ in done:
            pass
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return (hits / np.float64(spp)).astype(np.float32).reshape(height, width)


# -- files ------------------------------------------------------------------------------------


def aov_paths(path: str | os.PathLike, names: tuple[str, ...]) -> dict[str, Path]:
    """Where the AOVs ``names`` go beside the image ``path`` when its format holds one image
    (``.png``, ``.npy``): ``render.depth.png`` and so on; none for ``.npz`` and ``.exr``, which
    hold them all."""
    target = Path(path)
    if target.suffix.lower() in SINGLE_FILE_SUFFIXES:
        return {}
    return {name: target.with_name(f"{target.stem}.{name}{target.suffix}") for name in names}


def camera_data(frame: CameraFrame) -> dict[str, np.ndarray]:
    """The camera of an image, as dataset tools take it: ``K`` (3, 3) float64 intrinsics
    (OpenCV's pixel convention, ``camera.intrinsics``), ``world_to_camera_opencv`` and
    ``world_to_camera_opengl`` (4, 4) float64 extrinsics (OpenCV's axes: y down, looking down
    +z; OpenGL's and Blender's: y up, looking down -z)."""
    return {
        "K": intrinsics(frame),
        "world_to_camera_opencv": world_to_camera_opencv(frame),
        "world_to_camera_opengl": world_to_camera_opengl(frame),
    }


def projection_name(frame: CameraFrame) -> str:
    """How ``frame`` projects, as the camera files name it: "perspective" (K divides by z) or
    "orthographic" (K affine: pixel = K (x, y, 1), fx and fy in pixels per world unit)."""
    return "orthographic" if frame.orthographic else "perspective"


def camera_json_path(path: str | os.PathLike) -> Path:
    """The camera sidecar of the image ``path``: ``render.camera.json`` beside ``render.png``."""
    target = Path(path)
    return target.with_name(f"{target.stem}.camera.json")


def _camera_json(frame: CameraFrame) -> bytes:
    import json

    record = {
        "width": frame.width,
        "height": frame.height,
        "projection": projection_name(frame),
        **{name: matrix.tolist() for name, matrix in camera_data(frame).items()},
    }
    return (json.dumps(record, indent=2) + "\n").encode()


def nerf_transforms(views: list[tuple[Path, CameraFrame]], folder: Path) -> dict:
    """The ``transforms.json`` that NeRF tools read for the images ``views`` (path, the frame
    it was seen through; one image size), their paths relative to ``folder`` (where the file
    goes), extension included: ``camera_angle_x`` (horizontal field of view, radians),
    ``fl_x``, ``fl_y``, ``cx``, ``cy``, ``w``, ``h`` (pixels, centres at c + 1/2 as those tools
    place them), and ``frames[]`` of ``file_path`` and ``transform_matrix``, camera-to-world in
    OpenGL's convention (``camera.camera_to_world_opengl``); a frame whose field of view
    differs from the first's carries its own ``camera_angle_x``, ``fl_x`` and ``fl_y``.
    ``projection`` names how the first frame projects (``projection_name``); an orthographic
    frame has no angle of view (``camera_angle_x`` left out) and its ``fl_x``, ``fl_y`` are
    pixels per world unit."""
    import math
    import os

    def lens(frame: CameraFrame) -> dict:
        K = intrinsics(frame)
        angle = {} if frame.orthographic else {"camera_angle_x": 2.0 * math.atan(frame.half_width)}
        return {**angle, "fl_x": K[0, 0], "fl_y": K[1, 1]}

    first = views[0][1]
    K = intrinsics(first)
    frames = []
    for path, frame in views:
        entry = {
            "file_path": "./" + Path(os.path.relpath(path, folder)).as_posix(),
            "transform_matrix": camera_to_world_opengl(frame).tolist(),
        }
        if lens(frame) != lens(first):  # a zoom: the frame's own (tools read these per frame)
            entry.update(lens(frame))
        frames.append(entry)
    return {
        **lens(first),
        "cx": K[0, 2] + 0.5,
        "cy": K[1, 2] + 0.5,
        "w": first.width,
        "h": first.height,
        "projection": projection_name(first),
        "frames": frames,
    }


def save_with_aovs(
    image: np.ndarray,
    aovs: dict[str, np.ndarray],
    path: str | os.PathLike,
    encoding: film.Encoding = film.DEFAULT_ENCODING,
    camera: CameraFrame | None = None,
) -> list[Path]:
    """Write the (h, w, 3) float32 linear beauty ``image`` and its ``aovs`` (``render_aovs``)
    to ``path`` by its extension, all or nothing (``film.write_atomically``); returns the files
    written besides ``path``.

    ``.npz``: ``beauty`` and one array per AOV under its name. ``.exr``: the beauty as R, G, B
    and the AOVs as the layers of ``EXR_CHANNELS``, float32, the ids as UINT channels holding
    the int32 values' bits (read them back with ``.view(np.int32)``: -1 is 0xFFFFFFFF).
    ``.png`` and the other display formats: the beauty as ``save_image`` writes it (with
    ``encoding``) and each AOV beside it in the same format, visualised (``visualize``, 8
    bits); ``.npy``: the beauty and each AOV's array beside it.

    With ``camera`` (the frame the image was seen through), its ``camera_data`` goes with
    them: as ``.npz`` keys, and as a JSON sidecar (``camera_json_path``) beside every format.
    """
    film.check_output_path(path, encoding)
    image = film.check_image_shape(image, path, encoding)
    target = Path(path)
    suffix = target.suffix.lower()
    beauty = film.linear_picture(image, encoding)  # the data formats' (composited) radiance
    arrays = {} if camera is None else camera_data(camera)
    if suffix == ".npz":
        files = [(target, lambda handle: np.savez(handle, beauty=beauty, **aovs, **arrays))]
    elif suffix == ".exr":
        files = [
            (target, lambda handle: film.write_exr_channels(exr_channels(beauty, aovs), handle))
        ]
    else:
        writer = film.WRITERS[suffix]
        files = [(target, lambda handle: writer(image, handle, encoding))]
        for name, side in aov_paths(target, tuple(aovs)).items():
            files.append((side, _side_writer(suffix, name, aovs[name], encoding)))
    if camera is not None:
        record = _camera_json(camera)
        files.append((camera_json_path(target), lambda handle: handle.write(record)))
    files += film.legend_sidecar(target, encoding)
    film.write_atomically(files)
    return [side for side, _ in files[1:]]


def _side_writer(suffix: str, name: str, values: np.ndarray, encoding: film.Encoding):
    """A writer(handle) of the AOV ``name``'s ``values`` as a file of its own."""

    def write(handle: BinaryIO) -> None:
        if suffix == ".npy":
            film.save_npy(values, handle)
        else:
            film.write_pixels(visualize(name, values), handle, suffix, encoding.quality)

    return write


def exr_channels(beauty: np.ndarray, aovs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The EXR channels of ``beauty`` (h, w, 3) float32 and ``aovs``: "RGB" and the names of
    ``EXR_CHANNELS`` -> (h, w) float32, or uint32 bits of the int32 ids."""
    channels = {"RGB": np.ascontiguousarray(beauty, np.float32)}
    for name, values in aovs.items():
        if values.dtype == np.int32:
            values = values.view(np.uint32)
        planes = values[..., None] if values.ndim == 2 else values
        for axis, channel in enumerate(EXR_CHANNELS[name]):
            channels[channel] = np.ascontiguousarray(planes[..., axis])
    return channels


# -- pictures of the AOVs ---------------------------------------------------------------------


def visualize(name: str, values: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 picture of the AOV ``name``'s ``values`` (as ``render_aovs`` returns).

    depth: inverse depth, nearest hit white, falling toward black with distance (escapes
    black); position: each axis over the range of the hits as RGB; uv: u and v over the range
    of the hits that have them as red and green (the others black); normal: ``(n + 1) / 2``
    as RGB (escapes black); albedo: gamma 2.2; ids: distinct colours (``id_colors``); ao:
    its share as grey."""
    if name == "depth":
        finite = np.isfinite(values)
        # (Never zero: a camera on a surface would make every other depth infinitely far.)
        nearest = max(float(values[finite].min()), 1e-30) if finite.any() else 1.0
        with np.errstate(divide="ignore"):
            level = np.where(finite, nearest / np.maximum(values, nearest), 0.0)
        return np.repeat(_to_bytes(level)[..., None], 3, axis=2)
    if name == "z_depth":
        return visualize("depth", values)
    if name == "position":
        return _over_the_hits(values)
    if name == "uv":  # blue zero
        return _over_the_hits(np.concatenate([values, np.zeros_like(values[..., :1])], axis=-1))
    if name == "normal":
        hit = np.any(values != 0, axis=-1, keepdims=True)
        return _to_bytes(np.where(hit, (values + 1.0) / 2.0, 0.0))
    if name == "albedo":
        return _to_bytes(np.clip(values, 0.0, 1.0) ** (1.0 / film.GAMMA))
    if name == "ao":  # grey: open white, enclosed black
        return np.repeat(_to_bytes(np.clip(values, 0.0, 1.0))[..., None], 3, axis=2)
    if name in ("object_id", "material_id"):
        return id_colors(values)
    raise ValueError(f"unknown AOV {name!r}; choose from {', '.join(AOV_NAMES)}")


def _over_the_hits(values: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 of (h, w, 3) float32 ``values``: each channel over its range among the
    pixels whose values are all finite, the others black (a channel equal everywhere is 0)."""
    finite = np.isfinite(values).all(axis=-1)
    if not finite.any():
        return np.zeros((*values.shape[:2], 3), np.uint8)
    low, high = values[finite].min(axis=0), values[finite].max(axis=0)
    scaled = (values - low) / np.maximum(high - low, 1e-30)
    return _to_bytes(np.where(finite[..., None], scaled, 0.0))


def _to_bytes(values: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(values, np.float64) * 255.0), 0, 255).astype(np.uint8)


def id_colors(ids: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 colour of each int id in ``ids``: black for -1 (nothing), and for every
    other id a colour by a bijection of the 24-bit number ``id + 1`` (an odd multiplier and an
    xor-shift, both invertible mod 2^24), so ids that differ by less than 2^24 never share a
    colour and neighbours look unrelated."""
    code = (np.asarray(ids, np.int64) + 1) & 0xFFFFFF
    code = (code * 0x9E3779) & 0xFFFFFF  # odd: invertible mod 2^24
    code ^= code >> 12
    code = (code * 0x5BD1E9) & 0xFFFFFF  # odd again
    code ^= code >> 11
    rgb = np.stack([(code >> 16) & 0xFF, (code >> 8) & 0xFF, code & 0xFF], axis=-1)
    return rgb.astype(np.uint8)


# -- what `embree-rt info` lists --------------------------------------------------------------

# How many objects of each kind `info` lists one by one before it summarises the rest.
LISTED_PER_KIND = 32


def id_listing(scene: Scene, floor_material: int) -> list[str]:
    """Lines for ``embree-rt info``: the objects and materials with the ids the AOVs give them
    (the first ``LISTED_PER_KIND`` spheres and mesh placements one by one, the rest as ranges;
    each ``instances`` entry as the range of its copies). ``floor_material`` is the floor's
    material id (``SceneGeometry.floor_material``)."""
    spheres = len(scene.sphere_radii)
    placements, instance_starts = scene.object_id_starts()
    names = scene.material_names

    def span(first: int, count: int) -> str:
        return f"{first:,}..{first + count - 1:,}" if count else "none"

    first_mesh = int(placements[0]) if len(placements) else spheres
    copies = sum(len(entry) for entry in scene.instances)
    first_copy = int(instance_starts[0]) if len(instance_starts) else first_mesh + len(placements)
    lines = [
        f"object ids: spheres {span(0, spheres)} in scene order, mesh placements "
        f"{span(first_mesh, len(placements))}, instances {span(first_copy, copies)}, "
        f"curve sets {span(first_copy + copies, len(scene.curves))}, "
        f"floor {FLOOR_ID}, nothing {NOTHING_ID}"
    ]
    for index in range(min(spheres, LISTED_PER_KIND)):
        center = np.round(scene.sphere_centers[index].astype(np.float64), 4).tolist()
        material = int(scene.sphere_materials[index])
        lines.append(
            f"  object {index}: sphere at {center}, radius {float(scene.sphere_radii[index]):g}, "
            f"material {material} ({names[material]})"
        )
    if spheres > LISTED_PER_KIND:
        lines.append(f"  more spheres: ids {LISTED_PER_KIND:,}..{spheres - 1:,} (not listed)")
    for object_id, placement in zip(placements[:LISTED_PER_KIND], scene.meshes, strict=False):
        material = scene.material_index(placement.material)
        position = np.round(placement.transform[:3, 3], 4).tolist()
        lines.append(
            f"  object {object_id}: mesh of {len(placement.mesh.faces):,} triangles at "
            f"{position}, material {material} ({placement.material})"
        )
    if len(placements) > LISTED_PER_KIND:
        lines.append(
            f"  more mesh placements: ids {placements[LISTED_PER_KIND]:,}..{placements[-1]:,} "
            "(not listed)"
        )
    for number, (entry, start) in enumerate(zip(scene.instances, instance_starts, strict=True)):
        lines.append(
            f"  objects {span(int(start), len(entry))}: instances[{number}], {len(entry):,} "
            f"copies of a mesh of {len(entry.mesh.faces):,} triangles"
        )
    lines.append(f"material ids: as listed, nothing {NOTHING_ID}")
    lines += [f"  material {index}: {name}" for index, name in enumerate(names)]
    if scene.floor is not None:
        lines.append(f"  material {floor_material}: floor")
    return lines
