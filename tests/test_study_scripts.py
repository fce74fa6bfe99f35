"""The figures of the study scripts in benchmarks/ (fast_settings.py, contact_ensemble.py), on
synthetic curves with known answers: what they report about runs is what the runs held."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def ensemble():
    return _load("contact_ensemble")


@pytest.fixture(scope="module")
def fast():
    return _load("fast_settings")


def test_figures_of_a_known_curve(ensemble):
    """F = 0 up to 0.5 mm, then linear to 1 N at 1.15 mm: onsets and the final-window mean exact."""
    U = np.linspace(0, 1.15e-3, 2301)
    F = np.clip((U - 0.5e-3) / 0.65e-3, 0, None)
    f = ensemble.figures(U, F)
    assert f["peak"] == pytest.approx(1.0)
    # window means (0.05 mm) first above 2 % of their peak: within a window of the exact 0.513 mm
    assert f["rearrangement_end"] == pytest.approx(0.5e-3 + 0.02 * 0.65e-3, abs=0.05e-3)
    assert np.isnan(f["steep_start"])  # a straight rise after the onset: no steep phase
    # mean of a linear ramp over U = 1.10–1.15 mm: its value at 1.125 mm
    assert f["final"] == pytest.approx((1.125e-3 - 0.5e-3) / 0.65e-3, rel=1e-3)
    # reads: window means over ±0.025 mm (a ramp's mean is its middle value)
    assert f["reads"][3] == pytest.approx(0.5 / 0.65, abs=1e-3) and f["reads"][2] == pytest.approx(0.3 / 0.65, abs=1e-3)
    short = ensemble.figures(U[U <= 0.9e-3], F[U <= 0.9e-3])  # a run that stopped at 0.9 mm
    assert np.isnan(short["final"]) and np.isnan(short["reads"][3]) and np.isfinite(short["reads"][2])


def test_paired_difference(ensemble):
    a = np.array([1.1, 2.2, 3.3])
    b = np.array([1.0, 2.0, 3.0])
    m, se, t, p = ensemble.paired(a, b)
    d = 2 * 0.1 / 2.1  # the same relative difference for every pair: certain, not a 1e15 t from rounding
    assert m == pytest.approx(d) and se == pytest.approx(0.0, abs=1e-15) and t == np.inf and p == 0.0
    m, se, t, p = ensemble.paired(np.array([1.0, 2.0]), np.array([2.0, 1.0]))
    assert m == pytest.approx(0.0) and se == pytest.approx(2 / 3) and t == pytest.approx(0.0) and p == pytest.approx(1.0)
    # t = 1.225 with 3 degrees of freedom: two-sided p = 0.308 (Student's t table)
    d = np.array([0.1, 0.3, -0.1, 0.1])  # mean 0.1, s.d. 0.163, s.e. 0.0816: t = 1.22
    aa, bb = (2 + d) / (2 - d), np.ones(4)  # 2(a − b)/(a + b) = d
    m, se, t, p = ensemble.paired(aa, bb)
    assert m == pytest.approx(0.1) and t == pytest.approx(0.1 / (np.std(d, ddof=1) / 2))
    assert p == pytest.approx(0.309, abs=0.002)


def test_seed_ranges(ensemble):
    assert ensemble._seeds("0-3") == [0, 1, 2, 3]
    assert ensemble._seeds("0,5") == [0, 5]


def test_fast_settings_table_reads_the_requested_plate(fast):
    """A run equal to the reference on the load cell but 10 % off on the lower plate: the load-cell
    table gives 0 %, the lower-plate one 10 %."""
    U = np.linspace(0, 1.15e-3, 1000)
    F = U / 1.15e-3
    ref = {"U_curve": U, "F_curve": F, "F_cell_curve": F, "steps": 10, "wall_s": 1.0, "F_final_N": 1.0,
           "F_cell_final_N": 1.0}
    other = {**ref, "F_curve": 1.1 * F}
    runs = [(fast.REFERENCE[0], ref, None), ("candidate", other, None)]
    cell = fast._table(runs, "F_cell")[-1]
    lower = fast._table(runs, "F")[-1]
    assert "| 0.0 % | 0.00 % |" in cell
    assert "| 10.0 % | 10.00 % |" in lower
    # a run saved before the load cell was kept has no load-cell curve: reported, not invented
    old = {k: v for k, v in other.items() if not k.startswith("F_cell")}
    assert "| — |" in fast._table([(fast.REFERENCE[0], ref, None), ("old", old, None)], "F_cell")[-1]


def test_fast_settings_expected_curves(fast):
    """Three study runs scattered ±2 % around F and two twins of a candidate at 1.05 F: the mean
    curves differ by 5 %, whatever each single run's scatter."""
    U = np.linspace(0, 1.15e-3, 1000)
    F = U / 1.15e-3

    def run(scale):
        return {"U_curve": U, "F_curve": scale * F, "F_cell_curve": scale * F}

    runs = [(fast.REFERENCE[0], run(1.0), None),
            ("study settings, gravity × (1 + 1e-8) (chaotic floor)", run(1.02), None),
            ("study settings, gravity × (1 − 1e-8) (chaotic floor)", run(0.98), None),
            ("mass scaling 25, α = 4e3 1/s", run(1.05), None),
            ("mass scaling 25, α = 4e3 1/s, gravity × (1 + 1e-8) (twin)", run(1.05), None),
            ("velocity × 10", run(2.0), None)]  # one run only: no expected curve
    lines = fast._ensembles(runs, "F_cell")
    assert len(lines) == 3
    assert lines[2].startswith("| mass scaling 25, α = 4e3 1/s | 2 | 5.00 % | 5.00 % | 5.00 % |")


