"""Scene model, scene files and mesh import."""

from embree_rt.scene.model import (
    Background,
    Camera,
    Floor,
    MeshObject,
    PointLight,
    RenderSettings,
    Scene,
)

__all__ = ["Background", "Camera", "Floor", "MeshObject", "PointLight", "RenderSettings", "Scene"]
