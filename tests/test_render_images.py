"""Rendered-image properties on tiny images: shadows, mirrors, lenses, energy, determinism."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import embree_rt.geometry as geometry_module
from embree_rt import (
    Background,
    Camera,
    Checker,
    Floor,
    Material,
    PointLight,
    Scene,
    preset,
    random_field,
    render,
)
from embree_rt.batches import batch_ranges
from embree_rt.embree import BVH


def pixel_of(camera: Camera, point, width: int, height: int) -> tuple[int, int]:
    """(row, column) where ``point`` lands, by the pinhole model written out independently."""
    position = np.asarray(camera.position, float)
    w = position - np.asarray(camera.look_at, float)
    w /= np.linalg.norm(w)
    u = np.cross(camera.up, w)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    d = np.asarray(point, float) - position
    depth = -d @ w
    half = np.tan(np.radians(camera.fov) / 2)
    x = (d @ u) / (depth * half * width / height)
    y = (d @ v) / (depth * half)
    return int((1 - y) / 2 * height), int((x + 1) / 2 * width)


def brightness(image: np.ndarray, row: int, col: int, radius: int = 1) -> float:
    return float(image[row - radius : row + radius + 1, col - radius : col + radius + 1].mean())


def test_shadowed_floor_is_darker_than_lit_floor() -> None:
    # A plain matte floor and a red ball: only the direct light differs between the two points,
    # and a gray pixel proves the camera sees the floor there, not the ball.
    gray = (0.8, 0.8, 0.8)
    scene = Scene(
        camera=Camera(position=(0, 4, 6), look_at=(0, 0, 0), fov=50),
        floor=Floor(checker=Checker(gray, gray), material=Material(ambient=0.1, diffuse=0.8)),
    )
    scene.lights.append(PointLight(position=(-6, 10, 0)))
    scene.add_material("red", Material(color=(1, 0, 0)))
    scene.add_sphere((0, 1.5, 0), 1.0, "red")
    width, height = 96, 72
    image = render(scene, width=width, height=height, spp=4, max_depth=2, seed=1).image
    # The light casts the ball's shadow around (1.06, 0, 0), away from the light.
    shadow = image[pixel_of(scene.camera, (1.1, 0.0, 0.8), width, height)]
    lit = image[pixel_of(scene.camera, (-1.1, 0.0, 0.8), width, height)]
    for color in (shadow, lit):
        assert color[0] == pytest.approx(color[1], rel=1e-4)  # floor, not ball
    assert shadow[0] < 0.5 * lit[0]


def test_removing_the_light_blocker_removes_the_shadow() -> None:
    def floor_at(with_sphere: bool) -> float:
        scene = Scene(camera=Camera(position=(0, 4, 6), look_at=(0, 0, 0), fov=50))
        scene.lights.append(PointLight(position=(0, 10, 0)))
        if with_sphere:
            scene.add_sphere((0, 1.5, -3), 1.0, "matte")  # off to the back: casts no shadow here
        image = render(scene, width=64, height=48, spp=2, max_depth=2, seed=3).image
        return brightness(image, *pixel_of(scene.camera, (0, 0, 1.2), 64, 48))

    assert floor_at(True) == pytest.approx(floor_at(False), rel=1e-5)


def test_mirror_sphere_shows_the_color_of_what_it_faces() -> None:
    def centre_color(material: str) -> np.ndarray:
        scene = Scene(
            camera=Camera(position=(0, 1, 5), look_at=(0, 1, 0), fov=30),
            floor=None,
            background=Background(horizon=(0.2, 0.2, 0.2), zenith=(0.2, 0.2, 0.2)),
        )
        scene.add_material("red", Material(color=(1.0, 0.0, 0.0), ambient=1.0, diffuse=0.0))
        scene.lights.append(PointLight(position=(5, 5, 5)))
        scene.add_sphere((0, 1, 0), 1.0, material)
        scene.add_sphere((0, 1, 12), 4.0, "red")  # behind the camera: only a mirror shows it
        image = render(scene, width=41, height=41, spp=1, max_depth=3, seed=0).image
        return image[18:23, 18:23].reshape(-1, 3).mean(axis=0)

    mirror = centre_color("mirror")
    matte = centre_color("matte")
    assert mirror[0] > 3 * max(mirror[1], mirror[2])
    assert matte[0] < 1.5 * matte[1]  # a matte sphere in the same place shows no red


def _quad(x0: float, x1: float, z: float) -> trimesh.Trimesh:
    vertices = np.array([[x0, -20, z], [x1, -20, z], [x1, 20, z], [x0, 20, z]], float)
    return trimesh.Trimesh(vertices, np.array([[0, 1, 2], [0, 2, 3]]), process=False)


def test_glass_sphere_flips_what_lies_behind_it() -> None:
    """A ball lens inverts the image of a distant wall: red on the left is seen on the right."""
    scene = Scene(camera=Camera(position=(0, 0, 8), look_at=(0, 0, 0), fov=25), floor=None)
    scene.add_material("red", Material(color=(1, 0, 0), ambient=1.0, diffuse=0.0))
    scene.add_material("blue", Material(color=(0, 0, 1), ambient=1.0, diffuse=0.0))
    scene.add_mesh(_quad(-40, 0, -6), "red")
    scene.add_mesh(_quad(0, 40, -6), "blue")
    scene.add_material("clear", preset("glass", transparency=1.0, specular=0.0))
    scene.add_sphere((0, 0, 0), 1.0, "clear")
    width = height = 81
    image = render(scene, width=width, height=height, spp=1, max_depth=6, seed=0).image
    row, col = pixel_of(scene.camera, (0, 0, 0), width, height)
    left_inside = image[row, col - 5]
    right_inside = image[row, col + 5]
    left_outside = image[row, 5]
    assert left_outside[0] > left_outside[2]  # direct view: red wall on the left
    assert left_inside[2] > 2 * left_inside[0]  # through the lens: blue on the left
    assert right_inside[0] > 2 * right_inside[2]


def _showcase_like_scene() -> Scene:
    scene = Scene(camera=Camera(position=(0, 1.5, 6), look_at=(0, 0.8, 0), fov=45))
    scene.lights += [PointLight((4, 6, 4), intensity=0.8), PointLight((-4, 5, 2), intensity=0.5)]
    scene.add_material("gold", preset("metal", color=(1.0, 0.8, 0.3)))
    scene.add_material("green_glass", preset("glass", color=(0.5, 1.0, 0.6)))
    scene.add_sphere((0, 1, 0), 1.0, "glass")
    scene.add_sphere((-2.2, 0.8, -0.5), 0.8, "gold")
    scene.add_sphere((2.2, 0.8, -0.5), 0.8, "mirror")
    scene.add_sphere((1.0, 0.4, 1.6), 0.4, "green_glass")
    scene.add_sphere((-1.0, 0.35, 1.8), 0.35, "matte")
    return scene


def test_no_nan_or_negative_values_with_glass_grazing_and_total_internal_reflection() -> None:
    image = render(_showcase_like_scene(), width=80, height=60, spp=4, max_depth=6, seed=7).image
    assert np.isfinite(image).all()
    assert (image >= 0).all()


def test_weights_never_exceed_one_in_a_white_furnace() -> None:
    """Sky of radiance 1 everywhere, lossless glass and mirrors, nothing else lit: no pixel may
    exceed 1, because reflection and refraction only redistribute the ray's weight."""
    scene = Scene(
        camera=Camera(position=(0, 0, 6), look_at=(0, 0, 0), fov=40),
        floor=None,
        background=Background(horizon=(1, 1, 1), zenith=(1, 1, 1)),
    )
    lossless_glass = Material(color=(1, 1, 1), ambient=0, diffuse=0, transparency=1.0, ior=1.52)
    scene.add_material("lossless_glass", lossless_glass)
    scene.add_material("perfect_mirror", Material(ambient=0, diffuse=0, reflectivity=1.0))
    scene.add_sphere((-1.1, 0, 0), 1.0, "lossless_glass")
    scene.add_sphere((1.1, 0, 0), 1.0, "perfect_mirror")
    image = render(scene, width=64, height=48, spp=2, max_depth=8, seed=0).image
    assert image.max() <= 1.0 + 1e-5
    assert image.min() > 0.5  # and little is lost: only deep paths are cut off


