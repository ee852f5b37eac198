"""Scene files (TOML or JSON, one schema) → ``Scene``. Every problem is a ``SceneError``.

Loading runs in three steps so that a mistake anywhere costs nothing: (1) every value in the file
is read and checked, and every material name resolved, with no file but the scene itself opened;
(2) the files it names (sphere arrays, meshes) are read and checked, each mesh file once; (3) only
then is the scene built, the random field (the one heavy generator) included.
"""

from __future__ import annotations

import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from embree_rt import budget
from embree_rt.ambient_occlusion import AmbientOcclusion, ao_problem
from embree_rt.camera import Camera
from embree_rt.choices import BACKGROUNDS
from embree_rt.errors import FieldError
from embree_rt.film import TONEMAPS, TRANSFERS
from embree_rt.materials import PRESETS, Checker, Material
from embree_rt.particle_extras import EXTRA_OPTIONS, ParticleExtras, extras_problem, is_switch
from embree_rt.scene.animation_file import read_animation
from embree_rt.scene.archives import Headers, array_headers, read_archive, unpacked_bytes
from embree_rt.scene.errors import SceneError, unknown_key_message
from embree_rt.scene.fields import Table
from embree_rt.scene.limits import MIN_LENGTH, SEED_LIMIT, placed_mesh_problem, spheres_problem
from embree_rt.scene.model import (
    Background,
    Floor,
    PointLight,
    RenderSettings,
    Scene,
    background_problem,
    camera_limits_problem,
    floor_problem,
    light_problem,
    material_limits_problem,
    render_problem,
)
from embree_rt.scene.paths import unreadable_problem
from embree_rt.scene.random_field import (
    FieldParameterError,
    FieldPlan,
    add_field_spheres,
    field_scene,
    plan_field,
)
from embree_rt.transforms import affine_array_problem, affine_problem

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

# A material's keys in a file, by what they hold (``Material`` checks their values).
MATERIAL_COLORS = ("color", "emission", "attenuation_color")
MATERIAL_NUMBERS = (
    "ambient",
    "diffuse",
    "specular",
    "shininess",
    "reflectivity",
    "transparency",
    "ior",
    "attenuation_distance",
    "outline",
)
MATERIAL_FLAGS = ("metallic", "unlit")


