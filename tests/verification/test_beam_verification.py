"""docs/verification.md cases 1–4 (beam solver): quick variants in the default suite, full ones slow."""

import pytest

from fiberpipe.verification import CASES


@pytest.mark.parametrize("name", list(CASES))
def test_case_quick(name):
    row = CASES[name](quick=True)
    assert row.passed, row


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_case_full(name):
    row = CASES[name](quick=False)
    assert row.passed, row


def test_elastica_reference_small_load_limit():
    from fiberpipe.verification.cases import elastica_tip

    _, w = elastica_tip(1e-3)
    assert w == pytest.approx(1e-3 / 3, rel=1e-3)  # linear limit PL³/3EI


def test_cli_table_and_exit_status(capsys):
    from fiberpipe.verification.__main__ import main

    assert main(["--quick", "cantilever_small"]) == 0
    out = capsys.readouterr().out
    assert "PASS" in out and "cantilever small" in out
