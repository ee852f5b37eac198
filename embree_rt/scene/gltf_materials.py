"""glTF materials as the file states them: what trimesh keeps of a glTF material is its core
metallic-roughness fields and a base-colour texture read through its first UV set, so the rest
(emission strength, transmission, index of refraction, volume absorption, unlit, samplers' wrap
modes and filters, KHR_texture_transform, texCoord 1, tangents, vertex alpha) is read here from
the file's own JSON and buffers, and attached to each loaded primitive as ``GltfLooks``.

Primitives are matched to trimesh's meshes by order: trimesh makes one mesh per primitive, in
the order of the file's meshes and their primitives (points, lines, triangles and strips alike),
and keeps the vertices in accessor order (``process=False``). A file where the counts do not
agree keeps trimesh's reading, with a one-line warning.
"""

from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from embree_rt.materials import RGB, Material
from embree_rt.scene.errors import warn_input
from embree_rt.scene.gltf import GltfBuffers, accessor_array, read_gltf, uri_path
from embree_rt.textures import (
    DEFAULT_SAMPLER,
    NEAREST,
    REPEAT,
    WRAP_MODES,
    Sampler,
    texels_from_image,
)

# glTF primitive modes trimesh turns into a mesh, point cloud or path (one entry each).
LOADED_MODES = (0, 1, 4, 5)
TRIANGLE_MODES = (4, 5)
DEFAULT_IOR = 1.5
# glTF's metallic-roughness model → Blinn-Phong: highlight exponent range, and the mirror
# reflectance at normal incidence of a dielectric (plastics, paint: about 4%) and of a metal.
SHININESS_RANGE = (1.0, 4096.0)
DIELECTRIC_REFLECTIVITY = 0.04
METAL_REFLECTIVITY = 0.9


@dataclass(frozen=True)
class TextureSlot:
    """One texture of a material as a primitive reads it: ``texels`` (h, w, 4) float32 (see
    ``embree_rt.textures.texels_from_image``), ``uv`` (2, v) float32 per vertex in trimesh's
    convention (v up) with the texture's KHR_texture_transform already applied (an affine map
    commutes with the barycentric blend), and its ``sampler``."""

    texels: np.ndarray
    uv: np.ndarray
    sampler: Sampler = DEFAULT_SAMPLER


@dataclass(frozen=True)
class GltfLooks:
    """What a glTF primitive's material says beyond one Blinn-Phong ``material`` per mesh.

    Per-point factors multiply their texture's sample: the base colour (RGB and alpha, alpha
    also by the vertex colours' ``vertex_alpha`` (v,) float32), ``emissive`` (RGB, the factor
    times KHR_materials_emissive_strength), ``transmission`` (R), ``metallic_roughness``
    (B metallic, G roughness), ``occlusion`` (R, blended toward 1 by ``occlusion_strength``)
    and the tangent-space ``normal`` map (scaled in x and y by ``normal_scale``), with
    ``tangents`` (4, v) float32 from the file (xyz and the bitangent's sign) or None.
    ``alpha_mode`` is "OPAQUE", "MASK" (cut out below ``alpha_cutoff``) or "BLEND";
    ``double_sided`` False hides the back of the surface.
    """

    material: Material
    base_color: TextureSlot | None = None
    base_color_factor: np.ndarray = field(default_factory=lambda: np.ones(4, np.float32))
    vertex_alpha: np.ndarray | None = None
    alpha_mode: str = "OPAQUE"
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    emissive: TextureSlot | None = None
    emissive_factor: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    transmission: TextureSlot | None = None
    transmission_factor: float = 0.0
    metallic_roughness: TextureSlot | None = None
    metallic_factor: float = 1.0
    roughness_factor: float = 1.0
    normal: TextureSlot | None = None
    normal_scale: float = 1.0
    occlusion: TextureSlot | None = None
    occlusion_strength: float = 1.0
    tangents: np.ndarray | None = None

    @property
    def per_point(self) -> bool:
        """Whether shading needs anything from it per hit besides the base colour."""
        return (
            self.alpha_mode == "BLEND"
            or self.emissive is not None
            or self.transmission is not None
            or self.metallic_roughness is not None
            or self.normal is not None
            or self.occlusion is not None
        )

    @property
    def has_alpha(self) -> bool:
        """Whether any point can be less than opaque (a cutout or a see-through blend)."""
        return self.alpha_mode in ("MASK", "BLEND")


