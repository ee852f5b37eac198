"""Memory budgets: what a random field or a render will need, known before anything is allocated.

An input that cannot fit (a hundred-billion-pixel image, ten billion spheres) is refused up front
with one line saying what it needs and what the machine has, instead of failing deep inside NumPy
or Embree. The constants are peak resident memory measured on this project's own code
(``/usr/bin/time -v``, the growth between two sizes of the same command, so the interpreter's own
~0.2 GB cancels out); they are estimates, good to well within a factor of two.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from embree_rt.batches import worker_count
from embree_rt.errors import InputError
from embree_rt.memory import available_memory, format_bytes
from embree_rt.sphere_modes import sphere_kind

# The scene model's sphere arrays: (3,) float32 centre, float32 radius, int32 material.
SCENE_BYTES_PER_SPHERE = 20
# A sphere's own colour (``Scene.sphere_colors``, particle files): (3,) uint8 sRGB, read where a
# hit is shaded through the scene's index of the sphere, never copied per sphere. 1e8 coloured
# spheres as point spheres: (20 + 3 + 51) bytes, 7.4 GB.
SPHERE_COLOR_BYTES = 3
# Generating a random field: one ring of cells in flight a thread (candidates, sort, random
# draws). On 2 threads, 2e6 spheres added 80 MB and 6e6 160 MB: 20 bytes a sphere and ~40 MB.
FIELD_RING_BYTES = 20 << 20
# Beyond the scene's arrays, per sphere, by how the spheres enter the BVH: Embree's BVH and
# buffers, the sphere buffer, the hit labels. Whole `embree-rt random` commands at a 64x36 image,
# 1e6 -> 1e7 spheres, grew by 148 (user geometry) and 71 (point spheres) bytes a sphere, the
# scene's 20 included (user geometry in spatial order in a 4-wide tree, 1e6 -> 8e6: 171);
# instanced icospheres (``--spheres mesh``, one Embree instance array:
# float64 placements while they are made, float32 ones in Embree, its BVH), 2e5 -> 2e6 spheres,
# by 286 (``--instance MESH``, the same array: 308; both take the larger figure, so neither
# is let through short of memory).
GEOMETRY_BYTES_PER_SPHERE = {"user": 152, "point": 51, "mesh": 310}
# Meshes in the BVH (estimates for `embree-rt info`): a triangle stored once (float32 vertex,
# int32 index, Embree's nodes), an instance of its own, and an instance in an instance array
# (48 bytes of transform and ~80 of Embree's, measured at 1e6).
BYTES_PER_TRIANGLE = 12 + 12 + 64
BYTES_PER_INSTANCE = 256
BYTES_PER_ARRAYED_INSTANCE = 128
# A round linear curve segment in the BVH (its share of the float32 (x, y, z, r) points, its
# index, Embree's nodes and build): the peak resident memory of building a BVH of separate
# segments (two points each, the worst case) grew by 153 bytes a segment from 2e5 to 1e6.
BYTES_PER_CURVE_SEGMENT = 160
# Per pixel: the float32 image, the film's float64 sums of the blocks in flight, the tone
# mapping's float32 temporaries and the encoder's bytes. 3840x2160 and 7680x4320 at 1 spp grew
# by 72 bytes a pixel with a PNG written (36 before it).
FILM_BYTES_PER_PIXEL = 76
# Per camera sample in flight: the rays and hit records of the batches the workers hold (up to
# three batches a worker). 1920x1080 at 1 spp, 2 workers, 2^18-sample batches: 69 bytes a
# sample inside a closed mirror (every ray hits and reflects, depth 6), 19-41 in a random field.
# Independent of the depth: a batch's film block sums its samples whenever it holds more than
# the batch's camera samples (benchmarks/depth_memory.py: the same peak at depth 6, 60, 600).
BYTES_PER_SAMPLE_IN_FLIGHT = 72
BATCHES_IN_FLIGHT_PER_WORKER = 3


class ImageSettings(Protocol):
    """What a budget reads of a render's settings (a scene's ``RenderSettings``): the image's
    ``width`` and ``height`` in pixels and its ``spp`` samples per pixel."""

    width: int
    height: int
    spp: int


class MemoryBudgetError(InputError, ValueError):
    """An input that would need more memory than the machine has available: a request the
    machine cannot meet, so bad input (the command names the flag or key at fault).

    ``needs`` maps what needs memory (``"spheres"``, ``"image"``, ``"samples"``) to (bytes,
    description); ``largest`` is the key of the biggest need, so a caller can name the input
    at fault.
    """

    def __init__(self, needs: Mapping[str, tuple[int, str]], available: int) -> None:
        self.needs = dict(needs)
        self.available = available
        self.needed = sum(size for size, _ in self.needs.values())
        self.largest = max(self.needs, key=lambda key: self.needs[key][0])
        # Name only the needs that matter: a sphere's bytes beside a terabyte image are noise.
        named = [text for size, text in self.needs.values() if size >= 0.05 * self.needed]
        super().__init__(
            f"{' and '.join(named)} would need ~{format_bytes(self.needed)} of memory, "
            f"this machine has {format_bytes(available)} available"
        )


def field_bytes(count: int) -> int:
    """What generating a random field of ``count`` spheres on all cores (as ``random_field``
    does) needs: its arrays and a ring in the making on each core."""
    return count * SCENE_BYTES_PER_SPHERE + worker_count(None) * FIELD_RING_BYTES


def geometry_bytes(count: int, kind: str) -> int:
    """What building the BVH of ``count`` spheres needs beyond the scene's own arrays, the
    spheres going in as ``kind`` ("user", "point" or "mesh": ``sphere_modes.sphere_kind``)."""
    return count * GEOMETRY_BYTES_PER_SPHERE[kind]


def bvh_bytes(
    sphere_count: int,
    kind: str,
    triangles: int,
    instances: int,
    arrayed: int,
    curve_segments: int = 0,
) -> int:
    """An estimate of a BVH's memory: ``sphere_count`` spheres entered as ``kind``
    (``geometry_bytes``), ``triangles`` distinct triangles, ``instances`` instances of their
    own and ``arrayed`` instances in instance arrays (neither counting the spheres' own
    instances when ``kind`` is "mesh": ``GEOMETRY_BYTES_PER_SPHERE`` holds those), and
    ``curve_segments`` round curve segments."""
    return (
        geometry_bytes(sphere_count, kind)
        + triangles * BYTES_PER_TRIANGLE
        + instances * BYTES_PER_INSTANCE
        + arrayed * BYTES_PER_ARRAYED_INSTANCE
        + curve_segments * BYTES_PER_CURVE_SEGMENT
    )


def image_bytes(width: int, height: int, spp: int, batch_size: int, workers: int) -> int:
    """What rendering a ``width`` x ``height`` image at ``spp`` samples per pixel needs: the film
    and the image, and the batches that ``workers`` hold at once (``batch_bytes``)."""
    return width * height * FILM_BYTES_PER_PIXEL + batch_bytes(
        width * height, spp, batch_size, workers
    )


def batch_bytes(pixels: int, spp: int, batch_size: int, workers: int) -> int:
    """What the batches of a render of ``pixels`` pixels at ``spp`` samples per pixel need,
    ``workers`` holding a few each: a batch holds ``batch_size`` samples in whole pixels, so
    at least one pixel's ``spp`` (``batches.batch_ranges``)."""
    batch = max(1, batch_size // spp) * spp
    in_flight = min(pixels * spp, batch * BATCHES_IN_FLIGHT_PER_WORKER * workers)
    return in_flight * BYTES_PER_SAMPLE_IN_FLIGHT


def bvh_needs(sphere_count: int, spheres: str) -> dict[str, tuple[int, str]]:
    """What building the BVH of ``sphere_count`` spheres in mode ``spheres`` ("analytic",
    "point", "mesh") needs, for ``require`` (a Dask worker's whole need: the film stays with
    the client)."""
    kind = sphere_kind(sphere_count, spheres)
    return {"spheres": (geometry_bytes(sphere_count, kind), f"the BVH of {sphere_count:,} spheres")}


def render_needs(
    sphere_count: int,
    spheres: str,
    settings: ImageSettings,
    *,
    batch_size: int,
    threads: int | None,
    aov_pixel_bytes: int = 0,
) -> dict[str, tuple[int, str]]:
    """What a render of ``settings`` needs beyond the scene itself, for ``require``: the BVH of
    ``sphere_count`` spheres in mode ``spheres``, and the image with its batches of
    ``batch_size`` samples on ``threads`` (None: every core) and its AOVs' arrays,
    ``aov_pixel_bytes`` a pixel (``aovs.aov_pixel_bytes``; 0: no AOVs)."""
    width, height, spp = settings.width, settings.height, settings.spp
    image = width * height * FILM_BYTES_PER_PIXEL
    text = f"a {width}x{height} image"
    if aov_pixel_bytes:
        image += width * height * aov_pixel_bytes
        text += " with AOVs"
    batches = batch_bytes(width * height, spp, batch_size, worker_count(threads))
    return {
        **bvh_needs(sphere_count, spheres),
        "image": (image, text),
        "samples": (batches, f"the samples in flight at {spp} spp"),
    }


def require(needs: Mapping[str, tuple[int, str]]) -> None:
    """Raise ``MemoryBudgetError`` when the ``needs`` (key -> (bytes, description)) add up to
    more than the memory available now."""
    available = available_memory()
    if available is not None and sum(size for size, _ in needs.values()) > available:
        raise MemoryBudgetError(needs, available)
