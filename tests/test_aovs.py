"""AOVs (issue 15): depth, normal, albedo, object and material ids from one ray per pixel centre.

Every AOV is checked against an independent float64 reference on the same pixel-centre rays:
brute-force first hits over every sphere (the quadratic), every triangle of every mesh placement
(trimesh's ray–triangle test on the placed vertices) and the floor plane. Rays whose answer
float32 rounding may change (grazing a sphere, on a triangle edge, two surfaces at nearly the
same distance, on a checker line) are left out and asserted to be few. Then: a textured mesh's
albedo against its texture sampled bilinearly here, the beauty bitwise equal to a render without
AOVs, the files (.npz, .exr read back by OpenEXR, .png beside the image) and the command.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from bvh_reference import float32_exact, sphere_hits, triangle_hits
from PIL import Image
from tolerances import RTOL32, assert_close, assert_vectors_close, ray_t_atol

import embree_rt as rt
from embree_rt import aovs as aov_module
from embree_rt import cli
from embree_rt.aovs import AOV_NAMES, FLOOR_ID, NOTHING_ID, id_colors, save_with_aovs
from embree_rt.camera import camera_frame, pixel_center_rays
from embree_rt.film import tonemap
from embree_rt.textures import srgb_to_linear

ROOT = Path(__file__).resolve().parent.parent
WIDTH, HEIGHT = 72, 45
CHECKER = 0.7
# At most this share of pixels may be left out as undecidable in float32.
MAX_AMBIGUOUS = 0.05


def sample_scene() -> rt.Scene:
    """Spheres of several materials and sizes (one resting on the floor, one far away), two flat
    boxes placed from one mesh, a checkered floor, and a sky the camera sees."""
    scene = rt.Scene(camera=rt.Camera(position=(0.4, 2.2, 7.5), look_at=(0.0, 0.6, 0.0), fov=50))
    scene.floor.checker = rt.Checker(color_a=(0.8, 0.7, 0.6), color_b=(0.1, 0.2, 0.3), size=CHECKER)
    scene.lights.append(rt.PointLight(position=(4.0, 8.0, 5.0)))
    scene.add_material("gold", rt.preset("metal", color=(1.0, 0.78, 0.34)))
    scene.add_material("teal", rt.preset("glossy", color=(0.1, 0.6, 0.55)))
    scene.add_sphere((0.0, 1.0, 0.0), 1.0, "glass")
    scene.add_sphere((-2.2, 0.6, 0.5), 0.6, "gold")
    scene.add_sphere((1.9, 0.45, 1.2), 0.45, "mirror")
    scene.add_sphere((-0.8, 0.25, 2.3), 0.25, "teal")
    scene.add_sphere((3.5, 2.5, -9.0), 2.5, "matte")
    box = trimesh.creation.box(extents=(0.8, 0.6, 0.8))
    for translate, angle, material in (
        ((2.6, 0.3, -1.0), 25.0, "teal"),
        ((-1.3, 1.6, -2.5), -40.0, "gold"),
    ):
        transform = trimesh.transformations.rotation_matrix(np.radians(angle), (0, 1, 0))
        transform[:3, 3] = translate
        scene.add_mesh(box, material, transform=transform, smooth=False)
    return scene


def render_with_aovs(scene: rt.Scene, **options) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    result = rt.render(
        scene, width=WIDTH, height=HEIGHT, spp=1, max_depth=1, aovs=AOV_NAMES, **options
    )
    return result.image, result.aovs


class Reference:
    """Float64 first hits of the pixel-centre rays of ``scene`` at WIDTH x HEIGHT, as flat
    (WIDTH * HEIGHT,) arrays: ``object_id``, ``material_id``, ``t``, ``t_atol``, ``normal``
    (n, 3) facing the ray, ``albedo`` (n, 3), ``ambiguous`` (n,) bool, and the rays."""

    def __init__(self, scene: rt.Scene) -> None:
        frame = camera_frame(scene.camera, WIDTH, HEIGHT)
        origins, directions, _ = pixel_center_rays(frame, 0, WIDTH * HEIGHT)
        o, d = float32_exact(origins.T), float32_exact(directions.T)
        n = len(o)
        self.origins, self.directions = o, d
        names = scene.material_names
        colors = [np.asarray(scene.materials[name].color, np.float32) for name in names]
        centers = float32_exact(scene.sphere_centers)
        radii = float32_exact(scene.sphere_radii)
        # Candidates per source: (t, object, material, normal, albedo, t_atol, ambiguous).
        candidates = []
        spheres = sphere_hits(o, d, centers, radii)
        hit = spheres.prim_id >= 0
        prim = np.maximum(spheres.prim_id, 0)
        material = scene.sphere_materials[prim]
        candidates.append(
            (
                spheres.t,
                np.where(hit, prim, NOTHING_ID),
                material,
                spheres.normal,
                np.array([colors[m] for m in material]),
                spheres.t_atol,
                spheres.ambiguous,
            )
        )
        for index, placement in enumerate(scene.meshes):
            vertices = trimesh.transform_points(placement.mesh.vertices, placement.transform)
            tris = triangle_hits(o, d, vertices, placement.mesh.faces)
            material = scene.material_index(placement.material)
            candidates.append(
                (
                    tris.t,
                    np.full(n, len(scene.sphere_radii) + index),
                    np.full(n, material),
                    tris.normal,
                    np.broadcast_to(colors[material], (n, 3)),
                    tris.t_atol,
                    tris.ambiguous,
                )
            )
        _, instance_starts = scene.object_id_starts()
        for entry, first_id in zip(scene.instances, instance_starts, strict=True):
            for copy, transform in enumerate(entry.transforms):
                vertices = trimesh.transform_points(entry.mesh.vertices, transform)
                tris = triangle_hits(o, d, vertices, entry.mesh.faces)
                material = int(entry.materials[copy])
                candidates.append(
                    (
                        tris.t,
                        np.full(n, first_id + copy),
                        np.full(n, material),
                        tris.normal,
                        np.broadcast_to(colors[material], (n, 3)),
                        tris.t_atol,
                        tris.ambiguous,
                    )
                )
        height = scene.floor.height
        with np.errstate(divide="ignore", invalid="ignore"):
            floor_t = (height - o[:, 1]) / d[:, 1]
        floor_t = np.where(floor_t > 0, floor_t, np.inf)
        point = o + np.where(np.isfinite(floor_t), floor_t, 0.0)[:, None] * d
        squares = np.floor(point[:, 0] / CHECKER) + np.floor(point[:, 2] / CHECKER)
        checker = scene.floor.checker
        floor_albedo = np.where(
            (squares.astype(np.int64) % 2 == 0)[:, None],
            np.float32(checker.color_a),
            np.float32(checker.color_b),
        )
        # On a checker line the square is decided by rounding of the float32 hit point.
        xz = point[:, [0, 2]]
        to_line = np.abs(xz / CHECKER - np.rint(xz / CHECKER)) * CHECKER
        on_line = (to_line < 1e-5 * (1.0 + np.abs(xz))).any(axis=1)
        floor_atol = ray_t_atol(o, d, np.abs(point).max(axis=1), normals=np.tile([0, 1, 0], (n, 1)))
        candidates.append(
            (
                floor_t,
                np.full(n, FLOOR_ID),
                np.full(n, len(scene.materials)),
                np.tile([0.0, 1.0, 0.0], (n, 1)),
                floor_albedo,
                floor_atol,
                on_line & np.isfinite(floor_t),
            )
        )

        t_all = np.stack([c[0] for c in candidates])  # (sources, n)
        order = np.argsort(t_all, axis=0)
        best, second = order[0], order[1]
        rays = np.arange(n)
        self.t = t_all[best, rays]
        self.hit = np.isfinite(self.t)
        pick = lambda k: np.stack([c[k] for c in candidates])[best, rays]  # noqa: E731
        self.object_id = np.where(self.hit, pick(1), NOTHING_ID)
        self.material_id = np.where(self.hit, pick(2), NOTHING_ID)
        normal = pick(3)
        # Facing the camera: the normals above point out of the objects, or either way.
        flip = np.where(np.einsum("ij,ij->i", normal, d) > 0, -1.0, 1.0)
        self.normal = np.where(self.hit[:, None], normal * flip[:, None], 0.0)
        self.albedo = np.where(self.hit[:, None], pick(4), 0.0)
        self.t_atol = np.where(self.hit, pick(5), 0.0)
        ambiguous = np.where(self.hit, pick(6), False)
        # Two sources at nearly the same distance (a sphere resting on the floor, a box behind
        # a sphere's rim): either may be first.
        with np.errstate(invalid="ignore"):  # inf - inf where nothing is hit
            gap = t_all[second, rays] - self.t
        ambiguous |= self.hit & (gap <= 1e-5 * (1.0 + self.t))
        self.ambiguous = ambiguous
        self.sphere_centers, self.sphere_radii = centers, radii


@pytest.fixture(scope="module")
def scene() -> rt.Scene:
    return sample_scene()


@pytest.fixture(scope="module")
def rendered(scene):
    return render_with_aovs(scene)


@pytest.fixture(scope="module")
def reference(scene) -> Reference:
    return Reference(scene)


def flat(values: np.ndarray) -> np.ndarray:
    return values.reshape(WIDTH * HEIGHT, *values.shape[2:])


def test_the_aovs_have_the_documented_shapes_and_types(rendered) -> None:
    beauty, layers = rendered
    assert beauty.shape == (HEIGHT, WIDTH, 3) and beauty.dtype == np.float32
    assert list(layers) == list(AOV_NAMES)
    for name, shape, dtype in (
        ("depth", (HEIGHT, WIDTH), np.float32),
        ("normal", (HEIGHT, WIDTH, 3), np.float32),
        ("uv", (HEIGHT, WIDTH, 2), np.float32),
        ("albedo", (HEIGHT, WIDTH, 3), np.float32),
        ("object_id", (HEIGHT, WIDTH), np.int32),
        ("material_id", (HEIGHT, WIDTH), np.int32),
    ):
        assert layers[name].shape == shape, name
        assert layers[name].dtype == dtype, name


def test_ids_match_brute_force_first_hits(rendered, reference: Reference, scene) -> None:
    _, layers = rendered
    decided = ~reference.ambiguous
    assert reference.ambiguous.mean() < MAX_AMBIGUOUS
    object_id = flat(layers["object_id"])
    np.testing.assert_array_equal(object_id[decided], reference.object_id[decided])
    np.testing.assert_array_equal(
        flat(layers["material_id"])[decided], reference.material_id[decided]
    )
    # Every kind of answer is really in the picture: each object, the floor, the sky.
    seen = set(np.unique(object_id[decided]).tolist())
    assert seen == {NOTHING_ID, FLOOR_ID, *range(len(scene.sphere_radii) + len(scene.meshes))}


def test_instance_array_copies_are_numbered_after_the_mesh_placements() -> None:
    # The sample scene with three more boxes as one instance array (after its two placed
    # boxes): each copy is an object of its own, numbered in order after the placements.
    scene = sample_scene()
    box = trimesh.creation.box(extents=(0.5, 0.5, 0.5))
    transforms = np.tile(np.eye(4), (3, 1, 1))
    transforms[:, :3, 3] = [(-3.0, 0.25, 2.0), (0.9, 0.25, 3.2), (3.2, 1.5, 0.8)]
    transforms[2, 0, 0] = -1.0  # a mirrored copy
    scene.add_instances(box, transforms, ["matte", "teal", "gold"], smooth=False)
    reference = Reference(scene)
    _, aovs = render_with_aovs(scene)
    clear = ~reference.ambiguous
    assert clear.mean() > 1 - MAX_AMBIGUOUS
    first_copy = len(scene.sphere_radii) + len(scene.meshes)
    for copy in range(3):  # every copy is seen
        assert np.sum(reference.object_id[clear] == first_copy + copy) > 10
    np.testing.assert_array_equal(flat(aovs["object_id"])[clear], reference.object_id[clear])
    np.testing.assert_array_equal(flat(aovs["material_id"])[clear], reference.material_id[clear])


def test_depth_is_the_distance_along_the_pixel_centre_ray(rendered, reference) -> None:
    _, layers = rendered
    depth = flat(layers["depth"])
    decided = ~reference.ambiguous
    assert np.isinf(depth[~reference.hit & decided]).all()
    hit = reference.hit & decided
    # The rays start at the camera with unit directions: t is the distance from the camera.
    np.testing.assert_allclose(np.linalg.norm(reference.directions[hit], axis=1), 1.0, rtol=1e-6)
    assert_close(depth[hit], reference.t[hit], atol=reference.t_atol[hit], err_msg="depth")


def test_normals_are_unit_world_normals_facing_the_camera(rendered, reference, scene) -> None:
    _, layers = rendered
    normal = flat(layers["normal"]).astype(np.float64)
    decided = ~reference.ambiguous
    hit = reference.hit
    np.testing.assert_array_equal(normal[~hit & decided], 0.0)
    np.testing.assert_allclose(np.linalg.norm(normal[hit], axis=1), 1.0, atol=4 * RTOL32)
    assert (np.einsum("ij,ij->i", normal[hit], reference.directions[hit]) <= 0).all()
    # Spheres: (p - c) / r at the reference hit point; a float32 error in t moves it by up to
    # t_atol along the ray, which turns the normal by at most t_atol / r.
    on_sphere = hit & decided & (reference.object_id >= 0)
    on_sphere &= reference.object_id < len(scene.sphere_radii)
    ids = reference.object_id[on_sphere]
    point = (
        reference.origins[on_sphere]
        + reference.t[on_sphere, None] * reference.directions[on_sphere]
    )
    expected = (point - reference.sphere_centers[ids]) / reference.sphere_radii[ids, None]
    assert on_sphere.sum() > 300
    turn = reference.t_atol[on_sphere] / reference.sphere_radii[ids]
    assert_vectors_close(normal[on_sphere], expected, atol=turn)
    # Flat boxes and the floor: their face normal, exactly up to float32 rounding.
    spheres = len(scene.sphere_radii)
    flat_faces = (reference.object_id == FLOOR_ID) | (reference.object_id >= spheres)
    elsewhere = hit & decided & flat_faces
    assert_vectors_close(normal[elsewhere], reference.normal[elsewhere], atol=8 * RTOL32)


def test_normals_face_the_camera_from_inside_a_sphere_and_under_the_floor() -> None:
    """A camera below the floor, inside a big sphere: rays going up meet the floor's underside
    (normal -y), rays going down the sphere's inside (normal toward the centre, -(p - c) / r)."""
    center, radius = np.array([0.0, -1.0, 4.0]), 20.0
    scene = rt.Scene(camera=rt.Camera(position=tuple(center), look_at=(0.0, -1.0, 0.0), fov=80))
    scene.add_sphere(tuple(center), radius, "matte")
    _, layers = render_with_aovs(scene)
    frame = camera_frame(scene.camera, WIDTH, HEIGHT)
    _, directions, _ = pixel_center_rays(frame, 0, WIDTH * HEIGHT)
    d = directions.T.astype(np.float64)
    normal = flat(layers["normal"]).astype(np.float64)
    object_id = flat(layers["object_id"])
    floor = object_id == FLOOR_ID
    assert 0.2 < floor.mean() < 0.8 and ((object_id == 0) | floor).all()
    assert_vectors_close(normal[floor], np.tile([0.0, -1.0, 0.0], (floor.sum(), 1)), atol=0.0)
    depth = flat(layers["depth"]).astype(np.float64)
    point = center + depth[~floor, None] * d[~floor]
    turn = ray_t_atol(np.tile(center, (len(point), 1)), d[~floor], 21.0) / radius
    assert_vectors_close(normal[~floor], -(point - center) / radius, atol=turn)


