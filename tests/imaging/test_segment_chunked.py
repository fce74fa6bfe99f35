"""Slab-by-slab segmentation equals the whole-volume one, across slab boundaries."""

import numpy as np
import pytest

from fiberpipe.imaging.phantom import make_phantom
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.segment_chunked import segment_chunked


def _volume():
    vol, _ = make_phantom(n_fibers=8, shape=(60, 48, 48), radius_vox=4, contrast_to_noise=3.0, seed=2)
    # a hollow ball whose cavity spans several slabs (filled), a hollow ball open to the border
    # (not filled), small specks astride slab boundaries (removed) and one large enough (kept)
    z, y, x = np.ogrid[:60, :48, :48]
    d = np.sqrt((z - 30) ** 2 + (y - 24) ** 2 + (x - 24) ** 2)
    vol[(d > 6) & (d < 9)] = 1.0
    vol[(d <= 6)] = 0.0
    vol[6:9, 3:5, 40:42] = 1.0     # 12 voxels across the boundary at 7
    vol[13:15, 40:46, 40:46] = 1.0  # 72 voxels across the boundary at 14
    return vol


@pytest.mark.parametrize("slab", [7, 13, 60])
def test_slab_segmentation_equals_the_whole_volume_one(slab):
    vol = _volume()
    ref, info = segment(vol, min_object_vox=30)
    out = np.zeros(vol.shape, dtype=bool)
    got = segment_chunked(vol, out, slab=slab, min_object_vox=30)
    assert got["threshold"] == pytest.approx(info["threshold"], rel=1e-6)
    assert np.array_equal(out, ref), int((out != ref).sum())
    assert got["n_components"] == info["n_components"]
    assert got["volume_fraction"] == pytest.approx(info["volume_fraction"])


def test_slab_segmentation_into_hdf5(tmp_path):
    import h5py

    vol = _volume()
    ref, _ = segment(vol)
    with h5py.File(tmp_path / "m.h5", "w") as f:
        ds = f.create_dataset("mask", shape=vol.shape, dtype=bool, chunks=(8, 48, 48), compression="lzf")
        segment_chunked(vol, ds, slab=9)
        assert np.array_equal(ds[()], ref)


def test_slabs_on_a_dask_cluster_give_the_one_process_mask(tmp_path):
    """The slabs on a local two-worker Dask cluster (workers read the .npy file themselves): the
    mask equals the whole-volume segment's voxel for voxel, cavity, shell and specks included."""
    distributed = pytest.importorskip("dask.distributed")
    from fiberpipe.imaging.volume_source import open_volume_source

    vol = _volume().astype(np.float32)
    np.save(tmp_path / "v.npy", vol)
    ref, info = segment(vol, min_object_vox=30)
    src, _, _ = open_volume_source(tmp_path / "v.npy")
    out = np.zeros(vol.shape, dtype=bool)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        with distributed.Client(c) as client:
            got = segment_chunked(src, out, slab=13, min_object_vox=30, scheduler=client)
    assert np.array_equal(out, ref), int((out != ref).sum())
    assert got["threshold"] == pytest.approx(info["threshold"], rel=1e-6)
    assert got["n_components"] == info["n_components"]
