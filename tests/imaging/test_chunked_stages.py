"""The segment, skeletonize and trace stages chunk by chunk (``chunks``): the same artifacts as in
memory, from HDF5, Zarr, MetaImage, .npy and raw volumes, in one process and on a Dask cluster,
with the slicing axis taken from the fibers' orientation."""

from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fiberpipe.artifacts import read_fibers, write_fibers
from fiberpipe.cli import main
from fiberpipe.config import validate_config
from fiberpipe.errors import ConfigError, InputError
from fiberpipe.imaging.accuracy import trace_accuracy
from fiberpipe.imaging.phantom import make_phantom
from fiberpipe.pipeline import run_pipeline
from fiberpipe.polylines import Polylines

VS = 10e-6  # m


@pytest.fixture(scope="module")
def phantom(tmp_path_factory):
    """A 64 x 96 x 96 phantom of 16 fibers along z, r = 4 voxels, as HDF5 and Zarr, and its truth."""
    d = tmp_path_factory.mktemp("chunked-stages")
    vol, truth = make_phantom(n_fibers=16, shape=(64, 96, 96), radius_vox=4.0, voxel_size_m=VS,
                              contrast_to_noise=5.0, seed=1)
    with h5py.File(d / "v.h5", "w") as f:
        ds = f.create_dataset("volume", data=vol, chunks=(8, 48, 48))
        ds.attrs["voxel_size_m"] = [VS] * 3
    write_fibers(d / "truth.h5", truth)
    return d, vol, truth


def _cfg(volume, **chunks):
    data = {"name": "chunked", "input": {"volume": str(volume)}, "mesh": {"element_length": "0.05 mm"},
            "trace": {"pictures": False}}
    if chunks:
        data["chunks"] = chunks
    return validate_config(data, where="test.yaml")


@pytest.fixture(scope="module")
def in_memory(phantom, tmp_path_factory):
    d, _, _ = phantom
    run = tmp_path_factory.mktemp("in-memory")
    report = run_pipeline(_cfg(d / "v.h5", mode="off"), run, to_stage="trace")
    return run, report


def _same_fibers(run, ref_run, tol_vox=0.05):
    got, ref = read_fibers(run / "fibers.h5"), read_fibers(ref_run / "fibers.h5")
    assert got.n_fibers == ref.n_fibers
    acc = trace_accuracy(got, ref, voxel_size_m=VS)
    assert acc["recall"] == 1.0 and acc["precision"] == 1.0, acc
    assert acc["mean_error_vox"] <= tol_vox, acc


def _zarr_copy(d, vol):
    zarr = pytest.importorskip("zarr")
    p = d / "v.zarr"
    if not p.exists():
        z = zarr.create_array(str(p), shape=vol.shape, dtype=vol.dtype, chunks=(8, 48, 48))
        z[:] = vol
        z.attrs["voxel_size_m"] = [VS] * 3
    return p


@pytest.mark.parametrize("fmt", ["h5", "zarr"])
def test_chunked_stages_give_the_in_memory_artifacts(phantom, in_memory, tmp_path, fmt):
    """Slabs of 16 slices from HDF5 and Zarr: the mask equal voxel for voxel, the skeleton within
    2 % in voxels, the traced fibers the same (count, mid-lines within 0.05 voxel)."""
    d, vol, truth = phantom
    src = d / "v.h5" if fmt == "h5" else _zarr_copy(d, vol)
    ref_run, ref = in_memory
    report = run_pipeline(_cfg(src, mode="on", slices=16), tmp_path, to_stage="trace")
    for stage in ("segment", "skeletonize", "trace"):
        assert report.stages[stage]["chunked"] is True
        assert "chunked" not in ref.stages[stage]
    with h5py.File(tmp_path / "mask.h5") as f, h5py.File(ref_run / "mask.h5") as g:
        assert f["mask"].chunks is not None  # written chunk by chunk
        assert np.array_equal(f["mask"][()], g["mask"][()])
    n_sk, n_ref = report.stages["skeletonize"]["skeleton_voxels"], ref.stages["skeletonize"]["skeleton_voxels"]
    assert abs(n_sk - n_ref) <= 0.02 * n_ref
    _same_fibers(tmp_path, ref_run)
    acc = trace_accuracy(read_fibers(tmp_path / "fibers.h5"), truth, voxel_size_m=VS)
    assert acc["recall"] == 1.0 and acc["precision"] == 1.0 and acc["mean_error_vox"] <= 0.3, acc


