"""Fiber radius measured on the grey image, independent of the mask: the full width at half
maximum (FWHM) of grey profiles across traced mid-lines."""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ..polylines import Polylines
from ._util import voxel_size_zyx, xyz_m_to_voxel


def _half_crossing(prof: np.ndarray, s: np.ndarray, level: float, i0: int, step: int) -> float | None:
    """Position (along ``s``) where ``prof`` first falls below ``level`` walking from ``i0`` by
    ``step``, linearly interpolated; None if it never does."""
    i = i0
    while 0 <= i + step < len(prof):
        a, b = prof[i], prof[i + step]
        if b < level <= a:
            w = (a - level) / (a - b) if a != b else 0.0
            return float(s[i] + w * (s[i + step] - s[i]))
        i += step
    return None


def fwhm_radius_vox(volume: np.ndarray, fibers: Polylines, voxel_size_m, *, half_width_vox: float = 8.0,
                    every_vox: float = 4.0, smooth_sigma_vox: float = 0.0, invert: bool = False) -> dict:
    """Fiber radius from grey-level profiles across the traced mid-lines.

    At points every ``every_vox`` along each fiber, the grey volume is sampled (trilinear) on two
    lines through the point, perpendicular to the fiber and to each other, over
    ``+-half_width_vox``. The background level of a profile is the lower of its two ends, the
    peak its value at the centre; the width is where the profile falls to the mean of the two on
    both sides (FWHM). For a disc of radius r blurred by a Gaussian PSF of sigma << r, FWHM = 2 r.
    Profiles whose half level is not crossed on both sides (a touching neighbour, the volume's
    edge) are skipped.

    Returns
    -------
    dict: ``median_radius_vox``, ``n_profiles``, ``n_used``.
    """
    v = voxel_size_zyx(voxel_size_m)
    img = np.asarray(volume, dtype=np.float32)
    if invert:
        img = -img
    if smooth_sigma_vox > 0:
        img = ndi.gaussian_filter(img, smooth_sigma_vox)
    s = np.arange(-half_width_vox, half_width_vox + 0.25, 0.25)
    widths, n_prof = [], 0
    for p in fibers:
        q = xyz_m_to_voxel(p, v)  # z y x
        if len(q) < 3:
            continue
        seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        for a in np.arange(every_vox / 2, arc[-1] - every_vox / 2 + 1e-9, every_vox):
            k = int(np.clip(np.searchsorted(arc, a), 1, len(q) - 1))
            c = q[k]
            t = q[min(k + 1, len(q) - 1)] - q[k - 1]
            nt = np.linalg.norm(t)
            if nt == 0:
                continue
            t /= nt
            e1 = np.cross(t, [1.0, 0.0, 0.0] if abs(t[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(t, e1)
            for e in (e1, e2):
                n_prof += 1
                pts = c[None, :] + s[:, None] * e[None, :]
                prof = ndi.map_coordinates(img, pts.T, order=1, mode="nearest")
                i0 = len(s) // 2
                lvl = 0.5 * (prof[i0] + min(prof[0], prof[-1]))
                lo = _half_crossing(prof, s, lvl, i0, -1)
                hi = _half_crossing(prof, s, lvl, i0, +1)
                if lo is not None and hi is not None:
                    widths.append(hi - lo)
    w = np.asarray(widths)
    return {"median_radius_vox": float(np.median(w) / 2) if len(w) else float("nan"),
            "n_profiles": int(n_prof), "n_used": int(len(w))}
