"""The orthographic camera: parallel rays from the image plane, sizes that do not shrink with
distance, depth from the image plane, and an affine K that projects what the AOVs saw back
onto pixel centres."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from tolerances import position_atol

from embree_rt import Camera, Scene, render
from embree_rt.aovs import camera_data
from embree_rt.camera import (
    camera_frame,
    camera_rays,
    pixel_center_rays,
    sample_rays,
    tiled_samples,
)
from embree_rt.geometry import SceneGeometry
from embree_rt.scene.errors import SceneError
from embree_rt.scene.loader import load_scene
from embree_rt.scene.views import STANDARD_VIEWS, standard_view

ORTHO = Camera(
    position=(3.0, 4.0, 9.0),
    look_at=(0.5, -0.2, 0.1),
    up=(0.0, 1.0, 0.0),
    projection="orthographic",
    view_height=5.0,
)


@pytest.mark.parametrize("spp", [1, 4])
def test_orthographic_rays_are_parallel_and_start_on_the_image_plane(spp: int) -> None:
    frame = camera_frame(ORTHO, 37, 23)
    index, _ = tiled_samples(frame, spp, 0, 37 * 23 * spp)
    origins, directions, _ = sample_rays(frame, spp, 3, index)
    view = np.subtract(ORTHO.look_at, ORTHO.position)
    view /= np.linalg.norm(view)
    assert np.allclose(directions, view[:, None], atol=1e-7)
    assert (directions == directions[:, :1]).all()  # the very same float32 direction
    # every origin lies on the plane through the eye facing the view, inside the view's
    # rectangle (half height 2.5, half width 2.5 * 37 / 23)
    offset = origins.astype(np.float64) - np.asarray(ORTHO.position)[:, None]
    assert np.abs(view @ offset).max() < position_atol(ORTHO.position)
    x, y = frame.u @ offset, frame.v @ offset
    atol = position_atol(ORTHO.position)
    assert np.abs(y).max() <= 2.5 + atol and np.abs(y).max() > 2.3
    assert np.abs(x).max() <= 2.5 * 37 / 23 + atol and np.abs(x).max() > 2.5 * 37 / 23 - 0.2
    # pixel centres: the origins of pixel (c, r) lie at x = (c + 1/2) 5 / 23 - half width
    _, centres_dir, _ = pixel_center_rays(frame, 0, 37 * 23)
    assert (centres_dir == directions[:, :1]).all()


def test_rays_made_inside_the_query_are_sample_rays_and_hit_the_same() -> None:
    scene = Scene(camera=ORTHO, floor=None)
    rng = np.random.default_rng(2)
    for centre in rng.uniform(-2, 2, size=(30, 3)):
        scene.add_sphere(tuple(centre), float(rng.uniform(0.1, 0.6)), "matte")
    frame = camera_frame(ORTHO, 61, 43)
    index, _ = tiled_samples(frame, 2, 0, 61 * 43 * 2)
    origins, directions, _ = sample_rays(frame, 2, 9, index)
    with SceneGeometry(scene, threads=1) as geometry:
        rows, surfaces, made = geometry.intersect_camera(camera_rays(frame, 2, 9), index)
        expected_rows, expected = geometry.intersect_compact(origins, directions, coherent=True)
    assert made.tobytes() == directions.tobytes()
    assert np.array_equal(rows, expected_rows) and 0 < len(rows) < len(index)
    assert surfaces.floor_count == 0
    for name in ("t", "position", "normal", "material"):
        assert getattr(surfaces, name).tobytes() == getattr(expected, name).tobytes(), name


def sphere_pixels(distance: float) -> tuple[int, np.ndarray]:
    """Pixels a unit sphere covers at ``distance`` from an orthographic camera, and its
    depth AOV."""
    scene = Scene(
        floor=None,
        camera=Camera(
            position=(0.0, 0.0, 0.0),
            look_at=(0.0, 0.0, -1.0),
            projection="orthographic",
            view_height=4.0,
        ),
    )
    scene.add_sphere((0.0, 0.0, -distance), 1.0, "matte")
    result = render(scene, width=80, height=80, spp=1, aovs=("object_id", "depth", "z_depth"))
    return int((result.aovs["object_id"] >= 0).sum()), result.aovs


def test_an_objects_size_in_pixels_does_not_depend_on_its_distance() -> None:
    near, near_aovs = sphere_pixels(3.0)
    far, far_aovs = sphere_pixels(300.0)
    # a disc of radius 1 in a 4 x 4 view of 80 x 80 pixels: pi (80 / 4)^2 pixel centres
    expected = math.pi * 20.0**2
    assert abs(near - expected) < 2 * math.pi * 20.0  # within the rim's pixels
    assert abs(near - far) <= 4  # the same pixel centres, bar rounding on the rim
    # depth from the image plane: the sphere's front at distance - 1 in the centre pixels
    for distance, aovs in ((3.0, near_aovs), (300.0, far_aovs)):
        centre = aovs["depth"][39:41, 39:41]
        assert np.allclose(centre, distance - np.sqrt(1 - 2 * (0.5 * 4 / 80) ** 2), rtol=1e-5)
        assert aovs["z_depth"].tobytes() == aovs["depth"].tobytes()


def test_k_and_extrinsics_project_the_position_aov_onto_pixel_centres(tmp_path) -> None:
    scene = Scene(camera=ORTHO, floor=None)
    scene.add_sphere((0.5, -0.2, 0.1), 1.5, "matte")
    scene.add_sphere((-1.0, 0.8, -2.0), 0.7, "matte")
    width, height = 53, 31
    result = render(scene, width=width, height=height, spp=1, aovs=("position",))
    data = camera_data(result.camera)
    position = result.aovs["position"].reshape(-1, 3).astype(np.float64)
    seen = np.isfinite(position).all(axis=1)
    assert 300 < seen.sum() < width * height
    camera_space = data["world_to_camera_opencv"] @ np.vstack(
        [position[seen].T, np.ones(seen.sum())]
    )
    assert (camera_space[2] > 0).all()  # in front of the image plane
    pixel = data["K"] @ np.vstack([camera_space[0], camera_space[1], np.ones(seen.sum())])
    rows, columns = np.divmod(np.flatnonzero(seen), width)
    # the hit lies on its pixel centre's ray: off it only by float32 rounding of the hit
    atol = position_atol(ORTHO.position, 3.0) * data["K"][0, 0]
    assert np.abs(pixel[0] - columns).max() < atol
    assert np.abs(pixel[1] - rows).max() < atol
    assert np.array_equal(data["K"][2], [0.0, 0.0, 1.0])
    # the sidecar says how K projects
    assert result.save(tmp_path / "view.npz") == [tmp_path / "view.camera.json"]
    record = json.loads((tmp_path / "view.camera.json").read_text())
    assert record["projection"] == "orthographic"
    assert np.array_equal(record["K"], data["K"])


def load_scene_text(folder, text: str) -> Scene:
    path = folder / "scene.toml"
    path.write_text(text)
    return load_scene(path)


def test_a_scene_file_sets_the_projection_and_refuses_fov_with_view_height(tmp_path) -> None:
    scene = load_scene_text(
        tmp_path, '[camera]\nposition = [0, 0, 5]\nprojection = "orthographic"\nview_height = 3\n'
    )
    assert scene.camera.projection == "orthographic" and scene.camera.view_height == 3.0
    frame = camera_frame(scene.camera, 10, 10)
    assert frame.orthographic and frame.half_height == 1.5
    # without a view height: what the fov sees at look_at's distance
    scene = load_scene_text(
        tmp_path, '[camera]\nposition = [0, 0, 5]\nprojection = "orthographic"\n'
    )
    assert camera_frame(scene.camera, 10, 10).half_height == pytest.approx(
        5 * math.tan(math.radians(45 / 2))
    )
    bad = {
        'projection = "orthographic"\nview_height = 3\nfov = 30\n': "fov cannot both",
        "view_height = 3\n": "only an orthographic camera",
        'projection = "fisheye"\n': "expected one of perspective, orthographic",
        'projection = "orthographic"\nview_height = -1\n': "view_height",
    }
    for text, problem in bad.items():
        with pytest.raises(SceneError, match=problem):
            load_scene_text(tmp_path, "[camera]\n" + text)


@pytest.mark.parametrize("up", [(0.0, 1.0, 0.0), (0.0, 0.0, 1.0)])
@pytest.mark.parametrize("name", STANDARD_VIEWS)
@pytest.mark.parametrize("orthographic", [True, False])
def test_standard_views_look_along_the_up_conventions_axes_and_frame_the_box(
    up, name: str, orthographic: bool
) -> None:
    low, high = np.array([-1.0, 0.5, 2.0]), np.array([3.0, 1.5, 2.5])
    camera = standard_view(Camera(up=up), low, high, name, 16 / 9, orthographic)
    frame = camera_frame(camera, 160, 90)
    up_axis = np.asarray(up)
    back = np.cross([1.0, 0.0, 0.0], up_axis)  # y-up: +z; z-up: -y (OVITO's front looks down +y)
    expected = {
        "front": -back,
        "back": back,
        "left": np.array([1.0, 0.0, 0.0]),
        "right": np.array([-1.0, 0.0, 0.0]),
        "top": -up_axis,
        "bottom": up_axis,
        "iso": -(np.array([1.0, 0.0, 0.0]) + up_axis + back) / math.sqrt(3),
    }[name]
    np.testing.assert_allclose(-frame.w, expected, atol=1e-12)
    assert frame.orthographic == orthographic
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    corners = low + corners * (high - low)
    # every corner in front of the camera and inside the image, the box not a speck in it
    relative = corners - frame.origin
    depth = relative @ -frame.w
    assert (depth > 0).all()
    x, y = relative @ frame.u, relative @ frame.v
    if not orthographic:
        x, y = x / depth, y / depth
    reach = max(np.abs(x).max() / frame.half_width, np.abs(y).max() / frame.half_height)
    assert reach < 1.0
    assert reach > (0.85 if orthographic else 0.3)


def test_the_command_line_frames_a_standard_view_and_names_its_projection(tmp_path, capsys) -> None:
    from embree_rt.cli import main

    scene = Path(__file__).resolve().parent.parent / "scenes" / "three_spheres.toml"
    common = ["render", str(scene), "--width", "24", "--height", "16", "--spp", "1", "--quiet"]
    for flags, projection in (
        (["--view", "top"], "orthographic"),
        (["--view", "top", "--perspective"], "perspective"),
        (["--ortho"], "orthographic"),
    ):
        out = tmp_path / f"{projection}{len(flags)}.npz"
        assert main([*common, *flags, "-o", str(out), "--aov", "depth"]) == 0
        record = json.loads(out.with_name(out.stem + ".camera.json").read_text())
        assert record["projection"] == projection
        if flags[0] == "--view":  # looking straight down the scene's y
            np.testing.assert_allclose(
                np.array(record["world_to_camera_opengl"])[2, :3], [0, 1, 0], atol=1e-12
            )
    # fov and view_height together: the scene file's rule, one line, exit 2, nothing written
    out = tmp_path / "refused.png"
    code = main([*common, "--ortho", "-D", "camera.view_height=2", "--fov", "30", "-o", str(out)])
    assert code == 2 and not out.exists()
    assert "view_height" in capsys.readouterr().err


def test_headlight_lights_what_faces_the_camera(tmp_path) -> None:
    from embree_rt.cli import main

    scene = tmp_path / "dark.toml"
    scene.write_text(
        "[camera]\nposition = [0, 1, 6]\nlook_at = [0, 1, 0]\n\n"
        "[[spheres]]\ncenter = [0, 1, 0]\nradius = 1\n"
    )
    common = ["render", str(scene), "--width", "16", "--height", "16", "--spp", "1", "--quiet"]
    assert main([*common, "-o", str(tmp_path / "dark.npy")]) == 0
    assert main([*common, "--headlight", "-o", str(tmp_path / "lit.npy")]) == 0
    dark, lit = np.load(tmp_path / "dark.npy"), np.load(tmp_path / "lit.npy")
    # the sphere's centre faces the camera: ambient alone without the light, much more with it
    assert (lit[8, 8] > 3 * dark[8, 8]).all()
    np.testing.assert_array_equal(lit[0, 0], dark[0, 0])  # the sky is the sky


def test_an_orthographic_camera_is_written_and_read_back(tmp_path) -> None:
    from embree_rt.scene.writer import save_scene

    scene = Scene(camera=ORTHO)
    save_scene(scene, tmp_path / "ortho.toml")
    again = load_scene(tmp_path / "ortho.toml")
    assert again.camera == ORTHO
    save_scene(Scene(), tmp_path / "plain.toml")  # a perspective camera's table as it was
    assert "projection" not in (tmp_path / "plain.toml").read_text()


@pytest.mark.parametrize("name", ["front", "top", "iso"])
@pytest.mark.parametrize("kept", [0.3, 0.6])
def test_an_orthographic_view_keeps_the_legends_rows_clear(name: str, kept: float) -> None:
    """``kept_below``: every corner of the box lies in the rows above the kept share of the
    image (room for a legend there), and the box still fills that part: it touches its top and
    bottom, or the image's sides, within the framing's margin."""
    low, high = np.array([-1.0, 0.5, 2.0]), np.array([5.0, 1.5, 2.5])
    camera = standard_view(Camera(), low, high, name, 16 / 9, True, kept_below=kept)
    frame = camera_frame(camera, 160, 90)
    corners = low + np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) * (
        high - low
    )
    relative = corners - frame.origin
    x, y = relative @ frame.u / frame.half_width, relative @ frame.v / frame.half_height
    # in image heights from the top: y = 1 is the top row, -1 the bottom one
    region_low = -1.0 + 2.0 * kept
    assert y.max() < 1.0 and y.min() > region_low and np.abs(x).max() < 1.0
    centred = abs((y.max() + y.min()) / 2 - (1.0 + region_low) / 2) < 1e-9
    fills = max((y.max() - y.min()) / (1.0 - region_low), np.abs(x).max())
    assert centred and fills > 0.9
