"""The random sphere field: exact counts, three heroes in the middle, small spheres resting on the
floor without touching each other (checked with a k-d tree), deterministic per seed, a million
spheres generated, and the ring-by-ring generator equal to an all-at-once meshgrid reference
whatever its ring size or thread count."""

from __future__ import annotations

import importlib
import inspect
import math
import pydoc
import time

import numpy as np
import pytest
from scipy.spatial import cKDTree

from embree_rt import Scene, random_field
from embree_rt.budget import SCENE_BYTES_PER_SPHERE, available_memory
from embree_rt.scene.random_field import (
    COLORS_PER_KIND,
    HERO_CLEARANCE,
    HERO_RADIUS,
    HEROES,
    _stable_order,
    add_field_spheres,
    field_scene,
    plan_field,
)

# The module, not the function of the same name that ``embree_rt.scene`` exports.
random_field_module = importlib.import_module("embree_rt.scene.random_field")


def materials_of(scene: Scene) -> list:
    """(n,) list of the Material of each sphere."""
    table = list(scene.materials.values())
    return [table[i] for i in scene.sphere_materials]


def hero_rows(scene: Scene) -> np.ndarray:
    """Rows of the spheres that are heroes: the article's big spheres of radius 1."""
    return np.flatnonzero(scene.sphere_radii >= 0.99)


