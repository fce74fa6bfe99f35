"""Slab-by-slab skeleton against the whole-volume one."""

import h5py
import numpy as np
import pytest
from scipy.spatial import cKDTree

from fiberpipe.imaging.phantom import make_phantom
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.skeleton import skeletonize
from fiberpipe.imaging.skeleton_chunked import skeletonize_chunked
from fiberpipe.imaging.trace_chunked import SliceSource


@pytest.fixture(scope="module")
def mask():
    vol, _ = make_phantom(n_fibers=10, shape=(120, 64, 64), radius_vox=4.0, touching_fraction=0.0,
                          contrast_to_noise=6.0, seed=3)
    m, _ = segment(vol)
    return m


@pytest.mark.parametrize("slab,tile", [(17, 512), (50, 30)])
def test_slab_skeleton_matches_the_whole_one(mask, slab, tile):
    """Skeleton voxels of slabs (halo 24) lie within one voxel of the whole-volume skeleton and vice versa; radius equal there."""
    sk, rad = skeletonize(mask)
    out_s, out_r = np.zeros_like(sk), np.zeros(mask.shape, np.float32)
    info = skeletonize_chunked(mask, out_s, out_r, slab=slab, halo=24, tile=tile)
    assert info["slabs"] == -(-mask.shape[0] // slab)
    a, b = np.argwhere(sk), np.argwhere(out_s)
    assert abs(len(b) - len(a)) <= 0.02 * len(a)
    assert np.mean(cKDTree(a).query(b)[0] <= 1.8) >= 0.99
    assert np.mean(cKDTree(b).query(a)[0] <= 1.8) >= 0.99
    both = sk & out_s
    assert np.allclose(rad[both], out_r[both], atol=1e-5)


def test_slab_skeleton_from_hdf5_on_dask(tmp_path, mask):
    """Read from HDF5 by workers of a local Dask cluster, written into HDF5: same skeleton as in process."""
    distributed = pytest.importorskip("dask.distributed")
    p = tmp_path / "mask.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("mask", data=mask, chunks=(16, 64, 64))
    ref_s, ref_r = np.zeros(mask.shape, bool), np.zeros(mask.shape, np.float32)
    skeletonize_chunked(mask, ref_s, ref_r, slab=40, halo=16, tile=40)
    with h5py.File(tmp_path / "skel.h5", "w") as g, \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as c, \
            distributed.Client(c) as client:
        s = g.create_dataset("skeleton", shape=mask.shape, dtype=bool)
        r = g.create_dataset("radius_vox", shape=mask.shape, dtype=np.float32)
        skeletonize_chunked(SliceSource(p, "mask"), s, r, slab=40, halo=16, tile=40, scheduler=client)
        assert np.array_equal(s[...], ref_s) and np.allclose(r[...], ref_r)


def test_halo_thinner_than_a_radius_is_refused(mask):
    from fiberpipe.errors import InputError

    with pytest.raises(InputError, match="raise the halo"):
        skeletonize_chunked(mask, np.zeros(mask.shape, bool), np.zeros(mask.shape, np.float32), slab=40, halo=3)
