"""The seed article's 2D ray demo, traced by embree_rt itself.

Circles are spheres centred in the plane z = 0 and the light's rays lie in that plane, so the
project's BVH finds every hit (the normal of a sphere hit by an in-plane ray lies in the plane)
and ``embree_rt.shading`` bends them: mirror reflection, Snell refraction with total internal
reflection, and glass split between the two by Schlick's Fresnel term, with the weights the
integrator gives them (the presets' reflectivity and transparency, children below
``integrator.MIN_WEIGHT`` dropped). Matte circles absorb.

The result is a set of polylines (``LightPaths``), one per light path: a ray and the child that
carries most of its light continue one polyline; the other child of a glass split starts a new
one at the hit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from embree_rt import shading
from embree_rt.embree import BVH, Rays
from embree_rt.integrator import MIN_WEIGHT, surface_offset
from embree_rt.materials import PRESETS

MATERIALS_2D = ("mirror", "glass", "matte")
MIRROR, GLASS, MATTE = range(3)
# What each segment is: straight from the light, a mirror (or glass's Fresnel) reflection, a
# refraction, a total internal reflection.
SEGMENT_KINDS = ("light", "reflection", "refraction", "internal")
LIGHT, REFLECTION, REFRACTION, INTERNAL = range(4)
MAX_DEPTH = 6


@dataclass(frozen=True)
class Layout:
    """One 2D scene: ``circles`` (n, 3) float64 (x, y, radius), ``materials`` (n,) int64
    indices into ``MATERIALS_2D``, the ``light`` (x, y), ``rays`` in the fan, spread over
    ``spread`` degrees centred on the direction ``aim`` (degrees, counterclockwise from +x),
    and the box ``[0, width] × [0, height]`` that the rays leave through."""

    circles: np.ndarray
    materials: np.ndarray
    light: tuple[float, float]
    rays: int
    spread: float
    aim: float
    width: float
    height: float
    max_depth: int = MAX_DEPTH


@dataclass
class LightPaths:
    """The light paths of a layout, as polylines packed end to end.

    Path k's points are ``points[starts[k]:starts[k + 1]]`` ((m + 1, 2) float64 for m
    segments), and its segments' ``weights`` (the light each carries, 1 leaving the light) and
    ``kinds`` (``SEGMENT_KINDS``) are ``weights[starts[k] - k:starts[k + 1] - k - 1]`` (float64,
    int64). ``starts`` is (paths + 1,) int64.
    """

    points: np.ndarray
    weights: np.ndarray
    kinds: np.ndarray
    starts: np.ndarray

    def segments(self) -> np.ndarray:
        """(segments, 4) float64 (x0, y0, x1, y1) of every segment, path after path."""
        inner = np.ones(len(self.points), bool)
        inner[self.starts[1:] - 1] = False  # a path's last point starts no segment
        first = np.flatnonzero(inner)
        return np.hstack([self.points[first], self.points[first + 1]])


def fan_directions(layout: Layout) -> np.ndarray:
    """(2, rays) float64 unit directions of the light's fan: evenly spaced over ``spread``
    degrees about ``aim``, each at the centre of its share of the angle."""
    share = (np.arange(layout.rays) + 0.5) / layout.rays - 0.5
    angle = np.radians(layout.aim + layout.spread * share)
    return np.stack([np.cos(angle), np.sin(angle)])


def _box_exit(origin: np.ndarray, direction: np.ndarray, width: float, height: float):
    """(n,) float64 distance along each ray (2, n) from inside the box to where it leaves."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(
            direction[0] > 0,
            (width - origin[0]) / direction[0],
            np.where(direction[0] < 0, -origin[0] / direction[0], np.inf),
        )
        ty = np.where(
            direction[1] > 0,
            (height - origin[1]) / direction[1],
            np.where(direction[1] < 0, -origin[1] / direction[1], np.inf),
        )
    return np.maximum(np.minimum(tx, ty), 0.0)


def _in_plane(xy: np.ndarray) -> np.ndarray:
    """(3, n) float32 points or directions in z = 0 from (2, n) ones."""
    return np.vstack([xy, np.zeros((1, xy.shape[1]))]).astype(np.float32)


def trace_layout(layout: Layout) -> LightPaths:
    """Trace the light's fan through ``layout`` with embree_rt's BVH and shading, down to
    ``layout.max_depth`` bounces; the light paths in order of the fan's rays."""
    count = len(layout.circles)
    bvh = BVH(threads=1)
    try:
        if count:
            centers = np.zeros((count, 3))
            centers[:, :2] = layout.circles[:, :2]
            bvh.add_spheres(centers, layout.circles[:, 2])
        bvh.commit()
        segments = _trace(bvh, layout)
    finally:
        bvh.close()
    return _pack(segments)


