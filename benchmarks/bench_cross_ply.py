"""The real cross-ply CT example: qim3d's ``fibers_150x150x150.tif`` (MIT, the ``qim3d`` 1.5.3 wheel
on the package index) through ``fiberpipe run`` to the trace stage with only ``voxel_size: 1.3 um``.

Usage (from the repository root)::

    python benchmarks/bench_cross_ply.py [--cache DIR] [--pictures DIR] [--out FILE.md] [--chunked]

The volume is fetched with ``pip download --no-deps qim3d==1.5.3`` into ``--cache`` (default
``~/.cache/fiberpipe``) and read from the wheel; it is not part of the repository. Reported: the
tracer ``auto`` chose, the regions along other axes, the traced radius, and for the fibers along z
(the slicing axis) that cross the middle slice, how many run over at least 80 % of the depth and
their median length. ``--pictures`` copies the run's ``trace_slices.png`` and
``trace_midlines.png`` there (as ``cross_ply_*.png``) with three orthogonal slices of the volume.
``--chunked`` runs the stages chunk by chunk (``chunks.mode: on``, 32-slice blocks) on a copy of the
volume as HDF5.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]  # the source checkout
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

VOXEL_SIZE_M = 1.3e-6
MEMBER = "qim3d/examples/fibers_150x150x150.tif"


def fetch_volume(cache: Path) -> Path:
    """The example volume, extracted from the qim3d 1.5.3 wheel (downloaded once into ``cache``)."""
    out = cache / "fibers_150x150x150.tif"
    if out.exists():
        return out
    cache.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "qim3d==1.5.3", "-d", str(cache)], check=True)
    wheel = next(cache.glob("qim3d-1.5.3-*.whl"))
    with zipfile.ZipFile(wheel) as z, z.open(MEMBER) as src, open(out, "wb") as dst:
        shutil.copyfileobj(src, dst)
    return out


def z_fiber_depths(fibers, n_slices: int) -> tuple[int, int, float]:
    """Among traced fibers running along z (their end-to-end direction nearest z) that cross the
    middle slice: how many, how many span at least 80 % of the depth, their median z extent."""
    spans = np.asarray([float(np.ptp(p[:, 2])) for p in _z_fibers_crossing_middle(fibers, n_slices)])
    return len(spans), int(np.sum(spans >= 0.8 * (n_slices - 1))), float(np.median(spans)) if len(spans) else 0.0


def _z_fibers_crossing_middle(fibers, n_slices: int) -> list:
    """The traced fibers (voxel coordinates x y z) along z (end to end) that cross the middle slice."""
    out = []
    for i in range(fibers.n_fibers):
        p = fibers.fiber(i) / VOXEL_SIZE_M
        d = p[-1] - p[0]
        if np.argmax(np.abs(d)) == 2 and p[:, 2].min() <= n_slices / 2 <= p[:, 2].max():
            out.append(p)
    return out


def z_fiber_depths_in_view(fibers, n_slices: int, n_across: int) -> tuple[int, int]:
    """As :func:`z_fiber_depths`, counting only the fibers whose straight course (a line fitted to the
    traced mid-line) stays inside the volume's x and y range over at least 80 % of the depth around
    the middle slice: a fiber tilted a few degrees near a side face leaves the field of view, and no
    tracing of the scan can follow it over 80 % of the depth. Returns (how many, how many of them
    span at least 80 % of the depth)."""
    n, full = 0, 0
    z = np.arange(n_slices, dtype=float)
    for p in _z_fibers_crossing_middle(fibers, n_slices):
        slope, offset = np.polyfit(p[:, 2], p[:, :2], 1)
        inside = np.all((np.outer(z, slope) + offset >= 0) & (np.outer(z, slope) + offset <= n_across - 1), axis=1)
        lo = hi = n_slices // 2
        while lo > 0 and inside[lo - 1]:
            lo -= 1
        while hi < n_slices - 1 and inside[hi + 1]:
            hi += 1
        if hi - lo >= 0.8 * (n_slices - 1):
            n += 1
            full += int(np.ptp(p[:, 2]) >= 0.8 * (n_slices - 1))
    return n, full


#: The band of y (voxels) between the unidirectional plies (y < 30 and y > 120), where no fiber runs along z.
OTHER_PLIES_Y_VOX = (30.0, 120.0)


def z_tracks_between_plies(fibers, n_slices: int, grey=None, radius_vox: float = 0.0) -> tuple[int, int, float, list]:
    """Traced fibers running along z (end to end nearest z) whose mean y lies in
    :data:`OTHER_PLIES_Y_VOX`, where only the other plies are: how many, how many cross the middle
    slice, their median z extent (voxels), and one line per track (z range, mean y and x, and, given
    ``grey``, how far the grey structure around it runs off z: a fiber of a unidirectional ply reads
    a few degrees, a fragment of a +-45 deg ply about 45)."""
    from fiberpipe.imaging.dense import structure_direction

    spans, crossing, lines = [], 0, []
    for i in range(fibers.n_fibers):
        p = fibers.fiber(i) / VOXEL_SIZE_M
        d = p[-1] - p[0]
        if np.argmax(np.abs(d)) == 2 and OTHER_PLIES_Y_VOX[0] <= p[:, 1].mean() <= OTHER_PLIES_Y_VOX[1]:
            spans.append(float(np.ptp(p[:, 2])))
            crossing += int(p[:, 2].min() <= n_slices / 2 <= p[:, 2].max())
            line = f"z {p[:, 2].min():.0f}-{p[:, 2].max():.0f}, y {p[:, 1].mean():.0f}, x {p[:, 0].mean():.0f}"
            if grey is not None:
                s = structure_direction(grey, p[:, ::-1], radius_vox, np.full(3, VOXEL_SIZE_M))
                line += f", grey structure {np.degrees(np.arccos(min(1.0, abs(s[0]) / np.linalg.norm(s)))):.0f} deg off z"
            lines.append(line)
    return len(spans), crossing, float(np.median(spans)) if spans else 0.0, lines


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "fiberpipe")
    ap.add_argument("--pictures", type=Path)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--chunked", action="store_true", help="chunks.mode: on (32-slice blocks), the volume as HDF5")
    a = ap.parse_args(argv)
    from fiberpipe.artifacts import read_fibers
    from fiberpipe.config import load_config
    from fiberpipe.pipeline import run_pipeline

    volume = fetch_volume(a.cache)
    with tempfile.TemporaryDirectory() as tmp:
        cfg_path = Path(tmp) / "cross_ply.yaml"
        source, chunks = volume, ""
        if a.chunked:
            import h5py
            import tifffile

            source, chunks = Path(tmp) / "volume.h5", "chunks: {mode: on, slices: 32}\n"
            with h5py.File(source, "w") as f:
                f.create_dataset("volume", data=tifffile.imread(volume), chunks=(16, 150, 150))
        cfg_path.write_text(f"input: {{volume: {source}, voxel_size: 1.3 um}}\nskeletonize: {{enabled: false}}\n{chunks}")
        t0 = time.perf_counter()
        run_pipeline(load_config(cfg_path), Path(tmp) / "run", to_stage="trace")
        wall = time.perf_counter() - t0
        run = Path(tmp) / "run"
        tr = json.loads((run / "summary.json").read_text())["stages"]["trace"]
        fibers = read_fibers(run / "fibers.h5")
        import tifffile

        n, full, median = z_fiber_depths(fibers, 150)
        n_view, full_view = z_fiber_depths_in_view(fibers, 150, 150)
        n_between, n_between_mid, between_median, between = z_tracks_between_plies(
            fibers, 150, tifffile.imread(volume), tr["median_radius_m"] / VOXEL_SIZE_M)
        if a.pictures:
            a.pictures.mkdir(parents=True, exist_ok=True)
            for name in ("trace_slices.png", "trace_midlines.png"):
                shutil.copy(run / name, a.pictures / f"cross_ply_{name}")
            _orthogonal_slices(volume, a.pictures / "cross_ply_volume.png")
    off = ", ".join(f"{ax}: {v['volume_fraction']:.0%} of the fiber volume, {v['fibers']} fibers"
                    + (f" ({v['oblique']} tracks off its axis left out)" if v.get("oblique") else "")
                    for ax, v in tr["off_axis"].items() if ax != "oblique")
    oblique = tr["off_axis"].get("oblique", {"fibers": 0, "length_vox": 0.0})
    lines = [f"# Real cross-ply CT (qim3d fibers_150x150x150.tif, 1.3 um), only voxel_size given"
             f"{' (chunked: 32-slice blocks, HDF5)' if a.chunked else ''}\n",
             f"- segment + trace: {wall:.1f} s; tracer chosen by auto: {tr['method']}; traced radius "
             f"{tr['median_radius_m'] / VOXEL_SIZE_M:.2f} voxels; {tr['fibers']} fibers",
             f"- regions along other axes: {off or 'none'}",
             f"- tracks more than 30 deg off their slicing axis (a +-45 deg ply), left out: {oblique['fibers']} "
             f"({oblique['length_vox']:.0f} voxels of track; {oblique.get('by_structure', 0)} of them by the grey "
             "structure around them)",
             f"- tracks along z between the unidirectional plies (y = {OTHER_PLIES_Y_VOX[0]:g}-{OTHER_PLIES_Y_VOX[1]:g}): "
             f"{n_between}, {n_between_mid} crossing the middle slice, median z extent {between_median:.0f} slices",
             f"- fibers along z crossing the middle slice: {n}; over >= 80 % of the depth: {full} ({full / max(n, 1):.0%}); "
             f"median z extent {median:.0f} of 150 slices",
             f"- of those whose straight course stays in the field of view over >= 80 % of the depth: {n_view}; "
             f"over >= 80 % of the depth: {full_view} ({full_view / max(n_view, 1):.0%})",
             "- the tracks along z between the plies: " + ("; ".join(between) or "none")]
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        a.out.write_text(text)


def _orthogonal_slices(volume: Path, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import tifffile

    v = tifffile.imread(volume)
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for ax, (img, title) in zip(axes, [(v[75], "z = 75 (x across, y down)"), (v[:, 75], "y = 75 (x across, z down)"),
                                       (v[:, :, 75], "x = 75 (y across, z down)")]):
        ax.imshow(img, cmap="gray")
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(out, dpi=70)
    plt.close(fig)


if __name__ == "__main__":
    main()
