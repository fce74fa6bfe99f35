"""A contact law or tangential penalty too stiff for the time step is refused before the run, with
the step it would need (central differences: (ω_beam² + 2k/m) Δt² ≤ 4)."""

import numpy as np
import pytest

from fiberpipe.errors import FiberpipeError
from fiberpipe.solver import Material, SimulationSettings, build_model, simulate
from fiberpipe.solver.laws import make_law
from fiberpipe.verification.case_config import contact_hook

R = 0.25e-3
MAT = Material(15e9, 1380.0, 0.3)


def _two_fibers():
    s = np.linspace(0.0, 3e-3, 11)
    x = np.vstack([np.c_[s, 0 * s, 0 * s], np.c_[s, 0 * s + 2 * R + 1e-6, 0 * s]])
    return build_model(x, np.array([0, 11, 22]), R, MAT)


def _run(m, **kw):
    simulate(m, [contact_hook(m, **kw)], SimulationSettings(end_time_s=1e-7, output_frames=2))


def test_linear_law_above_the_stable_stiffness_is_refused():
    m = _two_fibers()
    # (ωΔt)² = 2 k L Δt²/m: 1e9 N/m² uses ≈ 1 % of the budget, 1e12 N/m² ≈ 10 times all of it
    _run(m, law=make_law("linear", stiffness=1e9, E_pa=15e9, nu=0.3))
    with pytest.raises(FiberpipeError, match=r"too stiff for the time step.*smaller"):
        _run(m, law=make_law("linear", stiffness=1e12, E_pa=15e9, nu=0.3))


def test_friction_stiffness_above_the_stable_stiffness_is_refused():
    m = _two_fibers()
    k_limit = 0.5 * float(np.min(m.mass)) * (2.0 / 8.6e-8) ** 2  # 2kΔt²/m ≈ 3.6 on top of the beam's 3.2 (axial)
    with pytest.raises(FiberpipeError, match=r"friction.stiffness .* too stiff"):
        _run(m, friction=True, k_t=k_limit)


def test_scaled_stiffness_law_whose_first_slope_is_too_stiff_is_refused():
    m = _two_fibers()
    too_stiff = make_law("scaled_stiffness", d_m=1e-7, S=1.1, S0=1.0, K_def=1e9, per="contact", E_pa=15e9, nu=0.3)
    with pytest.raises(FiberpipeError, match=r"'scaled_stiffness' is too stiff for the time step"):
        _run(m, law=too_stiff)


def test_friction_stiffness_is_refused_just_above_its_limit_and_runs_just_below():
    from fiberpipe.solver.timestep import stable_time_step

    m = _two_fibers()
    rep = stable_time_step(m)
    dt = SimulationSettings().dt_safety * rep.dt_stable_s
    beam = max((2.0 * dt / rep.per_mode_s[k]) ** 2 for k in ("axial", "shear", "bending"))
    k_lim = (4.0 - beam) * float(np.min(m.mass)) / (2.0 * dt * dt)
    _run(m, friction=True, k_t=0.9 * k_lim)
    with pytest.raises(FiberpipeError, match=r"needs dt ≤"):
        _run(m, friction=True, k_t=1.1 * k_lim)
