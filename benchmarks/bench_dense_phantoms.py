"""Tracer accuracy on the dense-composite phantom family (:func:`make_dense_family_phantom`).

Usage (from the repository root)::

    python benchmarks/bench_dense_phantoms.py [--seeds 0-9] [--out FILE.md]

Per seed: 100^3 voxels, v_f 0.45-0.6, r 2.5-5 voxels, CNR 2-5, the main ply misaligned by 0-3
degrees and wavy by 0-1.5 voxels, rings and beam-hardening cupping, fibers touching on all sides, a
cross ply (fibers along x, lying in the slices) over 30 % of the y range. Otsu segmentation, then
the ``dense`` tracer with only the voxel size (the radius read from the grey slices), regions along
another axis traced along their own axis; and, when installed (the ``bench`` extra),
``fibretracker`` on the same grey volume (it slices along z only, tuned to the true radius).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]  # the source checkout
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the other benchmark scripts

import numpy as np  # noqa: E402

from bench_hard_phantoms import (  # noqa: E402
    fibretracker_cell, phantom_bench_args, worst_of, write_report)


def _subset(p, idx):
    from fiberpipe.polylines import Polylines

    return Polylines.from_list([p.fiber(int(i)) for i in idx], np.asarray(p.radius_m)[idx] if np.ndim(p.radius_m) else p.radius_m)


def main(argv=None) -> None:
    from fiberpipe.imaging.accuracy import trace_accuracy
    from fiberpipe.imaging.phantom_dense import make_dense_family_phantom
    from fiberpipe.imaging.segment import segment
    from fiberpipe.imaging.trace import trace

    a, seeds, run_fibretracker = phantom_bench_args(argv, __doc__, "0-9")
    rows = ["| seed | r (vox) | r traced (vox) | v_f | CNR | misalignment (deg) | fibers (main + cross) | recall | "
            "precision | mean err (vox) | p95 (vox) | coverage | split | cross ply traced (fibers) | main ply recall / "
            "precision | time (s) | fibretracker recall / precision / mean err / split |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    worst = {"recall": 1.0, "precision": 1.0, "mean": 0.0}
    for s in seeds:
        vol, truth = make_dense_family_phantom(s)
        m = truth.meta
        vs, r = m["voxel_size_m"], m["radius_vox"]
        mask, _ = segment(vol)
        t0 = time.perf_counter()
        f = trace(mask, voxel_size_m=vs, method="dense", grey=vol)
        dt = time.perf_counter() - t0
        acc = trace_accuracy(f, truth, voxel_size_m=vs)
        n_main = int(f.meta.get("n_fibers_main_axis", f.n_fibers))
        main_acc = trace_accuracy(_subset(f, np.arange(n_main)), _subset(truth, np.flatnonzero(m["axis_zyx"] == 0)),
                                  voxel_size_m=vs)
        cross = sum(v["fibers"] for ax, v in (f.meta.get("off_axis") or {}).items() if ax != "oblique")
        worst = worst_of(worst, acc)
        ft = fibretracker_cell(run_fibretracker, vol, vs, r, truth, splits=True)
        rows.append(f"| {s} | {r:.2f} | {f.meta.get('radius_vox_estimate', float('nan')):.2f} | "
                    f"{m['fiber_volume_fraction']:.2f} | {m['contrast_to_noise']:.2f} | {m['misalignment_deg']:.1f} | "
                    f"{m['n_main']} + {m['n_cross']} | {acc['recall']:.3f} | {acc['precision']:.3f} | "
                    f"{acc['mean_error_vox']:.3f} | {acc['p95_error_vox']:.3f} | {acc['coverage']:.3f} | {acc['n_split']} | "
                    f"{cross} | {main_acc['recall']:.3f} / {main_acc['precision']:.3f} | {dt:.1f} | {ft} |")
        print(rows[-1], flush=True)
    write_report(f"Dense-composite phantom family, seeds {a.seeds}", rows, worst, a.out)


if __name__ == "__main__":
    main()
