"""What a glTF file says that trimesh does not keep, read from its JSON here.

trimesh loads a glTF's meshes, materials and node hierarchy. It does not apply sparse accessors
(it reads their base, or zeros), ignores ``EXT_mesh_gpu_instancing`` (each instanced node shows
its one prototype), drops a camera node's own mesh and children, keeps no lights, and says
nothing of an extension it does not honour or of a file it cannot find. ``prepare_gltf`` reads
the JSON first and returns what trimesh should load — the file as it is, or, when it has to, a
rewrite of its JSON with sparse accessors made dense, instanced nodes' meshes taken off the nodes
(they become instance arrays) and cameras taken off their nodes — and what trimesh would lose:
the instance placements, the first camera a node uses, the ``KHR_lights_punctual`` lights.

Problems are ``MeshFileError`` (key inside the file, problem); things left out are one
``InputWarning`` line each.
"""

from __future__ import annotations

import base64
import importlib.util
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from embree_rt.scene.errors import MeshFileError, warn_input
from embree_rt.scene.mesh_companions import candidate_paths

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_COMPONENT_TYPES = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
# Tags the rewritten JSON puts on a mesh's ``extras``, so that the loaded geometries of an
# instanced node's mesh can be found (trimesh copies a mesh's extras into each primitive's
# metadata).
MESH_INDEX_TAG = "embree_rt_mesh_index"

# The extensions embree_rt honours, and how. A file requiring any other is refused (the glTF
# specification forbids loading it); one using any other optionally is loaded with a warning.
SUPPORTED_EXTENSIONS = {
    "KHR_draco_mesh_compression": "decoded by DracoPy",
    "KHR_materials_pbrSpecularGlossiness": "converted to metallic-roughness by trimesh",
    "EXT_texture_webp": "WebP images decoded by Pillow",
    "EXT_mesh_gpu_instancing": "each instanced node becomes instance arrays",
    "KHR_lights_punctual": "the file's lights, when it is rendered on its own (point; spot and "
    "directional as point lights)",
    "KHR_materials_emissive_strength": "the emission's strength",
    "KHR_materials_transmission": "glass of that transparency, tinted by the base colour",
    "KHR_materials_ior": "the glass's index of refraction",
    "KHR_materials_volume": "Beer-Lambert absorption inside the glass",
    "KHR_materials_unlit": "the base colour alone, no lights",
    "KHR_texture_transform": "offset, rotation, scale and texCoord of each texture",
}
# Extensions with no counterpart in Blinn-Phong shading and Whitted rays, which the warning
# naming what a file uses and embree_rt ignores says of them.
NO_COUNTERPART_EXTENSIONS = (
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_specular",
    "KHR_materials_iridescence",
    "KHR_materials_anisotropy",
    "KHR_materials_dispersion",
    "KHR_materials_diffuse_transmission",
)


def extension_problem(name: str) -> str | None:
    """Why embree_rt cannot honour the glTF extension ``name``, or None when it can."""
    if name in NO_COUNTERPART_EXTENSIONS:
        return "no counterpart in embree_rt's Blinn-Phong shading"
    if name not in SUPPORTED_EXTENSIONS:
        return "not supported by embree_rt"
    if name == "KHR_draco_mesh_compression" and importlib.util.find_spec("DracoPy") is None:
        return "needs the DracoPy package (pip install DracoPy)"
    return None


@dataclass(frozen=True)
class FileCamera:
    """A perspective camera of a glTF file in world space: ``position``, ``forward`` and ``up``
    (3,) float64 (unit vectors), vertical field of view in degrees, width / height or None."""

    key: str
    position: np.ndarray
    forward: np.ndarray
    up: np.ndarray
    yfov_degrees: float
    aspect_ratio: float | None


@dataclass(frozen=True)
class FileLight:
    """A ``KHR_lights_punctual`` light placed by a node, in world space: ``kind`` "point",
    "spot" or "directional"; ``position`` and ``direction`` (3,) float64 (the way it shines,
    unit); ``color`` linear RGB; ``intensity`` in the file's units (candela, or lux for a
    directional light); ``outer_cone_degrees`` for a spot."""

    key: str
    kind: str
    position: np.ndarray
    direction: np.ndarray
    color: tuple[float, float, float]
    intensity: float
    outer_cone_degrees: float | None = None


