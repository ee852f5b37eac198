"""What each particle is drawn with: a colour (8-bit sRGB, 3 bytes a particle) and a radius,
by element (Jmol colours, van der Waals radii: ASE's tables), by type (matplotlib's tab10),
by a property through a matplotlib colormap, or one for all."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from embree_rt.scene.errors import warn_input
from embree_rt.scene.particles.errors import ParticleFileError
from embree_rt.scene.particles.frame import ParticleFrame

# A particle whose element is unknown, and a type's radius when nothing else gives one (LAMMPS'
# reduced units: particles of diameter 1).
UNKNOWN_COLOR = (0.75, 0.4, 0.75)
UNKNOWN_ELEMENT_RADIUS = 1.5
TYPE_RADIUS = 0.5
TYPE_PALETTE = "tab10"
# matplotlib's tab10 (Tableau's ten category colours) as its 8-bit sRGB codes: matplotlib holds
# them as code / 255, so these give its float64 values bit for bit without importing
# matplotlib (0.1-0.2 s) for a render coloured by type (tests/test_particles.py compares them).
TAB10_SRGB8 = (
    (0x1F, 0x77, 0xB4),
    (0xFF, 0x7F, 0x0E),
    (0x2C, 0xA0, 0x2C),
    (0xD6, 0x27, 0x28),
    (0x94, 0x67, 0xBD),
    (0x8C, 0x56, 0x4B),
    (0xE3, 0x77, 0xC2),
    (0x7F, 0x7F, 0x7F),
    (0xBC, 0xBD, 0x22),
    (0x17, 0xBE, 0xCF),
)


@dataclass(frozen=True)
class ParticleLook:
    """How particles are coloured and sized.

    ``color_by``: "element", "type", a property's name, or None for the default (element where
    the file names elements, else type); ``color``: one sRGB colour (0..1) for all, overriding
    ``color_by``; ``colormap`` and ``value_range`` (low, high; None: the frame's own) for a
    property; ``radius`` one radius for all (else the file's radius column, else by element or
    type), times ``radius_scale``; ``color_columns`` names the red, green and blue columns
    (or one (n, 3) array, read as its ``_x _y _z`` columns) that give each particle its own
    sRGB colour, overriding ``color_by``."""

    color_by: str | None = None
    color: tuple[float, float, float] | None = None
    colormap: str = "viridis"
    value_range: tuple[float, float] | None = None
    radius: float | None = None
    radius_scale: float = 1.0
    color_columns: tuple[str, ...] | None = None


def to_srgb8(colors: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 of (n, 3) sRGB values in 0..1."""
    return np.clip(np.rint(np.asarray(colors, np.float64) * 255.0), 0, 255).astype(np.uint8)


def natural_order(labels: np.ndarray) -> np.ndarray:
    """The distinct ``labels`` (n,) str, numbers in numeric order ("2" before "10")."""
    names = np.unique(labels)
    return np.array(sorted(names, key=lambda s: (0, int(s), "") if s.isdigit() else (1, 0, s)))


def element_table(symbols: np.ndarray, path: str) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) sRGB colours and (k,) radii of the distinct ``symbols`` (k,) str: Jmol's colours
    and the van der Waals radii (covalent where ASE has no van der Waals), from ASE; an unknown
    symbol takes ``UNKNOWN_COLOR`` and ``UNKNOWN_ELEMENT_RADIUS``, said in one warning."""
    from ase.data import atomic_numbers, covalent_radii, vdw_radii
    from ase.data.colors import jmol_colors

    colors = np.empty((len(symbols), 3))
    radii = np.empty(len(symbols))
    unknown = []
    for i, symbol in enumerate(symbols):
        number = atomic_numbers.get(symbol.capitalize())
        if number is None:
            unknown.append(symbol)
            colors[i], radii[i] = UNKNOWN_COLOR, UNKNOWN_ELEMENT_RADIUS
            continue
        colors[i] = jmol_colors[number]
        radius = vdw_radii[number]
        radii[i] = radius if np.isfinite(radius) else covalent_radii[number]
    if unknown:
        warn_input(
            f"{path}: unknown element(s) {', '.join(map(repr, unknown))}: drawn in the default "
            f"colour {UNKNOWN_COLOR} with radius {UNKNOWN_ELEMENT_RADIUS}"
        )
    return colors, radii


def particle_look(frame: ParticleFrame, look: ParticleLook) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) uint8 sRGB colours and (n,) float64 radii of ``frame``'s particles by ``look``.
    Raises ``ParticleFileError`` for a property or label the file does not have."""
    kind, labels = frame.labels()
    label_colors, radii = label_look(frame.path, kind, labels)
    if frame.radii is not None:
        radii = frame.radii
    if look.radius is not None:
        radii = np.full(len(frame), float(look.radius))
    radii = np.asarray(radii, np.float64) * look.radius_scale
    by = look.color_by or kind
    if look.color_columns:
        if look.color is not None or look.color_by is not None:
            raise ParticleFileError(
                frame.path, "--color-columns", "give it or --color / --color-by, not both"
            )
        colors = rgb_colors(frame, look.color_columns)
    elif look.color is not None:
        colors = np.broadcast_to(to_srgb8(np.asarray(look.color)[None]), (len(frame), 3)).copy()
    elif by == kind:
        colors = to_srgb8(label_colors)
    elif by in ("element", "type"):
        values = frame.elements if by == "element" else frame.types
        if values is None:
            raise ParticleFileError(frame.path, "--color-by", f"the file names no {by}s")
        colors = to_srgb8(label_look(frame.path, by, values)[0])
    elif by in frame.properties:
        colors = colormap_colors(frame.properties[by], look.colormap, look.value_range)
    else:
        known = ", ".join(["element", "type", *frame.properties])
        raise ParticleFileError(
            frame.path, "--color-by", f"no property {by!r} in the file (it has: {known})"
        )
    return colors, radii


