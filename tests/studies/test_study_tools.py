"""The study's fit and sensitivity commands (``tools/study_fit.py``, ``tools/study_sensitivity.py``):
the fit never leaves the ranges the study states, and its grid points reuse the prediction's and
the sensitivity's ensembles (same specimens, same runs)."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

import study_fit  # noqa: E402
import study_prediction  # noqa: E402
import study_sensitivity  # noqa: E402
from fiberpipe.config import load_raw  # noqa: E402
from fiberpipe.studies.ensemble import specimen_key  # noqa: E402


@pytest.fixture(scope="module")
def base():
    return study_prediction._with(load_raw(ROOT / "configs" / "specimens" / "study-prediction.yaml"), study_prediction.FAST)


@pytest.mark.parametrize("text", ["specimen.bow.spool_radius=0.02,0.1",  # below Table 4 read in 1/cm
                                  "specimen.bow.spool_radius=0.1,5",  # beyond Table 4 read in 1/m
                                  "specimen.volume_fraction=0.377,0.45",
                                  "specimen.phi_mean=0.1"])  # no stated range for it in the fit
def test_the_fit_refuses_values_outside_the_studys_ranges(text):
    with pytest.raises(SystemExit, match="--grid"):
        study_fit.parse_grid([text])


def test_grid_points_reuse_the_prediction_and_the_sensitivity_runs_and_specimens(base, tmp_path):
    prediction = tmp_path / "pred"
    (prediction / "fast").mkdir(parents=True)
    (prediction / "fast" / "ensemble.json").write_text(json.dumps({"seeds": [0, 1, 2, 3]}))
    grid = study_fit.parse_grid(["specimen.bow.spool_radius=0.02604,0.1", "specimen.volume_fraction=0.35,0.377"])
    points = [{"specimen.bow.spool_radius": r, "specimen.volume_fraction": v}
              for r in grid["specimen.bow.spool_radius"] for v in grid["specimen.volume_fraction"]]
    folders = study_fit.point_folders(points, base, [0, 1, 2, 3], prediction, tmp_path / "sens", tmp_path / "fit")
    assert folders == [tmp_path / "sens" / "vf-35", prediction / "fast",
                       tmp_path / "fit" / "points" / "spool_radius0.1-volume_fraction0.35", tmp_path / "sens" / "bow-100mm"]
    # the prediction's point is the prediction's config itself: the same specimens (the key hashes the raw config)
    same = study_prediction._with(base, study_fit.changed_values(points[1], base))
    assert specimen_key(same) == specimen_key(base)
    variant = dict(study_sensitivity.VARIANTS[0][3])
    assert specimen_key(study_prediction._with(base, study_fit.changed_values(points[3], base))) == \
        specimen_key(study_prediction._with(base, variant))
    # another seed list than the prediction's: the sensitivity's rerun of the prediction (its seeds, as every variant's)
    other = study_fit.point_folders(points[1:2], base, [0, 1], prediction, tmp_path / "sens", tmp_path / "fit")
    assert other == [tmp_path / "sens" / study_sensitivity.RERUN]


@pytest.mark.parametrize("name", ["walls-mu-0", "walls-mu-0.3", "plate-6mm", "mu-0", "law-hertz"])
def test_compaction_variants_compact_the_predictions_own_specimens(base, name):
    overrides = next(v[3] for v in study_sensitivity.VARIANTS if v[0] == name)
    variant = study_prediction._with(base, overrides)
    assert specimen_key(variant) == specimen_key(base)


def test_the_wall_friction_variants_keep_the_fibers_mu_and_the_plate_variant_is_the_studys_plate(base):
    from fiberpipe.config import validate_config

    variants = {v[0]: v[3] for v in study_sensitivity.VARIANTS}
    for name, wall_mu in (("walls-mu-0", 0.0), ("walls-mu-0.3", 0.3)):
        config = validate_config(study_prediction._with(base, variants[name]))
        assert (config.scene.walls.mu, config.scene.friction.mu) == (wall_mu, 0.2)
    plates = validate_config(study_prediction._with(base, variants["plate-6mm"])).scene.plates
    # axis y: [along x (across the 3 mm cassette), along z (the fibers, 15 mm)]
    assert plates.axis == "y" and plates.size == pytest.approx([3e-3, 6e-3])


def _run_with_curve(folder: Path, scale_N: float) -> str:
    """A finished run's curve F = scale (U / 1.15 mm)², sampled as the post stage writes it."""
    import numpy as np

    U = np.linspace(0.0, 1.15e-3, 47)
    (folder / "post").mkdir(parents=True)
    rows = ["time_s,U_m,load_N"] + [f"{u:.9g},{u:.9g},{scale_N * (u / 1.15e-3) ** 2:.9g}" for u in U]
    (folder / "post" / "force_displacement.csv").write_text("\n".join(rows) + "\n")
    return str(folder)


