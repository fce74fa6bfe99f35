"""Fiber orientation distribution: from the mask (local structure tensor) and from traced fibers.

Both give the second-order orientation tensor ``A = <t t^T>`` (Advani & Tucker 1987, J. Rheol.
31:751), its eigenvalues (1, 0, 0 for perfectly aligned fibers, 1/2, 1/2, 0 for an isotropic
planar mat, 1/3 each for an isotropic 3D suspension), the dominant axis (eigenvector of the
largest eigenvalue) and a histogram of the angles between the fibers and that axis. The mask
measure also gives the fraction of the fiber volume within 45 degrees of the nearest volume axis,
which decides whether the slice-wise tracer applies (quasi-parallel fibers).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ..polylines import Polylines
from ._util import voxel_size_zyx

#: Histogram bins of the angle to the dominant axis, degrees.
ANGLE_BINS_DEG = np.arange(0.0, 91.0, 5.0)


def _summary(t_xyz: np.ndarray, w: np.ndarray) -> dict:
    """Orientation tensor, eigen-decomposition and angle histogram of unit directions (x y z)."""
    w = np.asarray(w, dtype=np.float64)
    wsum = float(w.sum())
    A = (t_xyz * w[:, None]).T @ t_xyz / wsum
    vals, vecs = np.linalg.eigh(A)
    order = np.argsort(vals)[::-1]
    vals, vecs = vals[order], vecs[:, order]
    main = vecs[:, 0] * (1.0 if vecs[np.argmax(np.abs(vecs[:, 0])), 0] > 0 else -1.0)
    ang = np.degrees(np.arccos(np.clip(np.abs(t_xyz @ main), 0.0, 1.0)))
    hist, _ = np.histogram(ang, bins=ANGLE_BINS_DEG, weights=w)
    # fraction within 45 deg of the volume axis nearest to each direction's best axis: the
    # slicing axis of the slices tracer is one volume axis, the one closest to the dominant axis
    axis = int(np.argmax(np.abs(main)))
    within = np.abs(t_xyz[:, axis]) >= np.cos(np.radians(45.0))
    # fraction within 30 deg of its own nearest volume axis, any of the three: fibers along volume
    # axes (a cross ply, a woven tow lying in the slices) that the slices tracer takes region by region
    along_axes = np.abs(t_xyz).max(axis=1) >= np.cos(np.radians(30.0))
    return {
        "tensor": A.round(6).tolist(),
        "eigenvalues": vals.round(6).tolist(),
        "dominant_axis_xyz": main.round(6).tolist(),
        "nearest_volume_axis": "xyz"[axis],
        "aligned_fraction_45deg": round(float(w[within].sum() / wsum), 4),
        "axis_aligned_fraction_30deg": round(float(w[along_axes].sum() / wsum), 4),
        "median_angle_deg": round(float(_weighted_median(ang, w)), 3),
        "angle_histogram": {"bin_edges_deg": ANGLE_BINS_DEG.tolist(),
                            "fraction": (hist / wsum).round(6).tolist()},
    }


def _weighted_median(x: np.ndarray, w: np.ndarray) -> float:
    o = np.argsort(x)
    c = np.cumsum(w[o])
    return float(x[o][np.searchsorted(c, 0.5 * c[-1])])


def fiber_orientation(polylines: Polylines) -> dict:
    """Orientation distribution of traced fibers, each segment weighted by its length.

    Returns a dict (JSON-ready): ``tensor`` (3x3, x y z), ``eigenvalues`` (descending),
    ``dominant_axis_xyz``, ``nearest_volume_axis``, ``aligned_fraction_45deg``,
    ``median_angle_deg``, ``angle_histogram`` (``bin_edges_deg``, ``fraction`` of fiber length),
    and ``source: "fibers"``. Empty input gives ``{"source": "fibers", "n_segments": 0}``.
    """
    segs, ws = [], []
    for p in polylines:
        d = np.diff(p, axis=0)
        L = np.linalg.norm(d, axis=1)
        ok = L > 0
        segs.append(d[ok] / L[ok, None])
        ws.append(L[ok])
    t = np.concatenate(segs) if segs else np.zeros((0, 3))
    if len(t) == 0:
        return {"source": "fibers", "n_segments": 0}
    out = _summary(t, np.concatenate(ws))
    out.update(source="fibers", n_segments=int(len(t)))
    return out


def mask_orientation(mask: np.ndarray, voxel_size_m=1.0, *, max_voxels: int = 2_000_000) -> dict:
    """Orientation distribution of the fibers in a mask, from the local structure tensor.

    Strategy: on a strided subsample of about ``max_voxels`` voxels (a view), the smoothed mask's
    gradient outer products are averaged over a window of about one fiber radius (the radius from
    volume and surface of the subsample, r = 2 V / S for cylinders, S corrected by 2/3 for the
    staircase of a digital surface); at each voxel with a strong response the fiber direction is
    the eigenvector of the smallest eigenvalue (Bigun & Granlund 1987; the method of the
    ``structure-tensor`` package). A window of one radius spans the cross-section's curvature, so
    the axis is the only direction without gradient.

    Returns the dict of :func:`fiber_orientation` with ``source: "mask"``, ``n_samples`` and
    ``radius_vox_subsampled``.
    """
    v = voxel_size_zyx(voxel_size_m)
    step = max(1, int(np.ceil((mask.size / float(max_voxels)) ** (1.0 / 3.0))))
    sub, scale, r = _subsample(mask, v, step)
    if r > 6.0:  # thick fibers: a coarser sample (radius ~3 samples) keeps the window small
        step *= int(r // 3.0)
        sub, scale, r = _subsample(mask, v, step)
    if min(sub.shape) < 3:  # np.gradient and the window need a few samples along every axis
        return {"source": "mask", "n_samples": 0}
    rho = float(np.clip(r, 1.0, 6.0))
    f = ndi.gaussian_filter(sub.astype(np.float32), 1.0)
    g = np.gradient(f, *scale)
    del f
    J = {}
    for i in range(3):
        for j in range(i, 3):
            J[i, j] = ndi.gaussian_filter(g[i] * g[j], rho / scale, truncate=3.0)
    del g
    tr = J[0, 0] + J[1, 1] + J[2, 2]
    strong = tr > 0.1 * float(np.percentile(tr[tr > 0], 90)) if np.any(tr > 0) else tr > 0
    n = int(strong.sum())
    if n == 0:
        return {"source": "mask", "n_samples": 0}
    T = np.empty((n, 3, 3), dtype=np.float64)
    for (i, j), a in J.items():
        T[:, i, j] = T[:, j, i] = a[strong]
    w = tr[strong].astype(np.float64)
    _, vecs = np.linalg.eigh(T)
    t_zyx = vecs[:, :, 0]
    out = _summary(t_zyx[:, ::-1].copy(), w)
    out.update(source="mask", n_samples=n, radius_vox_subsampled=round(r, 3), subsample_step=int(step))
    return out


def _subsample(mask: np.ndarray, v: np.ndarray, step: int):
    """Strided sample of the mask, its relative spacing (z y x) and the fiber radius in samples
    from r = 2 V / S (digital surface faces x 2/3)."""
    # a thin axis keeps at least 3 samples (a (3, 3000, 3000) volume is not cut to one slice)
    st = [max(1, min(step, (n - 1) // 2)) for n in mask.shape]
    sub = np.ascontiguousarray(mask[::st[0], ::st[1], ::st[2]])
    scale = v * np.asarray(st) / (v * np.asarray(st)).min()
    V = float(sub.sum())
    faces = sum(float(np.count_nonzero(np.diff(sub, axis=a))) * scale[[i for i in range(3) if i != a]].prod()
                for a in range(3))
    return sub, scale, 2.0 * V * scale.prod() / max(faces / 1.5, 1.0)


def is_quasi_parallel(orientation: dict, min_aligned_fraction: float) -> bool:
    """Whether the slice-wise tracer applies: at least ``min_aligned_fraction`` of the fibers run
    within 45 degrees of one volume axis."""
    return float(orientation.get("aligned_fraction_45deg", 0.0)) >= min_aligned_fraction


def axis_regions(mask: np.ndarray, voxel_size_m=1.0, *, grey: np.ndarray | None = None,
                 radius_vox: float | None = None, max_voxels: int = 2_000_000):
    """Which volume axis the fibers run along, voxel by voxel: the regions of a cross-ply or woven
    scan (a tow along z beside a tow lying in the slices).

    Strategy: fibers along volume axis a have no gradient along a, so of the three diagonal terms
    of the structure tensor (the smoothed mask's squared derivatives, averaged over two fiber
    radii so a fiber's inside takes the class of its surface) the one along the fibers' axis is the
    smallest (Bigun & Granlund 1987). Each sample of a strided subsample takes the axis of its
    smallest term; the labels are expanded back to the full grid (nearest sample). Only the
    diagonal is needed to tell the axis, so no eigen-decomposition per voxel.

    Given the ``grey`` volume, the derivatives are those of the grey values: in a dense pack the
    mask merges the fibers into solid regions with no gradient inside, the grey image keeps every
    fiber's outline, and the window is one fiber radius (``radius_vox``, when given) instead of two.

    Returns
    -------
    labels : (Z, Y, X) uint8 ndarray
        0, 1 or 2 (the volume axis, z y x order) on the mask, 255 off it.
    fractions : (3,) float ndarray
        Share of the mask's voxels in each class.
    """
    v = voxel_size_zyx(voxel_size_m)
    labels = np.full(mask.shape, 255, dtype=np.uint8)
    n_mask = int(np.count_nonzero(mask))
    classes = _axis_classes(mask, v, grey, radius_vox, max_voxels) if n_mask else None
    if classes is None:
        labels[mask] = 0
        return labels, np.array([1.0, 0.0, 0.0])
    cls, _, st = classes
    # expand the sample grid back to the full grid: sample i covers voxels i*st - st/2 .. i*st + st/2
    idx = [np.clip(np.rint(np.arange(n) / s).astype(np.int64), 0, cls.shape[a] - 1)
           for a, (n, s) in enumerate(zip(mask.shape, st))]
    for k in range(mask.shape[0]):  # one slice at a time: no full-size index arrays
        lab = cls[idx[0][k]][np.ix_(idx[1], idx[2])]
        labels[k][mask[k]] = lab[mask[k]]
    counts = np.bincount(labels[labels < 3].ravel(), minlength=3)[:3].astype(np.float64)
    return labels, counts / max(1.0, counts.sum())


def _axis_classes(mask, v: np.ndarray, grey, radius_vox, max_voxels: int):
    """The volume axis of the smallest structure-tensor diagonal term at every sample of a strided
    subsample (see :func:`axis_regions`): (classes, the mask's subsample, strides), or None when
    the subsample is too thin."""
    step = max(1, int(np.ceil((mask.size / float(max_voxels)) ** (1.0 / 3.0))))
    sub, scale, r = _subsample(mask, v, step)
    st = [max(1, min(step, (n - 1) // 2)) for n in mask.shape]
    if min(sub.shape) < 3:
        return None
    rho = float(np.clip(r, 1.0, 6.0))
    src = sub if grey is None else grey[::st[0], ::st[1], ::st[2]]
    f = ndi.gaussian_filter(src.astype(np.float32), 1.0)
    if grey is not None:  # scale-free: the classes compare derivatives of one field
        f /= max(float(np.std(f)), 1e-12)
    g = np.gradient(f, *scale)
    del f
    win = 2.0 * rho if grey is None or radius_vox is None else max(1.0, float(radius_vox) / step)
    D = np.stack([ndi.gaussian_filter(g[a] * g[a], win / scale, truncate=2.0) for a in range(3)])
    del g
    return np.argmin(D, axis=0).astype(np.uint8), sub, st


def axis_fractions(mask, voxel_size_m=1.0, *, max_voxels: int = 2_000_000) -> np.ndarray:
    """Share of the fiber volume running along each volume axis (z y x), measured on the strided
    subsample of :func:`axis_regions` only (no full-size labels: a mask on disk is sampled, not
    read)."""
    classes = _axis_classes(mask, voxel_size_zyx(voxel_size_m), None, None, max_voxels)
    if classes is None:
        return np.array([1.0, 0.0, 0.0])
    cls, sub, _ = classes
    counts = np.bincount(cls[sub.astype(bool)].ravel(), minlength=3)[:3].astype(np.float64)
    return counts / max(1.0, counts.sum())
