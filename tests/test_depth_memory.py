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


# The deepest render measured, rendered before each measurement: see ``peak_traced_bytes``.
DEEPEST = 600


def peak_traced_bytes(renderer: Integrator, max_depth: int) -> int:
    """The most bytes Python and NumPy held at once during a render (NumPy reports its array
    buffers to tracemalloc), above what was held when it began.

    A render of ``DEEPEST`` bounces comes first: compiled and warm, and CPython's type
    attribute cache full. Numba's dispatcher fingerprints each NamedTuple argument of a kernel
    call by looking up ``_asdict``, ``_fields``, ``__class__`` and ``__name__`` through
    ``PyObject_GetAttrString``, which makes a new str of each name; the cache (4096 slots,
    chosen by the name object's address) keeps the last name looked up in each slot, so new
    names pile up there, 56-58 bytes each, until every slot is taken (``sys._clear_type_cache``
    frees them). Filled before the measurement, each name it takes frees the one it replaces."""
    render(renderer, DEEPEST)
    tracemalloc.start()
    try:
        start, _ = tracemalloc.get_traced_memory()
        render(renderer, max_depth)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak - start


def test_a_render_holds_no_more_at_depth_600_than_at_depth_6(renderer) -> None:
    peaks = {depth: peak_traced_bytes(renderer, depth) for depth in (6, 60, DEEPEST)}
    # Before samples were summed as added, the block kept every bounce's (3, 64) float32 and
    # (64,) int64 arrays: ~1.3 kB a bounce, 0.8 MB at depth 600 on this 8x8 image. With the
    # type attribute cache filled first (and ``integrator.HitRays`` a dataclass: see why
    # there), depth 600 measured within -7..+4 kB of depth 6, numba's caches cold or warm;
    # 32 kB is 55 bytes a bounce at depth 600, a twenty-fourth of that regression's.
    assert peaks[DEEPEST] <= peaks[6] + 32 * 1024, peaks
    assert peaks[60] <= peaks[6] + 32 * 1024, peaks


def test_the_image_is_finite_and_lit_at_depth_200(renderer) -> None:
    image = render(renderer, 200)
    assert np.isfinite(image).all() and image.max() > 0