def test_the_fast_settings_error_compares_the_seeds_both_ensembles_finished(tmp_path):
    import numpy as np

    from fiberpipe.studies.fit import read_target

    diverged = {"seed": 1, "stage": "compaction", "step": 70028, "time_s": 0.0596,
                "diagnosis": "simulation diverged at t = 0.0596 s (step 70028): a node moved faster than the speed limit; node 1"}
    fast = {"seeds": [0, 2], "runs": [_run_with_curve(tmp_path / "f0", 20.0), _run_with_curve(tmp_path / "f2", 30.0)],
            "solver_wall_time_s": [60.0, 61.0], "diverged": [diverged]}
    study = {"seeds": [0, 1], "runs": [_run_with_curve(tmp_path / "s0", 40.0), _run_with_curve(tmp_path / "s1", 45.0)],
             "solver_wall_time_s": [600.0, 610.0], "diverged": []}
    error = study_prediction.fast_settings_error(fast, study)
    (row,) = error["seeds"]  # seed 1 diverged at the fast settings: no pair
    assert row["seed"] == 0 and row["final_load_difference_N"] == pytest.approx(-20.0, rel=1e-6)
    assert row["final_load_difference"] == pytest.approx(-0.5, rel=1e-6)
    U_t, _ = read_target(study_prediction.TARGET)  # the difference -20 (U/1.15 mm)² at the study's points
    expected = float(np.sqrt(np.mean((20.0 * (U_t / 1.15e-3) ** 2) ** 2)))
    assert row["curve_points_rms_difference_N"] == pytest.approx(expected, rel=1e-4)
    assert error["study_settings_solver_wall_time_s"] == [600.0] and error["fast_solver_wall_time_s"] == [60.0]
    assert error["diverged"]["fast"] == [diverged]
    specimens = []
    for seed, phi in ((0, 15.5), (2, 18.25)):
        folder = tmp_path / f"specimen-{seed}"
        folder.mkdir()
        (folder / "specimen.json").write_text(json.dumps({"closing": {"residual_load_N": 7.1 + seed, "wall_load_N": 25.0},
                                                          "statistics": {"phi_mean_deg": phi}}))
        specimens.append(str(folder))
    geometry = [{"v_f_U0": 0.371, "v_f_end": 0.444, "curvature_xz_per_m_U0": 24.0, "curvature_yz_per_m_U0": 31.0,
                 "curvature_xz_per_m_end": 27.0, "curvature_yz_per_m_end": 36.0}] * 2
    summary = {**fast, "settings": "fast", "final_load_N": [20.0, 30.0], "fast_settings_error": error,
               "specimens": specimens, "geometry": geometry,
               "final_load_statistics": {"n": 2, "mean_N": 25.0, "sd_N": 7.07, "mean_ci95_half_width_N": 63.5},
               "against_study": {"rms_N": 9.0, "rms_over_12N": 0.75, "mean_at_0.55mm_N": 5.7, "best_scale": 0.5,
                                 "best_scaled_rms_N": 2.4}}
    text = study_prediction.doc_markdown(summary, "make study-prediction")
    assert text.startswith(study_prediction.BEGIN) and text.endswith(study_prediction.END)
    assert "seed 1 diverged in the compaction at step 70028 (t = 0.0596 s), left out (a node moved faster than the " \
           "speed limit)" in text
    assert "| 0 | 40 | 20 | -20 (-50 %) |" in text
    assert "Φ 15.5–18.2° on average" in text and "7.1–9.1 N on the upper plate" in text
    assert "(0.5), the mean curve would still miss the points by 2.4 N RMS (20 % of 12 N)" in text
    assert "start at v_f 0.371 " in text and "At U = 0 24–31 1/m, at the end 27–36 1/m" in text


def test_the_prediction_with_no_seed_finished_is_one_line(monkeypatch, capsys, tmp_path):
    from fiberpipe.studies import ensemble

    message = f"{tmp_path}/fast: every member diverged (seed 0 diverged in the compaction at step 5 (t = 1e-06 s): ...)"
    monkeypatch.setattr(ensemble, "run_ensembles", lambda ensembles, **_: {
        "fast": {"error": message, "seeds": [0], "diverged": [{"seed": 0}]}})
    assert study_prediction.cli(["--seeds", "1", "--fast-only", "--out", str(tmp_path)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {message}"]


def test_the_best_scale_of_a_mean_curve_is_the_least_squares_factor(tmp_path):
    import numpy as np

    from fiberpipe.studies.fit import read_target

    U_t, F_t = read_target(study_prediction.TARGET)
    U, study_curve = U_t, F_t  # the mean curve sampled at the study's points
    for shape, factor in ((study_curve, 0.25), (study_curve + 1.0, 1.0)):  # the study's shape; a shifted one
        rows = ["U_m,load_mean_N"] + [f"{u:.9g},{factor * f:.9g}" for u, f in zip(U, shape)]
        (tmp_path / "ensemble.csv").write_text("\n".join(rows) + "\n")
        result = study_prediction.against_study(tmp_path)
        mean = factor * np.interp(U_t, U, shape)
        scale = float(mean @ F_t / (mean @ mean))
        assert result["best_scale"] == pytest.approx(scale, rel=1e-6)
        assert result["best_scaled_rms_N"] == pytest.approx(float(np.sqrt(np.mean((scale * mean - F_t) ** 2))), rel=1e-6)
    assert study_prediction.against_study(tmp_path)["best_scaled_rms_N"] > 0.1  # a shifted shape cannot be scaled onto it
    (tmp_path / "ensemble.csv").write_text("\n".join(["U_m,load_mean_N"] + [f"{u:.9g},{0.25 * f:.9g}" for u, f in zip(U, study_curve)]) + "\n")
    exact = study_prediction.against_study(tmp_path)
    assert exact["best_scale"] == pytest.approx(4.0, rel=1e-6) and exact["best_scaled_rms_N"] < 1e-6
