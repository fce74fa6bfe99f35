"""Reliability: checkpoint/resume through a real Ctrl-C, divergence diagnoses that keep the
last good frames and checkpoint, bad scene/solver input and bad checkpoints through the CLI (one
line, non-zero exit, no traceback, earlier results unchanged). docs/reliability.md lists them all."""

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from fiberpipe.errors import FiberpipeError, SimulationDiverged
from fiberpipe.solver import (Damping, Drive, Drives, LineLoad, Loads, Material, PointLoad, SimulationSettings,
                              Walls, build_model, simulate)
from fiberpipe.solver.integrator import STATUS_LEFT_BOX, STATUS_PENETRATION

from _scenes import SMALL_SCENE, cli, run_small, write_cfg

REPO = Path(__file__).resolve().parents[1]
MAT = Material(15e9, 1380.0, 0.3)
R = 0.25e-3

# a small compaction scene: plates, walls, gravity, mass- and stiffness-proportional damping (tests/_scenes.py)
SCENE = SMALL_SCENE


def one_line_error(result, code=None):
    assert result.exit_code != 0, result.output
    if code is not None:
        assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    errors = [ln for ln in result.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, result.output
    return errors[0]


def datasets(path: Path) -> dict:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None)
    return out


def assert_same_simulation(a: Path, b: Path):
    da, db = datasets(a), datasets(b)
    assert da.keys() == db.keys()
    for k in da:
        assert np.array_equal(da[k], db[k], equal_nan=True), k


