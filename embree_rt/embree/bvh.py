"""``BVH``: one Embree scene holding spheres, triangle meshes and instances, queried in batches."""

from __future__ import annotations

import ctypes
import threading
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba
import numpy as np

from embree_rt.closing import Closing
from embree_rt.compiled.work_split import parallel_region
from embree_rt.embree import device as device_module
from embree_rt.embree import (
    instance_arrays,
    kernels,
    library,
    spatial_order,
    sphere_buffers,
    user_spheres,
    world_normals,
)
from embree_rt.embree.validation import (
    as_indices,
    as_points,
    as_positive,
    as_ray_bounds,
    as_segment_starts,
    as_transform,
    as_triangle_indices,
)
from embree_rt.transforms import affine_array_problem

if TYPE_CHECKING:  # imported by ``all_hits``: most BVHs never ask for every hit
    from embree_rt.embree import multihit


@dataclass
class Hits:
    """Nearest hits of a batch of n rays.

    ``t`` (n,) float32, ``inf`` on a miss; ``geom_id``, ``prim_id``, ``inst_id`` (n,) int32, -1
    where none (``geom_id`` is the geometry inside the instanced BVH for an instance hit, and
    ``inst_id`` the instance's geometry id); ``normal`` (n, 3) float32 unnormalised geometric
    normal in world space; ``u``, ``v`` (n,) float32 hit coordinates (barycentric on triangles);
    ``inst_prim_id`` (n,) int32 the instance's number inside an instance array
    (``BVH.add_instances``), -1 where the hit is not in one.
    """

    t: np.ndarray
    geom_id: np.ndarray
    prim_id: np.ndarray
    inst_id: np.ndarray
    normal: np.ndarray
    u: np.ndarray
    v: np.ndarray
    inst_prim_id: np.ndarray | None = None

    @property
    def hit(self) -> np.ndarray:
        """(n,) bool: which rays hit something."""
        return self.geom_id >= 0


class GeometryFilter(NamedTuple):
    """Embree filter functions of one triangle geometry (``BVH.add_triangles``): ``user_data``
    the (w,) uint64 block Embree hands them as the geometry's user pointer, ``intersect`` the
    address of the nearest-hit filter and ``occluded`` the occlusion query's (0: occlusion
    queries meet the geometry unfiltered), each a ``void(const RTCFilterFunctionNArguments*)``;
    ``keep`` the arrays the block points at, held while Embree may call the filters."""

    user_data: np.ndarray
    intersect: int
    occluded: int
    keep: tuple


SPHERE_KINDS = ("user", "point")
_NO_SPHERES = (np.zeros((0, 4), np.float32), np.zeros(0, np.int32))
_IDENTITY_SLOTS = np.zeros(0, np.int32)
_NO_NORMAL_MATRICES = np.zeros((0, 3, 3), np.float32)
_NO_ARRAYS = np.zeros((0, instance_arrays.ARRAY_COLUMNS), np.uint64)

_kernel_lock = threading.Lock()
_symbols_registered = False
# Multi-threaded queries take ``work_split.parallel_region``; single-threaded BVHs use serial
# kernels, so many Python threads may query them concurrently.


def _prepare_kernels() -> None:
    global _symbols_registered
    with _kernel_lock:
        if not _symbols_registered:
            kernels.register_symbols()
            _symbols_registered = True


def native_lanes(device: device_module.Device) -> int:
    """The widest packet Embree runs natively on this CPU (16 with AVX-512, 8 with AVX2, else
    4). On this project's AVX2 machine 8-wide packets traced user-geometry spheres 1.2–1.8x
    faster than 4-wide ones, and 16-wide ones (emulated there) no faster than 8."""
    for lanes, prop in (
        (16, library.DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED),
        (8, library.DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED),
        (4, library.DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED),
    ):
        if device.property(prop):
            return lanes
    return 1


def _valid_lanes(lanes: int) -> int:
    if lanes not in kernels.LANE_CHOICES:
        raise ValueError(f"lanes: expected one of {kernels.LANE_CHOICES}, got {lanes!r}")
    return int(lanes)


def _release_handles(lib: ctypes.CDLL, scene: int, dev: device_module.Device) -> None:
    if scene:
        lib.rtcReleaseScene(scene)
    device_module.release(dev)


