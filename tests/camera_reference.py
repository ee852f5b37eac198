"""The camera's samples as NumPy first computed them: the reference the compiled camera rays
(``embree_rt.compiled.camera_rays``) must equal bit for bit.

Array by array, the same operations the compiled loops do per sample, in the same order and
precision: ``tiled_samples`` the tile order of a batch, ``sample_rays`` the jittered rays.
"""

from __future__ import annotations

import numpy as np

from embree_rt.camera import TILE_HEIGHT, TILE_WIDTH, CameraFrame, strata
from embree_rt.sampling import uniform_pair


def tiled_samples(frame: CameraFrame, spp: int, start: int, count: int) -> np.ndarray:
    """(count,) int64 sample indices ``[start, start + count)`` (whole pixels) in tile order."""
    first, stop = start // spp, (start + count) // spp
    if stop == first:
        return np.zeros(0, np.int64)
    width = frame.width
    top = first // width // TILE_HEIGHT * TILE_HEIGHT
    pairs = ((stop - 1) // width - top) // TILE_HEIGHT + 1
    tiles_across = -(-width // TILE_WIDTH)
    row = np.arange(top, top + pairs * TILE_HEIGHT, dtype=np.int64).reshape(-1, 1, TILE_HEIGHT, 1)
    column = np.arange(tiles_across, dtype=np.int64).reshape(1, -1, 1, 1) * TILE_WIDTH + np.arange(
        TILE_WIDTH, dtype=np.int64
    ).reshape(1, 1, 1, -1)
    lines = (row * width + column).reshape(pairs, -1)
    if width % TILE_WIDTH:
        inside = np.broadcast_to(column < width, (1, tiles_across, TILE_HEIGHT, TILE_WIDTH))
        lines = lines[:, inside.ravel()]
    head = lines[0][(lines[0] >= first) & (lines[0] < stop)]
    if pairs == 1:
        pixel = head
    else:
        pixel = np.concatenate([head, lines[1:-1].ravel(), lines[-1][lines[-1] < stop]])
    if spp == 1:
        return pixel
    return (pixel[:, None] * spp + np.arange(spp, dtype=np.int64)).ravel()


def sample_rays(
    frame: CameraFrame, spp: int, seed: int, index: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins (3, n) float32, unit directions (3, n) float32 and pixels (n,) int64 of the
    camera samples ``index`` (n,) int64, in NumPy."""
    nx, ny, cells = strata(spp)
    pixel = index // spp if spp > 1 else index
    row = pixel // frame.width
    col = pixel % frame.width
    jitter_x, jitter_y = uniform_pair(seed, index, 0)
    if spp > 1:
        cell = cells[index % spp]
        cell_y, cell_x = cell // nx, cell % nx
        jitter_x = (cell_x + jitter_x) / nx  # int64 + float32: float64
        jitter_y = (cell_y + jitter_y) / ny
    column, line = col + jitter_x, row + jitter_y  # float64
    screen_x = (column * (2.0 * frame.half_width / frame.width) - frame.half_width).astype(
        np.float32
    )
    screen_y = (frame.half_height - line * (2.0 * frame.half_height / frame.height)).astype(
        np.float32
    )
    u, v, w = (axis.astype(np.float32)[:, None] for axis in (frame.u, frame.v, frame.w))
    directions = u * screen_x + v * screen_y - w
    directions /= np.sqrt(directions[0] ** 2 + directions[1] ** 2 + directions[2] ** 2)
    origins = np.empty((3, len(pixel)), np.float32)
    origins[:] = frame.origin.astype(np.float32)[:, None]
    return origins, directions, pixel