@dataclass
class PreparedGltf:
    """``data``: the bytes trimesh should load (None: the file itself); ``instanced``: (mesh
    index, (n, 4, 4) float64 world transforms, the key of the node) per instanced node;
    ``camera`` and ``lights`` as the file places them."""

    data: bytes | None = None
    instanced: list[tuple[int, np.ndarray, str]] = field(default_factory=list)
    camera: FileCamera | None = None
    lights: list[FileLight] = field(default_factory=list)


# -- reading -------------------------------------------------------------------------------------


def read_gltf(path: Path) -> tuple[dict, bytes | None]:
    """The JSON of a ``.gltf`` or ``.glb`` and a GLB's binary chunk (None if it has none)."""
    data = path.read_bytes()
    if path.suffix.lower() != ".glb" and data[:4] != _GLB_MAGIC:
        return _parse_json(data), None
    if len(data) < 20 or data[:4] != _GLB_MAGIC:
        raise MeshFileError("(file)", "not a binary glTF (no 'glTF' header)")
    chunks = []
    at = 12
    while at + 8 <= len(data):
        length, kind = struct.unpack_from("<II", data, at)
        chunks.append((kind, data[at + 8 : at + 8 + length]))
        at += 8 + length
    if not chunks or chunks[0][0] != _CHUNK_JSON:
        raise MeshFileError("(file)", "the first chunk of the binary glTF is not JSON")
    binary = next((chunk for kind, chunk in chunks[1:] if kind == _CHUNK_BIN), None)
    return _parse_json(chunks[0][1]), binary


def _parse_json(data: bytes) -> dict:
    try:
        tree = json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise MeshFileError("(file)", f"malformed glTF JSON: {error}") from None
    if not isinstance(tree, dict):
        raise MeshFileError("(file)", "the glTF JSON is not an object")
    return tree


def uri_path(root: Path, uri: str) -> Path | None:
    """The file a glTF ``uri`` names, looked for as ``candidate_paths`` says, or None."""
    return next((p for p in candidate_paths(root, uri) if p.is_file()), None)


def _is_data_uri(uri: str) -> bool:
    return uri.startswith("data:")


class GltfBuffers:
    """The file's buffers, each read once when first asked for."""

    def __init__(self, path: Path, tree: dict, binary: bytes | None) -> None:
        self.path, self.tree, self.binary = path, tree, binary
        self.loaded: dict[int, bytes] = {}

    def __getitem__(self, index: int) -> bytes:
        if index not in self.loaded:
            buffer = self.tree["buffers"][index]
            uri = buffer.get("uri")
            if uri is None:
                if self.binary is None:
                    raise MeshFileError(f"buffers[{index}]", "no uri and no binary chunk")
                self.loaded[index] = self.binary
            elif _is_data_uri(uri):
                self.loaded[index] = base64.b64decode(uri.split(",", 1)[1])
            else:
                self.loaded[index] = uri_path(self.path.parent, uri).read_bytes()
        return self.loaded[index]


