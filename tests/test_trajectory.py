"""The frames pipeline of a particle trajectory (``cli.trajectory``): refitted frames are the
images of freshly built ones, overlapped frames those of sequential ones, and memory stays flat
over a long run.

Why bitwise on every ISA: each image is compared with one made on the same machine. A sphere's
hit is computed by the user-geometry callback from that sphere's float32 data and the ray alone,
in the same float64 arithmetic whatever tree called it, so the nearest hit is the least t over the
spheres a ray meets: a function of the spheres, not of the tree (refitted or built anew, with the
spheres in either order). Two distinct spheres met at exactly one float32 distance go to the
lower index in the scene, however a rebuild orders the spheres (``tests/test_refit.py`` builds
such ties). Overlap changes only which thread reads and writes: the
render itself runs the same code on the same inputs.
"""

from __future__ import annotations

import itertools
import re
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.cli import main
from embree_rt.cli.trajectory import FrameRendering, StageSeconds, render_frames

FRAMES = 5


def write_moving_dump(path: Path, frames: int = FRAMES, count: int = 60, seed: int = 4) -> None:
    """A LAMMPS text dump by hand (no library writes one): ``count`` particles of fixed types
    and radii drifting frame to frame inside a 0..10 box."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(2.0, 8.0, (count, 3))
    velocity = rng.normal(0.0, 0.2, (count, 3))
    types = rng.integers(1, 4, count)
    radii = np.round(rng.uniform(0.2, 0.6, count), 4)
    with open(path, "w") as out:
        for step in range(frames):
            positions = np.round(start + velocity * step, 6)
            out.write(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{count}\n")
            out.write("ITEM: BOX BOUNDS pp pp pp\n" + "0.0 10.0\n" * 3)
            out.write("ITEM: ATOMS id type x y z radius\n")
            for i in range(count):
                x, y, z = positions[i]
                out.write(f"{i + 1} {types[i]} {x} {y} {z} {radii[i]}\n")


def render_dump(tmp_path: Path, out: str, *flags: str) -> list[Path]:
    code = main(
        [
            "render",
            str(tmp_path / "d.lammpstrj"),
            "-o",
            str(tmp_path / out / "f_{frame:02d}.npy"),
            "--width",
            "40",
            "--height",
            "30",
            "--spp",
            "1",
            *(flags or ("--threads", "2")),
        ]
    )
    assert code in (0, None)
    return sorted((tmp_path / out).glob("f_*.npy"))


def test_refitted_frames_are_fresh_builds_bitwise(tmp_path, capsys):
    write_moving_dump(tmp_path / "d.lammpstrj")
    refitted = render_dump(tmp_path, "refit")
    assert f"{FRAMES - 1} refitted, 1 rebuilt" in capsys.readouterr().err
    rebuilt = render_dump(tmp_path, "rebuild", "--no-refit", "--threads", "2")
    assert f"0 refitted, {FRAMES} rebuilt" in capsys.readouterr().err
    assert len(refitted) == len(rebuilt) == FRAMES
    images = [np.load(path) for path in refitted]
    for a, b in zip(refitted, rebuilt, strict=True):
        np.testing.assert_array_equal(np.load(a), np.load(b))
    for a, b in itertools.pairwise(images):  # the particles move: so do the images
        assert not np.array_equal(a, b)


def moving_scene(frame: int, count: int = 30, seed: int = 6) -> rt.Scene:
    """A scene of ``count`` spheres drifting with ``frame`` (the same radii every frame)."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(-2.0, 2.0, (count, 3))
    velocity = rng.normal(0.0, 0.05, (count, 3))
    scene = rt.Scene()
    scene.add_spheres(start + velocity * frame, rng.uniform(0.1, 0.4, count), "matte")
    scene.camera = rt.Camera(position=(0.0, -9.0, 3.0), look_at=(0.0, 0.0, 0.0))
    scene.lights = [rt.PointLight(position=(3.0, -5.0, 8.0), intensity=60.0)]
    scene.render = scene.render.with_overrides(width=24, height=16, spp=1, max_depth=2)
    return scene


