"""``fiberpipe fit``: a known parameter is fitted back from a curve fiberpipe made itself, and bad
targets and parameters are refused with one line naming the problem."""

import csv
import json
import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fiberpipe.cli import main
from fiberpipe.config import validate_config
from fiberpipe.pipeline import run_pipeline
from fiberpipe.studies.fit import parse_param, read_target, run_fit

R_SPOOL, L, R = 0.06, 0.015, 0.25e-3  # bow radius, fiber length, fiber radius (m)
E_TRUE = 15e9


def bowed_fiber_config(youngs_modulus="15 GPa") -> dict:
    """One fiber bowed upwards (a circular arc of 60 mm radius, sagitta 0.47 mm) resting on its ends
    on the lower plate, its crown touching the upper plate; the lower plate rises by 0.3 mm and
    flattens it (quasi-static: damping over-critical for the first bending mode, 9 ms loading)."""
    z = np.linspace(0, L, 16)
    zc = z - L / 2
    sag = np.sqrt(R_SPOOL**2 - zc**2) - np.sqrt(R_SPOOL**2 - (L / 2) ** 2)
    y = R + 1e-6 + sag
    top = float(y.max() + R + 1e-6)
    return {
        "name": "bowed-fiber",
        "input": {"polylines": [[[0.0, float(a), float(b)] for a, b in zip(y, z)]]},
        "mesh": {"element_length": "1 mm", "resolve_overlaps": False},
        "material": {"youngs_modulus": youngs_modulus, "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
        "fiber": {"radius": "0.25 mm"},
        "scene": {"effects": ["damping", "plates"], "damping": {"alpha": "3e4 1/s"},
                  "plates": {"axis": "y", "lower": "moving", "upper": "fixed", "lower_position": 0.0,
                             "upper_position": top},
                  "loading": {"displacement": "0.3 mm", "velocity": "2000 mm/min"}},
        "solver": {"output_frames": 3},
        "post": {"plots": False},
    }


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    d = tmp_path_factory.mktemp("fit")
    raw = bowed_fiber_config()
    (d / "bowed.yaml").write_text(yaml.safe_dump(raw))
    run_pipeline(validate_config(raw, where="bowed"), d / "target-run")
    return d / "bowed.yaml", d / "target-run" / "post" / "force_displacement.csv"


def test_the_target_case_is_the_beam_it_claims_to_be(target):
    """Independent check of the case: a simply supported beam loaded at mid-span, F = 48 E I U / L³."""
    U, F = read_target(target[1])
    inertia = math.pi * R**4 / 4
    assert F[-1] == pytest.approx(48 * E_TRUE * inertia * U[-1] / L**3, rel=0.05)


def test_fit_recovers_the_youngs_modulus_of_a_bowed_fiber_within_3_percent(target, tmp_path):
    config, curve = target
    res = run_fit(config, curve, ["material.youngs_modulus=10 GPa:20 GPa"], budget=8, out=tmp_path / "fit",
                  echo=lambda *_: None)
    assert res["best"]["material.youngs_modulus"] == pytest.approx(E_TRUE, rel=0.03)
    assert res["evaluations"] <= 8
    on_disk = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert on_disk["best"] == res["best"] and on_disk["objective_N"] == res["objective_N"]
    rows = list(csv.DictReader((tmp_path / "fit" / "history.csv").open()))
    assert len(rows) == res["evaluations"]
    assert min(float(r["objective_N"]) for r in rows) == pytest.approx(res["objective_N"], rel=1e-6)
    assert (tmp_path / "fit" / "fit.png").stat().st_size > 0
    # a second fit over the same folder reuses the runs and reports what they cost the first time
    again = run_fit(config, curve, ["material.youngs_modulus=10 GPa:20 GPa"], budget=8, out=tmp_path / "fit",
                    echo=lambda *_: None)
    rows2 = list(csv.DictReader((tmp_path / "fit" / "history.csv").open()))
    assert again["best"] == res["best"]
    assert [r["wall_time_s"] for r in rows2] == [r["wall_time_s"] for r in rows]


def _write(path, text):
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, words", [
    ("U_m,force\n0,0\n1e-4,1\n", "missing column load_N"),
    ("U_m,load_N\n0,0\n2e-4,1\n1e-4,2\n", "U_m is not monotonic: line 4"),
    ("U_m,load_N\n0,0\n1e-4,nan\n", "line 3: NaN"),
])
def test_bad_target_curves_are_refused_with_one_line(tmp_path, text, words):
    cfg = _write(tmp_path / "c.yaml", yaml.safe_dump(bowed_fiber_config()))
    tgt = _write(tmp_path / "t.csv", text)
    r = CliRunner().invoke(main, ["fit", str(cfg), "--target", str(tgt), "--param", "material.youngs_modulus=1e9:2e9",
                                  "--out", str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0] and "t.csv" in lines[0], r.output
    assert not (tmp_path / "o").exists()  # no empty folder left behind


@pytest.mark.parametrize("param, words", [
    ("material.youngs_modulos=1e9:2e9", "unknown key 'material.youngs_modulos' (did you mean 'youngs_modulus'?)"),
    ("material.youngs_modulus=20 GPa:10 GPa", "LO must be below HI"),
    ("material.youngs_modulus=10 GPa:10 GPa", "LO must be below HI"),
    ("material.youngs_modulus=10 mm:20 mm", "material.youngs_modulus"),
    ("material.youngs_modulus", "expected KEY=LO:HI"),
])
def test_bad_parameters_are_refused_with_one_line(tmp_path, target, param, words):
    cfg = _write(tmp_path / "c.yaml", yaml.safe_dump(bowed_fiber_config()))
    r = CliRunner().invoke(main, ["fit", str(cfg), "--target", str(target[1]), "--param", param,
                                  "--out", str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0], r.output


def test_params_take_units_and_specimen_keys():
    base = bowed_fiber_config()
    p = parse_param("material.youngs_modulus=10 GPa:20 GPa", base, "c")
    assert (p["lo"], p["hi"]) == (10e9, 20e9)
    base["specimen"] = {"n_fibers": 10}
    p = parse_param("specimen.bow.spool_radius=40 mm:90 mm", base, "c")
    assert (p["key"], p["lo"], p["hi"]) == ("specimen.bow.spool_radius", pytest.approx(0.04), pytest.approx(0.09))


def test_seeds_need_a_specimen_section(tmp_path, target):
    cfg = _write(tmp_path / "c.yaml", yaml.safe_dump(bowed_fiber_config()))
    r = CliRunner().invoke(main, ["fit", str(cfg), "--target", str(target[1]), "--param", "material.youngs_modulus=1e9:2e9",
                                  "--seeds", "3", "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "no specimen section" in r.output, r.output


def test_specimen_keys_are_fitted_over_seeds_with_the_mean_curve(tmp_path):
    """A specimen key (the spool radius) over two specimen seeds: each evaluation builds both
    specimens and runs them; the objective is the RMS of the seeds' mean curve against the target,
    recomputed here from the runs' own force_displacement.csv."""
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    raw = {"extends": str(repo / "configs" / "paper-40.yaml"), "name": "tiny",
           "specimen": {"n_fibers": 6, "width": "1.5 mm", "volume_fraction": 0.2, "candidates": 1,
                        "upper_plate": "pile", "settle": {"enabled": False}},
           "scene": {"loading": {"displacement": "0.05 mm", "velocity": "10000 mm/min", "ramp": "smooth",
                                 "ramp_fraction": 0.1}},
           "solver": {"output_frames": 3}, "post": {"plots": False}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    (tmp_path / "t.csv").write_text("U_m,load_N\n0,0\n2.5e-5,0.001\n5e-5,0.002\n")
    res = run_fit(tmp_path / "c.yaml", tmp_path / "t.csv", ["specimen.bow.spool_radius=100 mm:1 m"], seeds=2,
                  budget=2, out=tmp_path / "f", echo=lambda *_: None)
    assert res["seeds"] == [0, 1] and res["evaluations"] == 2
    assert 0.1 <= res["best"]["specimen.bow.spool_radius"] <= 1.0
    curves = []
    for run in res["best_runs"]:
        d = tmp_path / "f" / "evaluations" / run
        assert (d / "specimen" / "fibers.h5").exists()
        rows = list(csv.DictReader((d / "post" / "force_displacement.csv").open()))
        U = np.array([float(r["U_m"]) for r in rows])
        F = np.array([float(r["load_N"]) for r in rows])
        Uu, inv = np.unique(U, return_inverse=True)
        curves.append(np.interp([0, 2.5e-5, 5e-5], Uu, np.bincount(inv, weights=F) / np.bincount(inv)))
    mean = np.mean(curves, axis=0)
    assert res["objective_N"] == pytest.approx(float(np.sqrt(np.mean((mean - [0, 0.001, 0.002]) ** 2))), rel=1e-9)
    assert res["spread_over_seeds"]["final_load_N"] == pytest.approx([c[-1] for c in curves], rel=1e-9)
