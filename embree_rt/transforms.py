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
    linear = matrix[:3, :3].astype(np.float32)  # what Embree stores
    singular_values = np.linalg.svd(linear.astype(np.float64), compute_uv=False)  # descending
    largest, smallest = float(singular_values[0]), float(singular_values[-1])
    if not (largest > 0.0 and smallest * MAX_CONDITION >= largest):
        return (
            "must be invertible: its linear part is singular in float32 (singular values "
            f"{largest:.3g} to {smallest:.3g}, a ratio beyond {MAX_CONDITION:.2g})"
        )
    return None


def as_affine(values: object, name: str) -> np.ndarray:
    """``values`` as a (4, 4) float64 placement; raises ValueError ``"NAME: problem"`` when
    ``affine_problem`` finds one."""
    problem = affine_problem(values)
    if problem is not None:
        raise ValueError(f"{name}: {problem}")
    return np.asarray(values, np.float64)