def test_pixel_centre_rays_go_through_the_pixel_centres() -> None:
    """Against the pinhole model in float64: the ray of pixel (row, column) points at
    ``(2 (column + 1/2) / W - 1) tan(fov / 2) W / H`` right and ``(1 - 2 (row + 1/2) / H)
    tan(fov / 2)`` up on the image plane at distance 1 in front of the eye."""
    camera = rt.Camera(position=(1.0, 2.0, 3.0), look_at=(-0.5, 0.3, -1.0), fov=38.0)
    width, height = 9, 7
    origins, directions, pixel = pixel_center_rays(camera_frame(camera, width, height), 0, 63)
    forward = np.subtract(camera.look_at, camera.position)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(camera.fov) / 2)
    row, column = np.divmod(np.arange(63), width)
    x = (2 * (column + 0.5) / width - 1) * half * width / height
    y = (1 - 2 * (row + 0.5) / height) * half
    expected = forward[None] + x[:, None] * right + y[:, None] * up
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    assert_vectors_close(directions.T, expected, atol=4 * RTOL32)
    np.testing.assert_array_equal(pixel, np.arange(63))
    np.testing.assert_array_equal(origins.T, np.tile(np.float32(camera.position), (63, 1)))
    # The middle pixel of an odd-sized image looks straight at look_at.
    assert_vectors_close(directions.T[31], forward, atol=4 * RTOL32)