def test_auto_mode_chunks_above_the_memory_budget(phantom, tmp_path):
    """auto: chunked when voxels x 16 bytes exceed chunks.memory_budget (590 k voxels: 9.4 MB)."""
    d, _, _ = phantom
    small = run_pipeline(_cfg(d / "v.h5", memory_budget="5 MB"), tmp_path / "a", to_stage="segment")
    large = run_pipeline(_cfg(d / "v.h5", memory_budget="20 MB"), tmp_path / "b", to_stage="segment")
    assert small.stages["segment"].get("chunked") is True
    assert "chunked" not in large.stages["segment"]


def test_chunked_stages_on_a_dask_cluster(phantom, in_memory, tmp_path):
    """chunks.scheduler: a local two-worker cluster gives the in-memory fibers; the scheduler is
    not part of the cache key (the in-process rerun is up to date)."""
    distributed = pytest.importorskip("dask.distributed")
    d, _, _ = phantom
    ref_run, _ = in_memory
    cfg = _cfg(d / "v.h5", mode="on", slices=16)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        cfg.chunks.scheduler = c.scheduler_address
        run_pipeline(cfg, tmp_path, to_stage="trace")
    with h5py.File(tmp_path / "mask.h5") as f, h5py.File(ref_run / "mask.h5") as g:
        assert np.array_equal(f["mask"][()], g["mask"][()])
    _same_fibers(tmp_path, ref_run)
    again = run_pipeline(_cfg(d / "v.h5", mode="on", slices=16), tmp_path, to_stage="trace")
    assert all(again.stages[s].get("skipped") for s in ("segment", "skeletonize", "trace"))


def test_fibers_along_x_are_sliced_along_x(phantom, tmp_path):
    """The same phantom turned so the fibers run along x: the chunked tracer reads its blocks
    across x (boxes of the z-slab store) and finds every fiber, as the in-memory tracer does."""
    d, vol, truth = phantom
    turned = np.ascontiguousarray(vol.transpose(1, 2, 0))  # (y, x, z) -> fibers along the last axis
    with h5py.File(tmp_path / "x.h5", "w") as f:
        f.create_dataset("volume", data=turned, chunks=(16, 48, 48)).attrs["voxel_size_m"] = [VS] * 3
    # voxel (z, y, x) of the phantom is voxel (y, x, z) of the turned volume: x y z -> z x y
    truth_x = Polylines(truth.points_m[:, [2, 0, 1]].copy(), truth.offsets, truth.radius_m)
    report = run_pipeline(_cfg(tmp_path / "x.h5", mode="on", slices=16), tmp_path / "on", to_stage="trace")
    assert report.stages["trace"]["slicing_axis"] == "x"
    ref = run_pipeline(_cfg(tmp_path / "x.h5", mode="off"), tmp_path / "off", to_stage="trace")
    assert report.stages["trace"]["fibers"] == ref.stages["trace"]["fibers"]
    acc = trace_accuracy(read_fibers(tmp_path / "on" / "fibers.h5"), truth_x, voxel_size_m=VS)
    assert acc["recall"] == 1.0 and acc["precision"] == 1.0 and acc["mean_error_vox"] <= 0.3, acc


def _metaimage(p: Path, vol: np.ndarray) -> Path:
    (p.with_suffix(".raw")).write_bytes(vol.astype("<f4").tobytes())
    nz, ny, nx = vol.shape
    p.write_text(f"ObjectType = Image\nNDims = 3\nDimSize = {nx} {ny} {nz}\nElementType = MET_FLOAT\n"
                 f"ElementSpacing = 0.01 0.01 0.01\nBinaryDataByteOrderMSB = False\nElementDataFile = {p.with_suffix('.raw').name}\n")
    return p