def accessor_array(tree: dict, buffers, index: int, normalized: bool = False) -> np.ndarray:
    """The values of accessor ``index``, (count, components) (components 1 for SCALAR), in
    the accessor's component type, with its ``sparse`` substitutions applied (onto zeros when
    it has no ``bufferView``). ``normalized``: integer components of a normalized accessor
    become float64 in [-1, 1] or [0, 1], as the glTF specification defines."""
    accessor = tree["accessors"][index]
    dtype = np.dtype(_COMPONENT_TYPES[accessor["componentType"]]).newbyteorder("<")
    width = _TYPE_SIZES[accessor["type"]]
    count = int(accessor["count"])
    if "bufferView" in accessor:
        values = _view_rows(
            tree,
            buffers,
            accessor["bufferView"],
            accessor.get("byteOffset", 0),
            dtype,
            width,
            count,
        )
    else:
        values = np.zeros((count, width), dtype)
    if "sparse" in accessor:
        sparse = accessor["sparse"]
        n = int(sparse["count"])
        where = sparse["indices"]
        index_type = np.dtype(_COMPONENT_TYPES[where["componentType"]]).newbyteorder("<")
        rows = _view_rows(
            tree, buffers, where["bufferView"], where.get("byteOffset", 0), index_type, 1, n
        )[:, 0]
        what = sparse["values"]
        substitutes = _view_rows(
            tree, buffers, what["bufferView"], what.get("byteOffset", 0), dtype, width, n
        )
        if n and rows.max() >= count:
            raise MeshFileError(
                f"accessors[{index}].sparse.indices",
                f"index {int(rows.max())} outside the accessor's {count} rows",
            )
        values = values.copy()
        values[rows.astype(np.int64)] = substitutes
    if normalized and accessor.get("normalized") and dtype.kind in "iu":
        info = np.iinfo(dtype)
        return np.maximum(values / float(info.max), -1.0)
    return values


def _view_rows(
    tree: dict, buffers, view_index: int, offset: int, dtype: np.dtype, width: int, count: int
) -> np.ndarray:
    """(count, width) ``dtype`` rows of buffer view ``view_index`` from byte ``offset``,
    honouring the view's ``byteStride``."""
    view = tree["bufferViews"][view_index]
    data = buffers[view["buffer"]]
    start = view.get("byteOffset", 0) + offset
    row_bytes = dtype.itemsize * width
    stride = view.get("byteStride", row_bytes)
    if count == 0:
        return np.zeros((0, width), dtype)
    rows = np.lib.stride_tricks.as_strided(
        np.frombuffer(data, np.uint8, count=(count - 1) * stride + row_bytes, offset=start),
        (count, row_bytes),
        (stride, 1),
    )
    return np.ascontiguousarray(rows).view(dtype).reshape(count, width)


# -- node transforms -----------------------------------------------------------------------------


def node_matrix(node: dict) -> np.ndarray:
    """(4, 4) float64 local transform of a glTF node: ``matrix`` (column-major), else T·R·S
    (rotation a unit quaternion x, y, z, w)."""
    if "matrix" in node:
        return np.array(node["matrix"], np.float64).reshape(4, 4).T
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_matrices(np.array([node.get("rotation", (0, 0, 0, 1))]))[0]
    matrix[:3, :3] *= np.asarray(node.get("scale", (1, 1, 1)), np.float64)
    matrix[:3, 3] = node.get("translation", (0, 0, 0))
    return matrix


def quaternion_matrices(xyzw: np.ndarray) -> np.ndarray:
    """(n, 3, 3) float64 rotations of (n, 4) quaternions x, y, z, w (normalised here)."""
    q = np.asarray(xyzw, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1),
        ],
        axis=1,
    )


def scene_nodes(tree: dict) -> list[tuple[int, np.ndarray]]:
    """(node index, (4, 4) float64 world transform) of each node of the file's scene (its
    ``scene``, else the first), depth first in the file's order; a node reached twice (a
    malformed, cyclic hierarchy) is visited once."""
    scenes = tree.get("scenes") or []
    if not scenes:
        return []
    roots = scenes[tree.get("scene", 0)].get("nodes", [])
    nodes = tree.get("nodes", [])
    visited: list[tuple[int, np.ndarray]] = []
    seen: set[int] = set()
    stack = [(index, np.eye(4)) for index in reversed(roots)]
    while stack:
        index, parent = stack.pop()
        if index in seen:
            continue
        seen.add(index)
        world = parent @ node_matrix(nodes[index])
        visited.append((index, world))
        stack.extend((child, world) for child in reversed(nodes[index].get("children", [])))
    return visited


# -- the whole file ------------------------------------------------------------------------------