def test_albedo_is_the_material_colour_and_the_floors_checker(rendered, reference) -> None:
    _, layers = rendered
    decided = ~reference.ambiguous
    albedo = flat(layers["albedo"])
    # A gather of the material's float32 colour (or the checker's), no arithmetic: equal on
    # every ISA.
    np.testing.assert_array_equal(albedo[decided], reference.albedo[decided].astype(np.float32))
    on_floor = decided & (reference.object_id == FLOOR_ID)
    assert len(np.unique(albedo[on_floor], axis=0)) == 2  # both checker colours seen


def test_tessellated_spheres_keep_their_sphere_ids(scene, rendered, reference) -> None:
    """--spheres mesh: spheres are instances, but each still has its index as its id."""
    _, mesh_layers = render_with_aovs(scene, spheres="mesh")
    o, d = reference.origins, reference.directions
    # Distance from each sphere's centre to each ray, in radii: well inside or well outside
    # every sphere, the icosphere (within 1.3% of the sphere) gives the same first hit.
    to_center = reference.sphere_centers[None] - o[:, None]
    along = np.einsum("nij,nj->ni", to_center, d)
    closest = np.sqrt(np.maximum(np.einsum("nij,nij->ni", to_center, to_center) - along**2, 0))
    ratio = closest / reference.sphere_radii[None]
    clear = ((ratio < 0.9) | (ratio > 1.05)).all(axis=1) & ~reference.ambiguous
    assert clear.mean() > 0.85
    np.testing.assert_array_equal(flat(mesh_layers["object_id"])[clear], reference.object_id[clear])
    np.testing.assert_array_equal(
        flat(mesh_layers["material_id"])[clear], reference.material_id[clear]
    )


