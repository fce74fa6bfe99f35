"""Specimen ensembles (``specimen.seeds``, ``--seeds``): the mean and band are the members' own
statistics, finished runs are reused, a killed Dask worker loses nothing, bad seeds and an
unreachable scheduler are refused with one line."""

import csv
import json
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fiberpipe.cli import main
from fiberpipe.errors import ConfigError
from fiberpipe.studies.ensemble import (collect_ensemble, ensemble_seeds, parse_seeds_option, run_ensemble, run_ensembles,
                                        run_member, specimen_key)

# four fibers of 4 mm on 1 mm elements, deposited without settling, compacted by 0.05 mm: ≈ 1 s a run
TINY = {
    "name": "tiny",
    "mesh": {"element_length": "1 mm"},
    "material": {"youngs_modulus": "15 GPa", "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
    "fiber": {"radius": "0.25 mm"},
    "scene": {"effects": ["gravity", "damping", "contact", "friction", "plates", "walls"],
              "damping": {"alpha": "3e4 1/s"}, "friction": {"mu": 0.2},
              "plates": {"axis": "y", "lower": "moving", "upper": "fixed"}, "walls": {"x": ["-0.75 mm", "0.75 mm"]},
              "loading": {"displacement": "0.05 mm", "velocity": "10000 mm/min", "ramp": "smooth", "ramp_fraction": 0.1}},
    "solver": {"output_frames": 3, "dt_safety": 0.5},
    "post": {"plots": False},
    "specimen": {"n_fibers": 4, "length": "4 mm", "width": "1.5 mm", "volume_fraction": 0.2, "candidates": 1,
                 "points_per_fiber": 9, "upper_plate": "pile", "settle": {"enabled": False}, "seeds": [0, 1]},
}


def _curve(run_dir):
    rows = list(csv.DictReader((Path(run_dir) / "post" / "force_displacement.csv").open()))
    U = np.array([float(r["U_m"]) for r in rows])
    F = np.array([float(r["load_N"]) for r in rows])
    end = int(np.argmax(U)) + 1
    Uu, inv = np.unique(U[:end], return_inverse=True)
    return Uu, np.bincount(inv, weights=F[:end]) / np.bincount(inv)


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The ensemble of seeds 0-2 run one member after the other in this process: (folder, summary)."""
    out = tmp_path_factory.mktemp("serial") / "ens"
    return out, run_ensemble(TINY, [0, 1, 2], out, workers=1, echo=lambda *_: None)


def test_ensemble_reports_the_members_mean_and_band_and_reuses_finished_runs(serial):
    out, summary = serial
    assert summary["seeds"] == [0, 1, 2]
    table = list(csv.DictReader((out / "ensemble.csv").open()))
    grid = np.array([float(r["U_m"]) for r in table])
    loads, finals = [], []
    for seed in (0, 1, 2):
        U, F = _curve(out / f"seed-{seed}")  # each member's own curve, read here from its run folder
        loads.append(np.interp(grid, U, F))
        finals.append(F[-1])
        info = json.loads((Path(summary["specimens"][seed]) / "specimen.json").read_text())
        assert summary["v_f0"][seed] == info["volume_fraction"]
        assert info["generator"]["seed"] == seed
    loads = np.array(loads)
    np.testing.assert_allclose([float(r["load_mean_N"]) for r in table], loads.mean(axis=0), rtol=1e-6, atol=1e-12)  # the CSV keeps 9 digits
    np.testing.assert_allclose([float(r["load_sd_N"]) for r in table], loads.std(axis=0, ddof=1), rtol=1e-6, atol=1e-12)
    assert summary["final_load_N"] == pytest.approx(finals, rel=1e-9)
    assert summary["final_load_mean_N"] == pytest.approx(float(np.mean(finals)), rel=1e-9)
    assert json.loads((out / "summary.json").read_text())["ensemble"] == json.loads((out / "ensemble.json").read_text())
    assert (out / "ensemble.png").stat().st_size > 0
    assert len({tuple(row) for row in loads}) == 3  # three specimens, three curves
    # a rerun reuses every run and specimen (no file rewritten); a new seed runs only itself
    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("simulation.h5")} | \
             {p: p.stat().st_mtime_ns for p in out.rglob("fibers.h5")}
    again = run_ensemble(TINY, [2, 0], out, workers=1, echo=lambda *_: None)
    assert again["final_load_N"] == pytest.approx([summary["final_load_N"][2], summary["final_load_N"][0]], rel=1e-9)
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items())


def test_collecting_finished_runs_gives_the_ensemble_they_ran_and_names_a_missing_seed(serial, tmp_path):
    import shutil

    out, summary = serial
    copy = tmp_path / "copy"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("ensemble*", "summary.json"))
    collected = collect_ensemble(copy, [0, 1, 2], echo=lambda *_: None)
    for key in ("seeds", "v_f0", "final_load_N", "final_load_mean_N", "final_load_sd_N", "specimens"):
        assert collected[key] == summary[key], key
    assert (copy / "ensemble.csv").is_file()
    assert collect_ensemble(copy, [0, 5], echo=lambda *_: None) == {
        "error": f"seed 5: no finished run in {copy / 'seed-5'}", "seeds": [0, 5]}


def test_variants_that_differ_only_in_their_compaction_share_specimens():
    other = yaml.safe_load(yaml.safe_dump(TINY))
    other["scene"]["loading"]["displacement"] = "0.1 mm"
    other["scene"]["damping"]["alpha"] = "1e3 1/s"
    other["solver"]["mass_scaling"] = 100
    other["solver"]["stable_step"] = "adaptive"
    assert specimen_key(other) == specimen_key(TINY)
    from fiberpipe.model.specimen_settle import settle_scene  # what the key leaves out, the settling does not read

    stepped = yaml.safe_load(yaml.safe_dump(TINY))
    stepped["solver"]["stable_step"] = "adaptive"
    settings = dict(width_m=1.5e-3, alpha_per_s=300.0, time_s=0.1, mu=0.2, lock="all", frames=3, mass_scaling=100.0)
    assert settle_scene(stepped, **settings) == settle_scene(TINY, **settings)
    for key, value in (("specimen.n_fibers", 5), ("specimen.seed", 3), ("scene.contact", {"law": "linear"}),
                       ("mesh.element_length", "0.5 mm")):
        changed = yaml.safe_load(yaml.safe_dump(TINY))
        section, name = key.split(".")
        changed.setdefault(section, {})[name] = value
        assert specimen_key(changed) != specimen_key(TINY), key
    # with the settling's own contact law, the compaction's is not the specimen's
    own = yaml.safe_load(yaml.safe_dump(TINY))
    own["specimen"]["settle"]["contact"] = {"law": "hertz_oriented"}
    other_law = yaml.safe_load(yaml.safe_dump(own))
    other_law["scene"]["contact"] = {"law": "linear", "stiffness": 1e6}
    assert specimen_key(other_law) == specimen_key(own) != specimen_key(TINY)


def _unreachable_at_seed_1(raw, run_dir, where, specimen_store):
    """The member's task, but seed 1's input is refused as a pile that cannot be closed is."""
    from fiberpipe.studies import ensemble

    if raw["specimen"]["seed"] == 1:
        raise ConfigError("specimen.volume_fraction = 0.9: closing the cassette does not reach it", where=where)
    return ensemble.run_member(raw, run_dir, where, specimen_store)


def test_keep_going_reports_a_refused_ensemble_and_finishes_the_others(tmp_path):
    # ensembles named by their folders (names with slashes)
    good, bad = str(tmp_path / "good"), str(tmp_path / "bad")
    results = run_ensembles({good: (TINY, [0], tmp_path / "good"), bad: (TINY, [0, 1], tmp_path / "bad")},
                            workers=1, echo=lambda *_: None, member=_unreachable_at_seed_1, keep_going=True)
    assert results[bad]["seeds"] == [0, 1]
    assert results[bad]["error"].startswith("seed 1: ") and "volume_fraction = 0.9" in results[bad]["error"]
    assert not (tmp_path / "bad" / "ensemble.json").exists()
    assert results[good]["seeds"] == [0] and (tmp_path / "good" / "ensemble.json").is_file()
    with pytest.raises(ConfigError, match="does not reach it"):  # without keep_going the error ends the pass
        run_ensembles({"bad": (TINY, [1], tmp_path / "bad2")}, workers=1, echo=lambda *_: None,
                      member=_unreachable_at_seed_1)


def _killed_once(raw, run_dir, where, specimen_store, marker):
    """The member's task, but the first attempt at seed 1 builds its specimen and then dies as a
    worker process does under kill -9 (SIGKILL: no clean-up, no reply to the scheduler)."""
    from fiberpipe.studies import ensemble

    seed = raw["specimen"]["seed"]
    with open(Path(marker).with_suffix(".log"), "a") as log:
        log.write(f"{seed} {os.getpid()}\n")
    if seed == 1 and not Path(marker).exists():
        specimen_dir = Path(specimen_store) / f"seed-1-{ensemble.specimen_key(raw)}"
        specimen_dir.parent.mkdir(parents=True, exist_ok=True)
        ensemble.build_member_specimen(raw, specimen_dir, where)
        Path(marker).write_text(str((specimen_dir / "fibers.h5").stat().st_mtime_ns))
        os.kill(os.getpid(), signal.SIGKILL)
    return ensemble.run_member(raw, run_dir, where, specimen_store)


def test_a_worker_killed_mid_run_loses_nothing_on_a_two_worker_local_cluster(tmp_path, serial):
    import functools

    import cloudpickle

    distributed = pytest.importorskip("dask.distributed")
    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import this test module
    marker = tmp_path / "killed"
    out = tmp_path / "ens"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  env={"NUMBA_NUM_THREADS": "1"}) as cluster:
        summary = run_ensembles({"tiny": (TINY, [0, 1, 2], out)}, scheduler=cluster.scheduler_address,
                                echo=lambda *_: None, member=functools.partial(_killed_once, marker=str(marker)))["tiny"]
    attempts = [line.split() for line in marker.with_suffix(".log").read_text().splitlines()]
    seed1_pids = [pid for seed, pid in attempts if seed == "1"]
    assert len(seed1_pids) >= 2 and seed1_pids[0] != seed1_pids[-1]  # killed, then run again elsewhere
    # the specimen the killed attempt finished is the one the rerun compacted (not rebuilt)
    fibers = Path(summary["specimens"][1]) / "fibers.h5"
    assert fibers.stat().st_mtime_ns == int(marker.read_text())
    assert summary["seeds"] == [0, 1, 2] and len(summary["final_load_N"]) == 3
    reference = serial[1]  # the same members run in this process: the same loads
    assert summary["final_load_N"] == pytest.approx(reference["final_load_N"], rel=1e-9, abs=1e-15)
    assert summary["v_f0"] == reference["v_f0"]


@pytest.mark.parametrize("seeds, words", [
    ("", "--seeds is empty"),
    ("1,2,1", "--seeds gives seed 1 more than once"),
    ("0", "the number of seeds must be at least 1"),
    ("a,b", "expected a number of seeds"),
])
def test_bad_seeds_options_are_refused_with_one_line(tmp_path, seeds, words):
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(TINY))
    result = CliRunner().invoke(main, ["run", str(tmp_path / "c.yaml"), "--seeds", seeds, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0], result.output


@pytest.mark.parametrize("seeds, words", [
    ([], "specimen.seeds is empty"),
    ([3, 4, 3], "specimen.seeds gives seed 3 more than once"),
])
def test_bad_specimen_seeds_are_refused_with_one_line_naming_the_key(tmp_path, seeds, words):
    raw = yaml.safe_load(yaml.safe_dump(TINY))
    raw["specimen"]["seeds"] = seeds
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    result = CliRunner().invoke(main, ["run", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0] and "c.yaml" in lines[0], result.output


def test_seeds_option_counts_from_specimen_seed_or_lists_them():
    assert parse_seeds_option("3", 5) == [5, 6, 7]
    assert parse_seeds_option("4,0,9", 5) == [4, 0, 9]
    assert parse_seeds_option(None, 5) is None
    raw = yaml.safe_load(yaml.safe_dump(TINY))
    assert ensemble_seeds(raw, None, "c") == [0, 1]
    assert ensemble_seeds(raw, "2,7", "c") == [2, 7]
    raw["specimen"].pop("seeds")
    assert ensemble_seeds(raw, None, "c") is None
    raw.pop("specimen")
    with pytest.raises(ConfigError, match="no specimen section"):
        ensemble_seeds(raw, "2", "c")


def test_an_unreachable_scheduler_is_one_line_naming_its_address(tmp_path, monkeypatch):
    pytest.importorskip("dask.distributed")
    import socket

    from fiberpipe.studies import runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 1.0)

    with socket.socket() as s:  # a free port: nothing listens there
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(TINY))
    result = CliRunner().invoke(main, ["run", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o"),
                                       "--scheduler", address])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip() and not ln.startswith(("ensemble:", "  on "))]
    assert len(lines) == 1 and f"--scheduler {address}: no Dask scheduler answers there" in lines[0], result.output


def test_study_with_seeds_compares_ensemble_means_on_shared_specimens(tmp_path, serial):
    """``fiberpipe study --seeds 2``: each point an ensemble; the points differ only in their
    compaction, so they share the reference's specimens; the error is the mean curves'."""
    from fiberpipe.post.curves import curve_error

    raw = yaml.safe_load(yaml.safe_dump(TINY))
    raw["specimen"].pop("seeds")
    raw["input"] = {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]}  # a study validates its points: replaced
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(raw))
    (tmp_path / "study.yaml").write_text("name: alpha\nbase: base.yaml\nsweep: {scene.damping.alpha: ['1e4 1/s']}\n"
                                         "reference: {overrides: {scene.damping.alpha: '3e4 1/s'}}\n"
                                         "measures: [curve, final_load]\n")
    result = CliRunner().invoke(main, ["study", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "s"),
                                       "--seeds", "2", "--workers", "1"])
    assert result.exit_code == 0, result.output
    (row,) = list(csv.DictReader((tmp_path / "s" / "study.csv").open()))
    assert len(list((tmp_path / "s" / "specimens").iterdir())) == 2  # two seeds, built once for all runs
    reference = json.loads((tmp_path / "s" / "reference" / "ensemble.json").read_text())
    assert reference["final_load_N"] == pytest.approx(serial[1]["final_load_N"][:2], rel=1e-9, abs=1e-15)
    point = json.loads((tmp_path / "s" / "points" / row["id"] / "ensemble.json").read_text())
    assert float(row["final_load_mean_N"]) == pytest.approx(np.mean(point["final_load_N"]), rel=1e-6)
    ref_table = list(csv.DictReader((tmp_path / "s" / "reference" / "ensemble.csv").open()))
    pt_table = list(csv.DictReader((tmp_path / "s" / "points" / row["id"] / "ensemble.csv").open()))
    U_ref, F_ref = (np.array([float(r[c]) for r in ref_table]) for c in ("U_m", "load_mean_N"))
    U, F = (np.array([float(r[c]) for r in pt_table]) for c in ("U_m", "load_mean_N"))
    assert float(row["curve_error"]) == pytest.approx(curve_error(U_ref, F_ref, U, F, scale=float(np.max(np.abs(F_ref)))),
                                                      rel=1e-5)
    assert float(row["curve_error"]) > 0  # α changes the curve


def _diverges_at_seed_1(raw, run_dir, where, specimen_store):
    """The member's task, but seed 1 is compacted under a gravity of 1e12 m/s² (a load wrong by
    orders of magnitude): the solver stops it as diverged, with its own diagnosis."""
    from fiberpipe.studies import ensemble

    if raw["specimen"]["seed"] == 1:
        raw = {**raw, "scene": {**raw["scene"], "gravity": {"acceleration": [0.0, -1e12, 0.0]}}}
    return ensemble.run_member(raw, run_dir, where, specimen_store)


def test_a_diverging_member_is_reported_and_left_out_while_the_others_finish(serial, tmp_path):
    import shutil

    from fiberpipe.errors import SimulationDiverged

    out, reference = serial
    copy = tmp_path / "ens"
    shutil.copytree(out, copy)  # seeds 0 and 2 finished there: reused
    lines = []
    summary = run_ensemble(TINY, [0, 1, 2], copy, workers=1, echo=lines.append, member=_diverges_at_seed_1)
    assert summary["seeds"] == [0, 2]
    assert summary["final_load_N"] == pytest.approx([reference["final_load_N"][0], reference["final_load_N"][2]], rel=1e-9)
    assert summary["final_load_mean_N"] == pytest.approx(np.mean(summary["final_load_N"]), rel=1e-12)
    assert len(summary["v_f0"]) == 2
    (record,) = summary["diverged"]
    assert record["seed"] == 1 and record["stage"] == "compaction"
    assert record["diagnosis"].startswith(f"simulation diverged at t = {record['time_s']:.6g} s (step {record['step']})")
    assert record["step"] >= 1 and record["time_s"] > 0
    assert json.loads((copy / "seed-1" / "diverged.json").read_text()) == record
    assert json.loads((copy / "ensemble.json").read_text())["diverged"] == [record]
    header = (copy / "ensemble.csv").read_text().splitlines()[0].split(",")
    assert "load_seed_1_N" not in header and {"load_seed_0_N", "load_seed_2_N"} <= set(header)
    assert any(line.startswith(f"  {copy}: seed 1 diverged in the compaction at step {record['step']}") for line in lines)
    # the finished runs alone give the same ensemble, seed 1 left out again
    collected = collect_ensemble(copy, [0, 1, 2], echo=lambda *_: None)
    assert collected["seeds"] == [0, 2] and collected["diverged"] == [record]
    # no member left: one line naming the seed (with keep_going, the ensemble's error)
    with pytest.raises(SimulationDiverged) as caught:
        run_ensembles({"alone": (TINY, [1], tmp_path / "alone")}, workers=1, echo=lambda *_: None,
                      member=_diverges_at_seed_1, specimen_store=copy / "specimens")
    assert "\n" not in str(caught.value) and "every member diverged (seed 1 diverged in the compaction" in str(caught.value)
    kept = run_ensembles({"alone": (TINY, [1], tmp_path / "alone")}, workers=1, echo=lambda *_: None,
                         member=_diverges_at_seed_1, specimen_store=copy / "specimens", keep_going=True)["alone"]
    assert kept["error"] == str(caught.value) and kept["diverged"][0]["step"] == record["step"]
