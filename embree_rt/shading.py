"""Shading: Blinn-Phong, mirror reflection, Snell refraction, Schlick Fresnel, sky, checker.

Pure functions on float32 NumPy arrays holding one ray per column: vectors are (3, n)
(component-major, so every pass runs over contiguous rows), per-ray scalars (n,). Directions
and normals are unit length unless a function says otherwise.
"""

from __future__ import annotations

import numpy as np

from embree_rt.columns import scatter, scatter_add
from embree_rt.materials import Checker


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) dot products of the columns of two (3, n) arrays (float32 for float32 input):
    ``(a0 b0 + a1 b1) + a2 b2``, summed into the first product's array (two temporaries
    fewer than the plain expression, the same roundings)."""
    result = a[0] * b[0]
    term = a[1] * b[1]
    if not isinstance(result, np.ndarray) or result.dtype != term.dtype:
        return result + term + a[2] * b[2]
    result += term
    np.multiply(a[2], b[2], out=term)
    result += term
    return result


def normalize(v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """(3, n) float32 unit vectors along the columns of (3, n) ``v``; zero columns stay zero.
    ``out``: a (3, n) float32 array to write them to (``v`` itself normalises in place)."""
    v = np.asarray(v, np.float32)
    inverse_length = np.sqrt(dot(v, v))
    np.maximum(inverse_length, np.float32(1e-30), out=inverse_length)
    np.divide(np.float32(1.0), inverse_length, out=inverse_length)
    return np.multiply(v, inverse_length, out=out)


def reflect(d: np.ndarray, n: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """(3, n) float32 mirror directions ``d - 2 (d·n) n`` of (3, n) ``d`` about (3, n) unit
    normals ``n``; the length of ``d`` is kept. ``out``: a (3, n) float32 array for them,
    which may be ``d`` or ``n`` itself (a gathered copy the caller no longer needs)."""
    d = np.asarray(d, np.float32)
    n = np.asarray(n, np.float32)
    twice = dot(d, n)
    twice *= np.float32(2.0)
    scaled = np.multiply(n, twice, out=n if out is n else None)
    return np.subtract(d, scaled, out=scaled if out is None else out)


def refract(d: np.ndarray, n: np.ndarray, eta: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Snell refraction of (3, n) unit directions ``d`` through (3, n) unit normals ``n``.

    ``n`` faces the incident side (d·n <= 0) and ``eta`` = n_incident / n_transmitted, a scalar
    or (n,). Returns ((3, n) float32 unit directions, (n,) bool total internal reflection);
    where there is total internal reflection the direction is the mirror one, so every column
    is a usable unit vector.
    """
    d = np.asarray(d, np.float32)
    n = np.asarray(n, np.float32)
    eta = np.broadcast_to(np.asarray(eta, np.float32), (d.shape[1],))
    directions, total_internal, _, _ = _snell(d, n, eta)
    return directions, total_internal


def _snell(d: np.ndarray, n: np.ndarray, eta: np.ndarray):
    """``refract`` of float32 ``d``, ``n`` (3, n) and ``eta`` (n,), and the (n,) float32
    cosines of incidence (clipped to [0, 1]) and of transmission it forms on the way, which
    Schlick's term reads again: (directions, total internal reflection, cos_i, cos_t)."""
    cos_i = dot(d, n)
    np.negative(cos_i, out=cos_i)
    np.clip(cos_i, np.float32(0.0), np.float32(1.0), out=cos_i)
    sin2_t = eta * eta * (np.float32(1.0) - cos_i * cos_i)
    total_internal = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(np.float32(0.0), np.float32(1.0) - sin2_t))
    directions = eta * d + (eta * cos_i - cos_t) * n
    if total_internal.any():
        mirrored = np.flatnonzero(total_internal)
        scatter(
            directions,
            mirrored,
            reflect(np.take(d, mirrored, axis=1), np.take(n, mirrored, axis=1)),
        )
    return normalize(directions, out=directions), total_internal, cos_i, cos_t


