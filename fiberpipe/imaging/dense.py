"""Dense packs: the fiber radius read from the grey slices, and when a scan is one.

A unidirectional composite scanned at 5-10 voxels per fiber diameter, packed at v_f 0.45-0.65,
thresholds into one merged region: its distance transform measures the pores, not the fibers
(5.2 voxels for fibers of 3), so the grey tracer (:func:`fiberpipe.imaging.trace.trace_slices`
with ``grey``), which needs the radius within about 10 %, reads it from the grey slices instead.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from ..errors import InputError

#: Mask volume fraction from which a scan of thin fibers counts as a dense pack (v_f 0.45-0.65 in
#: composites; a loose bundle or a mat stays well below).
DENSE_MIN_VOLUME_FRACTION = 0.35
#: Largest fiber radius (voxels, from the mask) of a dense pack the grey tracer is for: above it the
#: mask separates the fibers by itself (the study's bundles, 16 voxels).
DENSE_MAX_RADIUS_VOX = 8.0
#: Blur of the fitted disk template (:func:`fiberpipe.imaging.trace.fit_centres`), pixels: the
#: in-slice denoising of the grey slices (0.7) with a scanner's point spread of about one voxel
#: (0.7, the phantoms' 0.8 less the partial-volume ramp it already includes).
FIT_SIGMA_VOX = 1.0
#: Radii tried by :func:`estimate_radius_grey`, as factors of the start value.
_RADIUS_FACTORS = np.arange(0.45, 1.26, 0.05)


def is_dense_pack(volume_fraction: float, radius_vox: float) -> bool:
    """Whether a scan is a dense pack of thin fibers: a mask volume fraction of at least
    :data:`DENSE_MIN_VOLUME_FRACTION` and a (mask) radius of at most :data:`DENSE_MAX_RADIUS_VOX`."""
    return volume_fraction >= DENSE_MIN_VOLUME_FRACTION and radius_vox <= DENSE_MAX_RADIUS_VOX


def estimate_radius_grey(grey_slices, mask_t, samp: np.ndarray, r_start: float, detect, *, n_slices: int = 8) -> float:
    """The fiber radius (pixels) that explains the grey slices best: for each trial radius, fiber
    centres are detected and blurred disks of that radius fitted to a few slices together
    (:func:`fiberpipe.imaging.trace.fit_centres`'s model); the radius with the least squared
    residual wins (least-squares model selection), refined by a parabola through its neighbours.

    ``grey_slices``: the normalised grey slices (``trace._GreySlices``); ``mask_t``: the mask, same
    axes; ``r_start``: the mask's estimate, which a merged pack overestimates (the trial radii run
    from 0.45 to 1.25 times it); ``detect(mask_slice, grey_slice, r)``: the tracer's centre
    detection in one slice, (n, 2) pixel indices.
    """
    from ._kernels import fit_disk_centres

    n = mask_t.shape[0]
    ks = np.unique(np.linspace(0.2 * (n - 1), 0.8 * (n - 1), n_slices).round().astype(int))
    slices = []
    for k in ks:
        sl = np.asarray(mask_t[k])
        # the grey of another region (a cross ply) is no fiber of the model
        slices.append((np.where(ndi.binary_dilation(sl, iterations=2), grey_slices[k], 0.0).astype(np.float32), sl))
    radii = r_start * _RADIUS_FACTORS
    radii = radii[radii >= 1.0]
    if len(radii) < 3:
        return float(r_start)
    cost = np.zeros(len(radii))
    for i, r in enumerate(radii):
        for g, sl in slices:
            c = detect(sl, g, r)
            if len(c) == 0:
                cost[i] += float(np.sum(g.astype(np.float64) ** 2))
                continue
            _, _, ssr = fit_disk_centres(g, np.ascontiguousarray(c, dtype=np.float64), np.ones(len(c)), float(r),
                                         FIT_SIGMA_VOX, float(samp[0]), float(samp[1]), 4, False)
            cost[i] += ssr
    j = int(np.argmin(cost))
    if not np.isfinite(cost[j]):
        raise InputError("trace: no fiber cross-sections found in the grey slices")
    if 0 < j < len(radii) - 1:
        y0, y1, y2 = cost[j - 1], cost[j], cost[j + 1]
        den = y0 - 2 * y1 + y2
        off = 0.5 * (y0 - y2) / den if den > 0 else 0.0
        return float(radii[j] + np.clip(off, -0.5, 0.5) * (radii[1] - radii[0]))
    return float(radii[j])
