"""Brute-force references for the BVH tests, independent of Embree's own traversal.

Spheres: the ray–sphere quadratic in float64 against every sphere. Triangles: trimesh's pure-NumPy
intersector (``trimesh.ray.ray_triangle.ray_triangle_id``) with a brute-force candidate finder in
place of its rtree, and embreex's own ``EmbreeScene.run``. Every reference also says which rays it
cannot decide robustly in float32 (grazing, on a triangle edge, two surfaces at the same distance, a
hit exactly on the ``tnear``/``tfar`` bound), so tests can leave those few out and assert that
they are few.

Imported by the ``tests/test_bvh_*.py`` modules as a plain module (pytest puts ``tests/`` on
``sys.path`` because the folder is not a package).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from tolerances import assert_close, ray_t_atol
from trimesh.ray.ray_triangle import ray_triangle_id

from embree_rt.embree import Rays

# Relative size of the band, around every decision boundary, inside which float32 Embree and a
# float64 reference may legitimately disagree.
AMBIGUITY = 1e-5
# Barycentric distance from a triangle's edge within which a hit may go to the neighbour, at the
# least (a grazing ray's u, v are less certain: see ``ReferenceHits.uv_atol``).
EDGE_BAND = 1e-4


@dataclass
class ReferenceHits:
    """Nearest hit of each of n rays, from a float64 reference.

    ``t`` (n,) float64, inf on a miss; ``prim_id`` (n,) int64, -1 on a miss; ``normal`` (n, 3)
    float64 unit outward/front-face normal, zero on a miss; ``u``, ``v`` (n,) float64 barycentric
    coordinates of triangle hits (NaN elsewhere); ``ambiguous`` (n,) bool, rays whose answer float32
    rounding may change (leave them out of exact comparisons). ``t_atol`` (n,) float64: how far a
    float32 t may lie from ``t`` on any ISA (``tolerances.ray_t_atol``: ulps of the coordinates
    of the ray and the primitive, over the cosine of incidence), 0 on a miss; ``uv_atol`` (n,):
    the same for u and v (the hit point's tolerance over the triangle's height), NaN off
    triangles.
    """

    t: np.ndarray
    prim_id: np.ndarray
    normal: np.ndarray
    u: np.ndarray
    v: np.ndarray
    ambiguous: np.ndarray
    t_atol: np.ndarray
    uv_atol: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """(n,) bool: rays that hit something."""
        return np.isfinite(self.t)


def float32_exact(values: np.ndarray) -> np.ndarray:
    """``values`` rounded to float32 and returned as float64, so Embree and the reference see the
    very same numbers (the BVH stores and traces float32)."""
    return np.asarray(values, np.float32).astype(np.float64)


def window(value: float | np.ndarray, count: int) -> np.ndarray:
    """A scalar or (count,) ``tnear``/``tfar`` as a (count,) float64 array."""
    return np.broadcast_to(np.asarray(value, np.float64), (count,)).copy()


def _nearest_per_ray(
    ray_index: np.ndarray, t: np.ndarray, count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ray, the pair with the smallest ``t`` and the second-smallest ``t``.

    ``ray_index``, ``t`` (p,) candidate pairs. Returns ``best`` (count,) int64 index into the pairs
    (-1 where a ray has none), ``t_first`` and ``t_second`` (count,) float64 (inf where none).
    """
    order = np.lexsort((t, ray_index))
    ray_sorted = ray_index[order]
    starts = np.flatnonzero(np.r_[True, ray_sorted[1:] != ray_sorted[:-1]]) if len(order) else []
    best = np.full(count, -1, np.int64)
    t_first = np.full(count, np.inf)
    t_second = np.full(count, np.inf)
    if len(order):
        starts = np.asarray(starts)
        rays = ray_sorted[starts]
        best[rays] = order[starts]
        t_first[rays] = t[order[starts]]
        has_second = np.r_[starts[1:], len(order)] - starts > 1
        t_second[rays[has_second]] = t[order[starts[has_second] + 1]]
    return best, t_first, t_second


# -- spheres --------------------------------------------------------------------------------------


