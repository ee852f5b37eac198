"""Scene files (TOML or JSON, one schema) → ``Scene``. Every problem is a ``SceneError``."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import trimesh

from embree_rt.materials import PRESETS, Checker, Material
from embree_rt.scene.errors import SceneError
from embree_rt.scene.fields import Table
from embree_rt.scene.meshes import load_mesh_parts
from embree_rt.scene.model import Background, Camera, Floor, PointLight, RenderSettings, Scene
from embree_rt.scene.random_field import random_field

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

MATERIAL_FIELDS = ("ambient", "diffuse", "specular", "reflectivity", "transparency")


def read_document(path: Path) -> dict:
    """The parsed TOML or JSON document at ``path``."""
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise SceneError(path, "(file)", "expected a .toml or .json scene file")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(path, "(file)", "no such file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise SceneError(path, "(file)", f"cannot read: {error}") from None
    try:
        if suffix == ".toml":
            return tomllib.loads(text)
        document = json.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(path, "(syntax)", f"malformed TOML: {error}") from None
    except json.JSONDecodeError as error:
        raise SceneError(
            path, "(syntax)", f"malformed JSON at line {error.lineno}: {error.msg}"
        ) from None
    if not isinstance(document, dict):
        raise SceneError(path, "(top level)", "expected a JSON object")
    return document


def load_scene(path: str | Path) -> Scene:
    """Load and validate a scene file; relative paths inside it are relative to the file."""
    path = Path(path)
    return SceneReader(path, read_document(path)).scene


class SceneReader:
    def __init__(self, path: Path, document: dict) -> None:
        self.path = path
        self.base = path.parent
        root = Table(path, "", document)
        generator = root.table("random_field")
        self.scene = self._random_field(generator) if generator else Scene()
        scene = self.scene
        if (table := root.table("render")) is not None:
            scene.render = self._render(table, scene.render)
        if (table := root.table("camera")) is not None:
            scene.camera = self._camera(table, scene.camera)
        if (table := root.table("background")) is not None:
            scene.background = Background(
                horizon=table.color("horizon", scene.background.horizon),
                zenith=table.color("zenith", scene.background.zenith),
            )
            table.finish()
        lights = root.tables("lights")
        if lights:
            scene.lights = [self._light(t) for t in lights]
        materials = root.table("materials")
        if materials is not None:
            for name in materials.data:
                scene.add_material(name, self._material(materials.table(name)))
            materials.finish()
        if root.has("floor"):
            scene.floor = self._floor(root)
        for table in root.tables("spheres"):
            self._sphere(table)
        for table in root.tables("sphere_arrays"):
            self._sphere_array(table)
        self._mesh_cache: dict[Path, list] = {}
        for table in root.tables("meshes"):
            self._mesh(table)
        root.finish()

    # -- sections -----------------------------------------------------------------------------

    def _random_field(self, table: Table) -> Scene:
        count = table.integer("count", None, low=1)
        if count is None:
            raise table.error("count", "is required")
        scene = random_field(
            count, seed=table.integer("seed", 0, low=0), heroes=table.boolean("heroes", True)
        )
        table.finish()
        return scene

    def _render(self, table: Table, current: RenderSettings) -> RenderSettings:
        settings = RenderSettings(
            width=table.integer("width", current.width, low=1),
            height=table.integer("height", current.height, low=1),
            spp=table.integer("spp", current.spp, low=1),
            max_depth=table.integer("max_depth", current.max_depth, low=0),
            seed=table.integer("seed", current.seed, low=0),
        )
        table.finish()
        return settings

    def _camera(self, table: Table, current: Camera) -> Camera:
        camera = Camera(
            position=table.vector("position", current.position),
            look_at=table.vector("look_at", current.look_at),
            up=table.vector("up", current.up),
            fov=table.number("fov", current.fov, low=0, high=180, low_open=True, high_open=True),
        )
        if np.allclose(camera.position, camera.look_at):
            raise table.error("look_at", "must differ from camera.position")
        view = np.subtract(camera.position, camera.look_at)
        if np.linalg.norm(np.cross(camera.up, view)) < 1e-9 * np.linalg.norm(view):
            raise table.error("up", "must not be parallel to the viewing direction")
        table.finish()
        return camera

    def _light(self, table: Table) -> PointLight:
        light = PointLight(
            position=table.vector("position", required=True),
            color=table.color("color", (1.0, 1.0, 1.0)),
            intensity=table.number("intensity", 1.0, low=0),
        )
        table.finish()
        return light

    def _material_fields(self, table: Table, base: Material) -> Material:
        fields = {}
        if table.has("color"):
            fields["color"] = table.color("color")
        for name in MATERIAL_FIELDS:
            if table.has(name):
                fields[name] = table.number(name, None, low=0, high=1)
        if table.has("shininess"):
            fields["shininess"] = table.number("shininess", None, low=0, low_open=True)
        if table.has("ior"):
            fields["ior"] = table.number("ior", None, low=1)
        if table.has("metallic"):
            fields["metallic"] = table.boolean("metallic", False)
        return Material(**{**base.__dict__, **fields})

    def _material(self, table: Table) -> Material:
        name = table.string("preset", "matte")
        if name not in PRESETS:
            raise table.error("preset", f"unknown preset {name!r}; known: {', '.join(PRESETS)}")
        material = self._material_fields(table, PRESETS[name])
        table.finish()
        return material

    def _floor(self, root: Table) -> Floor | None:
        value = root.raw("floor")
        if value is False:
            return None
        table = root.table("floor")
        default = Floor()
        base = default.material
        if table.has("preset"):
            name = table.string("preset")
            if name not in PRESETS:
                raise table.error("preset", f"unknown preset {name!r}; known: {', '.join(PRESETS)}")
            base = PRESETS[name]
        floor = Floor(
            height=table.number("height", default.height),
            checker=Checker(
                color_a=table.color("color_a", default.checker.color_a),
                color_b=table.color("color_b", default.checker.color_b),
                size=table.number("size", default.checker.size, low=0, low_open=True),
            ),
            material=self._material_fields(table, base),
        )
        table.finish()
        return floor

    def _material_name(self, table: Table, default: str | None = "matte") -> str | None:
        name = table.string("material", default)
        if name is not None and name not in self.scene.materials:
            raise table.error("material", f"undefined material {name!r}")
        return name

    def _sphere(self, table: Table) -> None:
        center = table.vector("center", required=True)
        radius = table.number("radius", required=True, low=0, low_open=True)
        self.scene.add_sphere(center, radius, self._material_name(table))
        table.finish()

    def _resolve(self, table: Table, name: str) -> Path:
        relative = table.string(name, required=True)
        return (self.base / relative).resolve()

    def _sphere_array(self, table: Table) -> None:
        path = self._resolve(table, "file")
        default_material = self._material_name(table)
        table.finish()
        key = table.key("file")
        try:
            with np.load(path, allow_pickle=False) as archive:
                arrays = {name: archive[name] for name in archive.files}
        except FileNotFoundError:
            raise SceneError(self.path, key, f"{path}: no such file") from None
        except Exception as error:
            raise SceneError(self.path, key, f"{path}: cannot read .npz: {error}") from None
        for required in ("centers", "radii"):
            if required not in arrays:
                raise SceneError(self.path, key, f"{path}: missing array {required!r}")
        centers, radii = arrays["centers"], arrays["radii"]
        if centers.ndim != 2 or centers.shape[1] != 3 or centers.dtype.kind not in "fiu":
            raise SceneError(self.path, key, f"{path}: centers must be (n, 3) numbers")
        if radii.shape != (len(centers),) or radii.dtype.kind not in "fiu":
            raise SceneError(self.path, key, f"{path}: radii must be ({len(centers)},) numbers")
        if not np.isfinite(centers).all():
            row = int(np.flatnonzero(~np.isfinite(centers).all(axis=1))[0])
            raise SceneError(self.path, key, f"{path}: centers row {row} is not finite")
        bad = ~(np.isfinite(radii) & (radii > 0))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise SceneError(self.path, key, f"{path}: radii row {row} must be > 0")
        materials = arrays.get("materials")
        if materials is None:
            materials = default_material
        else:
            if materials.shape != (len(centers),) or materials.dtype.kind not in "iuU":
                raise SceneError(
                    self.path, key, f"{path}: materials must be ({len(centers)},) names or ids"
                )
            if materials.dtype.kind == "U":
                unknown = sorted(set(np.unique(materials)) - set(self.scene.materials))
                if unknown:
                    raise SceneError(self.path, key, f"{path}: undefined material {unknown[0]!r}")
            elif len(materials) and (
                materials.min() < 0 or materials.max() >= len(self.scene.materials)
            ):
                raise SceneError(self.path, key, f"{path}: material id out of range")
        self.scene.add_spheres(centers, radii, materials)

    def _mesh(self, table: Table) -> None:
        path = self._resolve(table, "file")
        material = self._material_name(table, None)
        smooth = table.boolean("smooth", True)
        placement = self._placement(table)
        table.finish()
        if path not in self._mesh_cache:
            self._mesh_cache[path] = load_mesh_parts(path, self.path, table.key("file"))
        for mesh, node_transform in self._mesh_cache[path]:
            self.scene.add_mesh(mesh, material, placement @ node_transform, smooth)

    def _placement(self, table: Table) -> np.ndarray:
        if table.has("transform"):
            for name in ("translate", "rotate", "scale"):
                if table.has(name):
                    raise table.error(name, "give either transform or translate/rotate/scale")
            matrix = np.asarray(table.raw("transform"), dtype=object)
            try:
                matrix = matrix.astype(np.float64)
            except (TypeError, ValueError):
                raise table.error("transform", "expected a 4x4 list of numbers") from None
            if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
                raise table.error("transform", "expected a 4x4 list of finite numbers")
            if (
                not np.allclose(matrix[3], [0, 0, 0, 1])
                or abs(np.linalg.det(matrix[:3, :3])) < 1e-12
            ):
                raise table.error("transform", "must be an invertible affine matrix")
            return matrix
        translate = table.vector("translate", (0.0, 0.0, 0.0))
        rotate = table.vector("rotate", (0.0, 0.0, 0.0))
        scale_value = table.raw("scale", 1.0)
        if isinstance(scale_value, list):
            scale = table.vector("scale")
        else:
            scale = (table.number("scale", 1.0, low=0, low_open=True),) * 3
        if min(scale) <= 0:
            raise table.error("scale", f"must be > 0, got {list(scale)}")
        rotation = trimesh.transformations.euler_matrix(*(math.radians(a) for a in rotate), "sxyz")
        matrix = rotation @ np.diag([*scale, 1.0])
        matrix[:3, 3] = translate
        return matrix
