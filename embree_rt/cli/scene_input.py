"""What the command's scene argument names: a scene file (TOML or JSON) or a mesh file rendered
on its own (``Scene.from_file``), and what a cluster's workers make the scene from."""

from __future__ import annotations

import argparse
from pathlib import Path

from embree_rt.scene.model import Scene

SCENE_SUFFIXES = (".toml", ".json")


def is_mesh_file(path: str | Path) -> bool:
    """Whether ``path`` names a mesh file rather than a scene file, by its extension; raises
    ``SceneError`` for an extension that is neither's."""
    suffix = Path(path).suffix.lower()
    if suffix in SCENE_SUFFIXES:
        return False
    from embree_rt.scene.meshes import MESH_SUFFIXES  # trimesh: ~1 s to import

    if suffix in MESH_SUFFIXES:
        return True
    from embree_rt.scene.errors import SceneError

    raise SceneError(
        path,
        "(file)",
        f"expected a scene file ({', '.join(SCENE_SUFFIXES)}) or "
        f"a mesh file ({', '.join(MESH_SUFFIXES)})",
    )


def read_scene(args: argparse.Namespace) -> tuple[Scene, Path | Scene]:
    """The scene ``args.scene`` names, with ``--no-floor`` and the settings (``--set`` and the
    flags standing for a key), and the source a cluster's workers make it from: the scene
    file's path when they can load it as it is (they load a path with ``load_scene``; the
    render settings travel with the frames), else the ``Scene`` itself (scattered to them)."""
    from embree_rt.scene.settings import Setting, apply_to_scene, load_scene_with

    settings = list(args.settings)
    path = Path(args.scene)
    if is_mesh_file(path):
        scene = Scene.from_file(path, floor=not args.no_floor)
        apply_to_scene(scene, settings, str(path))
        return staged(scene, args), scene
    if args.no_floor:
        settings.append(Setting("floor", False, "--no-floor"))
    scene = load_scene_with(path, settings)
    if restaged(args):
        return staged(scene, args), scene
    return scene, (path if only_render_settings(settings) else scene)


def restaged(args: argparse.Namespace) -> bool:
    """Whether ``args`` change the scene after it is made (``staged``): then a cluster's
    workers are given the scene itself, not its file or recipe."""
    return getattr(args, "view", None) is not None or getattr(args, "headlight", False)


def staged(scene: Scene, args: argparse.Namespace) -> Scene:
    """``scene`` with its camera turned to ``args.view`` (``scene.views.standard_view``) of
    the scene's bounds, orthographic unless ``--perspective`` came last of the projection
    flags, and then with ``--headlight``: a white point light of intensity 1 at the camera
    (lights have no fall-off, so it lights what faces the camera evenly); a still's camera
    only, as a light does not move with an animation's camera."""
    from embree_rt.scene.errors import SceneError

    where = getattr(args, "scene", None) or "the scene"
    view = getattr(args, "view", None)
    if view is not None:
        if scene.animation is not None:
            raise SceneError(where, "animation", f"--view {view}: the animation moves the camera")
        staged_view(scene, args, view, where)
    if getattr(args, "headlight", False):
        if scene.animation is not None:
            raise SceneError(
                where,
                "animation",
                "--headlight: a light that follows an animated camera is "
                "not supported; place a light in the scene instead",
            )
        from embree_rt.scene.model import PointLight

        scene.lights.append(PointLight(position=tuple(scene.camera.position)))
    return scene


def staged_view(scene: Scene, args: argparse.Namespace, view: str, where: str) -> None:
    """Turn ``scene``'s camera to the standard ``view`` (``staged``)."""
    from embree_rt.scene.errors import SceneError
    from embree_rt.scene.views import scene_bounds, standard_view

    bounds = scene_bounds(scene)
    if bounds is None:
        raise SceneError(where, "(file)", f"--view {view}: the scene has nothing to frame")
    projections = [s.value for s in args.settings if s.key == "camera.projection"]
    orthographic = not projections or projections[-1] == "orthographic"
    aspect = scene.render.width / scene.render.height
    scene.camera = standard_view(scene.camera, *bounds, view, aspect, orthographic)


def only_render_settings(settings) -> bool:
    """Whether ``settings`` change the render settings alone (which travel with the frames to
    a cluster's workers), so workers can make the scene themselves."""
    return all(setting.key.startswith("render.") for setting in settings)
