"""``solver.stable_step: adaptive``: each step of the run's grid split into sub-steps that follow the
contact's stiffness (:class:`fiberpipe.solver.timestep.AdaptiveStep`).

Checks: the sub-steps against the central-difference bound they are chosen by; the undamped,
frictionless six-fiber scene at 1000 N/m with every contact law (and a Hertz law 150× too stiff for
the element step, which diverges there) creates no energy at the default dt_safety: the state
functions (the leapfrog kinetic term less its shift at the step changes, strain, stored contact and
plane potentials) stay within 1 % of the loads' work; a resumed adaptive run is the uninterrupted
one bit for bit; the sub-step of every history row is in ``dt_s``."""

import math

import numpy as np
import pytest

from fiberpipe.errors import SimulationDiverged
from fiberpipe.solver import Loads, Plates, SimulationSettings, Walls, simulate
from fiberpipe.solver.checkpoint import read_checkpoint, write_checkpoint
from fiberpipe.solver.laws import make_law
from fiberpipe.solver.terms.loads import LineLoad
from fiberpipe.solver.timestep import AdaptiveStep, stable_time_step
from fiberpipe.verification.case_config import contact_hook
from fiberpipe.verification.six_fibers import GAP_M, LAWS, law_label, six_fibers, six_fibers_law


def _scene(law, q_n_per_m):
    model, pitch = six_fibers()
    effects = [Loads([LineLoad(4, (0, 0, -q_n_per_m)), LineLoad(5, (0, 0, -q_n_per_m))]),
               Plates(axis="z", lower="fixed", upper="none", lower_position_m=0.0),
               Walls({"y": (0.0, 4 * pitch + GAP_M)}), contact_hook(model, law=law)]
    return model, effects


def _excess(res) -> float:
    """max over the rows of (state energy − loads' work) / max|W|, the leapfrog kinetic term taken
    less its shift at the step changes (``energy/step_change``)."""
    h = res.history
    work = h["energy/external"]
    state = (h["energy/kinetic_leapfrog"] - h["energy/step_change"] + h["energy/strain"]
             + h["energy/contact_stored"])
    assert h["energy/contact_stored"].max() > 0 and h["contacts"].max() > 0  # the scene tests contact
    return float(np.max((state - work) / np.max(np.abs(work))))


def _stiff_hertz():
    """The crossed Hertz law at 150× the fibers' modulus: at 30 N/m its tangent needs a step below
    the element step's (that run diverges)."""
    return make_law("hertz_crossed", phi_deg=90.0, E_pa=150 * 15e9, nu=0.3)


def test_the_substeps_follow_the_central_difference_bound():
    model, _ = six_fibers()
    rep = stable_time_step(model)
    dt = 0.9 * rep.dt_stable_s
    adaptive = AdaptiveStep(model, dt, 0.9, penalty_factor=0.1, penalty_dt_s=dt)
    assert adaptive.needed_substeps(0.0) == 1  # the beams and the plane penalty alone: the grid step
    m_min = float(np.min(model.mass))
    omega2 = max((2.0 / rep.per_mode_s[mode]) ** 2 for mode in ("shear", "bending")) + 4.0 * 0.1 / dt**2
    for k in (1e6, 1e7, 1e8):
        m = adaptive.needed_substeps(k)
        # (ω Δt/m)² ≤ 4 dt_safety² with ω² = ω_beam² + 2k/m_min + 4c/Δt_pen², and m − 1 would not do
        assert (omega2 + 2 * k / m_min) * (dt / m) ** 2 <= 4 * 0.81 * (1 + 1e-9)
        assert m == 1 or (omega2 + 2 * k / m_min) * (dt / (m - 1)) ** 2 > 4 * 0.81
    assert adaptive.needed_substeps(1e8) > 1


@pytest.mark.parametrize("law,q", [(six_fibers_law(name, kw), 1000.0) for name, kw in LAWS]
                         + [(six_fibers_law("scaled_stiffness", {"preset": "table1_phi2"}), 1000.0),
                            (_stiff_hertz(), 30.0)],
                         ids=[law_label(name, kw) for name, kw in LAWS] + ["table1_phi2", "hertz_crossed_150E"])
def test_six_fibers_create_no_energy_with_the_adaptive_step(law, q):
    model, effects = _scene(law, q)
    res = simulate(model, effects, SimulationSettings(end_time_s=2e-3, output_frames=3, history_every=20,
                                                      stable_step="adaptive"))
    assert _excess(res) < 0.01
    assert res.warnings == []


def test_a_law_too_stiff_for_the_element_step_diverges_there_and_runs_adaptive():
    model, effects = _scene(_stiff_hertz(), 30.0)
    with pytest.raises(SimulationDiverged):
        simulate(model, effects, SimulationSettings(end_time_s=2e-3, output_frames=3, history_every=20))
    model, effects = _scene(_stiff_hertz(), 30.0)
    res = simulate(model, effects, SimulationSettings(end_time_s=2e-3, output_frames=3, history_every=20,
                                                      stable_step="adaptive"))
    dt = res.history["dt_s"]
    # every row's sub-step is the grid step over a whole number, and the step shrank with the contact
    ratio = res.dt_s / dt
    assert np.allclose(ratio, np.round(ratio), rtol=1e-12) and dt.max() == res.dt_s and dt.min() < res.dt_s
    assert np.all(np.diff(dt) <= 0.0)  # it never grows
    assert math.isclose(res.frames_time[-1], res.steps * res.dt_s, rel_tol=1e-12)


def test_an_adaptive_run_resumed_from_a_checkpoint_is_the_same_bit_for_bit(tmp_path):
    law = six_fibers_law("scaled_stiffness", {"preset": "table1_phi2"})
    settings = dict(end_time_s=4e-4, output_frames=3, history_every=25, checkpoint_every=1000,
                    stable_step="adaptive")
    model, effects = _scene(law, 1000.0)
    saved = []
    ref = simulate(model, effects, SimulationSettings(**settings), on_checkpoint=saved.append)
    assert ref.history["dt_s"].min() < ref.dt_s and len(saved) >= 3  # the step changed before the checkpoints
    for k, ck in enumerate(saved):
        back = read_checkpoint(write_checkpoint(tmp_path / f"ck{k}.h5", ck, config_sha256="a"), config_sha256="a")
        model, effects = _scene(law, 1000.0)
        res = simulate(model, effects, SimulationSettings(**settings), resume=back)
        assert res.steps == ref.steps and np.array_equal(res.frames_positions, ref.frames_positions)
        for key in ref.history:
            assert np.array_equal(ref.history[key], res.history[key], equal_nan=True), key
        for name in ("x", "q", "v", "w", "acc"):
            assert np.array_equal(getattr(ref.final_state, name), getattr(res.final_state, name)), name
