"""The counter-based generator: uniform, independent streams, batch-split invariant."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from embree_rt.sampling import uniform

N = 200_000


def test_values_are_float32_on_a_24_bit_grid_strictly_below_one() -> None:
    values = uniform(7, np.arange(1_000_000, dtype=np.int64), 0)
    assert values.dtype == np.float32
    assert values.shape == (1_000_000,)
    assert values.min() >= 0.0
    assert values.max() < 1.0
    # Multiples of 2^-24: exactly representable, so no rounding up to 1.0 can ever happen.
    scaled = values.astype(np.float64) * 2.0**24
    np.testing.assert_array_equal(scaled, np.floor(scaled))
    # ... and not stuck on a coarser grid: nearly every sample is distinct.
    assert len(np.unique(values)) > 0.97 * len(values)


def test_uniform_histogram_mean_and_variance() -> None:
    values = uniform(0, np.arange(N, dtype=np.int64), 0).astype(np.float64)
    assert values.mean() == pytest.approx(0.5, abs=5 * np.sqrt(1 / 12 / N))
    assert values.var() == pytest.approx(1 / 12, abs=5 * np.sqrt(1 / 180 / N))
    counts = np.bincount((values * 64).astype(int), minlength=64)
    chi2 = ((counts - N / 64) ** 2 / (N / 64)).sum()
    assert chi2 < stats.chi2.ppf(1 - 1e-6, 63)


def test_pairs_of_dimensions_are_jointly_uniform() -> None:
    index = np.arange(N, dtype=np.int64)
    x, y = uniform(3, index, 0), uniform(3, index, 1)
    cells = (x * 16).astype(int) * 16 + (y * 16).astype(int)
    counts = np.bincount(cells, minlength=256)
    chi2 = ((counts - N / 256) ** 2 / (N / 256)).sum()
    assert chi2 < stats.chi2.ppf(1 - 1e-6, 255)


@pytest.mark.parametrize(
    "a, b",
    [
        ((0, 0), (0, 1)),  # two dimensions of one seed
        ((0, 0), (1, 0)),  # one dimension of two seeds
        ((5, 2), (6, 3)),
        ((0, 1_000_003), (1, 0)),  # pairs that alias under key = seed * k + dimension
    ],
)
def test_streams_are_uncorrelated(a: tuple[int, int], b: tuple[int, int]) -> None:
    index = np.arange(N, dtype=np.int64)
    first = uniform(a[0], index, a[1]).astype(np.float64)
    second = uniform(b[0], index, b[1]).astype(np.float64)
    # Different numbers element by element, not merely not identical arrays.
    assert np.mean(first == second) < 1e-3
    assert abs(np.corrcoef(first, second)[0, 1]) < 5 / np.sqrt(N)


def test_neighbouring_indices_are_uncorrelated() -> None:
    values = uniform(11, np.arange(N, dtype=np.int64), 0).astype(np.float64)
    for lag in (1, 2, 8, 1024):
        assert abs(np.corrcoef(values[:-lag], values[lag:])[0, 1]) < 5 / np.sqrt(N)


def test_every_seed_and_dimension_pair_has_its_own_stream() -> None:
    index = np.arange(8, dtype=np.int64)
    rows = {uniform(seed, index, dim).tobytes() for seed in range(32) for dim in range(32)}
    assert len(rows) == 32 * 32


def test_batch_split_and_order_invariance() -> None:
    index = np.arange(10_000, dtype=np.int64)
    whole = uniform(42, index, 5)
    pieces = [uniform(42, chunk, 5) for chunk in np.array_split(index, [1, 777, 4096, 9999])]
    np.testing.assert_array_equal(np.concatenate(pieces), whole)
    order = np.random.default_rng(0).permutation(len(index))
    np.testing.assert_array_equal(uniform(42, index[order], 5), whole[order])
    np.testing.assert_array_equal(uniform(42, index.astype(np.uint64), 5), whole)
    np.testing.assert_array_equal(uniform(42, index.astype(np.int32), 5), whole)
    np.testing.assert_array_equal(uniform(42, index, 5), whole)  # same call, same values


def test_far_indices_stay_uniform() -> None:
    """Sample indices of a 1e6-sphere 4K render at many spp run past 2^32."""
    far = uniform(7, np.arange(2**40, 2**40 + N, dtype=np.int64), 1).astype(np.float64)
    assert far.min() >= 0.0 and far.max() < 1.0
    assert far.mean() == pytest.approx(0.5, abs=5 * np.sqrt(1 / 12 / N))
    assert len(np.unique(far)) > 0.97 * N


def test_any_integer_seed_works_and_index_must_be_integer() -> None:
    index = np.arange(1000, dtype=np.int64)
    for seed in (-1, 2**64 - 1, 2**40 + 3):
        values = uniform(seed, index, 0)
        assert ((values >= 0) & (values < 1)).all()
    assert not np.array_equal(uniform(-1, index, 0), uniform(1, index, 0))
    with pytest.raises(TypeError, match="index"):
        uniform(0, np.arange(4, dtype=np.float64), 0)
    with pytest.raises(ValueError, match="dimension"):
        uniform(0, index, -1)


def test_the_pair_from_one_hash_is_jointly_uniform_and_uncorrelated() -> None:
    from embree_rt.sampling import uniform_pair

    index = np.arange(N, dtype=np.int64)
    x, y = uniform_pair(3, index, 0)
    assert x.dtype == y.dtype == np.float32
    assert min(x.min(), y.min()) >= 0.0 and max(x.max(), y.max()) < 1.0
    # the first value is uniform's own stream; the second is a different one
    np.testing.assert_array_equal(x, uniform(3, index, 0))
    assert np.mean(x == y) < 1e-3
    assert abs(np.corrcoef(x, y)[0, 1]) < 5 / np.sqrt(N)
    cells = (x * 16).astype(int) * 16 + (y * 16).astype(int)
    counts = np.bincount(cells, minlength=256)
    chi2 = ((counts - N / 256) ** 2 / (N / 256)).sum()
    assert chi2 < stats.chi2.ppf(1 - 1e-6, 255)
    scaled = y.astype(np.float64) * 2.0**24  # on the 24-bit grid, as uniform's values are
    np.testing.assert_array_equal(scaled, np.floor(scaled))