def test_the_summary_line_gives_the_frames_after_the_first(tmp_path, capsys):
    # Each stage's seconds are the mean over the frames after the first (whose time holds the
    # first build and numba's loading): 5, then 1 and 2, is 1.5.
    stage = StageSeconds()
    for seconds in (5.0, 1.0, 2.0):
        stage.add(seconds)
    assert (stage.count, stage.mean()) == (3, 1.5)
    write_moving_dump(tmp_path / "d.lammpstrj")
    render_dump(tmp_path, "frames")
    line = capsys.readouterr().err.strip().splitlines()[-1]
    numbers = r"(\d+\.\d\d) s"
    found = re.search(
        rf"{numbers} a frame after the first \(a frame's BVH {numbers}, render {numbers}; "
        rf"beside them, reading the next {numbers} and writing the last {numbers}\) -> ",
        line,
    )
    assert found is not None, line
    render_dump(tmp_path, "one", "--frames", "0:1", "--threads", "2")
    assert "after the first" not in capsys.readouterr().err  # one frame: no steady state


@pytest.mark.parametrize("refit", [True, False])
def test_overlapped_frames_are_sequential_frames_bitwise(refit: bool):
    numbers = list(range(6))
    images: dict[bool, dict[int, np.ndarray]] = {True: {}, False: {}}
    for overlap in (True, False):
        how = FrameRendering(threads=2, refit=refit, overlap=overlap)
        counts = render_frames(
            numbers,
            moving_scene,
            lambda n, result, overlap=overlap: images[overlap].__setitem__(n, result.image),
            how,
        )
        assert (counts.refitted, counts.rebuilt) == ((5, 1) if refit else (0, 6))
    assert sorted(images[True]) == numbers
    for n in numbers:
        np.testing.assert_array_equal(images[True][n], images[False][n])


def test_an_error_in_a_stage_is_raised_and_stops_the_frames():
    written = []

    def read(n: int) -> rt.Scene:
        if n == 3:
            raise OSError("frame 3 is truncated")
        return moving_scene(n)

    with pytest.raises(OSError, match="frame 3"):
        render_frames(range(6), read, lambda n, result: written.append(n), FrameRendering())
    assert written == [0, 1, 2]


def test_memory_is_flat_over_a_thousand_tiny_frames():
    """A thousand frames of a few spheres at 4x4 pixels: the memory Python holds grows by far
    less between frames 500 and 999 than it would were each frame's result kept alive (about
    1.9 kB a frame here, measured by keeping them: ~950 kB over those 499 frames). The first
    hundreds of frames are left out: caches (NumPy's, the kernels') fill there."""
    base = moving_scene(0, count=4)
    base.render = base.render.with_overrides(width=4, height=4)
    held: dict[int, int] = {}

    def read(n: int) -> rt.Scene:
        scene = moving_scene(0, count=4)
        scene.render = base.render
        scene.sphere_centers = base.sphere_centers + np.float32(0.001 * n)
        return scene

    def write(n: int, result) -> None:
        if n in (500, 999):
            held[n] = tracemalloc.get_traced_memory()[0]

    tracemalloc.start()
    try:
        counts = render_frames(range(1000), read, write, FrameRendering(threads=1))
    finally:
        tracemalloc.stop()
    assert (counts.refitted, counts.rebuilt) == (999, 1)
    assert held[999] - held[500] < 200 * 1024, held


def decoded(path: Path) -> list[np.ndarray]:
    """The (h, w, 3) uint8 frames of a video, decoded by the reader library (Pillow for GIF,
    imageio-ffmpeg's ffmpeg for the others)."""
    if path.suffix == ".gif":
        from PIL import Image, ImageSequence

        with Image.open(path) as gif:
            return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(gif)]
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    width, height = meta["size"]
    return [np.frombuffer(f, np.uint8).reshape(height, width, 3) for f in reader]


@pytest.mark.parametrize("suffix", [".gif", ".mp4", ".webm"])
def test_video_frames_are_the_trajectory_frames(tmp_path, suffix):
    """Each decoded frame is nearest to the PNG of its own frame among all the frames' PNGs:
    the video holds the frames in order, and they differ as the positions do."""
    from PIL import Image

    write_moving_dump(tmp_path / "d.lammpstrj", frames=FRAMES, count=60)
    flags = ["--width", "40", "--height", "30", "--spp", "1", "--threads", "2"]
    dump = str(tmp_path / "d.lammpstrj")
    assert main(["render", dump, "-o", str(tmp_path / "f_{frame}.png"), *flags]) in (0, None)
    pngs = [np.asarray(Image.open(tmp_path / f"f_{k}.png"), np.float64) for k in range(FRAMES)]
    video = tmp_path / f"v{suffix}"
    assert main(["render", dump, "-o", str(video), "--fps", "5", "--quality", "100", *flags]) in (
        0,
        None,
    )
    frames = decoded(video)
    assert len(frames) == FRAMES
    for k, frame in enumerate(frames):
        distances = [np.abs(frame - png).mean() for png in pngs]
        assert int(np.argmin(distances)) == k, distances
    assert [p.name for p in tmp_path.iterdir() if "partial" in p.name] == []


