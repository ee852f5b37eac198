"""Shading: Blinn-Phong, mirror reflection, Snell refraction, Schlick Fresnel, sky, checker.

Pure functions on float32 arrays; vectors are (n, 3), scalars per ray (n,).
"""

from __future__ import annotations

import numpy as np

from embree_rt.materials import Checker


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) float32 row-wise dot product of (n, 3) arrays."""
    return np.einsum("ij,ij->i", a, b)


def normalize(v: np.ndarray) -> np.ndarray:
    """(n, 3) float32 unit vectors (zero rows stay zero)."""
    inverse_length = np.float32(1.0) / np.maximum(np.sqrt(dot(v, v)), np.float32(1e-30))
    return (v * inverse_length[:, None]).astype(np.float32, copy=False)


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(n, 3) mirror direction ``d - 2 (d·n) n`` of directions ``d`` about unit normals ``n``."""
    return (d - 2.0 * dot(d, n)[:, None] * n).astype(np.float32, copy=False)


def refract(d: np.ndarray, n: np.ndarray, eta: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Snell refraction of unit ``d`` through unit ``n`` (on the incident side, d·n <= 0),
    ``eta`` = n_incident / n_transmitted. Returns ((n, 3) float32 unit directions, (n,) bool
    total internal reflection); where TIR, the direction is the mirror one."""
    eta = np.broadcast_to(np.asarray(eta, np.float32), (len(d),))
    cos_i = np.clip(-dot(d, n), 0.0, 1.0)
    sin2_t = eta**2 * (1.0 - cos_i**2)
    total_internal = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    refracted = eta[:, None] * d + (eta * cos_i - cos_t)[:, None] * n
    directions = np.where(total_internal[:, None], reflect(d, n), refracted)
    return normalize(directions), total_internal


def fresnel_schlick(
    cos_incident: np.ndarray, n1: float | np.ndarray, n2: float | np.ndarray
) -> np.ndarray:
    """(n,) float32 Schlick reflectance going from index ``n1`` into ``n2``; 1 on total
    internal reflection. Leaving the denser medium uses the transmitted angle's cosine."""
    cos_i = np.clip(np.asarray(cos_incident, np.float32), 0.0, 1.0)
    n1 = np.broadcast_to(np.asarray(n1, np.float32), cos_i.shape)
    n2 = np.broadcast_to(np.asarray(n2, np.float32), cos_i.shape)
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    sin2_t = (n1 / n2) ** 2 * (1.0 - cos_i**2)
    total_internal = sin2_t > 1.0
    cos = np.where(n1 > n2, np.sqrt(np.maximum(0.0, 1.0 - sin2_t)), cos_i)
    reflectance = r0 + (1.0 - r0) * (1.0 - cos) ** 5
    return np.where(total_internal, 1.0, reflectance).astype(np.float32, copy=False)


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
    """(n, 3) float32 light reflected toward the viewer by one point light:
    ``diffuse·max(0, N·L)·color·light + specular·max(0, N·H)^shininess·light``, zero where
    the light is behind the surface. Unit vectors (n, 3); diffuse, specular, shininess (n,)."""
    n_dot_l = dot(normal, to_light)
    shade = diffuse * np.maximum(n_dot_l, 0.0)
    radiance = shade[:, None] * color * light_rgb
    # Highlights only where there is a specular term and light: pow is the costly part.
    glossy = np.flatnonzero((specular > 0) & (n_dot_l > 0))
    if len(glossy):
        half = normalize(to_light[glossy] + to_viewer[glossy])
        n_dot_h = np.maximum(dot(normal[glossy], half), 0.0)
        highlight = specular[glossy] * n_dot_h ** shininess[glossy]
        light = np.broadcast_to(light_rgb, radiance.shape)[glossy]
        radiance[glossy] += highlight[:, None] * light
    return radiance.astype(np.float32, copy=False)


def sky(directions: np.ndarray, horizon, zenith) -> np.ndarray:
    """(n, 3) float32 sky gradient: ``horizon`` at and below y = 0, ``zenith`` straight up."""
    t = np.clip(directions[:, 1], 0.0, 1.0)[:, None]
    horizon = np.asarray(horizon, np.float32)
    zenith = np.asarray(zenith, np.float32)
    return ((1.0 - t) * horizon + t * zenith).astype(np.float32, copy=False)


def checker(points: np.ndarray, pattern: Checker) -> np.ndarray:
    """(n, 3) float32 checkerboard color of (n, 3) points, by squares of the xz-plane."""
    cells = np.floor(points[:, 0] / pattern.size) + np.floor(points[:, 2] / pattern.size)
    even = (cells.astype(np.int64) % 2) == 0
    color_a = np.asarray(pattern.color_a, np.float32)
    color_b = np.asarray(pattern.color_b, np.float32)
    return np.where(even[:, None], color_a, color_b).astype(np.float32, copy=False)