def dielectric_split(
    d: np.ndarray, n: np.ndarray, entering: np.ndarray, ior: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where light meets a dielectric of index ``ior`` (scalar or (k,)) from outside (index 1):
    (3, k) unit directions ``d`` through (3, k) unit normals ``n`` turned towards the rays,
    ``entering`` (k,) bool whether each ray goes into the dielectric (else leaves it).

    Returns the (3, k) float32 refracted directions (the mirror ones on total internal
    reflection, as ``refract``), the (k,) bool total internal reflection, and the (k,) float32
    Fresnel reflectance (``fresnel_schlick``; exactly 1 on total internal reflection): the share
    that reflects, the rest refracting."""
    n1 = np.where(entering, np.float32(1.0), ior)
    n2 = np.where(entering, ior, np.float32(1.0))
    d = np.asarray(d, np.float32)
    n = np.asarray(n, np.float32)
    eta = np.broadcast_to(np.asarray(n1 / n2, np.float32), (d.shape[1],))  # as refract takes it
    refracted, total_internal, cos_i, cos_t = _snell(d, n, eta)
    if n1.dtype == n2.dtype == np.float32:
        # Schlick's term reads the cosines Snell's law has just formed: with float32 indices
        # its own are the same float32 operations on the same values
        fresnel = _schlick(cos_i, cos_t, total_internal, n1, n2)
    else:
        fresnel = fresnel_schlick(cos_i, n1, n2)
    fresnel[total_internal] = 1.0
    return refracted, total_internal, fresnel


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
    eta = n1 / n2
    sin2_t = eta * eta * (np.float32(1.0) - cos_i * cos_i)
    total_internal = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(np.float32(0.0), np.float32(1.0) - sin2_t))
    return _schlick(cos_i, cos_t, total_internal, n1, n2)


def _schlick(cos_i, cos_t, total_internal, n1, n2) -> np.ndarray:
    """``fresnel_schlick`` given the (n,) float32 cosines of incidence and transmission and
    where total internal reflection is, as Snell's law forms them."""
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    cos = np.where(n1 > n2, cos_t, cos_i)
    reflectance = r0 + (np.float32(1.0) - r0) * (np.float32(1.0) - cos) ** 5
    reflectance = np.where(n1 == n2, np.float32(0.0), reflectance)
    return np.where(total_internal, np.float32(1.0), reflectance).astype(np.float32, copy=False)


def power(base: np.ndarray, exponent: np.ndarray) -> np.ndarray:
    """(n,) float32 ``max(base, 0) ** exponent`` for (n,) float32 ``base`` and positive
    ``exponent`` (a scalar or (n,)).

    Computed as ``exp(exponent · ln base)``: NumPy vectorises float32 ``exp`` and ``log`` but
    not ``pow``, so this is about three times faster. The error grows with ``|exponent · ln
    base|``: within 3e-6 relative wherever the power exceeds 1e-6, and 2e-7 absolute anywhere
    (far below what an 8-bit image shows).
    """
    result = np.maximum(base, np.float32(0.0))
    with np.errstate(divide="ignore"):  # log(0) = -inf, and exp(-inf) = 0 as 0 ** s is
        np.log(result, out=result)
    result *= exponent
    return np.exp(result, out=result)


def on_outline(cosine: np.ndarray, width: np.ndarray) -> np.ndarray:
    """(n,) bool: which hits lie on the outline of ``width`` (n,) float32 in [0, 1], a share of
    the radius, given the (n,) float32 cosines ``-d·N`` between each ray and its surface's
    normal turned to it.

    Seen along d, a sphere's (or a tube's cross-section's) point of normal N lies ``r·sin θ``
    from its centre, ``cos θ = -d·N``: within ``width · r`` of the silhouette exactly when
    ``sin θ > 1 - width``, i.e. ``cos² θ < width · (2 - width)``. Width 0 outlines nothing."""
    width = np.asarray(width, np.float32)
    return cosine * cosine < width * (np.float32(2.0) - width)


def _as_columns(rgb: np.ndarray) -> np.ndarray:
    """An RGB given as (3,) or (3, n), as something that broadcasts against (3, n)."""
    rgb = np.asarray(rgb, np.float32)
    return rgb[:, None] if rgb.ndim == 1 else rgb


def blinn_phong(
    normal: np.ndarray,
    incoming: np.ndarray,
    to_light: np.ndarray,
    color: np.ndarray,
    diffuse: np.ndarray,
    specular: np.ndarray,
    shininess: np.ndarray,
    light_rgb: np.ndarray,
) -> np.ndarray:
    """(3, n) float32 light that one point light sends toward the viewer off a surface.

    ``diffuse · max(0, N·L) · color · light_rgb + specular · max(0, N·H)^shininess · light_rgb``
    with ``H = normalize(L + V)``, and zero where ``N·L <= 0`` (no highlight on the dark side).
    ``normal``, ``to_light`` and ``incoming`` are (3, n) unit vectors: the viewer is at ``V =
    -incoming``, the direction of the ray that hit (a zero ``to_light`` column means no light
    there); ``color`` and ``light_rgb`` (3, n) or (3,); ``diffuse``,
    ``specular``, ``shininess`` (n,). The caller folds shadowing and the light's intensity
    into ``light_rgb`` or ``to_light``; there is no distance attenuation, as in the seed article.
    """
    light_rgb = _as_columns(light_rgb)
    n_dot_l = dot(normal, to_light)
    lit = n_dot_l > 0
    # (Temporaries reused in place where the float32 operations stay the same, in order.)
    shade = np.maximum(n_dot_l, np.float32(0.0), out=n_dot_l)
    shade *= diffuse
    radiance = shade * _as_columns(color)
    radiance *= light_rgb
    # Highlights only where there is a specular term and light: the power is the costly part.
    glossy = lit & (specular > 0)
    glossy_count = np.count_nonzero(glossy)
    if glossy_count == 0:
        return radiance
    if glossy_count > len(glossy) // 2:
        # Mostly glossy: every column, with the others' highlight masked to zero, costs less
        # than gathering five arrays and scattering back.
        half = to_light - incoming  # (L + V, bit for bit: x - y is x + (-y))
        n_dot_h = dot(normal, normalize(half, out=half))
        highlight = power(n_dot_h, shininess)
        highlight *= specular
        highlight *= glossy  # (h · s) · g is h · (s · g) for g in {0, 1}, finite h, s >= 0
        radiance += np.multiply(highlight, light_rgb, out=half)  # (half is free again)
        return radiance
    rows = np.flatnonzero(glossy)
    half = np.take(to_light, rows, axis=1)
    half -= np.take(incoming, rows, axis=1)
    n_dot_h = dot(np.take(normal, rows, axis=1), normalize(half, out=half))
    highlight = power(n_dot_h, shininess[rows])
    highlight *= specular[rows]
    light = light_rgb if light_rgb.shape[1] == 1 else np.take(light_rgb, rows, axis=1)
    scatter_add(radiance, rows, np.multiply(highlight, light, out=half))
    return radiance


def sky(directions: np.ndarray, horizon: np.ndarray, zenith: np.ndarray) -> np.ndarray:
    """(3, n) float32 sky gradient seen along (3, n) unit ``directions``.

    With ``t = clip(y, 0, 1)``: ``(1 - t) · horizon + t · zenith``; below the horizon the
    horizon color. ``horizon`` and ``zenith`` are RGB, (3,) or (3, n).
    """
    return sky_at(np.asarray(directions, np.float32)[1], horizon, zenith)


def sky_at(height: np.ndarray, horizon: np.ndarray, zenith: np.ndarray) -> np.ndarray:
    """``sky`` of directions given by their (n,) float32 y components ``height`` alone."""
    t = np.clip(np.asarray(height, np.float32), np.float32(0.0), np.float32(1.0))
    color = (np.float32(1.0) - t) * _as_columns(horizon)
    color += t * _as_columns(zenith)
    return color


def checker(points: np.ndarray, checker: Checker, out: np.ndarray | None = None) -> np.ndarray:
    """(3, n) float32 checkerboard color at (3, n) ``points``, by squares of the xz-plane:
    ``checker.color_a`` where ``floor(x / size) + floor(z / size)`` is even, else ``color_b``.
    ``out``: a (3, n) float32 array (or view) to write them to."""
    # float64 so the square a point falls in does not depend on float32 rounding of x / size.
    # The parity taken in float64, not through int64: a far hit (a grazing ray meets the floor
    # at any distance) over a small square passes 2**63 squares; beyond 2**53 all are even.
    # floor(x / size) + floor(z / size), formed in place in the copies of x and z.
    x, z = (np.array(points[axis], np.float64) for axis in (0, 2))
    for square in (x, z):
        np.divide(square, checker.size, out=square)
        np.floor(square, out=square)
    x += z
    odd = odd_integers(x).astype(np.intp)
    palette = np.array([checker.color_a, checker.color_b], np.float32).T  # (3, 2): even, odd
    if out is None:
        return np.take(palette, odd, axis=1)
    for row, colors in zip(out, palette, strict=True):  # ("clip": no copy of out; 0 and 1)
        np.take(colors, odd, out=row, mode="clip")
    return out


def odd_integers(values: np.ndarray) -> np.ndarray:
    """(n,) bool ``np.fmod(values, 2.0) != 0`` of (n,) float64 integer-valued ``values`` (or
    ±inf, NaN), bit for bit, some fifty times faster than libm's ``fmod``: ``v / 2`` is exact,
    and its floor times 2 gives ``v`` back exactly when ``v`` is even (every float64 from 2**53
    up is); ±inf and NaN count as odd, as ``fmod`` makes them NaN."""
    half = values * 0.5
    np.floor(half, out=half)
    half *= 2.0
    return (half != values) | np.isinf(values)
