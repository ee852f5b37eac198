"""Affine placements: the one rule for a (4, 4) matrix that places geometry in the scene.

Scene files, ``Scene.add_mesh`` and the Embree layer all check a placement with
``affine_problem``, so a matrix one of them accepts, the others accept too.
"""

from __future__ import annotations

import numpy as np

# Embree traces an instance in float32 through the inverse of its linear part, whose relative
# error is about cond · eps32 (cond: largest over smallest singular value). Past cond = 1 / eps32
# the inverse has no correct digit left: the matrix is singular as far as float32 can tell. The
# test is relative, so a uniform scale of any size passes (0.01 on a glTF node already at 0.01
# is as well conditioned as the identity), and a flattening of 1e7 : 1 does not.
MAX_CONDITION = 1.0 / float(np.finfo(np.float32).eps)  # 8.4e6
FLOAT32_MAX = float(np.finfo(np.float32).max)


def affine_problem(values: object) -> str | None:
    """Why ``values`` cannot place geometry, or None if it can.

    A placement is a (4, 4) matrix of finite numbers with last row ``[0, 0, 0, 1]`` whose 3 × 3
    linear part, rounded to float32 as Embree stores it, can be inverted in float32 (condition
    number at most ``MAX_CONDITION``). The problem reads after a ``KEY: `` prefix ("must be
    invertible: ...").
    """
    try:
        matrix = np.asarray(values, np.float64)
    except (TypeError, ValueError):
        return "expected a 4x4 matrix of numbers"
    if matrix.shape != (4, 4):
        return f"expected a 4x4 matrix, got shape {matrix.shape}"
    if not np.isfinite(matrix).all():
        return "expected a 4x4 matrix of finite numbers, got NaN or inf"
    x, y, z, w = matrix[3].tolist()  # plain floats: a tenth of np.allclose's time
    if max(abs(x), abs(y), abs(z), abs(w - 1.0)) > 1e-8:
        return f"must be affine: last row [0, 0, 0, 1], got {matrix[3].tolist()}"
    if np.abs(matrix[:3, :3]).max() > FLOAT32_MAX:
        return (
            f"expected a 4x4 matrix of numbers float32 can hold, got one beyond {FLOAT32_MAX:.2g}"
        )
    return _conditioning_problem(matrix[None, :3, :3])[1]


def _conditioning_problem(linear: np.ndarray) -> tuple[int, str | None]:
    """The first of the (n, 3, 3) float64 linear parts ``linear`` that float32 cannot invert
    (condition number beyond ``MAX_CONDITION``, rounded to float32 as Embree stores it), and
    why: (row, problem), or (-1, None) when every one can."""
    linear = linear.astype(np.float32).astype(np.float64)  # what Embree stores
    # A cheap sufficient test first: sigma_max <= |M|_F and sigma_min >= |det| / |M|_F^2, so
    # cond <= |M|_F^3 / |det|. Rotations and moderate scales pass it; only the rest pay an SVD.
    frobenius = np.sqrt(np.einsum("nij,nij->n", linear, linear))
    (a, b, c), (d, e, f), (g, h, i) = linear.transpose(1, 2, 0)
    determinant = np.abs(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g))
    with np.errstate(over="ignore", invalid="ignore"):
        surely_fine = (determinant > 0.0) & (frobenius**3 <= MAX_CONDITION * determinant)
    for row in np.flatnonzero(~surely_fine):
        singular_values = np.linalg.svd(linear[row], compute_uv=False)  # descending
        largest, smallest = float(singular_values[0]), float(singular_values[-1])
        if not (largest > 0.0 and smallest * MAX_CONDITION >= largest):
            return int(row), (
                "must be invertible: its linear part is singular in float32 (singular values "
                f"{largest:.3g} to {smallest:.3g}, a ratio beyond {MAX_CONDITION:.2g})"
            )
    return -1, None


def affine_array_problem(values: np.ndarray) -> tuple[int, str] | None:
    """The first of (n, 4, 4) placements that cannot place geometry, by ``affine_problem``'s
    rule, as (row, problem), or None: the same rule on a million matrices in well under a
    second (one SVD only for matrices a cheap bound cannot clear)."""
    matrices = np.asarray(values)
    if matrices.ndim != 3 or matrices.shape[1:] != (4, 4):
        return -1, f"expected shape (n, 4, 4), got {matrices.shape}"
    if matrices.dtype.kind not in "fiu":
        return -1, f"expected numbers, got dtype {matrices.dtype}"
    matrices = np.asarray(matrices, np.float64)
    magnitude = np.abs(matrices).max(axis=(1, 2), initial=0.0)  # NaN where any is NaN
    last_row_error = np.abs(matrices[:, 3] - (0.0, 0.0, 0.0, 1.0)).max(axis=1, initial=0.0)
    bad = ~((magnitude <= FLOAT32_MAX) & (last_row_error <= 1e-8))
    if bad.any():  # the single-matrix rule words the problem
        row = int(np.flatnonzero(bad)[0])
        return row, str(affine_problem(matrices[row]))
    row, problem = _conditioning_problem(matrices[:, :3, :3])
    return None if problem is None else (row, problem)


def as_affine(values: object, name: str) -> np.ndarray:
    """``values`` as a (4, 4) float64 placement; raises ValueError ``"NAME: problem"`` when
    ``affine_problem`` finds one."""
    problem = affine_problem(values)
    if problem is not None:
        raise ValueError(f"{name}: {problem}")
    return np.asarray(values, np.float64)