def test_box_volume_fraction(ensemble):
    """The study's 37.7 % box: 6.94 mm gap; its phase boundaries at U = 0.55 and 1.12 mm."""
    assert ensemble.STUDY_HEIGHT_M == pytest.approx(6.944e-3, rel=1e-3)
    assert ensemble.vf_at(0.0, 0.377, ensemble.STUDY_HEIGHT_M) == pytest.approx(0.377)
    assert ensemble.vf_at(1.12e-3, 0.377, ensemble.STUDY_HEIGHT_M) == pytest.approx(0.377 * 6.944 / 5.824, rel=1e-3)


def test_more_twins_join_their_settings(fast):
    names = [n for n, _ in fast._twins(3)]
    assert len(names) == 8
    fams = {fast._family(n) for n in names}
    assert fams == {fast._family(fast.REFERENCE[0]), "mass scaling 25, α = 4e3 1/s"}
    assert fast._twins(1) == []


def test_law_branch_table_reads_the_pairs():
    """benchmarks/law_branch.py: the paired rows come from the right columns (a +10 % law effect on
    every specimen, controls that differ by ±1 %), and chance is the controls' spread."""
    lb = _load("law_branch")
    figs = []
    for s, base in enumerate((0.5, 0.8, 1.0)):
        sign = 1 if s % 2 else -1
        figs.append({"seed": s, "branch_U_m": 0.95e-3, "unbranched": base, "control": base * (1 + 0.01 * sign),
                     "control_g": base, "parallel": base * 1.1, "oblique": base,
                     "parallel_delta_max_m": 0.3e-6, "oblique_delta_max_m": 0.5e-6, "control_delta_max_m": 0.6e-6})
    text = lb.table(figs)
    d = 2 * 0.1 / 2.1
    law_row = next(ln for ln in text.splitlines() if ln.startswith("| parallel − oblique"))
    assert f"{100 * d:+.2f} %" in law_row and "3 of 3" in law_row
    assert "| seed 1 | 0.800 | 0.808 | 0.800 | 0.880 | 0.800 | +9.5 % | 0.30 / 0.50 / 0.60 |" in text
    chance = 2 * 0.01 / 2.01  # |control_g − control| relative, the same on every specimen
    assert f"median {100 * chance:.1f} %" in text and "from the same state at U = 0.95 mm" in text