class GltfDocument:
    """A glTF or GLB file's JSON and buffers (read as ``gltf.read_gltf`` and ``gltf.GltfBuffers``
    read them), its images decoded on demand."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.json, binary = read_gltf(path)
        self.buffers = GltfBuffers(path, self.json, binary)
        self._texels: dict[tuple[int, bool], np.ndarray | None] = {}

    def accessor(self, index: int) -> np.ndarray:
        """(count, components) values of accessor ``index`` (``gltf.accessor_array``, sparse
        entries applied): float32 for floats and normalised integers, the integer type
        otherwise."""
        values = accessor_array(self.json, self.buffers, index, normalized=True)
        return values.astype(np.float32) if values.dtype.kind == "f" else values

    def texels(self, image_index: int, srgb: bool) -> np.ndarray | None:
        """(h, w, 4) float32 texels of image ``image_index`` (decoded once per colour space);
        None for an image file that is not there (``gltf.prepare_gltf`` warned of it)."""
        key = (image_index, srgb)
        if key not in self._texels:
            from PIL import Image

            image = self.json["images"][image_index]
            blob = None
            if "bufferView" in image:
                view = self.json["bufferViews"][image["bufferView"]]
                start = view.get("byteOffset", 0)
                blob = self.buffers[view["buffer"]][start : start + view["byteLength"]]
            elif image["uri"].startswith("data:"):
                blob = base64.b64decode(image["uri"].split(",", 1)[1])
            elif (found := uri_path(self.path.parent, image["uri"])) is not None:
                blob = found.read_bytes()
            self._texels[key] = (
                None if blob is None else texels_from_image(Image.open(io.BytesIO(blob)), srgb)
            )
        return self._texels[key]


def _sampler(document: GltfDocument, texture: dict) -> Sampler:
    if "sampler" not in texture:
        return DEFAULT_SAMPLER
    sampler = document.json["samplers"][texture["sampler"]]
    wrap_s = sampler.get("wrapS", REPEAT)
    wrap_t = sampler.get("wrapT", REPEAT)
    return Sampler(
        wrap_s=wrap_s if wrap_s in WRAP_MODES else REPEAT,
        wrap_t=wrap_t if wrap_t in WRAP_MODES else REPEAT,
        nearest=sampler.get("magFilter") == NEAREST,
    )


def texture_transform_matrix(transform: dict) -> np.ndarray:
    """(3, 3) float64 matrix of a KHR_texture_transform: ``T(offset) · R(rotation) ·
    S(scale)`` acting on glTF's (u, v, 1) columns, the extension's own definition."""
    offset = transform.get("offset", (0.0, 0.0))
    angle = transform.get("rotation", 0.0)
    scale = transform.get("scale", (1.0, 1.0))
    c, s = math.cos(angle), math.sin(angle)
    translation = np.array([[1, 0, offset[0]], [0, 1, offset[1]], [0, 0, 1]], np.float64)
    rotation = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]], np.float64)
    scaling = np.diag([scale[0], scale[1], 1.0])
    return translation @ rotation @ scaling


class _PrimitiveReader:
    """Reads one triangle primitive's texture slots (its UV sets read once each)."""

    def __init__(self, document: GltfDocument, primitive: dict) -> None:
        self.document = document
        self.attributes = primitive.get("attributes", {})
        self._uv_sets: dict[int, np.ndarray | None] = {}

    def uv_set(self, index: int) -> np.ndarray | None:
        """(v, 2) float32 TEXCOORD_index in glTF's convention (v down), None if absent."""
        if index not in self._uv_sets:
            name = f"TEXCOORD_{index}"
            values = None
            if name in self.attributes:
                values = self.document.accessor(self.attributes[name])[:, :2]
            self._uv_sets[index] = values
        return self._uv_sets[index]

    def slot(self, info: dict | None, srgb: bool) -> TextureSlot | None:
        """The texture a material's textureInfo ``info`` names, or None (absent, its image
        file or its UV set missing: then the factor alone applies, as for no texture)."""
        if not info or "index" not in info:
            return None
        texture = self.document.json["textures"][info["index"]]
        if "source" not in texture:
            return None
        transform = info.get("extensions", {}).get("KHR_texture_transform", {})
        uv = self.uv_set(transform.get("texCoord", info.get("texCoord", 0)))
        if uv is None:
            return None
        if transform:
            matrix = texture_transform_matrix(transform)
            uv = uv.astype(np.float64) @ matrix[:2, :2].T + matrix[:2, 2]
        uv = np.nan_to_num(np.asarray(uv, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        # trimesh's convention, v up, computed as trimesh computes it (float32 1 − v).
        columns = np.empty((2, len(uv)), np.float32)
        columns[0] = uv[:, 0]
        columns[1] = np.float32(1.0) - uv[:, 1]
        texels = self.document.texels(texture["source"], srgb)
        if texels is None:
            return None
        return TextureSlot(texels, columns, _sampler(self.document, texture))


def metallic_roughness_material(color: RGB, metallic: float, roughness: float) -> Material:
    """A Blinn-Phong ``Material`` that looks like glTF's metallic-roughness surface.

    With smoothness ``s = 1 − roughness`` and ``m = metallic`` (both clipped to [0, 1]):

    - ``shininess = 2 / α² − 2`` with ``α = roughness²``, the Blinn-Phong exponent whose lobe
      matches a Beckmann/GGX lobe of width α (Walter et al. 2007), clipped to [1, 4096];
    - ``specular = s · (0.5 + 0.4 m)``: no highlight on a fully rough surface, 0.5 (the glossy
      preset) on a smooth dielectric, 0.9 (the metal preset) on a smooth metal;
    - ``reflectivity = s² · (0.04 (1 − m) + 0.9 m)``: a smooth dielectric mirrors about 4% of
      the scene, a smooth metal 90% (the mirror preset); roughness blurs a real reflection
      away, which a sharp mirror bounce can only fade;
    - ``diffuse = 0.85 · (1 − m · s)``: dielectrics keep the matte preset's diffuse, a smooth
      metal has none (its colour is in what it reflects), a rough metal scatters like a matte
      surface of its colour;
    - ``metallic`` is ``m >= 0.5`` (metals tint their reflections and highlights' bounce).
    """
    values = metallic_roughness_parameters(np.float64(metallic), np.float64(roughness))
    return Material(
        color=color,
        diffuse=float(values["diffuse"]),
        specular=float(values["specular"]),
        shininess=float(values["shininess"]),
        reflectivity=float(values["reflectivity"]),
        metallic=bool(values["metallic"]),
    )


def metallic_roughness_parameters(metallic: np.ndarray, roughness: np.ndarray) -> dict:
    """The Blinn-Phong parameters of ``metallic_roughness_material``'s mapping for float64
    ``metallic`` and ``roughness`` (any shape, e.g. (k,) per hit of a metallic-roughness
    texture): float64 arrays "diffuse", "specular", "shininess", "reflectivity" and bool
    "metallic", of that shape."""
    m = np.clip(metallic, 0.0, 1.0)
    roughness = np.clip(roughness, 0.0, 1.0)
    s = 1.0 - roughness
    alpha = roughness * roughness
    low, high = SHININESS_RANGE
    with np.errstate(divide="ignore"):
        shininess = np.where(alpha == 0.0, high, np.clip(2.0 / alpha**2 - 2.0, low, high))
    return {
        "diffuse": 0.85 * (1.0 - m * s),
        "specular": s * (0.5 + 0.4 * m),
        "shininess": shininess,
        "reflectivity": s * s * (DIELECTRIC_REFLECTIVITY * (1.0 - m) + METAL_REFLECTIVITY * m),
        "metallic": m >= 0.5,
    }


def material_from_gltf(material: dict) -> Material:
    """The Blinn-Phong ``Material`` of a glTF material (``metallic_roughness_material`` for its
    factors), with its emission (factor × strength),
    KHR_materials_transmission as transparency (its IOR from KHR_materials_ior, 1.5 when
    absent, the base colour its tint), KHR_materials_volume as Beer–Lambert absorption (none
    when thicknessFactor is 0: a thin wall) and KHR_materials_unlit."""
    pbr = material.get("pbrMetallicRoughness", {})
    extensions = material.get("extensions", {})
    color = tuple(float(c) for c in pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0))[:3])
    base = metallic_roughness_material(
        color, float(pbr.get("metallicFactor", 1.0)), float(pbr.get("roughnessFactor", 1.0))
    )
    strength = float(
        extensions.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    )
    emission = tuple(float(c) * strength for c in material.get("emissiveFactor", (0, 0, 0)))
    fields: dict = {"emission": emission}
    if "KHR_materials_unlit" in extensions:
        fields["unlit"] = True
    transmission = extensions.get("KHR_materials_transmission")
    if transmission is not None and transmission.get("transmissionFactor", 0.0) > 0.0:
        fields["transparency"] = float(np.clip(transmission["transmissionFactor"], 0.0, 1.0))
        fields["ior"] = max(
            1.0, float(extensions.get("KHR_materials_ior", {}).get("ior", DEFAULT_IOR))
        )
        volume = extensions.get("KHR_materials_volume", {})
        if volume.get("thicknessFactor", 0.0) > 0.0:
            fields["attenuation_color"] = tuple(
                float(np.clip(c, 0.0, 1.0)) for c in volume.get("attenuationColor", (1, 1, 1))
            )
            fields["attenuation_distance"] = float(volume.get("attenuationDistance", math.inf))
    return Material(**{**base.__dict__, **fields})


