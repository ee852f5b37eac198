"""The files a mesh file makes trimesh read beside it, found without loading the mesh.

An OBJ names its material library on its first ``mtllib`` line, and that library names its
textures on its ``map_Kd`` lines; a glTF (``.gltf``, or the JSON chunk of a ``.glb``) names
external buffers and images by ``uri``. embree_rt loads meshes through trimesh, so these follow
trimesh's own rules: names are taken as written (the rest of the line, stripped), relative to
the mesh's directory, and tried as given, URI-decoded, with Windows separators as ``/``, without a
leading slash, then as a bare file name (``candidate_paths``, the one list the loader's resolver
also tries).
The other formats embree_rt reads are self-contained.

The cluster's scene key stamps these files (``embree_rt.distributed``): a texture repainted
under a running cluster is a new scene.
"""

from __future__ import annotations

import json
import mmap
import os
import struct
from pathlib import Path
from urllib.parse import unquote

_GLB_MAGIC = b"glTF"
_GLB_JSON_CHUNK = 0x4E4F534A


def companion_files(mesh: Path) -> list[Path]:
    """The files ``mesh`` names that trimesh may read with it, each once, in the order it
    names them (a library before its textures), every path a name may be read from included:
    one that does not exist is listed too, so that creating it later is noticed. A mesh that
    cannot be read lists nothing (loading it reports the problem)."""
    suffix = mesh.suffix.lower()
    try:
        if suffix == ".obj":
            found = _obj_companions(mesh)
        elif suffix in (".gltf", ".glb"):
            tree = json.loads(mesh.read_bytes()) if suffix == ".gltf" else _glb_json(mesh)
            found = [path for uri in _gltf_uris(tree) for path in candidate_paths(mesh.parent, uri)]
        else:
            return []
    except (OSError, ValueError, UnicodeDecodeError):
        return []
    return list(dict.fromkeys(found))


def _obj_companions(mesh: Path) -> list[Path]:
    name = first_line_after(mesh, b"mtllib")
    if name is None:
        return []
    found = candidate_paths(mesh.parent, name)
    for library in [path for path in found if path.is_file()]:
        for line in library.read_text(encoding="utf-8", errors="replace").splitlines():
            words = line.strip().split()
            if len(words) > 1 and words[0].lower() == "map_kd":
                at = line.lower().index("map_kd") + len("map_kd")
                found += candidate_paths(mesh.parent, line[at:].strip())
    return found


def first_line_after(path: Path, keyword: bytes) -> str | None:
    """The rest of the line after the first ``keyword`` in the file, stripped, or None. The
    file is searched in place (an OBJ can be gigabytes), not read into memory."""
    with open(path, "rb") as file:
        if os.fstat(file.fileno()).st_size == 0:
            return None
        with mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            at = data.find(keyword)
            if at < 0:
                return None
            end = data.find(b"\n", at)
            line = data[at + len(keyword) : end if end >= 0 else len(data)]
    return line.decode("utf-8", errors="replace").strip()


def _glb_json(path: Path) -> dict:
    """The JSON chunk of a binary glTF (the 12-byte header, then chunk length and type)."""
    with open(path, "rb") as file:
        header = file.read(20)
        if len(header) < 20 or header[:4] != _GLB_MAGIC:
            raise ValueError(f"{path}: not a binary glTF")
        length, kind = struct.unpack("<II", header[12:20])
        if kind != _GLB_JSON_CHUNK:
            raise ValueError(f"{path}: the first chunk is not JSON")
        return json.loads(file.read(length))


def _gltf_uris(tree: object) -> list[str]:
    """The external ``uri`` of each buffer and image (``data:`` URIs are inline)."""
    if not isinstance(tree, dict):
        return []
    uris = []
    for group in ("buffers", "images"):
        for item in tree.get(group) or []:
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and "base64," not in uri:
                uris.append(uri)
    return uris


def candidate_paths(root: Path, name: str) -> list[Path]:
    """Every path a file named ``name`` inside a mesh file in ``root`` is looked for at, in
    order, each once: as written; URI-decoded (glTF names are URIs: ``my%20tex.png``); with
    Windows separators read as ``/`` (3ds Max writes ``map_Kd .\\Tex.jpg``); without a leading
    slash; and as a bare file name, as Blender and assimp do."""
    written = name.strip()
    decoded = unquote(written)
    forward = decoded.replace("\\", "/")
    names = (written, decoded, forward, forward.lstrip("/"), forward.rsplit("/", 1)[-1])
    return list(dict.fromkeys((root / candidate).resolve() for candidate in names if candidate))
