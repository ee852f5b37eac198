"""The scene model: plain dataclasses a user can build in Python, and scene files load into."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from embree_rt.ambient_occlusion import AmbientOcclusion
from embree_rt.camera import Camera, Vec3, camera_problem
from embree_rt.film import Look
from embree_rt.legend import Legend
from embree_rt.materials import PRESETS, RGB, Checker, Material
from embree_rt.scene.animation import Animation
from embree_rt.scene.errors import SceneError
from embree_rt.scene.instances import MeshInstances
from embree_rt.scene.limits import (
    INTEGER_LIMIT,
    MIN_LENGTH,
    RADIANCE_LIMIT,
    color_problem,
    number_problem,
    placed_mesh_problem,
    spheres_problem,
    vector_problem,
)
from embree_rt.transforms import as_affine

if TYPE_CHECKING:  # trimesh (and SciPy behind it) loads in ~1 s: only scenes with meshes pay
    import trimesh
    from typing_extensions import Unpack


@dataclass
class PointLight:
    position: Vec3
    color: RGB = (1.0, 1.0, 1.0)
    intensity: float = 1.0


@dataclass
class Floor:
    """An infinite horizontal plane ``y = height`` with a checker pattern and a material."""

    height: float = 0.0
    checker: Checker = field(default_factory=Checker)
    material: Material = field(
        default_factory=lambda: Material(
            diffuse=0.8, specular=0.2, shininess=32.0, reflectivity=0.3
        )
    )


@dataclass
class Background:
    """Sky gradient: ``horizon`` color at direction y = 0 blending to ``zenith`` at y = 1."""

    horizon: RGB = (0.8, 0.88, 1.0)
    zenith: RGB = (0.25, 0.45, 0.9)


@dataclass
class RenderSettings:
    """Image size, samples per pixel, bounces, seed and look of a render (a scene's ``render``
    table)."""

    width: int = 640
    height: int = 360
    spp: int = 8
    max_depth: int = 6
    seed: int = 0
    # How the image is shown (``film.Look``): stops of exposure, tone map, transfer curve.
    exposure: float = 0.0
    tonemap: str = "reinhard"
    transfer: str = "gamma2.2"
    # Ambient occlusion of the camera rays' hits (``ambient_occlusion``): off at 0 samples.
    ao: AmbientOcclusion = field(default_factory=AmbientOcclusion)
    # What camera rays that meet nothing show (``film.BACKGROUNDS``): the sky, or a paper's
    # white, black or transparent background (the sky still lights reflections).
    background: str = "sky"

    def look(self) -> Look:
        """The ``film.Look`` these settings ask for."""
        return Look(exposure=self.exposure, tonemap=self.tonemap, transfer=self.transfer)

    def with_overrides(self, **values: Unpack[SettingOverrides]) -> RenderSettings:
        """These settings with each field named in ``values`` (``SettingOverrides``) replaced,
        unless its value is None: the one rule by which flags and keyword arguments override a
        scene's ``render`` table. An unknown name raises TypeError."""
        unknown = sorted(set(values) - set(SettingOverrides.__annotations__))
        if unknown:
            names = ", ".join(SettingOverrides.__annotations__)
            raise TypeError(f"unknown render setting {unknown[0]!r}: expected one of {names}")
        return replace(self, **{name: value for name, value in values.items() if value is not None})


class SettingOverrides(TypedDict, total=False):
    """The settings a render call may override by keyword (``render(scene, spp=64)``), each
    None or left out for the scene's own: image ``width`` and ``height`` in pixels, ``spp``
    samples per pixel, ``max_depth`` bounces, ``seed``."""

    width: int | None
    height: int | None
    spp: int | None
    max_depth: int | None
    seed: int | None


def render_problem(settings: RenderSettings) -> tuple[str, str] | None:
    """What keeps ``settings`` from numbering its samples, as (field, problem), or None: the
    samples of an image (width × height × spp) are numbered in int64."""
    samples = settings.width * settings.height * settings.spp
    if samples > INTEGER_LIMIT:
        return "spp", (
            f"a {settings.width}x{settings.height} image at {settings.spp} spp is {samples:.3g} "
            f"samples, more than the {INTEGER_LIMIT:.3g} int64 can number"
        )
    return None


