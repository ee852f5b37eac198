"""The seed article's random sphere field, scaled from a handful to millions of spheres.

Small spheres sit one per cell of a square grid on the floor (``y = radius``), jittered inside
their cells so they never overlap, filling the cells nearest the centre first: the field is a
disc. By default the grid spacing is 1 and the disc grows with the count at constant density, so
the foreground looks the same at every size and a million spheres reach the horizon. Given an
``extent`` (the disc's radius), the spacing shrinks or grows to fit the count, and the default
radii follow the spacing when it is below 1. Three hero spheres (glass, gold metal, mirror; the
classic "Ray Tracing in One Weekend" cover) stand in the middle, with a clear ring around each.

Spheres store a material index, so per-sphere random colors are quantised into a palette of
``COLORS_PER_KIND`` named materials per kind (``matte_00`` ... ``glass_15``).

Generation is split so a scene-file loader can check every parameter and know every material name
before the heavy part runs: ``plan_field`` (validate, derive the layout), ``field_scene`` (camera,
lights, materials; cheap), ``add_field_spheres`` (the vectorised sphere generation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from embree_rt.materials import PRESETS, preset
from embree_rt.scene.model import Camera, PointLight, RenderSettings, Scene

HERO_RADIUS = 1.0
HEROES = (  # (x, z) on the floor, material name; the glass one comes first
    ((0.0, 0.0), "hero_glass"),
    ((-4.0, 0.0), "hero_gold"),
    ((4.0, 0.0), "hero_mirror"),
)
# Small-sphere kinds and how often each is drawn (the article: mostly diffuse, some shiny).
DEFAULT_MIX: dict[str, float] = {
    "matte": 0.5,
    "glossy": 0.2,
    "metal": 0.15,
    "mirror": 0.05,
    "glass": 0.1,
}
COLORS_PER_KIND = 16
# Default small-sphere radii per unit of grid spacing: the cover's 0.2 in a unit cell, varied.
RADIUS_PER_SPACING = (0.12, 0.22)
# Free ring around each hero, beyond its radius, in grid spacings (a jittered sphere reaches at
# most 0.71 spacings from its cell centre, so 0.9 also leaves a visible gap).
HERO_CLEARANCE = 0.9
# Default framing, the cover's three-quarter view of the heroes (they span x in [-5, 5]); a field
# without heroes scales it down to its own size.
VIEW_POSITION = np.array([12.0, 2.4, 7.0])
VIEW_LOOK_AT = np.array([0.0, 0.8, 0.0])
VIEW_FRAME = 5.0


class FieldParameterError(ValueError):
    """A bad ``random_field`` parameter: ``name`` is the parameter, ``problem`` what is wrong."""

    def __init__(self, name: str, problem: str) -> None:
        self.name = name
        self.problem = problem
        super().__init__(f"{name}: {problem}")


@dataclass(frozen=True)
class FieldPlan:
    """Validated parameters of a random field and the layout derived from them.

    ``spacing`` is the grid cell side, ``extent`` the radius of the disc the small spheres
    cover, ``radius`` the (min, max) small-sphere radius, ``mix`` the kinds drawn, as
    (preset name, probability) pairs with probabilities summing to 1.
    """

    count: int
    seed: int
    heroes: int
    spacing: float
    extent: float
    radius: tuple[float, float]
    mix: tuple[tuple[str, float], ...]

    @property
    def small(self) -> int:
        return self.count - self.heroes


def plan_field(
    count: int,
    seed: int = 0,
    *,
    extent: float | None = None,
    radius: tuple[float, float] | None = None,
    mix: Mapping[str, float] | None = None,
    heroes: bool = True,
) -> FieldPlan:
    """Check the parameters of ``random_field`` and derive the layout (cheap: no spheres yet).

    Raises ``FieldParameterError`` naming the parameter at fault.
    """
    if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 1:
        raise FieldParameterError("count", f"must be a positive integer, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise FieldParameterError("seed", f"must be a non-negative integer, got {seed!r}")
    count, seed = int(count), int(seed)
    hero_count = min(count, len(HEROES)) if heroes else 0
    small = count - hero_count
    clear_area = hero_count * math.pi  # times (HERO_RADIUS + HERO_CLEARANCE * spacing) ** 2

    if radius is not None:
        radius = _radius_range(radius)
    if extent is not None:
        if not _finite(extent) or extent <= 0:
            raise FieldParameterError("extent", f"must be a finite number > 0, got {extent!r}")
        extent = float(extent)
        # Solve pi E^2 = small s^2 + clear_area (R + c s)^2 for the spacing s.
        a = small + clear_area * HERO_CLEARANCE**2
        b = 2 * clear_area * HERO_RADIUS * HERO_CLEARANCE
        c = clear_area * HERO_RADIUS**2 - math.pi * extent**2
        if c >= 0:
            raise FieldParameterError(
                "extent", f"too small to hold the hero spheres: must exceed {math.sqrt(hero_count)}"
            )
        spacing = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a) if a > 0 else extent
    else:
        spacing = 1.0 if radius is None else max(1.0, radius[1] / RADIUS_PER_SPACING[1])
        area = small * spacing**2 + clear_area * (HERO_RADIUS + HERO_CLEARANCE * spacing) ** 2
        extent = math.sqrt(area / math.pi)
    if radius is None:
        scale = min(spacing, 1.0)
        radius = (RADIUS_PER_SPACING[0] * scale, RADIUS_PER_SPACING[1] * scale)
    elif small and radius[1] > spacing / 2:
        raise FieldParameterError(
            "radius",
            f"{radius[1]:g} is too large: {small} spheres in extent {extent:g} are "
            f"{spacing:.3g} apart, so radii must be <= {spacing / 2:.3g}",
        )
    return FieldPlan(
        count=count,
        seed=seed,
        heroes=hero_count,
        spacing=spacing,
        extent=extent,
        radius=radius,
        mix=_normalised_mix(DEFAULT_MIX if mix is None else mix),
    )


def field_scene(plan: FieldPlan) -> Scene:
    """The field's scene without its spheres: camera, lights, render settings, materials."""
    # Without heroes, frame the field itself, close enough that its spheres read as spheres.
    frame = VIEW_FRAME if plan.heroes else min(max(plan.extent, 3 * plan.radius[1]), VIEW_FRAME)
    scale = frame / VIEW_FRAME
    # Lights keep their direction and climb with the field, so its far side is lit from above.
    height = max(1.0, plan.extent / 20.0)
    scene = Scene(
        camera=Camera(
            position=_vec(VIEW_POSITION * scale), look_at=_vec(VIEW_LOOK_AT * scale), fov=26.0
        ),
        lights=[
            PointLight(position=_vec(np.array([10.0, 20.0, 10.0]) * height), intensity=0.9),
            PointLight(position=_vec(np.array([-12.0, 14.0, 4.0]) * height), intensity=0.35),
        ],
        render=RenderSettings(width=960, height=540, spp=8, max_depth=6, seed=plan.seed),
    )
    if plan.heroes:
        scene.add_material("hero_glass", preset("glass"))
        scene.add_material("hero_gold", preset("metal", color=(0.95, 0.75, 0.35)))
        scene.add_material("hero_mirror", preset("mirror", color=(0.95, 0.95, 0.95)))
    rng = np.random.default_rng([plan.seed, 0])  # the palette's own stream
    for kind, _ in plan.mix:
        for k in range(COLORS_PER_KIND):
            scene.add_material(f"{kind}_{k:02d}", preset(kind, color=_palette_color(rng, kind)))
    return scene


