"""The Python face of the renderer: ``render`` one image, or a ``Renderer`` for many views of one
BVH, each returning a ``RenderResult`` (the linear image, its AOVs, what it took).

Above the integrator (``integrator.Integrator``, which traces and shades batches) and the AOV
pass (``aovs.render_aovs``): this module resolves the settings against the scene's ``render``
table, refuses what cannot fit in memory before anything is built, shows the progress bar, and
gathers what a render made into one value.
"""

from __future__ import annotations

import copy
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from embree_rt import budget, film
from embree_rt.aovs import (
    aov_pixel_bytes,
    check_aov_names,
    render_aovs,
    render_coverage,
    save_with_aovs,
)
from embree_rt.camera import Camera, CameraFrame, camera_frame
from embree_rt.integrator import DEFAULT_BATCH_SIZE, Integrator, RenderStats
from embree_rt.scene.model import RenderSettings, Scene, SettingOverrides

if TYPE_CHECKING:
    from typing_extensions import Unpack


@dataclass
class RenderResult:
    """What one render made.

    ``image`` (height, width, 3) float32 is the linear HDR radiance (the mean of the samples,
    not tone-mapped: ``to_srgb8`` gives the 8-bit picture a PNG holds, by ``look``, the
    scene's ``render`` exposure, tone map and transfer curve); ``aovs`` maps each AOV
    asked for to its (height, width) or (height, width, 3) array (``embree_rt.aovs``), empty
    when none were; ``stats`` counts the rays by kind (``"aov"``: the AOV pass's) and the
    seconds spent building the BVH and rendering (the AOV pass included).
    """

    image: np.ndarray
    aovs: dict[str, np.ndarray] = field(default_factory=dict)
    stats: RenderStats = field(default_factory=RenderStats)
    look: film.Look = film.DEFAULT_LOOK
    # The camera the image was seen through (its size included), for dataset files.
    camera: CameraFrame | None = None
    # With a background other than the sky (``film.BACKGROUNDS``): (height, width) float32
    # share of each pixel's camera rays that met something; ``image`` holds nothing where
    # they did not, and ``save`` composites the background there.
    background: str = "sky"
    alpha: np.ndarray | None = None

    def to_srgb8(self) -> np.ndarray:
        """(height, width, 3) uint8: the image tone-mapped as a PNG is written
        (``film.tonemap`` with the render's ``look``; by default Reinhard, gamma 2.2)."""
        return film.tonemap(self.image, self.look)

    def _repr_png_(self) -> bytes:
        """The picture as PNG bytes (``to_srgb8``): what Jupyter shows for a result."""
        return png_bytes(self.to_srgb8())

    def save(
        self, path: str | os.PathLike, encoding: film.Encoding = film.DEFAULT_ENCODING
    ) -> list[Path]:
        """Write the image to ``path`` by its extension (``film.IMAGE_SUFFIXES``; ``encoding``:
        8 or 16 bits, quality), with the AOVs in the same file (``.npz``, ``.exr``) or beside
        it, and with them the camera (``aovs.camera_data``: npz keys, a JSON sidecar); all or
        nothing, an existing file left as it was on failure. Returns the files
        written beside ``path``."""
        if encoding.look is None:
            encoding = encoding._replace(look=self.look)
        image = self.image
        if self.alpha is not None:
            encoding = encoding._replace(background=self.background)
            image = np.concatenate([image, self.alpha[..., None]], axis=2)
        if not self.aovs:
            film.save_image(image, path, encoding)
            return []
        return save_with_aovs(image, self.aovs, path, encoding, camera=self.camera)