class BVH(Closing):
    """One Embree scene: add geometry, ``commit()``, then ``intersect`` / ``occluded`` batches.

    ``threads`` is the number of threads the queries run on (default: all cores); ``lanes`` how
    many rays go to Embree in one call: 1 (single rays) or a packet of 4, 8 or 16 (default: the
    widest this CPU runs natively, see ``native_lanes``). ``build_quality`` is Embree's: "low",
    "medium" (Embree's default) or "high"; ``compact`` asks Embree for its compact (less memory)
    structures. ``robust`` selects Embree's watertight triangle test (no ray slips between two
    triangles sharing an edge); ``filters`` enables ``all_hits`` (every hit along a ray,
    ``multihit``); ``movable`` lets ``move_spheres`` move committed spheres
    and refit the BVH (Embree's dynamic scene, the spheres' geometry refitted). Release the
    Embree objects with ``close()`` or a ``with`` block; a finalizer does it otherwise.
    """

    def __init__(
        self,
        threads: int | None = None,
        lanes: int | None = None,
        *,
        build_quality: str = "medium",
        compact: bool = False,
        robust: bool = False,
        filters: bool = False,
        movable: bool = False,
    ) -> None:
        if threads is not None and (int(threads) != threads or threads < 1):
            raise ValueError(f"threads: must be a positive integer, got {threads!r}")
        if build_quality not in library.BUILD_QUALITY:
            raise ValueError(
                f"build_quality: expected one of {list(library.BUILD_QUALITY)}, got "
                f"{build_quality!r}"
            )
        self.threads = int(threads) if threads is not None else numba.config.NUMBA_NUM_THREADS
        self.threads = min(self.threads, numba.config.NUMBA_NUM_THREADS)
        self._device = device_module.acquire()
        self._lib = self._device.lib
        self._scene = self._lib.rtcNewScene(self._device.handle)
        self._device.check("rtcNewScene")
        self._finalizer = weakref.finalize(
            self, _release_handles, self._lib, self._scene, self._device
        )
        self._build_quality = library.BUILD_QUALITY[build_quality]
        # Embree builds user geometry in two levels, each geometry's own tree by that geometry's
        # quality (which can be "refit"), only in a scene of quality "low"
        # (Scene::createUserGeometryAccel, BVH8Factory::BVH8UserGeometry's DYNAMIC variant).
        scene_quality = library.BUILD_QUALITY["low"] if movable else self._build_quality
        self._lib.rtcSetSceneBuildQuality(self._scene, scene_quality)
        flags = (
            library.SCENE_FLAG_COMPACT * compact
            | library.SCENE_FLAG_ROBUST * robust
            | library.SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS * filters
            | library.SCENE_FLAG_DYNAMIC * movable
        )
        if flags:
            self._lib.rtcSetSceneFlags(self._scene, flags)
        self.filters = bool(filters)
        self.movable = bool(movable)
        self._device.check("setting the scene's build quality and flags")
        self._committed = False
        self._children: list[BVH] = []
        # Each sphere set by geometry id: its (n, 4) float32 (x, y, z, r) as stored and the
        # (n,) int32 slot where sphere i is stored (empty: sphere i is in slot i).
        self._sphere_buffers: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        # The user-geometry spheres' user data (three addresses), storage order and tie keys
        # (or None), kept alive here for as long as Embree may call the callbacks.
        self._sphere_user_data: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] = []
        # Each sphere set by geometry id: the (n,) int32 sphere stored in each slot (empty: the
        # given order) and how far from the origin it reaches; what ``move_spheres`` rewrites.
        self._sphere_orders: dict[int, np.ndarray] = {}
        self._sphere_reach: dict[int, float] = {}
        self._point_spheres: set[int] = set()
        self._bound_without_spheres = 0.0
        self._hit_filters: list[GeometryFilter] = []
        # Inverse-transpose of each single instance's linear part, by geometry id: one
        # (g, 3, 3) table at commit (world_normals).
        self._normal_matrices: dict[int, np.ndarray] = {}
        self._normal_matrix_table = _NO_NORMAL_MATRICES
        # Instance arrays by geometry id: the buffers Embree reads (transforms, child index) and
        # the children's coordinate bounds, all kept alive here; described to the compiled
        # passes by one table at commit (instance_arrays.ARRAY_* columns).
        self._arrays: dict[int, tuple[np.ndarray, np.ndarray | None, np.ndarray]] = {}
        self._array_table = _NO_ARRAYS
        self._has_instances = False
        self.geometry_count = 0
        self.primitive_count = 0
        self.instance_count = 0  # instances in instance arrays
        self.array_count = 0  # instance arrays
        # max |coordinate| over this BVH's own geometry: what an instance array's hit scale
        # is bounded from
        self.coordinate_bound = 0.0
        self.lanes = native_lanes(self._device) if lanes is None else _valid_lanes(lanes)

    # -- lifetime -----------------------------------------------------------------------------

    def close(self) -> None:
        """Release the Embree scene (and the device, when no other BVH uses it)."""
        self._finalizer()
        self._scene = None

    def _live_scene(self) -> int:
        if not self._scene:
            raise RuntimeError("this BVH has been closed")
        return self._scene

    # -- building -----------------------------------------------------------------------------

    def _attach(self, geometry: int, action: str) -> int:
        lib = self._lib
        scene = self._live_scene()
        if self._committed:
            lib.rtcReleaseGeometry(geometry)
            raise RuntimeError("cannot add geometry to a committed BVH")
        lib.rtcCommitGeometry(geometry)
        geom_id = lib.rtcAttachGeometry(scene, geometry)
        lib.rtcReleaseGeometry(geometry)
        self._device.check(action)
        self.geometry_count += 1
        return int(geom_id)

    def _new_geometry(self, kind: str) -> int:
        """A new Embree geometry of ``library.GEOMETRY_TYPE_<kind>``, to be ``_attach``ed."""
        self._live_scene()
        geometry = self._lib.rtcNewGeometry(
            self._device.handle, getattr(library, f"GEOMETRY_TYPE_{kind}")
        )
        self._device.check(f"rtcNewGeometry({kind})")
        return geometry

    def _new_buffer(self, geometry: int, kind: int, fmt: int, stride: int, count: int) -> int:
        pointer = self._lib.rtcSetNewGeometryBuffer(geometry, kind, 0, fmt, stride, count)
        self._device.check("rtcSetNewGeometryBuffer")
        return pointer

    def _new_filled_buffer(self, geometry: int, kind: int, fmt: int, rows: np.ndarray) -> int:
        """A new buffer of Embree's ``fmt`` holding ``rows`` (n, w), 4-byte items (float32 or
        uint32, as ``fmt`` reads them), n of them, each of w words."""
        count, width = rows.shape
        pointer = self._new_buffer(geometry, kind, fmt, 4 * width, count)
        if count:
            ctype = ctypes.c_float if rows.dtype == np.float32 else ctypes.c_uint32
            target = (ctype * rows.size).from_address(pointer)
            np.ctypeslib.as_array(target).reshape(count, width)[:] = rows
        return pointer

    def add_spheres(
        self,
        centers: np.ndarray,
        radii: np.ndarray,
        kind: str = "user",
        tie_keys: np.ndarray | None = None,
    ) -> int:
        """Add analytic spheres: ``centers`` (n, 3), ``radii`` (n,) positive. Returns geom id.

        ``kind="user"`` (default) enters them as user geometry with compiled callbacks
        (``user_spheres``); ``kind="point"`` as Embree's own ``SPHERE_POINT`` primitive, kept
        for comparison. Both report the nearest crossing in [tnear, tfar] (the exit point for a
        ray that starts inside) with an outward, unnormalised normal.

        ``tie_keys`` (n,) integers in [0, 2^32), user spheres only: of two of these spheres hit
        at one float32 distance, the one with the lower key takes the hit (the lower index
        given where the keys are equal); without them the lower index given. A caller that
        hands its spheres over in an order of its own passes each one's own index, so ties go
        the same way whatever order it chose. They stay with the sphere given through
        ``move_spheres``.
        """
        if kind not in SPHERE_KINDS:
            raise ValueError(f"kind: expected one of {SPHERE_KINDS}, got {kind!r}")
        centers = as_points(centers, "centers")
        radii = as_positive(radii, "radii", len(centers))
        count = len(centers)
        if tie_keys is not None:
            if kind != "user":
                raise ValueError(f"tie_keys: only user spheres break ties by key, not {kind!r}")
            if np.shape(tie_keys) != (count,):
                raise ValueError(f"tie_keys: expected shape ({count},), got {np.shape(tie_keys)}")
            tie_keys = as_indices(tie_keys, "tie_keys", 1 << 32).astype(np.uint32)
        if kind == "point":
            geometry = self._new_geometry("SPHERE_POINT")
            pointer = self._new_buffer(
                geometry, library.BUFFER_TYPE_VERTEX, library.FORMAT_FLOAT4, 16, count
            )
            packed = (
                np.ctypeslib.as_array((ctypes.c_float * (4 * count)).from_address(pointer)).reshape(
                    count, 4
                )
                if count
                else np.zeros((0, 4), np.float32)
            )
            reach = sphere_buffers.pack_spheres(
                centers, radii, sphere_buffers.IN_GIVEN_ORDER, packed
            )
            slot = _IDENTITY_SLOTS
            order_kept = sphere_buffers.IN_GIVEN_ORDER
            if self.movable:
                self._lib.rtcSetGeometryBuildQuality(geometry, library.BUILD_QUALITY_REFIT)
        else:
            geometry = self._new_geometry("USER")
            # Stored in spatial order, for the callbacks' memory traffic (spatial_order); the
            # callbacks report each sphere by its index among the spheres given.
            packed, order, slot, in_order, reach = spatial_order.store_in_spatial_order(
                centers, radii
            )
            if in_order:
                slot = _IDENTITY_SLOTS
                order_kept = sphere_buffers.IN_GIVEN_ORDER
            else:
                order_kept = order
            # Embree reads these through the user pointer for as long as the BVH lives.
            keys = 0 if tie_keys is None else tie_keys.ctypes.data
            user_data = np.array([packed.ctypes.data, order.ctypes.data, keys], np.uint64)
            self._sphere_user_data.append((user_data, order, tie_keys))
            lib = self._lib
            lib.rtcSetGeometryUserPrimitiveCount(geometry, count)
            lib.rtcSetGeometryUserData(geometry, user_data.ctypes.data)
            lib.rtcSetGeometryBoundsFunction(geometry, user_spheres.sphere_bounds.address, None)
            lib.rtcSetGeometryIntersectFunction(geometry, user_spheres.sphere_intersect.address)
            lib.rtcSetGeometryOccludedFunction(geometry, user_spheres.sphere_occluded.address)
            # A "low" scene builds each geometry on its own with the geometry's quality: the
            # same "low" makes that Embree's Morton builder. A movable one is built once (SAH)
            # and refitted on each commit of the geometry after.
            quality = library.BUILD_QUALITY_REFIT if self.movable else self._build_quality
            lib.rtcSetGeometryBuildQuality(geometry, quality)
            self._device.check("setting up user-geometry spheres")
        self.primitive_count += count
        self.coordinate_bound = max(self.coordinate_bound, float(reach))
        geom_id = self._attach(geometry, "adding spheres")
        self._sphere_buffers[geom_id] = (packed, slot)
        self._sphere_orders[geom_id] = order_kept
        self._sphere_reach[geom_id] = float(reach)
        if kind == "point":
            self._point_spheres.add(geom_id)
        return geom_id

    def move_spheres(
        self,
        geom_id: int,
        centers: np.ndarray,
        radii: np.ndarray,
        order: np.ndarray | None = None,
    ) -> None:
        """Give the committed spheres of ``geom_id`` (``add_spheres``) new ``centers`` (n, 3) and
        ``radii`` (n,), n as before, and refit the BVH to them; with ``order`` (n,) int
        (indices in [0, n)), sphere k as ``add_spheres`` was given them moves to
        ``centers[order[k]]``, ``radii[order[k]]``: a caller that keeps its spheres in an
        order of its own hands them over as they are, gathered in the one compiled pass that
        fills the buffer (NumPy's row gathers of a million shuffled rows took 4x as long). The
        buffer Embree reads is rewritten in place (each sphere in the slot it was given) and
        the geometry and scene committed again: Embree refits the geometry's tree (the bounds
        callback called for every sphere) where it has a refit builder for user geometry; the
        Embree 4.4 embreex ships rebuilds it (docs/performance.md, "Spheres moved between
        frames"), so what this saves there is the set-up around the build. A ``movable`` BVH
        only; not while a query runs.

        Queries then answer as a BVH freshly built on the moved spheres does, bit for bit: the
        callbacks compute the same hit from the same sphere whatever the tree, and an exact tie
        (two spheres at one float32 distance) goes the same way in any tree
        (``user_spheres``), by the tie keys ``add_spheres`` was given, which stay with each
        sphere given. A tree refitted over large motion answers more slowly: rebuild it
        (a new BVH) when its rays trace 1.2x slower than a fresh tree's
        (docs/performance.md)."""
        if not self.movable:
            raise RuntimeError("move_spheres needs a BVH made with movable=True")
        self._ready_to_query()
        if geom_id not in self._sphere_buffers:
            raise ValueError(f"geom_id: geometry {geom_id!r} is not a set of spheres")
        packed, _ = self._sphere_buffers[geom_id]
        centers = as_points(centers, "centers")
        radii = as_positive(radii, "radii", len(centers))
        if len(centers) != len(packed):
            raise ValueError(
                f"centers: geometry {geom_id} holds {len(packed)} spheres, got {len(centers)}"
            )
        kept = self._sphere_orders[geom_id]
        if order is not None:
            if np.shape(order) != (len(packed),):
                raise ValueError(f"order: expected shape ({len(packed)},), got {np.shape(order)}")
            order = as_indices(order, "order", len(packed))
            order = (order[kept] if len(kept) else order).astype(np.int32)
        reach = sphere_buffers.pack_spheres(
            centers, radii, kept if order is None else order, packed
        )
        self._sphere_reach[geom_id] = float(reach)
        self.coordinate_bound = max(self._bound_without_spheres, *self._sphere_reach.values())
        lib = self._lib
        scene = self._live_scene()
        geometry = lib.rtcGetGeometry(scene, geom_id)
        if geom_id in self._point_spheres:  # Embree's own buffer: it is told it changed
            lib.rtcUpdateGeometryBuffer(geometry, library.BUFFER_TYPE_VERTEX, 0)
        lib.rtcCommitGeometry(geometry)
        lib.rtcCommitScene(scene)
        self._device.check("refitting the moved spheres")

    def add_triangles(
        self, vertices: np.ndarray, faces: np.ndarray, hit_filter: GeometryFilter | None = None
    ) -> int:
        """Add a triangle mesh: ``vertices`` (m, 3) float, ``faces`` (k, 3) int in [0, m);
        ``hit_filter`` (a ``GeometryFilter``) rejects some of its hits, to cut holes in it or
        hide its back."""
        vertices = as_points(vertices, "vertices")
        faces = as_triangle_indices(faces, "faces", len(vertices))
        geometry = self._new_geometry("TRIANGLE")
        self._new_filled_buffer(
            geometry, library.BUFFER_TYPE_VERTEX, library.FORMAT_FLOAT3, vertices
        )
        self._new_filled_buffer(geometry, library.BUFFER_TYPE_INDEX, library.FORMAT_UINT3, faces)
        self.primitive_count += len(faces)
        if len(vertices):
            bound = float(np.abs(vertices).max())
            self.coordinate_bound = max(self.coordinate_bound, bound)
            self._bound_without_spheres = max(self._bound_without_spheres, bound)
        if hit_filter is not None:
            self._lib.rtcSetGeometryUserData(geometry, hit_filter.user_data.ctypes.data)
            self._lib.rtcSetGeometryIntersectFilterFunction(geometry, hit_filter.intersect)
            if hit_filter.occluded:
                self._lib.rtcSetGeometryOccludedFilterFunction(geometry, hit_filter.occluded)
            self._hit_filters.append(hit_filter)  # Embree reads its data while the BVH lives
        return self._attach(geometry, "adding triangles")

    def add_curves(self, points: np.ndarray, radii: np.ndarray, starts: np.ndarray) -> int:
        """Add round linear curves (Embree's ``ROUND_LINEAR_CURVE``): ``points`` (m, 3) and
        ``radii`` (m,) > 0 the control points, ``starts`` (k,) int the segments, segment s
        running from point ``starts[s]`` to ``starts[s] + 1`` as a cone touching a sphere at
        each end. Segments whose starts follow one another join (Embree reads neighbours from
        the index buffer), so a polyline is the run of its points. A hit's ``prim_id`` is its
        segment, ``u`` where along it (0 to 1), and its normal the surface's. Returns geom id."""
        points = as_points(points, "points")
        radii = as_positive(radii, "radii", len(points))
        starts = as_segment_starts(starts, "starts", len(points))
        geometry = self._new_geometry("ROUND_LINEAR_CURVE")
        packed = np.column_stack((points, radii)).astype(np.float32, copy=False)
        self._new_filled_buffer(geometry, library.BUFFER_TYPE_VERTEX, library.FORMAT_FLOAT4, packed)
        rows = starts.reshape(-1, 1)
        self._new_filled_buffer(geometry, library.BUFFER_TYPE_INDEX, library.FORMAT_UINT, rows)
        self.primitive_count += len(starts)
        if len(points):
            reach = (np.abs(points).max(axis=1) + radii).max()
            self.coordinate_bound = max(self.coordinate_bound, float(reach))
        return self._attach(geometry, "adding curves")

    def _check_instanceable(self, child: object, argument: str) -> None:
        """Raise unless ``child`` is a committed BVH other than this one."""
        if not isinstance(child, BVH):
            raise TypeError(f"{argument}: expected a BVH, got {type(child).__name__}")
        if child is self:
            raise ValueError(f"{argument}: a BVH cannot instance itself")
        if not child._committed:
            raise ValueError(f"{argument}: commit each child BVH before instancing it")

    def add_instance(self, other: BVH, transform: np.ndarray) -> int:
        """Place the committed BVH ``other`` by a (4, 4) affine ``transform`` (object → world)."""
        self._check_instanceable(other, "other")
        matrix = as_transform(transform, "transform")
        geometry = self._new_geometry("INSTANCE")
        self._lib.rtcSetGeometryInstancedScene(geometry, other._live_scene())
        column_major = np.ascontiguousarray(matrix.T, dtype=np.float32)
        self._lib.rtcSetGeometryTransform(
            geometry, 0, library.FORMAT_FLOAT4X4_COLUMN_MAJOR, column_major.ctypes.data
        )
        self._device.check("rtcSetGeometryTransform")
        geom_id = self._attach(geometry, "adding an instance")
        self._children.append(other)
        self._normal_matrices[geom_id] = np.linalg.inv(matrix[:3, :3]).T.astype(np.float32)
        return geom_id

    def add_instances(
        self,
        children: BVH | list[BVH],
        transforms: np.ndarray,
        child_index: np.ndarray | None = None,
    ) -> int:
        """Place committed BVHs by n affine ``transforms`` (n, 4, 4) (object → world) as ONE
        Embree instance array; returns its geometry id.

        ``children`` is one BVH, or a list of them with ``child_index`` (n,) ints choosing each
        instance's child (default: all the first). A hit in the array reports the array's id as
        ``inst_id`` and the instance's number as ``inst_prim_id``. The BVH keeps the (n, 3, 4)
        float32 transforms (48 bytes an instance) and the (n,) uint32 child index for Embree.
        """
        children = [children] if isinstance(children, BVH) else list(children)
        if not children:
            raise ValueError("children: expected at least one BVH")
        for child in children:
            self._check_instanceable(child, "children")
        problem = affine_array_problem(transforms)
        if problem is not None:
            row, text = problem
            raise ValueError(f"transforms: {text}" if row < 0 else f"transforms: row {row}: {text}")
        count = len(transforms)
        if count == 0:
            raise ValueError("transforms: expected at least one placement, got none")
        if count >= library.INVALID_ID:
            raise ValueError(f"transforms: at most {library.INVALID_ID - 1} instances, got {count}")
        # (n, 3, 4) float32 row major: RTC_FORMAT_FLOAT3X4_ROW_MAJOR, exactly M[:, :3, :4]
        packed = np.empty((count, 3, 4), np.float32)
        packed[:] = np.asarray(transforms)[:, :3, :]
        index = None
        if child_index is not None or len(children) > 1:
            if child_index is None:
                raise ValueError("child_index: required with several children")
            index = np.asarray(child_index)
            if index.shape != (count,) or (count and index.dtype.kind not in "iu"):
                raise ValueError(
                    f"child_index: expected shape ({count},) integers, got "
                    f"{index.shape} {index.dtype}"
                )
            bad = (index < 0) | (index >= len(children))
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                raise ValueError(
                    f"child_index: row {row} is {index[row]}, outside [0, {len(children)})"
                )
            index = np.ascontiguousarray(index, np.uint32)
        lib = self._lib
        geometry = self._new_geometry("INSTANCE_ARRAY")
        if index is None:
            lib.rtcSetGeometryInstancedScene(geometry, children[0]._live_scene())
        else:
            scenes = np.array([child._live_scene() for child in children], np.uint64)
            lib.rtcSetGeometryInstancedScenes(geometry, scenes.ctypes.data, len(children))
            lib.rtcSetSharedGeometryBuffer(
                geometry,
                library.BUFFER_TYPE_INDEX,
                0,
                library.FORMAT_UINT,
                index.ctypes.data,
                0,
                4,
                count,
            )
        lib.rtcSetSharedGeometryBuffer(
            geometry,
            library.BUFFER_TYPE_TRANSFORM,
            0,
            library.FORMAT_FLOAT3X4_ROW_MAJOR,
            packed.ctypes.data,
            0,
            48,
            count,
        )
        self._device.check("setting up an instance array")
        geom_id = self._attach(geometry, "adding an instance array")
        bounds = np.array([child.coordinate_bound for child in children], np.float32)
        self._arrays[geom_id] = (packed, index, bounds)
        self._children.extend(children)
        self.instance_count += count
        self.array_count += 1
        return geom_id

    def commit(self) -> None:
        """Build the BVH. Geometry cannot be added afterwards."""
        self._lib.rtcCommitScene(self._live_scene())
        self._device.check("rtcCommitScene")
        self._committed = True
        # Inverse-transpose of each geometry's linear part (identity but for instances): what
        # turns an object-space normal into a world-space one.
        table = np.zeros((max(self.geometry_count, 1), 3, 3), np.float32)
        table[:] = np.eye(3, dtype=np.float32)
        for geom_id, matrix in self._normal_matrices.items():
            table[geom_id] = matrix
        self._normal_matrix_table = table
        self._has_instances = bool(self._normal_matrices or self._arrays)
        self._normal_matrices = {}
        if self._arrays:
            table = np.zeros(
                (max(self.geometry_count, 1), instance_arrays.ARRAY_COLUMNS), np.uint64
            )
            for geom_id, (packed, index, bounds) in self._arrays.items():
                table[geom_id, instance_arrays.ARRAY_TRANSFORMS] = packed.ctypes.data
                table[geom_id, instance_arrays.ARRAY_COUNT] = len(packed)
                table[geom_id, instance_arrays.ARRAY_CHILD_INDEX] = (
                    0 if index is None else index.ctypes.data
                )
                table[geom_id, instance_arrays.ARRAY_CHILD_BOUND] = bounds.ctypes.data
            self._array_table = table

    # -- queries ------------------------------------------------------------------------------

    def run_query(self, chunk, parallel, arguments: tuple, n: int):
        """Run a query over n rays: on one thread, its ``chunk`` kernel over all of them in the
        calling thread (no threading layer: several Python threads may do so at once), else
        ``parallel``, its driver, on numba's threads; returns what the kernel returns."""
        if self.threads == 1:
            return chunk(np.empty(kernels.SCRATCH_WORDS, np.uint32), 0, n, *arguments)
        with parallel_region:
            numba.set_num_threads(self.threads)
            return parallel(*arguments)

    def _ready_to_query(self) -> None:
        """Refuse a query before ``commit``; make Embree's functions known to the kernels."""
        if not self._committed:
            raise RuntimeError("commit() the BVH before querying it")
        _prepare_kernels()

    def query_rays(self, rays: kernels.Rays) -> kernels.Rays:
        """``rays`` validated, as the kernels take them (refused before ``commit``)."""
        self._ready_to_query()
        origins = as_points(rays.origins, "origins")
        directions = as_points(rays.directions, "directions", len(origins))
        tnear, tfar = as_ray_bounds(rays.tnear, rays.tfar, len(origins))
        return kernels.Rays(origins, directions, tnear, tfar)

    def nearest_hits(self, rays: kernels.Rays, coherent: bool) -> Hits:
        """Embree's answers as it gives them (normals in object space) for validated rays."""
        n = len(rays.origins)
        hits = self.empty_hits(n)
        if n and self.geometry_count == 0:
            # Nothing to hit: the misses Embree would report (kernels' _store_miss), without
            # a call a ray.
            hits.t.fill(np.inf)
            for numbers in (hits.geom_id, hits.prim_id, hits.inst_id, hits.inst_prim_id):
                numbers.fill(-1)
            for values in (hits.normal, hits.u, hits.v):
                values.fill(0.0)
        elif n:
            arguments = (self.query(coherent), rays, *self.kernel_hits(hits))
            self.run_query(kernels.intersect_chunk, kernels.intersect, arguments, n)
        return hits

    def empty_hits(self, n: int) -> Hits:
        hits = Hits(
            t=np.empty(n, np.float32),
            geom_id=np.empty(n, np.int32),
            prim_id=np.empty(n, np.int32),
            inst_id=np.empty(n, np.int32),
            normal=np.empty((n, 3), np.float32),
            u=np.empty(n, np.float32),
            v=np.empty(n, np.float32),
        )
        # Only instance arrays have copy numbers to copy out; otherwise every hit's is -1.
        copies = bool(self.array_count)
        hits.inst_prim_id = np.empty(n, np.int32) if copies else np.full(n, -1, np.int32)
        return hits

    def query(self, coherent: bool = False) -> kernels.Query:
        """What the kernels call Embree's queries on (this committed BVH; Embree's coherent
        flag with ``coherent``), for compiled passes defined outside this class."""
        self._ready_to_query()
        return kernels.Query(self._live_scene(), kernels.query_arguments(coherent), self.lanes)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The committed BVH's world-space box as Embree holds it: ``lower``, ``upper`` (3,)
        float32 each (lower > upper when the BVH holds nothing)."""
        self._ready_to_query()
        # RTCBounds: lower x, y, z, pad, upper x, y, z, pad, aligned to 16 bytes
        row = np.zeros(12, np.float32)
        start = (-row.ctypes.data % 16) // 4
        box = row[start : start + 8]
        self._lib.rtcGetSceneBounds(self._live_scene(), box.ctypes.data)
        self._device.check("rtcGetSceneBounds")
        return box[0:3].copy(), box[4:7].copy()

    def kernel_hits(self, hits: Hits) -> tuple[kernels.NearestHits, np.ndarray | None]:
        """The kernels' view of ``hits``' arrays (``kernels.intersect``'s ``hits``), and where
        they write instance-array copy numbers (None when this BVH has no instance array)."""
        nearest = kernels.NearestHits(
            hits.t, hits.normal, hits.u, hits.v, hits.prim_id, hits.geom_id, hits.inst_id
        )
        return nearest, (hits.inst_prim_id if self.array_count else None)

    def sphere_buffer(self, geom_id: int) -> tuple[np.ndarray, np.ndarray]:
        """The sphere set ``geom_id``'s (m, 4) float32 (x, y, z, r) as stored, sphere p in slot
        ``slot[p]`` ((m,) int32; empty when slot p holds sphere p); none for another geometry."""
        return self._sphere_buffers.get(geom_id, _NO_SPHERES)

    def world_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """The tables compiled passes take object-space normals to world space with
        (``world_normals``): the (g, 3, 3) float32 normal matrices by geometry id and the
        instance arrays' (g, ``instance_arrays.ARRAY_COLUMNS``) uint64 table."""
        return self._normal_matrix_table, self._array_table

    def intersect(self, rays: kernels.Rays, coherent: bool = False) -> Hits:
        """Nearest hit of each of the ``rays`` (normals in world space)."""
        hits = self.nearest_hits(self.query_rays(rays), coherent)
        if self._has_instances:
            world_normals.hits_to_world(
                hits.inst_id,
                hits.inst_prim_id,
                hits.normal,
                self._normal_matrix_table,
                self._array_table,
            )
        return hits

    def instance_normals(
        self, inst_id: np.ndarray, inst_prim_id: np.ndarray, normals: np.ndarray
    ) -> np.ndarray:
        """(3, k) float32 world normals of k instance hits (``inst_id``, ``inst_prim_id`` (k,)
        int32) from ``normals`` (k, 3) float32 in the instanced object's space, e.g. smooth
        shading normals: ``world_normals.shading_normals`` (unit length on instance-array hits,
        unnormalised on single instances)."""
        return world_normals.shading_normals(
            np.ascontiguousarray(inst_id, np.int32),
            np.ascontiguousarray(inst_prim_id, np.int32),
            np.ascontiguousarray(normals, np.float32),
            self._normal_matrix_table,
            self._array_table,
        )

    def instance_children(self, inst_id: np.ndarray, inst_prim_id: np.ndarray) -> np.ndarray:
        """(k,) int32: for k hits, the position in its array's ``children`` of the child each
        was in (-1 for hits outside instance arrays)."""
        if not self.array_count:
            return np.full(len(inst_id), -1, np.int32)
        return instance_arrays.child_of_hits(
            np.ascontiguousarray(inst_id, np.int32),
            np.ascontiguousarray(inst_prim_id, np.int32),
            self._array_table,
        )

    def occluded(self, rays: kernels.Rays, coherent: bool = False) -> np.ndarray:
        """(n,) bool: whether anything lies on each of the ``rays`` within its bounds."""
        rays = self.query_rays(rays)
        n = len(rays.origins)
        blocked = np.zeros(n, bool)
        if n:
            arguments = (self.query(coherent), rays, blocked)
            self.run_query(kernels.occluded_chunk, kernels.occluded, arguments, n)
        return blocked

    def all_hits(
        self, rays: kernels.Rays, capacity: int = 16, out: multihit.HitBuffers | None = None
    ) -> multihit.HitBuffers:
        """Up to ``capacity`` nearest hits of each of the ``rays``, each primitive once (a
        ``filters=True`` BVH of one geometry, no instances): see ``multihit.all_hits`` for what
        it returns."""
        from embree_rt.embree import multihit

        rays = self.query_rays(rays)
        self._require_filters()
        with parallel_region:
            return multihit.all_hits(self._live_scene(), rays, int(capacity), self.threads, out)

    def committed_scene(self) -> int:
        """The committed Embree scene's handle (``RTCScene``), for a compiled pass that calls
        Embree's queries itself (``kernels.intersect_chunk``, ``point_query``) on this BVH;
        refuses before ``commit`` or after ``close``."""
        self._ready_to_query()
        return self._live_scene()

    def _require_filters(self) -> None:
        if not self.filters:
            raise RuntimeError("build the BVH with filters=True to collect every hit")