def prepare_gltf(path: Path) -> PreparedGltf:
    """Read ``path``'s JSON: check its extensions and the files it names, and find what trimesh
    would not keep (module docstring). Raises ``MeshFileError``; warns ``InputWarning``."""
    tree, binary = read_gltf(path)
    _check_extensions(path, tree)
    _check_files(path, tree)
    buffers = GltfBuffers(path, tree, binary)
    prepared = PreparedGltf()
    rewrite = False
    if any("sparse" in accessor for accessor in tree.get("accessors", [])):
        _densify_sparse(tree, buffers)
        rewrite = True
    nodes = tree.get("nodes", [])
    for index, world in scene_nodes(tree):
        node = nodes[index]
        extensions = node.get("extensions") or {}
        instancing = extensions.get("EXT_mesh_gpu_instancing")
        if instancing is not None and "mesh" in node:
            transforms = _instance_matrices(tree, buffers, instancing, f"nodes[{index}]")
            prepared.instanced.append((node["mesh"], world @ transforms, f"nodes[{index}]"))
            _tag_mesh(tree["meshes"][node["mesh"]], node["mesh"])
            del node["mesh"]
            rewrite = True
        if "camera" in node:
            if prepared.camera is None:
                prepared.camera = _camera(path, tree, node["camera"], world)
            del node["camera"]
            rewrite = True
        light = extensions.get("KHR_lights_punctual")
        if light is not None:
            prepared.lights.append(_light(tree, light.get("light"), world, f"nodes[{index}]"))
    if rewrite:
        prepared.data = _write(path, tree, binary)
    return prepared


def _check_extensions(path: Path, tree: dict) -> None:
    for index, name in enumerate(tree.get("extensionsRequired") or []):
        if (problem := extension_problem(name)) is not None:
            raise MeshFileError(
                f"extensionsRequired[{index}]", f"the file requires {name}, {problem}"
            )
    by_problem: dict[str, list[str]] = {}
    for name in tree.get("extensionsUsed") or []:
        if (problem := extension_problem(name)) is not None:
            by_problem.setdefault(problem, []).append(name)
    if by_problem:
        ignored = "; ".join(
            f"{', '.join(names)} ignored ({problem})" for problem, names in by_problem.items()
        )
        warn_input(f"{path}: extensionsUsed: {ignored}; the file renders without them")


