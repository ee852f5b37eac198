"""Mesh import through trimesh: OBJ, PLY, STL, OFF, GLB/glTF, each file loaded once, with what
the file says the mesh looks like: its material (glTF metallic-roughness mapped onto Blinn-Phong)
and its per-point colours (base-colour texture, vertex or face colours)."""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from embree_rt.materials import Material
from embree_rt.scene.errors import MeshFileError, SceneError, warn_input
from embree_rt.scene.gltf import MESH_INDEX_TAG, FileCamera, FileLight, PreparedGltf, prepare_gltf
from embree_rt.scene.gltf_materials import (
    LOOKS_KEY,
    GltfLooks,
    attach_gltf_looks,
    metallic_roughness_material,
)
from embree_rt.scene.mesh_companions import candidate_paths
from embree_rt.scene.mesh_formats import MESH_SUFFIXES
from embree_rt.scene.obj import check_obj_files
from embree_rt.scene.paths import unreadable_problem
from embree_rt.scene.ply import with_strips
from embree_rt.textures import DEFAULT_SAMPLER, Sampler, texels_from_image


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


@dataclass
class LoadedModel:
    """A mesh file as embree_rt reads it.

    ``parts``: (mesh, (4, 4) float64 node transform) per placed mesh (``mesh_parts``);
    ``instanced``: (mesh, (n, 4, 4) float64 transforms) per triangle primitive of each glTF node
    placed by ``EXT_mesh_gpu_instancing``; ``camera`` and ``lights``: a glTF's first camera and
    its ``KHR_lights_punctual`` lights, as the file places them (``embree_rt.scene.gltf``).
    """

    parts: list[tuple[trimesh.Trimesh, np.ndarray]]
    instanced: list[tuple[trimesh.Trimesh, np.ndarray]] = field(default_factory=list)
    camera: FileCamera | None = None
    lights: list[FileLight] = field(default_factory=list)

    def meshes(self) -> list[trimesh.Trimesh]:
        """Every distinct mesh of the file, placed or instanced, in order."""
        found = [mesh for mesh, _ in self.parts] + [mesh for mesh, _ in self.instanced]
        return list({id(mesh): mesh for mesh in found}.values())

    def every_placement(self) -> list[tuple[trimesh.Trimesh, np.ndarray]]:
        """``parts``, then each instanced copy as a part of its own (mesh, (4, 4) float64)."""
        copies = [(mesh, matrix) for mesh, transforms in self.instanced for matrix in transforms]
        return self.parts + copies


class _NamesAsWritten(trimesh.resolvers.FilePathResolver):
    """trimesh's resolver for the files a mesh file names, looking where
    ``mesh_companions.candidate_paths`` says (Windows separators, URI escapes, bare names), as
    Blender and assimp do; a name may lead outside the mesh's directory (``../textures``)."""

    def get(self, name: str) -> bytes:
        for path in candidate_paths(Path(self.parent), name):
            if unreadable_problem(path) is None and path.exists():
                return path.read_bytes()
        raise FileNotFoundError(name)


def read_model(path: Path) -> LoadedModel:
    """The meshes of the file at ``path`` (see ``LoadedModel``), checked: finite vertices,
    faces that index existing vertices, at least one triangle. Raises ``MeshFileError``;
    what it renders differently or leaves out is an ``InputWarning`` line."""
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshFileError(
            "(file)", f"unsupported mesh format; use one of {', '.join(MESH_SUFFIXES)}"
        )
    if (problem := unreadable_problem(path)) is not None:
        raise MeshFileError("(file)", problem)
    if not path.exists():
        raise MeshFileError("(file)", "no such file")
    prepared = prepare_gltf(path) if suffix in (".glb", ".gltf") else PreparedGltf()
    if suffix == ".obj":
        check_obj_files(path)
    resolver = _NamesAsWritten(str(path), allow_anywhere=True)
    # NumPy's RuntimeWarnings inside trimesh (a value beyond the file's float32, cast to inf)
    # are caught here: the vertices are checked below, and the error says what it meant.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            if prepared.data is not None:
                loaded = trimesh.load(
                    io.BytesIO(prepared.data),
                    file_type=suffix[1:],
                    resolver=resolver,
                    process=False,
                )
            else:
                loaded = trimesh.load(str(path), resolver=resolver, process=False)
        except Exception as error:  # trimesh raises many kinds for a file it cannot parse
            raise MeshFileError("(file)", f"cannot read mesh: {error}") from None
    overflowed = False
    for warning in caught:
        if issubclass(warning.category, RuntimeWarning):
            overflowed |= "overflow" in str(warning.message)
        else:  # trimesh's own warnings, as they were
            warnings.warn_explicit(
                warning.message, warning.category, warning.filename, warning.lineno
            )
    if suffix == ".ply":
        loaded = with_strips(loaded)
    if suffix in (".glb", ".gltf"):
        read_gltf_looks(path, loaded)
    parts = mesh_parts(loaded) if isinstance(loaded, trimesh.Trimesh | trimesh.Scene) else []
    instanced = []
    for mesh_index, transforms, _ in prepared.instanced:
        for geometry in loaded.geometry.values():
            if (
                isinstance(geometry, trimesh.Trimesh)
                and len(geometry.faces)
                and geometry.metadata.get(MESH_INDEX_TAG) == mesh_index
            ):
                instanced.append((geometry, transforms))
    model = LoadedModel(parts, instanced, prepared.camera, prepared.lights)
    if not model.meshes():
        raise MeshFileError("(file)", "the mesh has no triangles")
    for mesh in model.meshes():
        if not np.isfinite(mesh.vertices).all():
            beyond = " (values beyond the range of the file's number type)" if overflowed else ""
            raise MeshFileError("(file)", f"vertices contain NaN or inf{beyond}")
        # trimesh loads a face naming a missing vertex without complaint (PLY); catch it here,
        # where the message can name the file, not later in the BVH build.
        faces = np.asarray(mesh.faces)
        if faces.min() < 0 or faces.max() >= len(mesh.vertices):
            raise MeshFileError(
                "(file)", f"a face indexes a vertex outside [0, {len(mesh.vertices)})"
            )
    return model