class Renderer(Integrator):
    """Renders many views of one scene on one BVH, built once when it is made: the way to
    render the frames of a camera path, or an image and then its AOVs at another size.

    ``Renderer(scene, *, spheres="analytic", threads=None, batch_size=DEFAULT_BATCH_SIZE,
    movable=False)``:
    ``spheres`` is how spheres enter the BVH, "analytic" (compiled user geometry, exact),
    "point" (Embree's own point spheres) or "mesh" (instanced icospheres); ``threads`` the
    worker threads (None: every core); ``batch_size`` the camera samples a batch traces;
    ``movable`` lets ``update_spheres`` move the spheres between frames. The
    image is bitwise the same for any ``threads`` and ``batch_size``. Close it (or use it as a
    context manager) to free the BVH.

    An ``Integrator`` (which holds the BVH and traces the batches) with the one method a user
    needs, ``render``. Like every integrator, it first holds a scene built in Python to a scene
    file's limits: a value no file could hold raises the ``SceneError`` (a ValueError) the
    file's would.
    """

    def render(
        self,
        *,
        camera: Camera | None = None,
        aovs: Sequence[str] = (),
        quiet: bool = True,
        progress: Callable[[int, int], None] | None = None,
        **overrides: Unpack[SettingOverrides],
    ) -> RenderResult:
        """The scene seen by ``camera`` (default the scene's own). ``overrides`` (width, height,
        spp, max_depth, seed: ``SettingOverrides``) replace the scene's ``render`` table's
        (``RenderSettings.with_overrides``), those left out or None stay; ``aovs`` names
        AOVs (``embree_rt.aovs.AOV_NAMES``) to render after the image, which they leave bitwise
        unchanged. With ``quiet=False`` a progress bar runs on stderr (when it is a terminal);
        ``progress(done, total)`` counts camera samples."""
        names = check_aov_names(aovs)
        settings = self.scene.render.with_overrides(**overrides)
        frame = camera_frame(
            self.scene.camera if camera is None else camera, settings.width, settings.height
        )
        with progress_bar(settings.width * settings.height * settings.spp, quiet) as bar:
            image, stats = self.render_image(
                frame,
                spp=settings.spp,
                max_depth=settings.max_depth,
                seed=settings.seed,
                progress=integrator_progress(bar, progress),
            )
        look = settings.look()
        alpha = None
        if self.scene.render.background != "sky":
            began = time.perf_counter()
            alpha = render_coverage(self, frame, settings.spp, settings.seed)
            stats.rays["primary"] += settings.width * settings.height * settings.spp
            stats.render_s += time.perf_counter() - began
        background = self.scene.render.background
        if not names:
            return RenderResult(image, {}, stats, look, frame, background, alpha)
        began = time.perf_counter()
        layers = render_aovs(self, frame, names, settings.seed)
        stats.rays["aov"] = settings.width * settings.height  # one pixel-centre ray per pixel
        stats.render_s += time.perf_counter() - began
        return RenderResult(image, layers, stats, look, frame, background, alpha)

    def update_spheres(self, centers: np.ndarray, radii: np.ndarray) -> None:
        """Move the scene's spheres to ``centers`` (n, 3) and ``radii`` (n,) (the same n and
        materials: the next frame of a trajectory) and refit the BVH instead of building a new
        one (``SceneGeometry.move_spheres``); the next ``render`` sees them bit for bit as a
        ``Renderer`` built on the moved scene would. The renderer must be made with
        ``movable=True`` and analytic spheres; its ``scene`` becomes a copy holding the new
        spheres (the caller's scene is left as it was)."""
        centers = np.asarray(centers, np.float32)
        radii = np.asarray(radii, np.float32)
        move = getattr(self.geometry, "move_spheres", None)
        if move is None:
            raise TypeError(
                f"update_spheres: a {type(self.geometry).__name__} cannot move spheres; "
                "use a Renderer of one BVH"
            )
        move(centers, radii)
        moved = copy.copy(self.scene)
        moved.sphere_centers, moved.sphere_radii = centers, radii
        self.scene = moved

    def render_views(
        self,
        cameras: Iterable[Camera],
        pattern: str,
        *,
        aovs: Sequence[str] = (),
        encoding: film.Encoding | None = None,
        quiet: bool = True,
        **overrides: Unpack[SettingOverrides],
    ) -> list[Path]:
        """Render the scene seen by each of ``cameras`` in turn (``render``, with ``aovs`` and
        ``overrides``) and write view k as soon as it is done to ``pattern.format(k)`` (e.g.
        ``"views/view_{:04d}.png"``) with its AOVs and camera data (``aovs.save_with_aovs``:
        the camera as npz keys or a JSON sidecar, even with no AOVs), so memory stays that of
        one view whatever their number. ``encoding`` as ``save``'s (None: the scene's look,
        8 bits). With ``quiet=False`` a bar on stderr counts the
        views. Every path is checked before the first view is rendered: one that cannot be
        written, or two views given one name, raise ValueError, and nothing is written. An
        existing file is replaced (as ``save`` does). Returns the paths of the views' images,
        in order."""
        names = check_aov_names(aovs)
        cameras = list(cameras)
        paths = [Path(pattern.format(k)) for k in range(len(cameras))]
        if len(set(paths)) != len(paths):
            raise ValueError(f"pattern: {pattern!r} gives two views one file name")
        for path in paths:
            film.check_output_path(path, encoding or film.DEFAULT_ENCODING)
        bar = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm

            bar = tqdm(total=len(cameras), unit="view", file=sys.stderr)
        try:
            for camera, path in zip(cameras, paths, strict=True):
                result = self.render(camera=camera, aovs=names, **overrides)
                chosen = encoding or film.DEFAULT_ENCODING
                if chosen.look is None:
                    chosen = chosen._replace(look=result.look)
                save_with_aovs(result.image, result.aovs, path, chosen, camera=result.camera)
                del result  # one view in memory at a time
                if bar is not None:
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()
        return paths


