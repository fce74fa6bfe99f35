"""Validation cases 2–7 on their quick variants (30-fiber networks and mats, a 20-fiber wavy bundle,
three seeds each): minutes on a shared 2-core machine, so behind ``-m slow`` (docs/validation.md).

The laws themselves are judged by ``make validate`` on the full specimens; here every row must be
measured (finite, over three seeds, with its fit range), and the rows that hold at any size must
pass: the loop's energy balance, friction stiffening the response, and the quasi-static bound."""

import math

import pytest

from fiberpipe.validation.registry import case_function

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", autouse=True)
def shared_work(tmp_path_factory):
    from fiberpipe.validation.compaction_runs import WORK

    WORK["dir"] = tmp_path_factory.mktemp("validate-quick")
    yield
    WORK["dir"] = None


@pytest.mark.parametrize("name", ["network_3d", "planar_mat", "wavy_bundle", "janssen"])
def test_law_rows_are_measured_over_three_seeds(name):
    rows = case_function(name)(quick=True)
    for row in rows:
        assert len(row.values) == 3 and all(math.isfinite(v) for v in row.values), (row.quantity, row.note)


def test_friction_cycle_balances_its_energy_and_friction_stiffens():
    shift, balance, area = case_function("friction_cycles")(quick=True)
    assert balance.passed, balance.values
    assert shift.passed, shift.values
    assert all(math.isfinite(v) for v in area.values)


def test_quick_compactions_are_quasi_static():
    speed, kinetic = case_function("quasi_static")(quick=True)
    assert kinetic.passed, kinetic.values
    assert all(math.isfinite(v) for v in speed.values)
