"""embree_rt.trimesh_ray.ProximityQuery against a float64 brute force over every triangle
(trimesh's own vectorised closest point on triangles, ``trimesh.triangles.closest_point``, a
separate implementation), against trimesh's ProximityQuery where its answers are defined, and
on constructed ties."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from embree_rt.trimesh_ray import ProximityQuery, RayMeshIntersector

SCALES = (1e-4, 1.0, 1e8)


def _brute_force(mesh: trimesh.Trimesh, points: np.ndarray):
    """(n, k) float64 distance from every point to every triangle, and (n, k, 3) closest points.
    Computed with the mesh moved to the origin and scaled to unit size (trimesh's closest point
    uses absolute tolerances, right at unit scale only), then moved back."""
    center, size = mesh.bounds.mean(axis=0), mesh.scale
    triangles = (np.asarray(mesh.triangles, np.float64) - center) / size
    local = (points - center) / size
    n, k = len(points), len(triangles)
    tiled = np.tile(triangles, (n, 1, 1))
    closest = trimesh.triangles.closest_point(tiled, np.repeat(local, k, axis=0)).reshape(n, k, 3)
    return np.linalg.norm(closest - local[:, None], axis=2) * size, closest * size + center


def _tetrahedron() -> trimesh.Trimesh:
    """trimesh's test_acute_edge_case: a tetrahedron with a sharp edge (vertices 0-1)."""
    return trimesh.Trimesh(
        [[-1, 0.5, 0], [1, 0.5, 0], [0, -1, -0.5], [0, -1, 0.5]],
        [[0, 1, 2], [0, 2, 3], [0, 3, 1], [3, 2, 1]],
    )


def _meshes(scale: float, offset=(1000.0, -700.0, 300.0)):
    """A sphere, a box and a sharp-edged tetrahedron, of size ``scale``, away from the origin
    by ``offset`` times their size (1000: a frame at the origin would lose precision)."""
    shapes = (trimesh.creation.icosphere(2), trimesh.creation.box([1.0, 2.0, 0.5]), _tetrahedron())
    # process=False: trimesh's vertex merging hashes coordinates to int64, which overflows at 1e11
    return [trimesh.Trimesh((m.vertices + offset) * scale, m.faces, process=False) for m in shapes]


def _query_points(mesh: trimesh.Trimesh, seed: int) -> np.ndarray:
    """Points near the surface, on it, inside, and far away (up to 100 sizes)."""
    rng = np.random.default_rng(seed)
    center, size = mesh.bounds.mean(axis=0), mesh.scale
    near = center + rng.normal(size=(150, 3)) * size * 0.6
    far = center + rng.normal(size=(50, 3)) * size * 100
    on, _ = trimesh.sample.sample_surface(mesh, 50, seed=seed)
    return np.vstack([near, far, on, mesh.vertices[:10]])


@pytest.mark.parametrize("scale", SCALES)
def test_on_surface_matches_brute_force(scale):
    for number, mesh in enumerate(_meshes(scale)):
        points = _query_points(mesh, number)
        closest, distance, triangle = ProximityQuery(mesh).on_surface(points)
        assert closest.shape == points.shape and closest.dtype == np.float64
        assert distance.shape == (len(points),) and distance.dtype == np.float64
        assert triangle.shape == (len(points),) and triangle.dtype == np.int64
        distances, candidates = _brute_force(mesh, points)
        rows = np.arange(len(points))
        tolerance = 1e-6 * mesh.scale
        # the nearest distance, reached on the triangle reported, at the point reported
        np.testing.assert_allclose(distance, distances.min(axis=1), rtol=0, atol=tolerance)
        np.testing.assert_allclose(distances[rows, triangle], distance, rtol=0, atol=tolerance)
        np.testing.assert_allclose(closest, candidates[rows, triangle], rtol=0, atol=tolerance)
        np.testing.assert_allclose(
            np.linalg.norm(points - closest, axis=1), distance, rtol=0, atol=tolerance
        )
        # and far tighter than asked: float64 relative to the mesh, not to the origin
        assert np.abs(distance - distances.min(axis=1)).max() <= 1e-12 * mesh.scale * 100


