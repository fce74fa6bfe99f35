"""Large-volume segmentation: slab-by-slab segment of a volume larger than a quarter of memory.

Usage (from the repository root)::

    python benchmarks/bench_segment_large.py [--shape 1000 2000 2000] [--slab 32] [--dir /tmp]

Writes a uint16 raw volume (z y x; default 1000 x 2000 x 2000 = 8 GB) of straight fibers (r = 6
voxels, noise at CNR 4), then runs :func:`fiberpipe.imaging.segment_chunked.segment_chunked` on
it in a fresh process (reading slabs from the raw file, writing the mask to a chunked, compressed
HDF5 dataset), and reports the wall time per pass and the peak resident memory (ru_maxrss).
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


def write_volume(path: Path, shape, seed: int = 0) -> None:
    """Straight fibers along z on a jittered grid, grey 16384 / 49152, Gaussian noise (CNR 4)."""
    nz, ny, nx = shape
    rng = np.random.default_rng(seed)
    r, pitch = 6.0, 15.0
    yy, xx = np.mgrid[0:ny, 0:nx].astype(np.float32)
    img = np.zeros((ny, nx), dtype=np.float32)
    for cy in np.arange(pitch, ny - pitch, pitch):
        for cx in np.arange(pitch, nx - pitch, pitch):
            jy, jx = rng.uniform(-1.5, 1.5, 2)
            y0, x0 = int(cy - 8), int(cx - 8)
            sub = (yy[y0:y0 + 17, x0:x0 + 17] - cy - jy) ** 2 + (xx[y0:y0 + 17, x0:x0 + 17] - cx - jx) ** 2
            img[y0:y0 + 17, x0:x0 + 17] = np.maximum(img[y0:y0 + 17, x0:x0 + 17], np.clip(r + 0.5 - np.sqrt(sub), 0, 1))
    base = 16384 + 32768 * img
    noise = rng.normal(0, 32768 / 4, size=(16, ny, nx)).astype(np.float32)
    with open(path, "wb") as f:
        for k in range(nz):
            f.write(np.clip(base + noise[k % 16], 0, 65535).astype(np.uint16).tobytes())


def child(raw: str, shape, slab: int, out: str) -> None:
    import resource

    import h5py

    from fiberpipe.imaging.segment_chunked import RawSlabs, segment_chunked

    src = RawSlabs(raw, shape, "uint16")
    t0 = time.perf_counter()
    with h5py.File(out, "w") as f:
        ds = f.create_dataset("mask", shape=src.shape, dtype=bool, chunks=(min(slab, 16), 256, 256), compression="lzf")
        info = segment_chunked(src, ds, slab=slab)
    info["wall_s"] = round(time.perf_counter() - t0, 1)
    info["peak_rss_gb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2, 3)
    print(json.dumps(info))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shape", type=int, nargs=3, default=[1000, 2000, 2000])
    ap.add_argument("--slab", type=int, default=32)
    ap.add_argument("--dir", type=Path, default=Path("/tmp"))
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    ap.add_argument("--keep", action="store_true", help="keep the raw volume and the mask")
    a = ap.parse_args(argv)
    if a.child:
        child(a.child[0], a.shape, a.slab, a.child[1])
        return
    raw = a.dir / f"fiberpipe-large-{'x'.join(map(str, a.shape))}.raw"
    out = a.dir / "fiberpipe-large-mask.h5"
    t0 = time.perf_counter()
    if not raw.exists() or raw.stat().st_size != int(np.prod(a.shape)) * 2:
        write_volume(raw, a.shape)
    t_write = time.perf_counter() - t0
    r = subprocess.run([sys.executable, __file__, "--shape", *map(str, a.shape), "--slab", str(a.slab),
                        "--child", str(raw), str(out)], capture_output=True, text=True, check=True)
    info = json.loads(r.stdout.strip().splitlines()[-1])
    gb = np.prod(a.shape) * 2 / 1e9
    print(f"# Large-volume segment ({time.strftime('%Y-%m-%d')}, {os.cpu_count()} CPUs)\n")
    print(f"volume {' x '.join(map(str, a.shape))} uint16 ({gb:.1f} GB), slab {a.slab} slices; volume written in {t_write:.0f} s\n")
    print("| pass | wall time (s) |\n| --- | --- |")
    for k, v in info["time_s"].items():
        print(f"| {k} | {v} |")
    print(f"| total | {info['wall_s']} |\n")
    print(f"peak RSS {info['peak_rss_gb']} GB; threshold {info['threshold']:.1f}, volume fraction "
          f"{info['volume_fraction']:.4f}, {info['n_components']} components")
    if not a.keep:
        raw.unlink(missing_ok=True)
        out.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
