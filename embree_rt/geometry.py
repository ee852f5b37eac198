"""Scene geometry: every object of a ``Scene`` in one Embree BVH, and what each hit is.

Spheres go in as analytic spheres: by default Embree user geometry with compiled callbacks
(Embree's own point spheres beyond ``sphere_modes``' limit), ``spheres="point"`` Embree's
own point spheres, ``spheres="mesh"`` one tessellated icosphere placed once per sphere through
one Embree instance array. Each distinct triangle mesh is built once and instanced per
placement; a scene's ``instances`` (meshes placed by the thousand) go in as one instance array
each. The floor is the Embree
layer's analytic ground plane: exact at any distance, where a finite quad in the BVH would cut
the horizon and lose float32 precision far away.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from embree_rt.ambient_occlusion import HemisphereQuery
from embree_rt.closing import Closing
from embree_rt.compiled.camera_rays import CameraRays
from embree_rt.embree import BVH, spheres_in_spatial_order
from embree_rt.mesh_attributes import (
    HitLooks,
    MeshColors,
    blend_normals,
    mesh_hit_filter,
    no_looks,
    unit_vertex_normals,
)
from embree_rt.scene.model import MeshObject, Scene
from embree_rt.sphere_modes import SPHERE_MODES, sphere_kind
from embree_rt.textures import SRGB8_TO_LINEAR
from embree_rt.tracing import hemisphere, segments
from embree_rt.tracing.camera_query import intersect_camera_records
from embree_rt.tracing.records import HitLabels, HitRecords, intersect_records

if TYPE_CHECKING:
    import trimesh

ICOSPHERE_SUBDIVISIONS = 3


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
    ``looks`` what the hits on meshes with per-point looks show of their own
    (``mesh_attributes.HitLooks``: their colours from textures and vertex colours, and more),
    at its ``rows`` (j,) int64 (none when no hit has looks). ``painted`` (p,) int64 the columns
    that hit spheres with colours of their own (``Scene.sphere_colors``), ``paint`` (3, p)
    float32 those linear colours.
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
    looks: HitLooks = field(default_factory=no_looks)
    painted: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    paint: np.ndarray = field(default_factory=lambda: np.empty((3, 0), np.float32))
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


@dataclass
class BuiltMesh:
    """A distinct triangle mesh, built once into a BVH of its own (``bvh``) and placed any
    number of times: ``faces`` (f, 3) int64; ``vertex_normals`` (v, 3) float32 unit or zero and
    ``missing_normals`` (v,) float32 (``mesh_attributes.unit_vertex_normals``);
    ``face_normals`` (f, 3) float32; ``bounds`` (2, 3) float64 its box."""

    bvh: BVH
    faces: np.ndarray
    vertex_normals: np.ndarray
    missing_normals: np.ndarray
    face_normals: np.ndarray
    bounds: np.ndarray


@dataclass
class Placement:
    """A top-level geometry that places built meshes (indices ``meshes``; none for a curve
    set, placed as a BVH of its own): one instance, or
    (``in_array``) an instance array whose instance i has material ``materials[i]`` ((n,)
    int32; a single instance's is its one material); ``smooth`` shading; ``first_object`` the
    object id of its first copy (``Scene.object_id_starts``); ``scale`` a bound on a single
    instance's world coordinates (an array's hit records bound each instance themselves)."""

    geom_id: int
    meshes: list[int]
    materials: np.ndarray
    smooth: bool
    first_object: int
    scale: float = 0.0
    in_array: bool = False


def sphere_hit_colors(colors: np.ndarray, spheres: np.ndarray) -> np.ndarray:
    """(3, k) float32 linear base colours of the hits on spheres ``spheres`` (k,) int (the
    scene's order), from their (n, 3) uint8 sRGB ``colors``."""
    return SRGB8_TO_LINEAR[colors[spheres].T]


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
        movable: bool = False,
    ):
        """``take_spheres``: once the BVH holds its own copy of the spheres, before it is built,
        they are taken out of ``scene`` (left with none): a caller that owns the scene (a
        brick) then does not hold them twice while the BVH is built. ``movable``: the spheres
        can be moved afterwards (``move_spheres``)."""
        if spheres not in SPHERE_MODES:
            raise ValueError(f"spheres: expected one of {SPHERE_MODES}, got {spheres!r}")
        self.bvh = BVH(threads=threads, movable=movable)
        self._meshes: list[BuiltMesh] = []
        self._placements: list[Placement] = []
        self.sphere_centers = np.asarray(scene.sphere_centers, np.float32)
        self.sphere_radii = np.asarray(scene.sphere_radii, np.float32)
        # int32 as the scene holds them: no N-sized copies (1e8 spheres are 0.4 GB of them)
        self.sphere_materials = np.asarray(scene.sphere_materials, np.int32)
        self.sphere_geom_id = -1
        # (n, 3) uint8 sRGB per sphere in the scene's order, or None (``Scene.sphere_colors``)
        self.sphere_colors = scene.sphere_colors
        # The instance array of tessellated spheres (``spheres="mesh"``), or -1.
        self.sphere_array_geom_id = -1
        # The scene's index of each sphere the BVH holds, None when they are in the scene's
        # order; and the BVH's spheres' materials, in the BVH's order.
        self.sphere_index: np.ndarray | None = None
        self._sphere_labels = self.sphere_materials
        self.floor = scene.floor
        # The floor's material comes after the scene's own in the renderer's material table.
        self.floor_material = len(scene.materials)
        # Each curve set's own BVH, placed once in the scene's (closed with it).
        self._curve_bvhs: list[BVH] = []
        self.curve_segment_count = 0
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
        """Build ``mesh`` into a BVH of its own; its index among the built meshes."""
        child = BVH(threads=self.bvh.threads)
        vertex_normals, missing_normals = unit_vertex_normals(mesh.vertex_normals)
        self._meshes.append(
            BuiltMesh(
                child,
                np.asarray(mesh.faces, np.int64),
                vertex_normals,
                missing_normals,
                np.asarray(mesh.face_normals, np.float32),
                np.asarray(mesh.bounds, np.float64),
            )
        )
        child.add_triangles(mesh.vertices, mesh.faces, mesh_hit_filter(mesh))
        child.commit()
        return len(self._meshes) - 1

    def _place(
        self, child: int, transform: np.ndarray, material: int, smooth: bool, first_object: int
    ) -> int:
        """Place built mesh ``child`` by the (4, 4) ``transform``; returns its geometry id."""
        mesh = self._meshes[child]
        geom_id = self.bvh.add_instance(mesh.bvh, transform)
        low, high = mesh.bounds
        corners = np.array(
            [
                [x, y, z]
                for x in (low[0], high[0])
                for y in (low[1], high[1])
                for z in (low[2], high[2])
            ]
        )
        world = corners @ transform[:3, :3].T + transform[:3, 3]
        self._placements.append(
            Placement(
                geom_id,
                [child],
                np.array([material], np.int32),
                smooth,
                first_object,
                scale=float(np.abs(world).max()),
            )
        )
        self.triangle_count += len(mesh.faces)
        self.instance_count += 1
        return geom_id

    def _place_array(
        self,
        children: list[int],
        transforms: np.ndarray,
        child_index: np.ndarray | None,
        materials: np.ndarray,
        smooth: bool,
        first_object: int,
    ) -> int:
        """Place built meshes ``children`` by (n, 4, 4) ``transforms`` as one instance array,
        ``child_index`` (n,) picking each one's mesh (None: the only one), with (n,) int32
        ``materials``; returns its geometry id."""
        geom_id = self.bvh.add_instances(
            [self._meshes[c].bvh for c in children], transforms, child_index
        )
        self._placements.append(
            Placement(
                geom_id,
                children,
                np.ascontiguousarray(materials, np.int32),
                bool(smooth),
                first_object,
                in_array=True,
            )
        )
        faces = np.array([len(self._meshes[c].faces) for c in children], np.int64)
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
        # Ties between spheres go by the scene's own index, not by the Morton rank the BVH
        # reports: the ranks of moved spheres differ from a fresh build's, and a refitted BVH
        # must answer as a fresh one does.
        self.sphere_geom_id = self.bvh.add_spheres(
            centers, radii, kind=kind, tie_keys=self.sphere_index
        )

    def move_spheres(self, centers: np.ndarray, radii: np.ndarray) -> None:
        """Give the scene's spheres new ``centers`` (n, 3) and ``radii`` (n,) float, in the
        scene's order, n and materials as before, and refit the BVH (``BVH.move_spheres``; a
        ``movable`` geometry of analytic spheres). They stay in the order the first spheres
        put them in, so the material tables stand: the BVH gathers them into it as it fills
        its buffer (``order``)."""
        if self.sphere_geom_id < 0:
            raise ValueError("move_spheres: this geometry holds no analytic spheres to move")
        centers = np.asarray(centers, np.float32)
        radii = np.asarray(radii, np.float32)
        order = self.sphere_index
        if order is not None and len(centers) != len(order):
            order = None  # (the BVH refuses the count, naming it)
        self.bvh.move_spheres(self.sphere_geom_id, centers, radii, order=order)

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
        geom_id = self._place_array(
            [child], transforms, None, self.sphere_materials, True, first_object=0
        )  # copy j is sphere j: object j
        self.sphere_array_geom_id = geom_id

    def _add_meshes(self, scene: Scene) -> None:
        children: dict[int, int] = {}
        mesh_ids, instance_starts = scene.object_id_starts()
        # Mesh looks: the placements showing their own texture or vertex colours, by geom id.
        geom_ids = []
        for placement, object_id in zip(scene.meshes, mesh_ids, strict=True):
            key = id(placement.mesh)
            if key not in children:
                children[key] = self._child(placement.mesh)
            material = scene.material_index(placement.material)
            geom_ids.append(
                self._place(
                    children[key], placement.transform, material, placement.smooth, int(object_id)
                )
            )
        looks = list(scene.meshes)
        # one instance array per entry, its mesh built once
        for entry, first_id in zip(scene.instances, instance_starts, strict=True):
            key = id(entry.mesh)
            if key not in children:
                children[key] = self._child(entry.mesh)
            geom_ids.append(
                self._place_array(
                    [children[key]],
                    entry.transforms,
                    None,
                    entry.materials,
                    entry.smooth,
                    int(first_id),
                )
            )
            # a one-mesh array's hits name its faces as the mesh's own: the same lookups
            looks.append(MeshObject(mesh=entry.mesh, mesh_colors=entry.mesh_colors))
        self.mesh_colors = MeshColors(looks, geom_ids)

    def _add_curves(self, scene: Scene) -> None:
        """Each curve set as a BVH of its own placed once (identity): its hits then carry the
        instance's id, which names the set, its material and scale as a mesh placement's do;
        a placement of no mesh, so no mesh lookup reads them."""
        for curves, object_id in zip(scene.curves, scene.curve_ids(), strict=True):
            child = BVH(threads=self.bvh.threads)
            self._curve_bvhs.append(child)
            child.add_curves(curves.points, curves.radii, curves.starts)
            child.commit()
            geom_id = self.bvh.add_instance(child, np.eye(4))
            material = np.array([scene.material_index(curves.material)], np.int32)
            self._placements.append(
                Placement(
                    geom_id, [], material, False, int(object_id), scale=child.coordinate_bound
                )
            )
            self.curve_segment_count += len(curves)

    def _finish_tables(self) -> None:
        """The tables by top-level geometry id and the meshes' concatenated tables that turn a
        hit's ids into its material, scale and smooth normal, from the placements and meshes."""
        size = self.bvh.geometry_count
        self.instance_child = np.full(size, -1, np.int32)
        self.instance_material = np.zeros(size, np.intp)
        self.instance_smooth = np.zeros(size, bool)
        self.instance_scale = np.zeros(size, np.float32)
        self.object_start = np.full(size, -1, np.int64)
        # Per instance array: its mesh by (geom id, position among the array's children); the
        # transforms themselves stay in the BVH, which takes its hits' normals to world space.
        arrays = [placement for placement in self._placements if placement.in_array]
        widest = max((len(placement.meshes) for placement in arrays), default=1)
        self.array_child = np.full((size, widest), -1, np.int32)
        for placement in self._placements:
            geom_id = placement.geom_id
            self.instance_child[geom_id] = placement.meshes[0] if placement.meshes else -1
            self.instance_material[geom_id] = placement.materials[0]
            self.instance_smooth[geom_id] = placement.smooth
            self.instance_scale[geom_id] = placement.scale
            self.object_start[geom_id] = placement.first_object
            if placement.in_array:
                self.array_child[geom_id, : len(placement.meshes)] = placement.meshes
        meshes = self._meshes
        if meshes:
            face_counts = [len(mesh.faces) for mesh in meshes]
            self.mesh_face_offset = np.cumsum([0, *face_counts[:-1]]).astype(np.int64)
            vertex_offsets = np.cumsum([0] + [len(m.vertex_normals) for m in meshes[:-1]])
            self.mesh_faces = np.concatenate(
                [mesh.faces + o for mesh, o in zip(meshes, vertex_offsets, strict=True)]
            )
            self.mesh_vertex_normals = np.concatenate([mesh.vertex_normals for mesh in meshes])
            missing = np.concatenate([mesh.missing_normals for mesh in meshes])
            self.mesh_missing_normals = missing if missing.any() else None
            self.mesh_face_normals = np.concatenate([mesh.face_normals for mesh in meshes])
        self.labels = HitLabels(
            geometry_label=self.instance_material.astype(np.int64),
            geometry_scale=self.instance_scale,
            sphere_geom_id=self.sphere_geom_id,
            sphere_label=self._sphere_labels,
            plane_y=None if self.floor is None else float(self.floor.height),
            plane_label=self.floor_material,
            instance_labels={placement.geom_id: placement.materials for placement in arrays},
        )
        self.smooth_meshes = bool(self.instance_smooth.any())
        # Curve sets' hits carry instance ids too (their object ids and materials read them).
        self.has_meshes = self.instance_count > 0 or bool(self._curve_bvhs)
        # Mesh looks and sphere colours are found by each hit's Embree ids.
        self.needs_ids = self.has_meshes or self.sphere_colors is not None

    def close(self) -> None:
        self.bvh.close()
        for mesh in self._meshes:
            mesh.bvh.close()
        for curve_bvh in self._curve_bvhs:
            curve_bvh.close()

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
        own = [(compact.painted, compact.paint)]  # spheres' own colours, then meshes' looks
        if len(compact.looks.rows) and compact.looks.color is not None:
            own.append((compact.looks.rows, compact.looks.color))
        if any(len(columns) for columns, _ in own):
            full.colored = rows[np.concatenate([columns for columns, _ in own])]
            full.color = np.concatenate([color for _, color in own], axis=1)
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
        records = intersect_records(
            self.bvh,
            origins,
            directions,
            self.labels,
            coherent=coherent,
            ids=ids or self.needs_ids,
        )
        return records.rays, self._surfaces(records)

    def intersect_camera(
        self, camera: CameraRays, index: np.ndarray, ids: bool = True
    ) -> tuple[np.ndarray, SurfaceHits, np.ndarray]:
        """``intersect_compact`` of the camera rays of samples ``index`` (n,) int64, made
        inside the query (``tracing.camera_query``): the (k,) ray numbers that hit, their
        ``SurfaceHits``, and the (3, n) float32 directions of all n rays."""
        records, directions = intersect_camera_records(
            self.bvh, camera, index, self.labels, ids or self.needs_ids
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
        if self.sphere_colors is not None:
            self._color_sphere_hits(surfaces, records)
        if self.mesh_colors and meshes.stop > meshes.start:  # mesh looks: textures, colours
            looks = self.mesh_colors.hit_looks(
                records.inst_id[meshes],
                records.prim_id[meshes],
                records.u[meshes],
                records.v[meshes],
                meshes.start,
            )
            if looks is not None:
                surfaces.looks = looks
                if looks.normal is not None:
                    self._apply_normal_maps(surfaces, records, looks)
        return surfaces

    def _color_sphere_hits(self, surfaces: SurfaceHits, records: HitRecords) -> None:
        """Give the hits on spheres their spheres' own colours (``Scene.sphere_colors``): the
        sphere group's by primitive, tessellated spheres' by instance-array copy."""
        spheres = records.group("spheres")
        if self.sphere_array_geom_id >= 0:
            meshes = records.group("other")
            on = np.flatnonzero(records.inst_id[meshes] == self.sphere_array_geom_id)
            rows = (meshes.start + on).astype(np.int64)
            index = records.inst_prim_id[rows]
        else:
            rows = np.arange(spheres.start, spheres.stop, dtype=np.int64)
            index = self.scene_sphere(records.prim_id[spheres])
        if len(rows):
            surfaces.painted = rows
            surfaces.paint = sphere_hit_colors(self.sphere_colors, index)

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
        if self.bvh.array_count:
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
        (3, n) float32 at ``rows`` (k,) int and ``target`` (3,): ``segments.occluded_toward``."""
        return segments.occluded_toward(self.bvh, points, rows, target, self.labels.plane_y)

    def occluded_hemispheres(self, rays: HemisphereQuery) -> np.ndarray:
        """(n,) bool: whether any surface, floor included, lies within ``rays.distance`` (inf:
        any) on each of ambient occlusion's n ``rays`` (``HemisphereQuery``), made inside the
        query: ``hemisphere.occluded_hemispheres``."""
        return hemisphere.occluded_hemispheres(self.bvh, rays, self.labels.plane_y)

    def toward_lights(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        targets: np.ndarray,
        takes: np.ndarray,
    ) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
        """Per light of ``targets`` (L, 3), what the ``points`` (3, n) float32 with unit
        ``normals`` (3, n) that ``takes`` ((n,) bool) light see of it, the floor included:
        ``segments.toward_lights``."""
        return segments.toward_lights(
            self.bvh, points, normals, targets, takes, self.labels.plane_y
        )


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
