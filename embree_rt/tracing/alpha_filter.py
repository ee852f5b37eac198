"""Cutouts and one-sided surfaces during traversal: Embree geometry filter functions.

A glTF surface with ``alphaMode`` MASK is not there where its alpha (base-colour factor ×
texture alpha × vertex alpha) is below the cutoff, for camera, secondary and shadow rays alike;
a BLEND surface is not there where its alpha is 0, and for shadow rays (which ask yes or no)
where it is below one half; a ``doubleSided: false`` surface is not there for rays that reach
its back (shadow rays still meet it: a one-sided wall casts its shadow both ways). Embree calls
the filter for every hit its triangle test accepts on such a geometry, and the filter rejects
the hits on what is not there, so the traversal goes on past them: the next surface is found in
the same query, exactly as if the hole were in the mesh. Only geometries that need it get a
filter: every other triangle, sphere and instance is traced as before, at no cost.

The filter is a numba ``cfunc`` (``void(const RTCFilterFunctionNArguments*)``, read by the
Embree layer's layout: ``multihit``'s ``FILTER_*`` and ``HITN_*`` words; for an instanced
geometry the ray and hit are in the mesh's own space). Its per-geometry data is one block of
8-byte words (``BLOCK_*``) that the geometry's user pointer points at. The texture is read by
``embree_rt.textures``' own wrap rules, compiled.
"""

from __future__ import annotations

import numpy as np
from numba import carray, njit, types

from embree_rt.compiled import pointers
from embree_rt.compiled.callbacks import on_first_use
from embree_rt.embree import GeometryFilter
from embree_rt.embree.kernels import RAY_DIR
from embree_rt.embree.multihit import (
    FILTER_HIT,
    FILTER_N,
    FILTER_RAY,
    FILTER_USER,
    FILTER_VALID,
    HITN_NG,
    HITN_PRIM_ID,
    HITN_U,
    HITN_V,
)
from embree_rt.textures import REPEAT, reduce_coordinate, wrap_texel

# The data block, in 8-byte words (floats as float32 in the low half of their word).
BLOCK_FLAGS = 0
BLOCK_CUTOFF = 1
BLOCK_ALPHA = 2  # the base colour factor's alpha
BLOCK_FACES = 3  # (f, 3) int32
BLOCK_UV = 4  # (2, v) float32, or 0: no texture
BLOCK_VERTICES = 5
BLOCK_TEXELS = 6  # (h, w, 4) float32, alpha in the fourth channel
BLOCK_HEIGHT = 7
BLOCK_WIDTH = 8
BLOCK_WRAP_S = 9
BLOCK_WRAP_T = 10
BLOCK_NEAREST = 11
BLOCK_VERTEX_ALPHA = 12  # (v,) float32, or 0
BLOCK_WORDS = 13

FLAG_ONE_SIDED = 1
FLAG_MASK = 2
FLAG_BLEND = 4
# Below this alpha a BLEND surface lets a shadow ray through.
BLEND_SHADOW_CUTOFF = 0.5

_wrap = njit(inline="always")(wrap_texel)
_reduce = njit(inline="always")(reduce_coordinate)


@njit(inline="always")
def _float_word(block_address, index):
    return carray(pointers.floats(block_address + 8 * index), 1)[0]


@njit(cache=True)
def texture_alpha(texels_address, height, width, wrap_s, wrap_t, nearest, u, v):
    """The alpha channel of (h, w, 4) float32 texels at (u, v) (v up), sampled as
    ``embree_rt.textures.sample_texture`` samples: reduced coordinates, wrap, nearest or
    bilinear."""
    texels = carray(pointers.floats(texels_address), height * width * 4)
    s = _reduce(u, wrap_s)
    t = 1.0 - (v - np.floor(v)) if wrap_t == REPEAT else _reduce(1.0 - v, wrap_t)
    if nearest:
        column = _wrap(np.int64(np.floor(s * width)), width, wrap_s)
        row = _wrap(np.int64(np.floor(t * height)), height, wrap_t)
        return texels[(row * width + column) * 4 + 3]
    x = s * width - 0.5
    y = t * height - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    c0 = _wrap(np.int64(x0), width, wrap_s)
    c1 = _wrap(np.int64(x0) + 1, width, wrap_s)
    r0 = _wrap(np.int64(y0), height, wrap_t)
    r1 = _wrap(np.int64(y0) + 1, height, wrap_t)
    top = (1.0 - fx) * texels[(r0 * width + c0) * 4 + 3] + fx * texels[(r0 * width + c1) * 4 + 3]
    low = (1.0 - fx) * texels[(r1 * width + c0) * 4 + 3] + fx * texels[(r1 * width + c1) * 4 + 3]
    return (1.0 - fy) * top + fy * low


