"""Per-hit material columns (``materials.HitMaterials``) against the ``Material`` each hit is on,
and a tracer's NumPy camera rays and light segments (``tracer.RaysInNumPy``) against the
kernels that make them inside the query.

References are the ``Material`` objects read one hit at a time in float64 (the seed article's
shares ``ambient·(1 − r)(1 − t)``, ``diffuse·(1 − r)(1 − t)``, ``r·(1 − t)``; an unlit surface
shows its colour whole), not the table the columns are gathered from.
"""

from __future__ import annotations

import numpy as np
import pytest
from tolerances import RTOL32, assert_close

from embree_rt import Camera, Scene
from embree_rt.camera import camera_frame, camera_rays, tiled_samples
from embree_rt.geometry import SceneGeometry
from embree_rt.materials import HitMaterials, Material, MaterialTable, preset
from embree_rt.mesh_attributes import HitLooks
from embree_rt.tracer import RaysInNumPy

MATERIALS = [
    preset("matte", color=(0.9, 0.2, 0.1)),
    preset("metal", color=(1.0, 0.8, 0.3)),
    preset("glass"),
    Material(color=(0.2, 0.4, 0.6), unlit=True, specular=0.5, transparency=0.3),
    Material(emission=(2.0, 1.0, 0.5), attenuation_color=(0.5, 0.9, 1.0), attenuation_distance=2.0),
]


def test_columns_are_each_hits_material_and_its_shares() -> None:
    rng = np.random.default_rng(7)
    material = rng.integers(0, len(MATERIALS), 500).astype(np.intp)
    hits = HitMaterials.gather(MaterialTable.from_materials(MATERIALS), material)
    ambient, diffuse, reflect = hits.shares()
    for j, m in enumerate(material):
        expected = MATERIALS[m]
        local = (1.0 - expected.reflectivity) * (1.0 - expected.transparency)
        shares = (
            (1.0, 0.0, 0.0)
            if expected.unlit
            else (
                expected.ambient * local,
                expected.diffuse * local,
                expected.reflectivity * (1.0 - expected.transparency),
            )
        )
        assert_close([ambient[j], diffuse[j], reflect[j]], shares, rtol=RTOL32, atol=0.0)
        assert_close(hits.color[:, j], expected.color, rtol=RTOL32, atol=0.0)
        assert_close(hits.emission[:, j], expected.emission, rtol=RTOL32, atol=0.0)
        assert_close(hits.absorption[:, j], expected.absorption, rtol=RTOL32, atol=0.0)
        assert hits.lit[j] == (not expected.unlit)
        assert hits.metallic[j] == expected.metallic
        assert hits.ior[j] == np.float32(expected.ior)
        # an unlit surface neither shines nor lets light through
        assert hits.specular[j] == (0.0 if expected.unlit else np.float32(expected.specular))
        assert hits.transparency[j] == (
            0.0 if expected.unlit else np.float32(expected.transparency)
        )
    assert np.array_equal(hits.occlusion, np.ones(500)) and np.array_equal(
        hits.coverage, np.ones(500)
    )


def test_columns_that_no_material_varies_are_zero_stride_views_of_their_value() -> None:
    table = MaterialTable.from_materials(MATERIALS[:3])  # none glows, none absorbs
    hits = HitMaterials.gather(table, np.array([0, 1, 2, 1], np.intp))
    for column, value in ((hits.emission, 0.0), (hits.absorption, 0.0), (hits.coverage, 1.0)):
        assert column.strides[-1] == 0 and np.all(column == value)


