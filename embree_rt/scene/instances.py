"""Meshes placed by the thousand: one mesh, n placements, rendered through one Embree instance
array (``BVH.add_instances``), so a million copies cost 48 bytes of transform each and the
mesh's triangles once.

A placements file (``.npz``, read with ``allow_pickle=False``) holds either ``transforms``
(n, 4, 4), or ``positions`` (n, 3) with optional ``rotations`` (n, 3) in degrees (about X, then
Y, then Z, as a ``[[meshes]]`` entry's ``rotate``) and ``scales`` (n,) or (n, 3) (> 0); and
optionally ``materials`` (n,) names or ids, as a ``[[sphere_arrays]]`` file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from embree_rt.scene.archives import read_archive
from embree_rt.transforms import affine_array_problem

if TYPE_CHECKING:
    import trimesh


@dataclass
class MeshInstances:
    """n placements of one mesh.

    ``transforms`` (n, 4, 4) float64 affine, mesh space to world; ``materials`` (n,) int32
    indices into the scene's ``material_names``; ``smooth``: interpolate vertex normals;
    ``mesh_colors``: the hits take the mesh's own per-point colours (texture, vertex or face
    colours) in place of the material's colour, as a ``MeshObject``'s do.
    """

    mesh: trimesh.Trimesh
    transforms: np.ndarray
    materials: np.ndarray
    smooth: bool = True
    mesh_colors: bool = False

    def __len__(self) -> int:
        return len(self.transforms)


def euler_xyz_matrices(degrees: np.ndarray) -> np.ndarray:
    """(n, 3, 3) float64 rotations Rz @ Ry @ Rx for (n, 3) angles in degrees about X, Y, Z
    (static axes: the ``rotate`` convention of scene files)."""
    x, y, z = np.radians(np.asarray(degrees, np.float64)).T
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rotation = np.empty((len(x), 3, 3))
    rotation[:, 0] = np.stack([cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx], axis=1)
    rotation[:, 1] = np.stack([sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx], axis=1)
    rotation[:, 2] = np.stack([-sy, cy * sx, cy * cx], axis=1)
    return rotation


def placement_matrices(
    positions: np.ndarray, rotations: np.ndarray | None = None, scales: np.ndarray | None = None
) -> np.ndarray:
    """(n, 4, 4) float64 placements: scale, then rotate (``euler_xyz_matrices``), then move to
    ``positions`` (n, 3); ``rotations`` (n, 3) degrees, ``scales`` (n,) or (n, 3)."""
    positions = np.asarray(positions, np.float64)
    n = len(positions)
    matrices = np.zeros((n, 4, 4))
    linear = (
        np.broadcast_to(np.eye(3), (n, 3, 3))
        if rotations is None
        else (euler_xyz_matrices(rotations))
    )
    if scales is not None:
        scales = np.asarray(scales, np.float64)
        linear = linear * (scales[:, None, None] if scales.ndim == 1 else scales[:, None, :])
    matrices[:, :3, :3] = linear
    matrices[:, :3, 3] = positions
    matrices[:, 3, 3] = 1.0
    return matrices


def read_placements(
    path: Path, fail: Callable[[str], Exception], material_problem: Callable
) -> tuple[np.ndarray, np.ndarray | None]:
    """The (n, 4, 4) float64 placements of the file at ``path`` and its (n,) materials (names
    or ids, checked by ``material_problem(materials, n)``, which returns a problem or None),
    or None. Every problem is raised as ``fail("problem")``: the file is checked in full
    before anything is built from it."""
    arrays = read_archive(path, fail)
    known = {"transforms", "positions", "rotations", "scales", "materials"}
    if unknown := sorted(set(arrays) - known):
        raise fail(f"unknown array {unknown[0]!r} (known: {', '.join(sorted(known))})")
    if "transforms" in arrays:
        if given := sorted({"positions", "rotations", "scales"} & set(arrays)):
            raise fail(
                f"give either transforms or positions/rotations/scales, not {given[0]!r} too"
            )
        matrices = arrays["transforms"]
        if matrices.ndim != 3 or matrices.shape[1:] != (4, 4) or matrices.dtype.kind not in "fiu":
            raise fail(
                f"transforms must be (n, 4, 4) numbers, got {matrices.shape} {matrices.dtype}"
            )
        name = "transforms"
    elif "positions" in arrays:
        matrices = _matrices_from_parts(arrays, fail)
        name = "positions/rotations/scales"
    else:
        raise fail(
            f"expected an array 'transforms' or 'positions' (has: {', '.join(arrays) or 'none'})"
        )
    if len(matrices) == 0:
        raise fail(f"{name}: no placements")
    if (problem := affine_array_problem(matrices)) is not None:
        row, text = problem
        raise fail(f"{name} row {row}: {text}")
    matrices = np.asarray(matrices, np.float64)
    materials = arrays.get("materials")
    if materials is not None:
        if materials.dtype.kind == "S":
            materials = materials.astype(str)
        if (problem := material_problem(materials, len(matrices))) is not None:
            raise fail(problem)
    return matrices, materials


def _matrices_from_parts(arrays: dict, fail: Callable[[str], Exception]) -> np.ndarray:
    positions = arrays["positions"]
    if positions.ndim != 2 or positions.shape[1] != 3 or positions.dtype.kind not in "fiu":
        raise fail(f"positions must be (n, 3) numbers, got {positions.shape} {positions.dtype}")
    n = len(positions)
    if not np.isfinite(positions).all():
        raise fail(f"positions row {_first(~np.isfinite(positions).all(axis=1))} is not finite")
    rotations = arrays.get("rotations")
    if rotations is not None:
        if rotations.shape != (n, 3) or rotations.dtype.kind not in "fiu":
            raise fail(
                f"rotations must be ({n}, 3) degrees, got {rotations.shape} {rotations.dtype}"
            )
        if not np.isfinite(rotations).all():
            raise fail(f"rotations row {_first(~np.isfinite(rotations).all(axis=1))} is not finite")
    scales = arrays.get("scales")
    if scales is not None:
        if scales.shape not in ((n,), (n, 3)) or scales.dtype.kind not in "fiu":
            raise fail(
                f"scales must be ({n},) or ({n}, 3) numbers, got {scales.shape} {scales.dtype}"
            )
        bad = ~(np.isfinite(scales) & (scales > 0))
        if bad.any():
            row = _first(bad if bad.ndim == 1 else bad.any(axis=1))
            raise fail(f"scales row {row} must be finite and > 0, got {scales[row].tolist()}")
    return placement_matrices(positions, rotations, scales)


def _first(bad: np.ndarray) -> int:
    return int(np.flatnonzero(bad)[0])


def single_mesh(mesh: trimesh.Trimesh | trimesh.Scene) -> trimesh.Trimesh:
    """``mesh`` as one Trimesh: a trimesh.Scene's nodes (``meshes.mesh_parts``) baked at their
    node transforms and concatenated (one child for an instance array). Raises ValueError if
    it holds no triangles."""
    from embree_rt.scene.meshes import mesh_parts

    parts = mesh_parts(mesh)
    if not parts:
        raise ValueError(f"mesh: the {type(mesh).__name__} holds no triangles")
    return mesh_from_parts(parts)


def mesh_from_parts(parts: list[tuple[trimesh.Trimesh, np.ndarray]]) -> trimesh.Trimesh:
    """One Trimesh from (mesh, (4, 4) node transform) parts (at least one): the mesh itself
    for a single part in place, else the parts baked at their transforms and concatenated."""
    import trimesh

    if len(parts) == 1 and np.array_equal(parts[0][1], np.eye(4)):
        return parts[0][0]
    baked = []
    for part, transform in parts:
        copy = part.copy()
        copy.apply_transform(transform)
        baked.append(copy)
    return trimesh.util.concatenate(baked)


def bounding_ball(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (3,) float64 and radius of a ball holding all (m, 3) ``vertices``: centred on
    their bounding box, as large as the farthest vertex from there."""
    vertices = np.asarray(vertices, np.float64)
    center = (vertices.min(axis=0) + vertices.max(axis=0)) / 2.0
    return center, float(np.linalg.norm(vertices - center, axis=1).max())


