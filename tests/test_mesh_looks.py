"""Meshes look as their files say, and no mesh puts NaN in a picture.

The colours are checked on renders of the project's own assets (``assets/make_assets.py``) against
closed forms: a cube face seen head-on, lit by one light straight behind the camera, shows
``(ambient + diffuse · intensity · N·L) · colour`` with N·L = 1 to 1e-8, so each texture quadrant
must come out as that factor times the quadrant's sRGB colour decoded to linear by the standard's
formula (written out here), times the file's base-colour factor. Vertex colours are checked per
pixel: a render with the mesh's colours divided by the same render in white is the colour at the
point each camera ray hits, which trimesh's NumPy ray–triangle test finds independently.
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from asset_meaning import assert_same_meaning, glb_meaning
from bvh_reference import triangle_hits
from camera_samples import primary_rays

import embree_rt as rt
from embree_rt.camera import camera_frame
from embree_rt.geometry import SceneGeometry
from embree_rt.scene.meshes import load_mesh_parts, metallic_roughness_material
from embree_rt.textures import sample_bilinear, texels_from_image

ROOT = Path(__file__).resolve().parent.parent
ASSETS = ROOT / "assets"
# The head-on view: camera on the +z axis, a unit cube at the origin (its front face at z = 0.5),
# one light far behind the camera, so every point of the face sees it along the normal.
SIZE = 48
FOV = 20.0
CAMERA_Z = 5.0
INTENSITY = 0.8
AMBIENT, DIFFUSE = 0.1, 0.85  # the matte defaults every look below keeps


def _make_assets():
    spec = importlib.util.spec_from_file_location("make_assets", ASSETS / "make_assets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


MAKE = _make_assets()


def srgb_to_linear(code: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) decoding 8-bit codes, float64."""
    c = np.asarray(code, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def load_part(path: Path) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The one mesh in ``path`` and its node transform, as the scene loader reads them."""
    (part,) = load_mesh_parts(path, "scene.toml", "meshes[0].file")
    return part


def write_scene(path: Path, meshes: str, *, lights: bool = True, sky=(0.8, 0.88, 1.0)) -> Path:
    """A scene file of the head-on view around ``meshes`` (TOML ``[[meshes]]`` tables)."""
    light = f"[[lights]]\nposition = [0.0, 0.0, 1e4]\nintensity = {INTENSITY}\n" if lights else ""
    path.write_text(
        f"""
floor = false
[camera]
position = [0.0, 0.0, {CAMERA_Z}]
look_at = [0.0, 0.0, 0.0]
fov = {FOV}
[background]
horizon = {[float(c) for c in sky]}
zenith = {[float(c) for c in sky]}
{light}
{meshes}
""",
        encoding="utf-8",
    )
    return path


def render_file(path: Path, spp: int = 4) -> np.ndarray:
    return rt.render(rt.load_scene(path), width=SIZE, height=SIZE, spp=spp, max_depth=2).image


def quadrant_pixels(image: np.ndarray) -> list[np.ndarray]:
    """The (25, 3) pixels of a 5×5 block at the centre of each quadrant of the front face, in
    QUADRANT_COLORS's order (top left, top right, bottom left, bottom right)."""
    half_height = math.tan(math.radians(FOV) / 2)
    blocks = []
    for x, y in ((-0.25, 0.25), (0.25, 0.25), (-0.25, -0.25), (0.25, -0.25)):
        # The point (x, y, 0.5) on the image plane at distance 1, then in pixels.
        px, py = x / (CAMERA_Z - 0.5), y / (CAMERA_Z - 0.5)
        column = int((px / half_height + 1) / 2 * SIZE)
        row = int((1 - py / half_height) / 2 * SIZE)
        blocks.append(image[row - 2 : row + 3, column - 2 : column + 3].reshape(-1, 3))
    return blocks


def lit_quadrant_colors(factor=(1.0, 1.0, 1.0)) -> list[np.ndarray]:
    """(3,) float64 linear radiance of each quadrant under the head-on light."""
    shade = AMBIENT + DIFFUSE * INTENSITY
    return [shade * np.asarray(factor) * srgb_to_linear(c) for c in MAKE.QUADRANT_COLORS]


def assert_quadrants(image: np.ndarray, expected: list[np.ndarray]) -> None:
    for pixels, want in zip(quadrant_pixels(image), expected, strict=True):
        np.testing.assert_allclose(
            pixels, np.broadcast_to(want, pixels.shape), rtol=1e-5, atol=1e-6
        )


# -- base-colour textures ------------------------------------------------------------------------


def _obj_without_kd(directory: Path) -> Path:
    """quadrant_cube.obj with an MTL that names the texture and no Kd (trimesh fills in grey)."""
    obj = directory / "cube.obj"
    obj.write_text(
        (ASSETS / "quadrant_cube.obj").read_text().replace("quadrant_cube.mtl", "plain.mtl")
    )
    (directory / "quadrants.png").write_bytes((ASSETS / "quadrants.png").read_bytes())
    (directory / "plain.mtl").write_text("newmtl quadrants\nmap_Kd quadrants.png\n")
    return obj


def _glb_without_factor(directory: Path) -> Path:
    """The cube in glTF with the texture and no baseColorFactor (glTF: white)."""
    vertices, faces, uv = MAKE.textured_cube()
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=MAKE.quadrants(), metallicFactor=0.0, roughnessFactor=1.0
    )
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    path = directory / "cube.glb"
    trimesh.Trimesh(vertices, faces, visual=visual, process=False).export(path)
    return path


