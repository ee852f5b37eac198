"""Meshes placed by the thousand: ``--spheres mesh`` and a scene's ``instances`` go into the BVH
as Embree instance arrays, and render as the same meshes placed one by one do."""

from __future__ import annotations

import numpy as np

from embree_rt.geometry import SceneGeometry
from embree_rt.scene.random_field import random_field


def test_mesh_spheres_are_one_instance_array_with_each_spheres_material():
    scene = random_field(60, seed=4)
    with SceneGeometry(scene, spheres="mesh", threads=1) as geometry:
        assert geometry.bvh.geometry_count == 1  # one array, however many spheres
        assert geometry.bvh.instance_count == geometry.instance_count == 60
        # straight down onto each sphere's top: its own material, its own outward normal
        centers = scene.sphere_centers.astype(np.float64)
        origins = (centers + np.array([0.0, 50.0, 0.0])).T.astype(np.float32)
        directions = np.tile(np.float32([[0.0], [-1.0], [0.0]]), (1, 60))
        surfaces = geometry.intersect(origins, directions)
    assert surfaces.hit.all() and not surfaces.floor.any()
    np.testing.assert_array_equal(surfaces.material, scene.sphere_materials)
    top = centers[:, 1] + scene.sphere_radii
    # an icosphere of 3 subdivisions lies within 0.3% of its radius inside the sphere
    np.testing.assert_allclose(surfaces.position[1], top, atol=0.004 * scene.sphere_radii.max())
    assert np.all(surfaces.normal[1] > 0.99) and np.all(surfaces.face_normal[1] > 0.99)
