"""How large and how small a scene's numbers may be: what float32 geometry and shading carry.

A float64 number can be finite and still beyond float32 (1e39), or round to zero in it (a radius
of 1e-320), and Embree and the shading compute in float32 (largest 3.4e38, smallest normal
1.2e-38). Scene files, sphere arrays, mesh files and ``Scene.add_spheres`` / ``add_mesh`` /
``add_instances`` are held to these limits where their values enter, so nothing past them reaches
a kernel: no overflow to inf, no inf · 0 = NaN in an image.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np

from embree_rt.errors import range_problem

# Every coordinate (a position, a centre, a placed mesh's vertex, a radius) within 1e10 of the
# origin, and, so that one rule covers a file, every other number too (no ior, shininess,
# angle or weight needs more). Why 1e10: Embree's ray-triangle test takes a triple product of
# coordinate differences (the distance along the ray is (v0 - o) · (e1 × e2) over a
# determinant), each up to 2·√3·1e10 ≈ 3.5e10, so at most ~4e31, a factor of 1e7 under
# float32's largest; the sphere test only squares them (~1e21). Ten million kilometres in
# metres: no scene float32 can draw with any precision is cut off.
COORDINATE_LIMIT = 1e10
# Lengths that divide or are squared (a sphere's radius, the checker's square) at least 1e-18:
# a squared radius stays a normal float32 (1e-36 > 1.2e-38), never zero.
MIN_LENGTH = 1e-18
# Colours (of materials, lights, floor squares, the sky) and light intensities at most 1e6 a
# component: a shading term multiplies three of them (material colour × light colour ×
# intensity ≤ 1e18), which leaves float32 a factor of 1e20 for the sums over lights, bounces and
# samples before anything could overflow.
RADIANCE_LIMIT = 1e6
# Counts, sizes, depths and sample numbers are int64 in the renderer's arrays.
INTEGER_LIMIT = 2**63 - 1
# Seeds are hashed as uint64 (``sampling``): a larger one would alias a smaller one silently.
SEED_LIMIT = 2**64 - 1


def shown(value: object) -> str:
    """``value``'s repr, cut to 40 characters: how a message quotes what it refuses."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def number_problem(
    value: object, low: float | None = None, high: float | None = None, **open_bounds: bool
) -> str | None:
    """What keeps ``value`` from being a number of a scene, or None: not a real number, not
    finite, beyond ``COORDINATE_LIMIT`` (every number of a scene lies within it), or out of
    [``low``, ``high``] (``errors.range_problem``, which ``open_bounds``, ``low_open`` and
    ``high_open``, are passed to)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        return f"expected a number, got {shown(value)}"
    if not isinstance(value, numbers.Integral) and not math.isfinite(value):
        return f"must be finite, got {value}"
    if not -COORDINATE_LIMIT <= value <= COORDINATE_LIMIT:  # exact for an int of any size
        return f"must lie within ±{COORDINATE_LIMIT:g} (float32's reach), got {shown(value)}"
    return range_problem(value, low, high, **open_bounds)


def vector_problem(
    value: object, *, non_negative: bool = False, high: float | None = None
) -> str | None:
    """What keeps ``value`` from being three numbers of a scene (``number_problem``), each not
    negative if ``non_negative`` and at most ``high`` if given, or None."""
    if (
        isinstance(value, str | bytes)
        or not isinstance(value, Sequence | np.ndarray)
        or (isinstance(value, np.ndarray) and value.ndim != 1)
        or len(value) != 3
    ):
        return f"expected a list of three numbers, got {shown(value)}"
    for item in value:
        if isinstance(item, bool | np.bool_) or not isinstance(item, numbers.Real):
            return f"expected numbers, got {shown(item)}"
        if (problem := number_problem(item)) is not None:
            return problem
        if non_negative and item < 0:
            return f"must not be negative, got {float(item)}"
        if high is not None and item > high:
            return f"must be <= {high:g} a component, got {item:g}"
    return None


def color_problem(value: object) -> str | None:
    """What keeps ``value`` from being a colour of a scene (linear RGB, three numbers from 0 to
    ``RADIANCE_LIMIT``), or None."""
    return vector_problem(value, non_negative=True, high=RADIANCE_LIMIT)


def spheres_problem(centers: np.ndarray, radii: np.ndarray) -> str | None:
    """What is wrong with (n, 3) ``centers`` and (n,) ``radii`` (any real dtype), naming the
    first bad row, or None: a centre must be finite and within ``COORDINATE_LIMIT``, a radius in
    [``MIN_LENGTH``, ``COORDINATE_LIMIT``]. Two passes of min/max, no copy, when all is well."""
    if len(radii) == 0:
        return None
    # NaN fails every comparison, so it is caught as out of range.
    if not (centers.min() >= -COORDINATE_LIMIT and centers.max() <= COORDINATE_LIMIT):
        with np.errstate(invalid="ignore"):
            inside = (centers >= -COORDINATE_LIMIT) & (centers <= COORDINATE_LIMIT)
        row = int(np.flatnonzero(~inside.all(axis=1))[0])
        return (
            f"centers row {row} must be finite and within ±{COORDINATE_LIMIT:g}, "
            f"got {centers[row].tolist()}"
        )
    if not (radii.min() >= MIN_LENGTH and radii.max() <= COORDINATE_LIMIT):
        with np.errstate(invalid="ignore"):
            inside = (radii >= MIN_LENGTH) & (radii <= COORDINATE_LIMIT)
        row = int(np.flatnonzero(~inside)[0])
        return (
            f"radii row {row} must be a finite number in [{MIN_LENGTH:g}, "
            f"{COORDINATE_LIMIT:g}], got {radii[row]}"
        )
    return None


def placed_reach(vertices: np.ndarray, transforms: np.ndarray) -> np.ndarray:
    """(m,) float64: how far from the origin (largest |coordinate|) the bounding box of
    (n, 3) ``vertices`` reaches, placed by each of the (m, 4, 4) affine ``transforms``; an
    upper bound of the placed vertices' reach (exact for a box aligned with the axes)."""
    vertices = np.asarray(vertices, np.float64)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    center, half = (low + high) / 2.0, (high - low) / 2.0
    transforms = np.asarray(transforms, np.float64)
    linear = transforms[:, :3, :3]
    with np.errstate(over="ignore", invalid="ignore"):
        placed_center = linear @ center + transforms[:, :3, 3]
        placed_half = np.abs(linear) @ half
        reach = (np.abs(placed_center) + placed_half).max(axis=1)
    return np.where(np.isnan(reach), np.inf, reach)


def placed_mesh_problem(vertices: np.ndarray, transforms: np.ndarray) -> tuple[int, str] | None:
    """The first of the (m, 4, 4) ``transforms`` that places (n, 3) ``vertices`` beyond
    ``COORDINATE_LIMIT``, as (row, problem), or None (``placed_reach``'s bound)."""
    if len(vertices) == 0:
        return None
    reach = placed_reach(vertices, transforms)
    beyond = np.flatnonzero(~(reach <= COORDINATE_LIMIT))
    if len(beyond) == 0:
        return None
    row = int(beyond[0])
    return row, (
        f"places the mesh {reach[row]:.3g} from the origin, beyond the ±{COORDINATE_LIMIT:g} "
        "float32 geometry carries"
    )
