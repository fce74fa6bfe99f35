"""Energy balance of prescribed motions (drives) with mass-proportional damping.

Mass-proportional damping acts on the absolute velocity of every node, driven ones included
(docs/solver.md, ``Damping``): its dissipation on a driven node is in ALLVD, so the drive's reaction
must contain the damping force it overcomes, or ETOTAL drifts by the driven nodes' ALLVD (the
crossing-fiber hard case had an energy residual of 11.7 from exactly that).
"""

from __future__ import annotations

import numpy as np
import pytest

from fiberpipe.solver import Damping, Drive, Drives, Material, SimulationSettings, build_model, simulate
from fiberpipe.solver.layout import DRIVEN

R = 0.25e-3
MAT = Material(15e9, 1380.0, 0.3)
L, N_EL = 3e-3, 10


def straight_fiber():
    s = np.linspace(0.0, L, N_EL + 1)
    nodes = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    return build_model(nodes, np.array([0, N_EL + 1]), R, MAT)


class EndDrive(Drives):
    """A :class:`Drives` whose first drive moves only the last node of its fiber (translations
    prescribed, rotation fixed); the other nodes are free."""

    def setup(self, model, scene):
        super().setup(model, scene)
        end = model.fiber_node_index(int(self.drives[0].fiber), "end")
        keep = scene.fix_mask[end]
        scene.fix_mask[:] &= np.uint8(0xFF & ~DRIVEN)
        scene.fix_mask[end] = keep


def history(res):
    return {k: np.asarray(v, float) for k, v in res.history.items()}


@pytest.mark.parametrize("alpha", [1e4, 1e5])
def test_fiber_pulled_by_one_end_at_constant_velocity_with_damping_balances(alpha):
    """One end of a free straight fiber pulled at a constant 0.5 m/s (sideways and along it), the
    rest following through the beam: max |ETOTAL − ETOTAL₀| < 1e-3 of the external work. Measured
    4.6e-4 (α = 1e4) and 5.2e-5 (α = 1e5); without the damping force in the drive's reaction the
    end node's dissipation alone is ~4 % (α = 1e4) of it."""
    m = straight_fiber()
    res = simulate(m, [EndDrive([Drive(0, [0.2e-3, 0.3e-3, 0.0], 0.5, ramp="linear")]), Damping(alpha)],
                   SimulationSettings(output_frames=5))
    assert res.completed
    h = history(res)
    wk = h["energy/external"]
    tot = h["energy/total"]
    end = m.fiber_node_index(0, "end")
    assert np.allclose(res.frames_positions[-1][end] - m.nodes_m[end], [0.2e-3, 0.3e-3, 0.0], atol=1e-12)
    assert h["energy/damping"][-1] > 0.5 * wk[-1]  # damping on and doing most of the work's sink
    assert np.max(np.abs(tot - tot[0])) / np.max(np.abs(wk)) < 1e-3


def test_rigidly_translated_fiber_dissipates_alpha_m_v2_t():
    """A whole fiber translated rigidly at constant v by a drive: the (absolute-velocity) mass-
    proportional damping dissipates ALLVD = α m v² t, the drive supplies it (ALLWK = ALLKE + ALLVD),
    no strain. Checked on the constant-velocity part of the run (the first and last step, where the
    velocity jumps from/to 0, are O(Δt))."""
    alpha, v = 2e4, 2.0
    U = np.array([0.3e-3, -0.4e-3, 1.2e-3])
    U *= 0.4e-3 / np.linalg.norm(U)
    m = straight_fiber()
    T = 0.4e-3 / v
    res = simulate(m, [Drives([Drive(0, U, v, ramp="linear")]), Damping(alpha)],
                   SimulationSettings(output_frames=5, end_time_s=T))
    h = history(res)
    t = h["time"]
    dt = res.dt_s
    M = float(m.mass.sum())
    sel = (t > 100 * dt) & (t < T - 2 * dt)
    assert np.count_nonzero(sel) > 100
    vd = h["energy/damping"][sel]
    # rate exactly α m v² (every inner step dissipates α m v² Δt) ...
    slope = np.diff(vd) / np.diff(t[sel])
    assert np.allclose(slope, alpha * M * v**2, rtol=1e-9)
    # ... and the total α m v² t up to the first step's half-speed v̄ = v/2 (an O(Δt) offset)
    assert np.allclose(vd, alpha * M * v**2 * t[sel], rtol=1e-3)
    assert np.allclose(h["energy/kinetic"][sel], 0.5 * M * v**2, rtol=1e-12)
    assert np.max(h["energy/strain"]) < 1e-12 * M * v**2
    # the balance: WK = KE + VD at every inner row (ETOTAL constant there)
    tot = h["energy/total"][sel]
    assert np.max(np.abs(tot - tot[0])) < 1e-9 * h["energy/external"][sel][-1]
