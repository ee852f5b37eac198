"""Mesh import through trimesh: OBJ, PLY, STL, OFF, GLB/glTF, each file loaded once, with what
the file says the mesh looks like: its material (glTF metallic-roughness mapped onto Blinn-Phong)
and its per-point colours (base-colour texture, vertex or face colours)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from embree_rt.materials import Material
from embree_rt.scene.errors import SceneError
from embree_rt.scene.gltf_materials import (
    LOOKS_KEY,
    GltfLooks,
    attach_gltf_looks,
    metallic_roughness_material,
    warn,
)
from embree_rt.textures import DEFAULT_SAMPLER, Sampler, texels_from_image

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
    if path.suffix.lower() in (".glb", ".gltf"):
        read_gltf_looks(path, loaded)
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


def read_gltf_looks(path: Path, loaded: trimesh.Trimesh | trimesh.Scene) -> None:
    """Attach to each of ``loaded``'s meshes what the glTF file ``path`` says of its material
    beyond what trimesh keeps (``gltf_materials.attach_gltf_looks``); a file whose materials
    cannot be read that way keeps trimesh's reading, with a one-line warning."""
    meshes = list(loaded.geometry.values()) if isinstance(loaded, trimesh.Scene) else [loaded]
    try:
        attach_gltf_looks(path, meshes)
    except (OSError, ValueError, KeyError, IndexError, TypeError) as error:
        warn(f"{path}: glTF materials read as trimesh reads them only "
             f"({type(error).__name__}: {error})")  # fmt: skip


# -- what a mesh looks like ----------------------------------------------------------------------

# trimesh fills an MTL material's missing ``Kd`` with this grey; beside a ``map_Kd`` texture it
# is read as no ``Kd`` at all (factor 1), or every such texture would render at 40% brightness.
_TRIMESH_DEFAULT_RGBA = (102, 102, 102, 255)
@dataclass(frozen=True)
class MeshSurface:
    """The colour a mesh gives each point of its surface, linear RGB.

    A point's base colour is ``factor`` × the texture at its interpolated UV × its interpolated
    vertex colour (or its face's colour), each factor present or not: ``factor`` (3,) float32;
    ``texels`` (h, w, 4) float32, linear RGB and alpha (``embree_rt.textures``), with ``uv``
    (2, v) float32 per vertex; ``vertex_colors`` (3, v) float32; ``face_colors`` (3, f) float32.
    The texture is read as ``sampler`` says; ``looks`` is what a glTF file says besides
    (emissive texture, alpha, ...: ``gltf_materials.GltfLooks``). Per-vertex arrays hold one
    vertex per column, so that gathers at the hits come out (3, n).
    """

    factor: np.ndarray
    texels: np.ndarray | None = None
    uv: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    face_colors: np.ndarray | None = None
    sampler: Sampler = DEFAULT_SAMPLER
    looks: GltfLooks | None = None


def _rgb(rgba: object) -> np.ndarray:
    """(3,) float64 RGB in [0, 1] of an 8-bit RGBA (or RGB) colour."""
    return np.asarray(rgba, np.float64)[:3] / 255.0


def _colors_in_unit_range(colors: np.ndarray) -> np.ndarray:
    """(n, 3) float64 of (n, 3 or 4) colours stored as floats in [0, 1] or as normalised
    integers (glTF's COLOR_0 may be either; trimesh keeps what the accessor held)."""
    colors = np.asarray(colors)
    if colors.dtype.kind in "iu":
        colors = colors / float(np.iinfo(colors.dtype).max)
    colors = np.nan_to_num(np.asarray(colors, np.float64)[:, :3], nan=0.0, posinf=1.0)
    return np.clip(colors, 0.0, 1.0)


def _texture_image(material: object):
    """The base-colour image of a trimesh material (glTF's baseColorTexture, MTL's map_Kd)."""
    if isinstance(material, trimesh.visual.material.PBRMaterial):
        return material.baseColorTexture
    return getattr(material, "image", None)


def _base_color_factor(material: object) -> np.ndarray:
    """(3,) float64 linear base-colour factor of a trimesh material: glTF's baseColorFactor
    (white when absent, as glTF defines), or MTL's Kd."""
    if isinstance(material, trimesh.visual.material.PBRMaterial):
        factor = material.baseColorFactor
        return np.ones(3) if factor is None else _rgb(factor)
    diffuse = getattr(material, "diffuse", None)
    if diffuse is None:
        return np.ones(3)
    if _texture_image(material) is not None and tuple(diffuse) == _TRIMESH_DEFAULT_RGBA:
        return np.ones(3)
    return _rgb(diffuse)


