"""``embree-rt render SCENE --cameras CAMERAS.json -o views/v_{view:03d}.png``: many views of
one BVH (``api.Renderer.render_views``), each view written with its AOVs and camera data as it
finishes, a progress bar counting the views.

The cameras file (JSON or TOML) holds ``cameras``, a list of tables each read as a scene file's
``[camera]`` table is (the same keys and checks; a key left out takes the camera's default).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from embree_rt.camera import Camera
from embree_rt.cli.errors import UsageError
from embree_rt.cli.job import Job

VIEW_FIELD = "{view"


def read_cameras(path: str) -> list[Camera]:
    """The cameras of the file at ``path``; a ``SceneError`` naming the file and the key
    (``cameras[2].fov``) for what a scene file's camera could not be."""
    from embree_rt.scene.errors import SceneError
    from embree_rt.scene.loader import SceneReader, read_document

    document = read_document(Path(path))
    entries = document.get("cameras")
    if not isinstance(entries, list) or not entries:
        raise SceneError(path, "cameras", "expected a non-empty list of camera tables")
    cameras = []
    for index, entry in enumerate(entries):
        try:
            cameras.append(SceneReader(Path(path), {"camera": entry}).scene.camera)
        except SceneError as error:
            key = f"cameras[{index}]" + error.key.removeprefix("camera")
            raise SceneError(path, key, error.problem) from None
    return cameras


def run_views(job: Job, args: argparse.Namespace, timeline) -> None:
    """Render ``job``'s scene seen by each camera of ``args.cameras`` to ``-o``'s ``{view}``
    pattern, on this machine; views on disk are refused unless ``--overwrite``."""
    from embree_rt.api import Renderer, require_memory
    from embree_rt.cli.checks import output_encoding
    from embree_rt.cli.sources import prepare_scene

    pattern = job.output.pattern
    if job.on_dask:
        raise UsageError("--cameras: the views are rendered on this machine")
    if job.reads_trajectory or job.output.framed:
        raise UsageError("--cameras: views of one scene, not frames ({frame}, --frames)")
    if VIEW_FIELD not in pattern:
        raise UsageError("--cameras: -o needs a {view} pattern, e.g. views/v_{view:03d}.png")
    cameras = read_cameras(args.cameras)
    positional = pattern.replace(VIEW_FIELD, "{0")
    try:
        paths = [Path(positional.format(k)) for k in range(len(cameras))]
    except (ValueError, IndexError, KeyError) as error:
        raise UsageError(f"-o: {pattern}: cannot format a view number: {error}") from None
    existing = [p for p in paths if p.exists()]
    if existing and not job.output.overwrite:
        raise UsageError(f"-o: {existing[0]} exists (--overwrite to replace the views)")
    for directory in sorted({p.parent for p in paths}):
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise UsageError(f"-o: cannot make the directory {directory}: {error}") from None
    made = prepare_scene(job, timeline)
    scene = made.scene
    require_memory(scene, scene.render, spheres=job.spheres, threads=job.where.threads)
    encoding = output_encoding(job.output)._replace(look=scene.render.look())
    with Renderer(scene, spheres=job.spheres, threads=job.where.threads) as renderer:
        try:
            renderer.render_views(
                cameras, positional, aovs=job.output.aovs or (), encoding=encoding, quiet=job.quiet
            )
        except ValueError as error:
            raise UsageError(f"-o: {error}") from None
    if not job.quiet:
        print(f"embree-rt: {len(cameras)} views of {job.scene_name} -> {pattern}", file=sys.stderr)