def test_the_beauty_is_bitwise_the_render_without_aovs(scene, rendered) -> None:
    # The AOV pass runs after the beauty and changes no state the beauty reads: both images
    # come from the same instructions on the same machine, so they are equal on any ISA.
    beauty, _ = rendered
    plain = rt.render(scene, width=WIDTH, height=HEIGHT, spp=1, max_depth=1).image
    np.testing.assert_array_equal(beauty, plain)
    assert beauty.std() > 0.01


def test_aovs_do_not_depend_on_threads_or_batch_size(scene, rendered) -> None:
    # Each pixel is one ray through its centre; Embree answers the same ray the same way in
    # any packet, so the AOVs agree exactly (the ids) and to float32 rounding (the rest).
    _, layers = rendered
    with rt.Renderer(scene, threads=1, batch_size=97) as renderer:
        small = renderer.render(width=WIDTH, height=HEIGHT, spp=1, max_depth=1, aovs=AOV_NAMES).aovs
    for name in ("object_id", "material_id"):
        np.testing.assert_array_equal(small[name], layers[name])
    for name in ("depth", "normal", "albedo"):
        np.testing.assert_allclose(small[name], layers[name], rtol=4 * RTOL32, atol=1e-6)


def test_a_textured_meshs_albedo_is_its_texture() -> None:
    """A quad carrying a random 8x6 sRGB texture, turned and moved by its placement: albedo at
    each pixel equals the texture sampled bilinearly (with repeat) at the hit's UV, here in
    float64 from the float64 hit point."""
    rng = np.random.default_rng(15)
    codes = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    texture = Image.fromarray(codes, "RGB")
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=texture, metallicFactor=0.0, roughnessFactor=1.0
    )
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    quad = trimesh.Trimesh(vertices, faces, process=False, visual=visual)
    scene = rt.Scene(camera=rt.Camera(position=(0.2, 0.1, 3.0), look_at=(0, 0, 0), fov=45))
    scene.floor = None
    transform = trimesh.transformations.rotation_matrix(np.radians(20.0), (0, 1, 0))
    transform[:3, 3] = (0.1, 0.05, 0.0)
    scene.add_mesh(quad, transform=transform)
    _, layers = render_with_aovs(scene)

    frame = camera_frame(scene.camera, WIDTH, HEIGHT)
    origins, directions, _ = pixel_center_rays(frame, 0, WIDTH * HEIGHT)
    o, d = float32_exact(origins.T), float32_exact(directions.T)
    placed = trimesh.transform_points(vertices, transform)
    hits = triangle_hits(o, d, placed, faces)
    decided = (hits.prim_id >= 0) & ~hits.ambiguous
    assert decided.sum() > 800
    corners = faces[hits.prim_id[decided]]
    u, v = hits.u[decided, None], hits.v[decided, None]
    hit_uv = (1 - u - v) * uv[corners[:, 0]] + u * uv[corners[:, 1]] + v * uv[corners[:, 2]]
    texels = srgb_to_linear(codes / 255.0)
    h, w = codes.shape[:2]
    # Texel centres at u = (column + 0.5) / w, v = 1 - (row + 0.5) / h; neighbours wrap.
    x = hit_uv[:, 0] * w - 0.5
    y = (1.0 - hit_uv[:, 1]) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    c0, r0 = x0.astype(int) % w, y0.astype(int) % h
    c1, r1 = (c0 + 1) % w, (r0 + 1) % h
    expected = (
        (1 - fx) * (1 - fy) * texels[r0, c0]
        + fx * (1 - fy) * texels[r0, c1]
        + (1 - fx) * fy * texels[r1, c0]
        + fx * fy * texels[r1, c1]
    )
    albedo = flat(layers["albedo"])[decided]
    # The UV is known to uv_atol; the texture changes by at most 1 per texel.
    slope = max(w, h) * (hits.uv_atol[decided] + 1e-6)
    assert_close(albedo, expected, atol=slope[:, None] + 1e-6)
    assert np.ptp(expected, axis=0).min() > 0.3  # many colours really were compared
    object_id = flat(layers["object_id"])
    np.testing.assert_array_equal(object_id[decided], 0)  # the first and only object


