"""embree_rt: a Whitted-style ray tracer for scenes of very many objects."""

from embree_rt.materials import PRESETS, Checker, Material, preset
from embree_rt.scene import (
    Background,
    Camera,
    Floor,
    MeshObject,
    PointLight,
    RenderSettings,
    Scene,
)

__all__ = [
    "PRESETS",
    "Background",
    "Camera",
    "Checker",
    "Floor",
    "Material",
    "MeshObject",
    "PointLight",
    "RenderSettings",
    "Scene",
    "preset",
]