def add_field_spheres(scene: Scene, plan: FieldPlan) -> None:
    """Generate the field's spheres into ``scene`` (made by ``field_scene(plan)``): the heroes,
    then ``plan.small`` small spheres, vectorised (a million take well under a second)."""
    hero_xz = np.array([xz for xz, _ in HEROES[: plan.heroes]], np.float64).reshape(-1, 2)
    for (x, z), material in HEROES[: plan.heroes]:
        scene.add_sphere((x, HERO_RADIUS, z), HERO_RADIUS, material)
    if plan.small == 0:
        return
    rng = np.random.default_rng([plan.seed, 1])  # the spheres' own stream
    spacing = plan.spacing
    cells = _free_cells(plan.small, spacing, plan.extent, hero_xz)
    radii = rng.uniform(*plan.radius, size=plan.small)
    reach = spacing / 2 - radii  # the sphere stays inside its cell, so none overlap
    xz = cells + (rng.random((plan.small, 2)) * 2 - 1) * reach[:, None]
    centers = np.column_stack([xz[:, 0], radii, xz[:, 1]]).astype(np.float32)

    probabilities = np.array([p for _, p in plan.mix])
    kind = rng.choice(len(plan.mix), size=plan.small, p=probabilities)
    shade = rng.integers(0, COLORS_PER_KIND, size=plan.small)
    first = scene.material_index(f"{plan.mix[0][0]}_00")
    materials = (first + kind * COLORS_PER_KIND + shade).astype(np.int32)
    # float32 radii equal the float32 heights exactly, so every sphere touches the floor.
    scene.add_spheres(centers, radii.astype(np.float32), materials)


