"""A load–unload–reload cycle with friction: the plates' net work over the closed loop is ≥ 0 and
equals the energy dissipated plus the change of the stored energy; post reports the cycle."""

import copy
import json

import numpy as np
import pytest
from _scenes import CYCLE_SCENE, run_small

from fiberpipe.post.history import load_simulation

START_M, TURN_M = 0.06e-3, 0.02e-3  # the loop: 0.06 mm → 0.02 mm → back to 0.06 mm


@pytest.fixture(scope="module")
def cycle_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("cycle")
    _, run = run_small(d, copy.deepcopy(CYCLE_SCENE), to="post")
    return run


def _loop_deltas(sim):
    """Each energy column's change over the closed loop, found here from the raw history: from the
    last row before the unloading move to the reloading's crossing of START_M (interpolated in U)."""
    h, e = sim.history, sim.energy
    seg = np.asarray(h["segment"]).astype(int)
    U = np.asarray(h["plate_displacement"])[:, 0]
    i0 = int(np.flatnonzero(seg == 1)[0]) - 1
    assert U[i0] == pytest.approx(START_M, rel=1e-9)
    assert U[seg == 1].min() == pytest.approx(TURN_M, rel=1e-6)
    reload = np.flatnonzero((seg == 2) & (U >= START_M))
    i1 = int(reload[0])
    w = (START_M - U[i1 - 1]) / (U[i1] - U[i1 - 1])

    def d(name):
        x = np.asarray(e[name], float)
        return float(x[i1 - 1] + w * (x[i1] - x[i1 - 1]) - x[i0])
    return {name: d(name) for name in ("external", "friction", "damping", "strain", "kinetic_leapfrog",
                                       "contact_stored")}


def test_closed_cycle_plate_work_is_dissipation_plus_stored_change(cycle_run):
    sim = load_simulation(cycle_run / "simulation.h5")
    d = _loop_deltas(sim)
    work = d["external"]  # no gravity, loads or drives: the plates' prescribed work alone
    dissipated = d["friction"] + d["damping"]
    stored = d["strain"] + d["kinetic_leapfrog"] + d["contact_stored"]
    assert work >= 0.0
    assert d["friction"] > 0.5 * work  # friction acts: most of the loop's work goes there
    assert abs(work - dissipated - stored) <= 0.02 * work, (work, dissipated, stored)


def test_post_reports_the_cycle_and_the_residual_strain(cycle_run):
    post = cycle_run / "post"
    s = json.loads((post / "summary.json").read_text())
    sim = load_simulation(cycle_run / "simulation.h5")
    d = _loop_deltas(sim)
    [c] = s["loading_cycles"]
    assert (c["first_segment"], c["start_U_m"], c["turn_U_m"]) == (1, pytest.approx(START_M), pytest.approx(TURN_M))
    assert c["plate_work_J"] == pytest.approx(d["external"], rel=1e-9)
    assert c["dissipated_J"] == pytest.approx(d["friction"] + d["damping"], rel=1e-9)
    [u] = s["unloadings"]
    F = np.asarray(sim.history["plate_force"])[:, 1]  # the load cell: the upper plate
    U = np.asarray(sim.history["plate_displacement"])[:, 0]
    seg = np.asarray(sim.history["segment"])
    rows = np.flatnonzero((seg == 1) & (F <= 0.01 * F.max()))
    assert u["residual_U_m"] == pytest.approx(U[rows[0]], rel=1e-12)
    assert u["residual_strain"] == pytest.approx(U[rows[0]] / s["plate_gap_m"], rel=1e-12)
    assert s["plate_gap_m"] == pytest.approx(0.12e-3 + 0.5e-3, rel=0.05)  # the tallest bow + 2 r
    for name in ("loading_cycles.csv", "unloadings.csv", "loops.png"):
        assert (post / name).exists(), name
    report = (post / "report.md").read_text()
    assert "## Loading cycles" in report and "residual strain" in report


def test_friction_gives_back_almost_nothing_over_the_cycle(cycle_run):
    """The simulate summary reports the energy the friction gave back (its contacts' negative
    dissipations): over the load reversals it stays a small part of what friction dissipated."""
    s = json.loads((cycle_run / "summary.json").read_text())["stages"]["simulate"]
    sim = load_simulation(cycle_run / "simulation.h5")
    fd = float(np.asarray(sim.energy["friction"])[-1])
    assert s["friction_returned_J"] >= 0.0
    assert s["friction_returned_over_dissipated"] == pytest.approx(s["friction_returned_J"] / fd)
    assert s["friction_returned_over_dissipated"] < 1e-3
