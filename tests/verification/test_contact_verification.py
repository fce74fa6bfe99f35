"""docs/verification.md cases 5-8 through the dynamics (fiberpipe.verification.contact_cases).

Default suite: the quick variants; ``-m slow``: the full cases (longer settling, more loads, the
study's 15 mm beams and the slow rearrangement reference run).

Checked rows must pass. Informational rows (``Row.informational``: comparisons the code is known
not to reproduce, printed as such by ``python -m fiberpipe.verification``) are held to their
measured behaviour instead, so a change in it (better or worse) shows up here.
"""

import pytest

from fiberpipe.verification.contact_cases import CONTACT_CASES, johnson_delta, johnson_line_load, kinematic_uy


def _check_informational(r):
    if r.case.startswith("rearrangement α = 0"):
        d = r.data
        # measured (quick): curve error 2.96 %, contact with beam 1 lost in 60/61 frames (gap ≤ 2.9 % r)
        assert not r.passed and 0.01 < d["curve_error"] < 0.05, (
            f"undamped rearrangement: curve error {100 * d['curve_error']:.3f} % (measured 2.1 %, inside the 5 % band: "
            f"the study's departure not reproduced); if it now exceeds 5 %, make the row a checked one ({r.note})")
        assert d["curve_error"] > 10 * d["damped_curve_error"], r.note  # measured 2.96 % against 0.11 %
        assert d["frames_contact_lost"] > d["frames"] // 2 and 0 < d["max_gap_m"] < 0.05 * 0.25e-3, (
            f"undamped rearrangement: beams 2/3 off beam 1 in {d['frames_contact_lost']}/{d['frames']} frames, "
            f"gap up to {d['max_gap_m'] * 1e6:.3g} µm (measured 55/61 frames, 6.1–6.2 µm)")
    elif r.case.startswith("3-beam static α = 0") and "energy residual" in r.case:
        resid = r.data["max_abs_residual"]
        # measured over 16 T at the default step: 0.06–0.09 (quick), 0.057–0.074 (full); the energy goes
        # missing (the checked row "energy gained" holds it ≤ 1 % above the loads' work)
        assert 0.01 < resid < 0.15, (
            f"undamped 3-beam case: |residual| up to {resid:.3g} (measured 0.06–0.09 at the default step); "
            f"if it is now within 1e-2, make the row a checked one ({r.note})")
    elif r.case.startswith("3-beam static α = 0"):
        lo, hi = r.data["rf_over_ref"]
        # measured (quick): RF error 59 % over the last quarter of 0.6 ms
        assert not r.passed and r.error > 0.05 and lo < 0.95 and hi > 1.05, (
            f"undamped 3-beam case from the set-up: RF/ref ∈ [{lo:.3f}, {hi:.3f}] over the last quarter, "
            f"error {100 * r.error:.2f} %; if it now settles within 1 %, make the row a checked one ({r.note})")
    else:
        raise AssertionError(f"unexpected informational row {r.case!r}: {r.note}")


def _check(rows):
    rows = rows if isinstance(rows, list) else [rows]
    assert rows
    for r in rows:
        if r.informational:
            _check_informational(r)
            continue
        assert r.passed, f"{r.case}: reference {r.reference:.6g}, measured {r.measured:.6g}, error {r.error:.3g} ≥ {r.tolerance} ({r.note})"


QUICK = ["contact_parallel", "contact_crossed_2", "contact_crossed_6", "contact_crossed_10", "contact_crossed_90",
         "three_beam_static", "friction_inclined_stick", "friction_inclined_slide", "sliding_parallel",
         "rearrangement"]


@pytest.mark.parametrize("name", QUICK)
def test_contact_case_quick(name):
    _check(CONTACT_CASES[name](quick=True))


@pytest.mark.slow
@pytest.mark.parametrize("name", QUICK)
def test_contact_case_full(name):
    _check(CONTACT_CASES[name](quick=False))


def test_three_beam_static_uses_the_setup_angle_and_can_fail():
    """β₀ is the set-up's 30°, not the settled β; the settled one differs by ~0.1° (the plate's and
    walls' penalty onset lets the lower beams in by up to δ_s/2 = 2.5 µm)."""
    rows = CONTACT_CASES["three_beam_static"](quick=True, alphas=(1e5,))
    d = rows[0].data
    assert d["beta0_deg"] == pytest.approx(30.0, abs=1e-9)
    assert 0 < abs(d["settled_beta_minus_beta0_deg"]) < 0.15, d
    assert all(r.passed and not r.informational and r.error > 0 for r in rows), [r.note for r in rows]


def test_references():
    # Johnson: 66 N/m → 32.05 nm (our fibers) and back; kinematic rearrangement curve starts at 0
    assert johnson_delta(66.0) == pytest.approx(3.2049e-8, rel=1e-3)
    assert johnson_line_load(3.2049e-8) == pytest.approx(66.0, rel=1e-3)
    assert kinematic_uy(0.0) == pytest.approx(0.0, abs=1e-15)
    assert kinematic_uy(3**0.5 * 0.25e-3) == pytest.approx(0.25e-3)


def test_table_marks_informational_rows_and_exit_status_ignores_them(monkeypatch, capsys):
    from fiberpipe.verification import __main__ as vm
    from fiberpipe.verification.cases import Row

    rows = [Row("checked", 1.0, 1.001, 1e-3, 0.01),
            Row("departs", 1.0, 1.02, 0.02, 0.05, must_exceed=True, informational=True, note="2 % only")]
    assert rows[0].passed and not rows[1].passed
    assert Row("departs", 1.0, 1.1, 0.1, 0.05, must_exceed=True).passed
    monkeypatch.setattr(vm, "run_all", lambda quick=False, only=None, residuals=None: rows)
    assert vm.main([]) == 0
    out = capsys.readouterr().out
    assert "NOT REPRODUCED (info)" in out and "> 5 %" in out and "2 % only" in out
    assert "1/1 passed; informational (not counted): 1 row, 1 not reproduced" in out
    rows.append(Row("broken", 1.0, 2.0, 1.0, 0.01))
    assert vm.main([]) == 1


def test_parallel_contact_closes_its_state_function_balance_within_1e_3():
    """The suddenly pressed pair under α Δt = 0.16: its residual is the step's slow drift (2.5e-4),
    not the O(αΔt) swing a damping booked out of step with the leapfrog term leaves (1.7e-3)."""
    from fiberpipe.verification.energy_residual import recording

    with recording() as runs:
        CONTACT_CASES["contact_parallel"](quick=True)
    assert len(runs) == 1 and runs[0] < 1e-3, runs


def test_two_degree_crossing_with_the_point_law_closes_its_balance_within_1e_3():
    """The 2° crossing runs the point law (blend_length 1 mm), whose crossing sits near element
    joints of both fibers: the smooth joint share keeps it conservative (6.7e-5); the share that
    switched without a force gained 1.0e-2 at the first contact."""
    from fiberpipe.verification.energy_residual import recording

    with recording() as runs:
        CONTACT_CASES["contact_crossed_2"](quick=True)
    assert len(runs) == 1 and runs[0] < 1e-3, runs


def test_residual_table_flags_the_runs_above_the_tolerance():
    from fiberpipe.verification.energy_residual import format_residuals

    text = format_residuals({"a": [1e-5, 2e-3], "b": [1e-4], "c": []})
    assert "| a | 2 | 1e-05, 0.002 | 1 of 2 |" in text and "| b | 1 | 0.0001 | yes |" in text
    assert "| c |" not in text
