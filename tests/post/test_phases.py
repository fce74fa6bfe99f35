"""fiberpipe.post.phases: the study's three compaction phases found on curves of known shape."""

import numpy as np
import pytest

from fiberpipe.post.phases import compaction_phases, describe

U = np.linspace(0.0, 1.15e-3, 4601)


def test_flat_transition_steep():
    """Zero to 0.55 mm, a slow linear transition to 0.9 mm, then 10× steeper: the study's shape."""
    F = np.where(U < 0.55e-3, 0.0, (U - 0.55e-3) * 2e3) + np.where(U > 0.9e-3, (U - 0.9e-3) * 2e4, 0.0)
    ph = compaction_phases(U, F)
    assert ph["rearrangement_end_U_m"] == pytest.approx(0.55e-3 + 0.02 * F.max() / 2e3, abs=0.03e-3)
    assert ph["steep_start_U_m"] == pytest.approx(0.9e-3, abs=0.05e-3)
    assert ph["steepness"] == pytest.approx(2.2e4 / ((6.2 - 0.124) / (1.125e-3 - 0.612e-3)), rel=0.1)
    assert ph["steep_slope_N_per_m"] == pytest.approx(2.2e4, rel=0.1)
    assert "steep rise from 0.9" in describe(ph) or "steep rise from 0.8" in describe(ph)


def test_straight_rise_has_no_steep_phase():
    F = U * 1e3
    ph = compaction_phases(U, F)
    assert ph["rearrangement_end_U_m"] < 0.05e-3
    assert ph["steep_start_U_m"] is None
    assert ph["steepness"] == pytest.approx(1.0, abs=0.05)
    assert "no steep phase" in describe(ph)


def test_bursts_average_out():
    """The flat/steep shape with ±20 % of the final load as sample noise (contact bursts): the
    boundaries move by less than two windows."""
    rng = np.random.default_rng(0)
    clean = np.where(U < 0.55e-3, 0.0, (U - 0.55e-3) * 2e3) + np.where(U > 0.9e-3, (U - 0.9e-3) * 2e4, 0.0)
    F = np.clip(clean + 0.2 * clean.max() * rng.uniform(-1, 1, U.size) * (U > 0.6e-3)
                + 0.01 * clean.max() * rng.uniform(0, 1, U.size), 0, None)  # and ±1 % noise during rearrangement
    ph = compaction_phases(U, F)
    assert ph["steep_start_U_m"] == pytest.approx(0.9e-3, abs=0.1e-3)
    assert 0.5e-3 < ph["rearrangement_end_U_m"] < 0.65e-3


def test_a_burst_during_rearrangement_is_still_rearrangement():
    """A 0.5 N burst of 0.03 mm at U = 0.2 mm that falls back to zero: the onset stays at the
    last crossing (≈ 0.61 mm), not the burst."""
    F = np.where(U < 0.55e-3, 0.0, (U - 0.55e-3) * 2e3) + np.where(U > 0.9e-3, (U - 0.9e-3) * 2e4, 0.0)
    F = F + np.where((U > 0.2e-3) & (U < 0.23e-3), 0.5, 0.0)
    ph = compaction_phases(U, F)
    assert ph["rearrangement_end_U_m"] == pytest.approx(0.55e-3 + 0.02 * 6.2 / 2e3, abs=0.03e-3)
    assert ph["steep_start_U_m"] == pytest.approx(0.9e-3, abs=0.05e-3)


def test_a_preload_is_no_rearrangement_and_a_straight_line_no_steep_phase():
    """F = 1 N + 1e3 U: loaded from the start, and the onset is the curve's own first window
    (a straight line keeps steepness 1 whatever its offset)."""
    ph = compaction_phases(U, 1.0 + U * 1e3)
    assert ph["rearrangement_end_U_m"] == 0.0 and ph["status"] == "ok"
    assert ph["steepness"] == pytest.approx(1.0, abs=0.05) and ph["steep_start_U_m"] is None
    assert describe(ph).startswith("loaded from the start")
    ph = compaction_phases(U, np.ones_like(U))  # a constant load: no rise at all
    assert ph["steep_start_U_m"] is None and "no rise" in describe(ph)


def test_a_late_locking_is_flagged_as_censored():
    """Locking at 1.12 mm of a run ending at 1.15 mm: found at the latest breakpoint the 0.05 mm
    windows allow (≈ 1.03 mm) and flagged, not reported as a locking at 1.03 mm."""
    F = np.where(U < 0.55e-3, 0.0, (U - 0.55e-3) * 2e3) + np.where(U > 1.12e-3, (U - 1.12e-3) * 2e5, 0.0)
    ph = compaction_phases(U, F)
    assert ph["steep_start_censored"] and ph["steep_start_U_m"] < 1.12e-3
    assert "or later" in describe(ph)
    F = np.where(U < 0.55e-3, 0.0, (U - 0.55e-3) * 2e3) + np.where(U > 0.9e-3, (U - 0.9e-3) * 2e4, 0.0)
    assert not compaction_phases(U, F)["steep_start_censored"]


def test_the_last_window_does_not_depend_on_rounding():
    """A travel ending exactly on a window edge (1.15 mm) or 1e-12 m past it, with one spiky last
    sample: the same windows, no spurious window beyond the data."""
    F = U * 1e3
    F2 = F.copy()
    F2[-1] = 50.0
    a = compaction_phases(U, F2)
    b = compaction_phases(U + np.r_[np.zeros(U.size - 1), 1e-12], F2)
    assert a["peak_U_m"] == pytest.approx(b["peak_U_m"]) and a["peak_U_m"] <= U[-1]
    assert a["steep_start_U_m"] == b["steep_start_U_m"]
    two = compaction_phases(np.array([0.0, 1.15e-3]), np.array([0.0, 1.0]))
    assert two["status"] == "too short" and two["peak_window_load_N"] == pytest.approx(1.0)  # the last sample kept


def test_bad_input_is_undetermined_not_no_load():
    F = U * 1e3
    for u, f in ((U, np.where(U > 0.5e-3, np.nan, F)), (U[:1], F[:1]), (U[::-1] * 0, F)):
        ph = compaction_phases(u, f)
        assert ph["status"] == "undetermined" and describe(ph).startswith("phases undetermined")


def test_no_load_and_unloading_branch():
    ph = compaction_phases(U, np.zeros_like(U))
    assert ph["rearrangement_end_U_m"] is None and describe(ph) == "no load: rearrangement only"
    # a loading then unloading history: only the loading branch counts
    UU = np.r_[U, U[::-1]]
    FF = np.r_[U * 1e3, np.full(U.size, 5.0)]
    assert compaction_phases(UU, FF)["peak_window_load_N"] == pytest.approx(1.15, rel=0.03)
