"""Make the small meshes the example scenes use, from trimesh's primitives.

    python assets/make_assets.py

Writes, beside this script: torus.obj, gem.ply, capsule.stl, cone.off, twisted_box.glb, and
trio.glb (a glTF scene of three nodes, each with its own transform).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent


def torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=0.6, minor_radius=0.22, major_sections=48,
                                  minor_sections=24)  # fmt: skip


def gem() -> trimesh.Trimesh:
    """A faceted gem: an icosahedron, squashed, its facets kept flat."""
    mesh = trimesh.creation.icosahedron()
    mesh.apply_scale([0.5, 0.7, 0.5])
    return mesh


def capsule() -> trimesh.Trimesh:
    return trimesh.creation.capsule(height=0.8, radius=0.3, count=[24, 24])


def cone() -> trimesh.Trimesh:
    return trimesh.creation.cone(radius=0.5, height=1.2, sections=48)


def twisted_box() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(0.6, 1.4, 0.6))
    box = box.subdivide().subdivide().subdivide()
    vertices = box.vertices.copy()
    angle = vertices[:, 1] * 1.2  # twist about y, more with height
    cos, sin = np.cos(angle), np.sin(angle)
    x, z = vertices[:, 0].copy(), vertices[:, 2].copy()
    vertices[:, 0] = cos * x - sin * z
    vertices[:, 2] = sin * x + cos * z
    return trimesh.Trimesh(vertices, box.faces, process=False)


def trio() -> trimesh.Scene:
    scene = trimesh.Scene()
    colors = [(230, 80, 60, 255), (70, 170, 90, 255), (60, 110, 220, 255)]
    for i, color in enumerate(colors):
        mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.35)
        mesh.visual.vertex_colors = color
        transform = trimesh.transformations.translation_matrix([(i - 1) * 0.9, 0.35, 0])
        scene.add_geometry(mesh, node_name=f"ball{i}", transform=transform)
    return scene


def main() -> None:
    torus().export(HERE / "torus.obj")
    gem().export(HERE / "gem.ply")
    capsule().export(HERE / "capsule.stl")
    cone().export(HERE / "cone.off")
    twisted_box().export(HERE / "twisted_box.glb")
    trio().export(HERE / "trio.glb")


if __name__ == "__main__":
    main()
