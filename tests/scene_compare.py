"""Field-by-field comparison of two ``Scene`` objects and a pinhole projection, for scene tests.

Imported by ``tests/test_scene_files.py``, ``test_mesh_import.py`` and ``test_random_field.py`` as a
plain module (``tests/`` is on ``sys.path``: the folder is not a package).
"""

from __future__ import annotations

import numpy as np

from embree_rt import Camera, Scene


def sharing(scene: Scene) -> list[int]:
    """For each mesh placement, the index of the first placement with the very same Trimesh."""
    first: dict[int, int] = {}
    return [first.setdefault(id(p.mesh), i) for i, p in enumerate(scene.meshes)]


def assert_same_scene(actual: Scene, expected: Scene, *, mesh_atol: float = 0.0) -> None:
    """Every field equal; sphere arrays exactly, mesh vertices within ``mesh_atol``."""
    assert actual.render == expected.render
    assert actual.camera == expected.camera
    assert actual.background == expected.background
    assert actual.lights == expected.lights
    assert actual.floor == expected.floor
    assert list(actual.materials.items()) == list(expected.materials.items())
    np.testing.assert_array_equal(actual.sphere_centers, expected.sphere_centers)
    np.testing.assert_array_equal(actual.sphere_radii, expected.sphere_radii)
    np.testing.assert_array_equal(actual.sphere_materials, expected.sphere_materials)
    assert actual.sphere_centers.dtype == np.float32 and actual.sphere_materials.dtype == np.int32
    assert len(actual.meshes) == len(expected.meshes)
    for got, want in zip(actual.meshes, expected.meshes, strict=True):
        assert (got.material, got.smooth) == (want.material, want.smooth)
        np.testing.assert_allclose(got.transform, want.transform, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got.mesh.faces, want.mesh.faces)
        np.testing.assert_allclose(got.mesh.vertices, want.mesh.vertices, rtol=0, atol=mesh_atol)
    assert sharing(actual) == sharing(expected)


def project(camera: Camera, aspect: float, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of ``points`` (n, 3): (n, 2) float64 screen coordinates, each in
    [-1, 1] when inside the frame (``camera.fov`` vertical, ``aspect`` = width / height), and (n,)
    float64 depth along the view direction (negative: behind the camera)."""
    position = np.asarray(camera.position, np.float64)
    forward = np.asarray(camera.look_at, np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    offset = np.asarray(points, np.float64) - position
    depth = offset @ forward
    half_height = np.tan(np.radians(camera.fov) / 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        screen = np.column_stack(
            [
                (offset @ right) / (depth * half_height * aspect),
                (offset @ up) / (depth * half_height),
            ]
        )
    return screen, depth


def in_frame(camera: Camera, aspect: float, points: np.ndarray) -> np.ndarray:
    """(n,) bool: which points the camera sees inside its frame."""
    screen, depth = project(camera, aspect, points)
    return (depth > 0) & (np.abs(screen) <= 1).all(axis=1)
