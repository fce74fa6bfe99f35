"""Orientation distribution (mask structure tensor and traced fibers) and the tracer choice."""

import json

import numpy as np
import pytest

from fiberpipe.imaging.orientation import fiber_orientation, is_quasi_parallel, mask_orientation
from fiberpipe.imaging.phantom import make_phantom, make_short_fiber_phantom
from fiberpipe.imaging.profile import fwhm_radius_vox
from fiberpipe.imaging.segment import segment
from fiberpipe.polylines import Polylines


def _isotropic_planar_lines(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0, np.pi, n)
    d = np.c_[np.cos(phi), np.sin(phi), np.zeros(n)]
    return Polylines.from_list([np.vstack([np.zeros(3), 1e-3 * u]) for u in d], 1e-5)


def test_fiber_orientation_tensor_of_known_distributions():
    # all along z: A = diag(0, 0, 1), every angle 0
    z = Polylines.from_list([np.c_[np.zeros(5) + i, np.zeros(5), np.arange(5.0)] * 1e-4 for i in range(3)], 1e-5)
    o = fiber_orientation(z)
    assert np.allclose(o["tensor"], np.diag([0, 0, 1]), atol=1e-9)
    assert o["eigenvalues"][0] == pytest.approx(1.0) and o["aligned_fraction_45deg"] == 1.0
    assert o["angle_histogram"]["fraction"][0] == pytest.approx(1.0)
    # isotropic in the x-y plane: eigenvalues 1/2, 1/2, 0; angles to the dominant axis uniform on
    # 0..90 deg, so each 5-degree bin holds 1/18 and half lie within 45 deg
    o = fiber_orientation(_isotropic_planar_lines())
    assert np.allclose(o["eigenvalues"], [0.5, 0.5, 0.0], atol=0.03)
    assert np.allclose(o["angle_histogram"]["fraction"], 1 / 18, atol=0.02)
    assert o["aligned_fraction_45deg"] == pytest.approx(0.5, abs=0.05)


@pytest.mark.parametrize("orientation", ["planar", "isotropic"])
def test_mask_orientation_agrees_with_the_true_fibers(orientation):
    vol, truth = make_short_fiber_phantom(shape=(60, 120, 120), n_fibers=60, orientation=orientation, seed=3)
    mask, _ = segment(vol)
    om = mask_orientation(mask, truth.meta["voxel_size_m"])
    ot = fiber_orientation(truth)
    assert om["aligned_fraction_45deg"] == pytest.approx(ot["aligned_fraction_45deg"], abs=0.08)
    assert np.allclose(om["eigenvalues"], ot["eigenvalues"], atol=0.08)
    assert not is_quasi_parallel(om, 0.9)


def test_quasi_parallel_phantom_is_recognised():
    vol, truth = make_phantom(n_fibers=20, shape=(120, 80, 80), radius_vox=4, seed=1)
    om = mask_orientation(segment(vol)[0], truth.meta["voxel_size_m"])
    assert om["nearest_volume_axis"] == "z" and om["aligned_fraction_45deg"] > 0.98
    assert om["eigenvalues"][0] > 0.95 and is_quasi_parallel(om, 0.9)


@pytest.mark.parametrize("r", [2.0, 3.5])
def test_fwhm_radius_recovers_the_phantom_radius(r):
    vol, truth = make_short_fiber_phantom(shape=(50, 100, 100), n_fibers=40, radius_vox=r, seed=2)
    got = fwhm_radius_vox(vol, truth, truth.meta["voxel_size_m"])
    assert got["n_used"] > 0.8 * got["n_profiles"]
    assert got["median_radius_vox"] == pytest.approx(r, rel=0.06)


def test_auto_picks_the_skeleton_tracer_for_a_fiber_mat_and_reports_the_distribution(tmp_path, write_yaml):
    from fiberpipe.config import load_config
    from fiberpipe.imaging.io import save_volume_tif
    from fiberpipe.pipeline import run_pipeline

    vol, truth = make_short_fiber_phantom(shape=(50, 120, 120), n_fibers=50, radius_vox=2.5, length_vox=(40, 90),
                                          seed=4, dtype=np.uint8)
    p = tmp_path / "mat.tif"
    save_volume_tif(p, vol, truth.meta["voxel_size_m"])
    cfg = load_config(write_yaml(f"input: {{volume: {p}}}\nmesh: {{element_length: 0.1 mm}}\n"))
    assert cfg.trace.method == "auto"
    run_pipeline(cfg, tmp_path / "run", to_stage="mesh")
    tr = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]["trace"]
    assert tr["method"] == "skeleton"
    assert tr["aligned_fraction_45deg_mask"] < 0.9
    o = tr["orientation"]
    assert len(o["angle_histogram"]["fraction"]) == len(o["angle_histogram"]["bin_edges_deg"]) - 1
    assert sum(o["angle_histogram"]["fraction"]) == pytest.approx(1.0, abs=1e-4)
    assert np.allclose(np.trace(np.array(o["tensor"])), 1.0, atol=1e-4)
    saved = json.loads((tmp_path / "run" / "orientation.json").read_text())
    assert set(saved) == {"mask", "fibers"}
    for name in ("trace_slices.png", "trace_midlines.png", "orientation.png"):
        assert (tmp_path / "run" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert tr["pictures"] == ["trace_slices.png", "trace_midlines.png", "orientation.png"]


def test_crossings_of_a_tilted_line_with_a_slice_are_where_the_line_meets_the_plane():
    from fiberpipe.imaging.overlay import crossings

    vs = (2e-5, 1e-5, 1e-5)  # dz = 2 dx: the z index of a point is its z / dz
    p = np.array([[3.0, 4.0, 0.0], [13.0, 9.0, 40.0]]) * 1e-5  # x y z, m
    P, ids = crossings(Polylines.from_list([p], 1e-5), 0, 10.0, vs)  # plane z index 10 = z 20e-5 m: halfway
    assert list(ids) == [0] and np.allclose(P, [[6.5, 8.0]])  # (y, x) in voxels


def test_explicit_slices_on_a_fiber_mat_warns_naming_the_key(tmp_path, write_yaml, caplog):
    from fiberpipe.config import load_config
    from fiberpipe.imaging.io import save_volume_tif
    from fiberpipe.pipeline import run_pipeline

    vol, truth = make_short_fiber_phantom(shape=(50, 100, 100), n_fibers=40, radius_vox=2.5, seed=5, dtype=np.uint8)
    p = tmp_path / "mat.tif"
    save_volume_tif(p, vol, truth.meta["voxel_size_m"])
    cfg = load_config(write_yaml(f"input: {{volume: {p}}}\ntrace: {{method: slices, min_length: 0}}\n"
                                 "skeletonize: {enabled: false}\n"))
    with caplog.at_level("WARNING", logger="fiberpipe"):
        run_pipeline(cfg, tmp_path / "run", to_stage="trace")
    msgs = [r.getMessage() for r in caplog.records if "quasi-parallel" in r.getMessage()]
    assert len(msgs) == 1 and "trace.method: skeleton" in msgs[0] and "\n" not in msgs[0]