def primitive_looks(document: GltfDocument, primitive: dict, vertex_count: int) -> GltfLooks | None:
    """The ``GltfLooks`` of a triangle primitive with a material, or None without one."""
    if "material" not in primitive:
        return None
    material = document.json["materials"][primitive["material"]]
    reader = _PrimitiveReader(document, primitive)
    pbr = material.get("pbrMetallicRoughness", {})
    extensions = material.get("extensions", {})
    factor = np.asarray(pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0)), np.float32)
    alpha_mode = material.get("alphaMode", "OPAQUE")
    vertex_alpha = tangents = None
    if "COLOR_0" in reader.attributes and alpha_mode != "OPAQUE":
        colors = document.accessor(reader.attributes["COLOR_0"])
        if colors.shape[1] == 4 and (colors[:, 3] < 1).any():
            vertex_alpha = np.ascontiguousarray(colors[:, 3], np.float32)
    normal_info = material.get("normalTexture")
    normal = reader.slot(normal_info, srgb=False)
    if normal is not None and "TANGENT" in reader.attributes:
        tangents = np.ascontiguousarray(
            document.accessor(reader.attributes["TANGENT"]).T, np.float32
        )
    occlusion_info = material.get("occlusionTexture") or {}
    transmission = extensions.get("KHR_materials_transmission", {})
    strength = float(
        extensions.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    )
    looks = GltfLooks(
        material=material_from_gltf(material),
        base_color=reader.slot(pbr.get("baseColorTexture"), srgb=True),
        base_color_factor=factor,
        vertex_alpha=vertex_alpha,
        alpha_mode=alpha_mode if alpha_mode in ("MASK", "BLEND") else "OPAQUE",
        alpha_cutoff=float(material.get("alphaCutoff", 0.5)),
        double_sided=bool(material.get("doubleSided", False)),
        emissive=reader.slot(material.get("emissiveTexture"), srgb=True),
        emissive_factor=np.asarray(material.get("emissiveFactor", (0, 0, 0)), np.float32)
        * np.float32(strength),
        transmission=reader.slot(transmission.get("transmissionTexture"), srgb=False),
        transmission_factor=float(transmission.get("transmissionFactor", 0.0)),
        metallic_roughness=reader.slot(pbr.get("metallicRoughnessTexture"), srgb=False),
        metallic_factor=float(pbr.get("metallicFactor", 1.0)),
        roughness_factor=float(pbr.get("roughnessFactor", 1.0)),
        normal=normal,
        normal_scale=float((normal_info or {}).get("scale", 1.0)),
        occlusion=reader.slot(occlusion_info, srgb=False),
        occlusion_strength=float(occlusion_info.get("strength", 1.0)),
        tangents=tangents,
    )
    for slot in (
        looks.base_color,
        looks.emissive,
        looks.transmission,
        looks.metallic_roughness,
        looks.normal,
        looks.occlusion,
    ):
        if slot is not None and slot.uv.shape[1] != vertex_count:
            return None
    return looks


