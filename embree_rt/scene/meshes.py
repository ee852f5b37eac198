"""Mesh import through trimesh: OBJ, PLY, STL, OFF, GLB/glTF, each file loaded once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from embree_rt.materials import RGB
from embree_rt.scene.errors import SceneError

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def mesh_parts(
    loaded: trimesh.Trimesh | trimesh.Scene,
) -> list[tuple[trimesh.Trimesh, np.ndarray]]:
    """The triangle meshes in ``loaded``, each with its (4, 4) float64 transform to the
    scene's space: a Trimesh with the identity, or a trimesh.Scene's nodes that hold a Trimesh,
    with the node's world transform (a mesh under several nodes appears once per node, as the
    same object). Meshes without a face, points and paths are left out."""
    if isinstance(loaded, trimesh.Trimesh):
        parts = [(loaded, np.eye(4))]
    else:
        parts = []
        for node in loaded.graph.nodes_geometry:
            transform, geometry_name = loaded.graph[node]
            geometry = loaded.geometry[geometry_name]
            if isinstance(geometry, trimesh.Trimesh):
                parts.append((geometry, np.asarray(transform, np.float64)))
    return [(mesh, transform) for mesh, transform in parts if len(mesh.faces)]


def load_mesh_parts(path: Path, file: object, key: str) -> list[tuple[trimesh.Trimesh, np.ndarray]]:
    """The meshes in ``path`` with their (4, 4) float64 node transforms (identity for a plain
    mesh; a multi-node glTF keeps one part per node). Errors name the scene ``file`` and ``key``."""
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise SceneError(
            file, key, f"{path}: unsupported mesh format; use one of {', '.join(MESH_SUFFIXES)}"
        )
    if not path.is_file():
        raise SceneError(file, key, f"{path}: no such file")
    try:
        loaded = trimesh.load(str(path), process=False)
    except Exception as error:  # trimesh raises many kinds for a file it cannot parse
        raise SceneError(file, key, f"{path}: cannot read mesh: {error}") from None
    parts = mesh_parts(loaded) if isinstance(loaded, trimesh.Trimesh | trimesh.Scene) else []
    if not parts:
        raise SceneError(file, key, f"{path}: the mesh has no triangles")
    for mesh, _ in parts:
        if not np.isfinite(mesh.vertices).all():
            raise SceneError(file, key, f"{path}: vertices contain NaN or inf")
        # trimesh loads a face naming a missing vertex without complaint (PLY); catch it here,
        # where the message can name the scene file and key, not later in the BVH build.
        faces = np.asarray(mesh.faces)
        if faces.min() < 0 or faces.max() >= len(mesh.vertices):
            raise SceneError(
                file, key, f"{path}: a face indexes a vertex outside [0, {len(mesh.vertices)})"
            )
    return parts


def mesh_base_color(mesh: trimesh.Trimesh) -> RGB | None:
    """The mesh's base color as linear-ish RGB in [0, 1], or None when it has only the default."""
    visual = mesh.visual
    try:
        if visual.kind == "texture" and hasattr(visual.material, "main_color"):
            rgba = np.asarray(visual.material.main_color, np.float64)
        elif visual.kind in ("face", "vertex"):
            colors = visual.face_colors if visual.kind == "face" else visual.vertex_colors
            rgba = np.asarray(colors, np.float64).mean(axis=0)
        else:
            return None
    except Exception:
        return None
    rgb = rgba[:3] / 255.0
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))
