"""SPEC 8 cases 5-8 through the dynamics (fiberpipe.verification.contact_cases).

Default suite: the quick variants; ``-m slow``: the full cases (longer settling, more loads, the
study's 15 mm beams and the slow rearrangement reference run).
"""

import pytest

from fiberpipe.verification.contact_cases import CONTACT_CASES, kinematic_uy, johnson_delta


def _check(rows):
    rows = rows if isinstance(rows, list) else [rows]
    assert rows
    for r in rows:
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


def test_references():
    # Johnson: 66 N/m → 32.05 nm (our fibres); kinematic rearrangement curve starts at 0
    assert johnson_delta(66.0) == pytest.approx(3.2049e-8, rel=1e-3)
    assert kinematic_uy(0.0) == pytest.approx(0.0, abs=1e-15)
    assert kinematic_uy(3**0.5 * 0.25e-3) == pytest.approx(0.25e-3)