def png_bytes(pixels: np.ndarray) -> bytes:
    """(h, w, 3) uint8 ``pixels`` as the bytes of a PNG file."""
    import io

    buffer = io.BytesIO()
    film.write_pixels(pixels, buffer, ".png")
    return buffer.getvalue()


# A scene's notebook preview (``Scene._repr_png_``): small, one sample, two bounces.
PREVIEW_WIDTH = 256
PREVIEW_SPP = 1
PREVIEW_DEPTH = 2


def preview(scene: Scene) -> RenderResult:
    """A quick look at ``scene``: ``PREVIEW_WIDTH`` pixels wide at its aspect ratio, one
    sample per pixel, two bounces; its own camera and look."""
    width = PREVIEW_WIDTH
    height = max(1, round(width * scene.render.height / scene.render.width))
    return render(scene, width=width, height=height, spp=PREVIEW_SPP, max_depth=PREVIEW_DEPTH)


def preview_png(scene: Scene) -> bytes:
    """``preview(scene)`` as PNG bytes: what Jupyter shows for a ``Scene``."""
    return preview(scene)._repr_png_()


Scene._repr_png_ = preview_png  # the scene model imports no renderer: it is given its preview


def render(
    scene: Scene,
    *,
    camera: Camera | None = None,
    aovs: Sequence[str] = (),
    threads: int | None = None,
    spheres: str = "analytic",
    batch_size: int = DEFAULT_BATCH_SIZE,
    quiet: bool = True,
    **overrides: Unpack[SettingOverrides],
) -> RenderResult:
    """Render ``scene`` once: build its BVH, render (``Renderer.render``), free the BVH.

    Arguments as ``Renderer`` and ``Renderer.render`` take them. What cannot fit in this
    machine's memory (the BVH, the image, its AOVs) raises ``budget.MemoryBudgetError`` before
    anything is built."""
    names = check_aov_names(aovs)
    settings = scene.render.with_overrides(**overrides)
    require_memory(
        scene, settings, spheres=spheres, threads=threads, batch_size=batch_size, aovs=names
    )
    with Renderer(scene, spheres=spheres, threads=threads, batch_size=batch_size) as renderer:
        return renderer.render(camera=camera, aovs=names, quiet=quiet, **overrides)


def require_memory(
    scene: Scene,
    settings: RenderSettings,
    *,
    spheres: str = "analytic",
    threads: int | None = None,
    batch_size: int = DEFAULT_BATCH_SIZE,
    aovs: tuple[str, ...] = (),
) -> None:
    """Raise ``budget.MemoryBudgetError`` unless this machine can hold ``scene``'s BVH and a
    render of ``settings`` (``budget.render_needs``): call it before building a ``Renderer``."""
    budget.require(
        budget.render_needs(
            len(scene.sphere_radii),
            spheres,
            settings,
            batch_size=batch_size,
            threads=threads,
            aov_pixel_bytes=aov_pixel_bytes(aovs),
        )
    )


@dataclass
class Progress:
    """Where a render stands: camera samples ``done`` of ``total``, ``stats`` (rays traced and
    seconds spent so far), and ``workers``, the Dask workers present (None: a local render)."""

    done: int = 0
    total: int = 0
    stats: RenderStats = field(default_factory=RenderStats)
    workers: int | None = None


@contextmanager
def progress_bar(total: int, quiet: bool) -> Iterator[Callable[[Progress], None] | None]:
    """The progress bar of every render, local or on a cluster: a tqdm bar on stderr counting
    ``total`` samples and showing rays/s (and the workers present, for a cluster); None when
    ``quiet`` or stderr is not a terminal."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, unit="sample", unit_scale=True, file=sys.stderr)

    def show(state: Progress) -> None:
        bar.update(state.done - bar.n)
        text = f"{state.stats.rays_per_s / 1e6:.1f} Mrays/s"
        if state.workers is not None:
            text += f", {state.workers} workers"
        bar.set_postfix_str(text, refresh=False)

    try:
        yield show
    finally:
        bar.close()


def integrator_progress(
    bar: Callable[[Progress], None] | None, progress: Callable[[int, int], None] | None
) -> Callable[[int, int, RenderStats], None]:
    """The integrator's progress callback ``(done, total, stats)``: it moves ``bar``
    (``progress_bar``'s, or None) and calls the caller's ``progress(done, total)``."""

    def show(done: int, total: int, stats: RenderStats) -> None:
        if bar is not None:
            bar(Progress(done, total, stats))
        if progress is not None:
            progress(done, total)

    return show