def test_uv_is_the_textured_quads_own_coordinates_and_inf_elsewhere(tmp_path: Path) -> None:
    """A textured quad seen head-on, its UVs an affine map of its own x, y (so interpolating
    them over either triangle gives that map exactly), beside a sphere and an untextured box
    over the floor: the ``uv`` AOV of each quad pixel is the map, applied in float64 to the
    hit point its ``position`` AOV gives (taken back into the quad's space); every pixel that
    hits anything else or escapes holds inf, and the picture beside a .png shows those black."""
    rng = np.random.default_rng(27)
    texture = Image.fromarray(rng.integers(0, 256, (4, 4, 3), dtype=np.uint8), "RGB")
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    linear, offset = np.array([[1.5, 0.3], [-0.2, 0.8]]), np.array([0.1, -0.4])
    uv = vertices[:, :2] @ linear.T + offset  # repeats past [0, 1] and goes negative
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=texture, metallicFactor=0.0, roughnessFactor=1.0
    )
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    quad = trimesh.Trimesh(vertices, faces, process=False, visual=visual)
    scene = rt.Scene(camera=rt.Camera(position=(0.0, 1.0, 5.0), look_at=(0.0, 1.0, 0.0), fov=45))
    transform = np.eye(4)
    transform[:3, 3] = (-0.6, 1.3, 0.0)
    scene.add_mesh(quad, transform=transform)
    scene.add_sphere((1.6, 1.0, 0.5), 0.6, "matte")
    box = trimesh.creation.box(extents=(0.5, 0.5, 0.5))
    scene.add_mesh(
        box, "matte", transform=trimesh.transformations.translation_matrix((1.2, 0.25, 1.5))
    )
    result = rt.render(
        scene, width=WIDTH, height=HEIGHT, spp=1, max_depth=1, aovs=["uv", "position", "object_id"]
    )
    layers = result.aovs
    assert layers["uv"].shape == (HEIGHT, WIDTH, 2) and layers["uv"].dtype == np.float32
    got, object_id = flat(layers["uv"]), flat(layers["object_id"])
    # Spheres are numbered first: the sphere is 0, the quad 1, the box 2.
    on_quad = object_id == 1
    assert on_quad.sum() > 300
    for other in (0, 2, FLOOR_ID, NOTHING_ID):  # each kind of pixel without UVs is there
        assert (object_id == other).sum() > 10, other
    assert np.isinf(got[~on_quad]).all()
    assert np.isfinite(got[on_quad]).all()

    position = flat(layers["position"])[on_quad].astype(np.float64)
    local = position - transform[:3, 3]
    expected = local[:, :2] @ linear.T + offset
    # A hundredth of the UV one pixel spans: a pixel's footprint on the quad, through the map.
    frame = camera_frame(scene.camera, WIDTH, HEIGHT)
    footprint = 2.0 * 5.0 * frame.half_width / WIDTH
    atol = 0.01 * footprint * np.linalg.norm(linear, 2)
    assert_close(got[on_quad], expected, atol=atol)
    assert np.ptp(expected, axis=0).min() > 1.0  # across the quad, not one corner

    path = tmp_path / "uv.png"
    written = save_with_aovs(result.image, {"uv": layers["uv"]}, path)
    assert written == [tmp_path / "uv.uv.png"]
    with Image.open(written[0]) as image:
        assert image.mode == "RGB" and image.size == (WIDTH, HEIGHT)
        picture = np.asarray(image).reshape(-1, 3)
    assert (picture[~on_quad] == 0).all()
    assert (picture[on_quad, 2] == 0).all()  # blue unused
    # Red and green rise with u and v: the lowest u is black in red, the highest full red.
    for axis in (0, 1):
        values = got[on_quad, axis]
        assert picture[on_quad, axis][np.argmin(values)] == 0
        assert picture[on_quad, axis][np.argmax(values)] == 255