def overlapping_pairs(centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(k, 2) rows of sphere pairs that intersect, found by a k-d tree over the centers."""
    centers = np.asarray(centers, np.float64)
    radii = np.asarray(radii, np.float64)
    pairs = cKDTree(centers).query_pairs(2 * radii.max(), output_type="ndarray")
    gap = np.linalg.norm(centers[pairs[:, 0]] - centers[pairs[:, 1]], axis=1)
    return pairs[gap < radii[pairs[:, 0]] + radii[pairs[:, 1]]]


@pytest.mark.parametrize("count", [1, 2, 3, 60, 10_000])
def test_exact_count(count: int) -> None:
    scene = random_field(count, seed=1)
    assert scene.sphere_centers.shape == (count, 3)
    assert scene.sphere_radii.shape == (count,)
    assert scene.sphere_materials.shape == (count,)
    assert np.isfinite(scene.sphere_centers).all()
    assert (scene.sphere_radii > 0).all()
    assert scene.sphere_materials.min() >= 0
    assert scene.sphere_materials.max() < len(scene.materials)


@pytest.mark.parametrize("count", [3, 60, 10_000])
def test_three_heroes_stand_in_the_middle(count: int) -> None:
    scene = random_field(count, seed=2)
    heroes = hero_rows(scene)
    assert len(heroes) == 3
    centers = scene.sphere_centers[heroes]
    np.testing.assert_array_equal(centers[:, 1], scene.sphere_radii[heroes])  # on the floor
    assert (np.hypot(centers[:, 0], centers[:, 2]) <= 5.0).all()
    kinds = [materials_of(scene)[i] for i in heroes]
    assert sum(m.transparency > 0 for m in kinds) == 1  # glass
    assert sum(m.metallic for m in kinds) == 1  # gold metal
    gold = next(m for m in kinds if m.metallic)
    assert gold.color[0] > gold.color[1] > gold.color[2]
    assert sum(m.reflectivity >= 0.9 and not m.metallic for m in kinds) == 1  # mirror
    # the small spheres are all smaller than the heroes
    small = np.setdiff1d(np.arange(count), heroes)
    assert (scene.sphere_radii[small] < 0.5).all()


@pytest.mark.parametrize("count", [1, 2])
def test_fewer_than_three_are_all_heroes(count: int) -> None:
    """Documented: the first (up to) three spheres are the heroes, the glass one first."""
    scene = random_field(count)
    assert len(hero_rows(scene)) == count
    assert materials_of(scene)[0].transparency > 0
    np.testing.assert_array_equal(scene.sphere_centers[:, 1], scene.sphere_radii)
    assert len(overlapping_pairs(scene.sphere_centers, scene.sphere_radii)) == 0


def test_heroes_can_be_left_out() -> None:
    scene = random_field(60, heroes=False)
    assert len(scene.sphere_radii) == 60
    assert len(hero_rows(scene)) == 0


def test_small_spheres_rest_on_the_floor_without_overlapping() -> None:
    scene = random_field(2000, seed=3)
    centers, radii = scene.sphere_centers, scene.sphere_radii
    small = np.setdiff1d(np.arange(2000), hero_rows(scene))
    assert len(small) == 1997
    np.testing.assert_array_equal(centers[small, 1], radii[small])
    assert scene.floor is not None and scene.floor.height == 0.0
    assert len(overlapping_pairs(centers, radii)) == 0


def test_small_spheres_wear_many_random_materials() -> None:
    scene = random_field(2000, seed=4)
    small = np.setdiff1d(np.arange(2000), hero_rows(scene))
    table = list(scene.materials.values())
    used = [table[i] for i in np.unique(scene.sphere_materials[small])]
    assert len(set(used)) > 20
    assert any(m.transparency > 0 for m in used)
    assert any(m.metallic for m in used)
    assert any(m.transparency == 0 and not m.metallic and m.reflectivity == 0 for m in used)


def test_overlap_check_catches_an_overlap() -> None:
    """The k-d tree check above is not vacuous: two touching spheres are found."""
    centers = np.array([[0.0, 0.2, 0.0], [0.3, 0.2, 0.0], [5.0, 0.2, 0.0]])
    assert overlapping_pairs(centers, np.array([0.2, 0.2, 0.2])).tolist() == [[0, 1]]


def test_same_seed_same_field_other_seed_other_field() -> None:
    first, again, other = random_field(500, seed=9), random_field(500, seed=9), random_field(500)
    # Bitwise, on any ISA: NumPy's generators turn integer streams into floats the same way on
    # every machine, and the field is built from them with correctly rounded operations alone
    # (+, -, *, /, sqrt), which IEEE 754 makes the same everywhere.
    for name in ("sphere_centers", "sphere_radii", "sphere_materials"):
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name))
    assert first.materials == again.materials
    assert first.camera == again.camera and first.lights == again.lights
    assert not np.array_equal(first.sphere_centers, other.sphere_centers)
    assert not np.array_equal(first.sphere_radii, other.sphere_radii)


@pytest.mark.parametrize("count", [0, -1, 2.5, True])
def test_bad_counts_are_rejected(count) -> None:
    with pytest.raises(ValueError, match="count"):
        random_field(count)


def test_a_million_spheres() -> None:
    count = 1_000_000
    scene = random_field(count, seed=0)
    centers, radii = scene.sphere_centers, scene.sphere_radii
    assert centers.shape == (count, 3) and centers.dtype == np.float32
    assert np.isfinite(centers).all()
    small = np.setdiff1d(np.arange(count), hero_rows(scene))
    assert len(small) == count - 3
    np.testing.assert_array_equal(centers[small, 1], radii[small])
    # constant density: a million spheres fill a disc of about sqrt(n / pi) units, not more
    reach = np.hypot(centers[:, 0], centers[:, 2]).max()
    assert reach <= 1.1 * math.sqrt(count / math.pi) + 6
    # no two small spheres overlap, and none touches a hero
    assert len(overlapping_pairs(centers[small], radii[small])) == 0
    tree = cKDTree(centers[small].astype(np.float64))
    for hero in hero_rows(scene):
        near = small[tree.query_ball_point(centers[hero], radii[hero] + radii[small].max())]
        gap = np.linalg.norm(centers[near] - centers[hero], axis=1)
        assert (gap >= radii[near] + radii[hero]).all()


@pytest.mark.parametrize("radius", [(0.05, 0.1), (0.3, 0.9)])
def test_radius_range_is_kept(radius: tuple[float, float]) -> None:
    """Small or large (then the grid spreads out), the radii stay in range and apart."""
    scene = random_field(3000, seed=6, radius=radius)
    small = np.setdiff1d(np.arange(3000), hero_rows(scene))
    radii = scene.sphere_radii[small]
    assert radii.min() >= np.float32(radius[0]) and radii.max() <= np.float32(radius[1])
    np.testing.assert_array_equal(scene.sphere_centers[small, 1], radii)
    assert len(overlapping_pairs(scene.sphere_centers, scene.sphere_radii)) == 0


@pytest.mark.parametrize("extent", [8.0, 60.0])
def test_extent_bounds_the_field(extent: float) -> None:
    """2000 spheres squeezed into (or spread over) a disc of the given radius, still apart."""
    scene = random_field(2000, seed=7, extent=extent)
    assert len(scene.sphere_radii) == 2000
    reach = np.hypot(scene.sphere_centers[:, 0], scene.sphere_centers[:, 2]).max()
    assert reach <= 1.05 * extent + 1.0
    assert reach >= 0.8 * extent  # the disc is filled out to the extent, not bunched up
    assert len(overlapping_pairs(scene.sphere_centers, scene.sphere_radii)) == 0


def test_mix_limits_the_kinds() -> None:
    scene = random_field(500, seed=8, mix={"glass": 1.0})
    small = np.setdiff1d(np.arange(500), hero_rows(scene))
    table = list(scene.materials.values())
    assert all(table[i].transparency > 0 for i in np.unique(scene.sphere_materials[small]))


@pytest.mark.parametrize(
    ("arguments", "name"),
    [
        ({"radius": (0.3, 0.1)}, "radius"),
        ({"radius": (0.1, 0.9), "extent": 5.0}, "radius"),  # 100 of them cannot fit apart
        ({"extent": -1.0}, "extent"),
        ({"extent": 1.0}, "extent"),  # too small even for the heroes
        ({"mix": {"velvet": 1.0}}, "velvet"),
        ({"mix": {"matte": 0.0}}, "mix"),
        ({"seed": -1}, "seed"),
    ],
)
def test_bad_parameters_name_the_parameter(arguments: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        random_field(100, **arguments)


def test_random_field_shows_the_parameters_it_takes() -> None:
    # Declared once, on plan_field: help() must still list them on random_field, and they stay
    # keyword-only past the seed.
    parameters = inspect.signature(random_field).parameters
    assert list(parameters) == ["count", "seed", "extent", "radius", "mix", "heroes"]
    assert parameters == inspect.signature(plan_field).parameters
    assert parameters["extent"].kind is inspect.Parameter.KEYWORD_ONLY
    assert "count: 'int', seed: 'int' = 0, *, extent" in pydoc.render_doc(random_field)
    with pytest.raises(TypeError):
        random_field(10, 0, 5.0)  # extent given by position


# -- generation in rings ---------------------------------------------------------------------


def meshgrid_field(count: int, seed: int, **arguments) -> tuple[np.ndarray, ...]:
    """The field as the first version made it, all at once: the grid cells of a meshgrid big
    enough, the ``count - 3`` nearest the origin outside the heroes' clear rings (a stable sort
    by float64 squared distance, cells in (x, z) order), then one Generator drawing radii,
    jitter, kinds and shades for all spheres in turn. A reference that shares no code with the
    ring-by-ring generator but the plan; returns centres, radii and materials of the spheres."""
    plan = plan_field(count, seed, **arguments)
    scene = field_scene(plan)
    hero_xz = np.array([xz for xz, _ in HEROES[: plan.heroes]], np.float64).reshape(-1, 2)
    keep_out = (HERO_RADIUS + HERO_CLEARANCE * plan.spacing) ** 2
    half = math.ceil(plan.extent / plan.spacing) + 2
    while True:
        axis = (np.arange(-half, half) + 0.5) * plan.spacing
        x, z = (grid.ravel() for grid in np.meshgrid(axis, axis, indexing="ij"))
        distance = x * x + z * z
        usable = distance <= (half * plan.spacing) ** 2
        for hx, hz in hero_xz:
            usable &= (x - hx) ** 2 + (z - hz) ** 2 > keep_out
        if np.count_nonzero(usable) >= plan.small:
            break
        half *= 2
    rows = np.flatnonzero(usable)
    nearest = rows[np.argsort(distance[rows], kind="stable")[: plan.small]]
    rng = np.random.default_rng([seed, 1])
    radii = rng.uniform(*plan.radius, size=plan.small)
    reach = plan.spacing / 2 - radii
    jitter = (rng.random((plan.small, 2)) * 2 - 1) * reach[:, None]
    kind = rng.choice(len(plan.mix), size=plan.small, p=np.array([p for _, p in plan.mix]))
    shade = rng.integers(0, COLORS_PER_KIND, size=plan.small)
    first = scene.material_index(f"{plan.mix[0][0]}_00")
    centers = np.column_stack([x[nearest] + jitter[:, 0], radii, z[nearest] + jitter[:, 1]])
    heroes = [((hx, HERO_RADIUS, hz), name) for (hx, hz), name in HEROES[: plan.heroes]]
    return (
        np.concatenate([np.reshape([c for c, _ in heroes], (-1, 3)), centers]).astype(np.float32),
        np.concatenate([[HERO_RADIUS] * plan.heroes, radii]).astype(np.float32),
        np.concatenate(
            [[scene.material_index(n) for _, n in heroes], first + kind * COLORS_PER_KIND + shade]
        ).astype(np.int32),
    )


FIELDS = [
    (1, 0, {}),
    (3, 0, {}),
    (60, 1, {}),
    (20_011, 2, {}),
    (5_000, 3, {"extent": 40.0}),  # spacing below 1, not a power of two: rounded distances
    (3_000, 6, {"radius": (0.3, 0.9)}),
    (2_000, 7, {"extent": 8.0}),
    (500, 4, {"heroes": False}),
    (700, 5, {"mix": {"glass": 2.0, "metal": 1.0}}),
]


def by_cell(centers: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """``centers`` and ``arrays`` reordered by position (x, then z): the field's spheres as a
    set, whatever order they are stored in."""
    order = np.lexsort((centers[:, 2], centers[:, 0]))
    return [centers[order], *(array[order] for array in arrays)]


def stored_order_keys(scene: Scene, plan, ring_cells: int) -> np.ndarray:
    """(k, 3) (ring, i, j) of the small spheres as stored: their cell (i, j), and the ring of
    squared distance its centre falls in, as the field's documentation defines rings."""
    small = scene.sphere_centers[plan.heroes :].astype(np.float64)
    i = np.floor(small[:, 0] / plan.spacing)
    j = np.floor(small[:, 2] / plan.spacing)
    x, z = (i + 0.5) * plan.spacing, (j + 0.5) * plan.spacing
    width = ring_cells * plan.spacing**2 / math.pi
    bounds = np.arange(int((x * x + z * z).max() / width) + 2) * width
    ring = np.searchsorted(bounds, x * x + z * z, side="right") - 1
    return np.column_stack([ring, i, j])