def spheres_to_instances(scene, mesh: trimesh.Trimesh, keep: int, seed: int) -> MeshInstances:
    """Replace every sphere of ``scene`` after the first ``keep`` by a copy of ``mesh``, fitted
    into the sphere's ball, resting where the sphere rests (its lowest point at the sphere's
    bottom), turned about y by a random angle (drawn from ``seed``), in the sphere's material;
    returns the ``MeshInstances`` added (the n replaced spheres are removed).

    The placements are (n, 4, 4) float64: 128 bytes each while they are made, 48 in Embree."""
    centers = scene.sphere_centers[keep:]
    radii = scene.sphere_radii[keep:]
    n = len(radii)
    ball_center, ball_radius = bounding_ball(mesh.vertices)
    if not ball_radius > 0.0:
        raise ValueError("mesh: all its vertices are one point")
    lowest = float(np.asarray(mesh.vertices)[:, 1].min())
    angle = np.random.default_rng([seed, 12]).uniform(0.0, 2.0 * np.pi, n)  # its own stream
    scale = radii / np.float64(ball_radius)
    cos = np.cos(angle)
    cos *= scale
    sin = np.sin(angle)
    sin *= scale
    del angle
    transforms = np.zeros((n, 4, 4))
    transforms[:, 0, 0] = cos
    transforms[:, 0, 2] = sin
    transforms[:, 1, 1] = scale
    transforms[:, 2, 0] = -sin
    transforms[:, 2, 2] = cos
    transforms[:, 3, 3] = 1.0
    # world = s R (v - c) + q: q over the sphere's centre, low enough for the mesh's lowest
    # point to touch the sphere's bottom (a turn about y leaves heights alone)
    cx, cy, cz = ball_center
    transforms[:, 0, 3] = centers[:, 0] - (cos * cx + sin * cz)
    transforms[:, 1, 3] = (centers[:, 1] - radii) - scale * (lowest - cy) - scale * cy
    transforms[:, 2, 3] = centers[:, 2] - (cos * cz - sin * cx)
    materials = np.array(scene.sphere_materials[keep:], np.int32)
    scene.sphere_centers = scene.sphere_centers[:keep].copy()
    scene.sphere_radii = scene.sphere_radii[:keep].copy()
    scene.sphere_materials = scene.sphere_materials[:keep].copy()
    added = MeshInstances(mesh=mesh, transforms=transforms, materials=materials)
    scene.instances.append(added)
    return added
