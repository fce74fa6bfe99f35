"""``fiberpipe specimen``: a virtual specimen from a config's specimen section, deterministic by
seed, in its cassette at the target v_f0, with its report and a ready config; specimens that
cannot fit their cassette are refused with one line."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fiberpipe.artifacts import read_fibers
from fiberpipe.cli import main
from fiberpipe.config import load_config
from fiberpipe.model.virtual_specimen import build_specimen
from fiberpipe.post.geometry import projected_curvature

REPO = Path(__file__).resolve().parents[2]
R = 0.25e-3


def base(**specimen) -> dict:
    """The study's scene (configs/paper-40.yaml) with a specimen section."""
    return {"extends": str(REPO / "configs" / "paper-40.yaml"), "name": "virtual",
            "specimen": {"settle": {"enabled": False}, **specimen}}


def _build(tmp_path, name, **specimen):
    from fiberpipe.config import load_raw

    (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(base(**specimen)))
    info = build_specimen(load_raw(tmp_path / f"{name}.yaml"), tmp_path / name, where=name)
    return read_fibers(tmp_path / name / "fibers.h5"), info


SMALL = dict(n_fibers=10, width="1.5 mm", volume_fraction=0.3, candidates=4)


@pytest.fixture(scope="module")
def seed3(tmp_path_factory):
    """The small specimen (10 fibers, 1.5 mm cassette, v_f0 = 30 %) of seed 3: (folder, fibers, info)."""
    d = tmp_path_factory.mktemp("seed3")
    fibers, info = _build(d, "a", seed=3, **SMALL)
    return d / "a", fibers, info


def test_specimen_is_deterministic_by_seed(tmp_path, seed3):
    _, a, _ = seed3
    b, _ = _build(tmp_path, "b", seed=3, **SMALL)
    c, _ = _build(tmp_path, "c", seed=4, **SMALL)
    assert np.array_equal(a.points_m, b.points_m)
    assert not np.allclose(a.points_m, c.points_m)


def _check_fits_its_cassette(d, fibers, info, n, width, vf0, min_contacts):
    """The specimen in folder ``d`` (n fibers of R, cassette ``width``) under its plate at ``vf0``,
    without overlaps, inside the walls, its config ready to run."""
    h = info["height_m"]
    assert h == pytest.approx(n * math.pi * R**2 / (vf0 * width), rel=1e-12)
    assert info["volume_fraction"] == pytest.approx(vf0, rel=0.005)
    # independently: Σ π r² × arc length over the box (tilted, bowed fibers are a little longer)
    assert info["statistics"]["volume_fraction"] == pytest.approx(vf0, rel=0.005)
    pts = fibers.points_m
    assert np.max(pts[:, 1] + R) <= h and np.min(pts[:, 1] - R) >= 0
    assert info["statistics"]["max_outside_m"] <= 1e-9  # inside the walls
    assert info["statistics"]["min_gap_m"] >= 0.9e-6  # no overlaps: the 1 µm clearance
    assert info["contacts_at_U0"]["fiber_fiber"] > min_contacts
    assert sum(info["phi_histogram_deg"]["counts"]) == info["statistics"]["neighbour_pairs"]
    cfg = load_config(d / "config.yaml")  # ready to run
    assert cfg.input.fibers == str((d / "fibers.h5").resolve())
    assert cfg.scene.plates.upper_position == pytest.approx(h) and cfg.scene.plates.lower_position == 0
    assert cfg.scene.walls.x == [-width / 2, width / 2]
    assert "specimen" not in yaml.safe_load((d / "config.yaml").read_text())
    assert json.loads((d / "specimen.json").read_text())["height_m"] == h


def test_specimen_fits_its_cassette_at_the_target_vf0(seed3):
    """10 fibers in a 1.5 mm cassette at v_f0 = 30 %, four trial drops per fiber: the study
    specimen's checks (test_study_specimen_fits_its_cassette_at_the_target_vf0, 40 fibers, slow)
    on a specimen a quarter its size (measured: 15 fiber–fiber contacts at U = 0)."""
    d, fibers, info = seed3
    _check_fits_its_cassette(d, fibers, info, 10, 1.5e-3, 0.3, min_contacts=10)