@pytest.mark.parametrize("offset", [0.0, 1000.0])
@pytest.mark.parametrize("scale", SCALES)
def test_on_surface_matches_trimesh(scale, offset):
    for number, mesh in enumerate(_meshes(scale, offset=(offset, -0.7 * offset, 0.3 * offset))):
        points = _query_points(mesh, 10 + number)
        ours = ProximityQuery(mesh).on_surface(points)
        theirs = trimesh.proximity.ProximityQuery(mesh).on_surface(points)
        distances, candidates = _brute_force(mesh, points)
        rows = np.arange(len(points))
        tolerance = 1e-6 * mesh.scale
        # trimesh's tolerances are absolute: at 1e-4 some of its answers are not the nearest
        # point, or not on its triangle; wherever its answer is the brute force's, it is ours
        right = (np.abs(theirs[1] - distances.min(axis=1)) <= tolerance) & (
            np.abs(theirs[0] - candidates[rows, theirs[2]]).max(axis=1) <= tolerance
        )
        assert right.sum() >= len(points) // 2
        # the same point, unless the two triangles' points differ and are as near to within
        # trimesh's tie tolerance (absolute on squared distances: at 1e-4 it ties anything),
        # where trimesh may take the farther
        same = np.abs(candidates[rows, ours[2]] - candidates[rows, theirs[2]]).max(axis=1)
        same = right & (same <= tolerance)
        assert same.sum() >= right.sum() - 3
        np.testing.assert_allclose(ours[0][same], theirs[0][same], rtol=0, atol=tolerance)
        assert (ours[1][right & ~same] <= theirs[1][right & ~same]).all()
        np.testing.assert_allclose(ours[1], distances.min(axis=1), rtol=0, atol=tolerance)
        assert (theirs[1][~right] >= ours[1][~right]).all()
        if scale == 1.0:
            assert right.all()
        # where one triangle is nearest by more than any tolerance, both name it
        ordered = np.sort(distances, axis=1)
        unique = (ordered[:, 1] - ordered[:, 0] > tolerance) & right
        assert unique.sum() >= (50 if scale >= 1 else 0)  # at 1e-4 trimesh is off on them all
        np.testing.assert_array_equal(ours[2][unique], theirs[2][unique])


def _ambiguous(scale: float) -> tuple[trimesh.Trimesh, np.ndarray]:
    """trimesh's test_returns_correct_point_in_ambiguous_cases, at ``scale``: the point is
    nearer face 0 by 1e-9 sizes, but lies along face 1's normal."""
    mesh = trimesh.Trimesh(
        np.array([[0.0, 0, 0], [0, 1, 0], [-1, 0, 0], [0, 0, -1]]) * scale,
        [[0, 1, 2], [0, 1, 3]],
        process=False,
    )
    return mesh, np.array([[-0.25 - 1e-9, 0.0, -0.25]]) * scale


@pytest.mark.parametrize("scale", SCALES)
def test_near_tie_goes_to_the_face_the_point_faces(scale):
    mesh, point = _ambiguous(scale)
    closest, _, triangle = ProximityQuery(mesh).on_surface(point)
    assert triangle.tolist() == [1]
    np.testing.assert_allclose(closest[0], np.array([0, 0, -0.25]) * scale, atol=1e-12 * scale)
    if scale == 1.0:  # trimesh's own answer (its tolerance is absolute, so only at scale 1)
        assert trimesh.proximity.closest_point(mesh, point)[2].tolist() == [1]


@pytest.mark.parametrize("scale", SCALES)
def test_sharp_edge_splits_by_facing_face(scale):
    # trimesh's test_acute_edge_case: points along a line whose closest point is a sharp edge
    mesh = _tetrahedron()
    mesh = trimesh.Trimesh(mesh.vertices * scale, mesh.faces, process=False)
    points = np.column_stack([np.zeros(20), np.ones(20), np.linspace(-1, 1, 20)]) * scale
    triangle = ProximityQuery(mesh).on_surface(points)[2]
    first, second = np.split(triangle, 2)
    assert len(set(first)) == 1 and len(set(second)) == 1 and first[0] != second[0]
    # each half names the face whose normal points most towards it, as the brute force says
    distances, candidates = _brute_force(mesh, points)
    for i, face in enumerate(triangle):
        tied = np.flatnonzero(distances[i] <= distances[i].min() + 1e-8 * mesh.scale)
        direction = points[i] - candidates[i, tied]
        cosines = np.einsum("ij,ij->i", mesh.face_normals[tied], direction)
        assert face == tied[np.argmax(cosines)]


def test_exact_ties_go_to_the_lowest_index():
    # a point midway between two parallel faces that both face it: equal distances and
    # cosines; the lower index wins whichever order the faces are listed in
    top = [[0, 0, 2], [0, 1, 2], [1, 0, 2]]
    bottom = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    point = np.array([[0.2, 0.2, 1.0]])
    for vertices in (top + bottom, bottom + top):
        mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [3, 4, 5]], process=False)
        closest, distance, triangle = ProximityQuery(mesh).on_surface(point)
        assert triangle.tolist() == [0] and distance.tolist() == [1.0]
        np.testing.assert_allclose(closest[0], mesh.vertices[0] + [0.2, 0.2, 0])


