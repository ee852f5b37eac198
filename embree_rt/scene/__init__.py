"""Scene model, scene files and mesh import."""

from embree_rt.scene.errors import SceneError
from embree_rt.scene.loader import load_scene
from embree_rt.scene.model import (
    Background,
    Camera,
    Floor,
    MeshObject,
    PointLight,
    RenderSettings,
    Scene,
)
from embree_rt.scene.random_field import random_field
from embree_rt.scene.writer import save_scene

__all__ = [
    "Background",
    "Camera",
    "Floor",
    "MeshObject",
    "PointLight",
    "RenderSettings",
    "Scene",
    "SceneError",
    "load_scene",
    "random_field",
    "save_scene",
]
