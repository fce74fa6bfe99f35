"""scene.loading.path: the plates' piecewise prescribed travel (moves, holds, refusals, history)."""

import numpy as np
import pytest

from fiberpipe.errors import FiberpipeError
from fiberpipe.solver._kernels_boundary import (RAMP_LINEAR, RAMP_SMOOTH, RAMP_SMOOTHSTEP, path_delta, path_travel,
                                                plane_position, ramp_fraction)
from fiberpipe.solver.terms import Plates

from _scenes import cli, run_small, small_scene, write_cfg

V = 1.0 / 60  # 1000 mm/min


@pytest.mark.parametrize("ramp, mode", [("smooth", RAMP_SMOOTH), ("linear", RAMP_LINEAR),
                                        ("smoothstep", RAMP_SMOOTHSTEP)])
def test_one_segment_table_is_the_one_segment_ramp(ramp, mode):
    """displacement: is a one-entry table whose travel is U · ramp_fraction, to the last bit."""
    p = Plates(displacement_m=1.15e-3, velocity_m_s=V, ramp=ramp)
    u, T, ta = p.travel_table()
    assert u.shape == (1,) and T[0] == pytest.approx(p.loading_time_s, rel=1e-15)
    ts = np.linspace(-0.1 * T[0], 1.1 * T[0], 20001)
    ref = np.array([1.15e-3 * ramp_fraction(t, T[0], ta[0], mode) for t in ts])
    got = np.array([path_travel(t, u, T, ta, mode)[0] for t in ts])
    np.testing.assert_array_equal(got, ref)
    assert {path_travel(t, u, T, ta, mode)[1] for t in ts[::100]} == {0}
    pos = np.array([plane_position(t, -2e-3, 1.0, u, T, ta, mode) for t in ts])
    np.testing.assert_allclose(pos, -2e-3 + ref, rtol=0, atol=1e-18)
    dt = 1e-7
    inc = np.array([path_delta(t, t - dt, u, T, ta, mode) for t in ts[::50]])
    ref_inc = np.array([1.15e-3 * (ramp_fraction(t, T[0], ta[0], mode) - ramp_fraction(t - dt, T[0], ta[0], mode))
                        for t in ts[::50]])
    np.testing.assert_allclose(inc, ref_inc, rtol=1e-12, atol=1e-22)


def _path(path_mm, hold_s=2e-3, ramp="smooth"):
    p = Plates(path_m=[u * 1e-3 for u in path_mm], hold_s=hold_s, velocity_m_s=V, ramp=ramp)
    return p, p.travel_table()


def test_path_moves_holds_and_reverses_smoothly():
    path = [1.0, 0.4, 1.15]
    p, (u, T, ta) = _path(path)
    assert p.displacement_m == pytest.approx(1.15e-3)
    # moves |Δu|/v/(1 − 0.1) with a 2 ms hold after each but the last
    moves = np.abs(np.diff([0.0] + path)) * 1e-3 / V / 0.9
    assert p.loading_time_s == pytest.approx(moves.sum() + 2 * 2e-3, rel=1e-12)
    ends = np.cumsum(np.ravel(np.column_stack([moves, [2e-3, 2e-3, 0.0]]))[:-1])
    for k, target in enumerate(path):
        t_end = ends[2 * k]
        assert path_travel(t_end, u, T, ta, RAMP_SMOOTH)[0] == pytest.approx(target * 1e-3, rel=1e-12)
        if k < len(path) - 1:  # the hold keeps the travel and counts with the move before it
            for t in np.linspace(t_end, ends[2 * k + 1], 7)[1:-1]:
                tr, entry = path_travel(t, u, T, ta, RAMP_SMOOTH)
                assert tr == pytest.approx(target * 1e-3, rel=1e-12) and entry // 2 == k
    assert path_travel(10.0, u, T, ta, RAMP_SMOOTH)[0] == pytest.approx(1.15e-3, rel=1e-12)
    # C1 with zero velocity at the turning point (t = end of the first move), plateau speed = v
    h = 1e-6
    t1 = ends[0]
    vel = [path_delta(t + h, t - h, u, T, ta, RAMP_SMOOTH) / (2 * h) for t in (t1 - 2 * h, t1, t1 + 2 * h)]
    assert max(abs(x) for x in vel) < 1e-5 * V
    ts = np.linspace(0, p.loading_time_s, 40001)
    tr = np.array([path_travel(t, u, T, ta, RAMP_SMOOTH)[0] for t in ts])
    speed = np.abs(np.diff(tr) / np.diff(ts))
    assert speed.max() == pytest.approx(V, rel=1e-6)
    assert np.all(tr >= 0) and tr.max() == pytest.approx(1.15e-3, rel=1e-12)


