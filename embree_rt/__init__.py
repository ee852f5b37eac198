"""embree_rt: a Whitted-style ray tracer for scenes of very many objects.

``render(scene)`` renders one image; ``Renderer(scene)`` keeps the BVH for many views
(``Renderer.render(camera=...)``). Both return a ``RenderResult``: the linear image, its AOVs
and the render's statistics.

The names below are imported on first use (PEP 562), so that ``embree-rt --version`` and
``--help`` start without NumPy, numba or Embree.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

from embree_rt.version import __version__

if TYPE_CHECKING:
    from embree_rt.ambient_occlusion import AmbientOcclusion
    from embree_rt.aovs import save_with_aovs
    from embree_rt.api import Renderer, RenderResult, render
    from embree_rt.camera import Camera
    from embree_rt.choices import AOV_NAMES
    from embree_rt.film import Encoding, Look, save_image, tonemap
    from embree_rt.integrator import RenderStats
    from embree_rt.materials import PRESETS, Checker, Material, preset
    from embree_rt.scene.errors import SceneError
    from embree_rt.scene.loader import load_scene
    from embree_rt.scene.model import (
        Background,
        CurveSet,
        Floor,
        MeshObject,
        PointLight,
        RenderSettings,
        Scene,
    )
    from embree_rt.scene.random_field import random_field
    from embree_rt.scene.writer import save_scene

# public name -> the module that defines it
_HOMES = {
    "AmbientOcclusion": "embree_rt.ambient_occlusion",
    "AOV_NAMES": "embree_rt.choices",
    "save_with_aovs": "embree_rt.aovs",
    "Renderer": "embree_rt.api",
    "RenderResult": "embree_rt.api",
    "render": "embree_rt.api",
    "Camera": "embree_rt.camera",
    "Encoding": "embree_rt.film",
    "Look": "embree_rt.film",
    "save_image": "embree_rt.film",
    "tonemap": "embree_rt.film",
    "RenderStats": "embree_rt.integrator",
    "PRESETS": "embree_rt.materials",
    "Checker": "embree_rt.materials",
    "Material": "embree_rt.materials",
    "preset": "embree_rt.materials",
    "SceneError": "embree_rt.scene.errors",
    "load_scene": "embree_rt.scene.loader",
    "Background": "embree_rt.scene.model",
    "CurveSet": "embree_rt.scene.model",
    "Floor": "embree_rt.scene.model",
    "MeshObject": "embree_rt.scene.model",
    "PointLight": "embree_rt.scene.model",
    "RenderSettings": "embree_rt.scene.model",
    "Scene": "embree_rt.scene.model",
    "random_field": "embree_rt.scene.random_field",
    "save_scene": "embree_rt.scene.writer",
}

__all__ = [
    "AOV_NAMES",
    "PRESETS",
    "AmbientOcclusion",
    "Background",
    "Camera",
    "Checker",
    "CurveSet",
    "Encoding",
    "Floor",
    "Look",
    "Material",
    "MeshObject",
    "PointLight",
    "RenderResult",
    "RenderSettings",
    "RenderStats",
    "Renderer",
    "Scene",
    "SceneError",
    "__version__",
    "load_scene",
    "preset",
    "random_field",
    "render",
    "save_image",
    "save_scene",
    "save_with_aovs",
    "tonemap",
]


def __getattr__(name: str) -> object:
    """The public name ``name``, imported from its module on first use."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'embree_rt' has no attribute {name!r}")
    value = getattr(import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOMES})
