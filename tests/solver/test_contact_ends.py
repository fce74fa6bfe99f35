"""Contact at a fiber's free end is conservative: an end cap sliding onto and off another fiber.

A segment at a fiber's free end owns its clamped closest point (the hemispherical end cap), so the
distance, the force and the energy are continuous as the closest point of the two infinite lines
crosses the free end. Were the point contact owned only while that point falls inside the segment,
the force would appear or vanish at full penetration, each such event would create or destroy
stored contact energy, and in an undamped bundle (the study's α = 0 case) fibers rattling against
each other's ends would gain energy until they diverged (paper-40 at α = 0 then leaves the box at
6e4 m/s after 4.5 ms).
"""

from __future__ import annotations

import numpy as np

from fiberpipe.solver import SimulationSettings, State, simulate
from fiberpipe.verification.case_config import contact_hook
from fiberpipe.solver.laws import make_law

from test_contact_dynamics import R, _model  # noqa: E402  (same folder, on sys.path under pytest)


def _mechanical_energy(res, k):
    h = res.history
    return h["energy/kinetic"][k] + h["energy/strain"][k]


def test_end_cap_passing_over_a_fiber_gives_back_its_energy():
    """A short fiber (0.6 mm, 2 elements) slides at 1 m/s across a free fiber, 2 µm lower than
    touching, end first, and leaves on the other side: an elastic passage (no damping, no friction),
    so the mechanical energy after it equals the energy before it (up to the O(Δt²) error of
    central differences, far below the 10 % the old ownership rule created or lost)."""
    L = 3e-3
    z = 2 * R - 2e-6
    m = _model([((0, 0, 0), (L, 0, 0), 10),
                ((1.5e-3, 0.3e-3, z), (1.5e-3, 0.9e-3, z), 2)])
    state = State.at_rest(m)
    state.v[m.node_fiber == 1, 1] = -1.0
    law = make_law("hertz_oriented", E_pa=15e9, nu=0.3)
    res = simulate(m, [contact_hook(m, law=law)], SimulationSettings(end_time_s=1.6e-3, output_frames=3),
                   state=state)
    assert res.completed
    contacts = np.asarray(res.history["contacts"])
    assert contacts.max() >= 1, "the fibers never touched: the case tests nothing"
    assert contacts[-1] == 0, "still in contact at the end: the passage is not complete"
    e0 = _mechanical_energy(res, 0)
    e1 = _mechanical_energy(res, -1)
    assert abs(e1 - e0) / e0 < 1e-3, (e0, e1)
