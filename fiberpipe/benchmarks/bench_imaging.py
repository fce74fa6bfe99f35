"""Imaging benchmark: tracer accuracy on phantoms (ours vs fibretracker) and full-size throughput.

Usage (from the repository root)::

    python -m fiberpipe.benchmarks.bench_imaging [--quick] [--out docs/bench/imaging.md]

(a) Accuracy over several seeds on phantoms of 40 curved quasi-parallel fibers (radius 5 voxels,
    a third in pairs touching along their whole length, PSF blur 1 voxel, contrast-to-noise 4 and
    6), for our ``slices`` tracer, our ``skeleton`` tracer and the MIT-licensed ``fibretracker``
    (PyPI 0.1.0, the ``bench`` extra) given the same grey volume.
(b) A 200 x 400 x 1000 voxel volume (z = 1000 slices, 40 fibers of radius 12 voxels) through
    load -> segment -> skeletonize -> trace, each path in a fresh subprocess: wall time per stage
    and peak resident memory (ru_maxrss). Path A runs every stage; path B is what the ``slices``
    tracer needs (no skeleton).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import io
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]  # the folder holding the fiberpipe package
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from fiberpipe.imaging.accuracy import format_accuracy, trace_accuracy  # noqa: E402
from fiberpipe.imaging.phantom import make_phantom  # noqa: E402
from fiberpipe.imaging.segment import segment  # noqa: E402
from fiberpipe.imaging.trace import trace  # noqa: E402
from fiberpipe.polylines import Polylines  # noqa: E402


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} CPUs (nproc), {cpu}, Python {platform.python_version()}"


def run_fibretracker(vol: np.ndarray, vs: float, r: float) -> Polylines:
    """fibretracker 0.1.0 on the grey volume, tuned to the phantom's radius (its own defaults
    are for r ~ 2.5-5 px): blob std r/2, min_distance r, peak threshold 0.5 of the contrast,
    intensity-weighted centroids, max_jump r/2, Gaussian-smoothed tracks."""
    # fibretracker's own (British) names
    from fibretracker.models.detector import get_fibre_coords as get_fiber_coords
    from fibretracker.models.tracker import track_fibres as track_fibers

    lo, hi = np.percentile(vol, [1, 99])
    v = np.clip((vol - lo) / (hi - lo), 0, 1).astype(np.float64)
    with contextlib.redirect_stdout(io.StringIO()):  # it prints progress with \r
        coords = get_fiber_coords(v, std=r / 2, min_distance=int(round(r)), threshold_abs=0.5,
                                  weighted_avg=True, window_size=int(round(r)))
        tracks = track_fibers(coords=coords, max_jump=max(2, int(round(r / 2))), max_skip=3,
                              momentum=0.1, track_min_length=int(3 * r), smoothtrack_gaussian=True,
                              sigma=2)
    fibers = [np.asarray(t, dtype=np.float64)[:, :3] * vs for t in tracks]  # x, y, z voxels -> m
    return Polylines.from_list(fibers, r * vs)


def accuracy_part(seeds, n_slices, report):
    rows, labels, times = [], [], []
    summary = {}
    ft_ok = True
    try:
        import fibretracker  # noqa: F401
    except Exception as exc:  # pragma: no cover - depends on the bench extra
        ft_ok = False
        report.append(f"fibretracker could not be imported ({type(exc).__name__}: {exc}); not measured.\n")
    for cnr in (4.0, 6.0):
        for seed in seeds:
            vol, truth = make_phantom(n_fibers=40, shape=(n_slices, 120, 120), radius_vox=5.0,
                                      contrast_to_noise=cnr, seed=seed)
            vs = truth.meta["voxel_size_m"]
            t = time.perf_counter()
            mask, _ = segment(vol)
            t_seg = time.perf_counter() - t
            methods = [("slices", lambda: trace(mask, voxel_size_m=vs)),
                       ("skeleton", lambda: trace(mask, voxel_size_m=vs, method="skeleton"))]
            if ft_ok:
                methods.append(("fibretracker", lambda: run_fibretracker(vol, vs, 5.0)))
            for name, fn in methods:
                t = time.perf_counter()
                out = fn()
                dt = time.perf_counter() - t + (t_seg if name != "fibretracker" else 0.0)
                a = trace_accuracy(out, truth, voxel_size_m=vs)
                rows.append(a)
                labels.append(f"{name}, CNR {cnr:g}, seed {seed}")
                times.append(dt)
                summary.setdefault(name, []).append(a)
                print(f"  {labels[-1]}: recall {a['recall']:.3f} precision {a['precision']:.3f} "
                      f"mean err {a['mean_error_vox']:.3f} vox ({dt:.1f} s)", flush=True)
    table = format_accuracy(rows, labels)
    # add a time column
    lines = table.split("\n")
    lines[0] += " time (s) |"
    lines[1] += " --- |"
    for i, dt in enumerate(times):
        lines[2 + i] += f" {dt:.2f} |"
    agg = ["| tracer | phantoms | min recall | min precision | mean F1 | mean err (vox) | worst mean err (vox) | mean p95 (vox) | mean coverage |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, lst in summary.items():
        f = lambda k: np.array([a[k] for a in lst], dtype=float)  # noqa: E731
        agg.append(f"| {name} | {len(lst)} | {f('recall').min():.3f} | {f('precision').min():.3f} | "
                   f"{f('f1').mean():.3f} | {np.nanmean(f('mean_error_vox')):.3f} | "
                   f"{np.nanmax(f('mean_error_vox')):.3f} | {np.nanmean(f('p95_error_vox')):.3f} | "
                   f"{f('coverage').mean():.3f} |")
    return "\n".join(agg), "\n".join(lines)


_STAGE_SCRIPT = r"""
import json, os, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
from fiberpipe.imaging.io import load_volume
from fiberpipe.imaging.segment import segment
from fiberpipe.imaging.skeleton import skeletonize
from fiberpipe.imaging.trace import trace
def rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # MB (Linux: kB)
out = {{}}
t = time.perf_counter(); vol, vs, _ = load_volume({path!r}); out['load'] = (time.perf_counter() - t, rss())
t = time.perf_counter(); mask, info = segment(vol); out['segment'] = (time.perf_counter() - t, rss())
del vol
if {skeleton}:
    t = time.perf_counter(); skel, rad = skeletonize(mask); out['skeletonize'] = (time.perf_counter() - t, rss())
