"""Real-scan benchmark: the real CT sample through ``fiberpipe run`` with default settings, and the
skeleton path on a short-fiber suspension phantom of the size of a typical lab scan.

Usage (from the repository root)::

    python benchmarks/bench_real_ct.py [--volume RAW] [--out FILE.md]

(a) The real CT of a polymer fiber scaffold (128^3 uint8 raw, no header; by default the copy kept
    beside the repository, skipped if absent) through segment -> skeletonize -> trace -> mesh ->
    a 2 us simulation, every imaging and mesh setting at its default, voxel size 10 um. Reported:
    wall time per stage, the tracer ``auto`` chose and why (fraction of the fiber volume within 45
    deg of one volume axis), the orientation tensor and angle histogram of the traced fibers,
    fibers joined / cut / dropped, and the traced median radius against the scan's own (FWHM of
    grey profiles across the traced mid-lines, :mod:`fiberpipe.imaging.profile`).
(b) A short-fiber phantom of 100 x 364 x 548 voxels (fibers r = 2.7 voxels, 30-100 voxels long,
    lying in the slice plane +-10 deg), the size and fiber scale of a typical CT of a short-fiber
    suspension: segment, orientation, skeletonize and skeleton trace times, trace accuracy.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]  # the source checkout
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the other benchmark scripts

import numpy as np  # noqa: E402

DEFAULT_RAW = ROOT.parent / "shared" / "data-real" / "quanfima_polymer3d" / "polymer3d_8bit_128x128x128.raw"


def real_scan(raw: Path) -> list[str]:
    from fiberpipe.artifacts import read_fibers
    from fiberpipe.config import load_config
    from fiberpipe.imaging.io import load_volume
    from fiberpipe.imaging.profile import fwhm_radius_vox
    from fiberpipe.pipeline import run_pipeline

    with tempfile.TemporaryDirectory() as tmp:
        cfg_path = Path(tmp) / "real.yaml"
        cfg_path.write_text(
            f"name: real-ct\ninput: {{volume: {raw}, shape: [128, 128, 128], dtype: uint8, voxel_size: 10 um}}\n"
            "scene: {effects: [gravity, damping]}\nsolver: {end_time: 2 us, output_frames: 2}\n")
        run = Path(tmp) / "run"
        t0 = time.perf_counter()
        run_pipeline(load_config(cfg_path), run)
        total = time.perf_counter() - t0
        st = json.loads((run / "summary.json").read_text())["stages"]
        fibers = read_fibers(run / "fibers.h5")
        vol, vs, _ = load_volume(raw, shape=(128, 128, 128), dtype="uint8", voxel_size_m=1e-5)
        scan = fwhm_radius_vox(vol, fibers, vs)
    tr = st["trace"]
    o = tr["orientation"]
    traced_r = float(np.median(fibers.radius_m)) / 1e-5
    lines = [
        "## Real CT sample (polymer scaffold, 128^3 uint8), default settings",
        "",
        "| stage | wall time (s) |", "| --- | --- |",
        *[f"| {k} | {v['wall_time_s']:.2f} |" for k, v in st.items()],
        f"| all (run_pipeline) | {total:.2f} |",
        "",
        f"- tracer chosen by `auto`: **{tr['method']}** ({100 * tr['aligned_fraction_45deg_mask']:.1f} % of the "
        "fiber volume within 45 deg of one volume axis; slices needs >= 90 %)",
        f"- traced fibers: {tr['fibers']} kept, {tr['joined_gaps']} gaps joined, {tr['cut_folds']} folds cut, "
        f"{tr['dropped_short_fibers']} dropped below trace.min_length = {tr['min_length_m'] * 1e3:.2g} mm; "
        f"mesh: {st['mesh']['fibers']} fibers, {st['mesh']['elements']} elements",
        f"- orientation tensor eigenvalues (traced fibers): {', '.join(f'{x:.3f}' for x in o['eigenvalues'])}; "
        f"dominant axis (x y z) {', '.join(f'{x:.3f}' for x in o['dominant_axis_xyz'])}; median angle to it "
        f"{o['median_angle_deg']:.1f} deg",
        "- angle histogram (fraction of fiber length per 5 deg bin, 0-90 deg): "
        + " ".join(f"{x:.3f}" for x in o["angle_histogram"]["fraction"]),
        f"- median radius: traced {traced_r:.2f} voxels, scan (FWHM of {scan['n_used']} grey profiles) "
        f"{scan['median_radius_vox']:.2f} voxels: ratio {traced_r / scan['median_radius_vox']:.3f}",
        "",
    ]
    return lines


def short_fiber_phantom() -> list[str]:
    from fiberpipe.imaging.accuracy import trace_accuracy
    from fiberpipe.imaging.orientation import mask_orientation
    from fiberpipe.imaging.phantom import make_short_fiber_phantom
    from fiberpipe.imaging.profile import fwhm_radius_vox
    from fiberpipe.imaging.segment import segment
    from fiberpipe.imaging.skeleton import skeletonize
    from fiberpipe.imaging.trace import trace

    vs = 1e-5
    vol, truth = make_short_fiber_phantom(shape=(100, 364, 548), n_fibers=700, radius_vox=2.7,
                                          length_vox=(30, 100), seed=0)
    times = {}
    t = time.perf_counter()
    mask, info = segment(vol)
    times["segment"] = time.perf_counter() - t
    t = time.perf_counter()
    om = mask_orientation(mask, vs)
    times["orientation (mask)"] = time.perf_counter() - t
    t = time.perf_counter()
    sk, rad = skeletonize(mask)
    times["skeletonize"] = time.perf_counter() - t
    t = time.perf_counter()
    f = trace(mask, voxel_size_m=vs, method="skeleton", skeleton=sk, radius_vox=rad)
    times["trace (skeleton)"] = time.perf_counter() - t
    acc = trace_accuracy(f, truth, voxel_size_m=vs)
    scan = fwhm_radius_vox(vol, f, vs)
    return [
        "## Short-fiber phantom, 100 x 364 x 548 voxels, skeleton path",
        "",
        f"{truth.n_fibers} fibers, r = 2.7 voxels, 30-100 voxels long, in the slice plane +-10 deg, CNR 4, "
        f"volume fraction {info['volume_fraction']:.3f}; mask aligned fraction {om['aligned_fraction_45deg']:.3f} "
        "(auto: skeleton)",
        "",
        "| step | wall time (s) |", "| --- | --- |",
        *[f"| {k} | {v:.2f} |" for k, v in times.items()],
        "",
        f"- traced {f.n_fibers} fibers ({f.meta['n_joins']} gaps joined); recall {acc['recall']:.3f}, precision "
        f"{acc['precision']:.3f}, mean error {acc['mean_error_vox']:.3f} voxel, p95 {acc['p95_error_vox']:.3f}, "
        f"coverage {acc['coverage']:.3f}, merged {acc['n_merged']}, split {acc['n_split']}",
        f"- median radius: traced {np.median(f.radius_m) / vs:.2f}, FWHM {scan['median_radius_vox']:.2f}, true 2.70 voxels",
        "",
    ]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--volume", type=Path, default=DEFAULT_RAW, help="the real CT raw file (128^3 uint8)")
    ap.add_argument("--out", type=Path, help="also write the markdown here")
    a = ap.parse_args(argv)
    lines = [f"# Real-scan benchmark ({time.strftime('%Y-%m-%d')}, {os.cpu_count()} CPUs)", ""]
    if a.volume.exists():
        lines += real_scan(a.volume)
    else:
        lines += [f"(real CT sample {a.volume} not present: skipped)", ""]
    lines += short_fiber_phantom()
    text = "\n".join(lines)
    print(text)
    if a.out:
        from fiberpipe.artifacts import write_text_atomic

        write_text_atomic(a.out, text + "\n")


if __name__ == "__main__":
    main()