def test_an_interrupted_video_leaves_no_file(tmp_path):
    from embree_rt.video import VideoWriter

    (tmp_path / "old.gif").write_bytes(b"kept")
    for name in ("v.mp4", "old.gif"):
        with pytest.raises(KeyboardInterrupt), VideoWriter(tmp_path / name, 10) as video:
            video.add(np.zeros((8, 8, 3), np.uint8))
            raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.gif"]
    assert (tmp_path / "old.gif").read_bytes() == b"kept"


def test_frames_on_a_dask_cluster_are_the_local_frames_bitwise(tmp_path, capsys):
    """local:2 gives each worker a contiguous run of frames (a BVH built once, then refitted):
    one rebuild a worker, and every image the local run's (a frame's image depends on its
    scene alone, not on the tree nor on which process renders it)."""
    write_moving_dump(tmp_path / "d.lammpstrj")
    here = render_dump(tmp_path, "here", "--threads", "1")
    capsys.readouterr()
    code = main(
        [
            "render",
            str(tmp_path / "d.lammpstrj"),
            "-o",
            str(tmp_path / "dask" / "f_{frame:02d}.npy"),
            *["--width", "40", "--height", "30", "--spp", "1", "--cluster", "local:2"],
        ]
    )
    assert code in (0, None)
    assert f"{FRAMES - 2} refitted, 2 rebuilt" in capsys.readouterr().err
    there = sorted((tmp_path / "dask").glob("f_*.npy"))
    assert [p.name for p in there] == [p.name for p in here]
    for a, b in zip(here, there, strict=True):
        np.testing.assert_array_equal(np.load(a), np.load(b))


def test_views_from_a_cameras_file_are_the_stills_of_those_cameras(tmp_path, capsys):
    """``--cameras``: view k is the still the API renders of the same file seen by camera k
    (bitwise: one machine, one scene, the same camera), written with its camera data; a bad key
    is refused naming the file and the camera, exit 2, nothing written."""
    import json

    write_moving_dump(tmp_path / "d.lammpstrj")
    cameras = [
        {"position": [0.0, -30.0, 10.0], "look_at": [5.0, 5.0, 5.0]},
        {"position": [30.0, 0.0, 10.0], "look_at": [5.0, 5.0, 5.0], "fov": 30.0},
    ]
    (tmp_path / "cams.json").write_text(json.dumps({"cameras": cameras}))
    size = ["--width", "40", "--height", "30", "--spp", "1", "--threads", "2"]
    dump = str(tmp_path / "d.lammpstrj")
    pattern = str(tmp_path / "views" / "v_{view:02d}.npz")
    argv = ["render", dump, "--cameras", str(tmp_path / "cams.json"), "-o", pattern, *size]
    assert main([*argv, "--aov", "depth"]) in (0, None)
    assert "2 views" in capsys.readouterr().err
    scene = rt.Scene.from_particles(dump, up="z")
    for k, camera in enumerate(cameras):
        with np.load(tmp_path / "views" / f"v_{k:02d}.npz") as view:
            expected = rt.render(
                scene,
                camera=rt.Camera(**camera),
                width=40,
                height=30,
                spp=1,
                threads=2,
            )
            np.testing.assert_array_equal(view["beauty"], expected.image)
            assert view["depth"].shape == (30, 40)
    (tmp_path / "bad.json").write_text(json.dumps({"cameras": [{"fovv": 3}]}))
    bad = [
        "render",
        dump,
        "--cameras",
        str(tmp_path / "bad.json"),
        "-o",
        str(tmp_path / "b_{view}.png"),
    ]
    assert main(bad) == 2
    assert "bad.json: cameras[0].fovv: unknown key" in capsys.readouterr().err
    assert not list(tmp_path.glob("b_*"))
