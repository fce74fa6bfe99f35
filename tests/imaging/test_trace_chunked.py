"""Tracing a mask on disk block by block (volumes larger than memory), in process and on Dask."""

import h5py
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from fiberpipe.imaging.accuracy import trace_accuracy
from fiberpipe.imaging.phantom import make_hard_phantom
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.trace import _BIG, assign_within, trace
from fiberpipe.imaging.trace_chunked import SliceSource, trace_chunked


def test_sparse_assignment_matches_the_dense_hungarian():
    """assign_within: as many pairs and the same total distance as the Hungarian on the full gated matrix."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        n, m = rng.integers(1, 30, 2)
        a, b = rng.uniform(0, 20, (n, 2)), rng.uniform(0, 20, (m, 2))
        lim = rng.uniform(0.5, 4, n)
        got = assign_within(a, b, lim)
        C = np.linalg.norm(a[:, None] - b[None], axis=2)
        C[C > lim[:, None]] = _BIG
        rr, cc = linear_sum_assignment(C)
        ref = [(i, j) for i, j in zip(rr, cc) if C[i, j] < _BIG]
        assert len(got) == len(ref)
        assert sum(C[i, j] for i, j in got) == pytest.approx(sum(C[i, j] for i, j in ref), abs=1e-9)
        assert len({i for i, _ in got}) == len(got) == len({j for _, j in got})


@pytest.fixture(scope="module")
def on_disk(tmp_path_factory):
    vol, truth = make_hard_phantom(2)
    mask, _ = segment(vol)
    p = tmp_path_factory.mktemp("chunked") / "mask.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("mask", data=mask, chunks=(16, 64, 64), compression="lzf")
    return p, mask, truth


@pytest.mark.parametrize("block", [40, 64, 1000])
def test_blocks_give_the_whole_volume_tracing(on_disk, block):
    """Blocks of 40 / 64 / all slices read from HDF5: same fibers, each whole (joined across block boundaries)."""
    p, mask, truth = on_disk
    vs = truth.meta["voxel_size_m"]
    r = truth.meta["radius_vox"] * vs
    ref = trace(mask, voxel_size_m=vs, expected_radius_m=r, off_axis="none")
    got = trace_chunked(SliceSource(p, "mask"), vs, expected_radius_m=r, block=block)
    assert got.meta["blocks"] == -(-mask.shape[0] // block)
    acc = trace_accuracy(got, truth, voxel_size_m=vs)
    assert acc["recall"] >= 0.98 and acc["precision"] >= 0.98 and acc["n_split"] == 0, acc
    assert acc["mean_error_vox"] <= 0.30
    ra = trace_accuracy(ref, truth, voxel_size_m=vs)
    assert got.n_fibers == ref.n_fibers
    assert acc["mean_error_vox"] == pytest.approx(ra["mean_error_vox"], abs=0.01)


def test_blocks_run_on_a_dask_cluster(on_disk):
    """The same blocks on a local Dask cluster (two workers, processes) give the in-process result."""
    distributed = pytest.importorskip("dask.distributed")
    p, mask, truth = on_disk
    vs = truth.meta["voxel_size_m"]
    r = truth.meta["radius_vox"] * vs
    local = trace_chunked(SliceSource(p, "mask"), vs, expected_radius_m=r, block=48)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        with distributed.Client(c) as client:
            remote = trace_chunked(SliceSource(p, "mask"), vs, expected_radius_m=r, block=48, scheduler=client)
    assert remote.n_fibers == local.n_fibers
    for a, b in zip(local, remote):
        assert np.allclose(a, b)


def test_missing_dataset_is_one_line(tmp_path, on_disk):
    from fiberpipe.errors import InputError

    p, _, _ = on_disk
    with pytest.raises(InputError, match="dataset 'nope' not found"):
        trace_chunked(SliceSource(p, "nope"), 1e-5, expected_radius_m=5e-5)


def test_large_volume_benchmark_runs_every_pass(tmp_path, capsys):
    """bench_large_volume on a small volume: the three passes report wall time, CPU time and peak memory; full-length fibers."""
    from imaging._bench_scripts import load_bench

    bench_large_volume = load_bench("bench_large_volume")

    bench_large_volume.main(["--shape", "40", "96", "96", "--slab", "16", "--block", "16", "--dir", str(tmp_path)])
    out = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in out.splitlines() if line.startswith("| ") and "{" in line}
    assert set(rows) == {"segment", "trace", "skeleton"}, out
    import json

    trace_row = json.loads(rows["trace"].split("|")[5])
    assert trace_row["fibers"] == 25 and trace_row["fibers_full_length"] == 25  # the 5 x 5 grid, whole length
    assert not list(tmp_path.iterdir())  # nothing left behind


def test_blocks_across_x_when_the_fibers_run_along_x(on_disk, tmp_path):
    """The mask turned so the fibers run along x: axis 'auto' finds x from the orientation of a
    strided sample, reads its blocks as boxes across x, and gives the fibers of the unturned mask."""
    from fiberpipe.polylines import Polylines

    p, mask, truth = on_disk
    vs = truth.meta["voxel_size_m"]
    r = truth.meta["radius_vox"] * vs
    with h5py.File(tmp_path / "x.h5", "w") as f:
        f.create_dataset("mask", data=np.ascontiguousarray(mask.transpose(1, 2, 0)), chunks=(16, 64, 64),
                         compression="lzf")
    turned = trace_chunked(SliceSource(tmp_path / "x.h5", "mask"), vs, expected_radius_m=r, block=48)
    assert turned.meta["axis"] == 2
    ref = trace_chunked(SliceSource(p, "mask"), vs, expected_radius_m=r, block=48, axis=0)
    back = Polylines(turned.points_m[:, [1, 2, 0]].copy(), turned.offsets, turned.radius_m)  # x y z <- z x y
    assert back.n_fibers == ref.n_fibers
    acc = trace_accuracy(back, ref, voxel_size_m=vs)
    assert acc["recall"] == 1.0 and acc["precision"] == 1.0 and acc["mean_error_vox"] <= 0.05, acc


def test_the_chunked_dense_tracer_leaves_an_oblique_ply_out_and_counts_it():
    """Fibers along z beside a ply 40 degrees off z (x-z plane): the chunked dense tracer (blocks of
    16 slices, grey detection) keeps the z fibers, leaves the ply's tracks out and reports them in
    ``meta["oblique"]``, as the in-memory tracer does; no kept track is more than 30 degrees off z."""
    from fiberpipe.imaging.phantom import render_polylines
    from fiberpipe.polylines import Polylines

    vs, r, shape = 1e-6, 2.5, (48, 40, 64)
    z = np.linspace(-2, 49, 52)
    lines = [np.column_stack([np.full_like(z, x), np.full_like(z, y), z]) for x in (4, 10, 16, 22) for y in (6, 14, 22, 30)]
    tilt = np.tan(np.radians(40))
    lines += [np.column_stack([x0 + tilt * z, np.full_like(z, y), z]) for x0 in (36, 44) for y in (6, 14, 22, 30)]
    fibers = Polylines.from_list([p * vs for p in lines], r * vs)
    vol = render_polylines(fibers, shape, vs, blur_sigma_vox=0.8, contrast_to_noise=6.0, seed=3)
    mask = vol > 0.5
    ref = trace(mask, voxel_size_m=vs, method="dense", grey=vol, expected_radius_m=r * vs, off_axis="none")
    got = trace_chunked(mask, vs, expected_radius_m=r * vs, block=16, grey=vol, radius_from="grey", axis=0)
    for out in (ref, got):
        assert out.meta["oblique"]["fibers"] >= 4, out.meta.get("oblique")
        for i in range(out.n_fibers):
            d = out.fiber(i)[-1] - out.fiber(i)[0]
            assert np.degrees(np.arccos(abs(d[2]) / np.linalg.norm(d))) <= 30.0
    assert got.meta["method"] == "dense"
    z_ply = [i for i in range(got.n_fibers) if got.fiber(i)[:, 0].mean() / vs < 28]
    assert len(z_ply) == 16 and got.n_fibers == ref.n_fibers == 16, (got.n_fibers, ref.n_fibers)
