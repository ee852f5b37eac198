"""What a mesh hit's barycentrics give besides its position: the shading normal and the colour.

Embree reports a triangle hit as (face, u, v), the point ``(1 − u − v) p0 + u p1 + v p2``. Smooth
shading blends the corners' vertex normals with those weights; a textured or vertex-coloured
mesh blends its corners' UVs (then samples the texture) and vertex colours the same way.
Everything here works on whole batches of hits, in the mesh's own space.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np

from embree_rt.columns import scatter
from embree_rt.materials import HitMaterials
from embree_rt.scene.model import MeshObject
from embree_rt.textures import DEFAULT_SAMPLER, sample_texture

if TYPE_CHECKING:  # mesh import loads trimesh (~1 s): only scenes with meshes pay for it
    import trimesh

    from embree_rt.embree import GeometryFilter
    from embree_rt.scene.meshes import MeshSurface

# A vertex normal shorter than this has no direction to give: trimesh's average of the faces
# around a vertex cancels to zero (or to rounding residue, 1e-30) where back-to-back faces meet.
MIN_NORMAL_LENGTH = 1e-6
# A blend of unit normals shorter than this has cancelled (opposite normals across a crease).
MIN_BLEND_LENGTH = 1e-3


def unit_vertex_normals(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float32 unit vertex normals of (n, 3) ``normals`` and (n,) float32 1 where a
    vertex has no usable normal (shorter than ``MIN_NORMAL_LENGTH``, or not finite), 0 elsewhere;
    the normals of those vertices are zero."""
    normals = np.asarray(normals, np.float64).reshape(-1, 3)
    length = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    usable = np.isfinite(length) & (length >= MIN_NORMAL_LENGTH)
    unit = np.zeros_like(normals)
    unit[usable] = normals[usable] / length[usable, None]
    return unit.astype(np.float32), (~usable).astype(np.float32)


def blend_normals(
    vertex_normals: np.ndarray,
    missing: np.ndarray | None,
    corners: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    face_normals: np.ndarray,
    face: np.ndarray,
) -> np.ndarray:
    """(k, 3) float32 smooth shading normals (not unit length) of k triangle hits.

    ``vertex_normals`` (n, 3) float32 unit or zero and ``missing`` (n,) float32 from
    ``unit_vertex_normals`` (None: no vertex lacks a normal); ``corners`` (k, 3) vertex indices,
    ``u``, ``v`` (k,) Embree barycentrics; ``face_normals`` (f, 3) float32 unit geometric
    normals of the faces and ``face`` (k,) the face of each hit, gathered only where needed.
    A corner without a normal lends the face's normal instead, and where the blend cancels the
    face normal is used: the result is never zero, so no NaN can come of normalising it.
    """
    u = u[:, None]
    v = v[:, None]
    w = 1 - u - v
    blend = (
        w * vertex_normals[corners[:, 0]]
        + u * vertex_normals[corners[:, 1]]
        + v * vertex_normals[corners[:, 2]]
    )
    if missing is not None:
        lent = w[:, 0] * missing[corners[:, 0]] + u[:, 0] * missing[corners[:, 1]]
        lent += v[:, 0] * missing[corners[:, 2]]
        rows = np.flatnonzero(lent)
        if len(rows):
            blend[rows] += lent[rows, None] * face_normals[face[rows]]
    length2 = np.einsum("ij,ij->i", blend, blend)
    cancelled = np.flatnonzero(length2 < np.float32(MIN_BLEND_LENGTH**2))
    if len(cancelled):
        blend[cancelled] = face_normals[face[cancelled]]
    return blend


