"""The preview's passes are the render's samples: camera rays for any sample indices, passes that
add up to ``Renderer.render``'s image, edits that stop a pass, and the edited scene as a file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from camera_samples import primary_rays

from embree_rt.camera import camera_frame, sample_rays
from embree_rt.film import Film
from embree_rt.integrator import Integrator
from embree_rt.scene import load_scene
from embree_rt.scene.loader import read_document
from embree_rt.web.preview import OvertakenError, PreviewSession

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def test_sample_rays_are_the_primary_rays_of_those_samples():
    scene = load_scene(SCENES / "three_spheres.toml")
    frame = camera_frame(scene.camera, 13, 7)
    spp = 5
    everything = primary_rays(frame, spp, 3, 0, 13 * 7 * spp)
    index = np.random.default_rng(1).permutation(13 * 7 * spp)[:100]
    for ours, theirs in zip(sample_rays(frame, spp, 3, index), everything, strict=True):
        # The same float operations on the same values, whatever the order: bitwise equal.
        assert np.array_equal(ours, theirs[..., index])


def test_passes_add_up_to_the_render():
    scene = load_scene(SCENES / "showcase.toml")
    width, height, spp = 40, 24, 4
    frame = camera_frame(scene.camera, width, height)
    with Integrator(scene, threads=1, batch_size=97 * spp) as renderer:
        expected, _ = renderer.render_image(frame, spp=spp, max_depth=6, seed=2)
        film = Film(width, height)
        for sample in range(spp):
            for first in range(0, width * height, 300):  # chunks unlike the render's batches
                count = min(300, width * height - first)
                film.add_block(renderer.trace_pixels(frame, spp, 2, sample, first, count, 6))
    image = film.image(spp)
    assert image.shape == expected.shape
    # float64 sums of the same float32 samples in another order: equal to float32 rounding.
    assert np.allclose(image, expected, rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="sample"):
        renderer.trace_pixels(frame, spp, 2, spp, 0, 1, 6)


def _session(name: str = "showcase.toml") -> PreviewSession:
    path = SCENES / name
    return PreviewSession(load_scene(path), read_document(path), path.parent)


def test_an_edit_stops_the_running_pass():
    session = _session()
    try:
        session.set_size(64, 36)
        stale = session.generation
        assert session.set_camera((1.0, 2.0, 6.0), (0.0, 0.8, 0.0)) is None
        with pytest.raises(OvertakenError):
            session.render_pass(0, stale, Film(64, 36))
        film = session.render_pass(0, session.generation, Film(64, 36))
        assert film.image(1).max() > 0
        assert "look_at" in session.set_camera((0.0, 1.0, 0.0), (0.0, 1.0, 0.0))
    finally:
        session.close()


def test_the_edited_scene_file_is_the_scene_as_edited(tmp_path):
    session = _session("mesh_and_spheres.toml")
    try:
        session.set_size(80, 45)
        before = len(session.scene.sphere_radii)
        assert session.set_camera((3.0, 2.5, 7.0), (0.0, 0.5, 0.0)) is None
        assert session.drop_sphere(40, 44, 0.25, "mirror")  # the bottom row sees the floor
        assert not session.drop_sphere(40, 0, 0.25, "mirror")  # the top row sees the sky
        path = tmp_path / "edited.toml"  # elsewhere: the mesh files must still be found
        path.write_text(session.scene_toml())
        edited = load_scene(path)
        assert len(edited.sphere_radii) == before + 1
        assert np.array_equal(edited.sphere_centers, session.scene.sphere_centers)
        assert np.array_equal(edited.sphere_radii, session.scene.sphere_radii)
        assert edited.material_names[edited.sphere_materials[-1]] == "mirror"
        assert edited.sphere_centers[-1][1] == pytest.approx(0.25 + session.scene.floor.height)
        assert edited.camera.position == (3.0, 2.5, 7.0)
        assert len(edited.meshes) == len(session.scene.meshes) > 0
    finally:
        session.close()


def test_a_cancelled_full_render_stops_at_the_next_batch():
    session = _session("three_spheres.toml")
    session.scene.render.width, session.scene.render.height = 320, 180  # 2 batches of samples
    reports = []

    def cancel_on_first_report(done: int, total: int) -> None:
        reports.append(done)
        session.render_generation += 1  # as the page's Cancel button does

    try:
        with pytest.raises(OvertakenError):
            session.full_render(session.render_generation, cancel_on_first_report)
        assert len(reports) == 1 and reports[0] < 320 * 180 * session.scene.render.spp
    finally:
        session.close()