t = time.perf_counter(); fib = trace(mask, voxel_size_m=vs); out['trace (slices)'] = (time.perf_counter() - t, rss())
out['n_fibers_slices'] = fib.n_fibers
if {skeleton}:
    t = time.perf_counter(); fs = trace(mask, voxel_size_m=vs, method='skeleton', skeleton=skel, radius_vox=rad)
    out['trace (skeleton)'] = (time.perf_counter() - t, rss()); out['n_fibers_skeleton'] = fs.n_fibers
np.savez({fib_path!r}, points_m=fib.points_m, offsets=fib.offsets, radius_m=fib.radius_m)
out['volume_fraction'] = info['volume_fraction']
print(json.dumps(out))
"""


def perf_part(shape, radius, report, tmp: Path):
    from fiberpipe.imaging.io import save_volume_tif

    t = time.perf_counter()
    vol, truth = make_phantom(n_fibers=40, shape=shape, radius_vox=radius, contrast_to_noise=5.0,
                              waviness_vox=3.0, seed=0, dtype="uint8")
    vs = truth.meta["voxel_size_m"]
    path = tmp / "big.tif"
    save_volume_tif(path, vol, vs)
    t_make = time.perf_counter() - t
    del vol
    results = {}
    for name, skel in (("A: all stages", True), ("B: slices path (no skeleton)", False)):
        fib_path = str(tmp / f"fib_{skel}.npz")
        code = _STAGE_SCRIPT.format(root=str(ROOT), path=str(path), skeleton=skel, fib_path=fib_path)
        t = time.perf_counter()
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env={**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
        wall = time.perf_counter() - t
        if res.returncode != 0:
            report.append(f"path {name} failed:\n```\n{res.stderr[-2000:]}\n```\n")
            continue
        out = json.loads(res.stdout.strip().splitlines()[-1])
        d = np.load(fib_path)
        fib = Polylines(d["points_m"], d["offsets"], d["radius_m"])
        acc = trace_accuracy(fib, truth, voxel_size_m=vs)
        results[name] = (out, wall, acc)
        print(f"  {name}: {wall:.1f} s process wall, {out}", flush=True)
    lines = ["| path | stage | wall time (s) | peak RSS so far (MB) |", "| --- | --- | --- | --- |"]
    for name, (out, wall, acc) in results.items():
        total = 0.0
        for st in ("load", "segment", "skeletonize", "trace (slices)", "trace (skeleton)"):
            if st in out:
                dt, mem = out[st]
                total += dt
                lines.append(f"| {name} | {st} | {dt:.1f} | {mem:.0f} |")
        peak = max(v[1] for k, v in out.items() if isinstance(v, list))
        lines.append(f"| {name} | **total of stages** | **{total:.1f}** | **{peak:.0f}** (process wall "
                     f"{wall:.1f} s incl. imports) |")
    acc_lines = ["| path | fibers traced (slices) | recall | precision | mean err (vox) | p95 err (vox) |",
                 "| --- | --- | --- | --- | --- | --- |"]
    for name, (out, wall, a) in results.items():
        acc_lines.append(f"| {name} | {out['n_fibers_slices']} | {a['recall']:.3f} | {a['precision']:.3f} | "
                         f"{a['mean_error_vox']:.3f} | {a['p95_error_vox']:.3f} |")
    head = (f"Volume (z, y, x) = {shape}, uint8 TIFF, 40 fibers of radius {radius} voxels (a third "
            f"touching), CNR 5; phantom generation + TIFF write (not counted): {t_make:.1f} s.")
    return head, "\n".join(lines), "\n".join(acc_lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer seeds, shorter phantoms, 1/4-length big volume")
    ap.add_argument("--out", default="docs/bench/imaging.md")
    ap.add_argument("--no-perf", action="store_true", help="skip part (b)")
    args = ap.parse_args(argv)
    seeds = [0, 1] if args.quick else [0, 1, 2, 3]
    n_slices = 120 if args.quick else 200
    shape = (250, 200, 400) if args.quick else (1000, 200, 400)
    report = []
    print("(a) accuracy", flush=True)
    agg, table = accuracy_part(seeds, n_slices, report)
    perf = None
    if not args.no_perf:
        print("(b) throughput", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            perf = perf_part(shape, 12.0, report, Path(tmp))
    cmd = "python -m fiberpipe.benchmarks.bench_imaging" + (" --quick" if args.quick else "")
    md = [f"# Imaging benchmark\n",
          f"- date: {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}",
          f"- machine: {machine()}",
          f"- command: `{cmd}` (NUMBA_NUM_THREADS=1; one process at a time)\n",
          "## (a) Tracer accuracy on phantoms\n",
          f"40 fibers, radius 5 voxels, (z, y, x) = ({n_slices}, 120, 120), a third in pairs touching "
          "along their whole length, waviness 2 voxels, PSF blur 1 voxel, CNR 4 and 6, seeds "
          f"{seeds}. Ours run on the Otsu mask of `segment`; fibretracker on the grey volume "
          "(blob detector, tuned to the radius). Errors are distances from traced points to the "
          "matched true mid-line, in voxels. Times include segmentation for ours.\n",
          "### Summary\n", agg, "", "### Per phantom\n", table, ""]
    if perf:
        head, stages, acc = perf
        md += ["## (b) Throughput and memory, 200 x 400 x 1000 voxels\n", head, "",
               "Each path runs in a fresh subprocess; peak RSS is `ru_maxrss` of that process "
               "after each stage. Target: < 60 s and < 4 GB.\n", stages, "",
               "Accuracy of the slices tracer on this volume:\n", acc, ""]
    md += report
    text = "\n".join(md) + "\n"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
