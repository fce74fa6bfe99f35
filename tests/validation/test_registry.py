"""fiberpipe validate: the case registry, its one-line errors, and the summary, table and docs section it writes."""

import json
import math

import pytest
from click.testing import CliRunner

from fiberpipe.cli import main
from fiberpipe.errors import FiberpipeError
from fiberpipe.validation.registry import CASES, case_function, run_cases, table_markdown, write_outputs
from fiberpipe.validation.rows import ValidationRow


def test_every_registered_case_has_a_validate_function():
    for name in CASES:
        assert callable(case_function(name))


def test_unknown_case_is_a_one_line_error_naming_the_cases():
    with pytest.raises(FiberpipeError, match="unknown case 'nope'; the cases are wavy_fiber, network_3d"):
        run_cases(["nope"])
    result = CliRunner().invoke(main, ["validate", "nope"])
    assert result.exit_code != 0
    assert result.output.count("\n") == 1 and "unknown case 'nope'" in result.output


def test_row_judged_on_the_mean_and_spread_flagged():
    row = ValidationRow("c", "q", 3.0, [2.0, 3.0, 4.3], 1 / 3, "src")
    assert row.measured == pytest.approx(3.1) and row.passed
    assert row.spread == pytest.approx(1.15) and row.spread_exceeds_tolerance
    bound = ValidationRow("c", "ratio", 0.0, [0.04, 0.07], 0.05, "src", relative=False)
    assert bound.error == pytest.approx(0.055) and not bound.passed and bound.status == "FAIL"


def test_outputs_written_and_docs_section_replaced(tmp_path):
    summary = {"quick": True, "passed": 1, "checked": 1, "cases": {"wavy_fiber": {
        "description": "d", "wall_time_s": 1.0,
        "rows": [ValidationRow("1 wavy", "K", 10.0, [10.1], 0.03, "beam", unit="N/m").as_dict()]}}}
    page = tmp_path / "page.md"
    page.write_text("intro\n<!-- validation: begin x -->\nold\n<!-- validation: end -->\nafter\n")
    write_outputs(summary, tmp_path / "out", docs_page=page)
    text = page.read_text()
    assert text.startswith("intro\n") and text.endswith("after\n") and "\nold\n" not in text
    assert "| 1 wavy | K | 10 N/m | beam | 10.1 N/m (1) | 1 % | 3 % | PASS |" in text
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["cases"]["wavy_fiber"]["rows"][0]["passed"]
    assert table_markdown(summary) in (tmp_path / "out" / "validation.md").read_text()


def test_bad_seeds_are_a_one_line_error():
    result = CliRunner().invoke(main, ["validate", "--seeds", "0,x", "wavy_fiber"])
    assert result.exit_code != 0 and result.output.count("\n") == 1 and "--seeds must be integers" in result.output


def test_quick_row_passes_inside_its_bounds_and_fails_outside_or_when_not_finite():
    inside = ValidationRow("c", "n", 3.0, [12.0], 1 / 3, "src", bounds=(1.0, 20.0))
    assert inside.passed and inside.status == "PASS" and not inside.spread_exceeds_tolerance
    assert not ValidationRow("c", "n", 3.0, [-2.0], 1 / 3, "src", bounds=(1.0, 20.0)).passed  # wrong sign
    assert not ValidationRow("c", "n", 3.0, [25.0], 1 / 3, "src", bounds=(1.0, 20.0)).passed
    assert not ValidationRow("c", "n", 3.0, [float("nan")], 1 / 3, "src", bounds=(1.0, 20.0)).passed
    assert "1 to 20 (quick)" in table_markdown({"cases": {"x": {"rows": [inside.as_dict()]}}})


def test_quick_variants_run_one_seed_and_full_cases_three_unless_seeds_are_given():
    from fiberpipe.validation.compaction_runs import SEEDS, seeds_for

    saved = SEEDS["seeds"]
    try:
        SEEDS["seeds"] = None
        assert seeds_for(quick=True) == [0] and seeds_for(quick=False) == [0, 1, 2]
        SEEDS["seeds"] = (4, 5)
        assert seeds_for(quick=True) == [4, 5] and seeds_for(quick=False) == [4, 5]
    finally:
        SEEDS["seeds"] = saved


def test_inverse_width_extrapolation_recovers_the_bulk_value():
    from fiberpipe.validation.wall_correction import extrapolate_inverse_width

    widths = [3.75e-3, 7.5e-3, 15e-3]
    bulk, slope = extrapolate_inverse_width(widths, [25.0 + 0.03 / w for w in widths])
    assert bulk == pytest.approx(25.0, rel=1e-9) and slope == pytest.approx(0.03, rel=1e-9)


def test_wall_correction_states_the_bulk_value_and_the_case_widths_offset():
    from fiberpipe.validation.wall_correction import extrapolated

    widths = [3.75e-3, 7.5e-3, 15e-3]
    figures = [[{"width_m": w, "beta": 160.0 - 0.2 / w} for w in widths]]
    limits, corrections, values = extrapolated(figures, "beta", 7.5e-3)
    assert limits[0] == pytest.approx(160.0)
    assert corrections[0] == pytest.approx((160.0 - 0.2 / 7.5e-3) / 160.0 - 1)
    nan_seed = [[{"width_m": w, "beta": float("nan")} for w in widths]]
    assert math.isnan(extrapolated(nan_seed, "beta", 7.5e-3)[0][0])
