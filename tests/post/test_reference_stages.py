"""``post.reference_stages``: the position error of the simulated mid-lines at each scanned stage's
U (mean and p95 of matched mid-lines, per fiber and overall), against known offsets."""

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from fiberpipe.artifacts import write_fibers
from fiberpipe.config import load_config
from fiberpipe.pipeline import run_pipeline
from fiberpipe.polylines import Polylines
from fiberpipe.post.positions import frame_at, reference_stage_errors

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
from test_fit import bowed_fiber_config  # noqa: E402  (the cheap bowed-fiber scene)


def _lines(n=3, pts=21, dx=1e-3):
    z = np.linspace(0, 5e-3, pts)
    return [np.c_[np.full(pts, k * dx), 0.1e-3 * np.sin(z / 1e-3 + k), z] for k in range(n)]


def test_frame_at_interpolates_between_the_bracketing_frames():
    frames = np.array([np.zeros((2, 3)), np.ones((2, 3)), 3 * np.ones((2, 3))])
    U = np.array([0.0, 1e-4, 2e-4])
    pos, u = frame_at(U, frames, 1.5e-4)
    assert u == 1.5e-4 and np.allclose(pos, 2.0)
    pos, u = frame_at(U, frames, 5e-4)  # beyond the last frame: the last frame
    assert u == 2e-4 and np.allclose(pos, 3.0)


def test_errors_are_the_known_offsets_per_fiber_and_overall():
    """Reference mid-lines shifted by 10, 20, 30 µm across the fibers (x, the fibers lie in y-z), in a
    shuffled order: every node is that far from its match, so mean and p95 are the shifts (to the
    measure's resolution: the reference is densified at a tenth of its segment length, 1 %)."""
    lines = _lines()
    sim = np.concatenate(lines)
    off = np.arange(4) * 21
    shifts = np.array([10e-6, 20e-6, 30e-6])
    order = [2, 0, 1]
    ref = Polylines.from_list([lines[k] + [shifts[k], 0, 0] for k in order], 0.1e-3)
    frames = np.array([sim, sim])
    overall, per_fiber = reference_stage_errors([{"displacement_m": 0.0, "fibers": "x"}], np.array([0.0, 1e-4]),
                                                frames, off, lambda _p: ref)
    assert overall[0]["mean_m"] == pytest.approx(shifts.mean(), rel=1e-2)
    assert overall[0]["p95_m"] == pytest.approx(np.percentile(np.repeat(shifts, 21), 95), rel=1e-2)
    for r in per_fiber:
        assert r["mean_m"] == pytest.approx(shifts[r["fiber"]], rel=1e-2)
        assert r["p95_m"] == pytest.approx(shifts[r["fiber"]], rel=2e-2)
        assert order[r["reference_fiber"]] == r["fiber"]  # matched to its own shifted copy


def test_post_stage_writes_the_table_and_plot(tmp_path):
    """The bowed fiber of the fit test, scanned at U = 0 shifted by 25 µm across its plane, and at
    U = 0.3 mm (its last frame) shifted by 40 µm."""
    raw = bowed_fiber_config()
    pts = np.asarray(raw["input"]["polylines"][0], float)
    write_fibers(tmp_path / "stage0.h5", Polylines.from_list([pts + [25e-6, 0, 0]], 0.25e-3))
    raw["post"] = {"plots": True, "reference_stages": [{"displacement": "0 mm", "fibers": "stage0.h5"}]}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    run_pipeline(load_config(tmp_path / "c.yaml"), tmp_path / "run", to_stage="simulate")
    from fiberpipe.post.history import load_simulation

    last = load_simulation(tmp_path / "run" / "simulation.h5").frames_positions[-1]
    write_fibers(tmp_path / "stage1.h5", Polylines.from_list([last + [40e-6, 0, 0]], 0.25e-3))
    raw["post"]["reference_stages"].append({"displacement": "0.3 mm", "fibers": "stage1.h5"})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    run_pipeline(load_config(tmp_path / "c.yaml"), tmp_path / "run")
    rows = list(csv.DictReader((tmp_path / "run" / "post" / "reference_stages.csv").open()))
    assert [float(r["mean_m"]) for r in rows] == [pytest.approx(25e-6, rel=1e-2), pytest.approx(40e-6, rel=1e-2)]
    assert float(rows[1]["U_m"]) == pytest.approx(0.3e-3, rel=1e-6)
    assert (tmp_path / "run" / "post" / "reference_stages.png").exists()
    summary = json.loads((tmp_path / "run" / "post" / "summary.json").read_text())
    assert len(summary["reference_stages"]) == 2
