"""Volumes larger than memory: segment, skeletonize and trace chunk by chunk, peak memory per pass.

Usage (from the repository root)::

    python benchmarks/bench_large_volume.py [--shape 1000 2000 2000] [--slab 32] [--block 64]
        [--passes segment trace skeleton] [--dir /tmp] [--scheduler ADDRESS] [--keep]

Writes the uint16 raw volume of :mod:`fiberpipe.benchmarks.bench_segment_large` (straight fibers
along z, r = 6 voxels on a jittered 15-voxel grid, CNR 4; 1000 x 2000 x 2000 = 8 GB by default)
slice by slice, then runs each pass in a fresh process and reports its wall time and peak resident
memory (ru_maxrss): ``segment_chunked`` (raw -> lzf HDF5 mask), ``trace_chunked`` (HDF5 mask ->
fibers, blocks of ``--block`` slices), ``skeletonize_chunked`` (HDF5 mask -> HDF5 skeleton and
radius, slabs of ``--slab`` slices with a 32-slice halo). With ``--scheduler`` the trace and
skeleton passes run their blocks on that Dask cluster.

The passes ``stage-segment``, ``stage-skeletonize`` and ``stage-trace`` run the pipeline's own
stages on the raw volume (``fiberpipe run`` with ``chunks.mode: on``, ``chunks.slices`` =
``--slab``, one stage per process, in one run folder), so the figures are those of the artifacts a
user gets (``mask.h5``, ``skeleton.h5``, ``fibers.h5``): ``--passes stage-segment stage-skeletonize
stage-trace``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]  # the source checkout
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the other benchmark scripts

import numpy as np  # noqa: E402


def _peak_gb() -> float:
    import resource

    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2, 3)


def child(pass_: str, raw: str, shape, slab: int, block: int, d: str, scheduler: str | None) -> dict:
    import h5py

    from fiberpipe.imaging.trace_chunked import SliceSource

    mask_p, skel_p = Path(d) / "fiberpipe-large-mask.h5", Path(d) / "fiberpipe-large-skeleton.h5"
    chunks = (min(slab, 16, shape[0]), min(256, shape[1]), min(256, shape[2]))
    t0 = time.perf_counter()
    if pass_ == "segment":
        from fiberpipe.imaging.segment_chunked import RawSlabs, segment_chunked

        src = RawSlabs(raw, shape, "uint16")
        with h5py.File(mask_p, "w") as f:
            ds = f.create_dataset("mask", shape=src.shape, dtype=bool, chunks=chunks,
                                  compression="lzf")
            info = segment_chunked(src, ds, slab=slab)
        out = {"volume_fraction": info["volume_fraction"], "time_s": info["time_s"]}
    elif pass_ == "trace":
        from fiberpipe.imaging.trace_chunked import trace_chunked

        f = trace_chunked(SliceSource(mask_p, "mask"), 1.0, expected_radius_m=6.0, block=block, scheduler=scheduler)
        L = f.lengths_m()
        out = {"fibers": int(f.n_fibers), "median_length_vox": float(np.median(L)) if len(L) else 0.0,
               "fibers_full_length": int(np.sum(L >= shape[0] - 2)), "time_track_s": round(f.meta["time_track_s"], 1)}
    elif pass_ == "skeleton":
        from fiberpipe.imaging.skeleton_chunked import skeletonize_chunked

        with h5py.File(skel_p, "w") as g:
            s = g.create_dataset("skeleton", shape=tuple(shape), dtype=bool, chunks=chunks,
                                 compression="lzf")
            r = g.create_dataset("radius_vox", shape=tuple(shape), dtype=np.float32, chunks=chunks,
                                 compression="lzf")
            out = skeletonize_chunked(SliceSource(mask_p, "mask"), s, r, slab=slab, halo=32, scheduler=scheduler)
    elif pass_.startswith("stage-"):
        out = _stage(pass_[len("stage-"):], raw, shape, slab, Path(d), scheduler)
    else:
        raise SystemExit(f"unknown pass {pass_!r}")
    import resource

    ru = resource.getrusage(resource.RUSAGE_SELF)
    # CPU time as well as wall time: on a shared machine the wall time depends on the CPU share
    out.update(wall_s=round(time.perf_counter() - t0, 1), cpu_s=round(ru.ru_utime + ru.ru_stime, 1),
               peak_rss_gb=_peak_gb())
    return out


#: Voxel size of the benchmark volume in the stage passes (the fibers' radius is 6 voxels).
VOXEL_SIZE_M = 10e-6


def _stage(name: str, raw: str, shape, slab: int, d: Path, scheduler: str | None) -> dict:
    """One pipeline stage, chunked, on the raw volume, into ``d/fiberpipe-large-run``."""
    from fiberpipe.config import validate_config
    from fiberpipe.pipeline import run_pipeline

    data = {"name": "large-volume", "input": {"volume": raw, "shape": list(shape), "dtype": "uint16",
                                              "voxel_size": VOXEL_SIZE_M},
            "chunks": {"mode": "on", "slices": slab},
            "trace": {"expected_radius": 6 * VOXEL_SIZE_M, "min_length": 0.0, "pictures": False,
                      "method": "slices"}}
    cfg = validate_config(data, where="bench_large_volume")
    cfg.chunks.scheduler = scheduler
    fig = run_pipeline(cfg, d / "fiberpipe-large-run", from_stage=name, to_stage=name, force=True).stages[name]
    keep = {"segment": ("volume_fraction",), "skeletonize": ("skeleton_voxels", "median_radius_vox"),
            "trace": ("fibers", "mean_length_m", "slicing_axis")}[name]
    return {k: fig[k] for k in keep if k in fig}


def main(argv=None) -> None:
    from bench_segment_large import write_volume

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shape", type=int, nargs=3, default=[1000, 2000, 2000])
    ap.add_argument("--slab", type=int, default=32)
    ap.add_argument("--block", type=int, default=64)
    ap.add_argument("--passes", nargs="+", default=["segment", "trace", "skeleton"])
    ap.add_argument("--dir", type=Path, default=Path("/tmp"))
    ap.add_argument("--scheduler")
    ap.add_argument("--keep", action="store_true", help="keep the raw volume, the mask and the skeleton")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    raw = a.dir / f"fiberpipe-large-{'x'.join(map(str, a.shape))}.raw"
    if a.child:
        print(json.dumps(child(a.child, str(raw), a.shape, a.slab, a.block, str(a.dir), a.scheduler)))
        return
    t0 = time.perf_counter()
    if not raw.exists() or raw.stat().st_size != int(np.prod(a.shape)) * 2:
        write_volume(raw, a.shape)
    t_write = time.perf_counter() - t0
    gb = np.prod(a.shape) * 2 / 1e9
    print(f"# Large volume, chunk by chunk ({time.strftime('%Y-%m-%d %H:%M')}, {os.cpu_count()} CPUs, load "
          f"{os.getloadavg()[0]:.1f})\n")
    print(f"volume {' x '.join(map(str, a.shape))} uint16 ({gb:.2f} GB), slab {a.slab}, block {a.block}; "
          f"written in {t_write:.0f} s\n", flush=True)
    print("| pass | wall time (s) | CPU time (s) | peak RSS (GB) | figures |\n| --- | --- | --- | --- | --- |", flush=True)
    for p in a.passes:
        cmd = [sys.executable, __file__, "--shape", *map(str, a.shape), "--slab", str(a.slab), "--block", str(a.block),
               "--dir", str(a.dir), "--child", p] + (["--scheduler", a.scheduler] if a.scheduler else [])
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            print(f"| {p} | failed | | | {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode} |", flush=True)
            break
        info = json.loads(r.stdout.strip().splitlines()[-1])
        wall, cpu, peak = info.pop("wall_s"), info.pop("cpu_s"), info.pop("peak_rss_gb")
        print(f"| {p} | {wall} | {cpu} | {peak} | {json.dumps(info)} |", flush=True)
    if not a.keep:
        for q in (raw, a.dir / "fiberpipe-large-mask.h5", a.dir / "fiberpipe-large-skeleton.h5"):
            q.unlink(missing_ok=True)
        import shutil

        shutil.rmtree(a.dir / "fiberpipe-large-run", ignore_errors=True)


if __name__ == "__main__":
    main()