@njit(cache=True)
def _filter(address, shadow):
    args = carray(pointers.words64(address), 6)
    n = np.int64(args[FILTER_N] & 0xFFFFFFFF)
    valid = carray(pointers.ints(args[FILTER_VALID]), n)
    block_address = args[FILTER_USER]
    block = carray(pointers.words64(block_address), BLOCK_WORDS)
    ray = carray(pointers.floats(args[FILTER_RAY]), 12 * n)
    hit = carray(pointers.floats(args[FILTER_HIT]), 9 * n)
    hit_words = carray(pointers.ints(args[FILTER_HIT]), 9 * n)
    flags = block[BLOCK_FLAGS]
    cutoff = _float_word(block_address, BLOCK_CUTOFF)
    if flags & FLAG_BLEND and shadow:
        cutoff = BLEND_SHADOW_CUTOFF
    vertices = np.int64(block[BLOCK_VERTICES])
    for lane in range(n):
        if valid[lane] == 0:
            continue
        if flags & FLAG_ONE_SIDED and not shadow:
            facing = (
                ray[RAY_DIR * n + lane] * hit[HITN_NG * n + lane]
                + ray[(RAY_DIR + 1) * n + lane] * hit[(HITN_NG + 1) * n + lane]
                + ray[(RAY_DIR + 2) * n + lane] * hit[(HITN_NG + 2) * n + lane]
            )
            if facing > 0.0:  # the ray meets the back of the surface
                valid[lane] = 0
                continue
        if flags & (FLAG_MASK | FLAG_BLEND) == 0:
            continue
        alpha = np.float64(_float_word(block_address, BLOCK_ALPHA))
        if block[BLOCK_UV] != 0 or block[BLOCK_VERTEX_ALPHA] != 0:
            prim = np.int64(hit_words[HITN_PRIM_ID * n + lane])
            u = np.float64(hit[HITN_U * n + lane])
            v = np.float64(hit[HITN_V * n + lane])
            w = 1.0 - u - v
            corners = carray(pointers.ints(block[BLOCK_FACES] + 12 * prim), 3)
            if block[BLOCK_VERTEX_ALPHA] != 0:
                vertex_alpha = carray(pointers.floats(block[BLOCK_VERTEX_ALPHA]), vertices)
                alpha *= (
                    w * vertex_alpha[corners[0]]
                    + u * vertex_alpha[corners[1]]
                    + v * vertex_alpha[corners[2]]
                )
            if block[BLOCK_UV] != 0:
                uv = carray(pointers.floats(block[BLOCK_UV]), 2 * vertices)
                s = w * uv[corners[0]] + u * uv[corners[1]] + v * uv[corners[2]]
                t = (
                    w * uv[vertices + corners[0]]
                    + u * uv[vertices + corners[1]]
                    + v * uv[vertices + corners[2]]
                )
                alpha *= texture_alpha(
                    block[BLOCK_TEXELS],
                    np.int64(block[BLOCK_HEIGHT]),
                    np.int64(block[BLOCK_WIDTH]),
                    np.int64(block[BLOCK_WRAP_S]),
                    np.int64(block[BLOCK_WRAP_T]),
                    block[BLOCK_NEAREST] != 0,
                    s,
                    t,
                )
        if flags & FLAG_MASK or shadow:
            if alpha < cutoff:
                valid[lane] = 0
        elif alpha <= 0.0:  # BLEND: nothing at all where fully transparent
            valid[lane] = 0


_SIGNATURE = types.void(types.uintp)


@on_first_use(_SIGNATURE, nopython=True, cache=True)
def _intersect_filter(address):
    _filter(address, False)


@on_first_use(_SIGNATURE, nopython=True, cache=True)
def _occluded_filter(address):
    _filter(address, True)


def triangle_filter(
    faces: np.ndarray,
    *,
    one_sided: bool,
    alpha_mode: str = "OPAQUE",
    cutoff: float = 0.5,
    alpha: float = 1.0,
    uv: np.ndarray | None = None,
    texels: np.ndarray | None = None,
    wrap: tuple[int, int] = (REPEAT, REPEAT),
    nearest: bool = False,
    vertex_alpha: np.ndarray | None = None,
) -> GeometryFilter | None:
    """The filter of a triangle mesh, or None when it needs none (two-sided and opaque).

    ``faces`` (f, 3) int; ``alpha_mode`` "OPAQUE", "MASK" (cut out below ``cutoff``) or
    "BLEND"; ``alpha`` the base-colour factor's; ``uv`` (2, v) float32 per vertex (v up) with
    ``texels`` (h, w, 4) float32 whose fourth channel is alpha, read with ``wrap`` (s, t) and
    ``nearest``; ``vertex_alpha`` (v,) float32.
    """
    cutout = alpha_mode in ("MASK", "BLEND")
    if not one_sided and not cutout:
        return None
    faces = np.ascontiguousarray(faces, np.int32)
    block = np.zeros(BLOCK_WORDS, np.uint64)
    floats = block.view(np.float32)  # word k's low half is float k * 2
    flags = FLAG_ONE_SIDED * one_sided
    flags |= FLAG_MASK * (alpha_mode == "MASK") | FLAG_BLEND * (alpha_mode == "BLEND")
    block[BLOCK_FLAGS] = flags
    floats[2 * BLOCK_CUTOFF] = cutoff
    floats[2 * BLOCK_ALPHA] = alpha
    block[BLOCK_FACES] = faces.ctypes.data
    keep: list = [faces]
    if cutout and uv is not None and texels is not None:
        uv = np.ascontiguousarray(uv, np.float32)
        texels = np.ascontiguousarray(texels, np.float32)
        keep += [uv, texels]
        block[BLOCK_UV] = uv.ctypes.data
        block[BLOCK_VERTICES] = uv.shape[1]
        block[BLOCK_TEXELS] = texels.ctypes.data
        block[BLOCK_HEIGHT], block[BLOCK_WIDTH] = texels.shape[:2]
        block[BLOCK_WRAP_S], block[BLOCK_WRAP_T] = wrap
        block[BLOCK_NEAREST] = bool(nearest)
    if cutout and vertex_alpha is not None:
        vertex_alpha = np.ascontiguousarray(vertex_alpha, np.float32)
        keep.append(vertex_alpha)
        block[BLOCK_VERTEX_ALPHA] = vertex_alpha.ctypes.data
        block[BLOCK_VERTICES] = len(vertex_alpha)
    # one-sidedness leaves shadow rays unfiltered: a one-sided wall casts its shadow both ways
    occluded = _occluded_filter.address if cutout else 0
    return GeometryFilter(block, _intersect_filter.address, occluded, tuple(keep))