Problem = tuple[str, str]  # (key, problem): the key as a scene file's table names it


def first_problem(*checks: tuple[str, str | None]) -> Problem | None:
    """The first of the (key, problem or None) ``checks`` with a problem, or None."""
    return next(((key, problem) for key, problem in checks if problem is not None), None)


def camera_limits_problem(camera: Camera) -> Problem | None:
    """What keeps ``camera`` from a scene: its vectors three numbers within the scene's reach,
    then the camera's own rule (``camera.camera_problem``)."""
    return first_problem(
        *((name, vector_problem(getattr(camera, name))) for name in ("position", "look_at", "up"))
    ) or camera_problem(camera)


def light_problem(light: PointLight) -> Problem | None:
    """What keeps ``light`` from a scene: a position within reach, a colour
    (``limits.color_problem``), an intensity from 0 to ``RADIANCE_LIMIT``."""
    return first_problem(
        ("position", vector_problem(light.position)),
        ("color", color_problem(light.color)),
        ("intensity", number_problem(light.intensity, 0.0, RADIANCE_LIMIT)),
    )


def background_problem(background: Background) -> Problem | None:
    """What keeps ``background``'s two colours from a scene."""
    return first_problem(
        ("horizon", color_problem(background.horizon)),
        ("zenith", color_problem(background.zenith)),
    )


def material_limits_problem(material: Material) -> Problem | None:
    """What keeps ``material`` from a scene beyond its own ranges (which ``Material`` checks):
    colours (``limits.color_problem``) and numbers within reach; an infinite
    ``attenuation_distance`` is the default, absorbing nothing."""
    distance = material.attenuation_distance
    return first_problem(
        ("color", color_problem(material.color)),
        ("shininess", number_problem(material.shininess)),
        ("ior", number_problem(material.ior)),
        ("emission", color_problem(material.emission)),
        ("attenuation_color", color_problem(material.attenuation_color)),
        ("attenuation_distance", None if distance == math.inf else number_problem(distance)),
    )


def floor_problem(floor: Floor) -> Problem | None:
    """What keeps ``floor`` from a scene, under the keys of a file's ``floor`` table (which
    holds its checker's and its material's keys too): a height within reach, two colours, a
    square of at least ``MIN_LENGTH``, its material's limits."""
    checker = floor.checker
    return first_problem(
        ("height", number_problem(floor.height)),
        ("color_a", color_problem(checker.color_a)),
        ("color_b", color_problem(checker.color_b)),
        ("size", number_problem(checker.size, MIN_LENGTH)),
    ) or material_limits_problem(floor.material)


@dataclass
class MeshObject:
    """One placement of a triangle mesh.

    Placements sharing the same ``mesh`` object are built once and instanced.
    ``transform`` is a (4, 4) float64 affine matrix from mesh space to world space. With
    ``mesh_colors`` the hits take the colours the mesh carries per point (its base-colour
    texture, vertex or face colours, see ``embree_rt.scene.meshes.mesh_surface``) in place of
    ``material``'s colour; ``Scene.add_mesh`` sets it when no material is named.
    """

    mesh: trimesh.Trimesh
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    material: str = "matte"
    smooth: bool = True
    mesh_colors: bool = False


@dataclass
class CurveSet:
    """Round tubes: polylines of control ``points`` (m, 3) float32 with a ``radii`` (m,)
    float32 > 0 at each, drawn as Embree's round linear curves (a cone between each pair of
    neighbouring points, touching a sphere at each), all of ``material``. ``starts`` (k,)
    int64 the segments: segment s runs from point ``starts[s]`` to ``starts[s] + 1``, so a
    polyline of p points is p - 1 consecutive starts and a bond a start of its own."""

    points: np.ndarray
    radii: np.ndarray
    starts: np.ndarray
    material: str = "matte"

    def __len__(self) -> int:
        return len(self.starts)