TEXTURED = {
    "obj_map_kd": (lambda _: ASSETS / "quadrant_cube.obj", (1.0, 1.0, 1.0)),
    "obj_map_kd_without_kd": (_obj_without_kd, (1.0, 1.0, 1.0)),
    "gltf_texture_times_factor": (lambda _: ASSETS / "quadrant_cube.glb", MAKE.CUBE_FACTOR),
    "gltf_texture_without_factor": (_glb_without_factor, (1.0, 1.0, 1.0)),
}


@pytest.mark.parametrize("case", TEXTURED)
def test_the_base_colour_texture_shows_decoded_from_srgb_times_the_factor(
    case: str, tmp_path: Path
) -> None:
    make_file, factor = TEXTURED[case]
    mesh_file = make_file(tmp_path)
    image = render_file(write_scene(tmp_path / "s.toml", f'[[meshes]]\nfile = "{mesh_file}"\n'))
    assert np.isfinite(image).all()
    # 8-bit factors: trimesh stores glTF's baseColorFactor in 8 bits; CUBE_FACTOR is k/255.
    assert_quadrants(image, lit_quadrant_colors(factor))


@pytest.mark.parametrize("case", TEXTURED)
def test_a_named_material_overrides_the_files_look(case: str, tmp_path: Path) -> None:
    make_file, factor = TEXTURED[case]
    mesh_file = make_file(tmp_path)
    scene = write_scene(
        tmp_path / "s.toml",
        f'[materials.paint]\ncolor = [0.2, 0.4, 0.6]\n[[meshes]]\nfile = "{mesh_file}"\n'
        'material = "paint"\n',
    )
    uniform = (AMBIENT + DIFFUSE * INTENSITY) * np.array([0.2, 0.4, 0.6])
    assert_quadrants(render_file(scene), [uniform] * 4)
    # The Python API alike: Scene.add_mesh with no material shows the file's look, with one
    # shows that material (the matte preset's grey) everywhere.
    mesh, _ = load_part(mesh_file)
    grey = (AMBIENT + DIFFUSE * INTENSITY) * np.asarray(rt.PRESETS["matte"].color)
    for material, expected in ((None, lit_quadrant_colors(factor)), ("matte", [grey] * 4)):
        api = rt.Scene(camera=rt.Camera(position=(0, 0, CAMERA_Z), look_at=(0, 0, 0), fov=FOV))
        api.floor = None
        api.lights.append(rt.PointLight(position=(0, 0, 1e4), intensity=INTENSITY))
        api.add_mesh(mesh, material)
        image = rt.render(api, width=SIZE, height=SIZE, spp=1, max_depth=2).image
        assert_quadrants(image, expected)


def test_a_smooth_metal_mirrors_the_sky_tinted_by_its_texture(tmp_path: Path) -> None:
    """glTF metallic 1, roughness 0: no diffuse, a 90% mirror whose reflection takes the base
    colour. With no light and a uniform sky B, the face shows C · (ambient · 0.1 + 0.9 · B)."""
    vertices, faces, uv = MAKE.textured_cube()
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=MAKE.quadrants(), metallicFactor=1.0, roughnessFactor=0.0
    )
    path = tmp_path / "chrome.glb"
    trimesh.Trimesh(
        vertices,
        faces,
        visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
        process=False,
    ).export(path)
    sky = np.array([0.3, 0.5, 0.9])
    image = render_file(
        write_scene(tmp_path / "s.toml", f'[[meshes]]\nfile = "{path}"\n', lights=False, sky=sky)
    )
    expected = [srgb_to_linear(c) * (AMBIENT * 0.1 + 0.9 * sky) for c in MAKE.QUADRANT_COLORS]
    assert_quadrants(image, expected)


