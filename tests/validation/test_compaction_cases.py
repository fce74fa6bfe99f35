"""Validation cases 2–7 on their quick variants (24-fiber networks and mats, a 20-fiber wavy bundle,
one seed, three times the loading speed): each row is measured, finite, and inside its quick
tolerance, the physical range stated in the case's module (``QUICK_BOUNDS``).

The laws themselves are judged by ``make validate`` on the full specimens over three seeds
(docs/validation.md)."""

import math

import pytest

from fiberpipe.validation.registry import case_function


@pytest.fixture(scope="module", autouse=True)
def shared_work(tmp_path_factory):
    from fiberpipe.validation.compaction_runs import SEEDS, WORK

    WORK["dir"], SEEDS["seeds"] = tmp_path_factory.mktemp("validate-quick"), None
    yield
    WORK["dir"] = None


@pytest.mark.parametrize("name", ["network_3d", "planar_mat", "wavy_bundle", "janssen", "friction_cycles",
                                  "quasi_static", "wall_correction"])
def test_quick_variant_rows_are_finite_and_within_their_quick_tolerance(name):
    rows = case_function(name)(quick=True)
    for row in rows:
        if row.informational:  # stated, not judged (the walls' share of case 8)
            assert all(math.isfinite(v) for v in row.values), (row.quantity, row.note)
            continue
        assert row.bounds is not None, row.quantity
        assert len(row.values) == 1 and all(math.isfinite(v) for v in row.values), (row.quantity, row.note)
        assert row.passed, (row.quantity, row.values, row.bounds, row.note)
