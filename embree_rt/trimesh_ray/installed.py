"""Opting in for every new ``trimesh.Trimesh``: ``install()`` gives each mesh created from then
on embree_rt's ray queries (``mesh.ray``) and proximity queries (``mesh.nearest``); ``uninstall()``
undoes it."""

from __future__ import annotations

import functools
import inspect

import trimesh

from embree_rt.trimesh_ray.intersector import RayMeshIntersector
from embree_rt.trimesh_ray.proximity import ProximityQuery

_original_init = None


def install() -> None:
    """Make every ``trimesh.Trimesh`` created from now on use ``RayMeshIntersector`` as
    ``mesh.ray`` and ``ProximityQuery`` as ``mesh.nearest``, where trimesh would have used its
    embree backend (``use_embree=True``, its default; a mesh made with ``use_embree=False``
    keeps trimesh's own ray and proximity queries). Calling it twice changes nothing."""
    global _original_init
    if _original_init is not None:
        return
    original = trimesh.Trimesh.__init__
    signature = inspect.signature(original)

    @functools.wraps(original)
    def __init__(self, *args, **kwargs):  # noqa: N807
        original(self, *args, **kwargs)
        bound = signature.bind(self, *args, **kwargs)
        if bound.arguments.get("use_embree", True):
            self.ray = RayMeshIntersector(self)
            self.nearest = ProximityQuery(self)

    _original_init = original
    trimesh.Trimesh.__init__ = __init__


def uninstall() -> None:
    """Undo ``install()``: new meshes get trimesh's own ray and proximity queries again."""
    global _original_init
    if _original_init is not None:
        trimesh.Trimesh.__init__ = _original_init
        _original_init = None
