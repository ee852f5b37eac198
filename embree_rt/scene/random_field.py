"""The seed article's random sphere field, scaled from dozens to millions of spheres.

Small spheres sit one per unit cell of a grid on the floor, jittered inside their cells (so they
never overlap), filling cells nearest the centre first: the field is a disc that grows with the
count at constant density, and at a million spheres it reaches the horizon. Three hero spheres
(glass, gold metal, mirror) stand in the middle.
"""

from __future__ import annotations

import math

import numpy as np

from embree_rt.materials import preset
from embree_rt.scene.model import Camera, PointLight, RenderSettings, Scene

HEROES = (
    # center, radius, material name
    ((0.0, 1.0, 0.0), 1.0, "hero_glass"),
    ((-4.0, 1.0, 0.0), 1.0, "hero_gold"),
    ((4.0, 1.0, 0.0), 1.0, "hero_mirror"),
)
# Kind of each small sphere: (preset, probability).
KINDS = (("matte", 0.5), ("glossy", 0.2), ("metal", 0.15), ("mirror", 0.05), ("glass", 0.1))
COLORS_PER_KIND = 16
RADIUS_RANGE = (0.12, 0.22)


def _palette(rng: np.random.Generator) -> list[tuple[str, str, tuple[float, float, float]]]:
    """(name, preset, color) for every small-sphere material: 16 colors per kind."""
    entries = []
    for kind, _ in KINDS:
        for k in range(COLORS_PER_KIND):
            if kind == "glass":
                color = 0.6 + 0.4 * rng.random(3)
            elif kind in ("metal", "mirror"):
                color = 0.5 + 0.5 * rng.random(3)
            else:
                color = rng.random(3) * rng.random(3)  # the article's product: deep colors
            entries.append((f"{kind}_{k:02d}", kind, tuple(float(c) for c in color)))
    return entries


def _cells_nearest_first(needed: int) -> np.ndarray:
    """(needed, 2) int64 grid cells (x, z) ordered by distance from the origin."""
    half = math.ceil(math.sqrt(needed / math.pi)) + 3
    while True:
        axis = np.arange(-half, half + 1)
        gx, gz = np.meshgrid(axis, axis, indexing="ij")
        cells = np.stack([gx.ravel(), gz.ravel()], axis=1)
        distance = (cells[:, 0] + 0.5) ** 2 + (cells[:, 1] + 0.5) ** 2
        inside = distance <= half**2
        if inside.sum() >= needed:
            cells, distance = cells[inside], distance[inside]
            order = np.argsort(distance, kind="stable")
            return cells[order[:needed]]
        half *= 2


def random_field(count: int, seed: int = 0, heroes: bool = True) -> Scene:
    """A random sphere field of ``count`` spheres in all (three heroes among them when
    ``heroes`` and ``count`` >= 3), deterministic for a given seed."""
    if isinstance(count, bool) or int(count) != count or count < 1:
        raise ValueError(f"count: must be a positive integer, got {count!r}")
    count = int(count)
    rng = np.random.default_rng(seed)
    scene = Scene(
        camera=Camera(position=(12.0, 2.4, 7.0), look_at=(0.0, 0.8, 0.0), fov=26.0),
        lights=[
            PointLight(position=(10.0, 20.0, 10.0), intensity=0.9),
            PointLight(position=(-12.0, 14.0, 4.0), intensity=0.35),
        ],
        render=RenderSettings(width=960, height=540, spp=8, max_depth=6, seed=seed),
    )
    scene.add_material("hero_glass", preset("glass"))
    scene.add_material("hero_gold", preset("metal", color=(0.95, 0.75, 0.35)))
    scene.add_material("hero_mirror", preset("mirror", color=(0.95, 0.95, 0.95)))
    for name, kind, color in _palette(rng):
        scene.add_material(name, preset(kind, color=color))

    hero_count = 3 if heroes and count >= 3 else 0
    for center, radius, material in HEROES[:hero_count]:
        scene.add_sphere(center, radius, material)
    small = count - hero_count
    if small == 0:
        return scene

    # Reserve extra cells for the ones the heroes occupy, then drop those.
    cells = _cells_nearest_first(small + (40 if hero_count else 0))
    centers_xz = cells + 0.5
    if hero_count:
        hero_xz = np.array([[c[0], c[2]] for c, _, _ in HEROES])
        gap = np.linalg.norm(centers_xz[:, None, :] - hero_xz[None], axis=2).min(axis=1)
        centers_xz = centers_xz[gap > 1.9]
    centers_xz = centers_xz[:small]
    radii = rng.uniform(*RADIUS_RANGE, size=small)
    jitter = (rng.random((small, 2)) - 0.5) * 2 * (0.5 - radii[:, None])
    xz = centers_xz + jitter
    centers = np.column_stack([xz[:, 0], radii, xz[:, 1]]).astype(np.float32)

    probabilities = np.array([p for _, p in KINDS])
    kind = rng.choice(len(KINDS), size=small, p=probabilities / probabilities.sum())
    shade = rng.integers(0, COLORS_PER_KIND, size=small)
    first_palette_index = scene.material_index(f"{KINDS[0][0]}_00")
    materials = first_palette_index + kind * COLORS_PER_KIND + shade
    scene.add_spheres(centers, radii.astype(np.float32), materials.astype(np.int32))
    return scene
