"""Shading: Blinn-Phong, mirror reflection, Snell refraction, Schlick Fresnel, sky, checker.

Pure functions on float32 NumPy arrays, one row per ray: vectors are (n, 3), per-ray scalars
(n,). Directions and normals are unit length unless a function says otherwise.
"""

from __future__ import annotations

import numpy as np

from embree_rt.materials import Checker


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) row-wise dot product of two (n, 3) arrays (float32 for float32 input)."""
    return np.einsum("ij,ij->i", a, b)


def normalize(v: np.ndarray) -> np.ndarray:
    """(n, 3) float32 unit vectors along the rows of (n, 3) ``v``; zero rows stay zero."""
    v = np.asarray(v, np.float32)
    inverse_length = np.float32(1.0) / np.maximum(np.sqrt(dot(v, v)), np.float32(1e-30))
    return v * inverse_length[:, None]


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(n, 3) float32 mirror directions ``d - 2 (d·n) n`` of (n, 3) ``d`` about (n, 3) unit
    normals ``n``; the length of ``d`` is kept."""
    d = np.asarray(d, np.float32)
    n = np.asarray(n, np.float32)
    return d - np.float32(2.0) * dot(d, n)[:, None] * n


def refract(d: np.ndarray, n: np.ndarray, eta: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Snell refraction of (n, 3) unit directions ``d`` through (n, 3) unit normals ``n``.

    ``n`` faces the incident side (d·n <= 0) and ``eta`` = n_incident / n_transmitted, a scalar
    or (n,). Returns ((n, 3) float32 unit directions, (n,) bool total internal reflection);
    where there is total internal reflection the direction is the mirror one, so every row is
    a usable unit vector.
    """
    d = np.asarray(d, np.float32)
    n = np.asarray(n, np.float32)
    eta = np.broadcast_to(np.asarray(eta, np.float32), (len(d),))
    cos_i = np.clip(-dot(d, n), np.float32(0.0), np.float32(1.0))
    sin2_t = eta * eta * (np.float32(1.0) - cos_i * cos_i)
    total_internal = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(np.float32(0.0), np.float32(1.0) - sin2_t))
    refracted = eta[:, None] * d + (eta * cos_i - cos_t)[:, None] * n
    directions = np.where(total_internal[:, None], reflect(d, n), refracted)
    return normalize(directions), total_internal


def fresnel_schlick(
    cos_incident: np.ndarray, n1: float | np.ndarray, n2: float | np.ndarray
) -> np.ndarray:
    """(n,) float32 Schlick reflectance of light going from index ``n1`` into ``n2``.

    ``cos_incident`` (n,) is the cosine of the angle of incidence; ``n1``, ``n2`` are scalars or
    (n,). ``R = R0 + (1 - R0)(1 - cos)^5`` with ``R0 = ((n1 - n2) / (n1 + n2))²``, where
    ``cos`` is the incident cosine entering a denser medium and the transmitted one leaving it
    (Schlick's formula is symmetric only in the larger angle). Exactly 1 on total internal
    reflection; 0 across an index-matched interface (n1 == n2), which is no interface at all.
    """
    cos_i = np.clip(np.asarray(cos_incident, np.float32), np.float32(0.0), np.float32(1.0))
    n1 = np.broadcast_to(np.asarray(n1, np.float32), cos_i.shape)
    n2 = np.broadcast_to(np.asarray(n2, np.float32), cos_i.shape)
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    eta = n1 / n2
    sin2_t = eta * eta * (np.float32(1.0) - cos_i * cos_i)
    total_internal = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(np.float32(0.0), np.float32(1.0) - sin2_t))
    cos = np.where(n1 > n2, cos_t, cos_i)
    reflectance = r0 + (np.float32(1.0) - r0) * (np.float32(1.0) - cos) ** 5
    reflectance = np.where(n1 == n2, np.float32(0.0), reflectance)
    return np.where(total_internal, np.float32(1.0), reflectance).astype(np.float32, copy=False)


def blinn_phong(
    normal: np.ndarray,
    to_viewer: np.ndarray,
    to_light: np.ndarray,
    color: np.ndarray,
    diffuse: np.ndarray,
    specular: np.ndarray,
    shininess: np.ndarray,
    light_rgb: np.ndarray,
) -> np.ndarray:
    """(n, 3) float32 light that one point light sends toward the viewer off a surface.

    ``diffuse · max(0, N·L) · color · light_rgb + specular · max(0, N·H)^shininess · light_rgb``
    with ``H = normalize(L + V)``, and zero where ``N·L <= 0`` (no highlight on the dark side).
    ``normal``, ``to_viewer``, ``to_light`` are (n, 3) unit vectors; ``color`` and
    ``light_rgb`` (n, 3) (or (3,)); ``diffuse``, ``specular``, ``shininess`` (n,). The caller
    folds shadowing and the light's intensity into ``light_rgb``; there is no distance
    attenuation, as in the seed article.
    """
    n_dot_l = dot(normal, to_light)
    shade = diffuse * np.maximum(n_dot_l, np.float32(0.0))
    radiance = (shade[:, None] * color * light_rgb).astype(np.float32, copy=False)
    # Highlights only where there is a specular term and light: the power is the costly part.
    glossy = np.flatnonzero((specular > 0) & (n_dot_l > 0))
    if len(glossy):
        half = normalize(to_light[glossy] + to_viewer[glossy])
        n_dot_h = np.maximum(dot(normal[glossy], half), np.float32(0.0))
        highlight = specular[glossy] * n_dot_h ** shininess[glossy]
        light = np.broadcast_to(light_rgb, radiance.shape)[glossy]
        radiance[glossy] += highlight[:, None] * light
    return radiance


def sky(directions: np.ndarray, horizon: np.ndarray, zenith: np.ndarray) -> np.ndarray:
    """(n, 3) float32 sky gradient seen along (n, 3) unit ``directions``.

    With ``t = clip(y, 0, 1)``: ``(1 - t) · horizon + t · zenith``; below the horizon the
    horizon color. ``horizon`` and ``zenith`` are RGB, (3,) or (n, 3).
    """
    t = np.clip(np.asarray(directions, np.float32)[:, 1], 0.0, 1.0)[:, None]
    horizon = np.asarray(horizon, np.float32)
    zenith = np.asarray(zenith, np.float32)
    return ((np.float32(1.0) - t) * horizon + t * zenith).astype(np.float32, copy=False)


def checker(points: np.ndarray, checker: Checker) -> np.ndarray:
    """(n, 3) float32 checkerboard color at (n, 3) ``points``, by squares of the xz-plane:
    ``checker.color_a`` where ``floor(x / size) + floor(z / size)`` is even, else ``color_b``."""
    # float64 so the square a point falls in does not depend on float32 rounding of x / size.
    points = np.asarray(points, np.float64)
    cells = np.floor(points[:, 0] / checker.size) + np.floor(points[:, 2] / checker.size)
    even = np.remainder(cells, 2.0) == 0.0
    color_a = np.asarray(checker.color_a, np.float32)
    color_b = np.asarray(checker.color_b, np.float32)
    return np.where(even[:, None], color_a, color_b)
