"""build_simulation: config → (model, effects, settings), on a cantilever with a closed-form tip
deflection and on a scene of plates, walls and gravity."""

from pathlib import Path

import numpy as np
import pytest

from fiberpipe.config import load_config
from fiberpipe.model.mesh import Mesh
from fiberpipe.solver import simulate
from fiberpipe.solver.build import build_simulation

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "verify"


def _mesh(cfg):
    x = np.zeros((51, 3))
    x[:, 0] = np.linspace(0, 15e-3, 51)
    return Mesh(x, np.array([0, 51]), np.array([cfg.fiber.radius]))


def test_cantilever_small_config_settles_at_PL3_3EI():
    cfg = load_config(CONFIGS / "cantilever-small.yaml")
    model, effects, settings = build_simulation(_mesh(cfg), cfg)
    assert [e.name for e in effects] == ["clamps", "loads", "damping"]
    res = simulate(model, effects, settings)
    E, r, L, P = 15e9, 0.25e-3, 15e-3, 1e-3
    ref = P * L**3 / (3 * E * np.pi * r**4 / 4)
    assert -res.frames_positions[-1, -1, 2] == pytest.approx(ref, rel=0.01)


def test_build_plates_walls_gravity(write_yaml):
    p = write_yaml("""
name: t
input:
  polylines:
    - [[0, 0, 0], ["3 mm", 0, 0]]
material: {youngs_modulus: "15 GPa", poisson_ratio: 0.3, density: 1380}
fiber: {radius: "0.25 mm"}
scene:
  effects: [gravity, damping, plates, walls]
  damping: {alpha: "1e5 1/s"}
  plates: {axis: z, lower: moving, upper: fixed}
  walls: {y: ["-1 mm", "1 mm"]}
  loading: {displacement: "0.01 mm", velocity: "1000 mm/min", ramp: smooth}
solver: {output_frames: 3}
""")
    cfg = load_config(p)
    x = np.zeros((11, 3))
    x[:, 0] = np.linspace(0, 3e-3, 11)
    model, effects, settings = build_simulation(Mesh(x, np.array([0, 11]), np.array([0.25e-3])), cfg)
    assert [e.name for e in effects] == ["gravity", "damping", "plates", "walls"]
    res = simulate(model, effects, settings)
    h = res.history
    assert h["plate_force"].shape[1] == 2 and h["wall_force"].shape[1] == 2
    assert h["plate_displacement"][-1, 0] == pytest.approx(1e-5, rel=1e-6)
    assert h["plate_force"][-1, 1] > 0


def test_solver_force_dt_runs_a_step_above_the_stable_limit_that_is_refused_without_it():
    """``solver.dt`` above the stable limit is refused with a message naming ``solver.force_dt``; with
    ``solver.force_dt: true`` the run takes that step (the cantilever's stable step is ~1.9e-7 s)."""
    from fiberpipe.errors import FiberpipeError
    from fiberpipe.solver.integrator import choose_time_step

    cfg = load_config(CONFIGS / "cantilever-small.yaml", {"solver.dt": "5e-7 s"})
    model, effects, settings = build_simulation(_mesh(cfg), cfg)
    with pytest.raises(FiberpipeError, match=r"solver\.force_dt: true"):
        choose_time_step(model, effects, settings)
    cfg = load_config(CONFIGS / "cantilever-small.yaml", {"solver.dt": "5e-7 s", "solver.force_dt": True})
    model, effects, settings = build_simulation(_mesh(cfg), cfg)
    assert choose_time_step(model, effects, settings)[0] == pytest.approx(5e-7)
