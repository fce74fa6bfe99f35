"""Smoke test on real CT (quanfima polymer scaffold, 128^3 uint8); skipped when the sample is not beside the checkout."""

from pathlib import Path

import numpy as np
import pytest

from fiberpipe.imaging.io import load_volume
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.skeleton import skeletonize
from fiberpipe.imaging.trace import trace

RAW = Path(__file__).resolve().parents[2] / ".." / "shared" / "data-real" / "quanfima_polymer3d" / \
    "polymer3d_8bit_128x128x128.raw"


@pytest.mark.skipif(not RAW.exists(), reason="shared real CT data not present")
def test_real_polymer_scaffold_smoke():
    vol, vs, src = load_volume(RAW, shape=(128, 128, 128), dtype="uint8", voxel_size_m=1e-6)
    assert vol.shape == (128, 128, 128) and src.startswith("raw:")
    mask, info = segment(vol)
    assert 0.05 < info["volume_fraction"] < 0.3
    skel, rad = skeletonize(mask)
    diam = 2 * np.median(rad[skel])
    assert 2.5 <= diam <= 5.0  # the data README's estimate: about 3.5 voxels
    fibers = trace(mask, voxel_size_m=vs)
    assert fibers.n_fibers > 5
    assert np.all(np.isfinite(fibers.points_m))
    d = 2 * np.median(fibers.radius_m) / 1e-6
    assert 2.0 <= d <= 6.0
    sk = trace(mask, voxel_size_m=vs, method="skeleton", skeleton=skel, radius_vox=rad)
    assert sk.n_fibers > 5 and np.all(np.isfinite(sk.points_m))


@pytest.mark.skipif(not RAW.exists(), reason="shared real CT data not present")
def test_real_scan_runs_end_to_end_with_the_default_settings(tmp_path, write_yaml):
    """Input, voxel size and a short simulation given; every imaging and mesh setting default."""
    import json

    from fiberpipe.artifacts import read_fibers
    from fiberpipe.config import load_config
    from fiberpipe.imaging.profile import fwhm_radius_vox
    from fiberpipe.pipeline import run_pipeline

    cfg = load_config(write_yaml(
        f"input: {{volume: {RAW}, shape: [128, 128, 128], dtype: uint8, voxel_size: 10 um}}\n"
        "scene: {effects: [gravity, damping]}\nsolver: {end_time: 2 us, output_frames: 2}\n"))
    run_pipeline(cfg, tmp_path / "run")
    st = json.loads((tmp_path / "run" / "summary.json").read_text())["stages"]
    assert {"segment", "skeletonize", "trace", "mesh", "simulate", "post"} <= set(st)
    tr = st["trace"]
    # the tracer follows the measured orientation (this scaffold is not quasi-parallel)
    assert tr["method"] == ("slices" if tr["aligned_fraction_45deg_mask"] >= 0.9 else "skeleton")
    assert tr["dropped_short_fibers"] > 0 and tr["fibers"] > 20 and st["mesh"]["fibers"] == tr["fibers"]
    # the traced median radius against the scan's own (FWHM of grey profiles), within 20 %
    vol, vs, _ = load_volume(RAW, shape=(128, 128, 128), dtype="uint8", voxel_size_m=1e-5)
    fibers = read_fibers(tmp_path / "run" / "fibers.h5")
    scan = fwhm_radius_vox(vol, fibers, vs)["median_radius_vox"]
    traced = float(np.median(fibers.radius_m)) / 1e-5
    assert traced == pytest.approx(scan, rel=0.2), (traced, scan)
