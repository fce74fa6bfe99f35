"""Post-processing against closed-form references, and the post stage on a synthetic run."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from fiberpipe.config import validate_config
from fiberpipe.model.mesh import mesh_polylines
from fiberpipe.polylines import Polylines
from fiberpipe.post.compaction import fit_van_wyk
from fiberpipe.post.curves import curve_error
from fiberpipe.post.energies import contact_energy_created, energy_balance, quasi_static_ratio
from fiberpipe.post.geometry import projected_curvature, volume_fraction
from fiberpipe.post.positions import position_error
from fiberpipe.post.report import run_post
from fiberpipe.stages.simulate import write_simulation


def _arc(radius, n=200, angle=1.0):
    th = np.linspace(0, angle, n)
    return np.c_[radius * np.sin(th), np.zeros(n), radius * (1 - np.cos(th))]


def test_projected_curvature_of_an_arc_is_one_over_radius():
    pts = _arc(0.02)
    off = np.array([0, len(pts)])
    assert projected_curvature(pts, off, "xz") == pytest.approx(50.0, rel=1e-3)
    assert projected_curvature(pts, off, "yz") == pytest.approx(0.0, abs=1e-9)  # a line in YZ


def test_volume_fraction_of_a_known_box():
    pts = np.array([[0, 0, 0], [0, 0, 10e-3]], float)
    vf = volume_fraction(1e-9, pts, np.array([0.25e-3]), plate_axis=1, plate_gap_m=1e-3, walls={0: (-1e-3, 1e-3)})
    assert vf == pytest.approx(1e-9 / (2e-3 * 1e-3 * 10.5e-3))


def test_position_error_recovers_a_known_shift_and_matches_shuffled_fibers():
    fibers = [np.c_[np.full(30, i * 1e-3), np.zeros(30), np.linspace(0, 15e-3, 30)] for i in range(4)]
    ref = Polylines.from_list(fibers, 0.25e-3)
    sim = Polylines.from_list([f + [0, 40e-6, 0] for f in fibers[::-1]], 0.25e-3)
    err = position_error(sim.points_m, sim.offsets, ref.points_m, ref.offsets)
    assert err["mean_m"] == pytest.approx(40e-6, rel=1e-3)
    assert sorted(err["matched"]) == [(0, 3), (1, 2), (2, 1), (3, 0)]


def test_van_wyk_fit_recovers_its_parameters():
    vf = np.linspace(0.377, 0.6, 40)
    E = 15e9
    p = 2e-4 * E * (vf**3 - 0.377**3)
    fit = fit_van_wyk(vf, p, E)
    assert fit["k"] == pytest.approx(2e-4, rel=1e-3) and fit["n"] == pytest.approx(3.0, rel=1e-3)
    assert fit["r2"] > 0.9999


def test_energy_balance_and_quasi_static_ratio():
    t = np.linspace(0, 1, 11)
    e = {"kinetic": 0.1 * t, "strain": t, "external": 1.1 * t, "damping": 0 * t}
    assert np.max(energy_balance(e)) == pytest.approx(0.0, abs=1e-15)
    assert quasi_static_ratio(e)[5] == pytest.approx(0.1)
    e["external"] = 1.2 * t  # 0.1 J of work missing out of 1.2
    assert energy_balance(e)[-1] == pytest.approx(0.1 / 1.2)


def test_contact_energy_created_bounds_what_the_contact_made():
    """ALLPW = W_normal + W_friction + ALLFD (the return map's loss, booked on both sides), with
    W_normal = created − Δ(stored penalty energy) and W_friction = −(true loss) − Δ(spring energy).
    With the friction work recorded the bound reads created − stored, friction or not; without it
    (older histories) it also subtracts the friction loss and spring energy."""
    t = np.linspace(0, 1, 11)
    stored = 0.02 * t**2  # normal penalty energy, J
    made = 0.5 * t  # energy the discretisation creates, J
    assert contact_energy_created({"contact": made - stored, "external": t}) == pytest.approx(made - stored)
    assert contact_energy_created({"contact": -stored, "external": t}).max() == 0.0  # sound: nothing created
    spring, loss = 0.01 * t**2, 0.3 * t
    w_friction = -loss - spring
    pw = (made - stored) + w_friction + loss  # a return map that books the true loss
    recorded = {"contact": pw, "friction": loss, "friction_work": w_friction, "external": t}
    assert contact_energy_created(recorded) == pytest.approx(made - stored)
    older = {"contact": pw, "friction": loss, "external": t}
    assert contact_energy_created(older)[-1] == pytest.approx(made[-1] - stored[-1] - loss[-1] - spring[-1])


def test_curve_error():
    U = np.linspace(0, 1e-3, 50)
    assert curve_error(U, U * 10, U, U * 10) == pytest.approx(0)
    assert curve_error(U, U * 10, U, U * 10.2) == pytest.approx(0.02)


def _synthetic_compaction(run_dir, strain_J_per_m2=5e3):
    """A two-fiber run folder with a simulated compaction (F = 1e3 U on the load cell, 6 frames, strain
    energy ``strain_J_per_m2`` U²): ``(simulation.h5's path, its config)``."""
    lines = [np.c_[np.full(20, x), np.zeros(20), np.linspace(0, 6e-3, 20)] for x in (-0.3e-3, 0.3e-3)]
    mesh = mesh_polylines(Polylines.from_list(lines, 0.25e-3), 0.3e-3)
    K, T = 6, 50
    t = np.linspace(0, 1e-2, T)
    U = 0.2e-3 * t / t[-1]
    frames = np.repeat(mesh.nodes_m[None], K, axis=0)
    result = SimpleNamespace(
        frames_time=np.linspace(0, 1e-2, K),
        frames_positions=frames,
        history={
            "time": t,
            "plate_displacement": np.c_[U, 0 * U],
            "plate_force": np.c_[1e3 * U, 1e3 * U],
            "plate_position": np.c_[-0.25e-3 + U, 0.25e-3 + 0 * U],
            "contacts": np.full(T, 3.0),
            "energy": {"kinetic": 1e-9 * t, "strain": strain_J_per_m2 * U**2, "external": 5e3 * U**2 + 1e-9 * t, "damping": 0 * t},
        },
        dt_s=1e-7,
        steps=1000,
        wall_time_s=1.0,
        effects=["plates", "contact"],
    )
    sim_path = write_simulation(run_dir / "simulation.h5", mesh, result)
    cfg = validate_config(
        {"name": "synthetic", "input": {"fibers": "x.h5"}, "scene": {"effects": ["plates"], "plates": {"axis": "y"}, "loading": {"displacement": "0.5 mm"},
                                                         "walls": {"x": [-0.6e-3, 0.6e-3]}}}
    )
    return sim_path, cfg


def test_post_stage_on_a_synthetic_compaction(tmp_path):
    sim_path, cfg = _synthetic_compaction(tmp_path)
    figures = run_post(cfg, sim_path, tmp_path / "post")
    s = json.loads((tmp_path / "post" / "summary.json").read_text())
    assert s["final_load_N"] == pytest.approx(0.2)
    assert s["energy_balance_residual_max"] < 1e-9
    assert s["contact_energy_created_J"] == 0.0 and s["contact_energy_created_over_external"] == 0.0
    report = (tmp_path / "post" / "report.md").read_text()
    assert "energy created by the contact, at least" in report and "above 5 %" not in report
    assert s["contacts_per_fiber_final"] == pytest.approx(3.0)
    # v_f = fiber volume / (1.2 mm walls × plate gap × fiber length + 2r)
    vol = np.pi * (0.25e-3) ** 2 * 6e-3 * 2
    assert s["vf_initial"] == pytest.approx(vol / (1.2e-3 * 0.5e-3 * 6.5e-3), rel=1e-6)
    for name in ("force_displacement.png", "energies.png", "force_displacement.csv", "report.md", "geometry.csv"):
        assert (tmp_path / "post" / name).exists(), name
    assert "final_load_N" in figures
    header = (tmp_path / "post" / "force_displacement.csv").read_text().splitlines()[0]
    assert header == "time_s,U_m,load_N,lower_plate_force_N,upper_plate_force_N"
    # the phases: a straight rise from U = 0 (F = 1e3 U), so no rearrangement and no steep phase
    assert s["phases"]["rearrangement_end_U_m"] < 0.02e-3
    assert s["phases"]["steep_start_U_m"] is None
    assert "## Compaction phases" in (tmp_path / "post" / "report.md").read_text()
    # and in the comparison of runs (make reproduce)
    from fiberpipe.post.compare import compare_runs

    table = compare_runs([tmp_path], tmp_path / "cmp")
    head, _, row = table.splitlines()[:3]
    assert "rearrangement_end_U_mm" in head and "steep_start_U_mm" in head
    cells = dict(zip([c.strip() for c in head.strip("|").split("|")], [c.strip() for c in row.strip("|").split("|")]))
    assert float(cells["final_load_N"]) == pytest.approx(0.2) and cells["steep_start_U_mm"] == "nan"
    assert float(cells["contact_energy_created_over_WK"]) == 0.0  # no contact energy in this history
    assert (tmp_path / "cmp" / "comparison.png").exists()


def test_compare_reads_every_run_before_making_its_folder(tmp_path):
    """A damaged post/summary.json, a folder without a simulation or an output folder that cannot be
    made is one error (naming what is wrong), and a refused comparison leaves no folder behind."""
    from fiberpipe.errors import InputError
    from fiberpipe.post.compare import compare_runs

    sim_path, cfg = _synthetic_compaction(tmp_path)
    run_post(cfg, sim_path, tmp_path / "post")
    for text in ("[]", '{"final_load_N": '):
        (tmp_path / "post" / "summary.json").write_text(text)
        with pytest.raises(InputError, match=r"post/summary.json: is not .*rerun its post stage"):
            compare_runs([tmp_path], tmp_path / "cmp")
        assert not (tmp_path / "cmp").exists()
    (tmp_path / "post" / "summary.json").unlink()
    with pytest.raises(InputError, match="nothing has no simulation.h5: run it first"):
        compare_runs([tmp_path, tmp_path / "nothing"], tmp_path / "cmp")
    assert not (tmp_path / "cmp").exists()
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError, match="afile/cmp is not writable"):
        compare_runs([tmp_path], tmp_path / "afile" / "cmp")
    # without a post summary its figures are nan
    assert "| nan | nan |" in compare_runs([tmp_path], tmp_path / "cmp")


def test_phantom_of_a_simulated_frame_refuses_a_frame_it_does_not_have_before_making_its_folder(tmp_path):
    from click.testing import CliRunner

    from fiberpipe.cli import main

    sim_path, _ = _synthetic_compaction(tmp_path)

    def phantom(frame, out, voxel="50 um"):
        return CliRunner().invoke(main, ["phantom", "--from-simulation", str(sim_path), "--frame", str(frame),
                                         "--voxel-size", voxel, "--out", str(out)])

    for frame, voxel, message in ((6, "50 um", "error: frame 6: the simulation has 6 frames (0 to 5, or -6 to -1 from the last)"),
                                  (-7, "50 um", "error: frame -7: the simulation has 6 frames"),
                                  (-1, "0 um", "error: --voxel-size 0 um: must be positive")):
        res = phantom(frame, tmp_path / "ph", voxel)
        assert isinstance(res.exception, SystemExit) and res.exit_code != 0, res.output
        assert message in res.output, res.output
        assert not (tmp_path / "ph").exists()
    # a negative frame counts from the last and is written as its index from 0
    res = phantom(-1, tmp_path / "ph")
    assert res.exit_code == 0, res.output
    assert "frame 5," in res.output
    from fiberpipe.artifacts import read_artifact

    assert int(read_artifact(tmp_path / "ph" / "truth.h5", "fibers", names=()).attrs["frame"]) == 5
    assert (tmp_path / "ph" / "volume.tif").exists()


def test_summary_json_is_strict_json_with_null_for_figures_not_computed(tmp_path):
    """NaN and ±inf have no JSON literal: a figure that could not be computed is written as null, so
    any JSON parser reads the file, and compare reads null as NaN."""
    from fiberpipe.artifacts import json_text
    from fiberpipe.post.compare import _figure, compare_runs

    def strict(text):
        return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON literal {c}"))

    obj = {"a": float("nan"), "b": [np.inf, -np.inf, np.float64(1.5)], "c": {"d": np.int64(3), "e": np.array([1.0, np.nan])},
           "f": None, "g": True, "h": tmp_path, "i": {2, 1}, True: 1, None: 2, 3: 3}
    assert strict(json_text(obj)) == {"a": None, "b": [None, None, 1.5], "c": {"d": 3, "e": [1.0, None]}, "f": None,
                                      "g": True, "h": str(tmp_path), "i": [1, 2], "true": 1, "null": 2, "3": 3}
    with pytest.raises(ValueError, match="two keys"):
        json_text({1: "a", "1": "b"})
    # the post stage on a run without strain energy: K/S is infinite, written as null
    sim_path, cfg = _synthetic_compaction(tmp_path, strain_J_per_m2=0.0)
    run_post(cfg, sim_path, tmp_path / "post")
    s = strict((tmp_path / "post" / "summary.json").read_text())
    assert s["peak_ke_over_se"] is None
    assert np.isnan(_figure(s, "peak_ke_over_se")) and np.isnan(_figure(s, "missing"))
    assert np.isnan(_figure({"x": True}, "x"))
    head, _, row = compare_runs([tmp_path], tmp_path / "cmp").splitlines()[:3]
    cells = dict(zip([c.strip() for c in head.strip("|").split("|")], [c.strip() for c in row.strip("|").split("|")]))
    assert cells["peak_ke_over_se"] == "nan"


def test_report_flags_energy_created_by_the_contact():
    from fiberpipe.post.report import _created

    assert "above 5 %" in _created({"contact_energy_created_J": 0.13, "contact_energy_created_over_external": 10.6})
    assert "above 5 %" not in _created({"contact_energy_created_J": 1e-6, "contact_energy_created_over_external": 0.01})
    assert _created({}) == "n/a"


def test_report_names_the_plane_onset_when_a_scene_with_planes_creates_energy():
    from fiberpipe.post.report import _created

    s = {"contact_energy_created_J": 0.13, "contact_energy_created_over_external": 0.5}
    assert "onset_fraction" in _created(s, planes=True) and "dt_safety" in _created(s, planes=True)
    assert "onset_fraction" not in _created(s, planes=False)
    assert "onset_fraction" not in _created({**s, "contact_energy_created_over_external": 0.01}, planes=True)
