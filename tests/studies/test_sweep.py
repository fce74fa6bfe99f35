"""A small study end to end: points run (cached), errors against the reference, table and plot."""

import csv

import pytest

from fiberpipe.errors import ConfigError, FiberpipeError
from fiberpipe.studies.sweep import load_study, run_study

BASE = """
name: tiny-cantilever
input:
  polylines:
    - [[0, 0, 0], ["6 mm", 0, 0]]
mesh: {element_length: "0.5 mm"}
fiber: {radius: "0.25 mm"}
scene:
  effects: [clamps, loads, damping]
  clamps: [{fiber: 0, at: start}]
  loads: [{fiber: 0, at: end, force: [0, 0, "-1 mN"]}]
  damping: {alpha: "2e4 1/s"}
solver: {end_time: "0.5 ms", output_frames: 3}
"""

STUDY = """
name: dt-safety
base: base.yaml
sweep:
  solver.dt_safety: [0.5, 0.9]
reference:
  overrides: {solver.dt_safety: 0.25}
measures: [positions]
"""


def test_study_runs_points_and_writes_table(tmp_path):
    (tmp_path / "base.yaml").write_text(BASE)
    (tmp_path / "study.yaml").write_text(STUDY)
    out = run_study(tmp_path / "study.yaml", tmp_path / "out", echo=lambda s: None)
    rows = list(csv.DictReader((out / "study.csv").open()))
    assert [r["solver.dt_safety"] for r in rows] == ["0.5", "0.9"]
    for r in rows:
        err = float(r["position_error"])
        assert 0 <= err < 1e-2  # the same physics at another stable step: tiny differences
        assert int(r["steps"]) > 0 and float(r["wall_time_s"]) > 0
    assert int(rows[0]["steps"]) > int(rows[1]["steps"])  # the smaller step takes more steps
    assert (out / "pareto.png").exists() and (out / "study.md").exists()
    # each point keeps its own config, which its summary (and an interrupted run's resume command)
    # names: running it again is the same run, up to date
    import json

    from click.testing import CliRunner

    from fiberpipe.cli import main

    point = out / "points" / rows[0]["id"]
    assert json.loads((point / "summary.json").read_text())["config"] == str(point / "config.yaml")
    again = CliRunner().invoke(main, ["run", str(point / "config.yaml"), "--out", str(point)])
    assert again.exit_code == 0 and "simulate     up to date" in again.output, again.output


def test_study_with_a_bad_key_fails_before_running(tmp_path):
    (tmp_path / "base.yaml").write_text(BASE)
    (tmp_path / "study.yaml").write_text(STUDY.replace("solver.dt_safety: [0.5, 0.9]", "solver.dt_safty: [0.5]"))
    with pytest.raises(ConfigError, match="dt_safty"):
        run_study(tmp_path / "study.yaml", tmp_path / "out", echo=lambda s: None)
    assert not (tmp_path / "out" / "points").exists() or not any((tmp_path / "out" / "points").iterdir())


@pytest.mark.parametrize("sweep,message", [
    ("mesh.element_length.x: [0.9]", r"'mesh.element_length.x': 'mesh.element_length' is a value"),
    ("scene.clamps.5.at: [end]", r"'scene.clamps.5.at': 'scene.clamps' is a list of 1; '5' is not one of its indices"),
    ("scene.clamps.x.at: [end]", r"'x' is not one of its indices"),
    ("solver.dt_safety: []", r"sweep.solver.dt_safety has no values"),
    ("{}", r"sweep has no keys"),
])
def test_a_sweep_key_that_cannot_be_set_fails_before_running(tmp_path, sweep, message):
    """A sweep key that walks into a value or past a list's end, or a key without values, is one
    ConfigError naming it, before any run (not a traceback, not a study of no points)."""
    (tmp_path / "base.yaml").write_text(BASE)
    text = STUDY.replace("sweep:\n  solver.dt_safety: [0.5, 0.9]", "sweep: {}" if sweep == "{}" else "sweep:\n  " + sweep)
    (tmp_path / "study.yaml").write_text(text)
    with pytest.raises(ConfigError, match=message):
        run_study(tmp_path / "study.yaml", tmp_path / "out", echo=lambda s: None)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("reference,message", [
    ("reference:\n  run: nope/simulation.h5", "reference run not found"),
    ("reference:\n  run: base.yaml", "base.yaml"),
    ("reference:\n  extrapolate: {key: solver.dt_safety, order: 0}", "order must be > 0"),
])
def test_a_reference_that_cannot_serve_fails_before_running(tmp_path, reference, message):
    """A reference run that is missing or not a simulation artifact, or an extrapolation order that
    is not positive, fails before the points run (they took minutes for nothing)."""
    (tmp_path / "base.yaml").write_text(BASE)
    (tmp_path / "study.yaml").write_text(STUDY.replace("reference:\n  overrides: {solver.dt_safety: 0.25}", reference))
    with pytest.raises((ConfigError, FiberpipeError), match=message):
        run_study(tmp_path / "study.yaml", tmp_path / "out", echo=lambda s: None)
    assert not (tmp_path / "out").exists()