@dataclass
class HitLooks:
    """What k hits on meshes with per-point looks show, beyond one material per mesh: ``rows``
    (k,) int64 the hits' columns in their ``SurfaceHits``; ``color`` (3, k) float32 linear base
    colour; ``emission`` (3, k) float32 (None: the material's own); ``coverage`` (k,) float32
    alpha of see-through (BLEND) surfaces (None: opaque); ``normal`` (3, j) float32 unit
    shading normals a normal map gives, in the mesh's own space, of the hits at positions
    ``normal_at`` (j,) int64 among these (None: the usual normals); ``occlusion`` (k,) float32
    the share of ambient light that reaches each point (None: all); ``parameters`` the
    Blinn-Phong parameters that metallic-roughness and transmission textures vary
    (``TexturedParameters``), of the hits at positions ``parameters_at`` (j,) int64 among these
    (None: the materials'). ``uv`` (2, k) float32 the coordinates the base-colour texture is
    read at, inf at hits on a mesh without that texture (None: no hit is on one). ``NO_LOOKS``
    of hits that show nothing of their own has no rows."""

    rows: np.ndarray
    color: np.ndarray
    emission: np.ndarray | None = None
    coverage: np.ndarray | None = None
    normal: np.ndarray | None = None
    normal_at: np.ndarray | None = None
    occlusion: np.ndarray | None = None
    parameters: TexturedParameters | None = None
    parameters_at: np.ndarray | None = None
    uv: np.ndarray | None = None

    def apply_to(self, hits: HitMaterials, glows: bool) -> None:
        """Write what these hits show of their own over the columns of ``hits`` (the
        ``HitMaterials`` of every hit, these at ``rows``): colour, textured parameters,
        occlusion, coverage and, when some material ``glows`` (else nothing glows), emission."""
        if len(self.rows) == 0:
            return
        scatter(hits.color, self.rows, self.color)
        if self.parameters is not None:
            hits.vary(self.rows[self.parameters_at], self.parameters)
        if self.emission is not None and glows:
            scatter(hits.emission, self.rows, self.emission)
        if self.occlusion is not None:
            hits.occlusion = np.array(hits.occlusion)
            hits.occlusion[self.rows] = self.occlusion
        if self.coverage is not None:
            hits.coverage = np.array(hits.coverage)
            hits.coverage[self.rows] = self.coverage


@dataclass
class TexturedParameters:
    """The Blinn-Phong parameters of j hits that metallic-roughness and transmission textures
    vary, named as ``HitMaterials``' columns: ``diffuse``, ``specular``, ``shininess``,
    ``reflectivity``, ``transparency`` (j,) float32 and ``metallic`` (j,) bool."""

    diffuse: np.ndarray
    specular: np.ndarray
    shininess: np.ndarray
    reflectivity: np.ndarray
    transparency: np.ndarray
    metallic: np.ndarray


def no_looks() -> HitLooks:
    """The ``HitLooks`` of hits that show nothing of their own: no rows."""
    return HitLooks(np.zeros(0, np.int64), np.zeros((3, 0), np.float32))


def surface_looks(
    surface: MeshSurface,
    faces: np.ndarray,
    face: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    frame: TangentFrame | None = None,
) -> HitLooks:
    """The looks of k hits on a mesh with per-point looks (``rows`` left empty); ``frame``
    the tangent frame its normal map, if any, is read in (``tangent_frame``).

    ``faces`` (f, 3) int64 the mesh's triangles; ``face`` (k,) the triangle each hit is on and
    ``u``, ``v`` (k,) float32 its Embree barycentrics.
    """
    corners = np.take(faces, face, axis=0)
    w = np.float32(1.0) - u - v

    def blend(columns: np.ndarray) -> np.ndarray:
        """(c, k) per-vertex ``columns`` (c, n) blended at the hits."""
        out = np.take(columns, corners[:, 0], axis=1) * w
        out += np.take(columns, corners[:, 1], axis=1) * u
        out += np.take(columns, corners[:, 2], axis=1) * v
        return out

    looks = surface.looks
    color = np.empty((3, len(face)), np.float32)
    color[:] = surface.factor[:, None]
    alpha = uv = None
    if surface.texels is not None:
        uv = blend(surface.uv)
        sample = sample_texture(surface.texels, uv, surface.sampler)
        color *= sample[:3]
        alpha = sample[3]
    if surface.vertex_colors is not None:
        color *= blend(surface.vertex_colors)
    if surface.face_colors is not None:
        color *= np.take(surface.face_colors, face, axis=1)
    result = HitLooks(np.zeros(0, np.int64), color, uv=uv)
    if looks is None:
        return result
    if looks.alpha_mode == "BLEND":
        coverage = np.full(len(face), looks.base_color_factor[3], np.float32)
        if alpha is not None:
            coverage *= alpha
        if looks.vertex_alpha is not None:
            coverage *= blend(looks.vertex_alpha[None, :])[0]
        result.coverage = np.clip(coverage, np.float32(0.0), np.float32(1.0))
    if looks.emissive is not None:
        slot = looks.emissive
        result.emission = sample_texture(slot.texels, blend(slot.uv), slot.sampler)[:3]
        result.emission *= looks.emissive_factor[:, None]
    if looks.occlusion is not None:
        slot = looks.occlusion
        sample = sample_texture(slot.texels, blend(slot.uv), slot.sampler)[0]
        result.occlusion = np.float32(1.0) + np.float32(looks.occlusion_strength) * (
            np.clip(sample, np.float32(0.0), np.float32(1.0)) - np.float32(1.0)
        )
    if (looks.metallic_roughness is not None or looks.transmission is not None) and not (
        looks.material.unlit
    ):
        result.parameters = textured_parameters(looks, blend)
        result.parameters_at = np.arange(len(face))
    if looks.normal is not None and frame is not None:
        slot = looks.normal
        sample = sample_texture(slot.texels, blend(slot.uv), slot.sampler)[:3]
        result.normal = mapped_normals(sample, looks.normal_scale, frame, face, blend)
        result.normal_at = np.arange(len(face))
    return result


