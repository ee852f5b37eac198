"""``embree-rt serve FILE`` of a particle file and of a mesh file: the page previews the scene
``embree-rt render FILE`` makes (framed, lit, on a floor) and converges to its image; the
downloaded scene file names the particle file and renders the same scene."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from embree_rt.scene import load_scene
from embree_rt.scene.model import Scene
from tests.web_harness import (
    browser,
    canvas_image,
    command_render,
    psnr,
    running_server,
    wait_until,
)

pytest.importorskip("MDAnalysis")
VIEWPORT = {"width": 900, "height": 620}


def write_dump(path: Path) -> None:
    rng = np.random.default_rng(8)
    positions = np.round(rng.uniform(0, 8, (60, 3)), 4)
    rows = "".join(
        f"{i + 1} {1 + i % 3} {x} {y} {z}\n" for i, (x, y, z) in enumerate(positions.tolist())
    )
    path.write_text(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n60\nITEM: BOX BOUNDS pp pp pp\n"
        + "0 8\n" * 3
        + "ITEM: ATOMS id type x y z\n"
        + rows
    )


def preview_against_render(path: Path, tmp_path: Path) -> Path | None:
    """Serve ``path``, wait for the preview to converge, compare it with ``embree-rt render
    path`` at the canvas's size; returns the downloaded scene file."""
    spp = Scene.from_particles(path).render.spp if path.suffix == ".lammpstrj" else None
    with running_server(str(path)) as (url, _), browser() as chromium:
        context = chromium.new_context(viewport=VIEWPORT, bypass_csp=True, accept_downloads=True)
        page = context.new_page()
        page.goto(url)

        def converged():
            shown = page.evaluate("document.getElementById('preview').dataset.pass || ''")
            done, _, of = shown.partition("/")
            return bool(of) and done == of

        wait_until(converged, 90, "the preview to converge", page)
        if spp is not None:
            assert page.evaluate("document.getElementById('preview').dataset.pass") == (
                f"{spp}/{spp}"
            )
        width, height = page.evaluate("[preview.width, preview.height]")
        shown = canvas_image(page)
        with page.expect_download(timeout=10_000) as download:
            page.click("#download-scene")
        saved = tmp_path / "served.toml"
        download.value.save_as(saved)
        context.close()
    rendered = command_render(path, width, height, tmp_path / "render.png")
    assert shown.shape == rendered.shape == (height, width, 3)
    assert psnr(shown, rendered) >= 40  # the same scene: only the preview's sampling differs
    return saved


def test_serve_a_particle_file(tmp_path):
    path = tmp_path / "d.lammpstrj"
    write_dump(path)
    saved = preview_against_render(path, tmp_path)
    scene, again = Scene.from_particles(path), load_scene(saved)
    np.testing.assert_array_equal(again.sphere_centers, scene.sphere_centers)
    np.testing.assert_array_equal(again.sphere_colors, scene.sphere_colors)
    assert again.camera.position == pytest.approx(scene.camera.position)
    assert len(again.lights) == len(scene.lights)
    assert again.floor.height == pytest.approx(scene.floor.height)


def test_serve_a_mesh_file(tmp_path):
    import trimesh

    path = tmp_path / "ico.ply"
    trimesh.creation.icosphere(subdivisions=2, radius=1.5).export(path)
    preview_against_render(path, tmp_path)


def test_serve_a_bad_particle_file_is_one_line(tmp_path):
    (tmp_path / "e.xyz").write_text("")
    done = subprocess.run(
        [sys.executable, "-m", "embree_rt", "serve", str(tmp_path / "e.xyz"), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"embree-rt: error: {tmp_path / 'e.xyz'}: (file): the file is empty"
    ]
