"""What the float64 passes over Embree's recorded hits (``settled_hits``, ``decided_hits``) read,
as named tuples the compiled kernels take whole: the rays, the mesh's tables and the
tolerances of trimesh's rules."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class WorldRays(NamedTuple):
    """n rays in float64: ``origins``, ``directions`` (n, 3) float64 world rays (unit
    directions); ``magnitude`` (n,) float64 the largest local coordinate of each ray
    (``local_frame.local_rays``); ``near`` (n,) float64 the world distance hits must lie
    beyond (``inclusive``: at or beyond)."""

    origins: np.ndarray
    directions: np.ndarray
    magnitude: np.ndarray
    near: np.ndarray
    inclusive: bool


class MeshTables(NamedTuple):
    """The mesh's per-triangle tables: ``planes`` (triangles, 6) float64, each triangle's first
    vertex and unit normal in one C-contiguous row (``plane_distances``); ``triangles``
    (triangles, 3, 3) float64; ``altitude`` (triangles,) float64 smallest local altitude (0:
    degenerate) and ``floor_altitude`` its minimum."""

    planes: np.ndarray
    triangles: np.ndarray
    altitude: np.ndarray
    floor_altitude: float


class Fans(NamedTuple):
    """The faces around each vertex position, CSR: ``canonical`` (triangles, 3) int64 each
    triangle's corners as position ids, ``starts`` (positions + 1,) int64 and ``faces``
    (3 triangles,) int64: the faces around position p are ``faces[starts[p]:starts[p + 1]]``."""

    canonical: np.ndarray
    starts: np.ndarray
    faces: np.ndarray


class Hits(NamedTuple):
    """Hits as columns: ``rays``, ``tris`` (k,) int64 and ``distance`` (k,) float64."""

    rays: np.ndarray
    tris: np.ndarray
    distance: np.ndarray


class Tolerances(NamedTuple):
    """trimesh's rules as numbers: ``band_scale`` the edge band per unit of magnitude / altitude
    (a hit nearer its triangle's edge, barycentric, is decided in float64); ``graze`` (float32)
    the |cos| at or below which a hit is too; ``parallel_cos`` the |cos| at or below which a
    ray misses a triangle's plane; ``zero`` ray_triangle's barycentric tolerance."""

    band_scale: float
    graze: np.float32
    parallel_cos: float
    zero: float


def world_rays(
    origins: np.ndarray,
    directions: np.ndarray,
    magnitude: np.ndarray,
    near: np.ndarray,
    inclusive: bool,
) -> WorldRays:
    """``WorldRays`` of the arrays given, as the kernels take them (C-contiguous float64)."""
    return WorldRays(
        np.ascontiguousarray(origins, np.float64),
        np.ascontiguousarray(directions, np.float64),
        np.ascontiguousarray(magnitude, np.float64),
        np.ascontiguousarray(near, np.float64),
        bool(inclusive),
    )


def tolerances(band_scale: float, graze: float, parallel_cos: float, zero: float) -> Tolerances:
    """``Tolerances`` with the kernels' types (graze compared in float32, as Embree's cos)."""
    return Tolerances(float(band_scale), np.float32(graze), float(parallel_cos), float(zero))
