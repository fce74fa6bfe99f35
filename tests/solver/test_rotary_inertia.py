"""Isotropic lumped rotary inertia: spinning fibers conserve energy, and the bending-governed
stable time step of :func:`fiberpipe.solver.stable_time_step` is the real limit."""

from __future__ import annotations

import numpy as np
import pytest

from fiberpipe.errors import SimulationDiverged
from fiberpipe.solver import Material, SimulationSettings, State, build_model, simulate, stable_time_step

R = 0.25e-3
MAT = Material(15e9, 1380.0, 0.3)


def _fiber(n=10, L=3e-3, **kw):
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    return build_model(s * np.array([0.0, 0.0, L]), np.array([0, n + 1]), R, MAT, **kw)


def _energy(res):
    h = res.history
    return h["energy/kinetic"] + h["energy/strain"]


def test_rotary_inertia_is_isotropic_polar():
    m = _fiber()
    L = 0.3e-3
    jp = 1380.0 * np.pi * R**4 / 2 * L / 2  # ρ J_p L/2 of one element half
    assert np.allclose(m.J[1:-1], 2 * jp) and np.allclose(m.J[[0, -1]], jp)


@pytest.mark.parametrize("spin_rad_s", [1e4, 1e5])
def test_free_spinning_fiber_conserves_energy(spin_rad_s):
    """A free fiber spinning about its axis with small random bending rates, undamped, 2e4 steps.
    With the anisotropic inertia and the explicit gyroscopic term it gained 1000× its energy in
    12 000 steps (1e4 rad/s) or blew up in 1 600 (1e5 rad/s)."""
    m = _fiber()
    st = State.at_rest(m)
    st.w[:, 2] = spin_rad_s
    st.w[:, 0] = 1e3 * np.random.default_rng(0).standard_normal(m.n_nodes)
    res = simulate(m, [], SimulationSettings(end_time_s=2e4 * 0.9 * 9.1e-8, output_frames=3), state=st)
    e = _energy(res)
    assert res.completed
    # leapfrog's energy measure (KE at half steps) oscillates by ~1e-3 with modes near the limit;
    # what must not happen is growth
    assert np.max(np.abs(e - e[0])) / e[0] < 1e-2
    assert abs(e[-500:].mean() - e[:500].mean()) / e[0] < 1e-3


def test_bending_governed_limit_is_the_real_limit():
    """rotary_inertia_scale = 0.01 makes the bending mode govern (Δt = √(2s) L/c): a vibrating
    fiber at 0.98 × that limit stays bounded over 2e4 steps, at 1.05 × it diverges."""
    m = _fiber(rotary_inertia_scale=0.01)
    rep = stable_time_step(m)
    assert rep.governing_mode == "bending"
    assert rep.dt_stable_s == pytest.approx(np.sqrt(0.02) * 0.3e-3 / np.sqrt(15e9 / 1380.0), rel=1e-9)

    def run(factor):
        st = State.at_rest(m)
        st.w[:, 0] = 1e2 * np.random.default_rng(1).standard_normal(m.n_nodes)
        return simulate(m, [], SimulationSettings(dt_s=factor * rep.dt_stable_s, end_time_s=2e4 * rep.dt_stable_s,
                                                  output_frames=3, force_dt=True), state=st)

    # near the limit leapfrog's energy measure swings (KE at half steps), but it stays bounded
    e = _energy(run(0.98))
    assert np.max(e) < 5 * e[0]
    assert abs(e[-500:].mean() - e[:500].mean()) < 0.2 * e[:500].mean()
    with pytest.raises(SimulationDiverged):
        run(1.05)