@dataclass
class Scene:
    """Everything to render.

    ``materials`` maps names to materials (the presets are always there). Spheres are stored in
    bulk: ``sphere_centers`` (n, 3) float32, ``sphere_radii`` (n,) float32 and
    ``sphere_materials`` (n,) int32, an index into ``material_names``. ``sphere_colors`` is None
    (each sphere its material's colour) or (n, 3) uint8 sRGB, each sphere's own base colour in
    place of its material's (3 bytes a sphere: particle files colour every particle).
    """

    camera: Camera = field(default_factory=Camera)
    lights: list[PointLight] = field(default_factory=list)
    materials: dict[str, Material] = field(default_factory=lambda: dict(PRESETS))
    floor: Floor | None = field(default_factory=Floor)
    background: Background = field(default_factory=Background)
    render: RenderSettings = field(default_factory=RenderSettings)
    sphere_centers: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    sphere_radii: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    sphere_materials: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    sphere_colors: np.ndarray | None = None
    meshes: list[MeshObject] = field(default_factory=list)
    instances: list[MeshInstances] = field(default_factory=list)
    curves: list[CurveSet] = field(default_factory=list)
    # A camera path (``scene.animation``): None for a still image.
    animation: Animation | None = None
    # What the scene's maker found and chose, one line each (a mesh file rendered on its own:
    # whose camera and lights, where the floor is), for ``embree-rt info``.
    notes: list[str] = field(default_factory=list)
    # What the particles' colours mean (``legend.Legend``), when a legend was asked for.
    legend: Legend | None = None

    @classmethod
    def from_file(cls, path, floor: bool = True) -> Scene:
        """A mesh file (OBJ, PLY, STL, OFF, glTF/GLB) rendered on its own, as it places its
        meshes: from its own camera and under its own lights when it has them, else from a
        camera framed on its bounds under a default rig, with a floor under it unless
        ``floor`` is False (``embree_rt.scene.model_file``). Raises ``SceneError`` naming the
        file and the key in it."""
        from pathlib import Path

        from embree_rt.scene.meshes import load_model
        from embree_rt.scene.model_file import stage_model

        path = Path(path)
        model = load_model(path)
        scene = cls()
        try:
            for mesh, transform in model.parts:
                scene.add_mesh(mesh, transform=transform)
            for mesh, transforms in model.instanced:
                scene.add_instances(mesh, transforms)
        except ValueError as error:  # the file's own numbers, refused as a Python caller's are
            raise SceneError(path, "(file)", str(error)) from None
        scene._stage(stage_model(path, model), floor)
        return scene

    @classmethod
    def from_particles(
        cls,
        path,
        frame: int = 0,
        topology=None,
        look=None,
        up: str = "z",
        select: str | None = None,
        wrap: bool = False,
        floor: bool = True,
        *,
        materials: dict[str, str] | None = None,
        box: bool = False,
        bonds=None,
        legend: bool = False,
        stage: bool = True,
    ) -> Scene:
        """Frame ``frame`` of the particle file ``path`` (a trajectory over ``topology``)
        rendered on its own: one sphere a particle, coloured and sized by ``look``
        (``embree_rt.scene.particles.ParticleLook``; default: by element, else by type), the
        file's ``up`` axis ("x", "y" or "z") upward, ``select`` keeping a subset (MDAnalysis's
        selection language), ``wrap`` putting positions into the periodic box, ``materials``
        a material a type, ``box`` drawing the simulation box (``add_particles``), ``bonds`` (a
        ``BondLook``) drawing its bonds as sticks, ``legend`` recording what the colours mean
        (``Scene.legend``); framed from the bounds under the default rig, a floor under it
        unless ``floor`` is False (with ``stage`` False, no framing: the camera, lights and
        floor stay a new ``Scene``'s, for a trajectory's frames seen as its first). Raises
        ``SceneError`` naming the file and the problem."""
        from embree_rt.scene.particles import read_particles

        particles = read_particles(path, frame=frame, topology=topology)
        scene = cls()
        scene.add_particles(
            particles,
            look=look,
            up=up,
            select=select,
            wrap=wrap,
            materials=materials,
            box=box,
            bonds=bonds,
            legend=legend,
        )
        if stage:
            scene.stage_particles(floor)
        return scene

    def add_particles(
        self,
        particles,
        look=None,
        up: str = "z",
        select: str | None = None,
        wrap: bool = False,
        material: str = "matte",
        *,
        materials: dict[str, str] | None = None,
        box: bool = False,
        bonds=None,
        legend: bool = False,
    ) -> None:
        """Add a ``ParticleFrame``, an ``ase.Atoms`` or an MDAnalysis ``AtomGroup`` as
        spheres of ``material``, or of ``materials[type]`` for the types it names (elements
        where the particles have no types); ``box`` adds the simulation box's 12 edges as thin
        round curves; with ``bonds`` (an ``embree_rt.scene.particles.bonds.BondLook``) its
        bonds as sticks; with ``legend``, what their colours mean becomes ``Scene.legend`` (see
        ``from_particles`` for the rest). ``SceneError`` for a type no particle has or a file
        without a box."""
        from embree_rt.scene.particles import bonds as bond_sticks
        from embree_rt.scene.particles.box import BOX_COLOR
        from embree_rt.scene.particles.to_scene import (
            UP_ROTATIONS,
            box_lines,
            particle_materials,
            particle_spheres,
            prepared,
        )

        frame = prepared(particles, select)
        centers, radii, colors, note = particle_spheres(frame, look, up, None, wrap)
        names = particle_materials(frame, materials, material)
        edges = box_lines(frame, up) if box else None
        notes = [note]
        if bonds is not None:
            # (the sticks' ends and radius are float64 sums of the centres and radii)
            drawn = (np.asarray(centers, np.float64), radii, colors)
            radii, bond_note = bond_sticks.add_bonds(
                self, frame, drawn, bonds, UP_ROTATIONS[up], material
            )
            notes.append(bond_note)
        self.add_spheres(centers, radii, names, colors=colors, copy=False)  # (made here)
        if edges is not None:
            points, radius = edges
            starts = np.arange(0, len(points), 2)
            self.add_curves(points, radius, "matte", starts=starts, color=BOX_COLOR)
        self.notes.extend(notes)
        if legend:
            from embree_rt.scene.particles.key import particle_legend
            from embree_rt.scene.particles.look import ParticleLook

            self.legend = particle_legend(frame, look or ParticleLook())

    def stage_particles(self, floor: bool = True) -> None:
        """Camera, lights and floor framed on the spheres and curves (a box, bonds), as a mesh
        file's are."""
        from embree_rt.scene.staging import stage_spheres

        centers, radii = self.sphere_centers, self.sphere_radii
        if self.curves:
            centers = np.concatenate([centers, *(curves.points for curves in self.curves)])
            radii = np.concatenate([radii, *(curves.radii for curves in self.curves)])
        self._stage(stage_spheres(centers, radii), floor)

    @classmethod
    def from_trimesh(cls, loaded: trimesh.Trimesh | trimesh.Scene, floor: bool = True) -> Scene:
        """A trimesh.Trimesh or trimesh.Scene rendered on its own (as ``add_mesh`` places it):
        from the trimesh.Scene's camera when it has one, else framed on its bounds; a default
        light rig; a floor under it unless ``floor`` is False. Raises as ``add_mesh``."""
        from embree_rt.scene.model_file import stage_trimesh

        scene = cls()
        scene.add_mesh(loaded)
        scene._stage(stage_trimesh(loaded), floor)
        return scene

    def _stage(self, staging, floor: bool) -> None:
        """Camera, lights and floor from a ``staging.Staging``: its first view the camera
        rule accepts (``camera_problem``), a render as wide as the file camera's aspect."""
        from embree_rt.scene.errors import warn_input

        for view in staging.views:
            camera = Camera(position=view.position, look_at=view.look_at, up=view.up, fov=view.fov)
            if (problem := camera_problem(camera)) is None:
                break
            warn_input(
                f"{view.note}: cannot be used ({problem[0]}: {problem[1]}); the next "
                "choice is taken"
            )
        self.camera = camera
        self.notes.append(view.note)
        if view is not staging.views[-1] and staging.aspect_ratio:  # the file's own camera
            self.render.height = max(1, round(self.render.width / staging.aspect_ratio))
        self.lights = [
            PointLight(position=light.position, color=light.color, intensity=light.intensity)
            for light in staging.lights
        ]
        self.notes += staging.notes
        if floor:
            height, size = staging.floor
            self.floor = Floor(height=height, checker=Checker(size=size))
            self.notes.append(f"floor: under the model, y = {height:.6g}")
        else:
            self.floor = None
            self.notes.append("floor: none")

    def __repr__(self) -> str:
        """One short line: what the scene holds and how it renders (a dataclass's own repr
        would print every sphere and matrix)."""

        def count(number: int, noun: str) -> str:
            return f"{number:,} {noun}{'' if number == 1 else 's'}"

        parts = [count(len(self.sphere_radii), "sphere")]
        if self.meshes:
            distinct = len({id(placed.mesh) for placed in self.meshes})
            parts.append(f"{len(self.meshes):,} mesh placements of {distinct:,} meshes")
        if self.instances:
            copies = sum(len(entry) for entry in self.instances)
            parts.append(f"{copies:,} instances in {len(self.instances):,} arrays")
        parts.append(count(len(self.lights), "light"))
        parts.append("no floor" if self.floor is None else f"floor at y = {self.floor.height:g}")
        settings = self.render
        parts.append(f"{settings.width}x{settings.height} at {settings.spp} spp")
        if self.animation is not None:
            parts.append(f"{self.animation.frames} frames")
        return f"Scene({', '.join(parts)})"

    # ``_repr_png_``, the quick preview Jupyter shows for a scene, is given to the class by
    # ``embree_rt.api`` (``preview_png``): rendering stands above the scene model, which
    # imports none of it.

    def check(self, file: str = "scene") -> None:
        """Hold the scene to the limits a scene file is held to (``scene.limits``): its camera,
        sky, lights, materials, floor and spheres, by the rules the file's reader applies to
        the same values. A value a file could not hold (a light of intensity 1e39, which
        float32 shading turns into inf and then NaN) raises the ``SceneError`` the file's
        would, ``file`` standing for the file."""
        checks = [(("camera",), camera_limits_problem(self.camera))]
        checks.append((("background",), background_problem(self.background)))
        checks += [((f"lights[{i}]",), light_problem(light)) for i, light in enumerate(self.lights)]
        checks += [
            (("materials", name), material_limits_problem(material))
            for name, material in self.materials.items()
        ]
        if self.floor is not None:
            checks.append((("floor",), floor_problem(self.floor)))
        for prefix, problem in checks:
            if problem is not None:
                raise SceneError(file, ".".join([*prefix, problem[0]]), problem[1])
        if (problem := spheres_problem(self.sphere_centers, self.sphere_radii)) is not None:
            raise SceneError(file, "spheres", problem)

    @property
    def material_names(self) -> list[str]:
        return list(self.materials)

    def object_id_starts(self) -> tuple[np.ndarray, np.ndarray]:
        """The objects' numbering (the ids AOVs and ``info`` give them): spheres 0 .. n - 1 in
        scene order, then each mesh placement, then each ``instances`` entry's copies in
        order. Returns (len(meshes),) int64, each placement's id, and (len(instances),) int64,
        the id of each entry's first copy (copy j of entry e is ``starts[e] + j``)."""
        first_mesh = len(self.sphere_radii)
        mesh_ids = first_mesh + np.arange(len(self.meshes), dtype=np.int64)
        sizes = np.array([len(entry) for entry in self.instances], np.int64)
        instance_starts = first_mesh + len(self.meshes) + np.cumsum(sizes) - sizes
        return mesh_ids, instance_starts

    def curve_ids(self) -> np.ndarray:
        """(len(curves),) int64 the object id of each curve set, after every sphere, mesh
        placement and instance (``object_id_starts``): a curve set is one object."""
        first = len(self.sphere_radii) + len(self.meshes) + sum(len(e) for e in self.instances)
        return first + np.arange(len(self.curves), dtype=np.int64)

    def add_curves(
        self,
        points: np.ndarray,
        radii: float | np.ndarray,
        material: str = "matte",
        *,
        starts: np.ndarray | None = None,
        color: RGB | None = None,
    ) -> CurveSet:
        """Add round tubes through ``points`` (m, 3): one polyline through them all, or with
        ``starts`` (k,) int the segments from point ``starts[s]`` to ``starts[s] + 1`` (bonds:
        pairs of points, ``starts = 0, 2, 4, ...``). ``radii`` one radius or (m,) per point,
        each > 0. ``material`` a material's name; with ``color`` (linear RGB) the tubes take
        that material in that colour (a material of its own, named after both). Returns the
        ``CurveSet`` added; ValueError naming the argument for bad values."""
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
            raise ValueError(f"points: expected (m, 3) with m >= 2, got shape {points.shape}")
        radii = np.broadcast_to(np.asarray(radii, np.float64), (len(points),))
        if not np.isfinite(points).all():
            raise ValueError("points: must be finite")
        if not (np.isfinite(radii) & (radii > 0)).all():
            raise ValueError("radii: must be finite and > 0")
        if (problem := spheres_problem(points, radii)) is not None:  # (its rule, for points)
            raise ValueError(problem.replace("centers", "points", 1))
        if starts is None:
            starts = np.arange(len(points) - 1, dtype=np.int64)
        starts = np.asarray(starts)
        if starts.ndim != 1 or (len(starts) and starts.dtype.kind not in "iu"):
            raise ValueError(f"starts: expected (k,) integers, got {starts.dtype} {starts.shape}")
        if len(starts) and (starts.min() < 0 or starts.max() >= len(points) - 1):
            raise ValueError(f"starts: each must lie in [0, {len(points) - 1})")
        self.material_index(material)
        if color is not None:
            rgb = tuple(float(c) for c in color)
            name = f"{material}@{rgb[0]:g},{rgb[1]:g},{rgb[2]:g}"
            if name not in self.materials:
                self.materials[name] = replace(self.materials[material], color=rgb)
            material = name
        curve_set = CurveSet(
            points.astype(np.float32),
            radii.astype(np.float32),
            starts.astype(np.int64, copy=False),
            material,
        )
        self.curves.append(curve_set)
        return curve_set

    def material_index(self, name: str) -> int:
        try:
            return self.material_names.index(name)
        except ValueError:
            raise ValueError(f"undefined material {name!r}") from None

    def add_material(self, name: str, material: Material) -> str:
        self.materials[name] = material
        return name

    def add_sphere(self, center: Vec3, radius: float, material: str = "matte") -> None:
        self.add_spheres(np.asarray([center]), np.asarray([radius]), material)

    def add_spheres(
        self,
        centers: np.ndarray,
        radii: np.ndarray,
        materials: str | np.ndarray | list[str] = "matte",
        *,
        colors: np.ndarray | None = None,
        copy: bool = True,
    ) -> None:
        """Append spheres: ``centers`` (n, 3), ``radii`` (n,), one material name for all, or
        (n,) names, or (n,) int indices into ``material_names``; ``colors`` None or (n, 3)
        each sphere's base colour, uint8 sRGB or floats in 0..1 sRGB (kept as uint8: spheres
        without their own take their material's colour, rounded to 8-bit sRGB, once any
        sphere has one).

        ``copy=False`` hands the arrays over: when the scene holds no spheres yet and they are
        already (n, 3) float32, (n,) float32 and (n,) int32, it keeps them as they are (no copy
        of a hundred million spheres); do not modify them afterwards. Centres and radii must lie
        within ``scene.limits``' bounds (ValueError naming the first bad row)."""
        centers, radii = np.asarray(centers), np.asarray(radii)
        if centers.dtype.kind not in "fiu" or radii.dtype.kind not in "fiu":
            centers, radii = np.asarray(centers, np.float64), np.asarray(radii, np.float64)
        centers, radii = centers.reshape(-1, 3), radii.reshape(-1)
        if len(radii) != len(centers):
            raise ValueError(f"radii: {len(radii)} values for {len(centers)} centers")
        # Checked before the cast: a float64 1e39 or 1e-320 would become inf or 0 in float32.
        if (problem := spheres_problem(centers, radii)) is not None:
            raise ValueError(problem)
        centers = centers.astype(np.float32, copy=False)
        radii = radii.astype(np.float32, copy=False)
        ids = self.material_ids(materials, len(centers), "centers")
        if colors is not None or self.sphere_colors is not None:
            from embree_rt.scene.sphere_colors import joined_colors

            self.sphere_colors = joined_colors(
                self.sphere_colors, self.sphere_materials, self.materials, ids, colors
            )
        if not copy and len(self.sphere_radii) == 0:
            self.sphere_centers, self.sphere_radii, self.sphere_materials = centers, radii, ids
            return
        self.sphere_centers = np.concatenate([self.sphere_centers, centers])
        self.sphere_radii = np.concatenate([self.sphere_radii, radii])
        self.sphere_materials = np.concatenate([self.sphere_materials, ids])

    def material_ids(
        self, materials: str | np.ndarray | list[str], count: int, what: str = "objects"
    ) -> np.ndarray:
        """(count,) int32 indices into ``material_names`` of one material name for all, (count,)
        names, or (count,) int indices (checked against the table); ValueError otherwise."""
        if isinstance(materials, str):
            return np.full(count, self.material_index(materials), np.int32)
        materials = np.asarray(materials)
        if materials.dtype.kind in "iu":
            if len(materials) and (materials.min() < 0 or materials.max() >= len(self.materials)):
                raise ValueError("materials: index out of range")
            ids = np.asarray(materials, np.int32)
        else:
            names, inverse = np.unique(materials.astype(str), return_inverse=True)
            lookup = np.array([self.material_index(n) for n in names], np.int32)
            ids = lookup[inverse].astype(np.int32, copy=False)
        if ids.shape != (count,):
            raise ValueError(f"materials: {len(ids)} values for {count} {what}")
        return ids

    def add_instances(
        self,
        mesh: trimesh.Trimesh | trimesh.Scene,
        transforms: np.ndarray,
        materials: str | np.ndarray | list[str] | None = None,
        smooth: bool = True,
    ) -> MeshInstances:
        """Place ``mesh`` by each of the (n, 4, 4) ``transforms`` (mesh space to world), as one
        Embree instance array; returns the ``MeshInstances`` added.

        ``materials``: one name for all, (n,) names or ids, or None: each copy looks as the
        mesh's file says (as ``add_mesh``). A trimesh.Scene becomes one mesh, its nodes baked at
        their transforms. Raises TypeError or ValueError (naming the first bad row) before
        anything is added.
        """
        import trimesh

        from embree_rt.scene.instances import single_mesh
        from embree_rt.transforms import affine_array_problem

        if not isinstance(mesh, trimesh.Trimesh | trimesh.Scene):
            raise TypeError(
                f"mesh: expected a trimesh.Trimesh or trimesh.Scene, got {type(mesh).__name__}"
            )
        if not isinstance(smooth, bool | np.bool_):
            raise TypeError(f"smooth: expected True or False, got {type(smooth).__name__}")
        if (problem := affine_array_problem(transforms)) is not None:
            row, text = problem
            raise ValueError(f"transforms: {text}" if row < 0 else f"transforms: row {row}: {text}")
        transforms = np.array(transforms, np.float64)
        if len(transforms) == 0:
            raise ValueError("transforms: expected at least one placement, got none")
        child = single_mesh(mesh)
        if (problem := placed_mesh_problem(child.vertices, transforms)) is not None:
            raise ValueError(f"transforms: row {problem[0]}: {problem[1]}")
        if materials is None:
            ids = self.material_ids(self._mesh_material(child), len(transforms), "transforms")
        else:
            ids = self.material_ids(materials, len(transforms), "transforms")
        added = MeshInstances(
            mesh=child,
            transforms=transforms,
            materials=ids,
            smooth=bool(smooth),
            mesh_colors=materials is None,
        )
        self.instances.append(added)
        return added

    def add_mesh(
        self,
        mesh: trimesh.Trimesh | trimesh.Scene,
        material: str | None = None,
        transform: np.ndarray | None = None,
        smooth: bool = True,
    ) -> list[MeshObject]:
        """Place ``mesh`` by the (4, 4) ``transform`` (default: where it is) and return the
        placements made.

        A Trimesh is one placement. A trimesh.Scene (what ``trimesh.load`` gives for a glTF) is
        one placement per node holding a triangle mesh, at ``transform`` @ the node's own
        transform, as a scene file's ``[[meshes]]`` entry does. With no material name, each mesh
        looks as its file says: the material the file gives it (see
        ``embree_rt.scene.meshes.mesh_material``) and, per point, its base-colour texture and
        vertex or face colours. A material name overrides all of that. Raises TypeError for an
        argument of the wrong type and ValueError for a transform that cannot place geometry
        (``embree_rt.transforms``) or a mesh without triangles, before anything is added.
        """
        import trimesh

        from embree_rt.scene.meshes import mesh_parts

        if not isinstance(mesh, trimesh.Trimesh | trimesh.Scene):
            raise TypeError(
                f"mesh: expected a trimesh.Trimesh or trimesh.Scene, got {type(mesh).__name__}"
            )
        if material is not None and not isinstance(material, str):
            raise TypeError(f"material: expected a material name, got {type(material).__name__}")
        if not isinstance(smooth, bool | np.bool_):
            raise TypeError(f"smooth: expected True or False, got {type(smooth).__name__}")
        placement = np.eye(4) if transform is None else as_affine(transform, "transform")
        if material is not None:
            self.material_index(material)
        parts = mesh_parts(mesh)
        if not parts:
            raise ValueError(f"mesh: the {type(mesh).__name__} holds no triangles")
        placements = [placement @ node_transform for _, node_transform in parts]
        if isinstance(mesh, trimesh.Scene):  # a node's transform may spoil the placement
            for matrix in placements:
                as_affine(matrix, "transform")
        for (part, _), matrix in zip(parts, placements, strict=True):
            if (problem := placed_mesh_problem(part.vertices, matrix[None])) is not None:
                raise ValueError(f"transform: {problem[1]}")
        added = [
            MeshObject(
                mesh=part,
                transform=matrix,
                material=self._mesh_material(part) if material is None else material,
                smooth=bool(smooth),
                mesh_colors=material is None,
            )
            for (part, _), matrix in zip(parts, placements, strict=True)
        ]
        self.meshes.extend(added)
        return added

    def _mesh_material(self, mesh: trimesh.Trimesh) -> str:
        """The name of the material the mesh's own file gives it (added to ``materials`` under a
        name made of its values), or "matte" when the file gives none."""
        from embree_rt.scene.meshes import mesh_material

        material = mesh_material(mesh)
        if material is None:
            return "matte"
        name = "base_color_{:02x}{:02x}{:02x}".format(*(round(c * 255) for c in material.color))
        if replace(material, color=Material().color) != Material():
            # More than a colour (glTF's metallic and roughness): a digest of all the values.
            name += "_" + hashlib.sha1(repr(material).encode()).hexdigest()[:6]
        if name not in self.materials:
            self.materials[name] = material
        return name
