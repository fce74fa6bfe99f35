"""``fiberpipe._prefetch.prefetch_row``: a hint that compiles for the arrays the kernels pass it and
changes nothing they compute."""

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from fiberpipe._prefetch import prefetch_row


@njit
def _gather_sum(a, idx, ahead):
    s = 0.0
    for k in range(idx.shape[0]):
        if ahead > 0 and k + ahead < idx.shape[0]:
            prefetch_row(a, idx[k + ahead])
        s += a[idx[k], 0]
    return s


@njit
def _touch_1d(a, i):
    prefetch_row(a, i)
    return a[i]


def test_prefetch_leaves_the_sum_unchanged_for_2d_rows():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(10_000, 3))
    idx = rng.integers(0, 10_000, 5_000)
    assert _gather_sum(a, idx, 4) == _gather_sum(a, idx, 0)
    assert np.isclose(_gather_sum(a, idx, 4), a[idx, 0].sum(), rtol=1e-12)


@pytest.mark.parametrize("dtype", [np.float64, np.int64])
def test_prefetch_compiles_for_1d_arrays_and_any_integer_index(dtype):
    a = np.arange(10, dtype=dtype)
    assert _touch_1d(a, np.int32(3)) == 3
    assert _touch_1d(a, 7) == 7


def test_prefetch_refuses_a_non_array():
    @njit
    def bad(v):
        prefetch_row(v, 0)

    with pytest.raises(TypingError):
        bad(1.0)
