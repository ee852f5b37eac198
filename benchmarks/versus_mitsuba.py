"""Mitsuba 3 beside embree_rt on one random sphere field: warm renders and bare traversal.

The workload (issue 10): N spheres, radii uniform in [0.2, 0.6], resting on the ground y = 0
(centre y = r), centres' x and z uniform in [-S, S] with S = 2·sqrt(N); a pinhole camera at
(0, 0.25·S + 3, -1.2·S) looking at the origin, vertical fov 40°, 1920×1080; one point light at
(S, 2S, -S). Spheres may overlap.

For each count it measures, Mitsuba and embree_rt taking turns (A, B, A, B, ...), and reports
each side's median and the median of the per-pair ratios (the machine is shared: pairs taken
close together keep a ratio fair while the load drifts):

- ``render``: one image at 1 spp, one primary and one shadow ray per pixel. Mitsuba: its
  ``direct`` integrator with ``emitter_samples = 1``, ``bsdf_samples = 0`` (one shadow ray, no
  BSDF ray), an ``independent`` sampler, a box pixel filter, ``mi.render(scene, spp=1)`` and
  ``dr.eval`` + ``dr.sync_thread`` on the image. embree_rt: a ``Renderer`` built once,
  ``.render(..., spp=1, max_depth=0)``. Both scenes are built before the clock (their build
  times are reported apart) and one render of each is discarded first. ``speed_vs_mitsuba`` is
  Mitsuba's time over ours: above 1 we are faster. ``one_call_s`` is the public
  ``embree_rt.render(...)`` once, BVH build included.
- ``traversal``: the bare queries on exactly the same rays, generated once in NumPy: primary
  rays through the 1920×1080 pixel centres, in 4×2 pixel tiles (so each 8-wide packet, which
  both sides use on an AVX2 machine, is one tile), and shadow rays from their hits toward the
  light (the origins of ``traversal.shadow_rays``, unit directions, tfar the distance).
  Mitsuba: ``scene.ray_intersect_preliminary(rays, coherent=True)`` (as its integrator calls
  it for camera rays; t, primitive and shape index evaluated) and ``scene.ray_test(rays)``.
  embree_rt: ``BVH.intersect(..., coherent=True)`` (as the renderer calls it for camera rays)
  and ``BVH.occluded`` on a BVH of ``add_spheres`` plus the ground as two triangles, all
  threads.
- ``agreement``: fraction of primary rays that hit, the fraction on which both name the same
  object (the same sphere, the ground, or nothing), the shadowed fraction, and whether the hit
  fractions agree within ``HIT_FRACTION_TOLERANCE``. ``primary_vs_float64`` says, on a sample,
  which side float64 proves wrong where the two name different objects, and both sides'
  distance errors where they name the same sphere. (Mitsuba's ellipsoid test starts from the
  point t = -o·d / |d| in the sphere's unit space, where |d| = 1/r: the point nearest the
  centre is at -o·d / |d|², so its quadratic cancels on the far, small spheres of big fields.)
  ``mitsuba_render_coverage`` is the mean alpha of Mitsuba's render (pixels whose sample hit).
  With ``--images DIR`` both renders are saved at a quarter of the size, to look at.

Differences that remain: embree_rt's floor is its analytic infinite checker plane; Mitsuba's is
a ``rectangle`` of half-size ``GROUND_HALF_SIZE``·S (in the bare traversal both have that quad),
so it ends a few pixels below the horizon (Mitsuba's camera ``far_clip`` is raised to reach it).
Mitsuba's picture is diffuse only (a checkerboard texture on the ground); embree_rt shades
Blinn-Phong with ambient light and a sky. Mitsuba's ellipsoids cull back faces (a ray starting
inside a sphere misses it), ours return the exit hit.

Dr.Jit compiles each distinct kernel once per process (and keeps compiled kernels on disk, in
~/.drjit, across processes); the discarded first render pays tracing and any compilation, and
``kernels`` reports, from ``dr.kernel_history``, how many kernels the first and a warm render
launched and how many of those came from the cache. A warm render still traces the integrator
in Python/C++ every call: that is part of what Mitsuba costs per image, and is timed.

Mitsuba is optional (``pip install -e '.[bench]'``). Its llvm variant needs an LLVM shared
library; on Debian 12: ``apt-get install libllvm19`` and
``DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1`` (set to that path by this
script when unset and the file exists). Without Mitsuba, or when its llvm variant cannot load,
the JSON says so and why, and the embree_rt side is still measured.

With ``--instances N ...`` it also compares instancing (issue 12), for each N: the spheres of
the N-sphere field replaced by copies of one 320-triangle icosphere (scaled to each radius,
turned about y at random), beside the same ground quad. embree_rt: one instance array,
``BVH.add_instances``; Mitsuba: a ``shapegroup`` holding the mesh (a temporary ``.ply``) and one
``instance`` per copy, as its documentation describes. Reported: each side's build (our
matrices to a committed BVH; Mitsuba's ``load_dict`` of the scene), the bare primary queries
on the pixel-centre rays in turns, and how many rays agree (both miss, or both hit within a
distance tolerance). Mitsuba builds a scene description per copy in Python, so its build time
grows fastest; pick N accordingly (1e5 takes Mitsuba about 15 s here).

    python benchmarks/versus_mitsuba.py                          # 1e3, 1e5, 1e6 spheres
    python benchmarks/versus_mitsuba.py --counts 1000 --repeat 3 --images /tmp/versus
    python benchmarks/versus_mitsuba.py --counts --instances 1000 10000 100000

Prints one JSON object on stdout; progress on stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.metadata
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from traversal import shadow_rays  # run as a script: benchmarks/ is on sys.path

import embree_rt
from embree_rt import Renderer
from embree_rt.camera import camera_frame
from embree_rt.embree import BVH, Rays

DEBIAN_LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"
MITSUBA_VARIANT = "llvm_ad_rgb"
WIDTH, HEIGHT, FOV = 1920, 1080, 40.0
TILE = (4, 2)  # pixels across, down: one 8-wide packet
# The ground quad's half-size in units of S: wide enough that it reaches within a few pixels of
# the horizon, so it covers about what embree_rt's infinite floor does.
GROUND_HALF_SIZE = 100.0
# Primary hit fractions may differ by silhouette rays (float32 rounding, different quadratics)
# and where the sides' geometry differs (rays starting inside, see the docstring): not more.
HIT_FRACTION_TOLERANCE = 1e-3
SPHERE_ALBEDO = (0.7, 0.25, 0.2)
VERDICT_SAMPLE = 20_000  # rays checked in float64, per kind (see float64_verdict)


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# -- the workload ---------------------------------------------------------------------------------


def sphere_field(count: int, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Issue 10's field: centres (count, 3) float32 with y = r, radii (count,) float32 in
    [0.2, 0.6], and S = 2·sqrt(count), the half-width of the square the centres fill."""
    rng = np.random.default_rng(seed)
    side = 2.0 * math.sqrt(count)
    radii = rng.uniform(0.2, 0.6, count)
    centers = np.c_[rng.uniform(-side, side, count), radii, rng.uniform(-side, side, count)]
    return centers.astype(np.float32), radii.astype(np.float32), side


