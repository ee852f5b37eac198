"""Camera paths: the ``[animation]`` table (checks, interpolation, saving) and the command's
frame files (patterns, ``--frames``, skipping frames on disk, ``--overwrite``)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.cli import main
from embree_rt.scene.animation import Animation, Keyframe, camera_at, frame_cameras

BASE = """[render]
width = 24
height = 16
spp = 1
[camera]
position = [0.0, 1.0, 5.0]
look_at = [0.0, 0.5, 0.0]
[[lights]]
position = [3.0, 5.0, 3.0]
[[spheres]]
center = [0.0, 0.5, 0.0]
radius = 0.5
material = "mirror"
[[spheres]]
center = [1.5, 0.4, 0.0]
radius = 0.4
"""


def scene_file(folder: Path, animation: str) -> Path:
    path = folder / "scene.toml"
    path.write_text(BASE + animation, encoding="utf-8")
    return path


# -- checks ---------------------------------------------------------------------------------

BAD = {
    "no frames": ("[animation]\norbit = 90\n", "animation.frames: is required"),
    "zero frames": ("[animation]\nframes = 0\norbit = 90\n", "animation.frames: must be >= 1"),
    "neither": ("[animation]\nframes = 3\n", "animation.orbit: give either orbit"),
    "both": (
        "[animation]\nframes = 3\norbit = 9\nkeyframes = [{frame = 0}]\n",
        "animation.orbit: give either orbit",
    ),
    "orbit not a number": ('[animation]\nframes = 3\norbit = "x"\n', "animation.orbit: expected"),
    "frame past the end": (
        "[animation]\nframes = 3\nkeyframes = [{frame = 0}, {frame = 3}]\n",
        "animation.keyframes[1].frame: must be < animation.frames (3), got 3",
    ),
    "frames out of order": (
        "[animation]\nframes = 9\nkeyframes = [{frame = 4}, {frame = 4}]\n",
        "animation.keyframes[1].frame: must be greater than the previous keyframe's (4)",
    ),
    "keyframe without frame": (
        "[animation]\nframes = 9\nkeyframes = [{fov = 30}]\n",
        "animation.keyframes[0].frame: is required",
    ),
    "misspelt key": (
        "[animation]\nframes = 9\nkeyframes = [{frame = 0, fvo = 30}]\n",
        "animation.keyframes[0].fvo: unknown key (did you mean 'fov'?)",
    ),
    "bad fov": (
        "[animation]\nframes = 9\nkeyframes = [{frame = 0, fov = 180}]\n",
        "animation.keyframes[0].fov: must be > 0 and < 180 degrees",
    ),
    "looking at itself": (
        "[animation]\nframes = 9\nkeyframes = [{frame = 0, position = [0.0, 0.5, 0.0]}]\n",
        "animation.keyframes[0].look_at: must differ from camera.position",
    ),
    "path through look_at": (
        "[animation]\nframes = 3\nkeyframes = [{frame = 0, position = [-1.0, 0.5, 0.0]}, "
        "{frame = 2, position = [1.0, 0.5, 0.0]}]\n",
        "animation.keyframes: frame 1's interpolated camera: look_at must differ",
    ),
    "unknown key": ("[animation]\nframes = 3\norbit = 9\nloop = true\n", "animation.loop: unknown"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_animation_table_names_file_and_key(tmp_path: Path, case: str) -> None:
    text, message = BAD[case]
    path = scene_file(tmp_path, text)
    with pytest.raises(rt.SceneError) as caught:
        rt.load_scene(path)
    assert str(caught.value).startswith(f"{path}: "), caught.value
    assert message in str(caught.value)


# -- camera paths ---------------------------------------------------------------------------


def test_orbit_turns_about_look_at_around_up_by_the_frame_share_of_the_angle() -> None:
    camera = rt.Camera(position=(0.0, 1.0, 5.0), look_at=(0.0, 0.5, 0.0), up=(0.0, 1.0, 0.0))
    animation = Animation(frames=8, orbit=360.0)
    for f, turned in enumerate(frame_cameras(camera, animation)):
        offset = np.subtract(turned.position, camera.look_at)
        # The angle about +y from the starting offset (0, 0.5, 5): positive is towards +x.
        angle = math.degrees(math.atan2(offset[0], offset[2])) % 360.0
        assert angle == pytest.approx(45.0 * f, abs=1e-9)
        assert offset[1] == pytest.approx(0.5, abs=1e-12)  # the height along up stays
        assert math.hypot(offset[0], offset[2]) == pytest.approx(5.0, rel=1e-12)
        assert turned.look_at == camera.look_at and turned.fov == camera.fov


def test_keyframes_follow_catmull_rom_through_every_key() -> None:
    camera = rt.Camera()
    points = [(0.0, 1.0, 5.0), (4.0, 2.0, 1.0), (1.0, 3.0, -4.0), (-3.0, 1.0, 0.5)]
    keys = [Keyframe(10 * k, p, (0.0, 0.0, 0.0), 45.0) for k, p in enumerate(points)]
    cameras = frame_cameras(camera, Animation(frames=31, keyframes=keys))
    for key in keys:
        assert cameras[key.frame].position == key.position  # exactly the keyframe's camera
    # Uniformly spaced keys: the textbook Catmull-Rom segment from p1 to p2 at t = 0.3.
    p0, p1, p2, p3 = (np.array(p) for p in points)
    t = 0.3
    expected = 0.5 * (
        2 * p1
        + (p2 - p0) * t
        + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2
        + (3 * p1 - p0 - 3 * p2 + p3) * t**3
    )
    assert np.allclose(cameras[13].position, expected, rtol=0, atol=1e-12)


def test_keyframe_fov_is_monotone_and_frames_outside_the_keys_hold() -> None:
    keys = [
        Keyframe(2, (0.0, 1.0, 5.0), (0.0, 0.0, 0.0), 30.0),
        Keyframe(5, (0.0, 1.0, 6.0), (0.0, 0.0, 0.0), 90.0),
        Keyframe(9, (0.0, 1.0, 7.0), (0.0, 0.0, 0.0), 100.0),
    ]
    cameras = frame_cameras(rt.Camera(), Animation(frames=12, keyframes=keys))
    fovs = [c.fov for c in cameras]
    assert fovs[:3] == [30.0] * 3 and fovs[9:] == [100.0] * 3
    assert all(a <= b for a, b in itertools.pairwise(fovs))  # no overshoot past 100
    assert camera_at(rt.Camera(), Animation(12, keyframes=keys), 11).position == (0.0, 1.0, 7.0)


def test_keyframe_fields_left_out_keep_the_previous_value(tmp_path: Path) -> None:
    path = scene_file(
        tmp_path,
        "[animation]\nframes = 5\nkeyframes = [{frame = 0, fov = 30}, "
        "{frame = 4, position = [2.0, 1.0, 4.0]}]\n",
    )
    keys = rt.load_scene(path).animation.keyframes
    assert keys[0] == Keyframe(0, (0.0, 1.0, 5.0), (0.0, 0.5, 0.0), 30.0)
    assert keys[1] == Keyframe(4, (2.0, 1.0, 4.0), (0.0, 0.5, 0.0), 30.0)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
@pytest.mark.parametrize(
    "table",
    [
        "[animation]\nframes = 12\norbit = 270.5\n",
        "[animation]\nframes = 7\nkeyframes = [{frame = 1, fov = 30}, {frame = 6, "
        "position = [2.0, 1.0, 4.0], look_at = [0.5, 0.5, 0.0], fov = 50}]\n",
    ],
)
def test_scene_save_writes_the_animation_back(tmp_path: Path, table: str, suffix: str) -> None:
    scene = rt.load_scene(scene_file(tmp_path, table))
    saved = tmp_path / f"saved{suffix}"
    rt.save_scene(scene, saved)
    assert rt.load_scene(saved).animation == scene.animation
    assert scene.animation is not None


# -- the command ----------------------------------------------------------------------------


@dataclass
class Run:
    returncode: int
    stderr: str


@pytest.fixture
def run_cli(capsys):
    """The command in this process (its bad input is found before any render, and a render
    here is tiny): exit code and stderr."""

    def run(*args: str) -> Run:
        code = main(list(args))
        return Run(code, capsys.readouterr().err)

    return run


def one_line_error(result: Run) -> str:
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("embree-rt: error: "), result.stderr
    return lines[0]


ORBIT = "[animation]\nframes = 4\norbit = 120\n"


def test_frames_are_written_by_pattern_skipped_when_present_and_equal_local_frames(
    tmp_path: Path, run_cli
) -> None:
    path = scene_file(tmp_path, ORBIT)
    pattern = str(tmp_path / "shots" / "f_{frame:03d}.npy")
    (tmp_path / "shots").mkdir()
    kept = tmp_path / "shots" / "f_002.npy"
    kept.write_bytes(b"already here")
    result = run_cli("render", str(path), "-o", pattern, "--frames", "1:4")
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "shots").iterdir()) == [
        "f_001.npy",
        "f_002.npy",
        "f_003.npy",
        "transforms.json",  # poses for NeRF tools
    ]
    assert kept.read_bytes() == b"already here"  # on disk: skipped
    scene = rt.load_scene(path)
    for f in (1, 3):
        expected = rt.render(scene, camera=camera_at(scene.camera, scene.animation, f)).image
        assert np.array_equal(np.load(tmp_path / "shots" / f"f_{f:03d}.npy"), expected)
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "shots").iterdir()}
    result = run_cli("render", str(path), "-o", pattern, "--frames", "1:4")
    assert result.returncode == 0 and "all 3 frames are on disk" in result.stderr
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "shots").iterdir()} == stamps
    result = run_cli("render", str(path), "-o", pattern, "--frames", "2", "--overwrite", "--quiet")
    assert result.returncode == 0, result.stderr
    expected = rt.render(scene, camera=camera_at(scene.camera, scene.animation, 2)).image
    assert np.array_equal(np.load(kept), expected)


@pytest.mark.parametrize(
    ("animated", "output", "flags", "needle"),
    [
        (True, "out.png", [], "-o: {out}: the scene is animated: name the file with {{frame}}"),
        (True, "f_{frame}_{take}.png", [], "nothing else in braces"),
        (True, "f_{frame:q}.png", [], "cannot format a frame number"),
        (True, "f_{frame}.png", ["--frames", "3:9"], "--frames: '3:9' is not a non-empty range"),
        (True, "f_{frame}.png", ["--frames", "a:b"], "--frames: expected A:B"),
        (False, "f_{frame}.png", [], "a pattern with {{frame}} needs a scene with an [animation]"),
        (False, "out.png", ["--frames", "0:1"], "--frames: the scene has no [animation]"),
        (True, "f_{frame}.png", ["--aov", "depth"], "--aov: AOVs are written for still images"),
    ],
)
def test_bad_patterns_and_frame_ranges_are_one_line_errors(
    tmp_path: Path, run_cli, animated: bool, output: str, flags: list[str], needle: str
) -> None:
    path = scene_file(tmp_path, ORBIT if animated else "")
    target = tmp_path / output
    line = one_line_error(run_cli("render", str(path), "-o", str(target), *flags))
    assert needle.format(out=target) in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]  # nothing written


def test_the_shipped_animation_loads_and_moves_its_camera() -> None:
    (path,) = sorted((Path(__file__).resolve().parent.parent / "scenes" / "animations").glob("*"))
    scene = rt.load_scene(path)
    cameras = frame_cameras(scene.camera, scene.animation)
    assert len(cameras) == scene.animation.frames > 1
    assert len({c.position for c in cameras}) == len(cameras)  # a new view every frame