def test_metallic_roughness_mapping_limits_and_order() -> None:
    color = (0.5, 0.5, 0.5)
    rough_dielectric = metallic_roughness_material(color, 0.0, 1.0)
    assert (rough_dielectric.specular, rough_dielectric.reflectivity) == (0.0, 0.0)
    assert rough_dielectric.diffuse == rt.PRESETS["matte"].diffuse
    assert not rough_dielectric.metallic
    chrome = metallic_roughness_material(color, 1.0, 0.0)
    assert chrome.metallic and chrome.diffuse == 0.0
    assert chrome.reflectivity == pytest.approx(rt.PRESETS["mirror"].reflectivity)
    # Rougher: a wider, weaker highlight and a fainter mirror, for metals and dielectrics alike.
    for metallic in (0.0, 1.0):
        ladder = [metallic_roughness_material(color, metallic, r) for r in (0.1, 0.4, 0.7, 1.0)]
        for smoother, rougher in itertools.pairwise(ladder):
            assert rougher.shininess < smoother.shininess
            assert rougher.specular < smoother.specular
            assert rougher.reflectivity < smoother.reflectivity


def test_sample_bilinear_matches_a_float64_reference() -> None:
    """Per sample, in float64: texel centres at ((c + ½)/w, 1 − (r + ½)/h), the four
    surrounding texels blended linearly, indices wrapping (repeat)."""
    rng = np.random.default_rng(3)
    height, width = 5, 7
    texels = np.zeros((height, width, 4), np.float32)  # RGB, and a channel to ignore
    texels[..., :3] = rng.uniform(0, 1, (height, width, 3))
    texels[..., 3] = np.nan  # whatever it holds
    uv = rng.uniform(-3, 3, (2, 400)).astype(np.float32)
    got = sample_bilinear(texels, uv)
    assert got.shape == (3, 400) and got.dtype == np.float32
    expected = np.empty((3, 400))
    for i, (u, v) in enumerate(uv.T.astype(np.float64)):
        x = u * width - 0.5
        y = (1 - v) * height - 0.5
        x0, y0 = math.floor(x), math.floor(y)
        fx, fy = x - x0, y - y0
        value = 0.0
        for dy, wy in ((0, 1 - fy), (1, fy)):
            for dx, wx in ((0, 1 - fx), (1, fx)):
                value = value + wy * wx * texels[(y0 + dy) % height, (x0 + dx) % width, :3]
        expected[:, i] = value
    np.testing.assert_allclose(got, expected, atol=2e-5)
    # At a texel's centre, that texel alone; v = 1 is the image's top row.
    rows, columns = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    centres = np.stack([(columns.ravel() + 0.5) / width, 1 - (rows.ravel() + 0.5) / height])
    np.testing.assert_allclose(
        sample_bilinear(texels, centres.astype(np.float32)),
        texels.reshape(-1, 4)[:, :3].T,
        atol=1e-6,
    )


def test_srgb_codes_decode_to_the_standards_values() -> None:
    codes = np.array([[[0, 10, 128], [255, 188, 64]]], np.uint8)
    from PIL import Image

    texels = texels_from_image(Image.fromarray(codes, "RGB"))
    # 10/255 is on the linear segment (÷ 12.92); 128 and 188 are the curve's well-known values.
    want = [[[0.0, 10 / 255 / 12.92, 0.2158605], [1.0, 0.5028865, 0.0512695]]]
    np.testing.assert_allclose(texels[..., :3], want, rtol=1e-5, atol=1e-7)


# -- vertex and face colours ---------------------------------------------------------------------