@pytest.mark.parametrize("fmt", ["mhd", "npy", "raw"])
def test_chunked_segment_reads_metaimage_npy_and_raw(phantom, in_memory, tmp_path, fmt):
    """MetaImage (voxel size from its header), .npy and headerless raw: read slab by slab, the mask
    of the in-memory path voxel for voxel."""
    d, vol, _ = phantom
    ref_run, _ = in_memory
    extra = {}
    if fmt == "mhd":
        src = _metaimage(tmp_path / "v.mhd", vol)
    elif fmt == "npy":
        src = tmp_path / "v.npy"
        np.save(src, vol)
        extra = {"voxel_size": "10 um"}
    else:
        src = tmp_path / "v.bin"
        src.write_bytes(vol.astype("<f4").tobytes())
        extra = {"voxel_size": "10 um", "shape": list(vol.shape), "dtype": "<f4"}
    data = {"name": "c", "input": {"volume": str(src), **extra}, "chunks": {"mode": "on", "slices": 20}}
    report = run_pipeline(validate_config(data, where="t.yaml"), tmp_path / "run", to_stage="segment")
    assert report.stages["segment"]["chunked"] is True
    assert report.stages["segment"]["voxel_size_m"] == pytest.approx([VS] * 3)
    with h5py.File(tmp_path / "run" / "mask.h5") as f, h5py.File(ref_run / "mask.h5") as g:
        assert np.array_equal(f["mask"][()], g["mask"][()])


@pytest.mark.parametrize("chunks, message", [
    ({"slices": 0}, "'chunks.slices': Input should be greater than or equal to 1"),
    ({"memory_budget": "lots"}, "'chunks.memory_budget': cannot read 'lots' as an amount of memory"),
    ({"memory_budget": "4 m"}, "cannot read '4 m' as an amount of memory"),
    ({"mode": "sometimes"}, "'chunks.mode': Input should be 'auto', 'on' or 'off'"),
])
def test_bad_chunks_keys_are_one_line_config_errors(tmp_path, chunks, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        _cfg(tmp_path / "v.h5", **chunks)
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump({"input": {"volume": "v.h5"}, "chunks": chunks}))
    result = CliRunner().invoke(main, ["segment", str(p), "--out", str(tmp_path / "run")])
    errors = [ln for ln in result.output.splitlines() if ln.startswith("error:")]
    assert result.exit_code != 0 and len(errors) == 1 and "Traceback" not in result.output, result.output


def test_chunks_on_a_tiff_names_the_formats_and_the_key(phantom, tmp_path):
    from fiberpipe.imaging.io import save_volume_tif

    _, vol, _ = phantom
    save_volume_tif(tmp_path / "v.tif", vol, VS)
    with pytest.raises(InputError, match="read whole; the chunked stages read HDF5/NeXus, Zarr.*chunks.mode: off"):
        run_pipeline(_cfg(tmp_path / "v.tif", mode="on"), tmp_path / "run", to_stage="segment")


def test_the_skeleton_tracer_is_refused_when_chunked(phantom, tmp_path):
    d, _, _ = phantom
    data = {"input": {"volume": str(d / "v.h5")}, "chunks": {"mode": "on", "slices": 16},
            "trace": {"method": "skeleton"}, "mesh": {"element_length": "0.05 mm"}}
    with pytest.raises(InputError, match="trace.method is skeleton.*set trace.method: slices, or chunks.mode: off"):
        run_pipeline(validate_config(data, where="t.yaml"), tmp_path, to_stage="trace")


def test_nan_voxels_are_a_one_line_error_when_chunked(phantom, tmp_path):
    _, vol, _ = phantom
    bad = vol.copy()
    bad[40, 10, 10] = np.nan
    np.save(tmp_path / "v.npy", bad)
    data = {"input": {"volume": str(tmp_path / "v.npy"), "voxel_size": "10 um"}, "chunks": {"mode": "on", "slices": 16}}
    with pytest.raises(InputError, match="NaN or infinite voxels in slices"):
        run_pipeline(validate_config(data, where="t.yaml"), tmp_path / "run", to_stage="segment")
    assert not (tmp_path / "run" / "mask.h5").exists()  # atomic: no half-written mask


def test_large_volume_benchmark_runs_the_pipeline_stages(tmp_path, capsys):
    """bench_large_volume's stage passes: the pipeline's chunked stages each report wall time, CPU
    time and peak memory; every fiber of the 5 x 5 grid traced."""
    import json

    from imaging._bench_scripts import load_bench

    bench_large_volume = load_bench("bench_large_volume")

    bench_large_volume.main(["--shape", "40", "96", "96", "--slab", "16", "--dir", str(tmp_path),
                             "--passes", "stage-segment", "stage-skeletonize", "stage-trace"])
    out = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in out.splitlines() if line.startswith("| ") and "{" in line}
    assert set(rows) == {"stage-segment", "stage-skeletonize", "stage-trace"}, out
    assert json.loads(rows["stage-trace"].split("|")[5])["fibers"] == 25
    assert not list(tmp_path.iterdir())  # nothing left behind


