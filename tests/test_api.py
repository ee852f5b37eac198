"""The Python face (embree_rt/api.py): ``render`` and ``Renderer`` return one ``RenderResult``,
a ``Renderer`` serves many views of one BVH with their AOVs, and settings override the scene's
``render`` table by one rule."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import embree_rt as rt
from embree_rt.aovs import AOV_NAMES
from embree_rt.film import tonemap

SIZE = {"width": 40, "height": 24, "spp": 2, "max_depth": 3, "seed": 4}


def small_scene() -> rt.Scene:
    scene = rt.Scene(camera=rt.Camera(position=(0.0, 1.5, 6.0), look_at=(0.0, 0.8, 0.0)))
    scene.lights.append(rt.PointLight(position=(3.0, 6.0, 4.0)))
    scene.add_sphere((0.0, 1.0, 0.0), 1.0, "glass")
    scene.add_sphere((-1.8, 0.5, 0.6), 0.5, "mirror")
    scene.add_sphere((1.7, 0.6, -0.4), 0.6, "matte")
    return scene


def test_one_renderer_renders_every_view_as_render_does() -> None:
    # Each view is rendered from the same rays by the same code on the same BVH (a BVH built
    # from the same scene is the same, and the views share nothing else), so the images and
    # AOVs are bitwise those of a fresh render on any ISA.
    scene = small_scene()
    views = [scene.camera, replace(scene.camera, position=(4.0, 2.0, 4.0), fov=35.0)]
    with rt.Renderer(scene, threads=2) as renderer:
        results = [renderer.render(camera=view, aovs=AOV_NAMES, **SIZE) for view in views]
    for view, result in zip(views, results, strict=True):
        alone = rt.render(replace(scene, camera=view), aovs=AOV_NAMES, threads=1, **SIZE)
        np.testing.assert_array_equal(result.image, alone.image)
        assert result.aovs.keys() == alone.aovs.keys() == set(AOV_NAMES)
        for name in AOV_NAMES:
            np.testing.assert_array_equal(result.aovs[name], alone.aovs[name])
        assert result.image.shape == (24, 40, 3) and result.image.dtype == np.float32
        assert result.stats.rays["primary"] == 40 * 24 * 2
        assert result.stats.rays["aov"] == 40 * 24
        assert result.stats.render_s > 0
    assert not np.array_equal(results[0].image, results[1].image)
    assert results[0].stats.build_s == results[1].stats.build_s  # one BVH for both


def test_settings_left_out_come_from_the_scene() -> None:
    scene = small_scene()
    scene.render = rt.RenderSettings(**SIZE)
    overridden = scene.render.with_overrides(width=20, seed=None)
    assert overridden == rt.RenderSettings(**{**SIZE, "width": 20})
    assert scene.render.width == 40  # the scene's own table is left as it was
    result = rt.render(scene, width=20)
    assert result.image.shape == (24, 20, 3) and result.aovs == {}
    with pytest.raises(TypeError, match="'widht'"):  # a misspelt setting is no silent default
        rt.render(scene, widht=20)
    np.testing.assert_array_equal(result.image, rt.render(scene, **{**SIZE, "width": 20}).image)


def test_a_result_tone_maps_and_saves_itself(tmp_path: Path) -> None:
    scene = small_scene()
    result = rt.render(scene, aovs=["depth", "object_id"], **SIZE)
    np.testing.assert_array_equal(result.to_srgb8(), tonemap(result.image))
    assert result.to_srgb8().dtype == np.uint8
    assert result.save(tmp_path / "both.npz") == [tmp_path / "both.camera.json"]
    with np.load(tmp_path / "both.npz") as saved:
        assert sorted(saved.files) == [
            "K",
            "beauty",
            "depth",
            "object_id",
            "world_to_camera_opencv",
            "world_to_camera_opengl",
        ]
        np.testing.assert_array_equal(saved["beauty"], result.image)
        np.testing.assert_array_equal(saved["object_id"], result.aovs["object_id"])
    beside = result.save(tmp_path / "image.npy")
    assert sorted(path.name for path in beside) == [
        "image.camera.json",
        "image.depth.npy",
        "image.object_id.npy",
    ]
    plain = rt.render(scene, **SIZE)
    assert plain.save(tmp_path / "plain.png") == []
    assert sorted(path.name for path in tmp_path.iterdir() if path.name.startswith("plain")) == [
        "plain.png"
    ]


def test_bad_aov_names_are_refused_before_anything_is_built() -> None:
    with pytest.raises(ValueError, match="bogus"):
        rt.render(small_scene(), aovs=["depth", "bogus"], **SIZE)
    with rt.Renderer(small_scene(), threads=1) as renderer, pytest.raises(TypeError):
        renderer.render(aovs="depth", **SIZE)


# -- in a notebook ----------------------------------------------------------------------------


def test_a_renderer_builds_its_bvh_once_whatever_the_camera_and_settings(monkeypatch) -> None:
    from embree_rt import integrator

    builds = []
    built = integrator.SceneGeometry

    def counted(*args, **kwargs):
        builds.append(args)
        return built(*args, **kwargs)

    monkeypatch.setattr(integrator, "SceneGeometry", counted)
    scene = small_scene()
    with rt.Renderer(scene) as renderer:
        first = renderer.render(**SIZE)
        other = replace(scene.camera, position=(3.0, 2.0, 5.0), fov=30.0)
        second = renderer.render(
            camera=other, width=20, height=12, spp=1, max_depth=1, aovs=["depth"]
        )
    assert len(builds) == 1
    assert first.image.shape == (24, 40, 3) and second.image.shape == (12, 20, 3)
    assert second.aovs["depth"].shape == (12, 20)  # the AOVs seen by the other camera too


def test_results_and_scenes_show_themselves_in_a_notebook() -> None:
    import io

    from PIL import Image

    scene = small_scene()
    result = rt.render(scene, **SIZE)
    with Image.open(io.BytesIO(result._repr_png_())) as shown:
        np.testing.assert_array_equal(np.asarray(shown), result.to_srgb8())
    looked = rt.render(scene, **SIZE)
    looked.look = rt.Look(exposure=1.0, tonemap="aces")
    assert not np.array_equal(looked.to_srgb8(), result.to_srgb8())
    np.testing.assert_array_equal(looked.to_srgb8(), rt.tonemap(looked.image, looked.look))

    text = repr(scene)
    assert text == "Scene(3 spheres, 1 light, floor at y = 0, 640x360 at 8 spp)"
    many = rt.random_field(5000, seed=1)
    assert len(repr(many)) < 120  # a summary, not five thousand spheres
    with Image.open(io.BytesIO(scene._repr_png_())) as preview:  # 256 wide, the scene's aspect
        assert preview.size == (256, 144) and preview.mode == "RGB"
        pixels = np.asarray(preview)
    expected = rt.render(scene, width=256, height=144, spp=1, max_depth=2)
    np.testing.assert_array_equal(pixels, expected.to_srgb8())


class _Terminal:
    """A stderr that says it is a terminal and keeps what is written to it."""

    def __init__(self) -> None:
        self.text = ""

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> int:
        self.text += text
        return len(text)

    def flush(self) -> None:
        pass


def test_one_progress_bar_counts_samples_and_names_workers_only_on_a_cluster(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from embree_rt.api import Progress, progress_bar
    from embree_rt.integrator import RenderStats

    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    with progress_bar(100, quiet=True) as show:
        assert show is None
    stats = RenderStats(rays={"primary": 4_000_000}, render_s=2.0)
    for workers in (None, 3):
        terminal.text = ""
        with progress_bar(100, quiet=False) as show:
            show(Progress(done=40, total=100, stats=stats, workers=workers))
        assert "40.0/100" in terminal.text and "2.0 Mrays/s" in terminal.text, terminal.text
        assert ("3 workers" in terminal.text) == (workers == 3), terminal.text
    # A render's own callback reaches the caller's progress(done, total) with no bar too.
    seen = []
    with rt.Renderer(small_scene(), threads=1) as renderer:
        renderer.render(quiet=True, progress=lambda d, t: seen.append((d, t)), **SIZE)
    total = SIZE["width"] * SIZE["height"] * SIZE["spp"]
    assert seen and seen[-1] == (total, total)