def mesh_material(mesh: trimesh.Trimesh) -> Material | None:
    """The material a mesh's own file gives it, or None when it gives none (the caller's
    default applies).

    Its ``color`` is the base-colour factor (glTF ``baseColorFactor``, white by default, or MTL
    ``Kd``) for a mesh with a material, or the mean of its vertex or face colours; the per-point
    colours themselves are ``mesh_surface``'s. glTF's metallic and roughness factors (1 and 1
    when absent, as glTF defines) map by ``metallic_roughness_material``; an OBJ material keeps
    the matte defaults (MTL ``Ks``/``Ns`` are too often placeholders: converters write ``Ks 1``
    with ``Ns 0``). Colours are linear: glTF defines its factors and vertex colours so, and
    8-bit vertex colours of other formats are read the same way.
    """
    if (looks := mesh.metadata.get(LOOKS_KEY)) is not None:
        return looks.material
    visual = mesh.visual
    if isinstance(visual, trimesh.visual.TextureVisuals) and visual.material is not None:
        material = visual.material
        color = tuple(float(c) for c in _base_color_factor(material))
        if isinstance(material, trimesh.visual.material.PBRMaterial):
            metallic = 1.0 if material.metallicFactor is None else material.metallicFactor
            roughness = 1.0 if material.roughnessFactor is None else material.roughnessFactor
            return metallic_roughness_material(color, metallic, roughness)
        return Material(color=color)
    if visual.kind in ("face", "vertex"):
        colors = visual.face_colors if visual.kind == "face" else visual.vertex_colors
        mean = _colors_in_unit_range(colors).mean(axis=0)
        return Material(color=tuple(float(c) for c in mean))
    return None


def mesh_surface(mesh: trimesh.Trimesh) -> MeshSurface | None:
    """The per-point colours of ``mesh`` (see ``MeshSurface``), decoded once: the base-colour
    texture (sRGB) to linear texels, 8-bit vertex and face colours to [0, 1]. None when every
    point has the same colour (no texture; uniform or no vertex colours): then the material's
    colour is the whole story and the renderer does no per-hit work for the mesh.

    UVs that are not finite are read as 0: a broken coordinate must not put NaN in a picture.
    """
    visual = mesh.visual
    factor = np.ones(3)
    texels = uv = vertex_colors = face_colors = None
    if isinstance(visual, trimesh.visual.TextureVisuals):
        if visual.material is not None:
            factor = _base_color_factor(visual.material)
            image = _texture_image(visual.material)
            coordinates = visual.uv
            if (
                image is not None
                and coordinates is not None
                and len(coordinates) == len(mesh.vertices)
            ):
                texels = texels_from_image(image)
                uv = np.nan_to_num(np.asarray(coordinates, np.float64)[:, :2], nan=0.0,
                                   posinf=0.0, neginf=0.0)  # fmt: skip
                uv = np.ascontiguousarray(uv.T, np.float32)
        colors = visual.vertex_attributes.get("color")
        if colors is not None and len(colors) == len(mesh.vertices):
            vertex_colors = _colors_in_unit_range(colors)
    elif visual.kind == "vertex":
        vertex_colors = _colors_in_unit_range(visual.vertex_colors)
    elif visual.kind == "face":
        face_colors = _colors_in_unit_range(visual.face_colors)
    # Colours the same everywhere are one factor (what ``mesh_material`` makes the colour).
    if vertex_colors is not None and np.ptp(vertex_colors, axis=0).max() == 0:
        factor, vertex_colors = factor * vertex_colors[0], None
    if face_colors is not None and np.ptp(face_colors, axis=0).max() == 0:
        factor, face_colors = factor * face_colors[0], None
    sampler = DEFAULT_SAMPLER
    looks = mesh.metadata.get(LOOKS_KEY)
    if looks is not None:  # the glTF file's own reading of its base colour
        factor = looks.base_color_factor[:3].astype(np.float64)
        texels = uv = None
        if (base := looks.base_color) is not None:
            texels, uv, sampler = base.texels, base.uv, base.sampler
        if not looks.per_point:
            looks = None
    if texels is None and vertex_colors is None and face_colors is None and looks is None:
        return None

    return MeshSurface(
        factor=factor.astype(np.float32),
        texels=texels,
        uv=uv,
        vertex_colors=_columns(vertex_colors),
        face_colors=_columns(face_colors),
        sampler=sampler,
        looks=looks,
    )


def _columns(rows: np.ndarray | None) -> np.ndarray | None:
    """(3, n) float32 C-contiguous columns of (n, 3) ``rows`` (None stays None)."""
    return None if rows is None else np.ascontiguousarray(rows.T, np.float32)
