"""Materials: the Blinn-Phong + mirror + glass parameters of the seed article, and its presets."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from embree_rt.errors import FieldError, range_problem

RGB = tuple[float, float, float]


@dataclass(frozen=True)
class Material:
    """Surface response of an object.

    Shading adds ``ambient * color`` plus, per unoccluded point light, ``diffuse * max(0, N.L) *
    color`` and ``specular * max(0, N.H) ** shininess`` (white highlight). ``reflectivity`` blends
    a mirror bounce, tinted by ``color`` when ``metallic`` (as metals reflect); ``transparency`` > 0
    makes the surface glass with index ``ior``: its reflected and refracted weights are split by
    Schlick's Fresnel term, and what it transmits is tinted by ``color``.

    ``emission`` (linear RGB, any non-negative size) is light the surface gives off itself: it is
    added to what the hit returns (a glowing surface, not a light source: it lights nothing
    else). Glass absorbs along the path a ray travels inside it by Beer–Lambert's law: after a
    distance ``attenuation_distance`` what is left of white light is ``attenuation_color``
    (glTF's KHR_materials_volume; the default, an infinite distance, absorbs nothing).
    ``unlit`` surfaces show their colour as it is, with no lighting, shadow, reflection or
    transmission (glTF's KHR_materials_unlit).

    ``outline`` in [0, 1] (0, the default, draws none) blackens the rim of each sphere and tube
    where the surface turns away from the camera (fresnel's outline), as a share of its radius:
    a hit is on the outline when its projected distance from the silhouette is below
    ``outline · radius`` (``shading.on_outline``).
    """

    color: RGB = (0.8, 0.8, 0.8)
    ambient: float = 0.1
    diffuse: float = 0.85
    specular: float = 0.0
    shininess: float = 32.0
    reflectivity: float = 0.0
    transparency: float = 0.0
    ior: float = 1.0
    metallic: bool = False
    emission: RGB = (0.0, 0.0, 0.0)
    attenuation_color: RGB = (1.0, 1.0, 1.0)
    attenuation_distance: float = math.inf
    unlit: bool = False
    outline: float = 0.0

    def __post_init__(self) -> None:
        """The one place a material's ranges are checked (a scene file's reader reports these
        under its keys): raises ``FieldError`` naming the field."""
        if len(self.color) != 3 or any(float(c) < 0.0 for c in self.color):
            raise FieldError("color", f"expected three non-negative numbers, got {self.color!r}")
        for name in ("ambient", "diffuse", "specular", "reflectivity", "transparency", "outline"):
            if (problem := range_problem(float(getattr(self, name)), 0.0, 1.0)) is not None:
                raise FieldError(name, problem)
        if (problem := range_problem(self.shininess, 0.0, low_open=True)) is not None:
            raise FieldError("shininess", problem)
        if (problem := range_problem(self.ior, 1.0)) is not None:
            raise FieldError("ior", problem)
        for name in ("emission", "attenuation_color"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(float(c)) and float(c) >= 0 for c in value):
                raise FieldError(name, f"expected three finite numbers >= 0, got {value!r}")
            object.__setattr__(self, name, tuple(float(c) for c in value))
        if any(c > 1.0 for c in self.attenuation_color):
            raise FieldError(
                "attenuation_color", f"each must lie in [0, 1], got {list(self.attenuation_color)}"
            )
        problem = range_problem(self.attenuation_distance, 0.0, low_open=True)
        if problem is not None:
            raise FieldError("attenuation_distance", problem)
        object.__setattr__(self, "color", tuple(float(c) for c in self.color))

    @property
    def is_glass(self) -> bool:
        return self.transparency > 0.0

    @property
    def absorption(self) -> tuple[float, float, float]:
        """Beer–Lambert absorption coefficient per unit length, per channel: ``-ln(c) / d`` of
        ``attenuation_color`` c and ``attenuation_distance`` d (a black channel absorbs all)."""
        return tuple(
            math.inf if c == 0.0 else -math.log(c) / self.attenuation_distance
            for c in self.attenuation_color
        )


PRESETS: dict[str, Material] = {
    "matte": Material(diffuse=0.85, specular=0.0, shininess=8.0, reflectivity=0.0),
    "glossy": Material(diffuse=0.6, specular=0.5, shininess=64.0, reflectivity=0.05),
    "metal": Material(diffuse=0.3, specular=0.9, shininess=128.0, reflectivity=0.5, metallic=True),
    "mirror": Material(diffuse=0.05, specular=0.95, shininess=256.0, reflectivity=0.9),
    "glass": Material(
        color=(1.0, 1.0, 1.0),
        ambient=0.0,
        diffuse=0.05,
        specular=0.9,
        shininess=256.0,
        reflectivity=0.0,
        transparency=0.97,
        ior=1.52,
    ),
}


def preset(name: str, **overrides: object) -> Material:
    """The preset ``name`` with fields replaced, e.g. ``preset("metal", color=(1, 0, 0))``."""
    try:
        base = PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown material preset {name!r}; known: {', '.join(PRESETS)}") from None
    return replace(base, **overrides)


def shading_shares(
    ambient: np.ndarray, diffuse: np.ndarray, reflectivity: np.ndarray, transparency: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seed article's blend of local shading, mirror reflection and transmission, per
    material or per hit ((n,) float32 each): the (n,) float32 shares of ambient and diffuse
    light, ``ambient · local`` and ``diffuse · local`` with ``local = (1 − reflectivity)(1 −
    transparency)``, and the mirror's share ``reflectivity · (1 − transparency)``."""
    local = (1.0 - reflectivity) * (1.0 - transparency)
    return (
        (ambient * local).astype(np.float32),
        (diffuse * local).astype(np.float32),
        (reflectivity * (1.0 - transparency)).astype(np.float32),
    )


@dataclass(frozen=True)
class Checker:
    """A procedural checkerboard in the xz-plane: squares of side ``size`` alternate two colors
    (a scene holds them to its limits: ``scene.model.floor_problem``)."""

    color_a: RGB = (0.9, 0.9, 0.9)
    color_b: RGB = (0.15, 0.15, 0.15)
    size: float = 1.0


@dataclass
class MaterialColumns:
    """What shading reads of ``Material``, as arrays with one entry a material
    (``MaterialTable``) or a hit (``HitMaterials``): ``color``, ``emission`` and ``absorption``
    linear RGB (``Material.absorption``), the numbers ``ambient``, ``diffuse``, ``specular``,
    ``shininess``, ``reflectivity``, ``transparency``, ``ior`` and ``outline`` float32,
    ``metallic`` bool."""

    color: np.ndarray
    ambient: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    shininess: np.ndarray
    reflectivity: np.ndarray
    transparency: np.ndarray
    ior: np.ndarray
    metallic: np.ndarray
    emission: np.ndarray
    absorption: np.ndarray
    outline: np.ndarray


# The numbers every material and every hit has its own of: taken from the table alike.
_NUMBERS = ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior")


@dataclass
class MaterialTable(MaterialColumns):
    """Materials as arrays indexed by material id, so shading gathers per hit with one take.

    ``color``, ``emission`` and ``absorption`` (m, 3) float32; the numbers (m,) float32;
    ``metallic`` and ``unlit`` (m,) bool.
    """

    unlit: np.ndarray

    @classmethod
    def from_materials(cls, materials: list[Material]) -> MaterialTable:
        def column(name: str, dtype: type = np.float32) -> np.ndarray:
            return np.array([getattr(m, name) for m in materials], dtype)

        def rgb(name: str) -> np.ndarray:
            return column(name).reshape(-1, 3)

        return cls(
            color=rgb("color"),
            **{name: column(name) for name in _NUMBERS},
            metallic=column("metallic", bool),
            emission=rgb("emission"),
            absorption=rgb("absorption"),
            outline=column("outline"),
            unlit=column("unlit", bool),
        )

    @property
    def glows(self) -> bool:
        """Whether any material gives off light of its own (``emission``)."""
        return bool(self.emission.any())

    @property
    def outlined(self) -> bool:
        """Whether any material draws an outline."""
        return bool(self.outline.any())


@dataclass
class HitMaterials(MaterialColumns):
    """The material of each of k hits, one column per hit, made once per bounce
    (``HitMaterials.gather``, then what the hits show of their own written over it: a mesh's
    textures and colours, the floor's checker): what every shading stage reads.

    ``color`` (3, k) float32 linear surface colour; ``ambient``, ``diffuse``, ``specular``,
    ``shininess``, ``reflectivity``, ``transparency``, ``ior`` (k,) float32 and ``metallic``,
    ``lit`` (k,) bool, as ``Material`` has them (``lit``: not ``unlit``; an unlit hit's
    specular and transparency are zero: it shows its colour alone); ``emission`` and
    ``absorption`` (3, k) float32 (``Material.absorption``); ``occlusion`` (k,) float32 the
    share of ambient light that reaches each point (glTF occlusion maps) and ``coverage`` (k,)
    float32 the share of each ray a see-through surface stops (glTF BLEND alpha); ``outline``
    (k,) float32 ``Material.outline``. Columns the
    same for every hit (no material glows, none absorbs, no map occludes, every surface is
    opaque) are zero-stride views of that value: read like any other, written over only after
    ``np.array`` (the ``HitLooks`` that vary them make them so)."""

    lit: np.ndarray
    occlusion: np.ndarray
    coverage: np.ndarray

    def __len__(self) -> int:
        return len(self.ambient)

    @classmethod
    def gather(
        cls, table: MaterialTable, material: np.ndarray, color_from: int = 0
    ) -> HitMaterials:
        """The columns of k hits on the materials ``material`` (k,) intp of ``table``; the
        colour of the columns before ``color_from`` is left unset (the caller's: the floor's
        checker)."""
        k = len(material)
        color = np.empty((3, k), np.float32)
        # gathered straight into place (mode "clip": an ``out`` is not copied first, and the
        # ids are all in range)
        own = material[color_from:]
        for row, values in zip(color, table.color.T, strict=True):
            np.take(values, own, out=row[color_from:], mode="clip")

        def vectors(values: np.ndarray, any_nonzero: bool) -> np.ndarray:
            if any_nonzero:
                return np.take(np.ascontiguousarray(values.T), material, axis=1)
            return np.broadcast_to(np.float32(0.0), (3, k))

        lit = ~np.take(table.unlit, material)
        hits = cls(
            color=color,
            **{name: np.take(getattr(table, name), material) for name in _NUMBERS},
            metallic=np.take(table.metallic, material),
            lit=lit,
            emission=vectors(table.emission, table.glows),
            absorption=vectors(table.absorption, bool((table.absorption > 0).any())),
            occlusion=np.broadcast_to(np.float32(1.0), (k,)),
            coverage=np.broadcast_to(np.float32(1.0), (k,)),
            outline=(
                np.take(table.outline, material)
                if table.outlined
                else np.broadcast_to(np.float32(0.0), (k,))
            ),
        )
        if table.unlit.any():
            hits.specular[~lit] = 0.0
            hits.transparency[~lit] = 0.0
        return hits

    def vary(self, rows: np.ndarray, values: object) -> None:
        """Write the columns of the dataclass ``values`` (fields named as these columns, each
        (j,)) at the hits ``rows`` (j,) int64."""
        for item in fields(values):
            getattr(self, item.name)[rows] = getattr(values, item.name)

    def shares(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k,) float32 each: the hits' shares of ambient light, of diffuse light and of the
        mirror (``shading_shares``); an unlit hit shows its colour whole, as ambient light,
        and nothing else."""
        ambient, diffuse, reflect = shading_shares(
            self.ambient, self.diffuse, self.reflectivity, self.transparency
        )
        unlit = np.flatnonzero(~self.lit)
        if len(unlit):
            ambient[unlit] = 1.0
            diffuse[unlit] = 0.0
            reflect[unlit] = 0.0
        return ambient, diffuse, reflect
