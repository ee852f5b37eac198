"""What an asset file means, for comparing two writes of it across machines and library versions.

Bytes are the wrong thing to compare for files that carry compressed images: Pillow's PNG
encoder hands its deflate stream to whichever zlib it was built with (zlib, zlib-ng), and two
Pillow wheels write different, equally valid streams for the same pixels; a glTF binary that
embeds such an image then shifts every buffer view after it. Coordinates made with NumPy's
trigonometry may differ in their last bits between its SIMD kernels (SSE4.2, AVX2, AVX-512).
So a file is compared by its meaning:

- PNG: the decoded pixels and mode;
- glTF binary: the JSON with the byte layout left out (buffer views' offsets and lengths, the
  buffer's length: they follow the images' compressed sizes), every accessor decoded to its
  typed values, every image decoded to pixels;
- text (OBJ, MTL, OFF): the words, and the numbers grouped by the first word of their line;
- binary PLY and STL: trimesh's reading of them (vertices, faces, colours) and the PLY header.

Numbers compare with a tolerance of ``REL`` of the largest magnitude in their array: a few float32
ulps, the most two ISAs' float64 trigonometry can move a value rounded to float32, and far below
any change of the geometry a test would care about. Pixels must be equal (they are quantised from
closed forms with margins far from the rounding edges).

Imported by the tests as a plain module (pytest puts ``tests/`` on ``sys.path``).
"""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

REL = 4 * float(np.finfo(np.float32).eps)
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32}
_COMPONENTS[5126] = np.float32
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def pixels(data: bytes) -> tuple[str, np.ndarray]:
    """(mode, (h, w[, c]) array) of an encoded image."""
    with Image.open(io.BytesIO(data)) as image:
        return image.mode, np.asarray(image)


def glb_meaning(data: bytes) -> tuple[dict, list[np.ndarray], list[tuple[str, np.ndarray]]]:
    """(JSON without byte layout, decoded accessors, decoded images) of a glTF binary."""
    magic, version, _ = struct.unpack_from("<4sII", data, 0)
    assert (magic, version) == (b"glTF", 2)
    json_length, _ = struct.unpack_from("<I4s", data, 12)
    document = json.loads(data[20 : 20 + json_length])
    blob_start = 20 + json_length + 8
    blob = data[blob_start:]
    views = document.get("bufferViews", [])

    def view_bytes(index: int) -> bytes:
        view = views[index]
        start = view.get("byteOffset", 0)
        return blob[start : start + view["byteLength"]]

    accessors = []
    for accessor in document.get("accessors", []):
        dtype = np.dtype(_COMPONENTS[accessor["componentType"]])
        width = _WIDTH[accessor["type"]]
        view = views[accessor["bufferView"]]
        stride = view.get("byteStride", dtype.itemsize * width)
        raw = view_bytes(accessor["bufferView"])[accessor.get("byteOffset", 0) :]
        shape, strides = (accessor["count"], width), (stride, dtype.itemsize)
        accessors.append(np.ndarray(shape, dtype, buffer=raw, strides=strides).copy())
    images = [pixels(view_bytes(image["bufferView"])) for image in document.get("images", [])]
    for view in views:
        view.pop("byteOffset", None)
        view.pop("byteLength", None)
    for buffer in document.get("buffers", []):
        buffer.pop("byteLength", None)
    return document, accessors, images


