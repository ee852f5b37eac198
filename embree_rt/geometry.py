"""Scene geometry: every object of a ``Scene`` in one Embree BVH, and what each hit is.

Spheres go in as analytic Embree spheres, or (``spheres="mesh"``) as one tessellated icosphere
instanced per sphere. Each distinct triangle mesh is built once and instanced per placement.
The floor is an analytic plane intersected in NumPy: exact at any distance, where a finite quad
in the BVH would cut the horizon and lose float32 precision far away.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from embree_rt.embree import BVH
from embree_rt.materials import MaterialTable
from embree_rt.mesh_attributes import MeshColors, blend_normals, unit_vertex_normals
from embree_rt.scene.model import Scene

SPHERE_MODES = ("analytic", "mesh")
ICOSPHERE_SUBDIVISIONS = 3


@dataclass
class SurfaceHits:
    """What n rays hit, one ray per column.

    ``hit`` (n,) bool; ``t`` (n,) float32 (inf on a miss); ``position`` (3, n) float32;
    ``normal`` (3, n) float32 unit shading normal and ``face_normal`` (3, n) float32 unit
    geometric normal, both pointing out of the object (+y for the floor), whichever side the ray
    came from (the same array when they agree everywhere); ``material`` (n,) intp material id
    (the floor's is ``floor_material``); ``floor`` (n,) bool, the rays that hit the floor;
    ``scale`` (n,) float32, a bound on the size of the coordinates the hit was computed from
    (at least max |position|, and the object's |centre| + extent): its rounding error scales
    with it; ``incoming`` (3, n) float32, the direction of the ray that made the hit.
    ``colored`` (j,) int64 columns whose base colour is the surface's own (a mesh's texture or
    vertex colours), ``color`` (3, j) float32 linear those colours; both None when none is.
    """

    hit: np.ndarray
    t: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    face_normal: np.ndarray
    material: np.ndarray
    floor: np.ndarray
    scale: np.ndarray
    incoming: np.ndarray
    colored: np.ndarray | None = None
    color: np.ndarray | None = None


def _unit(vectors: np.ndarray) -> np.ndarray:
    """(3, n) float32 unit vectors along the columns of (3, n) ``vectors``."""
    x, y, z = vectors
    length = np.sqrt(x * x + y * y + z * z)
    return (vectors / np.maximum(length, np.float32(1e-30))).astype(np.float32, copy=False)


def _no_hits() -> SurfaceHits:
    vectors = np.zeros((3, 0), np.float32)
    return SurfaceHits(
        hit=np.zeros(0, bool), t=np.zeros(0, np.float32), position=vectors, normal=vectors,
        face_normal=vectors, material=np.zeros(0, np.intp), floor=np.zeros(0, bool),
        scale=np.zeros(0, np.float32), incoming=vectors,
    )  # fmt: skip


def _largest_magnitude(vectors: np.ndarray) -> np.ndarray:
    """(n,) largest |component| of each column of (3, n) ``vectors``."""
    x, y, z = np.abs(vectors)
    return np.maximum(np.maximum(x, y), z)


class SceneGeometry:
    """The BVH of a scene plus the tables that turn Embree's ids into shading inputs."""

    def __init__(self, scene: Scene, spheres: str = "analytic", threads: int | None = None):
        if spheres not in SPHERE_MODES:
            raise ValueError(f"spheres: expected one of {SPHERE_MODES}, got {spheres!r}")
        self.bvh = BVH(threads=threads)
        self._children: list[BVH] = []
        self.sphere_centers = np.asarray(scene.sphere_centers, np.float32)
        self.sphere_radii = np.asarray(scene.sphere_radii, np.float32)
        self.sphere_materials = np.asarray(scene.sphere_materials, np.intp)
        self.sphere_centers_by_column = np.ascontiguousarray(self.sphere_centers.T)
        self.sphere_geom_id = -1
        self.sphere_scale = (
            np.abs(self.sphere_centers).max(axis=1) + self.sphere_radii
            if len(self.sphere_radii)
            else np.zeros(0, np.float32)
        ).astype(np.float32)
        self.floor = scene.floor
        self.floor_material = len(scene.materials)
        self.materials = MaterialTable.from_materials(
            [*scene.materials.values(), *([scene.floor.material] if scene.floor else [])]
        )
        # Per top-level instance geometry id: which child mesh, material, shading mode.
        self._instance_child: list[int] = []
        self._instance_material: list[int] = []
        self._instance_smooth: list[bool] = []
        self._instance_geom_ids: list[int] = []
        self._instance_normal_matrix: list[np.ndarray] = []
        self._instance_scale: list[float] = []
        self._mesh_bounds: list[np.ndarray] = []
        self._mesh_face_offset: list[int] = []
        self._mesh_vertex_normals: list[np.ndarray] = []
        self._mesh_missing_normals: list[np.ndarray] = []
        self._mesh_faces: list[np.ndarray] = []
        self._mesh_face_normals: list[np.ndarray] = []
        self.triangle_count = 0
        self.instance_count = 0
        try:
            if len(self.sphere_radii):
                if spheres == "analytic":
                    self.sphere_geom_id = self.bvh.add_spheres(
                        self.sphere_centers, self.sphere_radii
                    )
                else:
                    self._add_tessellated_spheres()
            self._add_meshes(scene)
            self.bvh.commit()
            self._finish_tables()
        except BaseException:
            self.close()
            raise

    # -- building -----------------------------------------------------------------------------

    def _child(self, mesh: trimesh.Trimesh) -> int:
        child = BVH(threads=self.bvh.threads)
        self._children.append(child)
        child.add_triangles(mesh.vertices, mesh.faces)
        child.commit()
        self._mesh_face_offset.append(sum(len(f) for f in self._mesh_faces))
        self._mesh_faces.append(np.asarray(mesh.faces, np.int64))
        vertex_normals, missing_normals = unit_vertex_normals(mesh.vertex_normals)
        self._mesh_vertex_normals.append(vertex_normals)
        self._mesh_missing_normals.append(missing_normals)
        self._mesh_face_normals.append(np.asarray(mesh.face_normals, np.float32))
        self._mesh_bounds.append(np.asarray(mesh.bounds, np.float64))
        return len(self._children) - 1

    def _place(self, child: int, transform: np.ndarray, material: int, smooth: bool) -> None:
        geom_id = self.bvh.add_instance(self._children[child], transform)
        self._instance_geom_ids.append(geom_id)
        self._instance_child.append(child)
        self._instance_material.append(material)
        self._instance_smooth.append(smooth)
        self._instance_normal_matrix.append(np.linalg.inv(transform[:3, :3]).T)
        low, high = self._mesh_bounds[child]
        corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                            for z in (low[2], high[2])])  # fmt: skip
        world = corners @ transform[:3, :3].T + transform[:3, 3]
        self._instance_scale.append(float(np.abs(world).max()))
        self.triangle_count += len(self._mesh_faces[child])
        self.instance_count += 1

    def _add_tessellated_spheres(self) -> None:
        unit = trimesh.creation.icosphere(subdivisions=ICOSPHERE_SUBDIVISIONS, radius=1.0)
        child = self._child(unit)
        transform = np.eye(4)
        for center, radius, material in zip(
            self.sphere_centers, self.sphere_radii, self.sphere_materials, strict=True
        ):
            transform[:3, :3] = np.eye(3) * float(radius)
            transform[:3, 3] = center
            self._place(child, transform, int(material), smooth=True)

    def _add_meshes(self, scene: Scene) -> None:
        children: dict[int, int] = {}
        for placement in scene.meshes:
            key = id(placement.mesh)
            if key not in children:
                children[key] = self._child(placement.mesh)
            material = scene.material_index(placement.material)
            self._place(children[key], placement.transform, material, placement.smooth)
        # Mesh looks: the placements showing their own texture or vertex colours, by geom id.
        geom_ids = self._instance_geom_ids[len(self._instance_geom_ids) - len(scene.meshes) :]
        self.mesh_colors = MeshColors(scene.meshes, geom_ids)

    def _finish_tables(self) -> None:
        size = max(self._instance_geom_ids, default=-1) + 1
        self.instance_child = np.full(size, -1, np.int32)
        self.instance_material = np.zeros(size, np.intp)
        self.instance_smooth = np.zeros(size, bool)
        self.instance_normal_matrix = np.zeros((size, 3, 3), np.float32)
        self.instance_scale = np.zeros(size, np.float32)
        if size:
            ids = np.asarray(self._instance_geom_ids)
            self.instance_child[ids] = self._instance_child
            self.instance_material[ids] = self._instance_material
            self.instance_smooth[ids] = self._instance_smooth
            self.instance_normal_matrix[ids] = self._instance_normal_matrix
            self.instance_scale[ids] = self._instance_scale
        if self._mesh_faces:
            vertex_offsets = np.cumsum([0] + [len(n) for n in self._mesh_vertex_normals[:-1]])
            self.mesh_faces = np.concatenate(
                [f + o for f, o in zip(self._mesh_faces, vertex_offsets, strict=True)]
            )
            self.mesh_vertex_normals = np.concatenate(self._mesh_vertex_normals)
            missing = np.concatenate(self._mesh_missing_normals)
            self.mesh_missing_normals = missing if missing.any() else None
            self.mesh_face_normals = np.concatenate(self._mesh_face_normals)
            self.mesh_face_offset = np.asarray(self._mesh_face_offset, np.int64)

    def close(self) -> None:
        self.bvh.close()
        for child in self._children:
            child.close()

    def __enter__(self) -> SceneGeometry:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- queries ------------------------------------------------------------------------------

    def _floor_crossing(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tnear: float | np.ndarray,
        tfar: float | np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where each ray meets the floor plane: (n,) float32 distance along the ray (any value
        where it does not), and (n,) bool whether it does, in front of the origin and within
        [tnear, tfar]. ``origins``, ``directions`` (3, n) float32."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (np.float32(self.floor.height) - origins[1]) / directions[1]
        # Behind the origin is negative, parallel is ±inf or NaN: none passes all three tests.
        meets = (t >= np.maximum(tnear, np.float32(0.0))) & (t <= tfar) & (t != np.inf)
        return t, meets

    def intersect(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tnear: float | np.ndarray = 0.0,
        tfar: float | np.ndarray = np.inf,
    ) -> SurfaceHits:
        """Nearest surface on each ray; ``origins``, ``directions`` (3, n) float32, unit dirs.
        Every field has one column per ray (zeros where ``hit`` is False)."""
        rows, compact = self.intersect_compact(origins, directions, tnear, tfar)
        n = np.shape(origins)[1]
        full = SurfaceHits(
            hit=np.zeros(n, bool),
            t=np.full(n, np.inf, np.float32),
            position=np.zeros((3, n), np.float32),
            normal=np.zeros((3, n), np.float32),
            face_normal=np.zeros((3, n), np.float32),
            material=np.zeros(n, np.intp),
            floor=np.zeros(n, bool),
            scale=np.zeros(n, np.float32),
            incoming=np.zeros((3, n), np.float32),
        )
        for name in ("hit", "t", "material", "floor", "scale"):
            getattr(full, name)[rows] = getattr(compact, name)
        for name in ("position", "normal", "face_normal", "incoming"):
            getattr(full, name)[:, rows] = getattr(compact, name)
        if compact.colored is not None:
            full.colored, full.color = rows[compact.colored], compact.color
        return full

    def intersect_compact(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tnear: float | np.ndarray = 0.0,
        tfar: float | np.ndarray = np.inf,
    ) -> tuple[np.ndarray, SurfaceHits]:
        """Like ``intersect``, but only for the rays that hit: returns their (k,) int64 ray
        numbers and a ``SurfaceHits`` of k columns (what the integrator shades).

        The hits come grouped by kind, floor first, then spheres, then mesh instances, each
        group in ray order: each group is computed on contiguous arrays, written straight into
        its slice of the result. (Gathers into those slices use ``mode="clip"``: NumPy buffers
        ``out`` in the default mode, and the indices come from ``flatnonzero``.)
        """
        origins = np.asarray(origins, np.float32)
        directions = np.asarray(directions, np.float32)
        hits = self.bvh.intersect(origins.T, directions.T, tnear, tfar)
        on_object = hits.geom_id >= 0
        if self.floor is not None:
            floor_t, meets_floor = self._floor_crossing(origins, directions, tnear, tfar)
            on_floor = meets_floor & (floor_t < hits.t)
            on_object &= ~on_floor
            floor_rays = np.flatnonzero(on_floor)
        else:
            floor_rays = np.zeros(0, np.int64)
        on_instance = hits.inst_id >= 0
        sphere_rays = np.flatnonzero(
            on_object & ~on_instance & (hits.geom_id == self.sphere_geom_id)
            if self.sphere_geom_id >= 0
            else np.zeros(0, bool)
        )
        instance_rays = np.flatnonzero(on_object & on_instance)
        groups = (floor_rays, sphere_rays, instance_rays)
        k = sum(len(rays) for rays in groups)
        if k == 0:
            return np.zeros(0, np.int64), _no_hits()
        out = SurfaceHits(
            hit=np.ones(k, bool), t=np.empty(k, np.float32), position=np.empty((3, k), np.float32),
            normal=np.empty((3, k), np.float32), face_normal=None,
            material=np.empty(k, np.intp), floor=np.zeros(k, bool),
            scale=np.empty(k, np.float32), incoming=np.empty((3, k), np.float32),
        )  # fmt: skip
        out.face_normal = np.empty((3, k), np.float32) if len(instance_rays) else out.normal
        stops = np.cumsum([len(rays) for rays in groups])
        floor_part, sphere_part, instance_part = (
            slice(stop - len(rays), stop) for rays, stop in zip(groups, stops, strict=True)
        )
        for rays, part in zip(groups, (floor_part, sphere_part, instance_part), strict=True):
            if len(rays):
                np.take(directions, rays, axis=1, out=out.incoming[:, part], mode="clip")
        if len(floor_rays):
            t = np.take(floor_t, floor_rays, out=out.t[floor_part], mode="clip")
            position = out.position[:, floor_part]
            np.take(origins, floor_rays, axis=1, out=position, mode="clip")
            position += out.incoming[:, floor_part] * t
            out.normal[:, floor_part] = np.array([[0.0], [1.0], [0.0]], np.float32)
            out.material[floor_part] = self.floor_material
            out.floor[floor_part] = True
            out.scale[floor_part] = _largest_magnitude(position)
        if len(sphere_rays):
            prim = np.take(hits.prim_id, sphere_rays)
            t = np.take(hits.t, sphere_rays, out=out.t[sphere_part], mode="clip")
            center = np.take(self.sphere_centers_by_column, prim, axis=1)
            hit_points = np.take(origins, sphere_rays, axis=1)
            hit_points += out.incoming[:, sphere_part] * t
            hit_points -= center
            outward = out.normal[:, sphere_part]
            length = np.sqrt(hit_points[0] ** 2 + hit_points[1] ** 2 + hit_points[2] ** 2)
            np.divide(hit_points, np.maximum(length, np.float32(1e-30)), out=outward)
            # Re-project onto the sphere: removes the rounding error along the ray.
            position = out.position[:, sphere_part]
            np.multiply(np.take(self.sphere_radii, prim), outward, out=position)
            position += center
            np.take(self.sphere_materials, prim, out=out.material[sphere_part], mode="clip")
            # |centre| + radius bounds every coordinate of a point on the sphere.
            np.take(self.sphere_scale, prim, out=out.scale[sphere_part], mode="clip")
        if len(instance_rays):
            inst = np.take(hits.inst_id, instance_rays)
            t = np.take(hits.t, instance_rays, out=out.t[instance_part], mode="clip")
            prim, u, v = hits.prim_id[instance_rays], hits.u[instance_rays], hits.v[instance_rays]
            normal, face_normal = self._instance_normals(inst, prim, u, v)
            if self.mesh_colors:  # textures, vertex colours: the hit's own base colour
                out.colored, out.color = self.mesh_colors.hit_colors(
                    inst, prim, u, v, instance_part.start
                )
            out.normal[:, instance_part] = normal
            out.face_normal[:, instance_part] = face_normal
            if len(floor_rays) or len(sphere_rays):
                out.face_normal[:, : instance_part.start] = out.normal[:, : instance_part.start]
            position = out.position[:, instance_part]
            np.take(origins, instance_rays, axis=1, out=position, mode="clip")
            position += out.incoming[:, instance_part] * t
            np.take(self.instance_material, inst, out=out.material[instance_part], mode="clip")
            # The instance's world bounds bound every coordinate of a point on it.
            np.take(self.instance_scale, inst, out=out.scale[instance_part], mode="clip")
        return np.concatenate(groups), out

    def _instance_normals(self, inst, prim, u, v) -> tuple[np.ndarray, np.ndarray]:
        """(3, k) unit shading and geometric world normals of instance hits."""
        face = self.mesh_face_offset[self.instance_child[inst]] + prim
        matrices = self.instance_normal_matrix[inst]
        geometric = self.mesh_face_normals[face]
        corners = self.mesh_faces[face]
        # Never zero: corners without a normal, and blends that cancel, take the face's.
        interpolated = blend_normals(
            self.mesh_vertex_normals, self.mesh_missing_normals, corners, u, v, geometric
        )
        shading = np.where(self.instance_smooth[inst, None], interpolated, geometric)
        world_geometric = _unit(np.einsum("nij,nj->in", matrices, geometric))
        world_shading = _unit(np.einsum("nij,nj->in", matrices, shading))
        return world_shading, world_geometric

    def occluded(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tnear: float | np.ndarray = 0.0,
        tfar: float | np.ndarray = np.inf,
    ) -> np.ndarray:
        """(n,) bool: whether any surface, floor included, lies on each ray within the window;
        ``origins``, ``directions`` (3, n) float32."""
        origins = np.asarray(origins, np.float32)
        directions = np.asarray(directions, np.float32)
        blocked = self.bvh.occluded(origins.T, directions.T, tnear, tfar)
        if self.floor is None:
            return blocked
        _, meets_floor = self._floor_crossing(origins, directions, tnear, tfar)
        return blocked | meets_floor