@pytest.mark.parametrize("path, message", [
    (["1 mm", "-0.1 mm"], "scene.loading.path[1]"),
    (["1 mm", "1 mm"], "scene.loading.path[1]"),
    ([], "scene.loading.path is empty"),
])
def test_bad_path_is_refused_naming_the_key(tmp_path, path, message):
    cfg = small_scene(loading={"path": path, "velocity": "600 mm/min"})
    r = cli("run", write_cfg(tmp_path / "c.yaml", cfg), "--out", tmp_path / "run")
    assert r.exit_code != 0
    errors = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], r.output
    assert "Traceback" not in r.output


def test_path_beyond_the_plates_gap_is_refused(tmp_path):
    # the small scene's plates are 2 mm apart (fibers at z = 0 … 1.5 mm, r = 0.25 mm)
    cfg = small_scene(loading={"path": ["1 mm", "0.5 mm", "2.5 mm"], "velocity": "600 mm/min"})
    r = cli("run", write_cfg(tmp_path / "c.yaml", cfg), "--out", tmp_path / "run")
    assert r.exit_code != 0
    errors = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "scene.loading.path" in errors[0] and "2 mm apart" in errors[0], r.output


def test_path_and_a_different_displacement_or_a_lone_hold_are_refused():
    from fiberpipe.config import LoadingConfig

    with pytest.raises(ValueError, match="scene.loading.displacement"):
        LoadingConfig(displacement="2 mm", path=["1 mm", "0.5 mm"])
    with pytest.raises(ValueError, match="scene.loading.hold"):
        LoadingConfig(displacement="1 mm", hold="1 ms")
    with pytest.raises(FiberpipeError, match="scene.loading.path"):
        Plates(path_m=[1e-3, -1e-4], velocity_m_s=V)
    assert LoadingConfig(path=["1 mm", "0.5 mm"]).displacement == pytest.approx(1e-3)


def test_history_records_the_path_segment(tmp_path):
    """A run on a path: the plate travel follows the table and the history's segment column counts the
    moves (a hold with the move before it)."""
    from fiberpipe.post.history import load_simulation

    path = ["0.015 mm", "0.005 mm", "0.02 mm"]
    cfg = small_scene(loading={"path": path, "hold": "0.5 ms", "velocity": "600 mm/min"})
    _, run = run_small(tmp_path, cfg)
    sim = load_simulation(run / "simulation.h5")
    seg = np.asarray(sim.history["segment"])
    U = np.asarray(sim.history["plate_displacement"])[:, 0]
    t = np.asarray(sim.history["time"])
    assert set(np.unique(seg)) == {0, 1, 2} and np.all(np.diff(seg) >= 0)
    p = Plates(path_m=[0.015e-3, 0.005e-3, 0.02e-3], hold_s=0.5e-3, velocity_m_s=0.01)
    u, T, ta = p.travel_table()
    ref = np.array([path_travel(tt, u, T, ta, RAMP_SMOOTH)[0] for tt in t])
    np.testing.assert_allclose(U, ref, rtol=0, atol=1e-15)
    assert U[seg == 0].max() == pytest.approx(0.015e-3, rel=1e-6)
    assert U[seg == 1].min() == pytest.approx(0.005e-3, rel=1e-3)
    assert U[-1] == pytest.approx(0.02e-3, rel=1e-4)  # the last row is a few steps before the end
    assert t[-1] == pytest.approx(p.loading_time_s, rel=1e-3)