def ground_quad(side: float) -> tuple[np.ndarray, np.ndarray]:
    """The ground y = 0 as vertices (4, 3) float64 and faces (2, 3) int64, facing up (+y)."""
    h = GROUND_HALF_SIZE * side
    vertices = np.array([[-h, 0, -h], [-h, 0, h], [h, 0, h], [h, 0, -h]], float)
    return vertices, np.array([[0, 1, 2], [0, 2, 3]])


def camera(side: float) -> embree_rt.Camera:
    return embree_rt.Camera(
        position=(0.0, 0.25 * side + 3.0, -1.2 * side),
        look_at=(0.0, 0.0, 0.0),
        up=(0.0, 1.0, 0.0),
        fov=FOV,
    )


def light_position(side: float) -> tuple[float, float, float]:
    return (side, 2.0 * side, -side)


def tile_order(width: int, height: int) -> np.ndarray:
    """(width·height,) int64 row-major pixel indices in 4×2 tiles: tiles left to right, rows
    of tiles top to bottom, pixels row-major inside a tile."""
    tx, ty = TILE
    pixels = np.arange(width * height).reshape(height // ty, ty, width // tx, tx)
    return pixels.transpose(0, 2, 1, 3).reshape(-1)


def pixel_centre_rays(cam: embree_rt.Camera, width: int, height: int):
    """Primary rays through the pixel centres, in ``tile_order``: origins and unit directions,
    (n, 3) float32, with embree_rt's camera frame (the one its renderer uses)."""
    frame = camera_frame(cam, width, height)
    pixel = tile_order(width, height)
    x = (pixel % width + 0.5) / width
    y = (pixel // width + 0.5) / height
    directions = (
        ((2.0 * x - 1.0) * frame.half_width)[:, None] * frame.u
        + ((1.0 - 2.0 * y) * frame.half_height)[:, None] * frame.v
        - frame.w
    )
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.broadcast_to(frame.origin, directions.shape)
    return np.ascontiguousarray(origins, np.float32), directions.astype(np.float32)


def unit_shadow_rays(origins, directions, hits, light: np.ndarray):
    """``traversal.shadow_rays`` (same origins) with unit directions and tfar the distance:
    origins, directions (h, 3) float32, tfar (h,) float32. Mitsuba's ellipsoid test assumes unit
    directions (it finds the point nearest the centre as t = -o·d / |d|, not / |d|²) and loses
    precision without them."""
    _, s_origins, to_light, s_tfar = shadow_rays(origins, directions, hits, light)
    length = np.linalg.norm(to_light.astype(np.float64), axis=1)
    s_directions = (to_light / length[:, None]).astype(np.float32)
    return s_origins, s_directions, (s_tfar * length).astype(np.float32)


def embree_rt_scene(centers, radii, side: float) -> embree_rt.Scene:
    scene = embree_rt.Scene(
        camera=camera(side),
        floor=embree_rt.Floor(height=0.0),
        lights=[embree_rt.PointLight(position=light_position(side))],
    )
    scene.add_material("albedo", embree_rt.Material(color=SPHERE_ALBEDO))
    scene.add_spheres(centers, radii, "albedo")
    return scene


# -- Mitsuba --------------------------------------------------------------------------------------


def load_mitsuba() -> tuple[object, object, dict]:
    """(mitsuba, drjit, info) with the llvm variant set, or (None, None, info saying why)."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(DEBIAN_LLVM):
        os.environ["DRJIT_LIBLLVM_PATH"] = DEBIAN_LLVM
    info = {"variant": MITSUBA_VARIANT, "DRJIT_LIBLLVM_PATH": os.environ.get("DRJIT_LIBLLVM_PATH")}
    try:
        import mitsuba as mi
    except ImportError as error:
        reason = f"mitsuba is not importable ({error}); pip install -e '.[bench]'"
        return None, None, {**info, "available": False, "reason": reason}
    info["mitsuba"] = mi.__version__
    try:
        mi.set_variant(MITSUBA_VARIANT)
        import drjit as dr

        dr.eval(dr.arange(dr.llvm.Float, 8) + 1)  # the LLVM backend loads on first use
    except Exception as error:
        reason = (
            f"the {MITSUBA_VARIANT} variant cannot run: {error} "
            f"(on Debian: apt-get install libllvm19, DRJIT_LIBLLVM_PATH={DEBIAN_LLVM})"
        )
        return None, None, {**info, "available": False, "reason": reason}
    info.update(available=True, drjit=dr.__version__, threads=dr.thread_count())
    return mi, dr, info


def mitsuba_scene(mi, centers, radii, side: float):
    """The field as a Mitsuba scene: every sphere in one ``ellipsoids`` shape (centre, scale =
    radius on each axis, identity quaternion (x, y, z, w) = (0, 0, 0, 1), ``extent`` 1: its
    default of 3 would triple the radii), a ``rectangle`` ground, the point light."""
    data = np.zeros((len(radii), 10), np.float32)
    data[:, 0:3] = centers
    data[:, 3:6] = radii[:, None]
    data[:, 9] = 1.0
    h = GROUND_HALF_SIZE * side
    cam = camera(side)
    transform = mi.ScalarTransform4f()
    return mi.load_dict(
        {
            "type": "scene",
            # Point lights cannot be seen directly: hide_emitters changes nothing but says so.
            "integrator": {
                "type": "direct",
                "emitter_samples": 1,
                "bsdf_samples": 0,
                "hide_emitters": True,
            },
            "sensor": {
                "type": "perspective",
                "fov": FOV,
                "fov_axis": "y",
                # The default far clip (1e4) would cut the ground off short of the horizon.
                "far_clip": 10.0 * GROUND_HALF_SIZE * side,
                "to_world": transform.look_at(
                    origin=list(cam.position), target=list(cam.look_at), up=list(cam.up)
                ),
                "sampler": {"type": "independent", "sample_count": 1},
                "film": {
                    "type": "hdrfilm",
                    "width": WIDTH,
                    "height": HEIGHT,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgba",
                },
            },
            "spheres": {
                "type": "ellipsoids",
                "data": mi.TensorXf(data),
                "extent": 1.0,
                "bsdf": {
                    "type": "diffuse",
                    "reflectance": {"type": "rgb", "value": list(SPHERE_ALBEDO)},
                },
            },
            # The rectangle spans [-1, 1]² in z = 0 facing +z; turned to face +y. Checker squares
            # of side 1, as embree_rt's floor (uv spans [0, 1] over 2h; the texture's period is 1).
            "ground": {
                "type": "rectangle",
                "to_world": transform.rotate([1, 0, 0], -90).scale(h),
                "bsdf": {
                    "type": "diffuse",
                    "reflectance": {
                        "type": "checkerboard",
                        "color0": 0.8,
                        "color1": 0.15,
                        "to_uv": transform.scale([h, h, 1.0]),
                    },
                },
            },
            "light": {
                "type": "point",
                "position": list(light_position(side)),
                # radiance ~ albedo/π · I/d² with d ≈ 2.45 S: about 0.5 at the field
                "intensity": {"type": "rgb", "value": 10.0 * side * side},
            },
        }
    )


def mitsuba_rays(mi, dr, origins, directions, tfar=None):
    ray = mi.Ray3f(mi.Point3f(origins.T), mi.Vector3f(directions.T))
    if tfar is not None:
        ray.maxt = mi.Float(tfar)
    dr.eval(ray)
    dr.sync_thread()
    return ray


def kernel_stats(dr, call) -> dict:
    """Run ``call`` recording Dr.Jit's kernel launches: how many, how many came from its
    in-memory or disk cache, and the seconds spent generating and compiling code."""
    dr.kernel_history()  # drop what was recorded before
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        call()
        dr.sync_thread()
    jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    return {
        "kernels": len(jit),
        "cache_hits": sum(bool(k.get("cache_hit")) for k in jit),
        "disk_cache_hits": sum(bool(k.get("cache_disk")) for k in jit),
        "compile_s": round(
            sum(k.get("codegen_time", 0) + k.get("backend_time", 0) for k in jit) / 1e3, 4
        ),
    }


# -- timing ---------------------------------------------------------------------------------------


def seconds(call) -> tuple[float, object]:
    start = time.perf_counter()
    result = call()
    return time.perf_counter() - start, result


def in_turns(ours, theirs, repeat: int) -> tuple[list[float], list[float]]:
    """Wall times of ``repeat`` alternating calls: ours, theirs, ours, theirs, ..."""
    ours_s, theirs_s = [], []
    for _ in range(repeat):
        ours_s.append(seconds(ours)[0])
        if theirs is not None:
            theirs_s.append(seconds(theirs)[0])
    return ours_s, theirs_s


def summary(ours_s: list[float], theirs_s: list[float], rays: int | None = None) -> dict:
    """Medians, and the median over pairs of their time / ours (above 1: we are faster)."""
    row = {
        "embree_rt_s": [round(s, 4) for s in ours_s],
        "embree_rt_median_s": round(statistics.median(ours_s), 4),
    }
    if rays is not None:
        row["embree_rt_mrays_s"] = round(rays / statistics.median(ours_s) / 1e6, 2)
    if theirs_s:
        row["mitsuba_s"] = [round(s, 4) for s in theirs_s]
        row["mitsuba_median_s"] = round(statistics.median(theirs_s), 4)
        if rays is not None:
            row["mitsuba_mrays_s"] = round(rays / statistics.median(theirs_s) / 1e6, 2)
        ratios = [t / o for o, t in zip(ours_s, theirs_s, strict=True)]
        row["speed_vs_mitsuba"] = round(statistics.median(ratios), 3)
    return row


# -- one sphere count -----------------------------------------------------------------------------


def labels(is_hit: np.ndarray, on_spheres: np.ndarray, prim: np.ndarray) -> np.ndarray:
    """(n,) int64 object per ray: the sphere's index, -1 for the ground, -2 for nothing."""
    return np.where(is_hit, np.where(on_spheres, prim.astype(np.int64), -1), -2)


def exact_t(origins, directions, tfar, label, centers, radii, ground_half_size: float):
    """(n,) float64 ray parameter t at which each ray (origins, directions (n, 3) float32, taken
    exactly; ``tfar`` scalar or (n,)) meets the object ``label`` (n,) names (see ``labels``):
    inf for nothing, nan when the ray misses it within [0, tfar]. Spheres are solved in float64
    from the perpendicular offset (robust for far, small spheres)."""
    o, d = origins.astype(np.float64), directions.astype(np.float64)
    tfar = np.broadcast_to(np.asarray(tfar, np.float64), len(label))
    t = np.full(len(label), np.inf)
    ground = np.flatnonzero(label == -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tg = -o[ground, 1] / d[ground, 1]
        x, z = (o[ground, k] + tg * d[ground, k] for k in (0, 2))
    inside = (np.abs(x) <= ground_half_size) & (np.abs(z) <= ground_half_size)
    t[ground] = np.where(inside & (tg >= 0) & (tg <= tfar[ground]), tg, np.nan)
    sphere = np.flatnonzero(label >= 0)
    length = np.linalg.norm(d[sphere], axis=1)
    unit = d[sphere] / length[:, None]
    f = o[sphere] - centers[label[sphere]].astype(np.float64)
    b = np.einsum("ij,ij->i", f, unit)
    perpendicular = f - b[:, None] * unit
    r = radii[label[sphere]].astype(np.float64)
    with np.errstate(invalid="ignore"):
        half_chord = np.sqrt(r * r - np.einsum("ij,ij->i", perpendicular, perpendicular))
    near, far = (-b - half_chord) / length, (-b + half_chord) / length
    ts = np.where(near >= 0, near, far)
    t[sphere] = np.where((ts >= 0) & (ts <= tfar[sphere]), ts, np.nan)
    return t


def float64_verdict(origins, directions, tfar, ours, theirs, field, nearest: bool) -> dict:
    """Who float64 proves wrong on (a sample of at most ``VERDICT_SAMPLE`` of) the rays where the
    labels ``ours`` and ``theirs`` (n,) differ. ``field`` = (centers, radii, ground half-size).
    A side is wrong when the ray misses the object it names, or names nothing while the other
    side's object is there; with ``nearest`` (closest-hit queries), also when the other side's
    object is nearer."""
    rng = np.random.default_rng(0)
    differ = np.flatnonzero(ours != theirs)
    differ = rng.choice(differ, min(VERDICT_SAMPLE, len(differ)), replace=False)
    o, d = origins[differ], directions[differ]
    tfar = np.broadcast_to(tfar, len(ours))[differ]
    t_ours = exact_t(o, d, tfar, ours[differ], *field)
    t_theirs = exact_t(o, d, tfar, theirs[differ], *field)

    def wrong(mine, other):
        missed = np.isnan(mine) | (np.isinf(mine) & np.isfinite(other))
        return int((missed | (other < mine) if nearest else missed).sum())

    return {
        "disagreements": int((ours != theirs).sum()),
        "checked": len(differ),
        "embree_rt_wrong": wrong(t_ours, t_theirs),
        "mitsuba_wrong": wrong(t_theirs, t_ours),
    }


def distance_errors(origins, directions, ours, theirs, ours_t, theirs_t, field) -> dict:
    """Relative errors of both sides' t against float64 where both name the same sphere (a
    sample of at most ``VERDICT_SAMPLE`` rays; grazing rays that float64 says miss are left
    out): median and 99th percentile per side."""
    rng = np.random.default_rng(0)
    same = np.flatnonzero((ours == theirs) & (ours >= 0))
    same = rng.choice(same, min(VERDICT_SAMPLE, len(same)), replace=False)
    exact = exact_t(origins[same], directions[same], np.inf, ours[same], *field)
    keep = np.isfinite(exact)
    errors = {}
    for name, t in (("embree_rt", ours_t), ("mitsuba", theirs_t)):
        error = np.abs(t[same][keep] - exact[keep]) / exact[keep]
        errors[name] = {"median": float(np.median(error)), "p99": float(np.percentile(error, 99))}
    return {"checked": int(keep.sum()), **errors}


def our_labels(bvh: BVH, sphere_geometry: int, origins, directions, tfar=np.inf):
    """``labels`` and t (n,) float32 of embree_rt's nearest hits."""
    hits = bvh.intersect(Rays(origins, directions, 0.0, tfar))
    return labels(hits.hit, hits.geom_id == sphere_geometry, hits.prim_id), hits.t


def their_labels(mi, dr, scene, origins, directions, tfar=None, coherent: bool = False):
    """``labels`` and t (n,) float32 of Mitsuba's nearest hits (``ray_intersect_preliminary``;
    its answers on the same rays differ with ``coherent``, its Embree query flag)."""
    rays = mitsuba_rays(mi, dr, origins, directions, tfar)
    found = scene.ray_intersect_preliminary(rays, coherent=coherent)
    t = np.array(found.t)
    spheres_index = [shape.id() for shape in scene.shapes()].index("spheres")
    on_spheres = np.array(found.shape_index) == spheres_index
    return labels(np.isfinite(t), on_spheres, np.array(found.prim_index)), t


def save_preview(image: np.ndarray, path: Path) -> None:
    """A quarter-size (box-filtered) PNG of a linear (h, w, 3) image."""
    h, w = image.shape[0] // 4 * 4, image.shape[1] // 4 * 4
    small = image[:h, :w, :3].reshape(h // 4, 4, w // 4, 4, 3).mean(axis=(1, 3))
    embree_rt.save_image(np.ascontiguousarray(small, np.float32), path)


def check_agreement(
    field, bvh, sphere_geometry, mi, dr, theirs, primary, shadow, blocked, their_blocked
) -> dict:
    """Hit and shadowed fractions of both sides on the same rays, how often they name the same
    object, and float64's verdict where they do not (``float64_verdict``, ``distance_errors``).
    ``primary`` = (origins, directions), ``shadow`` = (origins, directions, tfar), ``blocked``
    and ``their_blocked`` (h,) bool answers of the two occlusion queries (None without
    Mitsuba)."""
    ours, ours_t = our_labels(bvh, sphere_geometry, *primary)
    agreement = {
        "primary_hit_fraction": {"embree_rt": float((ours > -2).mean())},
        "shadowed_fraction": {"embree_rt": float(blocked.mean())},
    }
    if mi is None:
        return agreement
    their, their_t = their_labels(mi, dr, theirs, *primary, coherent=True)  # as timed
    agreement["primary_hit_fraction"]["mitsuba"] = float((their > -2).mean())
    agreement["shadowed_fraction"]["mitsuba"] = float(their_blocked.mean())
    difference = abs((their > -2).mean() - (ours > -2).mean())
    agreement["hit_fractions_agree"] = bool(difference <= HIT_FRACTION_TOLERANCE)
    agreement["tolerance"] = HIT_FRACTION_TOLERANCE
    agreement["same_object_fraction"] = float((their == ours).mean())
    agreement["same_shadow_fraction"] = float((their_blocked == blocked).mean())
    agreement["primary_vs_float64"] = float64_verdict(
        *primary, np.inf, ours, their, field, nearest=True
    )
    agreement["primary_t_error_vs_float64"] = distance_errors(
        *primary, ours, their, ours_t, their_t, field
    )
    # Where the shadow answers differ: the blocker each side finds, checked in float64.
    differ = np.flatnonzero(blocked != their_blocked)
    if not len(differ):
        agreement["shadow_vs_float64"] = {"disagreements": 0}
        return agreement
    rays = tuple(array[differ] for array in shadow)
    our_blockers, _ = our_labels(bvh, sphere_geometry, *rays)
    their_blockers, _ = their_labels(mi, dr, theirs, *rays)
    verdict = float64_verdict(*rays, our_blockers, their_blockers, field, nearest=False)
    agreement["shadow_vs_float64"] = {**verdict, "disagreements": len(differ)}
    return agreement


def bench_count(count: int, args, mi, dr) -> dict:
    def progress(message: str) -> None:
        log(f"[{count:>8}] {message}")

    centers, radii, side = sphere_field(count, args.seed)
    row: dict = {"count": count, "side": side}
    image = dict(width=WIDTH, height=HEIGHT, spp=1, max_depth=0, seed=args.seed)

    # -- builds, first renders (discarded) --
    build_s, scene = seconds(lambda: embree_rt_scene(centers, radii, side))
    renderer_s, renderer = seconds(lambda: Renderer(scene))
    build = {"embree_rt_scene_s": round(build_s, 4), "embree_rt_renderer_s": round(renderer_s, 4)}
    first = {"embree_rt_s": round(seconds(lambda: renderer.render(**image))[0], 4)}
    theirs = None
    if mi is not None:
        mitsuba_s, theirs = seconds(lambda: mitsuba_scene(mi, centers, radii, side))
        build["mitsuba_load_dict_s"] = round(mitsuba_s, 4)

        def mitsuba_render():
            picture = mi.render(theirs, spp=1)
            dr.eval(picture)
            dr.sync_thread()
            return picture

        start = time.perf_counter()
        kernels = {"first_render": kernel_stats(dr, mitsuba_render)}
        first["mitsuba_s"] = round(time.perf_counter() - start, 4)
        kernels["warm_render"] = kernel_stats(dr, mitsuba_render)
        row["kernels"] = kernels
    progress(f"built: {build}; first renders {first}")
    row["build"] = build

    # -- renders in turns --
    with renderer:
        ours_s, theirs_s = in_turns(
            lambda: renderer.render(**image),
            mitsuba_render if mi is not None else None,
            args.repeat,
        )
        render = {"first_s": first, **summary(ours_s, theirs_s)}
        progress(
            f"render: ours {render['embree_rt_median_s']} s"
            + (
                f", Mitsuba {render['mitsuba_median_s']} s, speed vs Mitsuba "
                f"{render['speed_vs_mitsuba']}"
                if mi is not None
                else ""
            )
        )
        ours_image = renderer.render(**image).image
    render["one_call_s"] = round(seconds(lambda: embree_rt.render(scene, **image))[0], 4)
    row["render"] = render
    theirs_image = np.array(mitsuba_render()) if mi is not None else None
    if args.images:
        directory = Path(args.images)
        directory.mkdir(parents=True, exist_ok=True)
        save_preview(ours_image, directory / f"embree_rt_{count}.png")
        if theirs_image is not None:
            save_preview(theirs_image, directory / f"mitsuba_{count}.png")

    # -- bare traversal on the same rays --
    origins, directions = pixel_centre_rays(camera(side), WIDTH, HEIGHT)
    ground_vertices, ground_faces = ground_quad(side)
    start = time.perf_counter()
    bvh = BVH(threads=None)
    sphere_geometry = bvh.add_spheres(centers, radii)
    bvh.add_triangles(ground_vertices, ground_faces)
    bvh.commit()
    build["embree_rt_bvh_s"] = round(time.perf_counter() - start, 4)
    light = np.asarray(light_position(side))
    with bvh:
        hits = bvh.intersect(Rays(origins, directions))  # also compiles / warms the kernels
        s_origins, s_directions, s_tfar = unit_shadow_rays(origins, directions, hits, light)
        blocked = bvh.occluded(Rays(s_origins, s_directions, 0.0, s_tfar))
        intersect_theirs = occluded_theirs = None
        if mi is not None:
            primary = mitsuba_rays(mi, dr, origins, directions)
            shadow = mitsuba_rays(mi, dr, s_origins, s_directions, s_tfar)

            def intersect_theirs():
                found = theirs.ray_intersect_preliminary(primary, coherent=True)
                dr.eval(found.t, found.prim_index, found.shape_index)
                dr.sync_thread()
                return found

            def occluded_theirs():
                found = theirs.ray_test(shadow)
                dr.eval(found)
                dr.sync_thread()
                return found

            intersect_theirs()  # compiles the kernels
            their_blocked = np.array(occluded_theirs())
        agreement = check_agreement(
            (centers, radii, GROUND_HALF_SIZE * side),
            bvh,
            sphere_geometry,
            mi,
            dr,
            theirs,
            (origins, directions),
            (s_origins, s_directions, s_tfar),
            blocked,
            their_blocked if mi is not None else None,
        )
        if theirs_image is not None:
            # Mitsuba's own render: pixels whose camera sample hit something (alpha)
            agreement["mitsuba_render_coverage"] = float(theirs_image[..., 3].mean())
        traversal = {}
        for kind, ours, theirs_call, rays in (
            (
                "primary",
                lambda: bvh.intersect(Rays(origins, directions), coherent=True),
                intersect_theirs,
                len(origins),
            ),
            (
                "shadow",
                lambda: bvh.occluded(Rays(s_origins, s_directions, 0.0, s_tfar)),
                occluded_theirs,
                len(s_origins),
            ),
        ):
            ours_s, theirs_s = in_turns(ours, theirs_call, args.repeat)
            traversal[kind] = {"rays": rays, **summary(ours_s, theirs_s, rays)}
            progress(
                f"{kind:>7} rays: ours {traversal[kind]['embree_rt_mrays_s']} Mrays/s"
                + (
                    f", Mitsuba {traversal[kind]['mitsuba_mrays_s']} Mrays/s"
                    if theirs_call is not None
                    else ""
                )
            )
    row["traversal"] = traversal
    row["agreement"] = agreement
    return row


# -- instancing (issue 12) ------------------------------------------------------------------------


ICOSPHERE_SUBDIVISIONS = 2  # 320 triangles


def instance_placements(count: int, seed: int) -> tuple[np.ndarray, float]:
    """(count, 4, 4) float64 placements of a unit icosphere at the spheres of the ``count``-
    sphere field (scaled to each radius, turned about y at random) and the field's S."""
    centers, radii, side = sphere_field(count, seed)
    angle = np.random.default_rng(seed + 7).uniform(0.0, 2.0 * np.pi, count)
    cos, sin = np.cos(angle) * radii, np.sin(angle) * radii
    transforms = np.zeros((count, 4, 4))
    transforms[:, 0, 0], transforms[:, 0, 2] = cos, sin
    transforms[:, 1, 1] = radii
    transforms[:, 2, 0], transforms[:, 2, 2] = -sin, cos
    transforms[:, :3, 3] = centers
    transforms[:, 3, 3] = 1.0
    return transforms, side


def bench_instances(count: int, args, mi, dr, directory: Path) -> dict:
    import trimesh

    def progress(message: str) -> None:
        log(f"[{count:>8} instances] {message}")

    transforms, side = instance_placements(count, args.seed)
    ico = trimesh.creation.icosphere(subdivisions=ICOSPHERE_SUBDIVISIONS)
    ground_vertices, ground_faces = ground_quad(side)
    origins, directions = pixel_centre_rays(camera(side), WIDTH, HEIGHT)
    row: dict = {"instances": count, "triangles_per_copy": len(ico.faces)}

    def build_ours() -> BVH:
        child = BVH()
        child.add_triangles(ico.vertices, ico.faces)
        child.commit()
        bvh = BVH()
        bvh.add_triangles(ground_vertices, ground_faces)
        bvh.add_instances(child, transforms)
        bvh.commit()
        bvh.child = child  # kept alive with the scene
        return bvh

    build_s, bvh = seconds(build_ours)
    row["embree_rt_build_s"] = round(build_s, 3)
    theirs = None
    if mi is not None:
        mesh_path = directory / "icosphere.ply"
        ico.export(mesh_path)
        h = GROUND_HALF_SIZE * side
        transform = mi.ScalarTransform4f()

        def build_theirs():
            scene = {
                "type": "scene",
                "ground": {
                    "type": "rectangle",
                    "to_world": transform.rotate([1, 0, 0], -90).scale(h),
                },
                "copies": {
                    "type": "shapegroup",
                    "mesh": {"type": "ply", "filename": str(mesh_path)},
                },
            }
            for i, matrix in enumerate(transforms):
                scene[f"copy_{i}"] = {
                    "type": "instance",
                    "shapegroup": {"type": "ref", "id": "copies"},
                    "to_world": mi.ScalarTransform4f(matrix),
                }
            return mi.load_dict(scene)

        their_build_s, theirs = seconds(build_theirs)
        row["mitsuba_build_s"] = round(their_build_s, 3)
        row["build_speed_vs_mitsuba"] = round(their_build_s / build_s, 1)
    progress(f"built: {row}")
    with bvh:
        hits = bvh.intersect(Rays(origins, directions))  # warms the kernels
        intersect_theirs = None
        if theirs is not None:
            primary = mitsuba_rays(mi, dr, origins, directions)

            def intersect_theirs():
                found = theirs.ray_intersect_preliminary(primary, coherent=True)
                dr.eval(found.t)
                dr.sync_thread()
                return found

            their_t = np.array(intersect_theirs().t, np.float64)
            our_t = hits.t.astype(np.float64)
            both_miss = ~np.isfinite(our_t) & ~np.isfinite(their_t)
            tolerance = 1e-4 * (1.0 + np.where(np.isfinite(our_t), our_t, 0.0))
            with np.errstate(invalid="ignore"):
                both_hit = np.abs(our_t - their_t) <= tolerance
            row["agreement"] = {
                "hit_fraction": float(np.isfinite(our_t).mean()),
                "mitsuba_hit_fraction": float(np.isfinite(their_t).mean()),
                "same_answer_fraction": float((both_miss | both_hit).mean()),
            }
        ours_s, theirs_s = in_turns(
            lambda: bvh.intersect(Rays(origins, directions)), intersect_theirs, args.repeat
        )
        row["primary"] = {"rays": len(origins), **summary(ours_s, theirs_s, len(origins))}
        bvh.child.close()
    progress(f"primary rays: {row['primary']}")
    return row


# -- output ---------------------------------------------------------------------------------------


def machine() -> dict:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model, "nproc": os.cpu_count(), "load_average": list(os.getloadavg())}


def versions() -> dict:
    found = {"python": platform.python_version()}
    for package in ("embree-rt", "embreex", "numpy", "numba"):
        found[package] = importlib.metadata.version(package)
    with contextlib.suppress(OSError, subprocess.CalledProcessError):
        found["embree_rt_commit"] = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).parent,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    return found


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--counts", type=lambda s: int(float(s)), nargs="*", default=[1_000, 100_000, 1_000_000]
    )
    parser.add_argument(
        "--instances",
        type=lambda s: int(float(s)),
        nargs="*",
        default=[],
        help="also compare instancing at these counts (a shapegroup and instances in Mitsuba)",
    )
    parser.add_argument("--repeat", type=int, default=5, help="timed pairs per measurement")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--images", default=None, metavar="DIR", help="save quarter-size PNGs of both renders here"
    )
    args = parser.parse_args(argv)

    mi, dr, mitsuba = load_mitsuba()
    log(f"mitsuba: {mitsuba}")
    started = time.perf_counter()
    result = {
        "machine": machine(),
        "versions": versions(),
        "mitsuba": mitsuba,
        "config": {
            "width": WIDTH,
            "height": HEIGHT,
            "spp": 1,
            "max_depth": 0,
            "repeat": args.repeat,
            "seed": args.seed,
            "tile": TILE,
            "ground_half_size_per_side": GROUND_HALF_SIZE,
            "embree_rt_threads": os.cpu_count(),
        },
        "results": [bench_count(count, args, mi, dr) for count in args.counts],
    }
    if args.instances:
        import tempfile

        with tempfile.TemporaryDirectory() as directory:
            result["instances"] = [
                bench_instances(count, args, mi, dr, Path(directory)) for count in args.instances
            ]
    result["seconds"] = round(time.perf_counter() - started, 1)
    result["machine"]["load_average_end"] = list(os.getloadavg())
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
