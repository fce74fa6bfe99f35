"""Pictures to check a tracing: slices with the traced centres and radii drawn over the mask, the
mid-lines in 3D coloured by fiber, the orientation histogram (matplotlib, written atomically)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..polylines import Polylines
from ._util import voxel_size_zyx, xyz_m_to_voxel


def _save(fig, path: Path) -> None:
    from fiberpipe.artifacts import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")


def crossings(fibers: Polylines, axis: int, k: float, voxel_size_m) -> tuple[np.ndarray, np.ndarray]:
    """Where the fibers cross the plane ``index[axis] = k`` (voxel index units).

    Returns the in-plane positions (n, 2) (the other two axes in z y x order) and the fiber index of
    each crossing (n,).
    """
    v = voxel_size_zyx(voxel_size_m)
    other = [a for a in range(3) if a != axis]
    pts, ids = [], []
    for i, p in enumerate(fibers):
        q = xyz_m_to_voxel(p, v)
        c = q[:, axis] - k
        s = np.flatnonzero((c[:-1] <= 0) & (c[1:] > 0) | (c[:-1] > 0) & (c[1:] <= 0))
        for j in s:
            w = c[j] / (c[j] - c[j + 1]) if c[j] != c[j + 1] else 0.0
            pts.append((q[j] + w * (q[j + 1] - q[j]))[other])
            ids.append(i)
    return (np.asarray(pts).reshape(-1, 2), np.asarray(ids, dtype=np.int64))


def slice_overlay_png(path, mask: np.ndarray, fibers: Polylines, voxel_size_m, *, axis: int = 0,
                      depths=(0.25, 0.5, 0.75), truth: Polylines | None = None,
                      matches: list | None = None) -> Path:
    """Montage of three slices across ``axis`` with each traced fiber's centre (dot) and radius
    (circle) where it crosses the slice. With ``truth``: true centres as crosses; with ``matches``
    ((traced, true, cost) pairs, as :func:`fiberpipe.imaging.accuracy.trace_accuracy` returns),
    missed true fibers in red and false tracks in orange."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import EllipseCollection

    v = voxel_size_zyx(voxel_size_m)
    other = [a for a in range(3) if a != axis]
    n = mask.shape[axis]
    ks = [int(round(d * (n - 1))) for d in depths]
    fig, axes = plt.subplots(1, len(ks), figsize=(4.2 * len(ks), 4.4), squeeze=False)
    matched_tr = {m[0] for m in matches} if matches is not None else None
    matched_true = {m[1] for m in matches} if matches is not None else None
    cmap = plt.get_cmap("tab10")
    for ax, k in zip(axes[0], ks):
        # an index, not np.take: a mask on disk (h5py dataset) reads one slice
        ax.imshow(np.asarray(mask[(slice(None),) * axis + (k,)]), cmap="gray", interpolation="nearest", vmin=0, vmax=1.6)
        P, ids = crossings(fibers, axis, k, v)
        if len(P):
            r_pix = fibers.radius_m[ids, None] / v[other][None, :]  # radius in pixels along rows, columns
            false = np.array([i not in matched_tr for i in ids]) if matched_tr is not None else np.zeros(len(ids), bool)
            base = cmap(ids % 10) if matched_tr is None else np.tile([0.0, 0.45, 1.0, 1.0], (len(ids), 1))
            colours = np.where(false[:, None], np.array([[1.0, 0.55, 0.0, 1.0]]), base)
            ax.add_collection(EllipseCollection(2 * r_pix[:, 1], 2 * r_pix[:, 0], np.zeros(len(ids)), units="xy",
                                                offsets=P[:, ::-1], offset_transform=ax.transData,
                                                facecolors="none", edgecolors=colours, linewidths=1.2))
            ax.plot(P[:, 1], P[:, 0], ".", ms=3, color="blue")
        if truth is not None:
            T, tid = crossings(truth, axis, k, v)
            if len(T):
                miss = np.array([j not in matched_true for j in tid]) if matched_true is not None else np.zeros(len(tid), bool)
                ax.plot(T[~miss, 1], T[~miss, 0], "+", ms=5, color="lime", mew=0.8)
                ax.plot(T[miss, 1], T[miss, 0], "x", ms=7, color="red", mew=1.5)
        ax.set_title(f"{'zyx'[axis]} = {k} (of {n})", fontsize=9)
        ax.set_xlabel("zyx"[other[1]] + " (voxels)", fontsize=8)
        ax.set_ylabel("zyx"[other[0]] + " (voxels)", fontsize=8)
        ax.tick_params(labelsize=7)
    note = "circles: traced radius; dots: traced centres"
    if truth is not None:
        note += "; +: true centres" + ("; red x: missed; orange: false tracks" if matches is not None else "")
    fig.suptitle(note, fontsize=9)
    path = Path(path)
    _save(fig, path)
    plt.close(fig)
    return path


def midlines_3d_png(path, fibers: Polylines, *, max_fibers: int = 2000) -> Path:
    """The mid-lines in 3D (mm), one colour per fiber."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    cmap = plt.get_cmap("tab20")
    for i, p in enumerate(fibers):
        if i >= max_fibers:
            break
        q = p * 1e3
        ax.plot(q[:, 0], q[:, 1], q[:, 2], lw=0.8, color=cmap(i % 20))
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(f"{fibers.n_fibers} traced fibers", fontsize=9)
    path = Path(path)
    _save(fig, path)
    plt.close(fig)
    return path


def orientation_png(path, orientation: dict) -> Path:
    """Histogram of fiber angles to the dominant axis, one bar series per distribution (``mask``,
    ``fibers``) of an ``orientation.json`` dict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6))
    series = [(k, o) for k, o in orientation.items() if isinstance(o, dict) and "angle_histogram" in o]
    width = 5.0 / max(1, len(series))
    for n, (name, o) in enumerate(series):
        e = np.asarray(o["angle_histogram"]["bin_edges_deg"])
        f = np.asarray(o["angle_histogram"]["fraction"])
        ax.bar(e[:-1] + n * width, f, width=width, align="edge",
               label=f"{name}: eigenvalues {', '.join(f'{x:.2f}' for x in o['eigenvalues'])}")
    ax.set_xlabel("angle to the dominant axis (deg)")
    ax.set_ylabel("fraction")
    ax.set_xlim(0, 90)
    ax.legend(fontsize=8)
    path = Path(path)
    _save(fig, path)
    plt.close(fig)
    return path
