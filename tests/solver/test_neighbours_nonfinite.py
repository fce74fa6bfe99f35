"""A diverging step can leave NaN or inf positions: the neighbour search must neither crash nor
write out of bounds (it builds no pairs; the step loop's divergence check reports the run)."""

import numpy as np

from fiberpipe.solver.laws import make_law
from fiberpipe.solver.neighbours import build_pairs, segment_arclength


def _two_fibers(n=11):
    """Two parallel 10-element fibers 0.5 mm apart: positions, segments, radii, fiber ids, arc
    lengths and the pair/key output buffers of build_pairs."""
    x = np.c_[np.zeros(2 * n), np.repeat([0.0, 0.5e-3], n), np.tile(np.linspace(0, 3e-3, n), 2)]
    seg = np.array([[i, i + 1] for f in range(2) for i in range(f * n, f * n + n - 1)], np.int64)
    fib = np.repeat([0, 1], n - 1)
    arc = segment_arclength(seg, fib, x)
    radius = np.full(len(seg), 0.25e-3)
    return x, seg, radius, fib, arc, np.zeros((64, 2), np.int64), np.zeros(64, np.int64)


def test_non_finite_positions_build_no_pairs():
    x, seg, radius, fib, arc, pairs, keys = _two_fibers()
    assert build_pairs(x, seg, radius, fib, arc, 5e-5, 5e-4, pairs, keys) > 0
    for bad in (np.nan, np.inf, -np.inf):
        y = x.copy()
        y[3, 1] = bad
        assert build_pairs(y, seg, radius, fib, arc, 5e-5, 5e-4, pairs, keys) == 0


def test_crossed_law_with_a_nan_angle_reads_inside_its_table():
    from fiberpipe.solver.laws import law_point

    law = make_law("hertz_oriented", E_pa=15e9, nu=0.3)
    f, e = law_point(law.law_id, law.params(), 1e-8, 0.25e-3, 0.25e-3, np.nan)
    assert np.isfinite(f) or np.isnan(f)  # no out-of-bounds read; the value itself is irrelevant


def test_guard_holds_when_called_from_a_fastmath_kernel():
    """The hook calls build_pairs from fastmath code, where a float NaN test may be optimised away
    once inlined; the guard reads the IEEE bits instead."""
    from numba import njit

    @njit(fastmath=True)
    def from_fastmath(x, seg, radius, fib, arc, pairs, keys):
        return build_pairs(x, seg, radius, fib, arc, 5e-5, 5e-4, pairs, keys)

    x, seg, radius, fib, arc, pairs, keys = _two_fibers()
    assert from_fastmath(x, seg, radius, fib, arc, pairs, keys) > 0
    for bad in (np.nan, np.inf, -np.inf):
        y = x.copy()
        y[3, 1] = bad
        assert from_fastmath(y, seg, radius, fib, arc, pairs, keys) == 0
