"""What a batch holds does not grow with the number of bounces: inside a closed perfect mirror,
every ray reflects at every depth, and a batch's film block sums its samples as it goes instead
of keeping every bounce's until the batch ends (the memory a render needs is the same at depth
600 as at depth 6; ``benchmarks/depth_memory.py`` measures it as peak RSS)."""

from __future__ import annotations

import numpy as np
import pytest

from embree_rt import integrator
from embree_rt.camera import Camera, camera_frame
from embree_rt.film import FilmBlock
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


class CountingBlock(FilmBlock):
    """A film block that records the most samples it held unsummed at once."""

    peaks: list[int] = []  # noqa: RUF012 (one list for the test, reset by it)

    def __init__(self, first: int, count: int, hold: int | None = None) -> None:
        super().__init__(first, count, hold)
        self.unsummed = 0
        self.peaks.append(0)

    def add(self, pixel: np.ndarray, rgb: np.ndarray) -> None:
        self.unsummed += len(pixel)
        self.peaks[-1] = max(self.peaks[-1], self.unsummed)
        super().add(pixel, rgb)

    def settle(self) -> None:
        self.unsummed = 0
        super().settle()


class HoldingBlock(FilmBlock):
    """A film block that sums only at the end, as blocks did before they had a bound."""

    def __init__(self, first: int, count: int, hold: int | None = None) -> None:
        super().__init__(first, count, None)


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


def test_a_batch_holds_no_more_samples_at_depth_600_than_at_depth_6(renderer, monkeypatch):
    monkeypatch.setattr(integrator, "FilmBlock", CountingBlock)
    peaks = {}
    for depth in (6, 60, 600):
        CountingBlock.peaks = []
        render(renderer, depth)
        assert len(CountingBlock.peaks) == 1  # one batch
        peaks[depth] = CountingBlock.peaks[0]
    samples = SIZE * SIZE
    # At most a batch's worth held, plus the one add that went past it (a bounce's samples:
    # one per ray in flight, here every camera sample's ray).
    assert max(peaks.values()) <= 2 * samples
    assert peaks[600] == peaks[60]


def test_summing_as_it_goes_gives_bitwise_the_image_of_summing_at_the_end(renderer, monkeypatch):
    """Bitwise on every x86-64 ISA: the blocks add the same float64 samples in the same order
    (``FilmBlock``'s docstring); only when they add them differs."""
    settled = render(renderer, 200)
    monkeypatch.setattr(integrator, "FilmBlock", HoldingBlock)
    held = render(renderer, 200)
    assert np.isfinite(settled).all() and settled.max() > 0
    assert settled.tobytes() == held.tobytes()