def rgb_colors(frame: ParticleFrame, names: tuple[str, ...]) -> np.ndarray:
    """(n, 3) uint8 sRGB from the frame's three ``names`` columns (red, green, blue), or from
    one name's ``_x _y _z`` columns (an extended XYZ ``color`` array). The data say their
    range: all values within 0..1 are fractions, else 0..255 (``ParticleFileError`` beyond,
    below 0, or not finite)."""
    if len(names) == 1:
        names = tuple(f"{names[0]}_{axis}" for axis in "xyz")
    if len(names) != 3:
        raise ParticleFileError(frame.path, "--color-columns", "expected 3 column names, or 1")
    missing = [name for name in names if name not in frame.properties]
    if missing:
        known = ", ".join(frame.properties) or "none"
        raise ParticleFileError(
            frame.path, "--color-columns", f"no column {missing[0]!r} in the file (it has: {known})"
        )
    values = np.stack([frame.properties[name] for name in names], axis=1)
    bad = ~(np.isfinite(values) & (values >= 0) & (values <= 255)).all(axis=1)
    if bad.any():
        row = int(np.argmax(bad))
        raise ParticleFileError(
            frame.path,
            "--color-columns",
            f"particle {row}: colour {values[row].tolist()} is not within 0..1 or 0..255",
        )
    if values.max(initial=0.0) <= 1.0:
        return to_srgb8(values)
    return np.rint(values).astype(np.uint8)


def label_look(path: str, kind: str, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float64 sRGB colours and (n,) float64 radii of (n,) ``labels`` of ``kind``
    ("element": ``element_table``; "type": tab10 in the types' natural order, ``TYPE_RADIUS``)."""
    names, inverse = np.unique(labels, return_inverse=True)
    if kind == "element":
        colors, radii = element_table(names, path)
    else:
        position = {name: i for i, name in enumerate(natural_order(labels))}
        colors = _palette(len(position))[[position[name] for name in names]]
        radii = np.full(len(names), TYPE_RADIUS)
    return colors[inverse], radii[inverse]


def _palette(count: int) -> np.ndarray:
    base = np.asarray(TAB10_SRGB8, np.float64) / 255.0
    return base[np.arange(count) % len(base)]


def colormap_colors(
    values: np.ndarray, colormap: str, value_range: tuple[float, float] | None
) -> np.ndarray:
    """(n, 3) uint8 sRGB of (n,) ``values`` through matplotlib's ``colormap``, ``value_range``
    (low, high) mapped to its ends (None: the values' own finite range)."""
    import matplotlib

    try:
        cmap = matplotlib.colormaps[colormap]
    except KeyError:
        raise ValueError(f"--colormap: unknown colormap {colormap!r}") from None
    values = np.asarray(values, np.float64)
    low, high = colormap_range(values, value_range)
    span = high - low
    scaled = (values - low) / span if span > 0 else np.full(len(values), 0.5)
    return to_srgb8(cmap(np.clip(scaled, 0.0, 1.0))[:, :3])


def colormap_range(
    values: np.ndarray, value_range: tuple[float, float] | None
) -> tuple[float, float]:
    """(low, high) a colormap spans over (n,) float64 ``values``: ``value_range``, else the
    values' own finite range (0, 1 when none is finite)."""
    if value_range is not None:
        return float(value_range[0]), float(value_range[1])
    finite = values[np.isfinite(values)]
    return (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