def test_same_seed_same_image_for_any_thread_count_and_batch_size() -> None:
    scene = _showcase_like_scene()
    settings = dict(width=48, height=36, spp=3, max_depth=6, seed=11)
    reference = render(scene, threads=1, batch_size=1 << 18, **settings).image
    # Bitwise, on any ISA (the bits themselves differ between machines, not between these
    # renders on one): a sample's rays are the same float32 values whatever batch carries
    # them (counter-based jitter); Embree traces each ray of a packet in its own SIMD lane, and
    # NumPy's float32 arithmetic rounds each element on its own (its vectorised exp and log run
    # the same code on every element, the tail of an array included); and each pixel sums its
    # contributions in ray order. Checked with Embree's SSE4.2, AVX and AVX2 kernels.
    assert np.array_equal(reference, render(scene, threads=2, batch_size=1 << 18, **settings).image)
    assert np.array_equal(reference, render(scene, threads=2, batch_size=999, **settings).image)
    different_seed = render(scene, threads=2, **{**settings, "seed": 12}).image
    assert not np.array_equal(reference, different_seed)


def test_analytic_and_tessellated_spheres_render_nearly_the_same_image() -> None:
    from embree_rt.film import tonemap

    scene = _showcase_like_scene()
    settings = dict(width=96, height=72, spp=4, max_depth=6, seed=5)
    analytic = tonemap(render(scene, spheres="analytic", **settings).image).astype(float)
    mesh = tonemap(render(scene, spheres="mesh", **settings).image).astype(float)
    assert np.abs(analytic - mesh).mean() / 255 < 0.01