def textured_parameters(looks, blend) -> TexturedParameters:
    """The per-hit parameters (``HitLooks.parameters``) of hits on a glTF surface whose
    metallic-roughness texture (B metallic, G roughness, times the factors) or transmission
    texture (R, times the factor) varies them: the material mapping's own rule
    (``metallic_roughness_parameters``), per hit."""
    from embree_rt.scene.gltf_materials import metallic_roughness_parameters

    material = looks.material
    slot = looks.metallic_roughness
    if slot is not None:
        sample = sample_texture(slot.texels, blend(slot.uv), slot.sampler).astype(np.float64)
        values = metallic_roughness_parameters(
            looks.metallic_factor * sample[2], looks.roughness_factor * sample[1]
        )
    else:
        count = blend(looks.transmission.uv).shape[1]
        names = ("diffuse", "specular", "shininess", "reflectivity", "metallic")
        values = {name: np.full(count, getattr(material, name)) for name in names}
    transparency = np.full(len(values["diffuse"]), material.transparency, np.float32)
    if looks.transmission is not None:
        slot = looks.transmission
        sample = sample_texture(slot.texels, blend(slot.uv), slot.sampler)[0]
        transparency = np.clip(np.float32(looks.transmission_factor) * sample, 0.0, 1.0)
    return TexturedParameters(
        **{
            name: np.asarray(values[name], np.float32)
            for name in ("diffuse", "specular", "shininess", "reflectivity")
        },
        transparency=transparency.astype(np.float32),
        metallic=np.asarray(values["metallic"], bool),
    )


def mapped_normals(sample, scale: float, frame, face: np.ndarray, blend) -> np.ndarray:
    """(3, k) float32 unit normals, in the mesh's space, of k hits whose normal map reads
    ``sample`` (3, k) (codes / 255: the map's tangent-space normal is 2·sample − 1, its x and y
    times ``scale``, glTF's normalTexture.scale), in the hits' tangent ``frame``
    (``TangentFrame``): ``normalize(x T + y B + z N)`` with N the
    blended vertex normal, T the tangent made perpendicular to N and B = ±N × T, its sign the
    file's (tangent w) or that of the UVs' own bitangent (mirrored UVs flip it). ``blend``
    blends per-vertex columns at the hits."""
    mapped = np.float32(2.0) * sample - np.float32(1.0)
    mapped[:2] *= np.float32(scale)
    normal = _unit_columns(blend(frame.vertex_normals))
    if frame.tangents is not None:
        tangent = blend(frame.tangents[:3])
        sign = np.where(blend(frame.tangents[3:])[0] < 0, np.float32(-1.0), np.float32(1.0))
    else:
        tangent = np.take(frame.face_tangents, face, axis=1)
        bitangent = np.take(frame.face_bitangents, face, axis=1)
        sign = np.where(
            _dot(np.cross(normal.T, tangent.T).T, bitangent) < 0, np.float32(-1.0), np.float32(1.0)
        )
    tangent = _unit_columns(tangent - _dot(tangent, normal) * normal)
    bitangent = sign * np.cross(normal.T, tangent.T).T
    return _unit_columns(mapped[0] * tangent + mapped[1] * bitangent + mapped[2] * normal)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _unit_columns(vectors: np.ndarray) -> np.ndarray:
    """(3, k) float32 unit columns of (3, k) ``vectors`` (zero columns stay zero)."""
    vectors = np.asarray(vectors, np.float32)
    length = np.sqrt(_dot(vectors, vectors))
    return vectors / np.maximum(length, np.float32(1e-30))


@dataclass(frozen=True)
class TangentFrame:
    """Where a tangent-space normal map points, in the mesh's own space: ``vertex_normals``
    (3, v) float32 unit, and either the file's ``tangents`` (4, v) float32 (xyz, and w the
    sign of the bitangent N × T) or ``face_tangents``, ``face_bitangents`` (3, f) float32, the
    directions of increasing u and v (v up) across each triangle, derived from its UVs."""

    vertex_normals: np.ndarray
    tangents: np.ndarray | None = None
    face_tangents: np.ndarray | None = None
    face_bitangents: np.ndarray | None = None


