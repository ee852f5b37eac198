"""The one rule for a placement matrix (embree_rt/transforms.py): finite, affine, and invertible
in float32, judged by conditioning, not by the size of the determinant."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from embree_rt.embree import BVH
from embree_rt.transforms import MAX_CONDITION, affine_problem, as_affine


def scaled(*factors: float) -> np.ndarray:
    """(4, 4) placement: scale by ``factors`` (one or three), then rotate, then move."""
    rotation = trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 3.0])
    matrix = rotation @ np.diag([*np.broadcast_to(factors, 3), 1.0])
    matrix[:3, 3] = [5.0, -2.0, 1.0]
    return matrix


@pytest.mark.parametrize("factor", [1e-6, 1e-4, 0.01, 1.0, 1e4, 1e6])
def test_a_uniform_scale_of_any_size_is_a_placement(factor: float) -> None:
    # det = factor³ reaches 1e-18: an absolute determinant test would call most of these singular
    assert affine_problem(scaled(factor)) is None
    np.testing.assert_array_equal(as_affine(scaled(factor), "transform"), scaled(factor))


def test_conditioning_decides_singularity() -> None:
    assert affine_problem(scaled(1.0, 1.0, 2.0 / MAX_CONDITION)) is None
    for flat in (0.5 / MAX_CONDITION, 1e-12, 0.0):
        problem = affine_problem(scaled(1.0, 1.0, flat))
        assert problem is not None and problem.startswith("must be invertible")
    # the same ratio at any overall size
    assert affine_problem(scaled(1e-3, 1e-3, 1e-3 * 0.5 / MAX_CONDITION)) is not None
    assert affine_problem(np.diag([1e-300, 1e-300, 1e-300, 1.0])) is not None  # 0 in float32


@pytest.mark.parametrize(
    "matrix, fragment",
    [
        (np.eye(3), "4x4"),
        ("identity", "4x4 matrix of numbers"),
        (np.diag([1.0, np.nan, 1.0, 1.0]), "finite"),
        (np.diag([1e39, 1.0, 1.0, 1.0]), "float32"),
        (np.r_[np.eye(4)[:3], [[0.5, 0, 0, 1]]], "affine"),
    ],
    ids=["3x3", "text", "nan", "beyond float32", "projective"],
)
def test_what_is_not_a_placement_says_why(matrix, fragment: str) -> None:
    assert fragment in affine_problem(matrix)
    with pytest.raises(ValueError, match=rf"^transform: .*{fragment}"):
        as_affine(matrix, "transform")


def test_the_embree_layer_follows_the_same_rule() -> None:
    child = BVH()
    child.add_spheres([[0.0, 0.0, 0.0]], [1.0])
    child.commit()
    with child, BVH() as top:
        top.add_instance(child, scaled(1e-4))  # accepted: well conditioned
        with pytest.raises(ValueError, match="transform: must be invertible"):
            top.add_instance(child, scaled(1.0, 1.0, 1e-9))


def test_the_batched_rule_is_the_single_matrix_rule() -> None:
    """``affine_array_problem`` (a million matrices at once) accepts exactly what
    ``affine_problem`` accepts, across the condition-number boundary and every other way a
    placement can be wrong, and names the first bad row."""
    from embree_rt.transforms import affine_array_problem

    rng = np.random.default_rng(3)
    matrices = []
    for flat in (0.3, 0.9, 1.0, 1.1, 3.0):  # around cond = MAX_CONDITION
        rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        matrix = np.eye(4)
        matrix[:3, :3] = rotation @ np.diag([1.0, 0.5, flat / MAX_CONDITION])
        matrices.append(matrix)
    matrices += [
        np.diag([1.0, 1.0, 1.0, 2.0]),
        np.diag([1.0, np.nan, 1.0, 1.0]),
        np.diag([1e39, 1.0, 1.0, 1.0]),
        np.diag([0.0, 0.0, 0.0, 1.0]),
    ]
    for _ in range(20):  # mirrors, shears, tiny and huge uniform scales
        matrix = np.eye(4)
        matrix[:3, :3] = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-6, 6)
        matrix[:3, 3] = rng.normal(size=3)
        matrices.append(matrix)
    for matrix in matrices:
        single = affine_problem(matrix)
        batched = affine_array_problem(np.stack([np.eye(4), matrix]))
        assert (single is None) == (batched is None), (matrix, single, batched)
        if single is not None:
            assert batched == (1, single)