LOOKS_KEY = "gltf_looks"


def attach_gltf_looks(path: Path, meshes: list) -> None:
    """Read ``path``'s glTF materials and store each triangle primitive's ``GltfLooks`` in the
    ``metadata[LOOKS_KEY]`` of its trimesh mesh; ``meshes`` are trimesh's loaded geometries in
    its order (``trimesh.Scene.geometry``'s values). Warns in one line when the file's
    primitives cannot be matched to trimesh's meshes (the extensions it ignores are named by
    ``gltf.prepare_gltf``)."""
    document = GltfDocument(path)
    primitives = [
        primitive
        for mesh in document.json.get("meshes", [])
        for primitive in mesh.get("primitives", [])
        if primitive.get("mode", 4) in LOADED_MODES
    ]
    if len(primitives) != len(meshes):
        warn_input(
            f"{path}: {len(primitives)} glTF primitives for {len(meshes)} loaded "
            "meshes; emission, transmission, alpha, samplers, texture transforms not "
            "read"
        )
        return
    for primitive, mesh in zip(primitives, meshes, strict=True):
        if primitive.get("mode", 4) not in TRIANGLE_MODES:
            continue
        looks = primitive_looks(document, primitive, len(mesh.vertices))
        if looks is not None:
            mesh.metadata[LOOKS_KEY] = looks
