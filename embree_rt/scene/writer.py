"""``Scene`` → scene file (TOML or JSON): spheres and instance placements go to sibling ``.npz``
files, meshes to PLY files.

Each distinct mesh object is written once (``NAME.meshK.ply``) and every placement of it refers to
that file, so loading the saved scene shares one Trimesh between the placements again.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict
from pathlib import Path

import numpy as np

from embree_rt.materials import PRESETS, Material
from embree_rt.scene.animation import animation_document
from embree_rt.scene.model import CurveSet, Scene


def spheres_file(path: Path) -> Path:
    """Where ``save_scene(scene, path)`` writes the scene's sphere arrays."""
    return path.with_suffix(".spheres.npz")


def mesh_file(path: Path, index: int) -> Path:
    """Where ``save_scene(scene, path)`` writes the scene's ``index``-th distinct mesh."""
    return path.with_name(f"{path.stem}.mesh{index}.ply")


def scene_document(scene: Scene, path: Path) -> dict:
    """The scene as a plain dict in the file schema, writing its bulk data beside ``path``."""
    document: dict = {"render": asdict(scene.render), **look_document(scene)}
    if scene.render.background == "sky":  # files with the sky stay as they were
        del document["render"]["background"]
    if not scene.render.ao.samples:  # off: files without ambient occlusion stay as they were
        del document["render"]["ao"]
    else:
        if math.isinf(scene.render.ao.distance):  # unlimited: the key left out
            del document["render"]["ao"]["distance"]
        if not scene.render.ao.bounces:  # the default: the key left out
            del document["render"]["ao"]["bounces"]
    if scene.animation is not None:
        document["animation"] = animation_document(scene.animation)
    if len(scene.sphere_radii):
        spheres_path = spheres_file(path)
        names = np.asarray(scene.material_names)
        colors = {} if scene.sphere_colors is None else {"colors": scene.sphere_colors}
        np.savez_compressed(
            spheres_path,
            centers=scene.sphere_centers.astype(np.float32),
            radii=scene.sphere_radii.astype(np.float32),
            materials=names[scene.sphere_materials],
            **colors,
        )
        document["sphere_arrays"] = [{"file": spheres_path.name}]
    files: dict[int, str] = {}  # each distinct mesh written once, for meshes and instances

    def mesh_name(mesh) -> str:
        if id(mesh) not in files:
            mesh_path = mesh_file(path, len(files))
            mesh.export(mesh_path)
            files[id(mesh)] = mesh_path.name
        return files[id(mesh)]

    if scene.meshes:
        entries = []
        for placement in scene.meshes:
            entries.append(
                {
                    "file": mesh_name(placement.mesh),
                    "material": placement.material,
                    "smooth": placement.smooth,
                    "transform": np.asarray(placement.transform, float).tolist(),
                }
            )
        document["meshes"] = entries
    if scene.instances:
        names = np.asarray(scene.material_names)
        entries = []
        for number, instances in enumerate(scene.instances):
            placements_path = path.with_name(f"{path.stem}.instances{number}.npz")
            np.savez_compressed(
                placements_path,
                transforms=instances.transforms,
                materials=names[instances.materials],
            )
            entries.append(
                {
                    "mesh": mesh_name(instances.mesh),
                    "transforms": placements_path.name,
                    "smooth": instances.smooth,
                }
            )
        document["instances"] = entries
    if scene.curves:
        document["curves"] = [
            {"points": points, "radii": radii, "material": curves.material}
            for curves in scene.curves
            for points, radii in polylines(curves)
        ]
    return document


def polylines(curves: CurveSet) -> list[tuple[list, list]]:
    """The polylines of a curve set, each (points, radii) as lists: the runs of its segments
    whose starts follow one another (a file's ``[[curves]]`` entry holds one polyline, so a
    set of separate segments is written as one entry each)."""
    starts = np.sort(curves.starts)
    if not len(starts):
        return []
    breaks = np.flatnonzero(np.diff(starts) != 1) + 1
    runs = np.split(starts, breaks)
    return [
        (
            curves.points[run[0] : run[-1] + 2].astype(float).tolist(),
            curves.radii[run[0] : run[-1] + 2].astype(float).tolist(),
        )
        for run in runs
    ]