@pytest.mark.slow
def test_study_specimen_fits_its_cassette_at_the_target_vf0(tmp_path):
    """40 fibers of the study (Ø 0.5 mm, 15 mm, 3 mm cassette) at v_f0 = 37.7 %: four trial drops per
    fiber make a pile denser than that, so it fits under the plate without settling (≈ 20 s; the
    default suite checks the same on 10 fibers: test_specimen_fits_its_cassette_at_the_target_vf0)."""
    fibers, info = _build(tmp_path, "s", n_fibers=40, candidates=4, volume_fraction=0.377)
    _check_fits_its_cassette(tmp_path / "s", fibers, info, 40, 3e-3, 0.377, min_contacts=20)


@pytest.mark.parametrize("plane, on, off", [("flat", "xz", "yz"), ("upright", "yz", "xz")])
def test_bow_plane_puts_the_spool_curvature_on_its_projection(tmp_path, plane, on, off):
    """Arcs of radius 60 mm in the x-z (flat) or y-z (upright) plane: that projection measures 1/R."""
    fibers, _ = _build(tmp_path, plane, n_fibers=8, width="2 mm", volume_fraction=0.2, candidates=1,
                       bow={"spool_radius": "60 mm", "plane": plane})
    assert projected_curvature(fibers.points_m, fibers.offsets, on) == pytest.approx(1 / 0.06, rel=0.03)
    assert projected_curvature(fibers.points_m, fibers.offsets, off) < 0.05 / 0.06


def test_spool_radius_range_bows_each_fiber_within_it(tmp_path):
    fibers, info = _build(tmp_path, "rng", n_fibers=12, width="2 mm", volume_fraction=0.2, candidates=1,
                          bow={"spool_radius_range": ["40 mm", "90 mm"], "plane": "flat"})
    k = [projected_curvature(fibers.points_m[fibers.offsets[i]:fibers.offsets[i + 1]],
                             np.array([0, fibers.offsets[i + 1] - fibers.offsets[i]]), "xz") for i in range(12)]
    assert min(k) >= (1 / 0.09) * 0.97 and max(k) <= (1 / 0.04) * 1.03
    assert max(k) / min(k) > 1.3  # drawn, not one radius
    assert info["generator"]["spool_radius_range_m"] == [0.04, 0.09]


