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
- gltf_materials.glb, the glTF material gallery: an emissive panel, a glass ball absorbing
  toward blue-green, cut-out leaves and a normal-mapped panel (written by ``GltfWriter``);
- still_life.glb, a multi-part glTF model (a table whose four legs are one mesh under four
  nodes, a polished metal ball, a glossy torus, a painted ball, the textured cube), each part
  in its own metallic-roughness material: what ``embree-rt render still_life.glb`` shows.
"""

from __future__ import annotations

import io
import json
import struct
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
    return trimesh.creation.torus(
        major_radius=0.6, minor_radius=0.22, major_sections=48, minor_sections=24
    )


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


class GltfWriter:
    """A small glTF 2.0 writer, for files whose every field is spelled out (trimesh's exporter
    writes no samplers, extensions or second UV set): meshes of triangles with any attributes,
    materials given as the JSON they are, PNG images; ``glb()`` is the binary file."""

    def __init__(self) -> None:
        self.json: dict = {
            "asset": {"version": "2.0", "generator": "embree_rt make_assets"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "materials": [],
            "textures": [],
            "images": [],
            "samplers": [],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }
        self.blob = bytearray()

    def _view(self, data: bytes) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.json["bufferViews"].append(
            {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        )
        self.blob += data
        return len(self.json["bufferViews"]) - 1

    def accessor(self, values: np.ndarray) -> int:
        """An accessor of (n, k) float32 values (k = 1..4) or (n,) uint32 indices."""
        values = np.asarray(values)
        if values.dtype.kind in "iu":
            values = np.ascontiguousarray(values.reshape(-1), np.uint32)
            entry = {"componentType": 5125, "type": "SCALAR"}
        else:
            values = np.ascontiguousarray(values, np.float32).reshape(len(values), -1)
            entry = {
                "componentType": 5126,
                "type": ("SCALAR", "VEC2", "VEC3", "VEC4")[values.shape[1] - 1],
            }
            entry["min"] = values.min(axis=0).tolist()
            entry["max"] = values.max(axis=0).tolist()
        entry.update(bufferView=self._view(values.tobytes()), count=len(values))
        self.json["accessors"].append(entry)
        return len(self.json["accessors"]) - 1

    def texture(self, image: Image.Image, sampler: dict | None = None) -> int:
        """A texture of ``image`` (stored as PNG) read through ``sampler`` (glTF's JSON)."""
        stream = io.BytesIO()
        image.save(stream, format="PNG")
        self.json["images"].append(
            {"bufferView": self._view(stream.getvalue()), "mimeType": "image/png"}
        )
        texture = {"source": len(self.json["images"]) - 1}
        if sampler is not None:
            self.json["samplers"].append(sampler)
            texture["sampler"] = len(self.json["samplers"]) - 1
        self.json["textures"].append(texture)
        return len(self.json["textures"]) - 1

    def material(self, material: dict) -> int:
        self.json["materials"].append(material)
        return len(self.json["materials"]) - 1

    def mesh(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        material: int | None = None,
        translation=(0.0, 0.0, 0.0),
        **attributes: np.ndarray,
    ) -> int:
        """A mesh of one triangle primitive placed by a node at ``translation``; ``attributes``
        by glTF name (NORMAL, TEXCOORD_0, TEXCOORD_1, TANGENT, COLOR_0), (n, k) float32."""
        primitive = {
            "attributes": {
                "POSITION": self.accessor(vertices),
                **{name: self.accessor(a) for name, a in attributes.items()},
            },
            "indices": self.accessor(np.asarray(faces, np.uint32)),
        }
        if material is not None:
            primitive["material"] = material
        self.json["meshes"].append({"primitives": [primitive]})
        self.json["nodes"].append(
            {"mesh": len(self.json["meshes"]) - 1, "translation": [float(t) for t in translation]}
        )
        self.json["scenes"][0]["nodes"].append(len(self.json["nodes"]) - 1)
        return len(self.json["meshes"]) - 1

    def glb(self) -> bytes:
        document = {key: value for key, value in self.json.items() if value != []}
        used = sorted(
            {name for m in self.json["materials"] for name in m.get("extensions", {})}
            | {
                name
                for m in self.json["materials"]
                for info in _texture_infos(m)
                for name in info.get("extensions", {})
            }
        )
        if used:
            document["extensionsUsed"] = used
        while len(self.blob) % 4:
            self.blob.append(0)
        document["buffers"] = [{"byteLength": len(self.blob)}]
        text = json.dumps(document, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        body = (
            struct.pack("<I4s", len(text), b"JSON")
            + text
            + struct.pack("<I4s", len(self.blob), b"BIN\x00")
            + bytes(self.blob)
        )
        return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def _texture_infos(material: dict) -> list[dict]:
    """Every textureInfo a glTF material holds (its own, its pbr block's, its extensions')."""
    blocks = [
        material,
        material.get("pbrMetallicRoughness", {}),
        *material.get("extensions", {}).values(),
    ]
    return [
        value
        for block in blocks
        for key, value in block.items()
        if key.endswith("Texture") and isinstance(value, dict)
    ]


def quad(size: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square in the xy-plane centred at the origin facing +z: (4, 3) vertices, (2, 3) faces
    (counter-clockwise seen from +z) and (4, 2) glTF UVs (v down: (0, 0) at the top left)."""
    h = size / 2
    vertices = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    return vertices, np.array([[0, 1, 2], [0, 2, 3]]), uv


def _placed(
    vertices: np.ndarray, rotate_x: float = 0.0, rotate_y: float = 0.0, translate=(0.0, 0.0, 0.0)
) -> np.ndarray:
    """``vertices`` (n, 3) turned about x, then y (degrees), then moved."""
    matrix = trimesh.transformations.euler_matrix(
        np.radians(rotate_x), np.radians(rotate_y), 0, "sxyz"
    )
    return (vertices @ matrix[:3, :3].T + np.asarray(translate)).astype(np.float32)


def leaf_alpha(size: int = 64) -> Image.Image:
    """RGBA, white, opaque inside a pointed leaf with a round hole in it, clear elsewhere."""
    y, x = np.mgrid[0:size, 0:size] / (size - 1) * 2 - 1  # x right, y down, in [-1, 1]
    inside = np.abs(x) < 0.55 * (1 - y**2)
    hole = (x**2 + (y + 0.25) ** 2) < 0.15**2
    alpha = np.where(inside & ~hole, 255, 0).astype(np.uint8)
    return Image.fromarray(np.dstack([np.full((size, size, 3), 255, np.uint8), alpha]), "RGBA")


def bump_normals(size: int = 64, cells: int = 6) -> Image.Image:
    """A tangent-space normal map (x right, y up, as glTF's) of a grid of round bumps."""
    row, column = np.mgrid[0:size, 0:size] + 0.5
    x = (column / size * cells) % 1 - 0.5
    y = ((size - row) / size * cells) % 1 - 0.5  # up the image
    r2 = x**2 + y**2
    radius2 = 0.4**2
    bump = r2 < radius2
    height = np.sqrt(np.maximum(radius2 - r2, 1e-6))  # a spherical cap: dh/dx = -x / h
    normal = np.dstack(
        [np.where(bump, x / height, 0), np.where(bump, y / height, 0), np.ones_like(x)]
    )
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    return Image.fromarray(np.round((normal + 1) / 2 * 255).astype(np.uint8), "RGB")


def glowing_rings(size: int = 64) -> Image.Image:
    """Concentric rings fading from warm to dark: the emissive texture of the gallery's panel."""
    y, x = np.mgrid[0:size, 0:size] / (size - 1) * 2 - 1
    glow = 0.5 + 0.5 * np.cos(np.sqrt(x**2 + y**2) * 4 * 2 * np.pi)
    pixels = glow[..., None] * np.array([255, 190, 90]) + (1 - glow[..., None]) * [40, 10, 60]
    return Image.fromarray(np.round(pixels).astype(np.uint8), "RGB")


def gltf_materials_gallery() -> bytes:
    """A GLB of the glTF material features together: an emissive panel (emissive texture and
    strength), a glass ball (transmission, IOR, volume absorption), cut-out leaves (MASK, with
    a hole in each) that cast leaf-shaped shadows, and a panel of bumps (normal map)."""
    writer = GltfWriter()
    linear = {"magFilter": 9729, "minFilter": 9729}
    # The emissive panel, upright, facing the camera.
    vertices, faces, uv = quad(1.3)
    glow = writer.material(
        {
            "pbrMetallicRoughness": {"baseColorFactor": [0.05, 0.05, 0.05, 1], "metallicFactor": 0},
            "emissiveFactor": [1.0, 1.0, 1.0],
            "emissiveTexture": {"index": writer.texture(glowing_rings(), linear)},
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 1.5}},
        }
    )
    writer.mesh(
        _placed(vertices, rotate_y=25, translate=(-1.9, 0.75, -0.6)), faces, glow, TEXCOORD_0=uv
    )
    # The glass ball, absorbing toward blue-green.
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.65)
    glass = writer.material(
        {
            "pbrMetallicRoughness": {
                "baseColorFactor": [1, 1, 1, 1],
                "metallicFactor": 0,
                "roughnessFactor": 0.05,
            },
            "extensions": {
                "KHR_materials_transmission": {"transmissionFactor": 1.0},
                "KHR_materials_ior": {"ior": 1.5},
                "KHR_materials_volume": {
                    "thicknessFactor": 1.3,
                    "attenuationColor": [0.35, 0.8, 0.7],
                    "attenuationDistance": 0.6,
                },
            },
        }
    )
    writer.mesh(
        _placed(ball.vertices, translate=(0.0, 0.65, 0.2)),
        ball.faces,
        glass,
        NORMAL=ball.vertex_normals,
    )
    # Leaves, tilted over the floor: cut out by MASK, seen from both sides.
    leaf = writer.material(
        {
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.25, 0.6, 0.15, 1],
                "metallicFactor": 0,
                "baseColorTexture": {"index": writer.texture(leaf_alpha(), linear)},
            },
            "alphaMode": "MASK",
            "alphaCutoff": 0.5,
            "doubleSided": True,
        }
    )
    for tilt, turn, place in (
        (-60, 20, (1.0, 1.2, 1.3)),
        (-70, -35, (0.45, 1.35, 1.8)),
        (-50, 70, (1.6, 1.05, 1.0)),
    ):
        vertices, faces, uv = quad(0.8)
        writer.mesh(
            _placed(vertices, rotate_x=tilt, rotate_y=turn, translate=place),
            faces,
            leaf,
            TEXCOORD_0=uv,
        )
    # The panel of bumps: flat geometry, its normals from the map.
    vertices, faces, uv = quad(1.3)
    bumps = writer.material(
        {
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.85, 0.8, 0.75, 1],
                "metallicFactor": 0,
                "roughnessFactor": 0.4,
            },
            "normalTexture": {"index": writer.texture(bump_normals(), linear)},
        }
    )
    writer.mesh(
        _placed(vertices, rotate_y=-30, translate=(1.95, 0.75, -0.7)), faces, bumps, TEXCOORD_0=uv
    )
    return writer.glb()


