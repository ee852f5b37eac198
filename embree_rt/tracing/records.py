"""Hit records: the bookkeeping between Embree's raw answers and shading, compiled
(``intersect_records``).

After a batch is traced, one compiled pass turns each ray's raw hit (t, ids, object-space Ng)
into what shading reads — the hit point, the unit world-space geometric normal, a label (the
caller's material id) and the size of the coordinates the hit was computed from — and sorts the
hits into three groups written straight into (3, k) columns: the ground plane, the top-level
sphere set, and everything else (instances, top-level triangles), in one pass where NumPy
would take a dozen array passes and gathers per bounce.

The optional ground plane ``y = plane_y`` is analytic (an infinite plane cannot go into a BVH
without cutting the horizon and losing float32 precision far away): exact at any distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import carray, njit

from embree_rt.compiled import pointers
from embree_rt.embree import BVH, Hits, Rays
from embree_rt.embree.instance_arrays import (
    ARRAY_CHILD_BOUND,
    ARRAY_CHILD_INDEX,
    ARRAY_COUNT,
    ARRAY_LABELS,
    ARRAY_TRANSFORMS,
    is_array,
    transforms_of,
)
from embree_rt.embree.world_normals import unit_world_normal

GROUPS = ("plane", "spheres", "other")


@dataclass
class HitLabels:
    """What the caller attaches to Embree's ids, for ``intersect_records``.

    ``geometry_label`` (g,) int64 and ``geometry_scale`` (g,) float32, by top-level geometry
    id (the instance's id for an instance hit): the label of every hit on that geometry and a
    bound on its world coordinates; ``sphere_geom_id`` the top-level sphere set whose hits take
    ``sphere_label`` (m,) int32 by primitive instead (-1: none); ``plane_y`` the ground plane's
    height (None: no plane) and ``plane_label`` its label. (Sphere labels are int32, as the
    scene stores its sphere materials: no copy, 4 bytes a sphere.) ``instance_labels`` maps an
    instance array's geometry id to the (n,) int32 labels of its instances (arrays not in it
    take ``geometry_label``).
    """

    geometry_label: np.ndarray
    geometry_scale: np.ndarray
    sphere_geom_id: int = -1
    sphere_label: np.ndarray | None = None
    plane_y: float | None = None
    plane_label: int = -1
    instance_labels: dict[int, np.ndarray] | None = None


@dataclass
class HitRecords:
    """The k rays of a batch that hit, grouped plane first, then spheres, then the rest, each
    group in ray order.

    ``rays`` (k,) int64 ray numbers; ``counts`` (3,) the group sizes (``GROUPS``); ``t`` (k,)
    float32; ``position`` (3, k) float32 (on a sphere, re-projected onto its surface);
    ``normal`` (3, k) float32 unit geometric normal in world space, as the object faces (+y on
    the plane, outward on spheres); ``label`` (k,) int64; ``scale`` (k,) float32 bound on the
    coordinates (max |position| on the plane; |centre| + radius on a sphere; the table's value
    otherwise); ``incoming`` (3, k) float32 ray directions; ``prim_id``, ``inst_id`` (k,) int32
    and ``u``, ``v`` (k,) float32 as Embree reported them (``prim_id`` -1 on the plane);
    ``inst_prim_id`` (k,) int32 the instance's number inside its instance array (-1 elsewhere).
    The last five are None when the records were made without ids (``ids=False``: what a
    renderer of spheres and the floor never reads is not written).
    """

    rays: np.ndarray
    counts: np.ndarray
    t: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    label: np.ndarray
    scale: np.ndarray
    incoming: np.ndarray
    prim_id: np.ndarray | None
    inst_id: np.ndarray | None
    u: np.ndarray | None
    v: np.ndarray | None
    inst_prim_id: np.ndarray | None = None

    def group(self, name: str) -> slice:
        """The columns of group ``name`` (one of ``GROUPS``)."""
        index = GROUPS.index(name)
        start = int(self.counts[:index].sum())
        return slice(start, start + int(self.counts[index]))


PLANE, SPHERE, OTHER, MISS = 0, 1, 2, 3


@njit(nogil=True, cache=True)
def plane_crossing(oy, dy, tnear, tfar, plane_y):
    """t where a ray meets the plane y = plane_y inside [tnear, tfar] and in front of its
    origin, or NaN (behind, parallel, outside the window)."""
    if dy == 0.0:
        return np.nan
    t = (np.float32(plane_y) - oy) / dy
    if t >= max(tnear, np.float32(0.0)) and t <= tfar and t != np.inf:
        return t
    return np.nan


class RecordLabels(NamedTuple):
    """``HitLabels`` as ``build_records`` reads them: with ``has_plane`` the ground plane y =
    ``plane_y`` (float32) labelled ``plane_label``; ``sphere_geom`` the top-level sphere set's
    geometry id (-1: none), ``spheres`` (m, 4) float32 its (x, y, z, r) buffer as the BVH stores
    it, sphere p in slot ``sphere_slot[p]`` ((m,) int32; empty when slot p holds sphere p), and
    ``sphere_label`` (m,) int32; ``geometry_label`` (g,) int64 and ``geometry_scale`` (g,)
    float32 by top-level geometry id."""

    has_plane: bool
    plane_y: np.float32
    plane_label: int
    sphere_geom: int
    spheres: np.ndarray
    sphere_slot: np.ndarray
    sphere_label: np.ndarray
    geometry_label: np.ndarray
    geometry_scale: np.ndarray


@njit(nogil=True, cache=True)
def build_records(
    origins, directions, tnear, tfar, hits, inst_prim, labels, normal_matrices, arrays, ids
):
    """The compiled pass behind ``intersect_records``: classify, count, then fill.

    Inputs per ray: ``origins``, ``directions`` (3, n) float32, ``tnear``, ``tfar`` (n,) float32
    and the raw hits: ``hits`` (``kernels.NearestHits``, normals in the object's space) and
    ``inst_prim`` (n,) int32. ``labels``: a ``RecordLabels``; ``normal_matrices`` and
    ``arrays``: the BVH's tables for world normals (``world_normals``). ``ids``: whether to
    fill Embree's ids and (u, v) of each hit (else they are returned empty).
    """
    t, ng, u, v, prim, geom, inst = hits
    (
        has_plane,
        plane_y,
        plane_label,
        sphere_geom,
        spheres,
        sphere_slot,
        sphere_label,
        geometry_label,
        geometry_scale,
    ) = labels
    n = origins.shape[1]
    kind = np.empty(n, np.uint8)
    plane_t = np.empty(n, np.float32)
    counts = np.zeros(4, np.int64)
    for i in range(n):
        k = MISS if geom[i] < 0 else (SPHERE if inst[i] < 0 and geom[i] == sphere_geom else OTHER)
        if has_plane:
            tp = plane_crossing(origins[1, i], directions[1, i], tnear[i], tfar[i], plane_y)
            plane_t[i] = tp
            if tp < t[i]:  # NaN compares false; a miss has t = inf
                k = PLANE
        kind[i] = k
        counts[k] += 1
    k_total = counts[0] + counts[1] + counts[2]
    rays = np.empty(k_total, np.int64)
    out_t = np.empty(k_total, np.float32)
    position = np.empty((3, k_total), np.float32)
    normal = np.empty((3, k_total), np.float32)
    label = np.empty(k_total, np.int64)
    scale = np.empty(k_total, np.float32)
    incoming = np.empty((3, k_total), np.float32)
    k_ids = k_total if ids else 0
    out_prim = np.empty(k_ids, np.int32)
    out_inst = np.empty(k_ids, np.int32)
    out_u = np.empty(k_ids, np.float32)
    out_v = np.empty(k_ids, np.float32)
    cursor = np.array([0, counts[0], counts[0] + counts[1]], np.int64)
    for i in range(n):
        k = kind[i]
        if k == MISS:
            continue
        j = cursor[k]
        cursor[k] += 1
        rays[j] = i
        dx = directions[0, i]
        dy = directions[1, i]
        dz = directions[2, i]
        incoming[0, j] = dx
        incoming[1, j] = dy
        incoming[2, j] = dz
        if ids:
            out_u[j] = u[i]
            out_v[j] = v[i]
        if k == PLANE:
            tp = plane_t[i]
            out_t[j] = tp
            px = origins[0, i] + dx * tp
            pz = origins[2, i] + dz * tp
            position[0, j] = px
            position[1, j] = plane_y
            position[2, j] = pz
            normal[0, j] = 0.0
            normal[1, j] = 1.0
            normal[2, j] = 0.0
            label[j] = plane_label
            scale[j] = max(abs(px), abs(np.float32(plane_y)), abs(pz))
            if ids:
                out_prim[j] = -1
                out_inst[j] = -1
            continue
        ti = t[i]
        out_t[j] = ti
        if ids:
            out_prim[j] = prim[i]
            out_inst[j] = inst[i]
        if k == SPHERE:
            p = prim[i]
            s = sphere_slot[p] if len(sphere_slot) else p
            cx = np.float64(spheres[s, 0])
            cy = np.float64(spheres[s, 1])
            cz = np.float64(spheres[s, 2])
            r = np.float64(spheres[s, 3])
            # The normal from the hit point; the point re-projected onto the sphere removes the
            # rounding error along the ray.
            ox = origins[0, i] + np.float64(ti) * dx - cx
            oy = origins[1, i] + np.float64(ti) * dy - cy
            oz = origins[2, i] + np.float64(ti) * dz - cz
            length = math.sqrt(ox * ox + oy * oy + oz * oz)
            if length == 0.0:
                length = 1.0
            nx = ox / length
            ny = oy / length
            nz = oz / length
            normal[0, j] = nx
            normal[1, j] = ny
            normal[2, j] = nz
            position[0, j] = cx + r * nx
            position[1, j] = cy + r * ny
            position[2, j] = cz + r * nz
            label[j] = sphere_label[p]
            scale[j] = max(abs(cx), abs(cy), abs(cz)) + r
            continue
        top = inst[i] if inst[i] >= 0 else geom[i]
        position[0, j] = origins[0, i] + dx * ti
        position[1, j] = origins[1, i] + dy * ti
        position[2, j] = origins[2, i] + dz * ti
        wx, wy, wz = unit_world_normal(
            normal_matrices, arrays, top, inst_prim[i], ng[i, 0], ng[i, 1], ng[i, 2]
        )
        normal[0, j] = wx
        normal[1, j] = wy
        normal[2, j] = wz
        label[j] = geometry_label[top]
        scale[j] = geometry_scale[top]
    return (
        rays,
        counts[:3].copy(),
        out_t,
        position,
        normal,
        label,
        scale,
        incoming,
        out_prim,
        out_inst,
        out_u,
        out_v,
    )


# -- instance arrays ------------------------------------------------------------------------------


@njit(nogil=True, cache=True)
def finish_records(rays, start, stop, inst, inst_prim, label, scale, table):
    """Complete ``build_records``' output for the instance-array hits among columns
    [start, stop) (its "other" group), in place, and return their (stop - start,) int32
    instance numbers (-1 for hits outside an instance array).

    Per ray: ``rays`` (k,) int64 the ray of each column; ``inst``, ``inst_prim`` (n,) int32 the
    raw hits. Per column, overwritten for instance-array hits: ``label`` (k,) int64 the
    instance's own label where the array has per-instance labels; ``scale`` (k,) float32 a
    bound on the coordinates of the instance: max over axes of |translation| + the child's
    coordinate bound × the row's sum of |M|, which contains the instance's whole child.
    """
    out = np.full(stop - start, -1, np.int32)
    for j in range(start, stop):
        i = rays[j]
        g = inst[i]
        if not is_array(table, g):
            continue
        p = inst_prim[i]
        out[j - start] = p
        m = transforms_of(table, g)
        if table[g, ARRAY_LABELS] != 0:
            labels = carray(pointers.ints(table[g, ARRAY_LABELS]), table[g, ARRAY_COUNT])
            label[j] = labels[p]
        child = 0
        if table[g, ARRAY_CHILD_INDEX] != 0:
            index = carray(pointers.words32(table[g, ARRAY_CHILD_INDEX]), table[g, ARRAY_COUNT])
            child = index[p]
        bound = np.float64(carray(pointers.floats(table[g, ARRAY_CHILD_BOUND]), child + 1)[child])
        largest = 0.0
        for row in range(3):
            reach = abs(np.float64(m[p, row, 3])) + bound * (
                abs(np.float64(m[p, row, 0]))
                + abs(np.float64(m[p, row, 1]))
                + abs(np.float64(m[p, row, 2]))
            )
            largest = max(largest, reach)
        scale[j] = largest
    return out


# -- the queries --------------------------------------------------------------------------------

_NO_LABELS = np.zeros(0, np.int32)


def intersect_records(
    bvh: BVH,
    origins: np.ndarray,
    directions: np.ndarray,
    labels: HitLabels,
    tnear: float | np.ndarray = 0.0,
    tfar: float | np.ndarray = np.inf,
    coherent: bool = False,
    ids: bool = True,
) -> HitRecords:
    """The nearest hits in ``bvh`` of rays given as columns, ``origins``, ``directions``
    (3, n), with ``labels``' ground plane, as ``HitRecords``: only the rays that hit, grouped by
    kind, with world positions, unit normals and labels worked out in one compiled pass (and,
    with ``ids``, Embree's ids and (u, v) of each hit)."""
    origins = np.ascontiguousarray(origins, np.float32)
    directions = np.ascontiguousarray(directions, np.float32)
    rays = bvh.query_rays(Rays(origins.T, directions.T, tnear, tfar))
    hits = bvh.nearest_hits(rays, coherent)
    return records_of(bvh, origins, directions, rays.tnear, rays.tfar, hits, labels, ids)


def records_of(
    bvh: BVH,
    origins: np.ndarray,
    directions: np.ndarray,
    tnear: np.ndarray,
    tfar: np.ndarray,
    hits: Hits,
    labels: HitLabels,
    ids: bool = True,
) -> HitRecords:
    """The ``HitRecords`` of ``bvh``'s raw ``hits`` (``BVH.nearest_hits``) of rays given as
    (3, n) float32 columns with (n,) float32 bounds (without Embree's ids unless ``ids``;
    instance arrays need them)."""
    ids = ids or bool(bvh.array_count)
    spheres, sphere_slot = bvh.sphere_buffer(labels.sphere_geom_id)
    sphere_label = labels.sphere_label if labels.sphere_label is not None else _NO_LABELS
    has_plane = labels.plane_y is not None
    record_labels = RecordLabels(
        has_plane,
        np.float32(labels.plane_y if has_plane else 0.0),
        int(labels.plane_label),
        int(labels.sphere_geom_id) if len(spheres) else -1,
        spheres,
        sphere_slot,
        np.asarray(sphere_label, np.int32),
        np.asarray(labels.geometry_label, np.int64),
        np.asarray(labels.geometry_scale, np.float32),
    )
    normal_matrices, arrays = bvh.world_tables()
    nearest, _ = bvh.kernel_hits(hits)
    fields = build_records(
        origins,
        directions,
        tnear,
        tfar,
        nearest,
        hits.inst_prim_id,
        record_labels,
        normal_matrices,
        arrays,
        ids,
    )
    result = HitRecords(*fields)
    if not ids:
        result.prim_id = result.inst_id = result.u = result.v = None
        return result
    result.inst_prim_id = np.full(len(result.t), -1, np.int32)
    if bvh.array_count:
        other = result.group("other")
        result.inst_prim_id[other] = finish_records(
            result.rays,
            other.start,
            other.stop,
            hits.inst_id,
            hits.inst_prim_id,
            result.label,
            result.scale,
            labelled_array_table(arrays, labels),
        )
    return result


def labelled_array_table(arrays: np.ndarray, labels: HitLabels) -> np.ndarray:
    """The instance arrays' table ``arrays`` (``BVH.world_tables``) with the addresses of
    ``labels``' per-instance labels filled in."""
    if not labels.instance_labels:
        return arrays
    table = arrays.copy()
    for geom_id, values in labels.instance_labels.items():
        if not (0 <= geom_id < len(arrays) and arrays[geom_id, ARRAY_TRANSFORMS]):
            raise ValueError(f"instance_labels: geometry {geom_id} is not an instance array")
        count = int(arrays[geom_id, ARRAY_COUNT])
        if values.dtype != np.int32 or values.shape != (count,):
            raise ValueError(
                f"instance_labels: geometry {geom_id} needs ({count},) int32 labels, got "
                f"{values.shape} {values.dtype}"
            )
        if not values.flags.c_contiguous:
            raise ValueError(f"instance_labels: geometry {geom_id}'s labels must be contiguous")
        table[geom_id, ARRAY_LABELS] = values.ctypes.data
    return table