def test_a_scene_of_only_the_floor_and_sky() -> None:
    scene = rt.Scene(camera=rt.Camera(position=(0.0, 1.0, 4.0), look_at=(0.0, 0.5, 0.0)))
    _, layers = render_with_aovs(scene)
    object_id = flat(layers["object_id"])
    assert set(np.unique(object_id).tolist()) == {FLOOR_ID, NOTHING_ID}
    floor = object_id == FLOOR_ID
    np.testing.assert_array_equal(flat(layers["material_id"])[floor], len(scene.materials))
    np.testing.assert_array_equal(flat(layers["material_id"])[~floor], NOTHING_ID)
    assert np.isfinite(flat(layers["depth"])[floor]).all()
    assert np.isinf(flat(layers["depth"])[~floor]).all()
    # No AOVs asked for: the image and an empty dict.
    result = rt.render(scene, width=8, height=5, spp=1, aovs=[])
    assert result.aovs == {} and result.image.shape == (5, 8, 3)


def test_unknown_names_are_refused() -> None:
    assert aov_module.parse_aov_list("depth, normal,depth") == ("depth", "normal")
    for bad in ("depth,bogus", "", "depth,,normal"):
        with pytest.raises(ValueError):
            aov_module.parse_aov_list(bad)
    with pytest.raises(TypeError):
        aov_module.check_aov_names("depth")
    with pytest.raises(ValueError, match="bogus"):
        rt.render(sample_scene(), width=8, height=5, spp=1, aovs=["depth", "bogus"])


# -- files ------------------------------------------------------------------------------------


def test_npz_holds_the_beauty_and_every_aov(tmp_path: Path, rendered) -> None:
    beauty, layers = rendered
    path = tmp_path / "out.npz"
    assert save_with_aovs(beauty, layers, path) == []
    with np.load(path, allow_pickle=False) as data:
        assert sorted(data.files) == sorted(["beauty", *AOV_NAMES])
        np.testing.assert_array_equal(data["beauty"], beauty)
        for name in AOV_NAMES:
            assert data[name].dtype == layers[name].dtype
            np.testing.assert_array_equal(data[name], layers[name])
    # Without AOVs an .npz holds the beauty alone.
    rt.save_image(beauty, tmp_path / "plain.npz")
    with np.load(tmp_path / "plain.npz", allow_pickle=False) as data:
        assert data.files == ["beauty"]
        np.testing.assert_array_equal(data["beauty"], beauty)


def test_exr_layers_read_back_by_openexr(tmp_path: Path, rendered) -> None:
    import OpenEXR

    beauty, layers = rendered
    path = tmp_path / "out.exr"
    save_with_aovs(beauty, layers, path)
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        channels = {name: channel.pixels for name, channel in exr.channels().items()}
    assert set(channels) == {
        "R",
        "G",
        "B",
        "depth.Z",
        "z_depth.Z",
        "position.X",
        "position.Y",
        "position.Z",
        "uv.U",
        "uv.V",
        "normal.X",
        "normal.Y",
        "normal.Z",
        "albedo.R",
        "albedo.G",
        "albedo.B",
        "object_id.id",
        "material_id.id",
        "ao.Y",
    }
    np.testing.assert_array_equal(channels["ao.Y"], layers["ao"])
    for axis, name in enumerate("RGB"):
        np.testing.assert_array_equal(channels[name], beauty[..., axis])
    np.testing.assert_array_equal(channels["depth.Z"], layers["depth"])
    np.testing.assert_array_equal(channels["z_depth.Z"], layers["z_depth"])
    for axis, name in enumerate("XYZ"):
        np.testing.assert_array_equal(channels[f"position.{name}"], layers["position"][..., axis])
    for axis, name in enumerate("UV"):
        np.testing.assert_array_equal(channels[f"uv.{name}"], layers["uv"][..., axis])
    for axis, name in enumerate("XYZ"):
        np.testing.assert_array_equal(channels[f"normal.{name}"], layers["normal"][..., axis])
    for axis, name in enumerate("RGB"):
        np.testing.assert_array_equal(channels[f"albedo.{name}"], layers["albedo"][..., axis])
    for name in ("object_id", "material_id"):
        stored = channels[f"{name}.id"]
        assert stored.dtype == np.uint32  # the int32 ids' bits: -1 is 0xFFFFFFFF
        np.testing.assert_array_equal(stored.view(np.int32), layers[name])
    assert (layers["object_id"] == FLOOR_ID).any() and (layers["object_id"] == NOTHING_ID).any()


