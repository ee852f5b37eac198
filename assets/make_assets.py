"""Make the small meshes the example scenes use, from trimesh's primitives.

    python assets/make_assets.py

Writes, beside this script: torus.obj, gem.ply, capsule.stl, cone.off, twisted_box.glb,
trio.glb (a glTF scene of three nodes, each with its own transform), and the meshes that carry
their own looks:

- quadrants.png, a 64x64 sRGB texture of four solid quadrants (QUADRANT_COLORS), and
  quadrant_cube.obj + quadrant_cube.mtl, a unit cube showing it whole on every face (map_Kd);
- quadrant_cube.glb, the same cube in glTF, its base colour the texture times CUBE_FACTOR
  (metallic 0, roughness 1: no highlight, no reflection);
- painted_ball.ply, an icosphere with a colour per vertex;
- zero_normals.obj, an icosphere whose file gives every vertex the normal (0, 0, 0);
- node_scaled.glb, a 100-unit box whose glTF node scales it by 0.01 (as Duck.glb's does);
- still_life.glb, a multi-part glTF model (a table whose four legs are one mesh under four
  nodes, a polished metal ball, a glossy torus, a painted ball, the textured cube), each part
  in its own metallic-roughness material: what ``embree-rt render still_life.glb`` shows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

HERE = Path(__file__).resolve().parent

# 8-bit sRGB colours of the quadrants of quadrants.png, as the image shows them: (top left, top
# right, bottom left, bottom right).
QUADRANT_COLORS = ((200, 40, 40), (40, 170, 70), (40, 80, 210), (235, 200, 40))
QUADRANT_TEXELS = 64
# quadrant_cube.glb's baseColorFactor (RGB, linear, each k/255 so that 8 bits hold it exactly).
CUBE_FACTOR = (1.0, 0.6, 0.2)


def torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=0.6, minor_radius=0.22, major_sections=48,
                                  minor_sections=24)  # fmt: skip


def gem() -> trimesh.Trimesh:
    """A faceted gem: an icosahedron, squashed, its facets kept flat."""
    mesh = trimesh.creation.icosahedron()
    mesh.apply_scale([0.5, 0.7, 0.5])
    return mesh


def capsule() -> trimesh.Trimesh:
    return trimesh.creation.capsule(height=0.8, radius=0.3, count=[24, 24])


def cone() -> trimesh.Trimesh:
    return trimesh.creation.cone(radius=0.5, height=1.2, sections=48)


def twisted_box() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(0.6, 1.4, 0.6))
    box = box.subdivide().subdivide().subdivide()
    vertices = box.vertices.copy()
    angle = vertices[:, 1] * 1.2  # twist about y, more with height
    cos, sin = np.cos(angle), np.sin(angle)
    x, z = vertices[:, 0].copy(), vertices[:, 2].copy()
    vertices[:, 0] = cos * x - sin * z
    vertices[:, 2] = sin * x + cos * z
    return trimesh.Trimesh(vertices, box.faces, process=False)


def trio() -> trimesh.Scene:
    scene = trimesh.Scene()
    colors = [(230, 80, 60, 255), (70, 170, 90, 255), (60, 110, 220, 255)]
    for i, color in enumerate(colors):
        mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.35)
        mesh.visual.vertex_colors = color
        transform = trimesh.transformations.translation_matrix([(i - 1) * 0.9, 0.35, 0])
        scene.add_geometry(mesh, node_name=f"ball{i}", transform=transform)
    return scene


def quadrants() -> Image.Image:
    """QUADRANT_TEXELS square, one solid colour per quadrant (row 0 is the image's top)."""
    half = QUADRANT_TEXELS // 2
    pixels = np.zeros((QUADRANT_TEXELS, QUADRANT_TEXELS, 3), np.uint8)
    top_left, top_right, bottom_left, bottom_right = QUADRANT_COLORS
    pixels[:half, :half] = top_left
    pixels[:half, half:] = top_right
    pixels[half:, :half] = bottom_left
    pixels[half:, half:] = bottom_right
    return Image.fromarray(pixels, "RGB")


def textured_cube() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit cube centred at the origin with the whole texture on each face, seen upright from
    outside (the +y and -y faces have their top towards -z and +z): (24, 3) float64 vertices,
    (12, 3) int64 counter-clockwise faces, (24, 2) float64 UVs (v up, as OBJ and trimesh)."""
    # Per face: outward normal, then the directions of u and v across it.
    frames = [
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
        ((1, 0, 0), (0, 0, -1), (0, 1, 0)),
        ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((0, 1, 0), (1, 0, 0), (0, 0, -1)),
        ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    ]
    corners_uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    vertices, faces, uv = [], [], []
    for normal, along_u, along_v in frames:
        normal, along_u, along_v = (np.asarray(a, float) for a in (normal, along_u, along_v))
        first = len(vertices)
        for cu, cv in corners_uv:
            vertices.append(0.5 * normal + (cu - 0.5) * along_u + (cv - 0.5) * along_v)
            uv.append((cu, cv))
        faces += [(first, first + 1, first + 2), (first, first + 2, first + 3)]
    return np.array(vertices), np.array(faces, np.int64), np.array(uv)


def write_textured_obj(obj: Path, texture_name: str) -> None:
    """quadrant_cube as OBJ text with UVs and an MTL beside it naming the texture (map_Kd)."""
    vertices, faces, uv = textured_cube()
    mtl = obj.with_suffix(".mtl")
    lines = [f"mtllib {mtl.name}", "usemtl quadrants"]
    lines += [f"v {x:g} {y:g} {z:g}" for x, y, z in vertices]
    lines += [f"vt {u:g} {v:g}" for u, v in uv]
    lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in face) for face in faces]
    obj.write_text("\n".join(lines) + "\n", encoding="utf-8")
    mtl.write_text(
        f"newmtl quadrants\nKd 1 1 1\nKs 0 0 0\nmap_Kd {texture_name}\n", encoding="utf-8"
    )


def textured_gltf_cube(texture: Image.Image) -> trimesh.Trimesh:
    vertices, faces, uv = textured_cube()
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=texture,
        baseColorFactor=[*CUBE_FACTOR, 1.0],
        metallicFactor=0.0,
        roughnessFactor=1.0,
    )
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    return trimesh.Trimesh(vertices, faces, visual=visual, process=False)


def painted_ball() -> trimesh.Trimesh:
    """An icosphere whose vertex colours run through the hues around y, paler towards +y."""
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    x, y, z = ball.vertices.T / 0.5
    hue = (np.arctan2(z, x) / (2 * np.pi)) % 1.0
    rgb = np.clip(np.abs(((hue[:, None] * 6 + [0, 4, 2]) % 6) - 3) - 1, 0, 1)
    rgb = rgb + (1 - rgb) * (0.5 * (y[:, None] + 1)) ** 3  # towards white at the top
    ball.visual.vertex_colors = np.c_[np.round(rgb * 255), np.full(len(rgb), 255)].astype(np.uint8)
    return ball


def write_zero_normals_obj(obj: Path) -> None:
    """An icosphere as OBJ text whose every vertex normal is (0, 0, 0) (``vn 0 0 0``)."""
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in ball.vertices]
    lines += ["vn 0 0 0"] * len(ball.vertices)
    lines += ["f " + " ".join(f"{i + 1}//{i + 1}" for i in face) for face in ball.faces]
    obj.write_text("\n".join(lines) + "\n", encoding="utf-8")


def node_scaled() -> trimesh.Scene:
    """A box 100 units on a side under a glTF node that scales it by 0.01."""
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=(100.0, 100.0, 100.0))
    scene.add_geometry(box, node_name="scaled", transform=np.diag([0.01, 0.01, 0.01, 1.0]))
    return scene


def _pbr(mesh: trimesh.Trimesh, color, metallic: float, roughness: float) -> trimesh.Trimesh:
    """``mesh`` in a glTF metallic-roughness material of linear ``color`` (RGB)."""
    material = trimesh.visual.material.PBRMaterial(baseColorFactor=[*color, 1.0],
                                                   metallicFactor=metallic,
                                                   roughnessFactor=roughness)  # fmt: skip
    mesh.visual = trimesh.visual.TextureVisuals(material=material)
    return mesh


def still_life(texture: Image.Image) -> trimesh.Scene:
    """A table (top, and one leg mesh under four nodes) with things on it, in metres."""
    scene = trimesh.Scene()
    top = _pbr(trimesh.creation.box(extents=(1.6, 0.06, 0.9)), (0.45, 0.25, 0.12), 0.0, 0.55)
    scene.add_geometry(top, node_name="top", transform=_moved(0.0, 0.72, 0.0))
    leg = _pbr(trimesh.creation.cylinder(radius=0.035, height=0.69, sections=24),
               (0.08, 0.08, 0.09), 0.0, 0.4)  # fmt: skip
    upright = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    scene.add_geometry(leg, geom_name="leg", node_name="leg0",
                       transform=_moved(-0.72, 0.345, -0.37) @ upright)  # fmt: skip
    for i, (x, z) in enumerate([(0.72, -0.37), (-0.72, 0.37), (0.72, 0.37)], start=1):
        # the other three nodes name the same mesh: one glTF mesh placed four times
        scene.graph.update(frame_to=f"leg{i}", geometry="leg",
                           matrix=_moved(x, 0.345, z) @ upright)  # fmt: skip
    metal = _pbr(trimesh.creation.icosphere(subdivisions=3, radius=0.16), (0.95, 0.8, 0.5), 1.0,
                 0.05)  # fmt: skip
    scene.add_geometry(metal, node_name="metal_ball", transform=_moved(-0.45, 0.91, 0.1))
    ring = _pbr(torus(), (0.7, 0.05, 0.05), 0.0, 0.2)
    ring.apply_scale(0.25)
    scene.add_geometry(ring, node_name="torus", transform=_moved(0.0, 0.955, -0.22)
                       @ trimesh.transformations.rotation_matrix(0.5, [0, 1, 0]))  # fmt: skip
    ball = painted_ball()
    ball.apply_scale(0.3)
    scene.add_geometry(ball, node_name="painted_ball", transform=_moved(0.5, 0.9, 0.2))
    cube = textured_gltf_cube(texture)
    cube.apply_scale(0.22)
    scene.add_geometry(cube, node_name="cube", transform=_moved(0.45, 0.86, -0.25)
                       @ trimesh.transformations.rotation_matrix(0.6, [0, 1, 0]))  # fmt: skip
    return scene


def _moved(x: float, y: float, z: float) -> np.ndarray:
    return trimesh.transformations.translation_matrix([x, y, z])


def main(directory: Path = HERE) -> None:
    """Write every asset into ``directory`` (this script's own by default)."""
    torus().export(directory / "torus.obj")
    gem().export(directory / "gem.ply")
    capsule().export(directory / "capsule.stl")
    cone().export(directory / "cone.off")
    twisted_box().export(directory / "twisted_box.glb")
    trio().export(directory / "trio.glb")
    texture = quadrants()
    texture.save(directory / "quadrants.png", optimize=True)
    write_textured_obj(directory / "quadrant_cube.obj", "quadrants.png")
    textured_gltf_cube(texture).export(directory / "quadrant_cube.glb")
    painted_ball().export(directory / "painted_ball.ply")
    write_zero_normals_obj(directory / "zero_normals.obj")
    node_scaled().export(directory / "node_scaled.glb")
    still_life(texture).export(directory / "still_life.glb")


if __name__ == "__main__":
    main()
