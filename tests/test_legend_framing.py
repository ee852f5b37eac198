"""The legend's corner kept clear by a perspective framing (``staging.clear_of_corner``): the
framed box's corners, projected by the renderer's own camera frame, lie left of the legend or
above it and inside the image, the camera keeping its direction and never coming nearer; a
particle file's render with ``--legend`` shows no particle under the legend (its ``object_id``
AOV), and the framing moves only where it must."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from embree_rt.api import render
from embree_rt.camera import Camera, camera_frame
from embree_rt.cli import main
from embree_rt.legend import legend_corner, legend_patch, legend_size
from embree_rt.scene.model import Scene
from embree_rt.scene.particles.look import ParticleLook
from embree_rt.scene.staging import View, clear_of_corner, framed_view

ROOT = Path(__file__).resolve().parents[1]
PACKING = str(ROOT / "assets" / "packing.lammpstrj")
# Slack on the image's unit square for float64 rounding of the projection.
SLACK = 1e-9


def projected(view: View, low: np.ndarray, high: np.ndarray, width: int, height: int):
    """The box's eight corners through the camera frame a render uses (``camera_frame``): x, y
    (8,) float64 in image units (-1..1 from left to right, bottom to top) and depth (8,)."""
    camera = Camera(position=view.position, look_at=view.look_at, up=view.up, fov=view.fov)
    frame = camera_frame(camera, width, height)
    box = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    relative = low + box * (high - low) - frame.origin
    depth = -(relative @ frame.w)
    x = relative @ frame.u / depth / frame.half_width
    y = relative @ frame.v / depth / frame.half_height
    return x, y, depth, frame


def random_cases(count: int):
    """Boxes of every proportion, off-centre views of them, images from portrait to wide and
    corners from a sliver to most of the image."""
    rng = np.random.default_rng(36)
    for _ in range(count):
        low = rng.uniform(-50.0, 50.0, 3)
        high = low + rng.uniform(0.01, 30.0, 3) * rng.choice([1.0, 0.05], 3)
        view = framed_view(low, high, fov=float(rng.uniform(15.0, 90.0)))
        width, height = int(rng.integers(40, 400)), int(rng.integers(40, 400))
        corner = (float(rng.uniform(0.05, 0.8)), float(rng.uniform(0.05, 0.6)))
        yield low, high, view, width, height, corner


def test_a_view_moved_clear_keeps_the_box_out_of_the_corner_and_in_the_image() -> None:
    moved_count = 0
    for low, high, view, width, height, corner in random_cases(300):
        moved = clear_of_corner(view, low, high, width / height, corner)
        x, y, depth, frame = projected(moved, low, high, width, height)
        before = projected(view, low, high, width, height)
        left, top = 1.0 - 2.0 * corner[0], -1.0 + 2.0 * corner[1]
        assert (depth > 0).all()
        assert (x <= left + SLACK).all() or (y >= top - SLACK).all(), (corner, x, y)
        if moved == view:  # left as it was: it kept out already
            assert (before[0] <= left).all() or (before[1] >= top).all()
            continue
        moved_count += 1
        assert (np.abs(x) <= 1 + SLACK).all() and (np.abs(y) <= 1 + SLACK).all(), (x, y)
        # the same direction, no nearer to what it looks at
        assert np.allclose(frame.w, before[3].w, rtol=0, atol=1e-12)
        assert math.dist(moved.position, moved.look_at) >= math.dist(
            view.position, view.look_at
        ) * (1 - 1e-12)
    assert moved_count > 100  # most of the cases had to move (the test exercises the move)


def test_a_view_already_clear_is_returned_as_it_is() -> None:
    low, high = np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0])
    view = framed_view(low, high)
    # a wide image: the framed ball spans 0.56 of its width, and the corner takes a sliver
    assert clear_of_corner(view, low, high, 16 / 9, (0.1, 0.25)) is view


def legend_pixels(shape: tuple[int, int], legend) -> tuple[slice, slice]:
    """The rows and columns ``draw_legend`` paints over an image of ``shape`` (h, w)."""
    patch, _ = legend_patch(legend, legend_size(legend, shape[0]))
    top, left = legend_corner(shape, patch.shape)
    return slice(top, top + patch.shape[0]), slice(left, left + patch.shape[1])


@pytest.mark.parametrize(
    "size, view", [((120, 160), []), ((200, 200), []), ((120, 160), ["--view", "iso"])]
)
def test_no_particle_lies_under_the_legend_of_a_framed_render(tmp_path, size, view) -> None:
    """A portrait and a square image of the packing coloured by vz, framed by default or as a
    perspective standard view, whose framings reach the corner (before the move, 950-1800
    particle pixels lay under the legend in each)."""
    width, height = size
    out = tmp_path / "packing.npz"
    flags = ["--width", str(width), "--height", str(height), "--spp", "1", "--quiet"]
    look = ["--color-by", "vz", "--legend", "--aov", "object_id", *view]
    if view:
        look.append("--perspective")
    assert main(["render", PACKING, "-o", str(out), *look, *flags]) == 0
    ids = np.load(out)["object_id"]
    scene = Scene.from_particles(PACKING, look=ParticleLook(color_by="vz"), legend=True)
    particles = (ids >= 0) & (ids < len(scene.sphere_radii))
    rows, columns = legend_pixels(ids.shape, scene.legend)
    assert particles.sum() > 0.1 * ids.size  # the packing is in the picture
    assert not particles[rows, columns].any()


def test_a_framing_that_keeps_clear_already_is_unchanged(tmp_path) -> None:
    """Wide, the framed membrane keeps out of the legend's corner: its radiance is the same bits
    with --legend as without (both rendered here by the same code from the same camera), and
    without --legend the command frames as the Python API does (bitwise: the same scene and
    camera, rendered by the same code)."""
    membrane = str(ROOT / "assets" / "membrane.gsd")
    flags = ["--width", "160", "--height", "90", "--spp", "1", "--quiet"]
    assert main(["render", membrane, "-o", str(tmp_path / "key.npy"), "--legend", *flags]) == 0
    assert main(["render", membrane, "-o", str(tmp_path / "plain.npy"), *flags]) == 0
    plain = np.load(tmp_path / "plain.npy")
    assert np.array_equal(np.load(tmp_path / "key.npy"), plain)
    scene = Scene.from_particles(membrane)
    scene.render.width, scene.render.height, scene.render.spp = 160, 90, 1
    assert np.array_equal(render(scene).image, plain)
