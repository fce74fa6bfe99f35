"""Friction takes energy out, never puts it in (regression: share-scaled tangential stiffness).

A 3 mm fiber pressed onto a clamped one by a line load is launched along it at 5 cm/s, undamped.
Coulomb friction μ p L must stop it within microseconds, dissipating its kinetic energy ½ m v²
into ALLFD; afterwards nothing may gain energy (before the fix the tangential springs of
parallel contacts went unstable and fibers reached tens of m/s).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_hard_cases import R, fibers_model, hook  # noqa: E402

from fiberpipe.solver import Clamp, Clamps, LineLoad, Loads, State  # noqa: E402
from fiberpipe.solver.integrator import SimulationSettings, simulate  # noqa: E402


def _slide():
    L, v0 = 3e-3, 0.05
    m = fibers_model([((0, 0, 0), (L, 0, 0), 10), ((0, 0, 2 * R - 20e-9), (L, 0, 2 * R - 20e-9), 10)])
    st = State.at_rest(m)
    a, b = m.node_offsets[1], m.node_offsets[2]
    st.v[a:b, 0] = v0
    eff = [Clamps([Clamp(0, "start"), Clamp(0, "end")]), Loads([LineLoad(1, [0, 0, -66.0])]), hook(m, friction=True, mu=0.2)]
    res = simulate(m, eff, SimulationSettings(end_time_s=1e-3, output_frames=6, history_every=20), state=st)
    return m, res, a, b, v0


def test_sliding_fiber_is_stopped_by_friction_and_stays_stopped():
    m, res, a, b, v0 = _slide()
    fd = np.asarray(res.history["energy/friction"])
    ke = np.asarray(res.history["energy/kinetic"])
    # dissipation accumulates; ALLFD is the friction forces' work less the springs' energy, booked as
    # it is, and while the stuck pair vibrates its contact point slides under the loaded spring and
    # the spring's force turns with the normal: that exchanges 8e-6 of ALLFD here, either way
    # (1.3e-4 with the spring stretched at this step's contact point instead of the path's middle)
    assert np.max(np.maximum.accumulate(fd) - fd) < 1e-4 * fd[-1]
    m_fiber = float(m.mass[a:b].sum())
    assert fd[-1] == pytest.approx(0.5 * m_fiber * v0**2, rel=0.25)  # the sliding energy went into friction
    # the suddenly applied load sets the pair vibrating (undamped): that energy may slosh between
    # kinetic and strain but must not grow
    assert np.max(ke[len(ke) // 2 :]) < 1.2 * np.max(ke[: len(ke) // 4])
    x = np.asarray(res.frames_positions)
    assert abs(x[-1, a:b, 0].mean() - x[-2, a:b, 0].mean()) < 1e-7  # stopped
    # Abaqus' balance (booked contact work) closes
    h = res.history
    scale = np.maximum.accumulate(np.maximum(np.abs(h["energy/external"]), h["energy/kinetic"] + h["energy/strain"]))
    assert np.max(np.abs(h["energy/total"] - h["energy/total"][0]) / scale) < 0.01
    # the friction forces' own work (energy/friction_work, booked apart from the normal forces') is
    # the loss ALLFD books, with the sign of work done on the fibers: the return map's bookkeeping
    # agrees with the forces it applies (the small rest is the tangential springs' stored energy)
    wf = np.asarray(res.history["energy/friction_work"])
    assert wf[-1] < 0 and -wf[-1] == pytest.approx(fd[-1], rel=0.05)


def test_sliding_fiber_state_residual_stays_below_one_percent():
    """The state-function balance (stored contact energy, springs included, from the first step's)
    closes within 1 % while friction stops the fiber."""
    m, res, a, b, v0 = _slide()
    assert np.max(np.abs(res.history["energy/residual"][1:])) < 0.01


def test_booked_dissipation_is_the_forces_work_under_chatter():
    """A fiber on a plate, undamped, its nodes launched with alternating velocities (the highest
    modes): the plate friction's slip turns back and forth from step to step. ALLFD is the energy the
    friction forces took from the fiber (energy/friction_work, booked by the step loop) less what
    their springs store, so the state-function residual closes; the end-of-step product μ f_n × slip
    books 3.4× that work here (residual 1.1e-2). No contact gives energy back."""
    from test_contact_dynamics import _model
    from fiberpipe.solver import Gravity, Plates

    m = _model([((0, 0, R), (3e-3, 0, R), 10)])
    st = State.at_rest(m)
    k = np.arange(m.n_nodes)
    st.v[:, 0] = 0.01 * (-1.0) ** k
    st.v[:, 1] = 0.01 * (-1.0) ** (k // 2)
    ke0 = 0.5 * float(np.sum(m.mass * np.sum(st.v**2, axis=1)))
    res = simulate(m, [Gravity([0, 0, -9.81]), Plates(axis="z", lower="fixed", upper="none", lower_position_m=0.0,
                                                      mu=0.5)],
                   SimulationSettings(end_time_s=2e-4, output_frames=3, history_every=10), state=st)
    h = res.history
    fd, wf = h["energy/friction"][-1], -h["energy/friction_work"][-1]
    assert fd > 0.01 * ke0  # the friction does work here
    assert fd == pytest.approx(wf, rel=1e-3)  # less the springs' energy, small at the end
    assert np.max(np.abs(h["energy/residual"])) < 1e-3
    assert 0.0 <= res.friction_returned_J <= 1e-9 * fd