def _trace(bvh: BVH, layout: Layout) -> dict[str, np.ndarray]:
    """Every segment traced, as arrays: path id, depth, start and end (2, k), weight, kind."""
    mirror_reflect = PRESETS["mirror"].reflectivity
    transparency = PRESETS["glass"].transparency
    glass_reflect = PRESETS["glass"].reflectivity * (1.0 - transparency)
    ior = np.float32(PRESETS["glass"].ior)
    light = np.asarray(layout.light, np.float64)
    direction = fan_directions(layout).astype(np.float32)
    n = direction.shape[1]
    start = np.repeat(light[:, None], n, axis=1)  # where each segment is drawn from
    origin = start.astype(np.float32)  # where it is traced from (off the surface it left)
    weight = np.ones(n, np.float32)
    kind = np.full(n, LIGHT)
    path = np.arange(n)
    paths = n
    found: list[tuple[np.ndarray, ...]] = []
    for depth in range(layout.max_depth + 1):
        if len(path) == 0:
            break
        hits = bvh.intersect(Rays(_in_plane(origin[:2]).T, _in_plane(direction[:2]).T))
        leave = _box_exit(
            origin[:2].astype(np.float64),
            direction[:2].astype(np.float64),
            layout.width,
            layout.height,
        )
        hit = hits.hit & (hits.t < leave)
        t = np.where(hit, hits.t, leave)
        end = origin[:2] + direction[:2] * t.astype(np.float32)
        found.append((path, np.full(len(path), depth), start, end.astype(np.float64), weight, kind))
        if depth == layout.max_depth:
            break
        rows = np.flatnonzero(hit)
        material = layout.materials[hits.prim_id[rows]]
        rows, material = rows[material != MATTE], material[material != MATTE]
        d = _in_plane(direction[:2, rows])
        point = _in_plane(end[:, rows])
        normal = shading.normalize(hits.normal[rows].T)
        normal[2] = 0.0
        entering = shading.dot(d, normal) < 0
        normal *= np.where(entering, np.float32(1.0), np.float32(-1.0))  # towards the ray
        center = layout.circles[hits.prim_id[rows]]
        scale = np.maximum(
            np.abs(point[:2]).max(axis=0), np.hypot(center[:, 0], center[:, 1]) + center[:, 2]
        )
        offset = surface_offset(scale.astype(np.float32))
        glass = material == GLASS
        refracted, total_internal, fresnel = shading.dielectric_split(d, normal, entering, ior)
        w = weight[rows]
        reflect_weight = np.where(
            glass, w * (glass_reflect + transparency * fresnel), w * mirror_reflect
        )
        refract_weight = np.where(glass, w * transparency * (1.0 - fresnel), 0.0)
        reflect_kind = np.where(glass & total_internal, INTERNAL, REFLECTION)
        # The brighter child continues its parent's path; the other starts a new one.
        keep_reflect = reflect_weight >= MIN_WEIGHT
        keep_refract = refract_weight >= MIN_WEIGHT
        refract_continues = refract_weight > reflect_weight
        new_paths = (keep_reflect & refract_continues) | (keep_refract & ~refract_continues)
        new_path = np.full(len(rows), -1)
        new_path[new_paths] = paths + np.arange(np.count_nonzero(new_paths))
        paths += np.count_nonzero(new_paths)
        reflect_path = np.where(refract_continues, new_path, path[rows])
        refract_path = np.where(refract_continues, path[rows], new_path)
        reflected = shading.reflect(d, normal)
        outside = point + normal * offset
        inside = point - normal * offset
        r, f = np.flatnonzero(keep_reflect), np.flatnonzero(keep_refract)
        path = np.concatenate([reflect_path[r], refract_path[f]])
        start = np.concatenate([point[:2, r], point[:2, f]], axis=1).astype(np.float64)
        origin = np.concatenate([outside[:, r], inside[:, f]], axis=1)
        direction = np.concatenate([reflected[:, r], refracted[:, f]], axis=1)
        weight = np.concatenate([reflect_weight[r], refract_weight[f]]).astype(np.float32)
        kind = np.concatenate([reflect_kind[r], np.full(len(f), REFRACTION)])
    names = ("path", "depth", "start", "end", "weight", "kind")
    columns = {name: [part[i] for part in found] for i, name in enumerate(names)}
    return {
        name: np.concatenate(parts, axis=1 if name in ("start", "end") else 0)
        for name, parts in columns.items()
    }


def _pack(segments: dict[str, np.ndarray]) -> LightPaths:
    """Group the segments into paths: by path id, each path's segments in order of depth."""
    order = np.lexsort((segments["depth"], segments["path"]))
    path = segments["path"][order]
    count = len(path)
    first = np.ones(count, bool)  # the first segment of its path
    first[1:] = path[1:] != path[:-1]
    paths_before = np.cumsum(first)  # paths begun up to and including each segment
    points = np.empty((count + int(paths_before[-1]) if count else 0, 2))
    end_at = np.arange(count) + paths_before  # each segment's end, after its path's start
    points[end_at] = segments["end"][:, order].T
    points[end_at[first] - 1] = segments["start"][:, order].T[first]
    starts = np.append(end_at[first] - 1, len(points)).astype(np.int64)
    weights = segments["weight"][order].astype(np.float64)
    return LightPaths(points, weights, segments["kind"][order], starts)
