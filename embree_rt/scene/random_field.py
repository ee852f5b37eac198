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
lights, materials; cheap), ``add_field_spheres`` (the sphere generation, in rings of bounded
memory).
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import ParamSpec

import numpy as np

from embree_rt import budget
from embree_rt.batches import worker_count
from embree_rt.camera import Camera
from embree_rt.materials import PRESETS, preset
from embree_rt.scene.model import PointLight, RenderSettings, Scene

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
SHADE_BITS = 4  # a palette shade is the top bits of a 32-bit draw: 2**4 = COLORS_PER_KIND
# Small spheres are generated a ring of about this many grid cells at a time, and stored ring by
# ring: bounded memory, and (measured at 1e7 spheres) faster than rings of 2**16 or 2**20 cells.
RING_CELLS = 1 << 18
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

_Parameters = ParamSpec("_Parameters")


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
    try:  # before any sphere is made
        budget.require({"spheres": (budget.field_bytes(count), f"{count:,} spheres")})
    except budget.MemoryBudgetError as error:
        raise FieldParameterError("count", str(error)) from None
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


def add_field_spheres(scene: Scene, plan: FieldPlan, *, threads: int | None = None) -> None:
    """Generate the field's spheres into ``scene`` (made by ``field_scene(plan)``): the heroes,
    then ``plan.small`` small spheres.

    The small spheres are made one ring of about ``RING_CELLS`` grid cells at a time, on
    ``threads`` threads (default: all cores), each ring written straight into its slice of the
    scene's arrays: the memory beyond those arrays (20 bytes a sphere) stays bounded. Each sphere
    draws its random numbers at its rank by distance in the seed's stream (PCG64 jumped ahead),
    as if all were drawn at once, so the spheres do not depend on the rings or the threads; the
    rings decide only the order they are stored in: ring by ring, row by row within a ring.
    """
    count = plan.heroes + plan.small
    centers = np.empty((count, 3), np.float32)
    radii = np.empty(count, np.float32)
    materials = np.empty(count, np.int32)
    _hero_spheres(scene, plan, centers, radii, materials)
    if plan.small:
        rings, make = _ring_maker(scene, plan)

        def fill(ring: _Ring) -> None:
            rows = slice(plan.heroes + ring.first, plan.heroes + ring.first + ring.count)
            make(ring, centers[rows], radii[rows], materials[rows])

        with ThreadPoolExecutor(max_workers=worker_count(threads)) as pool:
            for _ in pool.map(fill, rings):  # re-raises a ring's error
                pass
    scene.add_spheres(centers, radii, materials, copy=False)


def add_field_spheres_where(
    scene: Scene,
    plan: FieldPlan,
    keep: Callable[[np.ndarray], np.ndarray],
    *,
    within: tuple[tuple[float, float], tuple[float, float]] | None = None,
    threads: int | None = None,
) -> np.ndarray:
    """Generate the field's spheres as ``add_field_spheres`` does, but add to ``scene`` only
    those whose (k, 3) float32 centres ``keep`` accepts ((k,) bool), in the field's order:
    bit for bit the spheres of the whole field, with no more memory than the kept ones and a
    ring per thread. ``within``: ((x0, z0), (x1, z1)), a box (bounds may be infinite) holding
    every centre ``keep`` accepts: the rings that cannot reach it are not generated. Returns
    (m,) int64 the kept spheres' rows in the whole field (their object ids)."""
    heroes = (
        np.empty((plan.heroes, 3), np.float32),
        np.empty(plan.heroes, np.float32),
        np.empty(plan.heroes, np.int32),
    )
    _hero_spheres(scene, plan, *heroes)
    kept = keep(heroes[0])
    pieces = [(np.flatnonzero(kept).astype(np.int64), *(part[kept] for part in heroes))]
    if plan.small:
        rings, make = _ring_maker(scene, plan)
        if within is not None:
            rings = [ring for ring in rings if _ring_reaches(ring, within, plan.spacing)]

        def fill(ring: _Ring) -> tuple[np.ndarray, ...]:
            centers = np.empty((ring.count, 3), np.float32)
            radii = np.empty(ring.count, np.float32)
            materials = np.empty(ring.count, np.int32)
            make(ring, centers, radii, materials)
            rows = np.flatnonzero(keep(centers))
            return (rows + (plan.heroes + ring.first), centers[rows], radii[rows], materials[rows])

        with ThreadPoolExecutor(max_workers=worker_count(threads)) as pool:
            pieces.extend(pool.map(fill, rings))
    # Joined one column at a time, each column's pieces let go as it is joined: at most the
    # pieces and one joined column are held at once, not the pieces and all four columns.
    columns = [list(column) for column in zip(*pieces, strict=True)]
    del pieces
    ids, centers, radii, materials = (_join(column) for column in columns)
    scene.add_spheres(centers, radii, materials, copy=False)
    return ids


