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
    F = np.clip(clean + 0.2 * clean.max() * rng.uniform(-1, 1, U.size) * (U > 0.6e-3), 0, None)
    ph = compaction_phases(U, F)
    assert ph["steep_start_U_m"] == pytest.approx(0.9e-3, abs=0.1e-3)
    assert 0.5e-3 < ph["rearrangement_end_U_m"] < 0.65e-3


def test_no_load_and_unloading_branch():
    ph = compaction_phases(U, np.zeros_like(U))
    assert ph["rearrangement_end_U_m"] is None and describe(ph) == "no load: rearrangement only"
    # a loading then unloading history: only the loading branch counts
    UU = np.r_[U, U[::-1]]
    FF = np.r_[U * 1e3, np.full(U.size, 5.0)]
    assert compaction_phases(UU, FF)["peak_window_load_N"] == pytest.approx(1.15, rel=0.03)