def test_a_bad_reference_override_is_named_as_such(tmp_path):
    (tmp_path / "base.yaml").write_text(BASE)
    (tmp_path / "study.yaml").write_text(STUDY.replace("{solver.dt_safety: 0.25}", "{solver.bogus: 1}"))
    with pytest.raises(ConfigError, match=r"reference.overrides \{'solver.bogus': 1\}"):
        run_study(tmp_path / "study.yaml", tmp_path / "out", echo=lambda s: None)


def test_unknown_study_key(tmp_path):
    (tmp_path / "study.yaml").write_text(STUDY + "colour: red\n")
    with pytest.raises(ConfigError, match="colour"):
        load_study(tmp_path / "study.yaml")


@pytest.mark.parametrize("extra,key,line", [
    ("  solver.dt_safety: [0.3]\n", "solver.dt_safety", 5),  # a sweep key twice: its first values were dropped
    ("measures: [curve]\n", "measures", 8),
])
def test_duplicate_study_key_is_refused(tmp_path, extra, key, line):
    (tmp_path / "base.yaml").write_text(BASE)
    text = STUDY.replace("reference:", extra + "reference:") if extra.startswith("  ") else STUDY + extra
    (tmp_path / "study.yaml").write_text(text)
    with pytest.raises(ConfigError, match=rf"duplicate key '{key}' at line \d+ \(first given at line {line}\)"):
        load_study(tmp_path / "study.yaml")


def test_docstring_example_base_exists():
    import re
    from pathlib import Path

    import fiberpipe.studies.sweep as sweep

    base = re.search(r"^\s*base: (\S+)", sweep.__doc__, re.M).group(1)
    studies = Path(__file__).resolve().parents[2] / "configs" / "studies"
    assert (studies / base).is_file(), base


def test_points_get_the_threads_their_solver_asks_for(monkeypatch):
    """numba reads NUMBA_NUM_THREADS once, when it starts: a study started without it must set it to
    the largest solver.threads of its points (here 2), else a solver.threads: 2 point runs on one
    thread; a value the user set stays."""
    import os

    from fiberpipe.studies import sweep

    assert sweep.numba_threads([{}, {"solver": {"dt_safety": 0.9}}]) == "1"
    assert sweep.numba_threads([{"solver": {"threads": 2}}, {}]) == "2"
    jobs = [("a", {"solver": {"threads": 2}}, "run-a"), ("b", {}, "run-b")]

    def seen(raw, run_dir, where):
        return {"wall_time_s": 0.0, "threads": os.environ["NUMBA_NUM_THREADS"]}

    monkeypatch.setenv("NUMBA_NUM_THREADS", "unset")  # restored after the test
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    got = sweep._execute(jobs, 1, None, "study", lambda *_: None, fn=seen)
    assert [got[k]["threads"] for k in "ab"] == ["2", "2"]
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    got = sweep._execute(jobs, 1, None, "study", lambda *_: None, fn=seen)
    assert [got[k]["threads"] for k in "ab"] == ["1", "1"]


def test_a_study_whose_errors_are_all_zero_still_plots(tmp_path):
    """Points equal to the reference (errors 0): linear error axis instead of a log one that
    matplotlib refuses ('Data cannot be log-scaled'), and no warning leaks into the output."""
    import warnings

    from fiberpipe.studies.sweep import _write_outputs

    (tmp_path / "base.yaml").write_text(BASE)
    (tmp_path / "study.yaml").write_text(STUDY)
    spec, _ = load_study(tmp_path / "study.yaml")
    rows = [{"solver.dt_safety": str(v), "position_error": 0.0, "wall_time_s": w, "steps": 10, "id": f"p{v}"}
            for v, w in ((0.5, 2.0), (0.9, 1.0))]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _write_outputs(tmp_path, spec, rows, {"solver_wall_time_s": 3.0, "steps": 20}, echo=lambda s: None)
    assert (tmp_path / "pareto.png").stat().st_size > 0 and (tmp_path / "study.csv").exists()