@pytest.mark.parametrize("off_axis", ["trace", "drop"])
def test_a_cross_ply_is_split_by_region_when_chunked(tmp_path, off_axis):
    """A dense pack with a cross ply lying in the slices (fibers along x over 30 % of y), chunked in
    16-slice slabs: each region is traced along its own axis (or left out), as in memory, and both
    plies are found whole (recall and precision ≥ 0.98 against the truth of the plies traced, no
    fiber split at a block face: without the blocks' warm-up 12 of this pack's 81 fibers split)."""
    from fiberpipe.imaging.phantom_dense import make_dense_phantom

    vol, truth = make_dense_phantom(seed=3, shape=(60, 64, 64), radius_vox=3.0, contrast_to_noise=2.5,
                                    cross_ply_fraction=0.3)
    vs = truth.meta["voxel_size_m"]
    with h5py.File(tmp_path / "ply.h5", "w") as f:
        f.create_dataset("volume", data=vol, chunks=(16, 32, 32)).attrs["voxel_size_m"] = [vs] * 3

    def run(mode, name):
        data = {"name": "ply", "input": {"volume": str(tmp_path / "ply.h5")}, "fiber": {"radius": 3.0 * vs},
                "skeletonize": {"enabled": False}, "chunks": {"mode": mode, "slices": 16},
                "trace": {"grey": True, "off_axis": off_axis, "min_length": 0.0, "pictures": False}}
        return run_pipeline(validate_config(data, where="t.yaml"), tmp_path / name, to_stage="trace").stages["trace"]

    on, off = run("on", "on"), run("off", "off")
    assert on["chunked"] and on["slicing_axis"] == "z"
    assert set(on["off_axis"]) == set(off["off_axis"]) == {"x"}
    x_on, x_off = on["off_axis"]["x"], off["off_axis"]["x"]
    assert x_on["action"] == x_off["action"] and abs(x_on["volume_fraction"] - x_off["volume_fraction"]) < 0.03
    kept = truth if off_axis == "trace" else Polylines.from_list(
        [truth.fiber(i) for i in np.flatnonzero(truth.meta["axis_zyx"] == 0)], truth.radius_m[truth.meta["axis_zyx"] == 0])
    acc = trace_accuracy(read_fibers(tmp_path / "on" / "fibers.h5"), kept, voxel_size_m=vs)
    assert acc["recall"] >= 0.98 and acc["precision"] >= 0.98, acc
    # the 16-slice blocks do not break the touching fibers (each block's tracks start 16 slices early)
    assert acc["n_split"] == 0 and on["fibers"] == off["fibers"], (acc, on["fibers"], off["fibers"])
    assert not (tmp_path / "on" / "trace_regions.tmp.h5").exists()


def test_auto_judges_a_dense_pack_alike_when_chunked(tmp_path):
    """``trace.method: auto`` asks the same question of a mask on disk (the chunked stage reads it as
    a strided sample) as of one in memory: a dense pack of thin fibers (mask volume fraction >= 0.35,
    radius <= 8 voxels) is one, along z and along x, and a loose bundle of thick fibers is not."""
    from fiberpipe.imaging.orientation import mask_orientation
    from fiberpipe.imaging.phantom_dense import make_dense_phantom
    from fiberpipe.imaging.segment import segment
    from fiberpipe.imaging.trace_chunked import StridedSample
    from fiberpipe.stages.trace import dense_pack

    vol, _ = make_dense_phantom(seed=2, shape=(24, 40, 40), radius_vox=3.0, contrast_to_noise=4.0,
                                cross_ply_fraction=0.0)
    dense, _ = segment(vol)
    loose, _ = segment(make_phantom(n_fibers=3, shape=(24, 64, 64), radius_vox=8.0, seed=2)[0])
    for mask, expected in ((dense, True), (np.ascontiguousarray(dense.transpose(2, 1, 0)), True), (loose, False)):
        with h5py.File(tmp_path / "mask.h5", "w") as f:
            f.create_dataset("mask", data=mask, chunks=(8,) + mask.shape[1:])
        with h5py.File(tmp_path / "mask.h5", "r") as f:
            sample = StridedSample(f["mask"])
            orient = mask_orientation(sample, 1.0)
            assert dense_pack(sample, orient) is dense_pack(mask, mask_orientation(mask, 1.0)) is expected