def tangent_frame(
    mesh: trimesh.Trimesh, uv: np.ndarray, tangents: np.ndarray | None
) -> TangentFrame:
    """The ``TangentFrame`` of ``mesh`` for a normal map read through ``uv`` (2, v) (v up):
    the file's tangents when it has them (glTF's TANGENT), else per triangle the solution of
    ``p1 − p0 = Δu1 T + Δv1 B``, ``p2 − p0 = Δu2 T + Δv2 B`` (a triangle whose UVs have no
    area gets any tangent perpendicular to its normal)."""
    normals, _ = unit_vertex_normals(mesh.vertex_normals)
    normals = np.ascontiguousarray(normals.T)
    if tangents is not None and tangents.shape == (4, len(mesh.vertices)):
        return TangentFrame(normals, tangents=tangents)
    faces = np.asarray(mesh.faces)
    points = np.asarray(mesh.vertices, np.float64)[faces]  # (f, 3 corners, 3)
    corner_uv = np.asarray(uv, np.float64).T[faces]  # (f, 3 corners, 2)
    e1, e2 = points[:, 1] - points[:, 0], points[:, 2] - points[:, 0]
    d1, d2 = corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    flat = np.abs(det) < 1e-20
    det = np.where(flat, 1.0, det)[:, None]
    tangent = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det
    bitangent = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / det
    if flat.any():  # any frame in the plane of the triangle
        normal = np.asarray(mesh.face_normals, np.float64)[flat]
        helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        tangent[flat] = np.cross(helper, normal)
        bitangent[flat] = np.cross(normal, tangent[flat])
    return TangentFrame(
        normals, face_tangents=_columns(tangent), face_bitangents=_columns(bitangent)
    )


def _columns(rows: np.ndarray) -> np.ndarray:
    """(3, n) float32 C-contiguous columns of (n, 3) ``rows``."""
    return np.ascontiguousarray(rows.T, np.float32)


def is_closed(mesh: trimesh.Trimesh) -> bool:
    """Whether ``mesh`` is a closed surface once its vertices are merged by position (glTF
    splits vertices along UV and normal seams, which leaves a closed model looking open)."""
    merged = mesh.copy()
    merged.merge_vertices(merge_tex=True, merge_norm=True)
    return bool(merged.is_watertight)


def mesh_hit_filter(mesh: trimesh.Trimesh) -> GeometryFilter | None:
    """The Embree hit filter a mesh's glTF material asks for (``alpha_filter``): cutouts where
    its alpha is low (MASK, BLEND) and, unless it is double-sided, no back. None for every
    other mesh, so that they trace at no extra cost: glass (a refracted ray must leave through
    the back of the surface) and closed surfaces (``is_closed``: their backs face inward, seen
    from outside only through a hole that is not there) are never one-sided."""
    # Here, not at the top: the glTF reader (~40 kB of source, ~12 ms to import) is for meshes.
    from embree_rt.scene.gltf_materials import LOOKS_KEY

    looks = mesh.metadata.get(LOOKS_KEY)
    if looks is None:
        return None
    one_sided = not looks.double_sided and not looks.material.is_glass
    if one_sided and not looks.has_alpha and is_closed(mesh):
        return None
    from embree_rt.tracing.alpha_filter import triangle_filter

    base = looks.base_color
    return triangle_filter(
        np.asarray(mesh.faces),
        one_sided=one_sided and not is_closed(mesh),
        alpha_mode=looks.alpha_mode,
        cutoff=looks.alpha_cutoff,
        alpha=float(looks.base_color_factor[3]),
        uv=None if base is None else base.uv,
        texels=None if base is None else base.texels,
        wrap=(DEFAULT_SAMPLER if base is None else base.sampler).wrap_s_t,
        nearest=base is not None and base.sampler.nearest,
        vertex_alpha=looks.vertex_alpha,
    )


