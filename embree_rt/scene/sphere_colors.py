"""Per-sphere base colours, stored as (n, 3) uint8 sRGB (``budget.SPHERE_COLOR_BYTES``): 1e8
coloured spheres add 0.3 GB (float32 linear would add 1.2 GB), and 8 bits are what colour
tables and colormaps are given in."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from embree_rt.materials import Material


def as_srgb8(colors: np.ndarray, count: int) -> np.ndarray:
    """(count, 3) uint8 of ``colors``: uint8 as they are, floats (sRGB in 0..1) rounded.
    ValueError for another shape or a value outside 0..1."""
    colors = np.asarray(colors)
    if colors.shape != (count, 3):
        raise ValueError(f"colors: expected ({count}, 3) values, got shape {colors.shape}")
    if colors.dtype == np.uint8:
        return colors
    if colors.dtype.kind not in "fiu":
        raise ValueError(f"colors: expected numbers, got {colors.dtype}")
    values = colors.astype(np.float64)
    bad = ~((values >= 0.0) & (values <= 1.0)).all(axis=1)
    if bad.any():
        row = int(np.argmax(bad))
        raise ValueError(f"colors: row {row}: {values[row].tolist()} is not sRGB in 0..1")
    return np.rint(values * 255.0).astype(np.uint8)


def material_srgb8(materials: Mapping[str, Material], ids: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 sRGB of the (linear) colours of ``materials`` (a scene's table) ``ids``
    (n,) int32."""
    linear = np.array([m.color for m in materials.values()], np.float64).reshape(-1, 3)
    linear = np.clip(linear, 0.0, 1.0)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return np.rint(encoded * 255.0).astype(np.uint8)[ids]


def joined_colors(
    old: np.ndarray | None,
    old_ids: np.ndarray,
    materials: Mapping[str, Material],
    ids: np.ndarray,
    colors: np.ndarray | None,
) -> np.ndarray:
    """(m + n, 3) uint8: a scene's sphere colours ``old`` (m, 3) uint8, or None for the colours
    of their materials ``old_ids`` (m,), followed by those of n new spheres of materials ``ids``
    (n,): ``colors`` (n, 3) (``as_srgb8``) or, None, their materials'."""
    if old is None:
        old = material_srgb8(materials, old_ids)
    new = material_srgb8(materials, ids) if colors is None else as_srgb8(colors, len(ids))
    return new if len(old) == 0 else np.concatenate([old, new])
