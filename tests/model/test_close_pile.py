"""``specimen.upper_plate: close``: the cassette closed onto the settled pile in the solver reaches
the target v_f0, stands in static equilibrium, reports its residual load, and refuses a target it
cannot reach with the densest v_f0 it reached."""

import json
import math
from pathlib import Path

import h5py  # noqa: F401  (fibers.h5 is read by fiberpipe)
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fiberpipe.cli import main
from fiberpipe.config import load_raw
from fiberpipe.model.virtual_specimen import build_specimen

REPO = Path(__file__).resolve().parents[2]
RHO, R, G = 1380.0, 0.25e-3, 9.81


def _config(tmp_path, volume_fraction, **close):
    raw = {"extends": str(REPO / "configs" / "paper-40.yaml"), "name": "close",
           "post": {"reference_fibers": None},
           "specimen": {"n_fibers": 12, "length": "6 mm", "width": "1.5 mm", "volume_fraction": volume_fraction,
                        "candidates": 2, "upper_plate": "close", "points_per_fiber": 21, "seed": 0,
                        "settle": {"time": "20 ms", "mass_scaling": 100, "gravity_scale": 100},
                        "close": {"velocity": "10000 mm/min", "relax_time": "3 ms", "damping_alpha": "3e3 1/s",
                                  **close}}}
    path = tmp_path / f"close-{volume_fraction}.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.fixture(scope="module")
def closed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("close")
    config = _config(tmp, 0.55)
    info = build_specimen(load_raw(config), tmp / "specimen", where=str(config), echo=lambda *_: None)
    return tmp / "specimen", info


def test_closing_reaches_the_target_volume_fraction(closed):
    folder, info = closed
    closing = info["closing"]
    assert closing["needed"] and closing["start_height_m"] > closing["target_height_m"]
    area = 12 * math.pi * R**2
    assert info["volume_fraction"] == pytest.approx(0.55, rel=1e-9)  # the plate gap is the target's
    assert info["height_m"] == pytest.approx(area / (0.55 * 1.5e-3), rel=1e-9)
    # the closed pile is under the plate, to the plate penalty's onset (specimen.close.tolerance)
    assert info["pile_top_m"] <= info["height_m"] + 5e-6
    assert closing["volume_fraction_reached"] == pytest.approx(0.55, rel=5e-6 / info["height_m"] + 1e-9)
    ready = yaml.safe_load((folder / "config.yaml").read_text())
    assert ready["scene"]["plates"]["upper_position"] == pytest.approx(info["height_m"], rel=1e-12)


def test_the_closed_pile_stands_in_static_equilibrium(closed):
    """After relaxing, the pile's vertical balance: the upper plate's residual load and the pile's
    weight down, the lower plate's load up, the walls' friction either way, at most μ = 0.2 × their
    normal load (a closed pile wedges between its walls)."""
    folder, info = closed
    closing = info["closing"]
    assert closing["kinetic_energy_end_J"] < 1e-3 * closing["strain_energy_end_J"]
    weight = 12 * RHO * math.pi * R**2 * 6e-3 * G
    lower, upper, walls = closing["lower_load_N"], closing["residual_load_N"], closing["wall_load_N"]
    assert upper > 0 and lower > 0
    assert abs(upper + weight - lower) <= 0.2 * walls + 0.02 * upper


def test_a_pile_already_under_the_target_is_not_closed(tmp_path):
    config = _config(tmp_path, 0.30)
    info = build_specimen(load_raw(config), tmp_path / "s", where=str(config), echo=lambda *_: None)
    assert info["closing"]["needed"] is False
    assert info["volume_fraction"] == pytest.approx(0.30, rel=1e-9)


def test_a_target_the_pile_cannot_reach_is_one_line_with_the_densest_reached(tmp_path):
    config = _config(tmp_path, 0.85, mass_scaling=100, damping_alpha="1e3 1/s", relax_time="1 ms")
    result = CliRunner().invoke(main, ["specimen", str(config), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert "specimen.volume_fraction = 0.85: closing the cassette does not reach it" in lines[0]
    densest = float(lines[0].split("densest it reached is v_f0 = ")[1].split(")")[0])
    assert 0.55 < densest < 0.85
    assert not (tmp_path / "o").exists()


def test_the_settling_takes_its_own_contact_section_and_mass_scaling():
    from fiberpipe.model.specimen_settle import settle_scene

    raw = {"scene": {"contact": {"law": "scaled_stiffness", "preset": "table1_phi6"}}, "solver": {"mass_scaling": 100}}
    scene = settle_scene(raw, width_m=3e-3, alpha_per_s=300.0, time_s=0.1, mu=0.2, lock="all", frames=3,
                         contact={"law": "hertz_oriented"})
    assert scene["scene"]["contact"] == {"law": "hertz_oriented"}
    assert "mass_scaling" not in scene["solver"]  # the compaction's mass scaling is not the settling's
    assert settle_scene(raw, width_m=3e-3, alpha_per_s=300.0, time_s=0.1, mu=0.2, lock="all",
                        frames=3)["scene"]["contact"] == raw["scene"]["contact"]


def test_a_closing_that_diverges_runs_once_more_at_half_the_step(monkeypatch):
    """A stiffening law can outgrow the step at the closing's peak load: the closing runs again at
    dt_safety × 0.5, reports the dt_safety it used, and a second divergence is the error."""
    from fiberpipe.errors import SimulationDiverged
    from fiberpipe.model import specimen_settle

    seen = []

    def diverges_at(limit):
        def run(scene, fibers, where, progress=None):
            seen.append(scene["solver"]["dt_safety"])
            if scene["solver"]["dt_safety"] > limit:
                raise SimulationDiverged("a node moved faster than the speed limit")
            return "cfg", "mesh", "result", 1.0
        return run

    monkeypatch.setattr(specimen_settle, "_run_scene", diverges_at(0.5))
    scene = {"solver": {"dt_safety": 0.9}}
    assert specimen_settle._run_closing(scene, None, "w") == ("cfg", "mesh", "result", 1.0, pytest.approx(0.45))
    assert seen == [0.9, pytest.approx(0.45)] and scene["solver"]["dt_safety"] == 0.9  # the caller's scene unchanged
    seen.clear()
    monkeypatch.setattr(specimen_settle, "_run_scene", diverges_at(0.1))
    with pytest.raises(SimulationDiverged):
        specimen_settle._run_closing(scene, None, "w")
    assert seen == [0.9, pytest.approx(0.45)]