class MeshColors:
    """The per-hit colours of the mesh placements that show their own (``mesh_colors``):
    each distinct mesh's surface decoded once, looked up by top-level instance geometry id.

    False (``bool()``) when no placement has per-point colours: then nothing is done per hit.
    """

    def __init__(self, placements: list[MeshObject], geom_ids: list[int]) -> None:
        """``placements`` and the instance geometry id each was given, in the same order."""
        self._surfaces: list[tuple[MeshSurface, np.ndarray, TangentFrame | None]] = []
        index_of_mesh: dict[int, int] = {}
        instance_surface: dict[int, int] = {}
        for placement, geom_id in zip(placements, geom_ids, strict=True):
            if not placement.mesh_colors:
                continue
            key = id(placement.mesh)
            if key not in index_of_mesh:
                from embree_rt.scene.meshes import mesh_surface  # loads trimesh: meshes only

                surface = mesh_surface(placement.mesh)
                index_of_mesh[key] = len(self._surfaces) if surface is not None else -1
                if surface is not None:
                    faces = np.asarray(placement.mesh.faces, np.int64)
                    looks = surface.looks
                    frame = None
                    if looks is not None and looks.normal is not None:
                        frame = tangent_frame(placement.mesh, looks.normal.uv, looks.tangents)
                    self._surfaces.append((surface, faces, frame))
            if index_of_mesh[key] >= 0:
                instance_surface[geom_id] = index_of_mesh[key]
        # Per instance geometry id: index into _surfaces, -1 for a placement without colours.
        size = max(instance_surface, default=-1) + 1
        self._instance_surface = np.full(size, -1, np.int64)
        for geom_id, index in instance_surface.items():
            self._instance_surface[geom_id] = index

    def __bool__(self) -> bool:
        return len(self._instance_surface) > 0

    def hit_looks(
        self, inst: np.ndarray, prim: np.ndarray, u: np.ndarray, v: np.ndarray, first_row: int
    ) -> HitLooks | None:
        """For k instance hits (``inst`` (k,) instance geometry ids, ``prim`` (k,) triangles,
        ``u``, ``v`` (k,) float32 barycentrics): the looks of the hits that have their own,
        their ``rows`` being ``first_row + i``; None when no hit has."""
        table = self._instance_surface
        known = inst < len(table)
        which = np.where(known, np.take(table, np.minimum(inst, len(table) - 1)), -1)
        painted = np.flatnonzero(which >= 0)
        if len(painted) == 0:
            return None
        surface_of_hit = which[painted]
        parts = []
        for index in np.unique(surface_of_hit):
            surface, faces, frame = self._surfaces[index]
            mine = np.flatnonzero(surface_of_hit == index) if len(self._surfaces) > 1 else None
            rows = painted if mine is None else painted[mine]
            part = surface_looks(surface, faces, prim[rows], u[rows], v[rows], frame)
            part.rows = np.arange(len(painted)) if mine is None else mine
            parts.append((part, surface))
        if len(parts) > 1 and any(part.emission is not None for part, _ in parts):
            for part, surface in parts:  # the others glow as their material says
                if part.emission is None:
                    own = (0.0,) * 3 if surface.looks is None else surface.looks.material.emission
                    part.emission = np.empty((3, len(part.rows)), np.float32)
                    part.emission[:] = np.asarray(own, np.float32)[:, None]
        parts = [part for part, _ in parts]
        looks = parts[0] if len(parts) == 1 else _gather_looks(parts, len(painted))
        looks.rows = painted + first_row
        return looks


def _gather_looks(parts: list[HitLooks], count: int) -> HitLooks:
    """One ``HitLooks`` of ``count`` hits from parts whose ``rows`` say where each goes; a
    coverage or occlusion some part lacks is 1 there; emission is given by all parts or none;
    normals only where a part has them."""
    color = np.empty((3, count), np.float32)
    for part in parts:
        scatter(color, part.rows, part.color)
    looks = HitLooks(np.zeros(0, np.int64), color)
    if parts[0].emission is not None:
        looks.emission = np.empty((3, count), np.float32)
        for part in parts:
            scatter(looks.emission, part.rows, part.emission)
    normals = [part for part in parts if part.normal is not None]
    if normals:
        looks.normal = np.concatenate([part.normal for part in normals], axis=1)
        looks.normal_at = np.concatenate([part.rows[part.normal_at] for part in normals])
    varied = [part for part in parts if part.parameters is not None]
    if varied:
        looks.parameters = TexturedParameters(
            **{
                item.name: np.concatenate([getattr(part.parameters, item.name) for part in varied])
                for item in fields(TexturedParameters)
            }
        )
        looks.parameters_at = np.concatenate([part.rows[part.parameters_at] for part in varied])
    if any(part.occlusion is not None for part in parts):
        looks.occlusion = np.ones(count, np.float32)
        for part in parts:
            if part.occlusion is not None:
                looks.occlusion[part.rows] = part.occlusion
    if any(part.uv is not None for part in parts):
        looks.uv = np.full((2, count), np.inf, np.float32)
        for part in parts:
            if part.uv is not None:
                scatter(looks.uv, part.rows, part.uv)
    if any(part.coverage is not None for part in parts):
        looks.coverage = np.ones(count, np.float32)
        for part in parts:
            if part.coverage is not None:
                looks.coverage[part.rows] = part.coverage
    return looks