@pytest.mark.parametrize(("count", "seed", "arguments"), FIELDS)
def test_rings_make_the_meshgrid_field_bit_for_bit(count: int, seed: int, arguments) -> None:
    """The same spheres, bitwise, heroes first in the same order: both do the same float64
    operations on the same numbers (IEEE arithmetic and a correctly rounded sqrt, no libm
    transcendental), so every ISA gives the same bits. Only the storage order of the small
    spheres differs (ring by ring, row by row, for locality)."""
    scene = random_field(count, seed, **arguments)
    centers, radii, materials = meshgrid_field(count, seed, **arguments)
    heroes = plan_field(count, seed, **arguments).heroes
    np.testing.assert_array_equal(scene.sphere_centers[:heroes], centers[:heroes])
    stored = by_cell(scene.sphere_centers, scene.sphere_radii, scene.sphere_materials)
    for got, expected in zip(stored, by_cell(centers, radii, materials), strict=True):
        np.testing.assert_array_equal(got, expected)
    assert scene.sphere_centers.dtype == np.float32 and scene.sphere_materials.dtype == np.int32


@pytest.mark.parametrize(("ring_cells", "threads"), [(1, 1), (7, 3), (1000, 2), (1 << 22, 1)])
def test_rings_and_threads_change_only_the_storage_order(
    ring_cells: int, threads: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Rings of 1 to 4 million cells, made on 1 to 3 threads: the same spheres, bit for bit
    (each draws its numbers at its rank by distance, whatever ring or thread makes it), stored
    ring by ring and row by row within a ring."""
    plan = plan_field(30_000, 11, extent=90.0)
    reference = field_scene(plan)
    add_field_spheres(reference, plan)
    monkeypatch.setattr(random_field_module, "RING_CELLS", ring_cells)
    scene = field_scene(plan)
    add_field_spheres(scene, plan, threads=threads)
    stored = by_cell(scene.sphere_centers, scene.sphere_radii, scene.sphere_materials)
    expected = by_cell(reference.sphere_centers, reference.sphere_radii, reference.sphere_materials)
    for got, want in zip(stored, expected, strict=True):
        np.testing.assert_array_equal(got, want)
    keys = stored_order_keys(scene, plan, ring_cells)
    ascending = np.lexsort(keys.T[::-1])
    np.testing.assert_array_equal(ascending, np.arange(len(keys)))
    assert len(np.unique(keys, axis=0)) == len(keys)  # one sphere a cell


def test_stable_order_equals_one_stable_sort() -> None:
    """The two-pass sort of a ring's distances, on values with many exact ties (a grid's
    squared distances) and on values spread over the whole range."""
    rng = np.random.default_rng(5)
    cells = rng.integers(-300, 300, (2, 50_000)) + 0.5
    grid = (cells**2).sum(axis=0)
    for values, low, high in (
        (grid, grid.min(), grid.max() + 1),
        (rng.uniform(3.0, 4.0, 20_000), 3.0, 4.0),
        (np.full(100, 2.0), 2.0, 2.0 + 1e-9),
    ):
        np.testing.assert_array_equal(
            _stable_order(values, low, high), np.argsort(values, kind="stable")
        )


def test_a_huge_count_is_refused_before_anything_is_made() -> None:
    count = max(10**10, 10 * (available_memory() or 0) // SCENE_BYTES_PER_SPHERE)
    started = time.perf_counter()
    with pytest.raises(ValueError, match=r"count: .* spheres would need ~[\d.,]+ GB .* available"):
        random_field(count)
    assert time.perf_counter() - started < 1.0