def text_meaning(text: str) -> tuple[list[str], dict[str, np.ndarray]]:
    """(the words, the numbers grouped by the first word of their line) of a text file: each
    group (OBJ's ``v``, ``vt``, ``f``; OFF's vertex rows) gets a tolerance of its own scale."""
    words: list[str] = []
    numbers: dict[str, list[float]] = {}
    for line in text.splitlines():
        tokens = line.split()
        key = tokens[0] if tokens and not _is_number(tokens[0]) else f"rows of {len(tokens)}"
        for token in tokens:
            if _is_number(token):
                numbers.setdefault(key, []).append(float(token))
            else:
                words.append(token)
    return words, {key: np.array(values) for key, values in numbers.items()}


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def assert_close_json(made: object, kept: object, where: str) -> None:
    """JSON values equal, floats within ``REL`` of their magnitude (at least 1)."""
    if isinstance(kept, dict):
        assert isinstance(made, dict) and made.keys() == kept.keys(), where
        for key in kept:
            assert_close_json(made[key], kept[key], f"{where}.{key}")
    elif isinstance(kept, list):
        assert isinstance(made, list) and len(made) == len(kept), where
        for i, (a, b) in enumerate(zip(made, kept, strict=True)):
            assert_close_json(a, b, f"{where}[{i}]")
    elif isinstance(kept, float) and not isinstance(kept, bool):
        assert isinstance(made, (int, float)), where
        assert abs(made - kept) <= REL * max(1.0, abs(kept)), f"{where}: {made} != {kept}"
    else:
        assert made == kept, f"{where}: {made!r} != {kept!r}"


def assert_close_arrays(made: np.ndarray, kept: np.ndarray, where: str) -> None:
    assert made.shape == kept.shape and made.dtype == kept.dtype, where
    if kept.dtype.kind == "f":
        scale = max(1.0, float(np.abs(kept).max(initial=0.0)))
        np.testing.assert_allclose(made, kept, rtol=0, atol=REL * scale, err_msg=where)
    else:
        np.testing.assert_array_equal(made, kept, err_msg=where)


def assert_same_meaning(made: Path, kept: Path) -> None:
    """Fail unless the files ``made`` and ``kept`` mean the same (see the module's docstring)."""
    name = kept.name
    suffix = kept.suffix.lower()
    a, b = made.read_bytes(), kept.read_bytes()
    if suffix == ".png":
        (mode_a, pixels_a), (mode_b, pixels_b) = pixels(a), pixels(b)
        assert mode_a == mode_b, name
        np.testing.assert_array_equal(pixels_a, pixels_b, err_msg=name)
    elif suffix == ".glb":
        json_a, accessors_a, images_a = glb_meaning(a)
        json_b, accessors_b, images_b = glb_meaning(b)
        assert_close_json(json_a, json_b, name)
        for i, (x, y) in enumerate(zip(accessors_a, accessors_b, strict=True)):
            assert_close_arrays(x, y, f"{name} accessor {i}")
        for i, ((mode_x, x), (mode_y, y)) in enumerate(zip(images_a, images_b, strict=True)):
            assert mode_x == mode_y, f"{name} image {i}"
            np.testing.assert_array_equal(x, y, err_msg=f"{name} image {i}")
    elif suffix in (".obj", ".mtl", ".off"):
        words_a, numbers_a = text_meaning(a.decode())
        words_b, numbers_b = text_meaning(b.decode())
        assert words_a == words_b and numbers_a.keys() == numbers_b.keys(), name
        for key, values in numbers_b.items():
            assert_close_arrays(numbers_a[key], values, f"{name} {key}")
    elif suffix in (".ply", ".stl"):
        if suffix == ".ply":
            header_end = b"end_header\n"
            assert a[: a.index(header_end)] == b[: b.index(header_end)], f"{name} header"
        mesh_a = trimesh.load(made, process=False)
        mesh_b = trimesh.load(kept, process=False)
        assert_close_arrays(mesh_a.vertices, mesh_b.vertices, f"{name} vertices")
        np.testing.assert_array_equal(mesh_a.faces, mesh_b.faces, err_msg=f"{name} faces")
        if mesh_b.visual.kind == "vertex":
            np.testing.assert_array_equal(
                mesh_a.visual.vertex_colors, mesh_b.visual.vertex_colors, err_msg=name
            )
    else:
        raise AssertionError(f"{name}: no meaning comparison for {suffix} files")
