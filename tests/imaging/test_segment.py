import numpy as np
import pytest

from fiberpipe.errors import InputError
from fiberpipe.imaging.phantom import make_phantom, render_polylines
from fiberpipe.imaging.segment import segment


def test_otsu_on_phantom_matches_true_occupancy():
    vol, truth = make_phantom(n_fibers=20, shape=(80, 80, 80), contrast_to_noise=4.0, seed=1)
    mask, info = segment(vol)
    ideal = render_polylines(truth, vol.shape, truth.meta["voxel_size_m"], blur_sigma_vox=0,
                             contrast_to_noise=None) > 0.5
    assert mask.dtype == bool and mask.shape == vol.shape
    assert 0.2 < info["threshold"] < 0.8
    assert info["volume_fraction"] == pytest.approx(ideal.mean(), rel=0.1)
    assert np.mean(mask == ideal) > 0.95
    assert info["n_components"] >= 1


def test_fixed_threshold_small_objects_and_holes():
    vol = np.zeros((30, 30, 30), np.float32)
    vol[5:25, 5:25, 5:25] = 1.0
    vol[12:16, 12:16, 12:16] = 0.0  # an enclosed cavity
    vol[1, 1, 1] = 1.0  # a one-voxel speck
    mask, info = segment(vol, method="fixed", threshold=0.5, smooth_sigma_vox=0, min_object_vox=10)
    assert mask[14, 14, 14] and not mask[1, 1, 1]
    assert info["n_components"] == 1 and info["volume_fraction"] == pytest.approx(20**3 / 30**3)
    mask, _ = segment(vol, method="fixed", threshold=0.5, smooth_sigma_vox=0, min_object_vox=0,
                      fill_holes=False)
    assert not mask[14, 14, 14] and mask[1, 1, 1]
    inv, _ = segment(1 - vol, method="fixed", threshold=0.5, smooth_sigma_vox=0, invert=True)
    assert inv[10, 10, 10]


def test_empty_full_and_bad_arguments():
    vol = np.random.default_rng(0).random((10, 10, 10)).astype(np.float32)
    with pytest.raises(InputError, match="empty"):
        segment(vol, method="fixed", threshold=2.0)
    with pytest.raises(InputError, match="whole volume"):
        segment(vol, method="fixed", threshold=-1.0, fill_holes=False)
    with pytest.raises(InputError, match="threshold"):
        segment(vol, method="fixed")
    with pytest.raises(InputError, match="unknown method"):
        segment(vol, method="magic")
    with pytest.raises(InputError, match="3D"):
        segment(vol[0])
    with pytest.raises(InputError, match="constant"):
        segment(np.ones((5, 5, 5)))
