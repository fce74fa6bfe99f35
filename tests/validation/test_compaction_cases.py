"""Validation cases 2–7 on their quick variants (30-fiber networks and mats, a 20-fiber wavy bundle,
three seeds each): minutes on a shared 2-core machine, so behind ``-m slow`` (docs/validation.md).

The laws themselves are judged by ``make validate`` on the full specimens; here every row must be
measured: finite, over three seeds (docs/validation.md says which rows the small specimens fail,
and why)."""

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


@pytest.mark.parametrize("name", ["friction_cycles", "quasi_static"])
def test_cycle_and_speed_rows_are_measured_over_three_seeds(name):
    for row in case_function(name)(quick=True):
        assert len(row.values) == 3 and all(math.isfinite(v) for v in row.values), row.quantity
