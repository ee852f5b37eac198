"""Scene geometry: every object of a ``Scene`` in one Embree BVH, and what each hit is.

Spheres go in as analytic spheres: by default Embree user geometry with compiled callbacks
(Embree's own point spheres beyond ``USER_GEOMETRY_MAX_SPHERES``), ``spheres="point"`` Embree's
own point spheres, ``spheres="mesh"`` one tessellated icosphere placed once per sphere through
one Embree instance array. Each distinct triangle mesh is built once and instanced per
placement; a scene's ``instances`` (meshes placed by the thousand) go in as one instance array
each. The floor is the Embree
layer's analytic ground plane: exact at any distance, where a finite quad in the BVH would cut
the horizon and lose float32 precision far away.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from embree_rt.ambient_occlusion import plane_blocks
from embree_rt.closing import Closing
from embree_rt.compiled.camera_rays import CameraRays
from embree_rt.embree import BVH, HitLabels, HitRecords, spheres_in_spatial_order
from embree_rt.mesh_attributes import (
    HitLooks,
    MeshColors,
    blend_normals,
    mesh_hit_filter,
    unit_vertex_normals,
)
from embree_rt.scene.model import MeshObject, Scene

if TYPE_CHECKING:
    import trimesh

SPHERE_MODES = ("analytic", "point", "mesh")
# Above this many spheres, "analytic" spheres are Embree's own point spheres. Measured on the
# 1e7-sphere random field (2 threads, benchmarks/build_quality.py): they trace as fast as user
# geometry there (primary 9.3-9.6 against 10.3-13.7 Mrays/s, shadow 12.3-14.4 against 12.4-12.9),
# build in 2.9 s instead of 5.0-5.4 s, and take 49 bytes a sphere in Embree instead of 93 (the
# whole command: 71 against 148), so 1e8 spheres fit in 8 GB. Below it user geometry traces up to
# 1.5x faster (DESIGN.md).
USER_GEOMETRY_MAX_SPHERES = 1 << 23
ICOSPHERE_SUBDIVISIONS = 3


def sphere_kind(count: int, spheres: str = "analytic") -> str:
    """How ``count`` spheres of mode ``spheres`` (``SPHERE_MODES``) enter the BVH: "user" or
    "point" (the ``BVH.add_spheres`` kinds), or "mesh" (instanced icospheres)."""
    if spheres == "mesh":
        return "mesh"
    if spheres == "point" or count > USER_GEOMETRY_MAX_SPHERES:
        return "point"
    return "user"


@dataclass
class SurfaceHits:
    """What k rays hit, one ray per column, floor hits first.

    ``t`` (k,) float32; ``position`` (3, k) float32; ``normal`` (3, k) float32 unit shading
    normal and ``face_normal`` (3, k) float32 unit geometric normal, both pointing out of the
    object (+y for the floor) whichever side the ray came from; ``flat`` is True when the two
    are one array (no smooth mesh was hit); ``material`` (k,) intp material id (the floor's is
    ``SceneGeometry.floor_material``); ``floor_count``: columns [0, floor_count) hit the floor,
    the rest objects; ``scale`` (k,) float32, a bound on the size of the coordinates the hit was
    computed from (at least max |position|, and the object's |centre| + extent): its rounding
    error scales with it; ``incoming`` (3, k) float32, the direction of the ray that made it.
    ``colored`` (j,) int64 columns whose base colour is the surface's own (a mesh's texture or
    vertex colours), ``color`` (3, j) float32 linear those colours; both None when none is;
    ``looks`` the rest those hits show (``mesh_attributes.HitLooks``, rows ``colored``).
    ``prim_id``, ``inst_id``, ``inst_prim_id`` (k,) int32: Embree's primitive, top-level
    instance and instance-array copy ids of each hit (-1 on the floor; ``inst_id`` -1 on the
    sphere set; ``inst_prim_id`` -1 outside instance arrays), which name the object hit
    (``SceneGeometry.object_ids``).
    """

    t: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    face_normal: np.ndarray
    flat: bool
    material: np.ndarray
    floor_count: int
    scale: np.ndarray
    incoming: np.ndarray
    colored: np.ndarray | None = None
    color: np.ndarray | None = None
    looks: HitLooks | None = None
    prim_id: np.ndarray | None = None
    inst_id: np.ndarray | None = None
    inst_prim_id: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def floor(self) -> np.ndarray:
        """(k,) bool: which columns hit the floor."""
        mask = np.zeros(len(self.t), bool)
        mask[: self.floor_count] = True
        return mask


def _unit(vectors: np.ndarray) -> np.ndarray:
    """(3, n) float32 unit vectors along the columns of (3, n) ``vectors``."""
    x, y, z = vectors
    length = np.sqrt(x * x + y * y + z * z)
    return (vectors / np.maximum(length, np.float32(1e-30))).astype(np.float32, copy=False)


class SceneGeometry(Closing):
    """The BVH of a scene plus the tables that turn Embree's ids into shading inputs."""

    def __init__(
        self,
        scene: Scene,
        spheres: str = "analytic",
        threads: int | None = None,
        take_spheres: bool = False,
    ):
        """``take_spheres``: once the BVH holds its own copy of the spheres, before it is built,
        they are taken out of ``scene`` (left with none): a caller that owns the scene (a
        brick) then does not hold them twice while the BVH is built."""
        if spheres not in SPHERE_MODES:
            raise ValueError(f"spheres: expected one of {SPHERE_MODES}, got {spheres!r}")
        self.bvh = BVH(threads=threads)
        self._children: list[BVH] = []
        self.sphere_centers = np.asarray(scene.sphere_centers, np.float32)
        self.sphere_radii = np.asarray(scene.sphere_radii, np.float32)
        # int32 as the scene holds them: no N-sized copies (1e8 spheres are 0.4 GB of them)
        self.sphere_materials = np.asarray(scene.sphere_materials, np.int32)
        self.sphere_geom_id = -1
        # The scene's index of each sphere the BVH holds, None when they are in the scene's
        # order; and the BVH's spheres' materials, in the BVH's order.
        self.sphere_index: np.ndarray | None = None
        self._sphere_labels = self.sphere_materials
        self.floor = scene.floor
        # The floor's material comes after the scene's own in the renderer's material table.
        self.floor_material = len(scene.materials)
        # Per top-level instance geometry id: which child mesh, material, shading mode.
        self._instance_child: list[int] = []
        self._instance_material: list[int] = []
        self._instance_smooth: list[bool] = []
        self._instance_geom_ids: list[int] = []
        self._instance_scale: list[float] = []
        self._mesh_bounds: list[np.ndarray] = []
        self._mesh_face_offset: list[int] = []
        self._mesh_vertex_normals: list[np.ndarray] = []
        self._mesh_missing_normals: list[np.ndarray] = []
        self._mesh_face_normals: list[np.ndarray] = []
        self._mesh_faces: list[np.ndarray] = []
        # Instance arrays: (geom id, its child mesh indices, per-instance materials, smooth)
        self._arrays: list[tuple[int, list[int], np.ndarray, bool]] = []
        # Object id of each instance geometry's first copy, by geometry id (Scene.object_id_starts)
        self._object_start: dict[int, int] = {}
        self._curve_geom_ids: list[int] = []
        self.triangle_count = 0
        self.instance_count = 0
        try:
            if len(self.sphere_radii):
                if spheres in ("analytic", "point"):
                    self._add_analytic_spheres(sphere_kind(len(self.sphere_radii), spheres))
                else:
                    self._add_tessellated_spheres()
            # Only the building reads the centres and radii (the BVH has its own copy).
            self.sphere_centers = self.sphere_radii = None
            if take_spheres:
                scene.sphere_centers = np.zeros((0, 3), np.float32)  # (no views: they
                scene.sphere_radii = np.zeros(0, np.float32)  # would keep the arrays)
                scene.sphere_materials = np.zeros(0, np.int32)
            self._add_meshes(scene)
            self._add_curves(scene)
            self.bvh.commit()
            self._finish_tables()
        except BaseException:
            self.close()
            raise

    # -- building -----------------------------------------------------------------------------

    def _child(self, mesh: trimesh.Trimesh) -> int:
        child = BVH(threads=self.bvh.threads)
        self._children.append(child)
        child.add_triangles(mesh.vertices, mesh.faces, mesh_hit_filter(mesh))
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
        low, high = self._mesh_bounds[child]
        corners = np.array(
            [
                [x, y, z]
                for x in (low[0], high[0])
                for y in (low[1], high[1])
                for z in (low[2], high[2])
            ]
        )
        world = corners @ transform[:3, :3].T + transform[:3, 3]
        self._instance_scale.append(float(np.abs(world).max()))
        self.triangle_count += len(self._mesh_faces[child])
        self.instance_count += 1

    def _place_array(
        self,
        children: list[int],
        transforms: np.ndarray,
        child_index: np.ndarray | None,
        materials: np.ndarray,
        smooth: bool,
    ) -> int:
        """Place meshes ``children`` (indices into ``_children``) by (n, 4, 4) ``transforms``
        as one instance array, ``child_index`` (n,) picking each one's mesh (None: the only
        one), with (n,) int32 ``materials``; returns its geometry id."""
        geom_id = self.bvh.add_instances(
            [self._children[c] for c in children], transforms, child_index
        )
        self._arrays.append(
            (geom_id, children, np.ascontiguousarray(materials, np.int32), bool(smooth))
        )
        faces = np.array([len(self._mesh_faces[c]) for c in children], np.int64)
        placed = faces[0] * len(transforms) if child_index is None else faces[child_index].sum()
        self.triangle_count += int(placed)
        self.instance_count += len(transforms)
        return geom_id

    def _add_analytic_spheres(self, kind: str) -> None:
        centers, radii = self.sphere_centers, self.sphere_radii
        if kind == "user":
            # In the scene's own order, the spheres a ray meets one after another would be read
            # from all over the materials and the BVH's sphere tables when their hits are
            # recorded; in Morton order (the order the BVH stores user spheres in) they are
            # neighbours there too. Point spheres are copied into Embree's leaves: no need.
            order, centers, radii, labels, in_order = spheres_in_spatial_order(
                centers, radii, self.sphere_materials
            )
            if not in_order:
                self.sphere_index, self._sphere_labels = order, labels
        self.sphere_geom_id = self.bvh.add_spheres(centers, radii, kind=kind)

    def scene_sphere(self, prim_id: np.ndarray) -> np.ndarray:
        """(k,) int32 the scene's index of each of the BVH's spheres ``prim_id`` (k,) int."""
        return prim_id if self.sphere_index is None else self.sphere_index[prim_id]

    def _add_tessellated_spheres(self) -> None:
        from trimesh.creation import icosphere

        unit = icosphere(subdivisions=ICOSPHERE_SUBDIVISIONS, radius=1.0)
        child = self._child(unit)
        transforms = np.zeros((len(self.sphere_radii), 4, 4))
        for axis in range(3):
            transforms[:, axis, axis] = self.sphere_radii
        transforms[:, :3, 3] = self.sphere_centers
        transforms[:, 3, 3] = 1.0
        geom_id = self._place_array([child], transforms, None, self.sphere_materials, smooth=True)
        self._object_start[geom_id] = 0  # copy j is sphere j

    def _add_meshes(self, scene: Scene) -> None:
        children: dict[int, int] = {}
        mesh_ids, instance_starts = scene.object_id_starts()
        for placement, object_id in zip(scene.meshes, mesh_ids, strict=True):
            key = id(placement.mesh)
            if key not in children:
                children[key] = self._child(placement.mesh)
            material = scene.material_index(placement.material)
            self._place(children[key], placement.transform, material, placement.smooth)
            self._object_start[self._instance_geom_ids[-1]] = int(object_id)
        # Mesh looks: the placements showing their own texture or vertex colours, by geom id.
        geom_ids = self._instance_geom_ids[len(self._instance_geom_ids) - len(scene.meshes) :]
        looks = list(scene.meshes)
        # one instance array per entry, its mesh built once
        for entry, first_id in zip(scene.instances, instance_starts, strict=True):
            key = id(entry.mesh)
            if key not in children:
                children[key] = self._child(entry.mesh)
            geom_ids.append(
                self._place_array(
                    [children[key]], entry.transforms, None, entry.materials, entry.smooth
                )
            )
            self._object_start[geom_ids[-1]] = int(first_id)
            # a one-mesh array's hits name its faces as the mesh's own: the same lookups
            looks.append(MeshObject(mesh=entry.mesh, mesh_colors=entry.mesh_colors))
        self.mesh_colors = MeshColors(looks, geom_ids)

    def _add_curves(self, scene: Scene) -> None:
        """Each curve set as a BVH of its own placed once (identity): its hits then carry the
        instance's id, which names the set, its material and scale as a mesh placement's do;
        ``instance_child`` stays -1, so no mesh lookup reads them."""
        self.curve_segment_count = 0
        for curves, object_id in zip(scene.curves, scene.curve_ids(), strict=True):
            child = BVH(threads=self.bvh.threads)
            self._children.append(child)
            child.add_curves(curves.points, curves.radii, curves.starts)
            child.commit()
            geom_id = self.bvh.add_instance(child, np.eye(4))
            self._curve_geom_ids.append(geom_id)
            self._instance_geom_ids.append(geom_id)
            self._instance_child.append(-1)
            self._instance_material.append(scene.material_index(curves.material))
            self._instance_smooth.append(False)
            self._instance_scale.append(child.coordinate_bound)
            self._object_start[geom_id] = int(object_id)
            self.curve_segment_count += len(curves)

    def _finish_tables(self) -> None:
        size = self.bvh.geometry_count
        self.instance_child = np.full(size, -1, np.int32)
        self.instance_material = np.zeros(size, np.intp)
        self.instance_smooth = np.zeros(size, bool)
        self.instance_scale = np.zeros(size, np.float32)
        if self._instance_geom_ids:
            ids = np.asarray(self._instance_geom_ids)
            self.instance_child[ids] = self._instance_child
            self.instance_material[ids] = self._instance_material
            self.instance_smooth[ids] = self._instance_smooth
            self.instance_scale[ids] = self._instance_scale
        # Per instance array: its mesh by (geom id, position among the array's children); the
        # transforms themselves stay in the BVH, which takes its hits' normals to world space.
        widest = max((len(children) for _, children, _, _ in self._arrays), default=1)
        self.array_child = np.full((size, widest), -1, np.int32)
        instance_labels = {}
        for geom_id, children, materials, smooth in self._arrays:
            self.array_child[geom_id, : len(children)] = children
            self.instance_child[geom_id] = children[0]
            self.instance_material[geom_id] = materials[0]
            self.instance_smooth[geom_id] = smooth
            instance_labels[geom_id] = materials
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
        self.labels = HitLabels(
            geometry_label=self.instance_material.astype(np.int64),
            geometry_scale=self.instance_scale,
            sphere_geom_id=self.sphere_geom_id,
            sphere_label=self._sphere_labels,
            plane_y=None if self.floor is None else float(self.floor.height),
            plane_label=self.floor_material,
            instance_labels=instance_labels,
        )
        self.smooth_meshes = bool(self.instance_smooth.any())
        # curves' hits carry instance ids too (their object ids and materials read them)
        self.has_meshes = self.instance_count > 0 or bool(self._curve_geom_ids)
        self.object_start = np.full(size, -1, np.int64)
        for geom_id, start in self._object_start.items():
            self.object_start[geom_id] = start

    def close(self) -> None:
        self.bvh.close()
        for child in self._children:
            child.close()

    # -- queries ------------------------------------------------------------------------------

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> RaySurfaces:
        """Nearest surface on each of n rays; ``origins``, ``directions`` (3, n) float32, unit
        directions. Returns a ``RaySurfaces``: every field has one column per ray (zeros where
        ``hit`` is False)."""
        rows, compact = self.intersect_compact(origins, directions)
        n = np.shape(origins)[1]
        full = RaySurfaces(
            hit=np.zeros(n, bool),
            t=np.full(n, np.inf, np.float32),
            position=np.zeros((3, n), np.float32),
            normal=np.zeros((3, n), np.float32),
            face_normal=np.zeros((3, n), np.float32),
            material=np.zeros(n, np.intp),
            floor=np.zeros(n, bool),
            scale=np.zeros(n, np.float32),
        )
        full.hit[rows] = True
        for name in ("t", "material", "floor", "scale"):
            getattr(full, name)[rows] = getattr(compact, name)
        for name in ("position", "normal", "face_normal"):
            getattr(full, name)[:, rows] = getattr(compact, name)
        if compact.colored is not None:
            full.colored, full.color = rows[compact.colored], compact.color
        return full

    def intersect_compact(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        coherent: bool = False,
        ids: bool = True,
    ) -> tuple[np.ndarray, SurfaceHits]:
        """Like ``intersect``, but only for the rays that hit: returns their (k,) int64 ray
        numbers and a ``SurfaceHits`` of k columns (what the integrator shades), floor hits
        first. The Embree layer's compiled hit records do the bookkeeping; only smooth mesh
        normals are left to do here. ``coherent``: the rays come in runs of neighbouring
        camera rays (Embree's coherent query; the same answers, found faster). ``ids``: whether
        the surfaces carry Embree's ids of each hit (``prim_id``, ``inst_id``,
        ``inst_prim_id``; None without them, unless the scene has meshes, which need them)."""
        records = self.bvh.intersect_records(
            origins, directions, self.labels, coherent=coherent, ids=ids or self.has_meshes
        )
        return records.rays, self._surfaces(records)

    def intersect_camera(
        self, camera: CameraRays, index: np.ndarray, ids: bool = True
    ) -> tuple[np.ndarray, SurfaceHits, np.ndarray]:
        """``intersect_compact`` of the camera rays of samples ``index`` (n,) int64, made
        inside the query (``BVH.intersect_camera_records``): the (k,) ray numbers that hit,
        their ``SurfaceHits``, and the (3, n) float32 directions of all n rays."""
        records, directions = self.bvh.intersect_camera_records(
            camera, index, self.labels, ids or self.has_meshes
        )
        return records.rays, self._surfaces(records), directions

    def _surfaces(self, records: HitRecords) -> SurfaceHits:
        """The ``SurfaceHits`` of a query's hit records: smooth and normal-mapped shading
        normals and mesh looks added to the records' geometric ones."""
        face_normal = records.normal
        normal = face_normal
        meshes = records.group("other")
        if self.smooth_meshes and meshes.stop > meshes.start:
            normal = face_normal.copy()
            normal[:, meshes] = self._smooth_normals(
                records.inst_id[meshes],
                records.inst_prim_id[meshes],
                records.prim_id[meshes],
                records.u[meshes],
                records.v[meshes],
                face_normal[:, meshes],
            )
        surfaces = SurfaceHits(
            t=records.t,
            position=records.position,
            normal=normal,
            face_normal=face_normal,
            flat=normal is face_normal,
            material=records.label,
            floor_count=int(records.counts[0]),
            scale=records.scale,
            incoming=records.incoming,
            prim_id=records.prim_id,
            inst_id=records.inst_id,
            inst_prim_id=records.inst_prim_id,
        )
        if self.mesh_colors and meshes.stop > meshes.start:  # mesh looks: textures, colours
            looks = self.mesh_colors.hit_looks(
                records.inst_id[meshes],
                records.prim_id[meshes],
                records.u[meshes],
                records.v[meshes],
                meshes.start,
            )
            if looks is not None:
                surfaces.colored, surfaces.color, surfaces.looks = looks.rows, looks.color, looks
                if looks.normal is not None:
                    self._apply_normal_maps(surfaces, records, looks)
        return surfaces

    def _apply_normal_maps(self, surfaces: SurfaceHits, records, looks: HitLooks) -> None:
        """Replace the shading normals of the hits a normal map turns (``looks.normal``, in
        their mesh's space) by those normals taken to world space."""
        rows = looks.rows[looks.normal_at]
        inst, inst_prim = records.inst_id[rows], records.inst_prim_id[rows]
        world = self.bvh.instance_normals(inst, inst_prim, looks.normal.T)
        if surfaces.flat:
            surfaces.normal = surfaces.normal.copy()
            surfaces.flat = False
        surfaces.normal[:, rows] = _unit(np.ascontiguousarray(world, np.float32))

    def _smooth_normals(self, inst, inst_prim, prim, u, v, face_normal) -> np.ndarray:
        """(3, k) unit world shading normals of k mesh hits: the vertex normals interpolated at
        (u, v) where the placement is smooth, ``face_normal`` (3, k) elsewhere. ``inst_prim``
        (k,) the instance within an instance array (-1 for other hits)."""
        smooth = self.instance_smooth[inst]
        child = self.instance_child[inst]
        # hits on curves (no mesh: child -1) read mesh 0's face 0, and keep their face normal
        prim = np.where(child >= 0, prim, 0)
        child = np.maximum(child, 0)
        if self._arrays:
            position = self.bvh.instance_children(inst, inst_prim)
            in_array = position >= 0
            child = np.where(in_array, self.array_child[inst, np.maximum(position, 0)], child)
        face = self.mesh_face_offset[child] + prim
        corners = self.mesh_faces[face]
        # Never zero: corners without a normal, and blends that cancel, take the face's.
        interpolated = blend_normals(
            self.mesh_vertex_normals,
            self.mesh_missing_normals,
            corners,
            u,
            v,
            self.mesh_face_normals,
            face,
        )
        world = _unit(self.bvh.instance_normals(inst, inst_prim, interpolated))
        return np.where(smooth, world, face_normal)

    def occluded_toward(
        self, points: np.ndarray, rows: np.ndarray, target: np.ndarray
    ) -> np.ndarray:
        """(k,) bool: whether any surface, floor included, lies between each of the ``points``
        (3, n) float32 at ``rows`` (k,) int and ``target`` (3,): ``BVH.occluded_toward``."""
        return self.bvh.occluded_toward(points, rows, target, plane_y=self.labels.plane_y)

    def occluded_rays(
        self, origins: np.ndarray, directions: np.ndarray, distance: float
    ) -> np.ndarray:
        """(n,) bool: whether any surface, floor included, lies on each ray from ``origins``
        along ``directions`` ((3, n) float32) within ``distance`` (inf: any): one occlusion
        batch (ambient occlusion's)."""
        blocked = self.bvh.occluded(origins.T, directions.T, 0.0, np.float32(distance))
        return blocked | plane_blocks(origins, directions, self.labels.plane_y, distance)

    def toward_lights(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        targets: np.ndarray,
        takes: np.ndarray | None = None,
    ) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
        """Per light of ``targets`` (L, 3), what the ``points`` (3, n) float32 with unit
        ``normals`` (3, n) see of it, the floor included: ``BVH.toward_lights``."""
        return self.bvh.toward_lights(points, normals, targets, takes, self.labels.plane_y)


@dataclass
class RaySurfaces:
    """What each of n rays hit (``SceneGeometry.intersect``), one ray per column: ``hit`` (n,)
    bool, and the fields of ``SurfaceHits`` (zeros where nothing was hit; ``t`` inf), with
    ``floor`` (n,) bool marking the floor hits; ``colored`` (j,) ray numbers and ``color``
    (3, j) as in ``SurfaceHits``."""

    hit: np.ndarray
    t: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    face_normal: np.ndarray
    material: np.ndarray
    floor: np.ndarray
    scale: np.ndarray
    colored: np.ndarray | None = None
    color: np.ndarray | None = None
