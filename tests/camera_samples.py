"""The camera rays of a run of a render's samples, as the tests ask for them."""

from __future__ import annotations

import numpy as np

from embree_rt.camera import CameraFrame, sample_rays


def primary_rays(
    frame: CameraFrame, spp: int, seed: int, start: int, count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``camera.sample_rays`` of the global sample indices ``[start, start + count)``: origins
    (3, count) float32, unit directions (3, count) float32 and pixel (count,) int64."""
    return sample_rays(frame, spp, seed, np.arange(start, start + count, dtype=np.int64))