def look_document(scene: Scene) -> dict:
    """The scene's camera, sky, lights, materials and floor in the file schema: what the
    renderer reads of a scene besides its render settings, animation and geometry."""
    document: dict = {
        "camera": {
            "position": list(scene.camera.position),
            "look_at": list(scene.camera.look_at),
            "up": list(scene.camera.up),
            "fov": float(scene.camera.fov),
        },
        "background": {
            "horizon": list(scene.background.horizon),
            "zenith": list(scene.background.zenith),
        },
        "lights": [
            {"position": list(lt.position), "color": list(lt.color), "intensity": lt.intensity}
            for lt in scene.lights
        ],
    }
    if scene.camera.projection != "perspective":  # perspective files stay as they were
        document["camera"]["projection"] = scene.camera.projection
    if scene.camera.view_height is not None:
        del document["camera"]["fov"]
        document["camera"]["view_height"] = float(scene.camera.view_height)
    materials = {
        name: _material_dict(material)
        for name, material in scene.materials.items()
        if PRESETS.get(name) != material
    }
    if materials:
        document["materials"] = materials
    if scene.floor is None:
        document["floor"] = False
    else:
        floor = scene.floor
        document["floor"] = {
            "height": floor.height,
            "color_a": list(floor.checker.color_a),
            "color_b": list(floor.checker.color_b),
            "size": floor.checker.size,
            **_material_dict(floor.material),
        }
        document["floor"].pop("preset")
    return document


def _material_dict(material) -> dict:
    fields = asdict(material)
    # Keys a material leaves at their defaults (no glow, no absorption, lit, no outline) are not
    # written.
    for name, default in asdict(Material()).items():
        if name in _OPTIONAL_MATERIAL_KEYS and fields[name] == default:
            del fields[name]
    for name, value in fields.items():
        if isinstance(value, tuple):
            fields[name] = list(value)
    return {"preset": "matte", **fields}


_OPTIONAL_MATERIAL_KEYS = (
    "emission",
    "attenuation_color",
    "attenuation_distance",
    "unlit",
    "outline",
)


def save_scene(scene: Scene, path: str | Path) -> None:
    """Write ``scene`` to ``path`` (``.toml`` or ``.json``), bulk data in files beside it:
    ``load_scene(path)`` gives the scene back."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise ValueError(f"{path}: expected a .toml or .json file name")
    document = plain_values(scene_document(scene, path))
    if suffix == ".json":
        text = json.dumps(document, indent=2) + "\n"
    else:
        import tomli_w

        text = tomli_w.dumps(document)
    path.write_text(inline_short_arrays(text), encoding="utf-8")


# An array of numbers, as json.dumps(indent=...) and tomli-w write it: "[", one number per line
# (a comma after each, or after all but the last), "]". Strings never hold a raw newline in
# either format, so "[" at the end of a line always opens an array.
_NUMBER = r"-?(?:\d+(?:\.\d+)?(?:[eE][-+]?\d+)?|inf|nan|Infinity|NaN)"
_NUMBER_ARRAY = re.compile(rf"\[\n((?:[ \t]*{_NUMBER},?\n)+)[ \t]*\]")
MAX_LINE = 100


def inline_short_arrays(text: str) -> str:
    """``text`` (TOML from tomli-w or indented JSON) with each array of numbers that fits on a
    line of ``MAX_LINE`` characters written on it, as a person would (``position = [0.0, 1.6,
    6.5]``): tomli-w has no option for it, and writes every vector one number per line. A 4 × 4
    transform becomes one row a line."""

    def inline(match: re.Match) -> str:
        numbers = [line.strip().rstrip(",") for line in match.group(1).splitlines()]
        written = "[" + ", ".join(numbers) + "]"
        line_start = text.rfind("\n", 0, match.start()) + 1
        fits = match.start() - line_start + len(written) + 1 <= MAX_LINE  # + 1: a comma after
        return written if fits else match.group(0)

    return _NUMBER_ARRAY.sub(inline, text)


def plain_values(value):
    """``value`` with NumPy scalars and tuples turned into the Python types TOML/JSON writers
    accept (a scene built in Python may hold ``np.float32`` coordinates)."""
    if isinstance(value, dict):
        return {str(key): plain_values(item) for key, item in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [plain_values(item) for item in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    return value