def _join(pieces: list[np.ndarray]) -> np.ndarray:
    """``np.concatenate(pieces)``, emptying ``pieces`` as it goes."""
    joined = np.concatenate(pieces)
    pieces.clear()
    return joined


def _ring_reaches(
    ring: _Ring, box: tuple[tuple[float, float], tuple[float, float]], spacing: float
) -> bool:
    """Whether a sphere of ``ring`` can have its centre in the (x, z) ``box``: some cell centre
    of the ring (a sphere strays less than half a cell from it) within a cell of the box."""
    (x0, z0), (x1, z1) = box
    x0, z0, x1, z1 = x0 - spacing, z0 - spacing, x1 + spacing, z1 + spacing
    near_x = max(x0, 0.0, -x1)
    near_z = max(z0, 0.0, -z1)
    far_x = max(abs(x0), abs(x1))
    far_z = max(abs(z0), abs(z1))
    return near_x * near_x + near_z * near_z < ring.high and far_x**2 + far_z**2 >= ring.low


def _hero_spheres(scene: Scene, plan: FieldPlan, centers, radii, materials) -> None:
    """Write the field's heroes into the first rows of ``centers`` (n, 3) float32, ``radii``
    and ``materials`` (n,)."""
    for row, ((x, z), material) in enumerate(HEROES[: plan.heroes]):
        centers[row] = (x, HERO_RADIUS, z)
        radii[row] = HERO_RADIUS
        materials[row] = scene.material_index(material)


def _ring_maker(scene: Scene, plan: FieldPlan):
    """The field's rings of small spheres, and ``make(ring, centers, radii, materials)``, which
    writes a ring's spheres into (ring.count, 3) / (ring.count,) arrays in the field's order."""
    hero_xz = np.array([xz for xz, _ in HEROES[: plan.heroes]], np.float64).reshape(-1, 2)
    layout = _CellLayout(plan.spacing, hero_xz)
    draws = _SphereDraws(plan, first_material=scene.material_index(f"{plan.mix[0][0]}_00"))

    def make(ring: _Ring, centers, radii, materials) -> None:
        x, z, rank = layout.cells(ring)
        draws.fill(ring.first, x, z, rank, centers, radii, materials)

    return layout.rings(plan.small, RING_CELLS), make


def _with_parameters_of(
    plan: Callable[_Parameters, FieldPlan],
) -> Callable[[Callable[[FieldPlan], Scene]], Callable[_Parameters, Scene]]:
    """Make ``build(field_plan) -> Scene`` a function of ``plan``'s parameters, which it plans
    with first: the parameters are declared once, on ``plan``, and ``help()`` and type checkers
    show them on both."""

    def decorate(build: Callable[[FieldPlan], Scene]) -> Callable[_Parameters, Scene]:
        def planned(*args: _Parameters.args, **kwargs: _Parameters.kwargs) -> Scene:
            return build(plan(*args, **kwargs))

        functools.update_wrapper(planned, build)  # its name and docstring
        returns = build.__annotations__["return"]
        planned.__annotations__ = {**plan.__annotations__, "return": returns}
        planned.__signature__ = inspect.signature(plan).replace(return_annotation=returns)
        return planned

    return decorate


@_with_parameters_of(plan_field)
def random_field(plan: FieldPlan) -> Scene:
    """A random sphere field of exactly ``count`` spheres resting on a reflective checkerboard,
    deterministic for a given ``seed``. Takes ``plan_field``'s parameters:

    ``heroes``: the first (up to) three spheres are the radius-1 hero spheres in the centre.
    ``extent``: radius of the disc the small spheres cover (default: grows as sqrt(count) at one
    sphere per unit cell). ``radius``: (min, max) small-sphere radius (default 0.12-0.22 per unit
    of spacing, capped at 0.22). ``mix``: preset name -> relative weight (default
    ``DEFAULT_MIX``). The camera and the lights adapt to the field's size. Raises
    ``FieldParameterError`` (a ``ValueError``) for a bad parameter.
    """
    scene = field_scene(plan)
    add_field_spheres(scene, plan)
    return scene


# -- helpers ----------------------------------------------------------------------------------


