"""post.loops on a synthetic loading path whose loop area and residual travel are known in closed form."""

import numpy as np
import pytest

from fiberpipe.post.loops import loading_cycles, residual_strains, segment_runs

A, B = 10.0, 5.0  # load a·U on loading, max(a·U − b, 0) on unloading (U in mm, F in N)


def _history(n=4001):
    """0 → 1 → 0.4 → 1.15 mm, linear in time, n rows per move."""
    moves = [(0.0, 1.0), (1.0, 0.4), (0.4, 1.15)]
    U = np.concatenate([np.linspace(a, b, n)[1 if k else 0:] for k, (a, b) in enumerate(moves)])
    seg = np.concatenate([np.full(n - (1 if k else 0), k) for k in range(3)])
    F = np.where(seg == 1, np.maximum(A * U - B, 0.0), A * U)
    t = np.arange(U.size) * 1e-6
    W = np.concatenate([[0.0], np.cumsum(0.5 * (F[1:] + F[:-1]) * np.diff(U) * 1e-3)])
    return t, seg, U * 1e-3, F, W


def test_segment_runs():
    assert segment_runs(np.array([0, 0, 1, 1, 1, 2])) == [(0, 0, 2), (1, 2, 5), (2, 5, 6)]
    assert segment_runs(np.zeros(0)) == []


def test_the_unload_reload_loop_and_its_area():
    t, seg, U, F, W = _history()
    Uc = np.column_stack([U, np.zeros_like(U)])
    Fc = np.column_stack([F, F])
    energy = {"external": W, "friction": 0.9 * W, "damping": 0.1 * W}
    [c] = loading_cycles(t, seg, Uc, Fc, energy)
    assert (c.first_segment, c.start_U_m, c.turn_U_m) == (1, pytest.approx(1e-3), pytest.approx(0.4e-3))
    # ∮ F dU = ∫ from 1 to 0.4 of max(aU − b, 0) + ∫ from 0.4 to 1 of aU (mm·N → J)
    area = (-(A / 2 * (1 - 0.25) - B * 0.5) + A / 2 * (1 - 0.16)) * 1e-3
    # the trapezoid rule is exact on the linear pieces; the load's jumps at the turns cost O(row spacing)
    assert c.loop_area_J == pytest.approx(area, rel=1e-3)
    assert c.plate_work_J == pytest.approx(c.loop_area_J, rel=1e-12)
    assert c.dissipated_J == pytest.approx(c.plate_work_J, rel=1e-12)
    assert np.isnan(c.stored_change_J)  # no stored-energy column given


def test_a_path_without_return_has_no_cycle():
    t, seg, U, F, W = _history()
    keep = seg < 2
    assert loading_cycles(t[keep], seg[keep], U[keep], F[keep]) == []


def test_residual_travel_after_unloading():
    t, seg, U, F, _ = _history()
    [u] = residual_strains(seg, U, F, gap_m=2e-3)
    # the load falls to 1 % of its peak (11.5 N) at a U − b = 0.115 N
    assert u.residual_U_m == pytest.approx((B + 0.01 * A * 1.15) / A * 1e-3, abs=1e-6)
    assert u.residual_strain == pytest.approx(u.residual_U_m / 2e-3)
    assert (u.segment, u.from_U_m, u.to_U_m) == (1, pytest.approx(1e-3), pytest.approx(0.4e-3))