def _sphere_candidates(
    origins: np.ndarray, directions: np.ndarray, centers: np.ndarray, radii: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every (ray, sphere) pair whose line passes within 1.01 radii of the centre (a superset).

    Uses the expanded form |o-c|^2 = |o|^2 - 2 o.c + |c|^2 so the bulk of the work is two matrix
    products; the exact test on the few survivors is done in the direct form by the caller.
    """
    block = max(1, 4_000_000 // max(len(centers), 1))
    c2 = np.einsum("ij,ij->i", centers, centers)
    reach = (1.01 * radii) ** 2 + 1e-9 * (1.0 + c2.max(initial=0.0))
    ray_parts, sphere_parts = [], []
    for start in range(0, len(origins), block):
        o = origins[start : start + block]
        d = directions[start : start + block]
        a = np.einsum("ij,ij->i", d, d)[:, None]
        o2 = np.einsum("ij,ij->i", o, o)[:, None]
        oc2 = o2 - 2.0 * (o @ centers.T) + c2[None, :]
        half_b = np.einsum("ij,ij->i", d, o)[:, None] - d @ centers.T
        # squared distance from the centre to the ray's line
        closest2 = oc2 - half_b * half_b / a
        rays, spheres = np.nonzero(closest2 <= reach[None, :] + 1e-9 * o2)
        ray_parts.append(rays + start)
        sphere_parts.append(spheres)
    return np.concatenate(ray_parts), np.concatenate(sphere_parts)


def sphere_hits(
    origins: np.ndarray,
    directions: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    tnear: float | np.ndarray = 0.0,
    tfar: float | np.ndarray = np.inf,
    ambiguity: float = AMBIGUITY,
    absolute: float = 0.0,
) -> ReferenceHits:
    """Nearest hit of each ray on a set of solid-surface spheres, by the float64 quadratic.

    ``origins``, ``directions`` (n, 3); ``centers`` (m, 3); ``radii`` (m,); ``tnear``, ``tfar``
    scalars or (n,). A hit is the smallest root t of |o + t d - c| = r with tnear <= t <= tfar,
    so a ray starting inside a sphere hits its far side. The normal is (hit - c) / r: outward.
    ``ambiguity`` (relative to the ray-to-sphere distance) plus ``absolute`` (in coordinate
    units: a few float32 ulps of the coordinates) is the width of the undecidable band.
    """
    o = np.asarray(origins, np.float64)
    d = np.asarray(directions, np.float64)
    c = np.asarray(centers, np.float64)
    r = np.asarray(radii, np.float64)
    n = len(o)
    near, far = window(tnear, n), window(tfar, n)
    rays, spheres = _sphere_candidates(o, d, c, r)

    oc = o[rays] - c[spheres]
    a = np.einsum("ij,ij->i", d[rays], d[rays])
    half_b = np.einsum("ij,ij->i", d[rays], oc)
    cc = np.einsum("ij,ij->i", oc, oc) - r[spheres] ** 2
    disc = half_b * half_b - a * cc
    root = np.sqrt(np.maximum(disc, 0.0))
    t0 = (-half_b - root) / a
    t1 = (-half_b + root) / a

    # Float32 rounding inside Embree scales with the distance from the ray origin to the sphere
    # (inputs are float32 already: see ``float32_exact``).
    length = np.sqrt(a)
    distance = np.sqrt(np.einsum("ij,ij->i", oc, oc))
    scale = distance + r[spheres]
    band = ambiguity * scale + absolute
    slack_t = band / length
    closest = np.sqrt(np.maximum(distance**2 - half_b**2 / a, 0.0))
    grazing = np.abs(closest - r[spheres]) <= band

    real = disc >= 0.0
    ok0 = real & (t0 >= near[rays]) & (t0 <= far[rays])
    ok1 = real & (t1 >= near[rays]) & (t1 <= far[rays])
    t_pair = np.where(ok0, t0, np.where(ok1, t1, np.inf))
    keep = np.isfinite(t_pair)
    best, t_first, t_second = _nearest_per_ray(rays[keep], t_pair[keep], n)

    hit = best >= 0
    pairs = np.flatnonzero(keep)[best[hit]]
    t = t_first
    prim = np.full(n, -1, np.int64)
    prim[hit] = spheres[pairs]
    normal = np.zeros((n, 3))
    point = o[hit] + t[hit, None] * d[hit]
    normal[hit] = (point - c[spheres[pairs]]) / r[spheres[pairs], None]

    t_atol = np.zeros(n)
    t_atol[hit] = ray_t_atol(
        o[hit],
        d[hit],
        np.abs(c[spheres[pairs]]).max(axis=1) + r[spheres[pairs]],
        normals=normal[hit],
    )

    ambiguous = np.zeros(n, bool)
    # two surfaces at nearly the same distance: either may be reported
    tie_slack = np.zeros(n)
    tie_slack[hit] = slack_t[pairs]
    ambiguous[hit] |= t_second[hit] - t_first[hit] <= tie_slack[hit]
    # grazing a sphere that lies at or before the nearest hit
    approach = -half_b / a
    reach_t = np.where(np.isfinite(t[rays]), t[rays], far[rays]) + slack_t
    ambiguous[rays[grazing & (approach <= reach_t) & (approach >= near[rays] - slack_t)]] = True
    # a root sitting on the tnear or tfar bound
    for root_t in (t0, t1):
        on_bound = real & (
            (np.abs(root_t - near[rays]) <= slack_t) | (np.abs(root_t - far[rays]) <= slack_t)
        )
        ambiguous[rays[on_bound]] = True
    nan = np.full(n, np.nan)
    return ReferenceHits(t, prim, normal, nan, nan.copy(), ambiguous, t_atol, nan.copy())


# -- triangles ------------------------------------------------------------------------------------


class _BruteForceTree:
    """Stands in for trimesh's rtree index: ``intersection`` is a plain AABB-overlap scan."""

    def __init__(self, triangles: np.ndarray) -> None:
        self.lower = triangles.min(axis=1)
        self.upper = triangles.max(axis=1)
        self.bounds = np.r_[self.lower.min(axis=0), self.upper.max(axis=0)]

    def intersection(self, box: np.ndarray) -> np.ndarray:
        box = np.asarray(box)
        overlap = (self.lower <= box[3:]).all(axis=1) & (self.upper >= box[:3]).all(axis=1)
        return np.flatnonzero(overlap)


def triangle_heights(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k,) float64 smallest height of each of the ``faces`` (k, 3) into ``vertices`` (m, 3):
    twice the area over the longest edge. A point error e moves barycentrics by up to e / height.
    """
    tri = np.asarray(vertices, np.float64)[np.asarray(faces)]
    edges = tri[:, [1, 2, 0]] - tri
    doubled_area = np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    return doubled_area / np.linalg.norm(edges, axis=2).max(axis=1)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(k, 3) float64 unit normals (v1 - v0) x (v2 - v0) of ``faces`` (k, 3) into ``vertices``."""
    tri = np.asarray(vertices, np.float64)[np.asarray(faces)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def triangle_hits(
    origins: np.ndarray,
    directions: np.ndarray,
    vertices: np.ndarray,
    faces: np.ndarray,
    tnear: float | np.ndarray = 0.0,
    tfar: float | np.ndarray = np.inf,
) -> ReferenceHits:
    """Nearest hit of each ray on a triangle mesh, by trimesh's NumPy ray–triangle test.

    ``origins``, ``directions`` (n, 3); ``vertices`` (m, 3); ``faces`` (k, 3) int; ``tnear``,
    ``tfar`` scalars or (n,). t is in units of the direction's length; ``u``, ``v`` are the
    barycentric weights of vertices 1 and 2 (hit = (1-u-v) v0 + u v1 + v v2); the normal is the
    unit (v1 - v0) x (v2 - v0), whichever side the ray comes from.
    """
    o = np.asarray(origins, np.float64)
    d = np.asarray(directions, np.float64)
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    n = len(o)
    near, far = window(tnear, n), window(tfar, n)
    triangles = vertices[faces]
    tri, rays, location = ray_triangle_id(
        triangles, o, d, tree=_BruteForceTree(triangles), multiple_hits=True
    )
    t_pair = np.einsum("ij,ij->i", location - o[rays], d[rays]) / np.einsum(
        "ij,ij->i", d[rays], d[rays]
    )
    if len(tri):
        weights = trimesh.triangles.points_to_barycentric(triangles[tri], location)
    else:
        weights = np.zeros((0, 3))

    # Float32 rounding inside Embree scales with the distance from the origin to the triangle.
    size = np.abs(triangles[tri] - triangles[tri][:, :1]).max(axis=(1, 2))
    scale = np.linalg.norm(triangles[tri][:, 0] - o[rays], axis=1) + size
    slack_t = AMBIGUITY * scale / np.linalg.norm(d[rays], axis=1)
    in_window = (t_pair >= near[rays]) & (t_pair <= far[rays])
    best, t_first, t_second = _nearest_per_ray(rays[in_window], t_pair[in_window], n)
    # How well float32 knows each pair's t, and u, v (the point's tolerance over the height).
    pair_t_atol = ray_t_atol(
        o[rays],
        d[rays],
        np.abs(triangles[tri]).max(axis=(1, 2)),
        normals=face_normals(vertices, faces[tri]),
    )
    pair_uv_atol = (
        pair_t_atol * np.linalg.norm(d[rays], axis=1) / triangle_heights(vertices, faces[tri])
    )

    hit = best >= 0
    pairs = np.flatnonzero(in_window)[best[hit]]
    prim = np.full(n, -1, np.int64)
    prim[hit] = tri[pairs]
    normal = np.zeros((n, 3))
    normal[hit] = face_normals(vertices, faces[tri[pairs]])
    u = np.full(n, np.nan)
    v = np.full(n, np.nan)
    u[hit] = weights[pairs, 1]
    v[hit] = weights[pairs, 2]
    t_atol = np.zeros(n)
    t_atol[hit] = pair_t_atol[pairs]
    uv_atol = np.full(n, np.nan)
    uv_atol[hit] = pair_uv_atol[pairs]

    ambiguous = np.zeros(n, bool)
    tie_slack = np.zeros(n)
    tie_slack[hit] = slack_t[pairs]
    ambiguous[hit] |= t_second[hit] - t_first[hit] <= tie_slack[hit]
    # on an edge or a vertex (within float32's reach of u, v): the neighbour (or nothing, at the
    # mesh border) may be reported
    on_edge = (
        weights.min(axis=1, initial=1.0) <= np.maximum(EDGE_BAND, pair_uv_atol)
        if len(tri)
        else np.zeros(0, bool)
    )
    reach_t = np.where(np.isfinite(t_first[rays]), t_first[rays], far[rays]) + slack_t
    ambiguous[rays[on_edge & (t_pair <= reach_t)]] = True
    on_bound = (np.abs(t_pair - near[rays]) <= slack_t) | (np.abs(t_pair - far[rays]) <= slack_t)
    ambiguous[rays[on_bound]] = True
    return ReferenceHits(t_first, prim, normal, u, v, ambiguous, t_atol, uv_atol)


@dataclass
class EmbreexHits:
    """embreex's answer: ``t`` (n,) float64 inf on a miss, ``prim_id`` (n,) int32 -1 on a miss,
    ``u``, ``v`` (n,) float32, ``normal`` (n, 3) float32 unnormalised geometric normal."""

    t: np.ndarray
    prim_id: np.ndarray
    u: np.ndarray
    v: np.ndarray
    normal: np.ndarray


def embreex_hits(
    origins: np.ndarray, directions: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> EmbreexHits:
    """Nearest hits from embreex's own ``EmbreeScene.run`` (tnear 0, tfar inf) on one mesh."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.asarray(vertices, np.float32), np.asarray(faces, np.int32))
    out = scene.run(
        np.ascontiguousarray(origins, np.float32),
        np.ascontiguousarray(directions, np.float32),
        output=1,
    )
    prim = out["primID"].astype(np.int32)
    hit = out["geomID"] >= 0
    prim[~hit] = -1
    t = np.where(hit, out["tfar"].astype(np.float64), np.inf)
    return EmbreexHits(t, prim, out["u"], out["v"], out["Ng"])


# -- scene and ray layouts ------------------------------------------------------------------------


def rays_toward_box(
    rng: np.random.Generator,
    count: int,
    lower: np.ndarray,
    upper: np.ndarray,
    distance: float,
    scale_directions: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """``count`` rays from a shell ``distance`` around the box centre to random points in the box.

    Returns origins and directions, (count, 3) float64. Directions have random lengths in
    [0.2, 5] unless ``scale_directions`` is False (then unit length), so tests also check that
    t is parametric in the direction's own length.
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    centre = (lower + upper) / 2
    around = rng.normal(size=(count, 3))
    origins = centre + distance * around / np.linalg.norm(around, axis=1, keepdims=True)
    targets = rng.uniform(lower, upper, size=(count, 3))
    directions = targets - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    if scale_directions:
        directions *= rng.uniform(0.2, 5.0, size=(count, 1))
    return origins, directions


def affine(rotation_axis, angle: float, scale, translation) -> np.ndarray:
    """(4, 4) float64 matrix T @ R @ S: scale, then rotate about ``rotation_axis``, then move."""
    rotation = trimesh.transformations.rotation_matrix(angle, rotation_axis)
    scaling = np.diag([*np.asarray(scale, float), 1.0])
    moving = trimesh.transformations.translation_matrix(translation)
    return moving @ rotation @ scaling


# rotation about a skew axis, non-uniform scale, translation
TRANSFORMS = [
    affine([1, 2, 3], 0.7, [0.5, 1.5, 2.5], [3.0, -1.0, 2.0]),
    affine([0, 0, 1], 2.0, [1.0, 1.0, 1.0], [-4.0, 2.0, 0.0]),
    affine([1, -1, 0], -1.1, [2.0, 0.7, 1.2], [0.5, 4.0, -3.0]),
]


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) float64 ``points`` mapped by the (4, 4) affine ``matrix``."""
    return np.asarray(points, np.float64) @ matrix[:3, :3].T + matrix[:3, 3]


def random_soup(rng: np.random.Generator, count: int, extent: float = 4.0):
    """A random triangle soup: ``count`` well-shaped triangles scattered in a cube.

    Returns vertices (3 count, 3) float64 and faces (count, 3) int64.
    """
    centres = rng.uniform(-extent, extent, size=(count, 1, 3))
    corners = rng.normal(scale=0.6, size=(count, 3, 3))
    # keep triangles away from degenerate (needle or zero-area) shapes
    area = np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    corners[area < 0.05] = np.array([[0, 0, 0], [0.8, 0, 0], [0, 0.8, 0.2]])
    vertices = (centres + corners).reshape(-1, 3)
    faces = np.arange(3 * count).reshape(count, 3)
    return vertices, faces


# -- comparing the BVH's answer with a reference --------------------------------------------------


def near_triangle_edge(u: np.ndarray, v: np.ndarray, tolerance=EDGE_BAND) -> np.ndarray:
    """(n,) bool: barycentric (u, v) within ``tolerance`` (a number or (n,)) of a triangle's
    edge."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    return np.minimum(np.minimum(u, v), 1.0 - u - v) <= tolerance


def unit(vectors: np.ndarray) -> np.ndarray:
    """(n, 3) float64 ``vectors`` scaled to unit length (zero rows stay zero)."""
    vectors = np.asarray(vectors, np.float64)
    length = np.linalg.norm(vectors, axis=1, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 0)


def _first_rays(mask: np.ndarray, limit: int = 5) -> list[int]:
    return np.flatnonzero(mask)[:limit].tolist()


def assert_hits_match(
    hits,
    ref: ReferenceHits,
    geom_id: int | np.ndarray,
    inst_id: int | np.ndarray = -1,
    *,
    triangles: bool = False,
    t_rtol: float = 1e-4,
    normal_cos: float = 0.9999,
    max_ambiguous: float = 0.01,
    min_hit_fraction: float = 0.2,
    min_miss_fraction: float = 0.0,
) -> np.ndarray:
    """Assert the BVH's ``hits`` equal the reference on every ray the reference is sure about.

    ``geom_id`` / ``inst_id``: what a hit must report, scalar or (n,) per ray (used where the
    reference hits). t must lie within ``t_rtol`` of the reference plus its per-ray ``t_atol``.
    For ``triangles``, barycentric u, v are compared too (within ``ref.uv_atol``), and rays the
    BVH hits on a triangle edge count as undecidable (trimesh drops near-misses it cannot see). Also
    checks that the comparison is not vacuous: few undecidable rays, enough hits (and misses).
    Returns the (n,) bool mask of rays that were compared.
    """
    n = len(ref.t)
    ours_hit = np.isfinite(hits.t)
    sure = ~ref.ambiguous
    if triangles:
        band = np.maximum(EDGE_BAND, np.nan_to_num(ref.uv_atol, nan=0.0))
        sure &= ~(ours_hit & near_triangle_edge(hits.u, hits.v, band))
    assert sure.mean() >= 1.0 - max_ambiguous, f"only {sure.mean():.4f} of rays decidable"
    assert (ref.hit & sure).mean() >= min_hit_fraction, "too few reference hits to be a test"
    assert (~ref.hit & sure).mean() >= min_miss_fraction, "too few reference misses"

    wrong = sure & (ours_hit != ref.hit)
    assert not wrong.any(), (
        f"{wrong.sum()} rays hit/miss differently, e.g. rays {_first_rays(wrong)}: "
        f"ours t={hits.t[wrong][:5]}, reference t={ref.t[wrong][:5]}"
    )
    both = sure & ref.hit
    missed = sure & ~ref.hit
    assert np.all(np.isinf(hits.t[missed])) and np.all(hits.t[missed] > 0)
    for name in ("geom_id", "prim_id", "inst_id"):
        assert np.all(getattr(hits, name)[missed] == -1), f"{name} must be -1 on a miss"

    assert_close(
        hits.t[both],
        ref.t[both],
        atol=ref.t_atol[both],
        rtol=t_rtol,
        err_msg="t differs from the reference",
    )
    bad_prim = both & (hits.prim_id != ref.prim_id)
    assert not bad_prim.any(), (
        f"{bad_prim.sum()} rays report another primitive, e.g. rays {_first_rays(bad_prim)}: "
        f"ours {hits.prim_id[bad_prim][:5]}, reference {ref.prim_id[bad_prim][:5]}"
    )
    expected_geom = np.broadcast_to(geom_id, (n,))
    expected_inst = np.broadcast_to(inst_id, (n,))
    assert np.array_equal(hits.geom_id[both], expected_geom[both]), "geom_id differs"
    assert np.array_equal(hits.inst_id[both], expected_inst[both]), "inst_id differs"

    cosine = np.einsum("ij,ij->i", unit(hits.normal[both]), ref.normal[both])
    bad_normal = cosine < normal_cos
    assert not bad_normal.any(), (
        f"{bad_normal.sum()} normals point elsewhere (cos down to {cosine.min():.6f}), e.g. "
        f"ours {hits.normal[both][bad_normal][:3].tolist()} vs "
        f"reference {ref.normal[both][bad_normal][:3].tolist()}"
    )
    if triangles:
        uv_atol = ref.uv_atol[both]
        assert_close(hits.u[both], ref.u[both], atol=uv_atol, rtol=0.0, err_msg="u differs")
        assert_close(hits.v[both], ref.v[both], atol=uv_atol, rtol=0.0, err_msg="v differs")
    return sure


def occluded_or_below_plane(
    bvh, origins: np.ndarray, directions: np.ndarray, tnear, tfar, plane_y: float
) -> np.ndarray:
    """(n,) bool: ``bvh.occluded`` of rays ``origins``, ``directions`` (n, 3) float32 within
    [tnear, tfar], or the ground plane y = ``plane_y`` crossed there, decided in float32 as the
    renderer's kernels decide it (``embree_rt.tracing.records.plane_crossing``: t = (plane_y -
    oy) / dy, counted when max(tnear, 0) <= t <= tfar and finite). NumPy's float32 division and
    comparisons are IEEE's, as the kernel's, so the answers are the kernel's bit for bit on
    every x86-64 ISA (no fused or reordered arithmetic is involved)."""
    origins = np.asarray(origins, np.float32)
    directions = np.asarray(directions, np.float32)
    count = len(origins)
    near = np.broadcast_to(np.asarray(tnear, np.float32), (count,))
    far = np.broadcast_to(np.asarray(tfar, np.float32), (count,))
    dy = directions[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (np.float32(plane_y) - origins[:, 1]) / dy
    crossed = (dy != 0) & (t >= np.maximum(near, np.float32(0))) & (t <= far) & (t != np.inf)
    return bvh.occluded(Rays(origins, directions, tnear, tfar)) | crossed
