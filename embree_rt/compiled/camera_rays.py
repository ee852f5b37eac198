"""Camera samples compiled: the tile order of a batch's samples and the ray of each sample.

``camera.tiled_samples`` and ``camera.sample_rays`` state the rule; these loops compute it in
one pass each, with no (n,) temporaries, and the Embree layer calls ``write_directions`` chunk
by chunk while it traces, so camera rays need no arrays before traversal. A perspective
camera's rays share its eye and differ in direction; an orthographic camera's share the
direction ``-w`` and start from the image plane, each at its own origin.

Every value is formed by the same operations, in the same order and the same precision, as the
NumPy expressions that first defined these rays (SplitMix64 in wrapping uint64; the jitter
and screen position in float64, rounded once to float32; the direction and its normalisation
in float32): IEEE 754 rounds each of them identically on any CPU. numba compiles without
``fastmath``, so LLVM neither contracts a multiply and an add into an FMA nor reorders a sum.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_UNIT = np.float32(2.0**-24)
_LOW24 = np.uint64(0xFFFFFF)


class CameraRays(NamedTuple):
    """What a camera sample's ray depends on besides its index (``camera.camera_rays``).

    ``origin``, ``u``, ``v``, ``w`` (3,) float32 the eye and the frame's axes; ``column_scale``
    = 2 half_width / width and ``half_width`` (likewise ``row_scale``, ``half_height``) float64;
    ``width``, ``spp`` the image's width and samples per pixel; ``nx``, ``ny`` and ``cells``
    (spp,) int64 the jitter grid (``camera.strata``); ``key`` the uint64 hash key of the seed
    and dimension 0 (``sampling.hash_key``); ``orthographic`` whether the rays are parallel
    (the half sizes then in world units)."""

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    column_scale: float
    half_width: float
    row_scale: float
    half_height: float
    width: int
    spp: int
    nx: int
    ny: int
    cells: np.ndarray
    key: np.uint64
    orthographic: bool


@njit(inline="always")
def splitmix64(x):
    """SplitMix64's finaliser of a uint64, wrapping as ``sampling``'s NumPy version does."""
    x = x + _GOLDEN
    x = (x ^ (x >> np.uint64(30))) * _MIX1
    x = (x ^ (x >> np.uint64(27))) * _MIX2
    return x ^ (x >> np.uint64(31))


@njit(inline="always")
def sample_screen(camera, index):
    """The float32 image-plane point (x right, y up) of camera sample ``index`` (int64)."""
    spp = camera.spp
    pixel = index // spp
    row = pixel // camera.width
    col = pixel - row * camera.width
    bits = splitmix64(np.uint64(index) ^ camera.key)
    jitter_x = np.float32(bits >> np.uint64(40)) * _UNIT
    jitter_y = np.float32((bits >> np.uint64(16)) & _LOW24) * _UNIT
    if spp > 1:
        cell = camera.cells[index - pixel * spp]
        cell_y = cell // camera.nx
        cell_x = cell - cell_y * camera.nx
        x = (np.float64(cell_x) + np.float64(jitter_x)) / np.float64(camera.nx)
        y = (np.float64(cell_y) + np.float64(jitter_y)) / np.float64(camera.ny)
    else:
        x = np.float64(jitter_x)
        y = np.float64(jitter_y)
    column = np.float64(col) + x
    line = np.float64(row) + y
    screen_x = np.float32(column * camera.column_scale - camera.half_width)
    screen_y = np.float32(camera.half_height - line * camera.row_scale)
    return screen_x, screen_y


@njit(inline="always")
def sample_direction(camera, index):
    """The float32 unit direction (x, y, z) of perspective camera sample ``index`` (int64)."""
    screen_x, screen_y = sample_screen(camera, index)
    u, v, w = camera.u, camera.v, camera.w
    dx = u[0] * screen_x + v[0] * screen_y - w[0]
    dy = u[1] * screen_x + v[1] * screen_y - w[1]
    dz = u[2] * screen_x + v[2] * screen_y - w[2]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    return dx / length, dy / length, dz / length


@njit(inline="always")
def sample_origin(camera, index):
    """The float32 origin (x, y, z) of orthographic camera sample ``index`` (int64): its
    image-plane point ``eye + x u + y v``, in float32 as a perspective direction is formed."""
    screen_x, screen_y = sample_screen(camera, index)
    o, u, v = camera.origin, camera.u, camera.v
    return (
        o[0] + (u[0] * screen_x + v[0] * screen_y),
        o[1] + (u[1] * screen_x + v[1] * screen_y),
        o[2] + (u[2] * screen_x + v[2] * screen_y),
    )


@njit(nogil=True, cache=True)
def write_directions(camera, index, first, stop, directions, origins):
    """Rays of samples ``index[first:stop]`` ((n,) int64): their directions into the same
    columns of ``directions`` (3, n) float32 and, for an orthographic camera, their origins
    into ``origins`` (3, n) float32 (None for a perspective camera, whose rays all start at
    its eye)."""
    if camera.orthographic:
        for i in range(first, stop):
            directions[0, i] = -camera.w[0]
            directions[1, i] = -camera.w[1]
            directions[2, i] = -camera.w[2]
            if origins is not None:
                ox, oy, oz = sample_origin(camera, index[i])
                origins[0, i] = ox
                origins[1, i] = oy
                origins[2, i] = oz
        return
    for i in range(first, stop):
        dx, dy, dz = sample_direction(camera, index[i])
        directions[0, i] = dx
        directions[1, i] = dy
        directions[2, i] = dz


@njit(nogil=True, cache=True)
def sample_rays(camera, index):
    """(3, n) float32 origins and (3, n) float32 unit directions of the (n,) int64 camera
    samples ``index``."""
    n = index.shape[0]
    directions = np.empty((3, n), np.float32)
    origins = np.empty((3, n), np.float32)
    write_directions(camera, index, 0, n, directions, origins)
    if not camera.orthographic:
        for i in range(n):
            origins[0, i] = camera.origin[0]
            origins[1, i] = camera.origin[1]
            origins[2, i] = camera.origin[2]
    return origins, directions


@njit(nogil=True, cache=True)
def tile_order(width, spp, tile_width, tile_height, first, stop):
    """The samples of pixels ``[first, stop)`` in tile order: (k,) int64 sample indices and
    (k,) int64 their pixels (the same array at 1 spp), k = (stop - first) spp. Tiles of
    ``tile_width`` x ``tile_height`` pixels left to right along each band of ``tile_height``
    rows (the last tile of a row cut at the image's edge), pixels row-major inside a tile, each
    pixel's samples together in order."""
    n = (stop - first) * spp
    index = np.empty(n, np.int64)
    # at 1 spp a sample's index is its pixel's: one array serves as both
    pixel = index if spp == 1 else np.empty(n, np.int64)
    if n == 0:
        return index, pixel
    k = 0
    top = first // width // tile_height * tile_height
    last_row = (stop - 1) // width
    for band in range(top, last_row + 1, tile_height):
        whole = band * width >= first and (band + tile_height) * width <= stop
        if whole and spp == 1:  # (most bands of a batch: no bounds to test, one array)
            for left in range(0, width, tile_width):
                right = min(left + tile_width, width)
                for row in range(band, band + tile_height):
                    for p in range(row * width + left, row * width + right):
                        index[k] = p
                        k += 1
            continue
        for left in range(0, width, tile_width):
            right = min(left + tile_width, width)
            for row in range(band, band + tile_height):
                for column in range(left, right):
                    p = row * width + column
                    if p < first or p >= stop:
                        continue
                    for s in range(spp):
                        index[k] = p * spp + s
                        pixel[k] = p
                        k += 1
    return index, pixel