def test_vertex_colours_are_interpolated_at_every_pixel(tmp_path: Path) -> None:
    """painted_ball.ply with its colours, over the same render in matte white: per pixel, the
    colour the ball has where the pixel's camera ray hits it (one sample per pixel)."""
    entry = f'[[meshes]]\nfile = "{ASSETS / "painted_ball.ply"}"\nsmooth = false\n'
    own = render_file(write_scene(tmp_path / "own.toml", entry), spp=1)
    white = render_file(
        write_scene(
            tmp_path / "white.toml",
            "[materials.white]\ncolor = [1.0, 1.0, 1.0]\n" + entry + 'material = "white"\n',
        ),
        spp=1,
    )
    ball = trimesh.load(str(ASSETS / "painted_ball.ply"), process=False)
    scene = rt.load_scene(tmp_path / "own.toml")
    frame = camera_frame(scene.camera, SIZE, SIZE)
    origins, directions, pixel = primary_rays(frame, 1, scene.render.seed, 0, SIZE * SIZE)
    reference = triangle_hits(origins.T, directions.T, ball.vertices, ball.faces)
    hit = (reference.prim_id >= 0) & ~reference.ambiguous
    assert hit.sum() > 300
    corners = ball.faces[reference.prim_id[hit]]
    u, v = reference.u[hit, None], reference.v[hit, None]
    colors = ball.visual.vertex_colors[:, :3] / 255.0
    expected = (1 - u - v) * colors[corners[:, 0]] + u * colors[corners[:, 1]]
    expected += v * colors[corners[:, 2]]
    rows, columns = np.divmod(pixel[hit], SIZE)
    lit = white[rows, columns]
    assert (lit > 0.05).all()
    np.testing.assert_allclose(own[rows, columns] / lit, expected, rtol=1e-4, atol=1e-5)
    assert np.ptp(expected, axis=0).min() > 0.3  # the ball really is many colours


def test_face_colours_colour_each_face() -> None:
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    palette = np.random.default_rng(5).integers(0, 256, (len(box.faces), 3))
    box.visual.face_colors = np.c_[palette, np.full(len(palette), 255)].astype(np.uint8)
    scene = rt.Scene()
    scene.floor = None
    scene.add_mesh(box)
    directions = np.random.default_rng(6).normal(size=(300, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.zeros((300, 3))  # from the centre, outward: every ray hits
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(origins.T.astype(np.float32), directions.T.astype(np.float32))
    assert hits.hit.all() and hits.colored is not None
    np.testing.assert_array_equal(np.sort(hits.colored), np.arange(300))
    color = np.empty((3, 300), np.float32)
    color[:, hits.colored] = hits.color
    reference = triangle_hits(origins, directions, box.vertices, box.faces)
    fine = ~reference.ambiguous
    np.testing.assert_allclose(
        color.T[fine], palette[reference.prim_id[fine]] / 255.0, rtol=1e-6, atol=1e-7
    )


# -- normals -------------------------------------------------------------------------------------


def test_zero_vertex_normals_shade_as_the_flat_faces(tmp_path: Path) -> None:
    """zero_normals.obj gives every vertex the normal (0, 0, 0): smooth shading falls back to
    the face normals, so the picture is the flat-shaded one, and finite."""
    entry = f'[[meshes]]\nfile = "{ASSETS / "zero_normals.obj"}"\nmaterial = "glossy"\n'
    scene = tmp_path / "s.toml"
    smooth = render_file(write_scene(scene, entry))
    flat = render_file(write_scene(scene, entry + "smooth = false\n"))
    assert np.isfinite(smooth).all()
    assert (flat > 0.1).mean() > 0.2  # the ball is there, and lit
    np.testing.assert_allclose(smooth, flat, atol=1e-4)


def test_vertex_normals_that_cancel_to_rounding_residue_give_no_nan() -> None:
    """Where trimesh's average of the faces around a vertex cancels (back-to-back faces, as in
    trimesh's chair_model.obj) the normal is rounding residue, here 1e-25: its float32 square
    underflows, so normalising it once gave 1e5-long normals, inf highlights and NaN."""
    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    ball.vertex_normals = np.random.default_rng(0).normal(size=ball.vertices.shape) * 1e-25
    images = []
    for smooth in (True, False):
        scene = rt.Scene(camera=rt.Camera(position=(0, 1, 4), look_at=(0, 0.5, 0), fov=40))
        scene.lights.append(rt.PointLight(position=(3, 5, 4)))
        placement = np.eye(4)
        placement[1, 3] = 1.0
        scene.add_mesh(ball, "glossy", transform=placement, smooth=smooth)
        images.append(rt.render(scene, width=48, height=36, spp=2).image)
    assert np.isfinite(images[0]).all()
    np.testing.assert_allclose(images[0], images[1], atol=1e-4)


def test_corners_without_a_normal_lend_the_face_normal() -> None:
    """Half the vertices of a ball keep their normals, half have none to give ((0, 0, 0), NaN
    or 1e-30 residue, in turn): every hit's shading normal is unit length, the face normal on
    faces with no usable corner, and on the others the blend of the corners' normals with the
    face normal standing in for the missing ones."""
    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    normals = ball.vertex_normals.copy()
    missing = np.random.default_rng(1).uniform(size=len(normals)) < 0.5
    unusable = np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 1.0], [1e-30, -2e-30, 1e-30]])
    given = normals.copy()
    given[missing] = unusable[np.arange(missing.sum()) % 3]
    ball.vertex_normals = given
    scene = rt.Scene()
    scene.floor = None
    scene.add_mesh(ball, "matte")
    rng = np.random.default_rng(2)
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins = np.zeros((2000, 3))  # from the centre, outward: every ray hits
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(origins.T.astype(np.float32), directions.T.astype(np.float32))
    reference = triangle_hits(origins, directions, ball.vertices, ball.faces)
    fine = hits.hit & ~reference.ambiguous
    assert fine.sum() > 1900
    corners = ball.faces[reference.prim_id[fine]]
    face = reference.normal[fine]
    weights = np.stack([1 - reference.u - reference.v, reference.u, reference.v], 1)[fine]
    stand_in = np.where(missing[corners][..., None], face[:, None, :], normals[corners])
    expected = np.einsum("nk,nkj->nj", weights, stand_in)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(hits.normal.T[fine], expected, atol=1e-5)
    all_missing = missing[corners].all(axis=1)
    assert all_missing.sum() > 50
    np.testing.assert_allclose(hits.normal.T[fine][all_missing], face[all_missing], atol=1e-5)


