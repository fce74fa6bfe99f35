"""solver.settle_time: the specimen settles under gravity before the loading starts (the study's
check of its specimen, its Fig. 15); the loaded run starts from that state at t = 0."""

import json

import pytest
from click.testing import CliRunner

from fiberpipe.cli import main

CONFIG = """
name: settle
input:
  polylines:
    - [[0, "0.25 mm", 0], [0, "0.25 mm", "6 mm"]]
    - [[0, "0.9 mm", 0], [0, "0.9 mm", "6 mm"]]
fiber: {radius: "0.25 mm"}
scene:
  effects: [gravity, damping, contact, plates]
  gravity: {acceleration: [0, "-9.81 m/s^2", 0]}
  damping: {alpha: "300 1/s"}
  plates: {axis: y, lower: moving, upper: none, lower_position: 0}
  loading: {displacement: "0.01 mm", velocity: "1000 mm/min"}
solver: {settle_time: "20 ms"}
"""


def test_settling_then_loading(tmp_path, write_yaml):
    out = tmp_path / "run"
    r = CliRunner().invoke(main, ["run", str(write_yaml(CONFIG)), "--out", str(out)])
    assert r.exit_code == 0, r.output
    sim = json.loads((out / "summary.json").read_text())["stages"]["simulate"]
    # the upper fiber falls 0.15 mm onto the lower one, which rests on the plate
    assert sim["settle_max_displacement_m"] == pytest.approx(0.15e-3, rel=0.05)
    post = json.loads((out / "post" / "summary.json").read_text())
    # the loaded run's accounts start at the settled state (were they not reset, the residual would
    # be O(1)); the bounce of the falling fiber makes the value itself chaotic: 0.0025–0.013 for
    # gravity perturbed by 1e-8 (measured), hence the bound
    assert post["energy_balance_residual_max"] < 3e-2
