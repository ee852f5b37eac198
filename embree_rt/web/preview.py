"""One browser tab's live preview: its own copy of the scene, traced one sample per pixel a pass.

Pass k traces sample k of every pixel, the very rays ``embree-rt render`` traces for it
(``Integrator.trace_pixels``), and the preview shows the mean of the passes so far: after ``spp``
passes it is the render's image at the preview's size. Any edit bumps ``generation``; a pass
that sees it change stops between chunks of pixels.
"""

from __future__ import annotations

import copy
import io
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from embree_rt.api import Renderer
from embree_rt.batches import worker_count
from embree_rt.camera import camera_frame, camera_problem, sample_rays
from embree_rt.film import Film, FilmBlock, tonemap
from embree_rt.integrator import Integrator
from embree_rt.scene.model import Scene
from embree_rt.scene.writer import inline_short_arrays

# Pixels a chunk of a pass traces: small enough that an edit stops a pass within ~0.1 s.
CHUNK_PIXELS = 1 << 14


class OvertakenError(Exception):
    """The work was overtaken by an edit or a cancel request."""


def png_bytes(image: np.ndarray) -> bytes:
    """The (h, w, 3) float32 linear ``image`` as an 8-bit PNG file, tone-mapped as renders are."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(tonemap(image)).save(buffer, format="PNG", compress_level=1)
    return buffer.getvalue()


class PreviewSession:
    """The scene a tab edits, its renderer and its progressive image.

    ``document`` is the scene file's parsed content, kept to write the edited scene back out;
    ``folder`` the scene file's directory, for its relative paths.
    """

    def __init__(self, scene: Scene, document: dict, folder: Path) -> None:
        # Own copies of what edits change; meshes are shared, never modified.
        self.scene = replace(
            scene,
            camera=copy.copy(scene.camera),
            sphere_centers=scene.sphere_centers.copy(),
            sphere_radii=scene.sphere_radii.copy(),
            sphere_materials=scene.sphere_materials.copy(),
            sphere_colors=None if scene.sphere_colors is None else scene.sphere_colors.copy(),
            render=copy.copy(scene.render),
        )
        self.document = document
        self.folder = folder
        self.dropped: list[dict] = []
        self.width, self.height = 320, 180
        self.generation = 0
        self.render_generation = 0
        self._lock = threading.Lock()
        self._renderer: Integrator | None = None
        self._pool = ThreadPoolExecutor(max_workers=worker_count(None))

    def close(self) -> None:
        self.generation += 1
        self.render_generation += 1
        self._pool.shutdown(wait=True, cancel_futures=True)
        with self._lock:
            if self._renderer is not None:
                self._renderer.close()
                self._renderer = None

    # -- edits --------------------------------------------------------------------------------

    def set_size(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.generation += 1

    def set_camera(self, position: tuple, look_at: tuple) -> str | None:
        """Move the camera; returns the problem if the camera would be invalid (not moved)."""
        camera = replace(self.scene.camera, position=tuple(position), look_at=tuple(look_at))
        problem = camera_problem(camera)
        if problem is not None:
            return f"camera.{problem[0]}: {problem[1]}"
        self.scene.camera = camera
        self.generation += 1
        return None

    def drop_sphere(self, x: float, y: float, radius: float, material: str) -> bool:
        """Put a sphere of ``radius`` on the floor where the preview pixel (x, y) sees it;
        False when that pixel does not see the floor. Cancels the running pass first."""
        self.generation += 1
        frame = camera_frame(self.scene.camera, self.width, self.height)
        column = min(max(int(x), 0), self.width - 1)
        row = min(max(int(y), 0), self.height - 1)
        origins, directions, _ = sample_rays(frame, 1, 0, np.array([row * self.width + column]))
        with self._lock:
            surfaces = self._current_renderer().geometry.intersect(origins, directions)
        if not (surfaces.hit[0] and surfaces.floor[0]):
            return False
        center = surfaces.position[:, 0].astype(np.float64)
        center[1] = self.scene.floor.height + radius
        center = tuple(round(float(c), 4) for c in center)
        self.scene.add_sphere(center, radius, material)
        self.dropped.append({"center": list(center), "radius": radius, "material": material})
        self.generation += 1
        with self._lock:
            if self._renderer is not None:
                self._renderer.close()
                self._renderer = None
        return True

    # -- rendering ----------------------------------------------------------------------------

    def _current_renderer(self) -> Integrator:
        """The integrator of the scene as it is now (call with the lock held)."""
        if self._renderer is None:
            self._renderer = Integrator(self.scene, threads=1)
        return self._renderer

    def render_pass(self, sample: int, generation: int, film: Film) -> Film:
        """Add sample ``sample`` of every pixel to ``film`` (the preview's size) and return it;
        raises OvertakenError as soon as ``generation`` is stale."""
        settings = self.scene.render
        frame = camera_frame(self.scene.camera, film.width, film.height)
        pixels = film.width * film.height
        with self._lock:
            renderer = self._current_renderer()

            def chunk(first: int) -> FilmBlock:
                if generation != self.generation:
                    raise OvertakenError
                count = min(CHUNK_PIXELS, pixels - first)
                return renderer.trace_pixels(
                    frame, settings.spp, settings.seed, sample, first, count, settings.max_depth
                )

            futures = [self._pool.submit(chunk, first) for first in range(0, pixels, CHUNK_PIXELS)]
            try:
                for future in futures:
                    film.add_block(future.result())
            finally:
                for future in futures:
                    future.cancel()
                for future in futures:
                    if not future.cancelled():
                        future.exception()  # wait: the renderer must outlive its work
        if generation != self.generation:
            raise OvertakenError
        return film

    def full_render(self, generation: int, progress) -> np.ndarray:
        """The scene at its own size and samples, as ``embree-rt render`` makes it (the same
        ``Renderer.render``); ``progress(done, total)`` after each batch. Raises OvertakenError when
        ``render_generation`` moves on."""

        def report(done: int, total: int) -> None:
            if generation != self.render_generation:
                raise OvertakenError
            progress(done, total)

        # A shallow copy: edits rebind the scene's fields, never change them in place.
        with Renderer(replace(self.scene)) as renderer:
            return renderer.render(progress=report).image

    # -- the edited scene as a file -------------------------------------------------------------

    def scene_toml(self) -> str:
        """The scene file this tab's scene now is: the original file's content with the camera
        as it is now and the dropped spheres added; files it names are made absolute, since the
        downloaded file will not sit beside them."""
        import tomli_w

        document = copy.deepcopy(self.document)
        for key in ("meshes", "sphere_arrays", "particles"):
            for entry in document.get(key, []):
                for name in ("file", "topology"):
                    if name in entry:
                        entry[name] = str((self.folder / entry[name]).resolve())
        camera = self.scene.camera
        document["camera"] = {
            **document.get("camera", {}),
            "position": [float(c) for c in camera.position],
            "look_at": [float(c) for c in camera.look_at],
        }
        if self.dropped:
            document["spheres"] = [*document.get("spheres", []), *self.dropped]
        return inline_short_arrays(tomli_w.dumps(document))


def session_factory(scene: Scene, document: dict, folder: Path):
    """A function making a fresh ``PreviewSession`` of ``scene``, whose scene file's content
    is ``document`` (its relative paths from ``folder``)."""

    def new_session() -> PreviewSession:
        return PreviewSession(scene, document, folder)

    return new_session