def load_model(path: Path, file: object = None, key: str | None = None) -> LoadedModel:
    """``read_model(path)`` with its problems raised as ``SceneError``: naming the scene
    ``file`` and its ``key`` that named the mesh, or, without them, the mesh file itself."""
    try:
        return read_model(path)
    except MeshFileError as error:
        if file is None:
            raise SceneError(path, error.key, error.problem) from None
        where = "" if error.key == "(file)" else f"{error.key}: "
        raise SceneError(file, key, f"{path}: {where}{error.problem}") from None


def load_mesh_parts(path: Path, file: object, key: str) -> list[tuple[trimesh.Trimesh, np.ndarray]]:
    """The meshes in ``path`` with their (4, 4) float64 node transforms (identity for a plain
    mesh; a multi-node glTF keeps one part per node), instanced glTF nodes baked as one part
    per copy. Errors name the scene ``file`` and ``key``."""
    return load_model(path, file, key).every_placement()


def read_gltf_looks(path: Path, loaded: trimesh.Trimesh | trimesh.Scene) -> None:
    """Attach to each of ``loaded``'s meshes what the glTF file ``path`` says of its material
    beyond what trimesh keeps (``gltf_materials.attach_gltf_looks``); a file whose materials
    cannot be read that way keeps trimesh's reading, with a one-line warning."""
    meshes = list(loaded.geometry.values()) if isinstance(loaded, trimesh.Scene) else [loaded]
    try:
        attach_gltf_looks(path, meshes)
    except (OSError, ValueError, KeyError, IndexError, TypeError) as error:
        warn_input(
            f"{path}: glTF materials read as trimesh reads them only "
            f"({type(error).__name__}: {error})"
        )


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


def is_placeholder_material(material: object) -> bool:
    """Whether ``material`` is the stand-in trimesh gives an OBJ with texture coordinates but
    no material (a 2x2 grey image read from no file, ``trimesh.visual.material.color_image()``):
    no material at all, not a texture. A texture read from an MTL records its file name."""
    if not isinstance(material, trimesh.visual.material.SimpleMaterial):
        return False
    image = getattr(material, "image", None)
    if image is None or "file_path" in getattr(image, "info", {}) or image.size != (2, 2):
        return False
    placeholder = np.asarray(trimesh.visual.material.color_image())
    return np.array_equal(np.asarray(image.convert("RGBA")), placeholder)


def _file_material(visual: object) -> object | None:
    """The material a mesh's file gives it: a TextureVisuals' material, None for none or for
    trimesh's placeholder."""
    if not isinstance(visual, trimesh.visual.TextureVisuals):
        return None
    material = visual.material
    return None if material is None or is_placeholder_material(material) else material


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
    if (material := _file_material(visual)) is not None:
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
        if (material := _file_material(visual)) is not None:
            factor = _base_color_factor(material)
            image = _texture_image(material)
            coordinates = visual.uv
            if (
                image is not None
                and coordinates is not None
                and len(coordinates) == len(mesh.vertices)
            ):
                texels = texels_from_image(image)
                uv = np.nan_to_num(
                    np.asarray(coordinates, np.float64)[:, :2], nan=0.0, posinf=0.0, neginf=0.0
                )
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
