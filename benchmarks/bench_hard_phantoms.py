"""Tracer accuracy on the harder quasi-parallel phantom family (:func:`make_hard_phantom`).

Usage (from the repository root)::

    python benchmarks/bench_hard_phantoms.py [--seeds 0-19] [--out FILE.md]

Per seed: 36 fibers, 40 % touching in pairs, r 4-6 voxels, CNR 3-4, tilts up to 10 degrees,
160 slices; Otsu segmentation, then the ``slices`` tracer (what ``trace.method: auto`` picks
there) and, when installed (the ``bench`` extra), ``fibretracker`` on the same grey volume.
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
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the other benchmark scripts


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def phantom_bench_args(argv, doc: str, default_seeds: str):
    """The phantom benchmarks' command line (``--seeds A-B``, ``--out``): ``(args, seeds,
    run_fibretracker)``, the last None when the optional fibretracker (the bench extra) is missing."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--seeds", default=default_seeds)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    try:
        from fiberpipe.benchmarks.bench_imaging import run_fibretracker
    except Exception:  # noqa: BLE001 — fibretracker is optional (bench extra)
        run_fibretracker = None
    return a, _seeds(a.seeds), run_fibretracker


def main(argv=None) -> None:
    from fiberpipe.imaging.accuracy import trace_accuracy
    from fiberpipe.imaging.orientation import is_quasi_parallel, mask_orientation
    from fiberpipe.imaging.phantom import make_hard_phantom
    from fiberpipe.imaging.segment import segment
    from fiberpipe.imaging.trace import trace

    a, seeds, run_fibretracker = phantom_bench_args(argv, __doc__, "0-19")
    rows = ["| seed | r (vox) | CNR | auto | recall | precision | mean err (vox) | p95 (vox) | coverage | time (s) | fibretracker recall / precision / mean err |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    worst = {"recall": 1.0, "precision": 1.0, "mean": 0.0}
    for s in seeds:
        vol, truth = make_hard_phantom(s)
        vs = truth.meta["voxel_size_m"]
        r = truth.meta["radius_vox"]
        mask, _ = segment(vol)
        auto = "slices" if is_quasi_parallel(mask_orientation(mask, vs), 0.9) else "skeleton"
        t0 = time.perf_counter()
        f = trace(mask, voxel_size_m=vs, method="slices")
        dt = time.perf_counter() - t0
        acc = trace_accuracy(f, truth, voxel_size_m=vs)
        worst = worst_of(worst, acc)
        ft = fibretracker_cell(run_fibretracker, vol, vs, r, truth)
        rows.append(f"| {s} | {r:.2f} | {truth.meta['contrast_to_noise']:.2f} | {auto} | {acc['recall']:.3f} | "
                    f"{acc['precision']:.3f} | {acc['mean_error_vox']:.3f} | {acc['p95_error_vox']:.3f} | "
                    f"{acc['coverage']:.3f} | {dt:.1f} | {ft} |")
        print(rows[-1], flush=True)
    write_report(f"Harder phantom family, seeds {a.seeds}", rows, worst, a.out)


def worst_of(worst: dict, acc: dict) -> dict:
    """The worst recall, precision and mean error so far, with one more seed's accuracy ``acc``."""
    return {"recall": min(worst["recall"], acc["recall"]), "precision": min(worst["precision"], acc["precision"]),
            "mean": max(worst["mean"], acc["mean_error_vox"])}


def fibretracker_cell(run_fibretracker, vol, vs, r, truth, splits: bool = False) -> str:
    """The fibretracker column of a seed's row ("-" when it is not installed)."""
    from fiberpipe.imaging.accuracy import trace_accuracy

    if run_fibretracker is None:
        return "-"
    try:
        fa = trace_accuracy(run_fibretracker(vol, vs, r), truth, voxel_size_m=vs)
    except Exception as exc:  # noqa: BLE001 - a peer tool's failure is a table cell, not a stop
        return f"failed ({type(exc).__name__})"
    cell = f"{fa['recall']:.3f} / {fa['precision']:.3f} / {fa['mean_error_vox']:.3f}"
    return cell + (f" / {fa['n_split']}" if splits else "")


def write_report(title: str, rows: list[str], worst: dict, out) -> None:
    """Print the table with its worst-case line, and write it atomically to ``out`` if given."""
    text = "\n".join([f"# {title} ({time.strftime('%Y-%m-%d')})", "", *rows, "",
                      f"worst recall {worst['recall']:.3f}, worst precision {worst['precision']:.3f}, "
                      f"worst mean error {worst['mean']:.3f} voxel", ""])
    print(text)
    if out:
        from fiberpipe.artifacts import write_text_atomic

        write_text_atomic(out, text)


if __name__ == "__main__":
    main()