def snapshot(run_dir: Path) -> dict:
    """sha256 of every file of a run folder except run.log (which records each attempt)."""
    return {str(p.relative_to(run_dir)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(run_dir.rglob("*")) if p.is_file() and p.name != "run.log"}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted run (in process) of SCENE up to simulate."""
    _, run = run_small(tmp_path_factory.mktemp("ref"), SCENE)
    assert not (run / "simulation.checkpoint.h5").exists()  # removed once simulation.h5 is written
    return run


# -- 1. checkpoint and resume ----------------------------------------------------------------------


def test_ctrl_c_checkpoint_then_resume_is_bit_for_bit(tmp_path, reference):
    cfg = write_cfg(tmp_path / "small.yaml", SCENE)
    run = tmp_path / "run"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-m", "fiberpipe.cli", "run", str(cfg), "--out", str(run), "--to", "simulate"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    ck = run / "simulation.checkpoint.h5"
    deadline = time.monotonic() + 120
    while not ck.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert ck.exists(), proc.communicate()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (out, err)
    assert "Traceback" not in err
    errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "checkpoint saved" in errors[0], err
    assert f"fiberpipe simulate {cfg} --out {run} --resume" in errors[0]
    assert ck.exists() and not (run / "simulation.h5").exists()
    # two ways to resume: explicitly, and `fiberpipe run` picking the checkpoint up
    run2 = tmp_path / "run2"
    shutil.copytree(run, run2)
    r = cli("simulate", cfg, "--out", run, "--resume")
    assert r.exit_code == 0, r.output
    assert "resuming from checkpoint" in r.output
    assert_same_simulation(reference / "simulation.h5", run / "simulation.h5")
    assert not ck.exists()
    r = cli("run", cfg, "--out", run2, "--to", "simulate")
    assert r.exit_code == 0, r.output
    assert "resuming from checkpoint" in r.output and "resuming from checkpoint" in (run2 / "run.log").read_text()
    assert_same_simulation(reference / "simulation.h5", run2 / "simulation.h5")
    # the artifacts check out, with their provenance
    r = cli("inspect", "--check", run / "simulation.h5")
    assert r.exit_code == 0 and "check: ok" in r.output, r.output


def _interrupted_copy(tmp_path, reference, cfg_dict=SCENE):
    """A run folder holding a checkpoint, made by a stop request in process (faster than a signal)."""
    from fiberpipe.solver.checkpoint import CHECKPOINT_NAME, write_checkpoint
    from fiberpipe.stages.simulate import run_simulate  # noqa: F401  (the stage the CLI runs)

    run = tmp_path / "run"
    shutil.copytree(reference, run)
    (run / "simulation.h5").unlink()
    # a checkpoint written by the stage itself: rerun with a tiny end and copy its last checkpoint
    from fiberpipe.config import load_config
    from fiberpipe.pipeline import STAGES, stage_key
    from fiberpipe.artifacts import read_mesh
    from fiberpipe.solver.build import build_simulation

    cfg = load_config(write_cfg(tmp_path / "small.yaml", cfg_dict))
    key = stage_key(STAGES["simulate"], cfg, {"mesh": run / "mesh.h5"})
    model, effects, settings = build_simulation(read_mesh(run / "mesh.h5"), cfg)
    polls = {"n": 0}

    def stop():
        polls["n"] += 1
        return signal.SIGINT if polls["n"] == 3 else None

    try:
        simulate(model, effects, settings, should_stop=stop,
                 on_checkpoint=lambda c: write_checkpoint(run / CHECKPOINT_NAME, c, config_sha256=key))
    except FiberpipeError:
        pass
    assert (run / CHECKPOINT_NAME).exists()
    return run, tmp_path / "small.yaml"


def test_force_discards_the_checkpoint_and_changed_config_is_refused(tmp_path, reference):
    run, cfg = _interrupted_copy(tmp_path, reference)
    ck = run / "simulation.checkpoint.h5"
    # a changed scene: --resume refuses, naming the file and the way out
    changed = dict(SCENE, scene=dict(SCENE["scene"], damping={"alpha": "2e4 1/s", "beta": "1e-9 s"}))
    cfg2 = write_cfg(tmp_path / "changed.yaml", changed)
    before = snapshot(run)
    line = one_line_error(cli("simulate", cfg2, "--out", run, "--resume"))
    assert "simulation.checkpoint.h5" in line and "different config" in line and "--force" in line
    assert snapshot(run) == before
    # --resume and --force together
    assert "contradict" in one_line_error(cli("simulate", cfg, "--out", run, "--resume", "--force"))
    # `run` with the changed config ignores the stale checkpoint (says so) and starts over
    r = cli("run", cfg2, "--out", run, "--to", "simulate")
    assert r.exit_code == 0 and "ignoring" in r.output and "different config" in r.output, r.output
    assert not ck.exists()
    # --force on the original config discards a checkpoint and recomputes from t = 0
    run, cfg = _interrupted_copy(tmp_path / "b", reference)
    r = cli("simulate", cfg, "--out", run, "--force")
    assert r.exit_code == 0 and "resuming" not in r.output, r.output
    assert_same_simulation(reference / "simulation.h5", run / "simulation.h5")


@pytest.mark.parametrize("damage, message", [
    (lambda p, run: p.write_bytes(b"\x89HDF\r\n garbage"), "not a readable HDF5 artifact"),
    (lambda p, run: shutil.copy(run / "mesh.h5", p), "is a mesh artifact, but a checkpoint artifact is needed"),
    (lambda p, run: _set_attr(p, "schema_version", 99), "schema version 99"),
])
def test_bad_checkpoints(tmp_path, reference, damage, message):
    run, cfg = _interrupted_copy(tmp_path, reference)
    ck = run / "simulation.checkpoint.h5"
    damage(ck, run)
    before = snapshot(run)
    assert message in one_line_error(cli("simulate", cfg, "--out", run, "--resume"))
    assert snapshot(run) == before


def _set_attr(path, key, value):
    with h5py.File(path, "r+") as f:
        f.attrs[key] = value


def test_resume_without_a_checkpoint(tmp_path, reference):
    cfg = write_cfg(tmp_path / "small.yaml", SCENE)
    run = tmp_path / "run"
    shutil.copytree(reference, run)
    (run / "simulation.h5").unlink()
    assert "no checkpoint to resume from" in one_line_error(cli("simulate", cfg, "--out", run, "--resume"))


# -- 2. divergence -----------------------------------------------------------------------------------


def straight(n_el=10, L=3e-3, y=0.0, z=0.0):
    x = np.zeros((n_el + 1, 3))
    x[:, 0] = np.linspace(0, L, n_el + 1)
    x[:, 1] = y
    x[:, 2] = z
    return x


def one_fiber():
    return build_model(straight(), [0, 11], R, MAT)


def _check_message(msg, *words):
    for w in ("simulation diverged at t =", "fiber", "element", "Suggested fix", *words):
        assert w in msg, msg


def test_dt_forced_above_the_limit(tmp_path):
    m = one_fiber()
    effects = [Loads([PointLoad(0, [0, 0, -1e-3], "end")])]
    with pytest.raises(SimulationDiverged) as ei:
        simulate(m, effects, SimulationSettings(dt_s=3e-7, force_dt=True, end_time_s=2e-3, history_every=1))
    _check_message(str(ei.value), "above the stable limit", "energ")
    part = ei.value.partial_result
    assert not part.completed and part.frames_time.size >= 1
    assert np.all(np.isfinite(part.frames_positions[-1]))  # the last good state is the last frame


def test_huge_load_blows_up_with_a_diagnosis():
    m = one_fiber()
    with pytest.raises(SimulationDiverged) as ei:
        simulate(m, [Loads([PointLoad(0, [0, 0, 1e6], "end")])], SimulationSettings(end_time_s=1e-4))
    _check_message(str(ei.value), "node 10", "fiber 0", "lower solver.dt_safety")


def test_runaway_penetration_into_a_wall():
    m = one_fiber()
    walls = Walls({"y": (-0.3e-3, 0.3e-3)})
    push = Loads([LineLoad(0, [0, 3e6, 0])])  # ~ the penalty's force at half a radius, per node
    with pytest.raises(SimulationDiverged) as ei:
        simulate(m, [walls, push, Damping(1e4)],
                 SimulationSettings(end_time_s=1e-5, chunk_steps=2, speed_limit_m_s=1e9))
    assert ei.value.status == STATUS_PENETRATION
    _check_message(str(ei.value), "runaway penetration", "radii", "wall y_hi", "penalty_factor")


def test_fiber_pushed_through_a_wall_leaves_the_box():
    m = build_model(np.vstack([straight(), straight(z=0.6e-3)]), [0, 11, 22], R, MAT)
    walls = Walls({"y": (-0.3e-3, 0.3e-3)})
    drive = Drives([Drive(1, [0, 2e-3, 0], 20.0, ramp="linear")])  # 2 mm in 0.1 ms, through y_hi
    with pytest.raises(SimulationDiverged) as ei:
        simulate(m, [walls, drive], SimulationSettings(chunk_steps=10**6, output_frames=2))  # one chunk
    assert ei.value.status == STATUS_LEFT_BOX
    _check_message(str(ei.value), "left the box", "fiber 1", "beyond the wall y_hi")


def test_diverged_run_keeps_last_good_frames_and_checkpoint(tmp_path):
    """Through the CLI: a driven fiber pushed through a wall after a few checkpoints."""
    cfg = {
        "name": "through",
        "input": {"polylines": [[[0, 0, 0], ["3 mm", 0, 0]], [[0, 0, "0.6 mm"], ["3 mm", 0, "0.6 mm"]]]},
        "fiber": {"radius": "0.25 mm"},
        "mesh": {"element_length": "0.3 mm"},
        "material": {"youngs_modulus": "15 GPa", "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
        "scene": {"effects": ["walls", "drives"], "walls": {"y": ["-0.3 mm", "0.3 mm"]},
                  "drives": [{"fiber": 1, "displacement": [0, "1 mm", 0], "velocity": "1 m/s"}]},
        "solver": {"output_frames": 11, "checkpoint_every": 500},
    }
    path = write_cfg(tmp_path / "through.yaml", cfg)
    run = tmp_path / "run"
    r = cli("run", path, "--out", run)
    line = one_line_error(r, code=3)
    _check_message(line, "fiber 1", "wall y_hi", "last good frames kept in", "last checkpoint simulation.checkpoint.h5 kept")
    from fiberpipe.artifacts import read_artifact

    part = read_artifact(run / "simulation_diverged.h5", "simulation")
    assert part.attrs["completed"] == False and "diverged" in part.attrs  # noqa: E712
    assert part["frames/positions"].shape[0] >= 2 and np.all(np.isfinite(part["frames/positions"]))
    assert (run / "simulation_diverged.pvd").exists() and any((run / "frames_diverged").iterdir())
    assert (run / "simulation.checkpoint.h5").exists() and not (run / "simulation.h5").exists()
    assert cli("inspect", "--check", run / "simulation.checkpoint.h5").exit_code == 0


# -- 3. bad scene and solver input through the CLI -----------------------------------------------------


def _with(path: str, value):
    cfg = yaml.safe_load(yaml.safe_dump(SCENE))
    node = cfg
    keys = path.split(".")
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    return cfg


@pytest.mark.parametrize("key, value, message", [
    ("fiber.radius", "-0.25 mm", "radius"),
    ("solver.dt_safety", 1.5, "dt_safety"),
    ("solver.dt", "1e-6 s", "above the stable limit"),
    ("solver.checkpoint_every", 0, "checkpoint_every"),
    ("scene.damping", {"alpha": "-1 1/s"}, "alpha"),
    ("scene.friction", {"mu": -0.2}, "mu"),
    ("scene.plates", {"axis": "z", "lower": "moving", "upper": "fixed", "lower_position": "-2 mm",
                      "upper_position": "4 mm"}, "scene.plates: the plates never touch the fibers: their gaps to the bundle add up to 4 mm"),
    ("scene.plates", {"axis": "z", "lower": "moving", "upper": "fixed", "lower_position": "0.5 mm"},
     "scene.plates.lower_position: the plane at 0.5 mm cuts through the bundle"),
    ("scene.walls", {"y": ["-0.1 mm", "0.1 mm"]}, "scene.walls.y: the plane at -0.1 mm cuts through the bundle"),
])
def test_out_of_range_scene_and_solver_input(tmp_path, reference, key, value, message):
    run = tmp_path / "run"
    shutil.copytree(reference, run)
    before = snapshot(run)
    cfg = _with(key, value)
    if key == "scene.friction":
        cfg["scene"]["effects"].append("friction")
    line = one_line_error(cli("run", write_cfg(tmp_path / "bad.yaml", cfg), "--out", run))
    assert message in line, line
    assert snapshot(run) == before


def test_plate_starting_away_from_the_bundle_warns(tmp_path, caplog):
    from fiberpipe.solver.terms.planes import check_scene_geometry
    from fiberpipe.solver import Plates

    m = one_fiber()
    w = check_scene_geometry(m, [Plates(axis="z", displacement_m=1e-3, velocity_m_s=1.0, lower_position_m=-0.5e-3)])
    assert len(w) == 1 and "starts 0.25 mm away from the bundle" in w[0]


# -- fuzz of the scene and solver sections through the simulate stage ----------------------------------

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

FUZZ_KEYS = {
    "plates": ["axis", "lower", "upper", "lower_position", "upper_position", "bogus"],
    "walls": ["x", "y", "z"],
    "loading": ["displacement", "velocity", "ramp"],
    "damping": ["alpha"],
    "gravity": ["acceleration"],
    "solver": ["output_frames", "checkpoint_every", "history_every", "dt_safety"],
}
FUZZ_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-3, 30), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.sampled_from(["0.3 mm", "-1 mm", "1e9 mm", "1000 mm/min", "-5 mm/min", "nan mm", "inf mm", "15 GPa",
                     "moving", "fixed", "none", "smooth", "q"]),
    st.lists(st.one_of(st.integers(-2, 2), st.sampled_from(["-0.2 mm", "0.2 mm", "5 mm", "x"])), max_size=4),
)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(block=st.sampled_from(sorted(FUZZ_KEYS)), data=st.data())
def test_fuzzed_scene_and_solver_fail_cleanly_or_run(tmp_path_factory, reference, block, data):
    key = data.draw(st.sampled_from(FUZZ_KEYS[block]))
    value = data.draw(FUZZ_VALUES)
    d = tmp_path_factory.mktemp("fuzz")
    run = d / "run"
    shutil.copytree(reference, run)
    (run / "simulation.h5").unlink()
    cfg = yaml.safe_load(yaml.safe_dump(SCENE))
    cfg["solver"]["end_time"] = "1e-6 s"  # a dozen steps: the point is the input handling
    target = cfg["solver"] if block == "solver" else cfg["scene"].setdefault(block, {})
    if block == "solver" and key == "dt_safety" and isinstance(value, float) and 0 < value < 1e-3:
        value = 1e-3  # a legal but glacial run is not what this test is about
    target[key] = value
    before = snapshot(run)
    r = cli("run", write_cfg(d / "fuzz.yaml", cfg), "--out", run, "--to", "simulate")
    if r.exit_code == 0:
        assert (run / "simulation.h5").exists()
    else:
        one_line_error(r)
        assert {k: v for k, v in snapshot(run).items() if not k.startswith(("simulation_diverged", "frames_diverged"))} == before