def test_png_writes_one_picture_per_aov_beside_the_image(tmp_path: Path, rendered) -> None:
    beauty, layers = rendered
    path = tmp_path / "out.png"
    written = save_with_aovs(beauty, layers, path)
    assert written == [tmp_path / f"out.{name}.png" for name in AOV_NAMES]
    with Image.open(path) as image:
        np.testing.assert_array_equal(np.asarray(image), tonemap(beauty))
    pictures = {}
    for name, side in zip(AOV_NAMES, written, strict=True):
        with Image.open(side) as image:
            assert image.size == (WIDTH, HEIGHT) and image.mode == "RGB"
            pictures[name] = np.asarray(image)
    # Ids: equal ids, equal colours; different ids, different colours; nothing is black.
    ids = layers["object_id"].ravel()
    colors = pictures["object_id"].reshape(-1, 3)
    unique_ids, first = np.unique(ids, return_index=True)
    np.testing.assert_array_equal(colors, colors[first][np.searchsorted(unique_ids, ids)])
    assert len(np.unique(colors[first], axis=0)) == len(unique_ids)
    assert (colors[ids == NOTHING_ID] == 0).all()
    # Depth: nearer is brighter; the sky is black.
    depth = layers["depth"].ravel()
    grey = pictures["depth"][..., 0].ravel().astype(int)
    assert (grey[np.isinf(depth)] == 0).all()
    near, far = (
        np.nanargmin(np.where(np.isinf(depth), np.nan, depth)),
        np.argmax(np.where(np.isinf(depth), -1, depth)),
    )
    assert grey[near] == 255 and grey[far] < grey[near]


def test_npy_writes_each_aov_array_beside_the_image(tmp_path: Path, rendered) -> None:
    beauty, layers = rendered
    written = save_with_aovs(beauty, {"depth": layers["depth"]}, tmp_path / "out.npy")
    assert written == [tmp_path / "out.depth.npy"]
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), beauty)
    np.testing.assert_array_equal(np.load(written[0]), layers["depth"])


def test_id_colours_are_distinct_for_distinct_ids() -> None:
    ids = np.arange(-2, 200_000)
    colors = id_colors(ids)
    packed = (colors[:, 0].astype(np.int64) << 16) | (colors[:, 1].astype(np.int64) << 8)
    packed |= colors[:, 2]
    assert len(np.unique(packed)) == len(ids)
    assert packed[1] == 0  # -1, nothing, is black; nothing else is
    assert (packed[ids != NOTHING_ID] != 0).all()


def test_a_failed_aov_write_leaves_every_old_file_alone(tmp_path: Path, rendered, monkeypatch):
    beauty, layers = rendered
    path = tmp_path / "out.png"
    save_with_aovs(beauty, layers, path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    calls = []

    def failing(name, values):
        calls.append(name)
        if name == "object_id":
            raise OSError(28, "No space left on device")
        return np.zeros((*values.shape[:2], 3), np.uint8)

    monkeypatch.setattr(aov_module, "visualize", failing)
    with pytest.raises(OSError):
        save_with_aovs(beauty * 2, layers, path)
    assert "object_id" in calls
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}  # no temp file left either
    assert after == before


# -- the command ------------------------------------------------------------------------------

SCENE_TOML = """
[camera]
position = [0.0, 1.5, 5.0]
look_at = [0.0, 0.8, 0.0]
[[lights]]
position = [3.0, 6.0, 4.0]
[[spheres]]
center = [0.0, 1.0, 0.0]
radius = 1.0
material = "glossy"
[[spheres]]
center = [1.6, 0.4, 0.5]
radius = 0.4
material = "metal"
"""


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )


CAMERA_KEYS = ("K", "world_to_camera_opencv", "world_to_camera_opengl")


def test_the_command_writes_aovs_and_names_the_files(tmp_path: Path) -> None:
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE_TOML)
    size = ["--width", "24", "--height", "16", "--spp", "1", "--quiet"]
    png = tmp_path / "out.png"
    result = run_cli("render", str(scene), "-o", str(png), "--aov", "object_id,depth", *size)
    assert result.returncode == 0, result.stderr
    sides = [
        tmp_path / "out.object_id.png",
        tmp_path / "out.depth.png",
        tmp_path / "out.camera.json",
    ]
    assert result.stdout.splitlines() == [str(side) for side in sides]
    assert all(side.is_file() for side in sides) and png.is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["s.toml", "out.png", *(side.name for side in sides)]
    )
    npz = tmp_path / "out.npz"
    result = run_cli("random", "--count", "40", "-o", str(npz), "--aov", "material_id", *size)
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"{tmp_path / 'out.camera.json'}\n"  # beside the .npz
    with np.load(npz) as data:
        assert sorted(data.files) == sorted(["beauty", "material_id", *CAMERA_KEYS])
        assert data["material_id"].shape == (16, 24)
        assert (data["material_id"] >= 0).any()


def test_an_unknown_aov_is_one_line_exit_2_and_writes_nothing(tmp_path: Path) -> None:
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE_TOML)
    old = tmp_path / "out.png"
    old.write_bytes(b"an old image")
    result = run_cli("render", str(scene), "-o", str(old), "--aov", "depth,segmentation")
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "embree-rt: error: --aov: unknown AOV 'segmentation'; choose from depth, z_depth, "
        "position, uv, normal, albedo, object_id, material_id, ao"
    ]
    assert old.read_bytes() == b"an old image"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png", "s.toml"]


def test_info_lists_objects_and_materials_with_their_ids(capsys) -> None:
    scene_file = ROOT / "scenes" / "mesh_and_spheres.toml"
    assert cli.main(["info", str(scene_file)]) == 0
    lines = capsys.readouterr().out.splitlines()
    scene = rt.load_scene(scene_file)
    spheres = len(scene.sphere_radii)
    objects = {
        int(line.split()[1].rstrip(":")): line for line in lines if line.startswith("  object ")
    }
    assert sorted(objects) == list(range(spheres + len(scene.meshes)))
    for index in range(spheres):
        name = scene.material_names[scene.sphere_materials[index]]
        assert "sphere" in objects[index] and f"({name})" in objects[index]
    for index, placement in enumerate(scene.meshes):
        line = objects[spheres + index]
        assert f"{len(placement.mesh.faces):,} triangles" in line
        assert f"({placement.material})" in line
    materials = [line.split(":", 1)[1].strip() for line in lines if line.startswith("  material ")]
    assert materials == [*scene.material_names, "floor"]


