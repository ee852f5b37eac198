"""What a batch holds does not grow with the number of bounces: inside a closed perfect mirror,
every ray reflects at every depth, and a batch's film block sums each sample into its pixel as it
is added instead of keeping every bounce's until the batch ends (the memory a render needs is the
same at depth 600 as at depth 6; ``benchmarks/depth_memory.py`` measures it as peak RSS)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from embree_rt.camera import Camera, camera_frame
from embree_rt.integrator import Integrator
from embree_rt.materials import Material
from embree_rt.scene.model import PointLight, Scene

SIZE = 8  # an 8x8 image at 1 spp: 64 camera samples, one batch


def mirror_room() -> Scene:
    """A camera and a light inside a sphere that reflects everything (no floor, no sky seen)."""
    scene = Scene(
        camera=Camera(position=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, -1.0), fov=60.0),
        lights=[PointLight(position=(0.0, 2.0, 1.0))],
        floor=None,
    )
    scene.add_material("perfect_mirror", Material(reflectivity=1.0, specular=0.5))
    scene.add_sphere((0.0, 0.0, 0.0), 5.0, "perfect_mirror")
    return scene


def render(renderer: Integrator, max_depth: int) -> np.ndarray:
    frame = camera_frame(renderer.scene.camera, SIZE, SIZE)
    image, stats = renderer.render_image(frame, spp=1, max_depth=max_depth, seed=3)
    # Every ray of every depth reflected: the room is closed and the mirror loses nothing.
    assert stats.rays["reflection"] == SIZE * SIZE * max_depth
    return image


@pytest.fixture(scope="module")
def renderer():
    with Integrator(mirror_room(), threads=1) as built:
        yield built


def peak_traced_bytes(renderer: Integrator, max_depth: int) -> int:
    """The most bytes Python and NumPy held at once during a render (NumPy reports its array
    buffers to tracemalloc), above what was held when it began."""
    render(renderer, 2)  # compiled and warm: no first-call allocations in the measurement
    tracemalloc.start()
    try:
        start, _ = tracemalloc.get_traced_memory()
        render(renderer, max_depth)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak - start


def test_a_render_holds_no_more_at_depth_600_than_at_depth_6(renderer) -> None:
    peaks = {depth: peak_traced_bytes(renderer, depth) for depth in (6, 60, 600)}
    # Before samples were summed as added, the block kept every bounce's (3, 64) float32 and
    # (64,) int64 arrays: ~1.3 kB a bounce, 0.8 MB at depth 600 on this 8x8 image.
    # What still grows with depth is ~50-200 bytes a bounce (Python objects the collector frees
    # on its own schedule: 40-130 kB at depth 600 from run to run), a sixth of that regression's
    # at most: the bound allows 256 kB, a third of the 0.8 MB it would hold.
    assert peaks[600] <= peaks[6] + 256 * 1024, peaks
    assert peaks[60] <= peaks[6] + 256 * 1024, peaks


def test_the_image_is_finite_and_lit_at_depth_200(renderer) -> None:
    image = render(renderer, 200)
    assert np.isfinite(image).all() and image.max() > 0