def test_points_on_the_surface_take_the_lowest_index_there():
    # a fine grid: each interior vertex is shared by 6 triangles, each edge by 2; points on the
    # surface have no side to face, so the lowest index among the triangles there wins
    grid = trimesh.creation.box().subdivide().subdivide()
    points = np.vstack([grid.vertices, grid.vertices[grid.edges_unique].mean(axis=1)])
    _, distance, triangle = ProximityQuery(grid).on_surface(points)
    distances, _ = _brute_force(grid, points)
    expected = np.array([np.flatnonzero(row <= 1e-12)[0] for row in distances])
    np.testing.assert_array_equal(triangle, expected)
    assert distance.max() <= 1e-15


def test_more_ties_than_the_first_room():
    # above a cylinder cap's centre: the closest point is the centre vertex, shared by all 64
    # cap triangles (more than FIRST_CAPACITY), all facing the point: the lowest index wins
    cylinder = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=64)
    top = cylinder.bounds[1, 2]
    points = np.array([[0.0, 0.0, top + 0.5], [0.0, 0.0, top + 50.0]])
    _, distance, triangle = ProximityQuery(cylinder).on_surface(points)
    distances, _ = _brute_force(cylinder, points)
    for i in range(2):
        tied = np.flatnonzero(distances[i] <= distances[i].min() + 1e-12)
        assert len(tied) == 64 and triangle[i] == tied.min()
    np.testing.assert_allclose(distance, [0.5, 50.0], rtol=1e-15)


def test_answers_do_not_depend_on_batching():
    # the parallel path (many points) and the serial one (few) give the same bits
    mesh = _meshes(1.0)[0]
    points = _query_points(mesh, 3)
    points = np.vstack([points] * 8)
    whole = ProximityQuery(mesh).on_surface(points)
    parts = [
        ProximityQuery(mesh).on_surface(points[i : i + 100]) for i in range(0, len(points), 100)
    ]
    for k in range(3):
        np.testing.assert_array_equal(whole[k], np.concatenate([p[k] for p in parts]))


@pytest.mark.parametrize("scale", SCALES)
def test_signed_distance_agrees_with_contains_and_trimesh(scale):
    for number, mesh in enumerate(_meshes(scale)):
        points = _query_points(mesh, 20 + number)
        signed = ProximityQuery(mesh).signed_distance(points)
        assert signed.shape == (len(points),) and signed.dtype == np.float64
        distances, _ = _brute_force(mesh, points)
        nearest = distances.min(axis=1)
        np.testing.assert_allclose(np.abs(signed), nearest, rtol=0, atol=1e-6 * mesh.scale)
        off = nearest > 1e-6 * mesh.scale
        inside = RayMeshIntersector(mesh).contains_points(points[off])
        np.testing.assert_array_equal(signed[off] > 0, inside)
        assert (signed[~off] >= 0).all()  # on the surface: positive, as trimesh's
        assert (~off).sum() >= 50 and inside.any() and (~inside).any()
        if scale == 1.0:
            theirs = trimesh.proximity.signed_distance(mesh, points)
            np.testing.assert_allclose(signed[off], theirs[off], rtol=0, atol=1e-9)


def test_coplanar_signed_distance():
    # trimesh's test_coplanar_signed_distance / test_noncoplanar_signed_distance
    box = trimesh.creation.box()
    query = ProximityQuery(box)
    assert query.signed_distance([box.bounds[0] + [100, 0, 0]])[0] < 0
    assert query.signed_distance([box.bounds[0] + [100, 100, 100]])[0] < 0
    assert query.signed_distance([[0.1, 0.2, 0.3]])[0] == pytest.approx(0.2)


def test_vertex_matches_trimesh_and_brute_force():
    mesh = _meshes(1.0)[0]
    points = _query_points(mesh, 5)
    distance, vertex = ProximityQuery(mesh).vertex(points)
    gaps = np.linalg.norm(points[:, None] - mesh.vertices[None], axis=2)
    np.testing.assert_allclose(distance, gaps.min(axis=1), rtol=1e-15)
    np.testing.assert_array_equal(vertex, trimesh.proximity.ProximityQuery(mesh).vertex(points)[1])
    assert distance.dtype == np.float64 and vertex.dtype == np.int64


def test_empty_and_bad_points():
    query = ProximityQuery(_meshes(1.0)[1])
    closest, distance, triangle = query.on_surface(np.zeros((0, 3)))
    assert closest.shape == (0, 3) and distance.shape == (0,) and triangle.dtype == np.int64
    assert query.signed_distance([]).shape == (0,)
    with pytest.raises(ValueError, match=r"points must be \(n,3\)"):
        query.on_surface(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="row 1 is not finite"):
        query.on_surface([[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(ValueError, match="row 0 lies too far"):
        query.on_surface([[1e30, 0, 0]])