# -- the camera with the pixels -------------------------------------------------------------------


def test_the_saved_camera_projects_each_hit_onto_its_pixels_centre(tmp_path: Path) -> None:
    """The AOV pass traces one unjittered ray through each pixel centre (whatever the spp):
    the position it hits, projected with the saved K and OpenCV extrinsics, must land on that
    centre, (column, row) in OpenCV's pixel convention. The positions are float32 of a scene a
    few units across seen from ~6 units: their rounding moves a projection by ~1e-5 pixel, so
    1e-3 pixel is a tolerance with room and still far below a pixel."""
    import json

    scene = rt.Scene(camera=rt.Camera(position=(1.0, 2.5, 6.0), look_at=(0.0, 0.5, 0.0), fov=50.0))
    scene.lights.append(rt.PointLight(position=(3.0, 6.0, 4.0)))
    scene.add_sphere((0.0, 1.0, 0.0), 1.0, "matte")
    scene.add_sphere((-1.8, 0.5, 0.6), 0.5, "mirror")
    result = rt.render(scene, width=40, height=30, spp=1, aovs=["depth", "z_depth", "position"])
    written = result.save(tmp_path / "view.npz")
    assert written == [tmp_path / "view.camera.json"]
    with np.load(tmp_path / "view.npz") as data:
        K, opencv, opengl = (data[k] for k in CAMERA_KEYS)
        depth, z_depth, position = data["depth"], data["z_depth"], data["position"]
    record = json.loads((tmp_path / "view.camera.json").read_text())
    assert (record["width"], record["height"]) == (40, 30)
    for key, matrix in zip(CAMERA_KEYS, (K, opencv, opengl), strict=True):
        np.testing.assert_array_equal(np.array(record[key]), matrix)

    hit = np.isfinite(depth)
    assert 0.3 < hit.mean() < 1.0  # spheres and floor, and some sky
    assert np.isinf(position[~hit]).all() and np.isinf(z_depth[~hit]).all()
    rows, columns = np.nonzero(hit)
    points = np.c_[position[hit].astype(np.float64), np.ones(hit.sum())]
    camera = (opencv @ points.T)[:3]
    assert (camera[2] > 0).all()  # in front: OpenCV looks down +z
    pixel = K @ camera
    np.testing.assert_allclose(pixel[0] / pixel[2], columns, atol=1e-3)
    np.testing.assert_allclose(pixel[1] / pixel[2], rows, atol=1e-3)
    # OpenGL's camera: the same frame with y and z flipped, looking down -z
    np.testing.assert_array_equal(opengl, np.diag([1.0, -1.0, -1.0, 1.0]) @ opencv)
    assert ((opengl @ points.T)[2] < 0).all()

    # z-depth: the distance times the cosine of the pixel's ray to the axis, that ray read
    # from K alone; and the camera-space z of the hit
    rays = np.linalg.inv(K) @ np.stack([columns, rows, np.ones(len(rows))])
    cosine = 1.0 / np.linalg.norm(rays, axis=0)
    np.testing.assert_allclose(z_depth[hit], depth[hit] * cosine, rtol=1e-5)
    np.testing.assert_allclose(z_depth[hit], camera[2], rtol=1e-5)


def test_an_animation_writes_the_transforms_json_nerf_tools_read(tmp_path: Path) -> None:
    import json

    from embree_rt.scene.animation import camera_at

    flight = Path(__file__).resolve().parent.parent / "scenes" / "animations"
    pattern = tmp_path / "shots" / "f_{frame:03d}.png"
    result = run_cli(
        "render",
        str(flight / "three_spheres_flight.toml"),
        "-o",
        str(pattern),
        "--width",
        "32",
        "--height",
        "18",
        "--spp",
        "1",
        "--frames",
        "10:13",
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    transforms = json.loads((tmp_path / "shots" / "transforms.json").read_text())
    scene = rt.load_scene(flight / "three_spheres_flight.toml")
    assert [f["file_path"] for f in transforms["frames"]] == [
        "./f_010.png",
        "./f_011.png",
        "./f_012.png",
    ]
    assert (transforms["w"], transforms["h"]) == (32, 18)
    for number, frame in zip(range(10, 13), transforms["frames"], strict=True):
        camera = camera_at(scene.camera, scene.animation, number)
        pose = np.array(frame["transform_matrix"])
        np.testing.assert_allclose(pose[:3, 3], camera.position, atol=1e-12)
        view = np.subtract(camera.look_at, camera.position)
        np.testing.assert_allclose(-pose[:3, 2], view / np.linalg.norm(view), atol=1e-12)
        np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-12)
        assert pose[1, 1] > 0  # up is up: OpenGL's y
        fov_x = frame.get("camera_angle_x", transforms["camera_angle_x"])
        half_y = np.tan(np.radians(camera.fov) / 2)
        assert fov_x == pytest.approx(2 * np.arctan(half_y * 32 / 18))
        assert (tmp_path / "shots" / frame["file_path"]).is_file()