def _pbr(mesh: trimesh.Trimesh, color, metallic: float, roughness: float) -> trimesh.Trimesh:
    """``mesh`` in a glTF metallic-roughness material of linear ``color`` (RGB)."""
    material = trimesh.visual.material.PBRMaterial(
        baseColorFactor=[*color, 1.0], metallicFactor=metallic, roughnessFactor=roughness
    )
    mesh.visual = trimesh.visual.TextureVisuals(material=material)
    return mesh


def still_life(texture: Image.Image) -> trimesh.Scene:
    """A table (top, and one leg mesh under four nodes) with things on it, in metres."""
    scene = trimesh.Scene()
    top = _pbr(trimesh.creation.box(extents=(1.6, 0.06, 0.9)), (0.45, 0.25, 0.12), 0.0, 0.55)
    scene.add_geometry(top, node_name="top", transform=_moved(0.0, 0.72, 0.0))
    leg = _pbr(
        trimesh.creation.cylinder(radius=0.035, height=0.69, sections=24),
        (0.08, 0.08, 0.09),
        0.0,
        0.4,
    )
    upright = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    scene.add_geometry(
        leg, geom_name="leg", node_name="leg0", transform=_moved(-0.72, 0.345, -0.37) @ upright
    )
    for i, (x, z) in enumerate([(0.72, -0.37), (-0.72, 0.37), (0.72, 0.37)], start=1):
        # the other three nodes name the same mesh: one glTF mesh placed four times
        scene.graph.update(frame_to=f"leg{i}", geometry="leg", matrix=_moved(x, 0.345, z) @ upright)
    metal = _pbr(
        trimesh.creation.icosphere(subdivisions=3, radius=0.16), (0.95, 0.8, 0.5), 1.0, 0.05
    )
    scene.add_geometry(metal, node_name="metal_ball", transform=_moved(-0.45, 0.91, 0.1))
    ring = _pbr(torus(), (0.7, 0.05, 0.05), 0.0, 0.2)
    ring.apply_scale(0.25)
    scene.add_geometry(
        ring,
        node_name="torus",
        transform=_moved(0.0, 0.955, -0.22)
        @ trimesh.transformations.rotation_matrix(0.5, [0, 1, 0]),
    )
    ball = painted_ball()
    ball.apply_scale(0.3)
    scene.add_geometry(ball, node_name="painted_ball", transform=_moved(0.5, 0.9, 0.2))
    cube = textured_gltf_cube(texture)
    cube.apply_scale(0.22)
    scene.add_geometry(
        cube,
        node_name="cube",
        transform=_moved(0.45, 0.86, -0.25)
        @ trimesh.transformations.rotation_matrix(0.6, [0, 1, 0]),
    )
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
    (directory / "gltf_materials.glb").write_bytes(gltf_materials_gallery())
    still_life(texture).export(directory / "still_life.glb")


if __name__ == "__main__":
    main()