def test_settled_specimen_reports_the_settling(tmp_path):
    raw = base(n_fibers=6, width="1.5 mm", volume_fraction=0.2, candidates=2, upper_plate="pile",
               settle={"enabled": True, "time": "1 ms", "frames": 3})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    r = CliRunner().invoke(main, ["specimen", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    for words in ("v_f0", "contacts at U = 0", "Phi histogram", "Table 4 curvatures", "settled 1 ms",
                  "deposited 6 fibers in"):
        assert words in r.output
    info = json.loads((tmp_path / "o" / "specimen.json").read_text())
    assert info["settle"]["lock_axial"] == "all" and info["settle"]["steps"] > 0
    fibers = read_fibers(tmp_path / "o" / "fibers.h5")
    assert info["height_m"] == pytest.approx(float(np.max(fibers.points_m[:, 1] + R)) + 1e-6)


def test_specimen_progress_follows_the_deposit_and_the_settling(tmp_path, monkeypatch):
    """With progress asked for (the command line on a terminal), the deposit's bar advances fiber by
    fiber and the settling's in simulated time up to its end; each bar is closed."""
    from fiberpipe.config import load_raw

    seen = {}

    def bar(label):
        calls = seen.setdefault(label, [])

        def update(done, total, *_more):
            calls.append((done, total))

        update.close = lambda: calls.append("closed")
        return update

    monkeypatch.setattr("fiberpipe.progress.terminal_bar", bar)
    raw = base(n_fibers=6, width="1.5 mm", volume_fraction=0.2, candidates=2, upper_plate="pile",
               settle={"enabled": True, "time": "1 ms", "frames": 3})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    info = build_specimen(load_raw(tmp_path / "c.yaml"), tmp_path / "o", where="c", progress=True)
    assert info["deposit"]["wall_time_s"] > 0
    assert seen["deposit"] == [(k, 6) for k in range(1, 7)] + ["closed"]
    settle = seen["settle"]
    assert settle[-1] == "closed" and len(settle) >= 2
    t_last, end = settle[-2]
    assert end == pytest.approx(1e-3) and end <= t_last < 1.01 * end  # the last step reaches the end
    assert all(a[0] <= b[0] for a, b in zip(settle[:-2], settle[1:-1]))  # simulated time only grows


@pytest.mark.parametrize("specimen, words", [
    ({"width": "0.4 mm"}, "cannot hold a fiber of diameter 0.5 mm"),
    ({"bow": {"spool_radius": "5 mm"}}, "cannot bend a 15 mm fiber"),
    ({"width": "1 mm", "bow": {"spool_radius": "20 mm", "plane": "flat"}}, "spans 1.46 mm across"),
    ({"n_fibers": 10, "width": "1.5 mm", "volume_fraction": 0.85, "candidates": 1}, "does not fit its cassette under"),
    ({"volume_fraction": 0.95}, "specimen.volume_fraction"),
])
def test_a_specimen_that_cannot_fit_its_cassette_is_refused_with_one_line(tmp_path, specimen, words):
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(base(**specimen)))
    r = CliRunner().invoke(main, ["specimen", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0], r.output


@pytest.mark.slow
def test_the_study_specimen_settled_under_the_target_plate(tmp_path):
    """configs/specimens/paper-40-target.yaml: deposited, settled 150 ms with friction and the axial
    lock (≈ 7 min on one core), the upper plate at the target v_f0."""
    r = CliRunner().invoke(main, ["specimen", str(REPO / "configs" / "specimens" / "paper-40-target.yaml"),
                                  "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    info = json.loads((tmp_path / "o" / "specimen.json").read_text())
    assert info["volume_fraction"] == pytest.approx(0.377, rel=0.005)
    assert info["statistics"]["volume_fraction"] == pytest.approx(0.377, rel=0.005)
    assert info["pile_top_m"] <= info["height_m"]


@pytest.mark.slow
def test_a_400_fiber_specimen_builds(tmp_path):
    """configs/specimens/bundle-400.yaml (its build time is measured by `make specimen-400`)."""
    r = CliRunner().invoke(main, ["specimen", str(REPO / "configs" / "specimens" / "bundle-400.yaml"),
                                  "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    info = json.loads((tmp_path / "o" / "specimen.json").read_text())
    assert info["generator"]["n_fibers"] == 400
    # settled with gravity × 100 (and mass × 100): contacts and plates pressed a few tenths of a µm
    assert info["statistics"]["min_gap_m"] >= -1e-6 and info["statistics"]["max_outside_m"] <= 0.1e-6
    assert info["settle"]["kinetic_energy_end_J"] < 0.05 * info["settle"]["kinetic_energy_max_J"]


def test_specimen_strain_sets_the_loading_to_that_strain_of_its_plate_gap(tmp_path):
    """``specimen.strain``: the ready config compacts the specimen by U = strain × its plate gap (a
    specimen of another height at the base config's nominal strain U/h0); without it, the base's U."""
    _, info = _build(tmp_path, "strain", n_fibers=6, width="1.5 mm", volume_fraction=0.3, strain=0.175)
    cfg = load_config(tmp_path / "strain" / "config.yaml")
    assert cfg.scene.loading.displacement == pytest.approx(0.175 * info["height_m"], rel=1e-12)
    assert cfg.scene.plates.upper_position == pytest.approx(info["height_m"])
    _build(tmp_path, "base", n_fibers=6, width="1.5 mm", volume_fraction=0.3)
    assert load_config(tmp_path / "base" / "config.yaml").scene.loading.displacement == pytest.approx(1.15e-3)
