"""Textures: 8-bit images decoded once to linear texels, sampled in batches.

Texture coordinates follow trimesh (and OBJ): ``u`` runs left to right, ``v`` bottom to top of
the image (trimesh flips glTF's top-down ``v`` on load). Texel ``(row, column)`` of an image
``h`` high and ``w`` wide has its centre at ``u = (column + 0.5) / w``, ``v = 1 - (row + 0.5) /
h``, as in OpenGL and glTF. Outside [0, 1) a ``Sampler``'s wrap modes apply (glTF's, which are
OpenGL's): REPEAT (the default), CLAMP_TO_EDGE, MIRRORED_REPEAT, each per axis, and it filters
linearly (the four nearest texels blended) or, for a NEAREST magnification filter, takes the one
texel the point falls in. There are no mipmaps: a minified texture is sampled as a magnified one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the caller decodes with Pillow; importing it costs every command ~12 ms
    from PIL import Image

# glTF sampler wrap modes and filters (OpenGL's codes).
REPEAT = 10497
CLAMP_TO_EDGE = 33071
MIRRORED_REPEAT = 33648
WRAP_MODES = (REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT)
NEAREST = 9728


@dataclass(frozen=True)
class Sampler:
    """How a texture is read: ``wrap_s`` along u, ``wrap_t`` along v (``WRAP_MODES``), and
    ``nearest`` (one texel) or linear filtering."""

    wrap_s: int = REPEAT
    wrap_t: int = REPEAT
    nearest: bool = False

    @property
    def wrap_s_t(self) -> tuple[int, int]:
        return self.wrap_s, self.wrap_t


DEFAULT_SAMPLER = Sampler()


def wrap_texel(index, size, mode):
    """Texel index (int, or int64 array) ``index`` along an axis of ``size`` texels brought into
    [0, size) by wrap ``mode``: repeat modulo ``size``, clamp to the edge texel, or mirror every
    other period. Plain arithmetic, so that the compiled alpha test (``embree_rt.tracing.
    alpha_filter``) runs this very function on single texels."""
    if mode == CLAMP_TO_EDGE:
        return np.minimum(np.maximum(index, 0), size - 1)
    if mode == MIRRORED_REPEAT:
        folded = index % (2 * size)
        return np.minimum(folded, 2 * size - 1 - folded)
    return index % size


def reduce_coordinate(coordinate, mode):
    """A texture coordinate (float or float32 array) moved into the period it samples the same
    texels in, by wrap ``mode`` ([0, 1) repeating, [0, 2) mirroring, [0, 1] clamping), so that
    far-out coordinates lose no precision in texel space. Shared with the alpha test as above."""
    if mode == CLAMP_TO_EDGE:
        return np.minimum(np.maximum(coordinate, 0.0), 1.0)
    if mode == MIRRORED_REPEAT:
        return coordinate - 2.0 * np.floor(coordinate * 0.5)
    return coordinate - np.floor(coordinate)


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """Linear values of sRGB-encoded ``encoded`` in [0, 1] (any shape, float), by the exact
    piecewise sRGB transfer function (IEC 61966-2-1), in float64."""
    encoded = np.asarray(encoded, np.float64)
    return np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)


# Linear value of each 8-bit sRGB code: images decode through one gather.
SRGB8_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


def texels_from_image(image: Image.Image, srgb: bool = True) -> np.ndarray:
    """(h, w, 4) float32 texels of an 8-bit image, row 0 at the top: RGB (linear from sRGB
    codes when ``srgb``, as colour textures are; code / 255 for data textures: normals,
    roughness) and alpha (code / 255; 1 where the image has none). 16 bytes a texel, so that a
    texel is fetched as one aligned word (2.8x faster than gathering 12-byte rows from a large
    texture). Palette, grey and alpha images included."""
    has_alpha = image.mode in ("RGBA", "LA", "PA") or "transparency" in image.info
    codes = np.asarray(image.convert("RGBA" if has_alpha else "RGB"), np.uint8)
    texels = np.ones((*codes.shape[:2], 4), np.float32)
    if srgb:
        texels[..., :3] = SRGB8_TO_LINEAR[codes[..., :3]]
    else:
        texels[..., :3] = codes[..., :3] / np.float32(255.0)
    if has_alpha:
        texels[..., 3] = codes[..., 3] / np.float32(255.0)
    return texels


def sample_bilinear(texels: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(3, n) float32 bilinear samples of the RGB of ``texels``, repeating outside [0, 1):
    ``sample_texture`` with the default sampler."""
    return sample_texture(texels, uv)[:3]


def sample_texture(
    texels: np.ndarray, uv: np.ndarray, sampler: Sampler = DEFAULT_SAMPLER
) -> np.ndarray:
    """(4, n) float32 samples (RGB and alpha) of ``texels`` (h, w, 4) float32 C-contiguous (as
    ``texels_from_image`` makes them) at texture coordinates ``uv`` (2, n) float32 (finite),
    read as ``sampler`` says.

    Linear filtering blends the four texels whose centres surround the point, with weights
    linear in the distance to them, neighbours beyond the border found by the wrap modes;
    nearest filtering takes the texel the point lies in.
    """
    height, width = texels.shape[:2]
    # One 16-byte word per texel: a 1-D take of single words is the cheapest gather.
    words = texels.reshape(height * width * 4).view(np.complex128)
    u, v = np.asarray(uv, np.float32)
    # Texel space with centres at integers: x = u·w − ½, y = (1 − v)·h − ½ (row 0 on top).
    # Reducing first keeps the numbers small, so far-out coordinates lose no precision.
    s = reduce_coordinate(u, sampler.wrap_s)
    if sampler.wrap_t == REPEAT:
        t = np.float32(1.0) - (v - np.floor(v))
    else:  # the wrap modes are defined on glTF's top-down coordinate, t = 1 − v
        t = reduce_coordinate(np.float32(1.0) - v, sampler.wrap_t)
    if sampler.nearest:
        column = wrap_texel(np.floor(s * np.float32(width)).astype(np.int64), width, sampler.wrap_s)
        row = wrap_texel(np.floor(t * np.float32(height)).astype(np.int64), height, sampler.wrap_t)
        picked = np.take(words, row * width + column).view(np.float32).reshape(-1, 4)
        return np.ascontiguousarray(picked.T)
    x = s * np.float32(width) - np.float32(0.5)
    y = t * np.float32(height) - np.float32(0.5)
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    # x0, y0 lie one texel beyond the reduced period at most: the wrap brings every neighbour in.
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    column0 = wrap_texel(x0, width, sampler.wrap_s)
    column1 = wrap_texel(x0 + 1, width, sampler.wrap_s)
    row0 = wrap_texel(y0, height, sampler.wrap_t)
    row1 = wrap_texel(y0 + 1, height, sampler.wrap_t)
    top = row0 * width
    bottom = row1 * width
    one = np.float32(1.0)
    blended = np.zeros((len(u), 4), np.float32)
    for index, weight in (
        (top + column0, (one - fx) * (one - fy)),
        (top + column1, fx * (one - fy)),
        (bottom + column0, (one - fx) * fy),
        (bottom + column1, fx * fy),
    ):
        texel = np.take(words, index).view(np.float32).reshape(-1, 4)
        texel *= weight[:, None]
        blended += texel
    return np.ascontiguousarray(blended.T)
