"""Smoke test on real CT (quanfima polymer scaffold, 128^3 uint8); skipped without ../shared."""

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