def _check_files(path: Path, tree: dict) -> None:
    """A buffer file that is missing is an error; an image file, a warning naming it."""
    for group in ("buffers", "images"):
        for index, item in enumerate(tree.get(group) or []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if not isinstance(uri, str) or _is_data_uri(uri):
                continue
            if uri_path(path.parent, uri) is not None:
                continue
            if group == "buffers":
                raise MeshFileError(
                    f"buffers[{index}].uri", f"no such file {uri!r} (looked in {path.parent})"
                )
            warn_input(
                f"{path}: images[{index}].uri: no such file {uri!r} (looked in "
                f"{path.parent}); the materials using it render without it"
            )


def _densify_sparse(tree: dict, buffers: GltfBuffers) -> None:
    """Give every sparse accessor its applied values in a new buffer (a data URI appended to
    ``buffers``), so trimesh reads what the file means."""
    blob = bytearray()
    views = tree.setdefault("bufferViews", [])
    new_buffer = len(tree.get("buffers", []))
    for index, accessor in enumerate(tree["accessors"]):
        if "sparse" not in accessor:
            continue
        values = np.ascontiguousarray(accessor_array(tree, buffers, index))
        blob += b"\0" * (-len(blob) % 4)
        views.append({"buffer": new_buffer, "byteOffset": len(blob), "byteLength": values.nbytes})
        blob += values.tobytes()
        accessor["bufferView"] = len(views) - 1
        accessor.pop("byteOffset", None)
        del accessor["sparse"]
    encoded = base64.b64encode(bytes(blob)).decode("ascii")
    tree.setdefault("buffers", []).append(
        {"byteLength": len(blob), "uri": f"data:application/octet-stream;base64,{encoded}"}
    )


def _instance_matrices(tree: dict, buffers: GltfBuffers, instancing: dict, key: str) -> np.ndarray:
    """(n, 4, 4) float64 T·R·S of each instance of an ``EXT_mesh_gpu_instancing`` node."""
    attributes = instancing.get("attributes") or {}
    columns = {}
    for name in ("TRANSLATION", "ROTATION", "SCALE"):
        if name in attributes:
            columns[name] = np.asarray(
                accessor_array(tree, buffers, attributes[name], True), np.float64
            )
    counts = {len(values) for values in columns.values()}
    if len(counts) != 1:
        raise MeshFileError(
            f"{key}.extensions.EXT_mesh_gpu_instancing.attributes",
            "needs TRANSLATION, ROTATION or SCALE, all of one count",
        )
    (n,) = counts
    matrices = np.zeros((n, 4, 4))
    matrices[:, 3, 3] = 1.0
    rotation = columns.get("ROTATION")
    matrices[:, :3, :3] = np.eye(3) if rotation is None else quaternion_matrices(rotation)
    if "SCALE" in columns:
        matrices[:, :3, :3] *= columns["SCALE"][:, None, :]
    if "TRANSLATION" in columns:
        matrices[:, :3, 3] = columns["TRANSLATION"]
    return matrices


def _tag_mesh(mesh: dict, index: int) -> None:
    extras = mesh.get("extras")
    mesh["extras"] = {**(extras if isinstance(extras, dict) else {}), MESH_INDEX_TAG: index}


def _camera(path: Path, tree: dict, index: int, world: np.ndarray) -> FileCamera | None:
    """The camera ``cameras[index]`` seen from the node at ``world``: it looks down the
    node's -z with +y up. None (with a warning) for a camera embree_rt cannot be."""
    key = f"cameras[{index}]"
    camera = tree["cameras"][index]
    if camera.get("type") != "perspective" or "perspective" not in camera:
        warn_input(
            f"{path}: {key}: a {camera.get('type')} camera is not supported (embree_rt's "
            "camera is a pinhole); the view is framed from the bounds instead"
        )
        return None
    perspective = camera["perspective"]
    forward = -world[:3, 2] / np.linalg.norm(world[:3, 2])
    up = world[:3, 1] / np.linalg.norm(world[:3, 1])
    return FileCamera(
        key=key,
        position=world[:3, 3].copy(),
        forward=forward,
        up=up,
        yfov_degrees=float(np.degrees(perspective["yfov"])),
        aspect_ratio=perspective.get("aspectRatio"),
    )


def _light(tree: dict, index: object, world: np.ndarray, key: str) -> FileLight:
    lights = (tree.get("extensions") or {}).get("KHR_lights_punctual", {}).get("lights", [])
    if not isinstance(index, int) or not 0 <= index < len(lights):
        raise MeshFileError(
            f"{key}.extensions.KHR_lights_punctual.light",
            f"no light {index!r} in the file's {len(lights)}",
        )
    light = lights[index]
    kind = light.get("type")
    if kind not in ("point", "spot", "directional"):
        raise MeshFileError(
            f"extensions.KHR_lights_punctual.lights[{index}].type",
            f"expected point, spot or directional, got {kind!r}",
        )
    spot = light.get("spot") or {}
    return FileLight(
        key=f"extensions.KHR_lights_punctual.lights[{index}]",
        kind=kind,
        position=world[:3, 3].copy(),
        direction=-world[:3, 2] / np.linalg.norm(world[:3, 2]),
        color=tuple(float(c) for c in light.get("color", (1.0, 1.0, 1.0))),
        intensity=float(light.get("intensity", 1.0)),
        outer_cone_degrees=float(np.degrees(spot.get("outerConeAngle", np.pi / 4)))
        if kind == "spot"
        else None,
    )


def _write(path: Path, tree: dict, binary: bytes | None) -> bytes:
    """The file with its JSON replaced by ``tree``: JSON text for a ``.gltf``, a binary glTF
    with the same binary chunk for a ``.glb``."""
    text = json.dumps(tree).encode("utf-8")
    if path.suffix.lower() != ".glb":
        return text
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), _CHUNK_JSON) + text
    if binary is not None:
        padded = binary + b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<II", len(padded), _CHUNK_BIN) + padded
    return _GLB_MAGIC + struct.pack("<II", 2, 12 + len(chunks)) + chunks
