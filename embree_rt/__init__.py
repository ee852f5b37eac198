"""embree_rt: a Whitted-style ray tracer for scenes of very many objects.

``render(scene)`` renders one image; ``Renderer(scene)`` keeps the BVH for many views
(``Renderer.render(camera=...)``). Both return a ``RenderResult``: the linear image, its AOVs
and the render's statistics.
"""

from embree_rt.ambient_occlusion import AmbientOcclusion
from embree_rt.aovs import AOV_NAMES, save_with_aovs
from embree_rt.api import Renderer, RenderResult, render
from embree_rt.camera import Camera
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
from embree_rt.version import __version__

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
