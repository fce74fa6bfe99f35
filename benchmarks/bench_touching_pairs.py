"""Touching pairs at r = 5.5 voxels: every fiber in a pair touching its partner along its whole
length (``make_phantom(touching_fraction=1.0)``), CNR 4, 160 x 120 x 120 voxels, 30 and 40 fibers.

Usage (from the repository root)::

    python benchmarks/bench_touching_pairs.py [--seeds 0-11] [--out FILE.md]

Otsu segmentation, then ``trace`` with only the voxel size (``auto`` is the stage's; here the
slices tracer, the one auto picks on such a bundle: volume fraction below a dense pack's).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]  # the source checkout
sys.path.insert(0, str(ROOT))


def main(argv=None) -> None:
    from fiberpipe.imaging.accuracy import trace_accuracy
    from fiberpipe.imaging.phantom import make_phantom
    from fiberpipe.imaging.segment import segment
    from fiberpipe.imaging.trace import trace

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0-11")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    lo, hi = (int(x) for x in a.seeds.split("-"))
    rows = ["| fibers | seed | volume fraction | recall | precision | mean err (vox) | p95 (vox) | coverage | split | "
            "merged | time (s) |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    worst = [1.0, 1.0, 0.0]
    for n in (30, 40):
        for seed in range(lo, hi + 1):
            vol, truth = make_phantom(n_fibers=n, shape=(160, 120, 120), radius_vox=5.5, touching_fraction=1.0,
                                      contrast_to_noise=4.0, seed=seed, dtype="uint16")
            vs = truth.meta["voxel_size_m"]
            mask, info = segment(vol)
            t0 = time.perf_counter()
            f = trace(mask, voxel_size_m=vs)
            dt = time.perf_counter() - t0
            acc = trace_accuracy(f, truth, voxel_size_m=vs)
            worst = [min(worst[0], acc["recall"]), min(worst[1], acc["precision"]), max(worst[2], acc["mean_error_vox"])]
            rows.append(f"| {n} | {seed} | {info['volume_fraction']:.2f} | {acc['recall']:.3f} | {acc['precision']:.3f} | "
                        f"{acc['mean_error_vox']:.3f} | {acc['p95_error_vox']:.3f} | {acc['coverage']:.3f} | "
                        f"{acc['n_split']} | {acc['n_merged']} | {dt:.1f} |")
            print(rows[-1], flush=True)
    text = "\n".join(rows) + (f"\n\nworst recall {worst[0]:.3f}, worst precision {worst[1]:.3f}, "
                              f"worst mean error {worst[2]:.3f} voxel\n")
    print(text)
    if a.out:
        a.out.write_text(text)


if __name__ == "__main__":
    main()