# -- the assets ----------------------------------------------------------------------------------


def test_make_assets_makes_exactly_the_files_in_assets(tmp_path: Path) -> None:
    MAKE.main(tmp_path)
    made = sorted(p.name for p in tmp_path.iterdir())
    # the particle files beside them are assets/make_particles.py's (tests/test_particles.py)
    particle_files = {"helix.pdb", "peptide.pdb", "membrane.gsd", "packing.lammpstrj"}
    kept = [p.name for p in ASSETS.iterdir() if p.suffix != ".py" and p.name not in particle_files]
    assert made == sorted(kept)
    for name in made:
        assert_same_meaning(tmp_path / name, ASSETS / name)


def test_asset_meaning_sees_a_changed_pixel_value_or_vertex(tmp_path: Path) -> None:
    """The meaning comparison above is not blind: another deflate stream of the same pixels is
    the same, but one texel changed by one code, one float of a glTF accessor changed, or one
    vertex of the torus moved by 1e-4 fails it."""
    from PIL import Image

    with Image.open(ASSETS / "quadrants.png") as image:
        texels = np.array(image)
    Image.fromarray(texels).save(tmp_path / "quadrants.png", compress_level=1)
    assert (tmp_path / "quadrants.png").read_bytes() != (ASSETS / "quadrants.png").read_bytes()
    assert_same_meaning(tmp_path / "quadrants.png", ASSETS / "quadrants.png")
    texels[0, 0, 0] ^= 1
    Image.fromarray(texels).save(tmp_path / "quadrants.png")
    with pytest.raises(AssertionError):
        assert_same_meaning(tmp_path / "quadrants.png", ASSETS / "quadrants.png")

    gallery = bytearray((ASSETS / "gltf_materials.glb").read_bytes())
    _, accessors, _ = glb_meaning(bytes(gallery))
    json_length = int.from_bytes(gallery[12:16], "little")
    document = json.loads(gallery[20 : 20 + json_length])
    view = document["bufferViews"][document["accessors"][0]["bufferView"]]
    first = 28 + json_length + view.get("byteOffset", 0)  # accessor 0's first value
    assert accessors[0].dtype == np.float32
    gallery[first : first + 4] = np.float32(accessors[0][0, 0] + 0.01).tobytes()
    (tmp_path / "gallery.glb").write_bytes(bytes(gallery))
    with pytest.raises(AssertionError):
        assert_same_meaning(tmp_path / "gallery.glb", ASSETS / "gltf_materials.glb")

    torus = (ASSETS / "torus.obj").read_text().replace("v 0.82000000 ", "v 0.82010000 ", 1)
    (tmp_path / "torus.obj").write_text(torus)
    with pytest.raises(AssertionError):
        assert_same_meaning(tmp_path / "torus.obj", ASSETS / "torus.obj")


def test_the_node_scaled_gltf_scales_by_its_node() -> None:
    mesh, transform = load_part(ASSETS / "node_scaled.glb")
    np.testing.assert_allclose(mesh.extents, [100.0, 100.0, 100.0])
    np.testing.assert_allclose(transform, np.diag([0.01, 0.01, 0.01, 1.0]), atol=1e-12)