class _SphereDraws:
    """The random numbers of the small spheres, drawn at any rank without drawing the others.

    The field's random stream (PCG64 keyed by ``[seed, 1]``) holds, for ``n`` small spheres in
    rank order: n radii, then n (x, z) jitter pairs, then n kind draws (each a float64 from one
    64-bit output), then n palette shades (each from one 32-bit half of an output, low half
    first, its top 4 bits): what ``uniform``, ``random``, ``choice(p=...)`` and
    ``integers(0, 16)`` of one NumPy Generator draw in that order, so the field is the one those
    calls make for all spheres at once.
    """

    def __init__(self, plan: FieldPlan, first_material: int) -> None:
        self.plan = plan
        self.first_material = first_material
        self.seed = np.random.SeedSequence([plan.seed, 1])  # the spheres' own stream
        cdf = np.array([p for _, p in plan.mix]).cumsum()
        self.cdf = cdf / cdf[-1]

    def _stream(self, position: int) -> np.random.PCG64:
        bits = np.random.PCG64(self.seed)
        bits.advance(position)
        return bits

    def fill(
        self,
        first: int,
        x: np.ndarray,
        z: np.ndarray,
        rank: np.ndarray,
        centers: np.ndarray,
        radii: np.ndarray,
        materials: np.ndarray,
    ) -> None:
        """The spheres of ranks ``first + rank`` (k,) int64, a permutation of 0 ... k - 1, in
        the cells centred at ``x``, ``z`` (k,) float64, written into ``centers`` (k, 3) float32,
        ``radii`` (k,) float32 and ``materials`` (k,) int32 in that order."""
        plan, n, k = self.plan, self.plan.small, len(x)
        radius = np.random.Generator(self._stream(first)).uniform(*plan.radius, size=k)[rank]
        reach = plan.spacing / 2 - radius  # the sphere stays inside its cell, so none overlap
        # (np.take, not jitter[rank]: NumPy's fancy indexing of a 2-wide row is 25x slower)
        jitter = np.take(
            np.random.Generator(self._stream(n + 2 * first)).random((k, 2)), rank, axis=0
        )
        jitter *= 2
        jitter -= 1
        jitter *= reach[:, None]
        centers[:, 0] = jitter[:, 0] + x
        # float32 radii equal the float32 heights exactly, so every sphere touches the floor.
        centers[:, 1] = radius
        centers[:, 2] = jitter[:, 1] + z
        radii[:] = radius
        # The kind is the number of cumulative probabilities <= the draw: choice(p=...)'s
        # searchsorted(side="right"), in a few passes.
        uniform = np.random.Generator(self._stream(3 * n + first)).random(k)[rank]
        kind = np.zeros(k, np.int32)
        for bound in self.cdf[:-1]:
            kind += uniform >= bound
        raw = self._stream(4 * n + first // 2).random_raw((first % 2 + k + 1) // 2)
        halves = np.empty((len(raw), 2), np.uint32)
        halves[:, 0] = raw  # the low 32 bits
        halves[:, 1] = raw >> np.uint64(32)
        shade = halves.reshape(-1)[first % 2 : first % 2 + k][rank] >> np.uint32(32 - SHADE_BITS)
        kind *= COLORS_PER_KIND
        kind += self.first_material
        np.add(kind, shade, out=materials, casting="unsafe")


@dataclass(frozen=True)
class _Ring:
    """The cells with ``low <= x * x + z * z < high``: ``count`` of them (the first ones, in the
    field's order) are the spheres of ranks ``first`` ... ``first + count - 1``."""

    low: float
    high: float
    first: int
    count: int


class _CellLayout:
    """The grid cells of a field in its order: nearest the origin first.

    Cell (i, j) is centred at x = (i + 0.5) * spacing, z = (j + 0.5) * spacing; cells within the
    clear ring of a hero at ``hero_xz`` (h, 2) are left out. The order is by squared distance
    ``x * x + z * z`` (float64), then by i, then by j. Rings of squared distance split it into
    pieces of bounded size that can be made independently.
    """

    def __init__(self, spacing: float, hero_xz: np.ndarray) -> None:
        self.spacing = spacing
        self.hero_xz = hero_xz
        self.keep_out = (HERO_RADIUS + HERO_CLEARANCE * spacing) ** 2
        # Beyond this squared distance no cell is near a hero.
        self.hero_zone = 0.0
        if len(hero_xz):
            hero_reach = float(np.hypot(hero_xz[:, 0], hero_xz[:, 1]).max())
            self.hero_zone = (hero_reach + math.sqrt(self.keep_out) + spacing) ** 2

    def rings(self, needed: int, ring_cells: int) -> list[_Ring]:
        """The rings holding the ``needed`` nearest cells, of about ``ring_cells`` cells each:
        ring k holds the cells with ``k * w <= x * x + z * z < (k + 1) * w``, for ``w`` the area
        of ``ring_cells`` cells over pi."""
        width = max(ring_cells, 1) * self.spacing**2 / math.pi  # a ring's squared-distance span
        rings: list[_Ring] = []
        found = 0
        while found < needed:
            low, high = len(rings) * width, (len(rings) + 1) * width
            if low < self.hero_zone:
                count = len(self._candidates(low, high)[0])
            else:  # no hero nearby: count the columns, row by row
                count = 2 * int(self._row_intervals(low, high)[3].sum())
            count = min(count, needed - found)
            rings.append(_Ring(low, high, found, count))
            found += count
        return [ring for ring in rings if ring.count]

    def cells(self, ring: _Ring) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ring's ``ring.count`` nearest cells: (count,) float64 x and z in (i, j) order (the
        order they are stored in: neighbours stay close in memory, which Embree's build and the
        traversal's caches like), and (count,) int64 the rank of each by distance (0: nearest)."""
        x, z = self._candidates(ring.low, ring.high)
        distance = x * x
        distance += z * z
        nearest = _stable_order(distance, ring.low, ring.high)[: ring.count]
        rank = np.full(len(x), -1, np.int64)
        rank[nearest] = np.arange(ring.count)
        if ring.count < len(x):  # the field's last ring: only its nearest cells
            kept = np.flatnonzero(rank >= 0)
            x, z, rank = x[kept], z[kept], rank[kept]
        return x, z, rank

    def _candidates(self, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
        """x, z (k,) float64 of the ring's cells that are clear of the heroes, in (i, j) order."""
        x, start, length = self._row_intervals(low, high)[1:]
        # Per row, the columns [-start - length, -start), then [start, start + length).
        starts = np.column_stack([-start - length, start]).reshape(-1)
        lengths = np.repeat(length, 2)
        offsets = np.cumsum(lengths) - lengths
        column = np.arange(int(lengths.sum()), dtype=np.int64)
        column += np.repeat(starts - offsets, lengths)
        z = (column + 0.5) * self.spacing
        x = np.repeat(x, 2 * length)
        if low < self.hero_zone and len(self.hero_xz):
            clear = np.ones(len(x), bool)
            for hx, hz in self.hero_xz:
                clear &= (x - hx) ** 2 + (z - hz) ** 2 > self.keep_out
            x, z = x[clear], z[clear]
        return x, z

    def _row_intervals(self, low: float, high: float) -> tuple[np.ndarray, ...]:
        """Rows i (r,) int64, their x (r,) float64, and per row the columns j >= 0 in the ring,
        ``start`` <= j < ``start + length`` (r,) int64 (the mirror cells -1 - j are in it too:
        their z is exactly -z); rows without any are left out."""
        reach = math.sqrt(high) / self.spacing
        rows = np.arange(math.floor(-reach - 0.5) - 1, math.ceil(reach - 0.5) + 2, dtype=np.int64)
        x = (rows + 0.5) * self.spacing
        start = self._first_column_reaching(x * x, low)
        length = self._first_column_reaching(x * x, high) - start
        keep = length > 0
        return rows[keep], x[keep], start[keep], length[keep]

    def _first_column_reaching(self, x2: np.ndarray, bound: float) -> np.ndarray:
        """(r,) int64: per row of squared x ``x2`` (r,), the least j >= 0 with
        ``x2 + z * z >= bound`` (it grows with j, so the columns below it are all nearer)."""
        s = self.spacing
        guess = np.ceil(np.sqrt(np.maximum(bound - x2, 0.0)) / s - 0.5)
        j = np.maximum(guess, 0.0).astype(np.int64)
        # The square root can land a column off either way: step to the exact answer.
        while (down := (j > 0) & (x2 + ((j - 0.5) * s) ** 2 >= bound)).any():
            j -= down
        while (up := x2 + ((j + 0.5) * s) ** 2 < bound).any():
            j += up
        return j


def _stable_order(values: np.ndarray, low: float, high: float) -> np.ndarray:
    """(k,) int64: ``np.argsort(values, kind="stable")`` for (k,) float64 ``values`` in
    ``[low, high)``, three times faster on a ring's distances.

    First a stable radix sort on ``values`` quantised to 16 bits (monotone, so equal values
    share a bucket in their original order), then a stable sort of the result, which is all
    but sorted already and so cheap for NumPy's timsort: together, order by value, then by
    position, exactly as the one stable sort.
    """
    scale = 65535.0 / (high - low) if high > low else 0.0
    bucket = ((values - low) * scale).astype(np.uint16)
    coarse = np.argsort(bucket, kind="stable")  # a radix sort for 16-bit keys
    return coarse[np.argsort(values[coarse], kind="stable")]


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
