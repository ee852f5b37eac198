"""Float comparisons that hold on every x86-64 machine: tolerances scaled to the geometry.

Embree picks SSE4.2, AVX2 or AVX-512 kernels for the CPU it runs on, and NumPy dispatches its
float32 ``exp``, ``log`` and ``power`` the same way; their results differ in the last bits from one
ISA to another. A float32 result computed from coordinates of size S is uncertain by a few ulps
of S whatever its own size: a hit at t = 8e-4 on a ray starting 7 units from the origin is known
to ~5e-7, not to 1e-5 of itself. So a tolerance here is an absolute part in ulps of the largest
coordinate involved (``position_atol``) plus a relative part of a few float32 epsilons
(``RTOL32``), never a bare relative tolerance on a value that may be near zero.

Imported by the tests as a plain module (pytest puts ``tests/`` on ``sys.path``).
"""

from __future__ import annotations

import numpy as np

EPS32 = float(np.finfo(np.float32).eps)  # 1.19e-7: the float32 spacing at 1
# How many ulps of the coordinates two float32 computations of one hit may differ by, per unit
# of 1 / cos(incidence). Measured on this project's rays: Embree's SSE4.2, AVX and AVX2 kernels,
# and its packet and single-ray paths, gave hit distances up to 10.7 ulps / cos apart (94 ulps
# on a ray meeting a triangle at cos = 0.003). 16 covers that with room and stays far below
# the error of any wrong formula.
ULPS = 16
RTOL32 = ULPS * EPS32  # 1.9e-6
# Below this |cos(incidence)| the tolerance stops growing: a ray that close to grazing is
# decided by rounding (tests leave such rays out as ambiguous, or accept either answer).
MIN_COSINE = 1e-3


def ulp32(values: object) -> np.ndarray:
    """The float32 spacing at ``|values|``, elementwise, as float64 (same shape as ``values``)."""
    return np.spacing(np.abs(np.asarray(values, np.float32))).astype(np.float64)


def coordinate_scale(*arrays: object) -> float:
    """The largest finite ``|x|`` over all ``arrays`` (numbers or arrays of any shape); 1 if none
    is larger, so a scene near the origin still gets the float32 spacing at 1."""
    largest = 1.0
    for values in arrays:
        values = np.abs(np.asarray(values, np.float64))
        values = values[np.isfinite(values)]
        if values.size:
            largest = max(largest, float(values.max()))
    return largest


def position_atol(*coordinates: object, ulps: float = ULPS) -> float:
    """Absolute tolerance on a point, distance or vector computed in float32 from
    ``coordinates``: ``ulps`` float32 ulps of the largest of them."""
    return ulps * float(ulp32(coordinate_scale(*coordinates)))


def ray_t_atol(
    origins: np.ndarray,
    directions: np.ndarray,
    scene_scale: float | np.ndarray,
    *,
    normals: np.ndarray | None = None,
    ulps: float = ULPS,
) -> np.ndarray:
    """(n,) float64 absolute tolerance on the hit distances t of n rays.

    ``origins``, ``directions`` (n, 3); ``scene_scale``: the largest ``|coordinate|`` of what the
    rays may hit, one number or (n,) (see ``coordinate_scale``). The hit point is uncertain by
    ``ulps`` ulps of the larger of that and the ray's origin; along the ray, by that over
    ``|cos|`` of the angle between the ray and the surface ``normals`` (n, 3) when given (any
    length; see ``incidence_cosine``); and t, in units of the direction's length, by that over
    ``|d|``.
    """
    origins = np.asarray(origins, np.float64)
    directions = np.asarray(directions, np.float64)
    scale = np.maximum(np.abs(origins).max(axis=1, initial=0.0), scene_scale)
    atol = ulps * ulp32(scale) / np.linalg.norm(directions, axis=1)
    if normals is not None:
        atol /= incidence_cosine(directions, normals)
    return atol


def incidence_cosine(directions: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(n,) float64 ``|cos|`` of the angle between rays and surfaces, at least ``MIN_COSINE``
    (also where a normal is zero or not finite). ``directions``, ``normals`` (n, 3), any
    lengths."""
    d = np.asarray(directions, np.float64)
    n = np.asarray(normals, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = np.abs(np.einsum("ij,ij->i", d, n)) / (
            np.linalg.norm(d, axis=1) * np.linalg.norm(n, axis=1)
        )
    return np.maximum(np.nan_to_num(cosine, nan=0.0), MIN_COSINE)


def assert_close(actual, expected, *, atol, rtol: float = RTOL32, err_msg: str = "") -> None:
    """Assert ``|actual - expected| <= atol + rtol |expected|`` elementwise.

    ``atol`` is a number or an array broadcasting to the values (one tolerance per ray); equal
    infinities pass. The message names the worst element in units of its tolerance.
    """
    actual = np.asarray(actual, np.float64)
    expected = np.asarray(expected, np.float64)
    actual, expected = np.broadcast_arrays(actual, expected)
    allowed = np.broadcast_to(np.asarray(atol, np.float64) + rtol * np.abs(expected), actual.shape)
    same_infinity = np.isinf(expected) & (actual == expected)
    with np.errstate(invalid="ignore"):
        error = np.where(same_infinity, 0.0, np.abs(actual - expected))
    bad = ~(error <= allowed)  # NaN fails
    if bad.any():
        with np.errstate(divide="ignore", invalid="ignore"):
            excess = np.where(bad, np.nan_to_num(error / allowed, nan=np.inf), 0.0)
        worst = np.unravel_index(int(np.argmax(excess)), bad.shape)
        raise AssertionError(
            f"{err_msg + ': ' if err_msg else ''}{int(bad.sum())} of {bad.size} values differ; "
            f"worst at {tuple(int(i) for i in worst)}: {actual[worst]!r} vs {expected[worst]!r}, "
            f"error {error[worst]:.3g} > allowed {allowed[worst]:.3g}"
        )


def assert_vectors_close(
    actual, expected, *, atol, rtol: float = RTOL32, err_msg: str = ""
) -> None:
    """Assert ``|a - e| <= atol + rtol |e|`` for the rows of (n, 3) ``actual`` and ``expected``.

    Vector lengths, not components: a component near zero of a long vector is only known to the
    vector's own precision, which componentwise relative tolerances would ignore.
    """
    actual = np.asarray(actual, np.float64)
    expected = np.asarray(expected, np.float64)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    assert_close(
        np.linalg.norm(actual - expected, axis=-1),
        np.zeros(actual.shape[:-1]),
        atol=np.asarray(atol, np.float64) + rtol * np.linalg.norm(expected, axis=-1),
        rtol=0.0,
        err_msg=err_msg,
    )