def random_field(
    count: int,
    seed: int = 0,
    *,
    extent: float | None = None,
    radius: tuple[float, float] | None = None,
    mix: Mapping[str, float] | None = None,
    heroes: bool = True,
) -> Scene:
    """A random sphere field of exactly ``count`` spheres resting on a reflective checkerboard,
    deterministic for a given ``seed``.

    ``heroes``: the first (up to) three spheres are the radius-1 hero spheres in the centre.
    ``extent``: radius of the disc the small spheres cover (default: grows as sqrt(count) at one
    sphere per unit cell). ``radius``: (min, max) small-sphere radius (default 0.12-0.22 per unit
    of spacing, capped at 0.22). ``mix``: preset name -> relative weight (default
    ``DEFAULT_MIX``). The camera and the lights adapt to the field's size. Raises
    ``FieldParameterError`` (a ``ValueError``) for a bad parameter.
    """
    plan = plan_field(count, seed, extent=extent, radius=radius, mix=mix, heroes=heroes)
    scene = field_scene(plan)
    add_field_spheres(scene, plan)
    return scene


# -- helpers ----------------------------------------------------------------------------------


def _free_cells(needed: int, spacing: float, extent: float, hero_xz: np.ndarray) -> np.ndarray:
    """(needed, 2) float64 centres of the grid cells nearest the origin, leaving out the cells
    within the clear ring of a hero at ``hero_xz`` (h, 2)."""
    keep_out = (HERO_RADIUS + HERO_CLEARANCE * spacing) ** 2
    half = math.ceil(extent / spacing) + 2
    while True:
        axis = (np.arange(-half, half) + 0.5) * spacing
        x, z = np.meshgrid(axis, axis, indexing="ij")
        x, z = x.ravel(), z.ravel()
        distance = x * x + z * z
        usable = distance <= (half * spacing) ** 2
        for hx, hz in hero_xz:
            usable &= (x - hx) ** 2 + (z - hz) ** 2 > keep_out
        if np.count_nonzero(usable) >= needed:
            rows = np.flatnonzero(usable)
            nearest = rows[np.argsort(distance[rows], kind="stable")[:needed]]
            return np.column_stack([x[nearest], z[nearest]])
        half *= 2


def _palette_color(rng: np.random.Generator, kind: str) -> tuple[float, float, float]:
    if kind == "glass":
        color = 0.6 + 0.4 * rng.random(3)  # lightly tinted
    elif kind in ("metal", "mirror"):
        color = 0.5 + 0.5 * rng.random(3)
    else:
        color = rng.random(3) * rng.random(3)  # the cover's product of two uniforms: deep colors
    return _vec(color)


def _radius_range(radius: object) -> tuple[float, float]:
    if (
        not isinstance(radius, list | tuple | np.ndarray)
        or len(radius) != 2
        or not all(_finite(r) for r in radius)
    ):
        raise FieldParameterError("radius", f"expected [min, max] finite numbers, got {radius!r}")
    low, high = float(radius[0]), float(radius[1])
    if not 0 < low <= high:
        raise FieldParameterError("radius", f"expected 0 < min <= max, got [{low:g}, {high:g}]")
    return low, high


def _normalised_mix(mix: Mapping[str, float]) -> tuple[tuple[str, float], ...]:
    if not isinstance(mix, Mapping) or not mix:
        raise FieldParameterError("mix", f"expected a table of preset = weight, got {mix!r}")
    for name, weight in mix.items():
        if name not in PRESETS:
            raise FieldParameterError(
                f"mix.{name}", f"unknown preset {name!r}; known: {', '.join(PRESETS)}"
            )
        if not _finite(weight) or weight < 0:
            raise FieldParameterError(f"mix.{name}", f"must be a number >= 0, got {weight!r}")
    total = float(sum(mix.values()))
    if total <= 0:
        raise FieldParameterError("mix", "at least one weight must be > 0")
    # Preset order, not the caller's order, so the palette names come out the same either way.
    return tuple((name, float(mix[name]) / total) for name in PRESETS if mix.get(name, 0) > 0)


def _finite(value: object) -> bool:
    return (
        not isinstance(value, bool)
        and isinstance(value, int | float | np.integer | np.floating)
        and math.isfinite(value)
    )


def _vec(values) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))