def read_document(path: Path) -> dict:
    """The parsed TOML or JSON document at ``path``."""
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise SceneError(path, "(file)", "expected a .toml or .json scene file")
    if (problem := unreadable_problem(path)) is not None:
        raise SceneError(path, "(file)", problem)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(path, "(file)", "no such file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise SceneError(path, "(file)", f"cannot read: {error}") from None
    try:
        # tomllib's messages say "(at line L, column C)"
        document = tomllib.loads(text) if suffix == ".toml" else json.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(path, "(syntax)", f"malformed TOML: {error}") from None
    except json.JSONDecodeError as error:
        raise SceneError(
            path, "(syntax)", f"malformed JSON at line {error.lineno}: {error.msg}"
        ) from None
    except RecursionError:  # the parsers recurse once a level
        raise SceneError(path, "(syntax)", "tables or lists nested too deeply") from None
    except ValueError as error:  # Python's limit on the digits of an int literal, above all
        limit = sys.get_int_max_str_digits()
        problem = f"an integer of more than {limit} digits" if "digits" in str(error) else error
        raise SceneError(path, "(syntax)", f"malformed {suffix[1:].upper()}: {problem}") from None
    if not isinstance(document, dict):
        raise SceneError(path, "(top level)", "expected a JSON object")
    if (key := _too_deep(document, MAX_NESTING)) is not None:
        raise SceneError(path, key, f"nested more than {MAX_NESTING} levels deep")
    return document


# No key of the schema is more than 5 levels down (instances[0].transform[3][2]); the limit keeps
# every later step (reading, repr in messages, NumPy) clear of Python's recursion limit.
MAX_NESTING = 16


def _too_deep(document: dict, limit: int) -> str | None:
    """The key of the first value of ``document`` nested more than ``limit`` tables or lists
    deep, or None; iterative, so any depth the parser returned is measured safely."""
    stack: list[tuple[str, object, int]] = [("", document, 0)]
    while stack:
        key, value, depth = stack.pop()
        if depth > limit:
            return key or "(top level)"
        if isinstance(value, dict):
            stack.extend((f"{key}.{k}" if key else str(k), v, depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((f"{key}[{i}]", v, depth + 1) for i, v in enumerate(value))
    return None


def load_scene(path: str | Path) -> Scene:
    """Load and validate a scene file; relative paths inside it are relative to the file.

    Raises ``SceneError`` (``str()`` = ``"FILE: KEY: problem"``) for any bad input.
    """
    path = Path(path)
    return SceneReader(path, read_document(path)).build()


def _check_unpacking(
    path: Path, fail: Callable[[str], Exception], cost: Callable[[Headers], tuple[int, str]]
) -> None:
    """Raise ``fail("problem")`` when the arrays of the ``.npz`` at ``path`` would ``cost``
    (bytes, what for) more than the memory available, known from the headers alone: a zip bomb
    is refused before anything is unpacked. A file that cannot be read is left for
    ``read_archive`` to report."""
    try:
        headers = array_headers(path)
    except Exception:  # missing, a directory, a corrupt zip or .npy header: read_archive says
        return
    if headers is None:
        return
    try:
        budget.require({"archive": cost(headers)})
    except budget.MemoryBudgetError as error:
        raise fail(str(error)) from None


def _sphere_array_cost(headers: Headers) -> tuple[int, str]:
    """What a sphere array needs in memory by its headers: its arrays unpacked, and each sphere
    in the scene and in the BVH in its least costly form (what any render of it needs at least)."""
    shape = headers.get("centers", ((0,), None))[0]
    count = shape[0] if shape else 1
    per_sphere = budget.SCENE_BYTES_PER_SPHERE + min(budget.GEOMETRY_BYTES_PER_SPHERE.values())
    return unpacked_bytes(headers) + count * per_sphere, f"{count:,} spheres"


@dataclass
class _ParticlesEntry:
    key: str  # the ``file`` key, which errors inside the particle file name
    path: Path
    topology: Path | None
    frame: int
    up: str
    select: str | None
    wrap: bool
    material: str
    look: object  # a particles.look.ParticleLook (imported where a scene has particles)
    materials: dict[str, str] | None = None  # a material a type
    extras: ParticleExtras = field(default_factory=ParticleExtras)


@dataclass
class _SphereArrayEntry:
    key: str  # the ``file`` key, which errors inside the .npz name
    path: Path
    material: str


@dataclass
class _InstancesEntry:
    key: str  # the ``mesh`` key
    path: Path
    placements_key: str  # the ``transforms`` key, which errors inside the .npz name
    placements_path: Path
    material: str | None
    smooth: bool


@dataclass
class _MeshEntry:
    key: str
    path: Path
    material: str | None
    smooth: bool
    placement: np.ndarray
    placement_key: str  # the key that sets how the placement scales: transform or scale


class SceneReader:
    """Reads and checks a parsed scene document (step 1); ``build()`` does steps 2 and 3."""

    def __init__(self, path: Path, document: dict) -> None:
        self.path = path
        self.base = path.parent
        root = Table(path, "", document)
        self.field: FieldPlan | None = self._field_plan(root.table("random_field"))
        # Cheap: the field's camera, lights and material palette, without its spheres.
        self.scene = field_scene(self.field) if self.field else Scene()
        scene = self.scene
        if (table := root.table("render")) is not None:
            scene.render = self._render(table, scene.render)
        if (table := root.table("camera")) is not None:
            scene.camera = self._camera(table, scene.camera)
        if (table := root.table("animation")) is not None:
            scene.animation = read_animation(table, scene.camera)
        if (table := root.table("background")) is not None:
            scene.background = Background(
                horizon=table.color("horizon", scene.background.horizon),
                zenith=table.color("zenith", scene.background.zenith),
            )
            self._check(table, background_problem(scene.background))
            table.finish()
        lights = root.tables("lights")
        if lights:
            scene.lights = [self._light(t) for t in lights]
        if (materials := root.table("materials")) is not None:
            for name in materials.data:
                scene.add_material(name, self._material(materials.table(name)))
            materials.finish()
        if root.has("floor"):
            scene.floor = self._floor(root)
        self.spheres = [self._sphere(t) for t in root.tables("spheres")]
        self.sphere_arrays = [self._sphere_array(t) for t in root.tables("sphere_arrays")]
        self.particles: list[_ParticlesEntry] = []
        for particles in root.tables("particles"):  # (an entry's legend checks those before it)
            self.particles.append(self._particles(particles))
        self.meshes = [self._mesh(t) for t in root.tables("meshes")]
        self.instances = [self._instances(t) for t in root.tables("instances")]
        self.curves = [self._curves(t) for t in root.tables("curves")]
        root.finish()

    def named_files(self) -> list[Path]:
        """The data files the scene names (sphere arrays, particle files and their topologies,
        meshes, instance placements), in the order it names them, each once: what step 2 of
        ``build`` reads."""
        paths = [entry.path for entry in self.sphere_arrays]
        for entry in self.particles:
            paths += [entry.path] + ([] if entry.topology is None else [entry.topology])
        paths += [entry.path for entry in self.meshes]
        for entry in self.instances:
            paths += [entry.path, entry.placements_path]
        return list(dict.fromkeys(paths))

    def build(self) -> Scene:
        scene = self.scene
        # Step 2: the files the scene names, each checked before anything is generated.
        arrays = [self._read_sphere_array(entry) for entry in self.sphere_arrays]
        placements = [self._read_placements(entry) for entry in self.instances]
        models: dict[Path, object] = {}  # one load per file: its placements share the meshes
        for entry in [*self.instances, *self.meshes]:
            if entry.path not in models:
                from embree_rt.scene.meshes import load_model  # trimesh: ~1 s to import

                models[entry.path] = load_model(entry.path, self.path, entry.key)
        for entry in self.instances:
            for _, node_transform in models[entry.path].every_placement():
                if (problem := affine_problem(node_transform)) is not None:
                    raise SceneError(self.path, entry.key, f"{entry.path}: a node {problem}")
        for entry, (transforms, _) in zip(self.instances, placements, strict=True):
            for mesh, node_transform in models[entry.path].every_placement():
                if problem := placed_mesh_problem(mesh.vertices, transforms @ node_transform):
                    row, text = problem
                    raise SceneError(
                        self.path,
                        entry.placements_key,
                        f"{entry.placements_path}: row {row} {text}",
                    )
        for entry in self.meshes:
            model = models[entry.path]
            for _, node_transform in model.parts:
                if np.array_equal(node_transform, np.eye(4)):
                    continue  # the placement alone, checked when it was read
                if (problem := affine_problem(node_transform)) is not None:
                    raise SceneError(self.path, entry.key, f"{entry.path}: a node {problem}")
                if (problem := affine_problem(entry.placement @ node_transform)) is not None:
                    raise SceneError(
                        self.path, entry.placement_key, f"with the file's node transforms {problem}"
                    )
            for mesh, node_transform in model.parts:
                placed = (entry.placement @ node_transform)[None]
                if (problem := placed_mesh_problem(mesh.vertices, placed)) is not None:
                    raise SceneError(self.path, entry.key, f"{entry.path}: {problem[1]}")
            for mesh, transforms in model.instanced:
                if (problem := affine_array_problem(entry.placement @ transforms)) is not None:
                    raise SceneError(
                        self.path,
                        entry.placement_key,
                        f"with the file's EXT_mesh_gpu_instancing copy {problem[0]}: {problem[1]}",
                    )
                if problem := placed_mesh_problem(mesh.vertices, entry.placement @ transforms):
                    raise SceneError(
                        self.path,
                        entry.key,
                        f"{entry.path}: instancing copy {problem[0]} {problem[1]}",
                    )
        # Step 3: build.
        if self.field is not None:
            add_field_spheres(scene, self.field)
        if self.spheres:
            centers, radii, names = zip(*self.spheres, strict=True)
            scene.add_spheres(np.array(centers), np.array(radii), list(names))
        for centers, radii, materials, colors in arrays:
            scene.add_spheres(centers, radii, materials, colors=colors)
        for entry in self.particles:
            self._add_particles(scene, entry)
        for entry in self.meshes:
            model = models[entry.path]
            for mesh, node_transform in model.parts:
                # The node's own transform first, then the user's placement of the whole file.
                scene.add_mesh(mesh, entry.material, entry.placement @ node_transform, entry.smooth)
            for mesh, transforms in model.instanced:
                scene.add_instances(
                    mesh, entry.placement @ transforms, entry.material, entry.smooth
                )
        if self.instances:
            from embree_rt.scene.instances import mesh_from_parts

            baked: dict[Path, object] = {}  # one mesh per file: entries sharing it share a child
            for entry, (transforms, materials) in zip(self.instances, placements, strict=True):
                if entry.path not in baked:
                    baked[entry.path] = mesh_from_parts(models[entry.path].every_placement())
                scene.add_instances(
                    baked[entry.path],
                    transforms,
                    entry.material if materials is None else materials,
                    entry.smooth,
                )
        for points, radii, material, color in self.curves:
            scene.add_curves(points, radii, material, color=color)
        return scene

    # -- sections -----------------------------------------------------------------------------

    def _field_plan(self, table: Table | None) -> FieldPlan | None:
        if table is None:
            return None
        table.require("count")
        count = table.integer("count", low=1)
        seed = table.integer("seed", 0, low=0, high=SEED_LIMIT)
        extent = table.number("extent", None, low=0, low_open=True)
        radius = table.pair("radius", low=MIN_LENGTH) if table.has("radius") else None
        mix = None
        if (mix_table := table.table("mix")) is not None:
            for name in mix_table.data:
                if name not in PRESETS:
                    raise mix_table.error(name, unknown_key_message(name, PRESETS))
            mix = {name: mix_table.number(name, required=True, low=0) for name in mix_table.data}
        heroes = table.boolean("heroes", True)
        table.finish()
        try:
            return plan_field(count, seed, extent=extent, radius=radius, mix=mix, heroes=heroes)
        except FieldParameterError as error:
            raise table.error(error.name, error.problem) from None

    def _render(self, table: Table, current: RenderSettings) -> RenderSettings:
        settings = RenderSettings(
            width=table.integer("width", current.width, low=1),
            height=table.integer("height", current.height, low=1),
            spp=table.integer("spp", current.spp, low=1),
            max_depth=table.integer("max_depth", current.max_depth, low=0),
            seed=table.integer("seed", current.seed, low=0, high=SEED_LIMIT),
            exposure=table.number("exposure", current.exposure, low=-64, high=64),
            tonemap=self._choice(table, "tonemap", TONEMAPS, current.tonemap),
            transfer=self._choice(table, "transfer", TRANSFERS, current.transfer),
            ao=self._ambient_occlusion(table.table("ao"), current.ao),
            background=self._choice(table, "background", BACKGROUNDS, current.background),
        )
        table.finish()
        self._check(table, render_problem(settings))
        return settings

    def _ambient_occlusion(
        self, table: Table | None, current: AmbientOcclusion
    ) -> AmbientOcclusion:
        if table is None:
            return current
        ao = AmbientOcclusion(
            samples=table.integer("samples", current.samples, low=0, high=4096),
            distance=table.number("distance", current.distance, low=0, low_open=True),
            bounces=table.boolean("bounces", current.bounces),
        )
        table.finish()
        self._check(table, ao_problem(ao))
        return ao

    def _choice(self, table: Table, name: str, choices: tuple[str, ...], default: str) -> str:
        value = table.string(name, default)
        if value not in choices:
            raise table.error(name, f"expected one of {', '.join(choices)}, got {value!r}")
        return value

    def _camera(self, table: Table, current: Camera) -> Camera:
        if table.has("fov") and table.has("view_height"):
            raise table.error(
                "view_height", "an orthographic camera's view_height and fov cannot both be set"
            )
        camera = Camera(
            position=table.vector("position", current.position),
            look_at=table.vector("look_at", current.look_at),
            up=table.vector("up", current.up),
            fov=table.number("fov", current.fov),
            projection=table.string("projection", current.projection),
            view_height=table.number("view_height", current.view_height),
        )
        table.finish()
        # The rule the renderer's camera follows, so that a scene which loads also renders.
        self._check(table, camera_limits_problem(camera))
        return camera

    def _light(self, table: Table) -> PointLight:
        light = PointLight(
            position=table.vector("position", required=True),
            color=table.color("color", (1.0, 1.0, 1.0)),
            intensity=table.number("intensity", 1.0),
        )
        self._check(table, light_problem(light))
        table.finish()
        return light

    def _preset(self, table: Table, default: Material) -> Material:
        if not table.has("preset"):
            return default
        name = table.string("preset")
        if name not in PRESETS:
            raise table.error("preset", f"unknown preset {name!r}; known: {', '.join(PRESETS)}")
        return PRESETS[name]

    def _material_fields(self, table: Table, base: Material) -> Material:
        """``base`` with the material keys ``table`` holds, checked by ``Material`` (its ranges)
        and ``model.material_limits_problem`` (a scene's limits)."""
        fields = {}
        for name in MATERIAL_COLORS:
            if table.has(name):
                fields[name] = table.color(name)
        for name in MATERIAL_NUMBERS:
            if table.has(name):
                fields[name] = table.number(name)
        for name in MATERIAL_FLAGS:
            if table.has(name):
                fields[name] = table.boolean(name, False)
        material = self._build(table, Material, **{**base.__dict__, **fields})
        self._check(table, material_limits_problem(material))
        return material

    def _material(self, table: Table) -> Material:
        material = self._material_fields(table, self._preset(table, PRESETS["matte"]))
        table.finish()
        return material

    def _floor(self, root: Table) -> Floor | None:
        value = root.raw("floor")
        if value is False:
            return None
        if value is True:
            return Floor()
        table = root.table("floor")
        default = Floor()
        floor = Floor(
            height=table.number("height", default.height),
            checker=Checker(
                color_a=table.color("color_a", default.checker.color_a),
                color_b=table.color("color_b", default.checker.color_b),
                size=table.number("size", default.checker.size),
            ),
            material=self._material_fields(table, self._preset(table, default.material)),
        )
        self._check(table, floor_problem(floor))
        table.finish()
        return floor

    @staticmethod
    def _build(table: Table, kind: type, **values):
        """``kind(**values)``, a ``FieldError`` it raises reported under ``table``'s key."""
        try:
            return kind(**values)
        except FieldError as error:
            raise table.error(error.field, error.problem) from None

    @staticmethod
    def _check(table: Table, problem: tuple[str, str] | None) -> None:
        """Raise a model check's (field, problem) under ``table``'s key; nothing for None."""
        if problem is not None:
            raise table.error(*problem)

    def _material_name(self, table: Table, default: str | None = "matte") -> str | None:
        name = table.string("material", default)
        if name is not None and name not in self.scene.materials:
            raise table.error("material", f"undefined material {name!r}")
        return name

    def _sphere(self, table: Table) -> tuple[tuple[float, float, float], float, str]:
        center = table.vector("center", required=True)
        radius = table.number("radius", required=True, low=MIN_LENGTH)
        material = self._material_name(table)
        table.finish()
        return center, radius, material

    def _file(self, table: Table, key: str = "file") -> Path:
        """The file ``key`` names, relative to the scene file's folder; refused, naming the
        key, when it is there but cannot be read (a missing one its reader reports)."""
        # realpath, not Path.resolve, which raises RuntimeError for a loop of symbolic links
        path = Path(os.path.realpath(self.base / table.file_name(key)))
        if (problem := unreadable_problem(path)) is not None:
            raise table.error(key, f"{path}: {problem}")
        return path

    def _curves(self, table: Table) -> tuple[np.ndarray, np.ndarray, str, tuple | None]:
        """A polyline of round tubes: ``points`` (at least two [x, y, z]), ``radius`` (one for
        all) or ``radii`` (one a point), ``material``, and ``color`` (the material in that
        colour). Checked here by the rules ``Scene.add_curves`` applies."""
        points = table.raw("points")
        if points is None:
            table.require("points")
        if not isinstance(points, list) or len(points) < 2:
            raise table.error(
                "points", f"expected a list of at least two [x, y, z], got {points!r}"
            )
        for row, point in enumerate(points):
            if not (
                isinstance(point, list)
                and len(point) == 3
                and all(isinstance(c, int | float) and not isinstance(c, bool) for c in point)
            ):
                raise table.error("points", f"row {row}: expected [x, y, z], got {point!r}")
        points = np.array(points, np.float64)
        if table.has("radius") == table.has("radii"):
            raise table.error("radius", "give radius (one for all points) or radii (one a point)")
        if table.has("radius"):
            radii = np.full(len(points), table.number("radius", low=MIN_LENGTH))
        else:
            values = table.raw("radii")
            if not isinstance(values, list) or len(values) != len(points):
                raise table.error("radii", f"expected {len(points)} numbers, one a point")
            if not all(isinstance(r, int | float) and not isinstance(r, bool) for r in values):
                raise table.error("radii", f"expected numbers, got {values!r}")
            radii = np.array(values, np.float64)
        if (problem := spheres_problem(points, radii)) is not None:
            raise table.error("points", problem.replace("centers", "points", 1))
        entry = (points, radii, self._material_name(table), table.color("color"))
        table.finish()
        return entry

    def _sphere_array(self, table: Table) -> _SphereArrayEntry:
        entry = _SphereArrayEntry(table.key("file"), self._file(table), self._material_name(table))
        table.finish()
        return entry

    def _particles(self, table: Table) -> _ParticlesEntry:
        from embree_rt.scene.particles.look import ParticleLook

        topology = self._file(table, "topology") if table.has("topology") else None
        color = table.vector("color", None, non_negative=True, high=1.0)
        entry = _ParticlesEntry(
            key=table.key("file"),
            path=self._file(table),
            topology=topology,
            frame=table.integer("frame", 0, low=0),
            up=table.string("up", "z"),
            select=table.string("select"),
            wrap=table.boolean("wrap", False),
            material=self._material_name(table),
            look=ParticleLook(
                color_by=table.string("color_by"),
                color=color,
                colormap=table.string("colormap", "viridis"),
                value_range=table.pair("range") if table.has("range") else None,
                radius=table.number("radius", None, low=0.0, low_open=True),
                radius_scale=table.number("radius_scale", 1.0, low=0.0, low_open=True),
                color_columns=self._color_columns(table),
            ),
            materials=self._type_materials(table),
            extras=self._particle_extras(table),
        )
        if entry.up not in ("x", "y", "z"):
            raise table.error("up", f"expected x, y or z, got {entry.up!r}")
        table.finish()
        return entry

    def _particle_extras(self, table: Table) -> ParticleExtras:
        """A ``[[particles]]`` entry's box, bonds and legend: the keys of ``EXTRA_OPTIONS``; one
        entry's legend at most (an image has one corner for it)."""
        values = {}
        for option in EXTRA_OPTIONS:
            if is_switch(option):
                values[option.name] = table.boolean(option.name, option.default)
            else:
                values[option.name] = table.number(option.name, option.default)
        extras = ParticleExtras(**values)
        if (problem := extras_problem(extras)) is not None:
            raise table.error(*problem)
        if extras.legend and any(entry.extras.legend for entry in self.particles):
            raise table.error("legend", "another [[particles]] entry has the legend already")
        return extras

    def _color_columns(self, table: Table) -> tuple[str, ...] | None:
        """A ``[[particles]]`` entry's ``color_columns``: 3 column names, or 1 array's name."""
        value = table.raw("color_columns")
        if value is None:
            return None
        if isinstance(value, str):
            value = [value]
        if (
            not isinstance(value, list)
            or len(value) not in (1, 3)
            or not all(isinstance(v, str) for v in value)
        ):
            raise table.error("color_columns", "expected 3 column names, or 1 array's name")
        return tuple(value)

    def _type_materials(self, table: Table) -> dict[str, str] | None:
        """A ``[[particles]]`` entry's ``materials``: a table of type -> material name."""
        materials = table.table("materials")
        if materials is None:
            return None
        out = {}
        for label in materials.data:
            name = materials.string(str(label), required=True)
            if name not in self.scene.materials:
                raise materials.error(str(label), f"undefined material {name!r}")
            out[str(label)] = name
        materials.finish()
        return out

    def _mesh(self, table: Table) -> _MeshEntry:
        entry = _MeshEntry(
            key=table.key("file"),
            path=self._file(table),
            material=self._material_name(table, None),
            smooth=table.boolean("smooth", True),
            placement=self._placement(table),
            placement_key=table.key("transform" if table.has("transform") else "scale"),
        )
        table.finish()
        return entry

    def _instances(self, table: Table) -> _InstancesEntry:
        entry = _InstancesEntry(
            key=table.key("mesh"),
            path=self._file(table, "mesh"),
            placements_key=table.key("transforms"),
            placements_path=self._file(table, "transforms"),
            material=self._material_name(table, None),
            smooth=table.boolean("smooth", True),
        )
        table.finish()
        return entry

    def _placement(self, table: Table) -> np.ndarray:
        """(4, 4) float64 placement: ``transform``, else scale, rotate X, Y, Z, translate."""
        if table.has("transform"):
            for name in ("translate", "rotate", "scale"):
                if table.has(name):
                    raise table.error(name, "give either transform or translate/rotate/scale")
            matrix = table.raw("transform")
            if (problem := affine_problem(matrix)) is not None:
                raise table.error("transform", problem)
            return np.asarray(matrix, np.float64)
        translate = table.vector("translate", (0.0, 0.0, 0.0))
        rotate = table.vector("rotate", (0.0, 0.0, 0.0))
        if isinstance(table.raw("scale"), list | tuple):
            scale = table.vector("scale")
            if min(scale) <= 0:
                raise table.error("scale", f"must be > 0, got {list(scale)}")
        else:
            scale = (table.number("scale", 1.0, low=0, low_open=True),) * 3
        # Static-axes XYZ Euler angles: R = Rz @ Ry @ Rx.
        from trimesh.transformations import euler_matrix

        rotation = euler_matrix(*(math.radians(a) for a in rotate), "sxyz")
        matrix = rotation @ np.diag([*scale, 1.0])
        matrix[:3, 3] = translate
        # Rotation and translation keep a matrix invertible: only the scale can spoil it.
        if (problem := affine_problem(matrix)) is not None:
            raise table.error("scale", f"{problem}, from {list(scale)}")
        return matrix

    # -- files --------------------------------------------------------------------------------

    def _read_sphere_array(self, entry: _SphereArrayEntry):
        """(centers (n, 3), radii (n,), materials: one name or (n,) names or ids, colors: None
        or (n, 3) uint8 sRGB) of a .npz."""
        path = entry.path

        def fail(problem: str) -> SceneError:
            return SceneError(self.path, entry.key, f"{path}: {problem}")

        _check_unpacking(path, fail, _sphere_array_cost)
        arrays = read_archive(path, fail)
        for required in ("centers", "radii"):
            if required not in arrays:
                raise fail(f"missing array {required!r} (has: {', '.join(arrays) or 'none'})")
        centers, radii = arrays["centers"], arrays["radii"]
        if centers.ndim != 2 or centers.shape[1] != 3 or centers.dtype.kind not in "fiu":
            raise fail(f"centers must be (n, 3) numbers, got {centers.shape} {centers.dtype}")
        n = len(centers)
        if radii.shape != (n,) or radii.dtype.kind not in "fiu":
            raise fail(f"radii must be ({n},) numbers, got {radii.shape} {radii.dtype}")
        if (problem := spheres_problem(centers, radii)) is not None:
            raise fail(problem)
        colors = arrays.get("colors")
        if colors is not None:
            from embree_rt.scene.sphere_colors import as_srgb8

            try:
                colors = as_srgb8(colors, n)
            except ValueError as error:
                raise fail(str(error)) from None
        materials = arrays.get("materials")
        if materials is None:
            return centers, radii, entry.material, colors
        if materials.dtype.kind == "S":
            materials = materials.astype(str)
        if (problem := self._materials_problem(materials, n)) is not None:
            raise fail(problem)
        return centers, radii, materials, colors

    def _add_particles(self, scene: Scene, entry: _ParticlesEntry) -> None:
        """A ``[[particles]]`` entry's file read and added as spheres; a problem in the file
        is reported against the scene file's key."""
        from embree_rt.scene.particles import read_particles
        from embree_rt.scene.particles.to_scene import extras_arguments

        try:
            frame = read_particles(entry.path, frame=entry.frame, topology=entry.topology)
            scene.add_particles(
                frame,
                look=entry.look,
                up=entry.up,
                select=entry.select,
                wrap=entry.wrap,
                material=entry.material,
                materials=entry.materials,
                **extras_arguments(entry.extras),
            )
        except SceneError as error:
            raise SceneError(self.path, entry.key, str(error)) from None
        except ValueError as error:
            raise SceneError(self.path, entry.key, f"{entry.path}: {error}") from None

    def _materials_problem(self, materials: np.ndarray, n: int) -> str | None:
        """What is wrong with a file's (n,) ``materials`` array of names or ids, or None."""
        if materials.shape != (n,) or materials.dtype.kind not in "iuU":
            return f"materials must be ({n},) names or ids, got {materials.shape} {materials.dtype}"
        if materials.dtype.kind == "U":
            unknown = sorted(set(np.unique(materials).tolist()) - set(self.scene.materials))
            if unknown:
                return f"materials: undefined material {unknown[0]!r}"
        elif n and (materials.min() < 0 or materials.max() >= len(self.scene.materials)):
            return f"materials: id out of range [0, {len(self.scene.materials)})"
        return None

    def _read_placements(self, entry: _InstancesEntry) -> tuple[np.ndarray, np.ndarray | None]:
        """(transforms (n, 4, 4), materials (n,) names or ids or None) of an instances entry."""
        from embree_rt.scene.instances import read_placements

        path = entry.placements_path

        def fail(problem: str) -> SceneError:
            return SceneError(self.path, entry.placements_key, f"{path}: {problem}")

        _check_unpacking(path, fail, lambda headers: (unpacked_bytes(headers), "its arrays"))
        return read_placements(path, fail, self._materials_problem)