@pytest.mark.parametrize(
    "total, batch_size, spp, workers",
    [
        (2073600, 262144, 1, 2),
        (2073600 * 8, 262144, 8, 2),
        (100 * 4, 30, 4, 3),
        (10, 262144, 1, 2),
        (2073600, 262144, 1, 1),
        (7 * 9, 1, 9, 4),
    ],
)
def test_batches_tile_the_samples_in_whole_pixels(total, batch_size, spp, workers) -> None:
    batches = batch_ranges(total, batch_size, spp, workers)
    starts = [start for start, _ in batches]
    counts = [count for _, count in batches]
    assert starts[0] == 0 and sum(counts) == total
    assert all(a + n == b for a, n, b in zip(starts, counts, starts[1:], strict=False))
    assert all(start % spp == 0 and count % spp == 0 and count > 0 for start, count in batches)
    assert max(counts) <= max(spp, batch_size // spp * spp)
    if workers > 1 and len(range(0, total, max(1, batch_size // spp) * spp)) > workers:
        # the last round is cut finer: its batches are at most about a third of a full one
        assert max(counts[-workers:]) <= max(counts) // 3 + spp


def test_spheres_beyond_the_user_geometry_limit_go_in_as_point_spheres(monkeypatch) -> None:
    """``sphere_kind`` below, at and above the limit, and SceneGeometry following it (the limit
    lowered to 10 so that a 20-sphere scene crosses it)."""
    from embree_rt import sphere_modes

    limit = sphere_modes.USER_GEOMETRY_MAX_SPHERES
    assert sphere_modes.sphere_kind(limit) == "user"
    assert sphere_modes.sphere_kind(limit + 1) == "point"
    assert sphere_modes.sphere_kind(5, "point") == "point"
    assert sphere_modes.sphere_kind(limit + 1, "mesh") == "mesh"
    kinds = []
    add_spheres = BVH.add_spheres

    def recording_add_spheres(self, centers, radii, kind="user", **options):
        kinds.append(kind)
        return add_spheres(self, centers, radii, kind=kind, **options)

    monkeypatch.setattr(BVH, "add_spheres", recording_add_spheres)
    scene = random_field(20, seed=3)
    for limit, expected in ((100, "user"), (10, "point")):
        monkeypatch.setattr(sphere_modes, "USER_GEOMETRY_MAX_SPHERES", limit)
        with geometry_module.SceneGeometry(scene):
            assert kinds[-1] == expected
