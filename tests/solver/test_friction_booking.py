"""ALLFD is the energy the friction forces took from the fibers less what their springs hold, every step.

Reference: the friction forces' work on the nodes ``W_f`` (``energy/friction_work``, the same
``½Δt f_n·(v_{n−½} + v_{n+½})`` the step loop applies) and the springs' energy ``E_s``
(``ContactStats.e_spring_J`` of the fiber pairs, ``PlaneFrictionData.e_spring_J`` of the plate) are
state-side quantities; the dissipation
booked over a step must be ``−ΔW_f − ΔE_s`` to rounding. Scene: the study's rearrangement (beam 1
driven down onto beams 2 and 3 on a plate, μ = 0.2), undamped, where the lower beams lose and regain
contact with beam 1 while sliding: contacts leave with loaded springs and a last force whose second
half-step of work had been left unbooked when ALLFD summed the contacts it visited (the full case's
state-function residual ended at −1.1e-3 of its work; now −6.7e-6).
"""

import numpy as np
import pytest

import fiberpipe.verification.contact_cases as cc
from fiberpipe.solver.integrator import Integrator, choose_time_step
from fiberpipe.solver.layout import ACC_FD, ACC_WF
from fiberpipe.solver.state import State


def _rearrangement_scene(monkeypatch):
    """The model, effects and settings ``rearrangement_run`` hands to ``simulate`` (3 mm beams, α = 0)."""
    got = {}

    def capture(m, eff, settings, **kw):
        got.update(m=m, eff=eff, settings=settings)
        raise StopIteration

    monkeypatch.setattr(cc, "simulate", capture)
    with pytest.raises(StopIteration):
        cc.rearrangement_run(alpha=0.0, length_m=3e-3)
    return got["m"], got["eff"], got["settings"]


def test_friction_dissipation_is_minus_the_forces_work_less_the_springs_energy_each_step(monkeypatch):
    m, eff, settings = _rearrangement_scene(monkeypatch)
    dt, _ = choose_time_step(m, eff, settings)
    integ = Integrator(m, eff, dt, history_rows=10, history_every=10**9)
    st = State.at_rest(m)
    stats = integ.term_data("contact").stats
    plate = integ.term_data("plane_friction")  # the plate's friction: the planes term's
    prev = np.array([0.0, 0.0, 0.0])
    mismatch = []
    for _ in range(150):  # 150 chunks of 100 steps, 1.2 ms: the loading and the lower beams' slide
        integ.advance(st, 100)
        cur = np.array([st.acc[ACC_FD], st.acc[ACC_WF], stats.e_spring_J[0] + plate.e_spring_J[0]])
        mismatch.append(float(np.sum(cur - prev)))
        prev = cur
    fd = float(st.acc[ACC_FD])
    assert fd > 0.0
    # tolerance: rounding of sums over ~1e4 steps; the contacts' own sum left 2.0e-3 of ALLFD here
    assert abs(sum(mismatch)) <= 1e-9 * fd, (sum(mismatch), fd)
    assert max(abs(x) for x in mismatch) <= 1e-9 * fd