def test_what_a_mesh_shows_of_its_own_is_written_over_its_hits_only() -> None:
    table = MaterialTable.from_materials(MATERIALS)
    hits = HitMaterials.gather(table, np.array([0, 4, 0, 4, 1], np.intp))
    rows = np.array([1, 3])
    color = np.float32([[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])
    looks = HitLooks(
        rows,
        color,
        emission=np.float32([[5.0, 6.0], [5.0, 6.0], [5.0, 6.0]]),
        coverage=np.float32([0.25, 1.0]),
        occlusion=np.float32([0.5, 0.75]),
    )
    looks.apply_to(hits, glows=table.glows)
    assert np.array_equal(hits.color[:, rows], color)
    expected = [MATERIALS[m].color for m in (0, 0, 1)]
    assert_close(hits.color[:, [0, 2, 4]].T, expected, rtol=RTOL32, atol=0.0)
    assert np.array_equal(hits.emission[:, rows], looks.emission)
    assert not hits.emission[:, [0, 2, 4]].any()
    assert np.array_equal(hits.coverage, [1.0, 0.25, 1.0, 1.0, 1.0])
    assert np.array_equal(hits.occlusion, [1.0, 0.5, 1.0, 0.75, 1.0])


class NumPyTracer(RaysInNumPy):
    """A scene's geometry asked only for rays as columns and segments to one target at a time,
    as a tracer of bricks is."""

    def __init__(self, geometry: SceneGeometry) -> None:
        self.geometry = geometry

    def intersect_compact(self, origins, directions, coherent=False, ids=True):
        return self.geometry.intersect_compact(origins, directions, coherent, ids)

    def occluded_toward_each(self, points, rows_each, targets):
        return [
            self.geometry.occluded_toward(points, rows, target)
            for rows, target in zip(rows_each, targets, strict=True)
        ]


@pytest.fixture(scope="module")
def geometry():
    scene = Scene()  # with its default floor
    rng = np.random.default_rng(3)
    centers = rng.uniform(-4, 4, (300, 3))
    centers[:, 1] += 4.0
    scene.add_spheres(centers, rng.uniform(0.2, 0.6, 300), "matte")
    with SceneGeometry(scene, threads=1) as built:
        built.bvh.lanes = 1  # one ray a query: the answers cannot depend on packets
        yield built


def test_numpy_camera_rays_and_light_segments_are_the_kernels(geometry) -> None:
    """The NumPy rays are the kernels' bit for bit: the camera rays come from the same
    compiled sample rule, and a segment's direction and unit direction are formed with the
    same float32 operations in the same order (no fused multiply-add: numba does not contract
    without fastmath), so the answers agree on every x86-64 ISA."""
    frame = camera_frame(Camera(position=(0, 3, 14), look_at=(0, 2, 0)), 48, 32)
    index, _ = tiled_samples(frame, 2, 0, 48 * 32 * 2)
    camera = camera_rays(frame, 2, 5)
    numpy_tracer = NumPyTracer(geometry)
    rows, surfaces, directions = geometry.intersect_camera(camera, index, ids=False)
    rows_np, surfaces_np, directions_np = numpy_tracer.intersect_camera(camera, index, ids=False)
    assert np.array_equal(directions, directions_np) and np.array_equal(rows, rows_np)
    assert np.array_equal(surfaces.position, surfaces_np.position)
    assert 0.3 < len(rows) / len(index) < 1.0 and surfaces.floor_count > 0
    targets = np.float32([[3.0, 9.0, 2.0], [-5.0, 6.0, -4.0]])
    takes = np.random.default_rng(4).random(len(rows)) < 0.9
    normal = surfaces.normal * np.where(
        (surfaces.incoming * surfaces.normal).sum(axis=0) < 0, 1, -1
    ).astype(np.float32)
    kernel = list(geometry.toward_lights(surfaces.position, normal, targets, takes))
    numpy = list(numpy_tracer.toward_lights(surfaces.position, normal, targets, takes))
    for (visible, direction, made), (visible_np, direction_np, made_np) in zip(
        kernel, numpy, strict=True
    ):
        assert made == made_np and 0 < np.count_nonzero(visible) < len(visible)
        assert np.array_equal(visible, visible_np)
        assert np.array_equal(direction, direction_np)
