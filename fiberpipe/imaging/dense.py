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
#: Smallest radius (pixels) :func:`estimate_radius_grey` tries: two pixels across, just above the
#: thinnest fibers the tracers take (1.5 voxels across).
GREY_RADIUS_MIN_VOX = 1.0
#: Steps of the radius search of :func:`estimate_radius_grey` in log(radius): a coarse pass over the
#: whole range, then a fine one around the coarse minimum.
_LOG_STEP_COARSE, _LOG_STEP_FINE = 0.14, 0.035
#: Offsets (slices) of the raw slices averaged into the two interleaved halves of
#: :func:`estimate_radius_grey`: each centred on the slice, neither sharing a slice (or its noise)
#: with the other.
_HALF_OFFSETS = ((-2, 0, 2), (-3, -1, 1, 3))


def is_dense_pack(volume_fraction: float, radius_vox: float) -> bool:
    """Whether a scan is a dense pack of thin fibers: a mask volume fraction of at least
    :data:`DENSE_MIN_VOLUME_FRACTION` and a (mask) radius of at most :data:`DENSE_MAX_RADIUS_VOX`."""
    return volume_fraction >= DENSE_MIN_VOLUME_FRACTION and radius_vox <= DENSE_MAX_RADIUS_VOX


def _interleaved_halves(grey_slices, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Two images of slice ``k`` with independent noise: the means of the raw slices at the offsets
    :data:`_HALF_OFFSETS` (even and odd), each blurred in the slice as the tracer's slices are and
    scaled to background 0, fiber 1 (``grey_slices``: a ``trace._GreySlices``)."""
    g, n = grey_slices.g, grey_slices.g.shape[0]
    out = []
    for offsets in _HALF_OFFSETS:
        ks = np.clip(k + np.asarray(offsets), 0, n - 1)
        mean = np.mean([np.asarray(g[q], dtype=np.float64) for q in ks], axis=0)
        if grey_slices.sigma_in > 0:
            mean = ndi.gaussian_filter(mean, grey_slices.sigma_in / grey_slices.samp, mode="nearest")
        out.append((mean - grey_slices.lo) / (grey_slices.hi - grey_slices.lo))
    return out[0], out[1]


def _fit_disk_model(grey: np.ndarray, near: np.ndarray, centres: np.ndarray, radius: float, samp, *,
                    fit_levels: bool) -> tuple[np.ndarray, float, float]:
    """The blurred-disk model of a slice (disks of ``radius`` blurred by :data:`FIT_SIGMA_VOX`),
    fitted on the pixels ``near`` the mask: the centres by the joint disk fit
    (:func:`fiberpipe.imaging._kernels.fit_disk_centres`) at amplitude 1 on background 0, or, with
    ``fit_levels``, one amplitude and one background for all disks by linear least squares
    alternating with the centres (twice). Returns the model on those pixels, the amplitude and the
    background."""
    from ._kernels import fit_disk_centres, render_disks

    c = np.ascontiguousarray(centres, dtype=np.float64).reshape(-1, 2)
    amplitude, background = 1.0, 0.0
    g = grey[near]
    for _ in range(2 if fit_levels else 1):
        scaled = np.where(near, (grey - background) / amplitude, 0.0).astype(np.float32)
        c, _, _ = fit_disk_centres(scaled, c, np.ones(len(c)), float(radius), FIT_SIGMA_VOX, float(samp[0]),
                                   float(samp[1]), 3, False)
        model = render_disks(np.array(grey.shape, dtype=np.int64), c, float(radius), FIT_SIGMA_VOX,
                             float(samp[0]), float(samp[1]))[near]
        if fit_levels:
            (background, amplitude), *_ = np.linalg.lstsq(np.column_stack([np.ones(len(g)), model]), g, rcond=None)
            amplitude = max(float(amplitude), 1e-3)
    return background + amplitude * model, float(amplitude), float(background)


def _cross_validated_cost(slices, detect, radius: float, samp, *, fit_levels: bool) -> tuple[float, float, float]:
    """Squared prediction error of the disk model of ``radius``: for each slice, the centres are
    detected and the model fitted on one half (:func:`_interleaved_halves`) and compared with the
    other, both ways. Returns the error and the mean fitted amplitude and background."""
    cost, levels = 0.0, []
    for first, second, sl, near in slices:
        for fit_on, test_on in ((first, second), (second, first)):
            centres = detect(sl, fit_on.astype(np.float32), radius)
            if len(centres) == 0:
                residual = test_on[near] - np.mean(test_on[near])
            else:
                model, amplitude, background = _fit_disk_model(fit_on, near, centres, radius, samp,
                                                               fit_levels=fit_levels)
                residual = test_on[near] - model
                levels.append((amplitude, background))
            cost += float(residual @ residual)
    amplitude, background = np.mean(levels, axis=0) if levels else (1.0, 0.0)
    return cost, float(amplitude), float(background)


def _least_cost_radius(slices, detect, radii: np.ndarray, samp, *, fit_levels: bool) -> tuple[float, float, float]:
    """The radius of least :func:`_cross_validated_cost` among ``radii`` (a geometric series),
    refined by a parabola in log(radius) through its neighbours, with the amplitude and background
    fitted there."""
    runs = [_cross_validated_cost(slices, detect, r, samp, fit_levels=fit_levels) for r in radii]
    costs = np.array([x[0] for x in runs])
    j = int(np.argmin(costs))
    best = float(np.log(radii[j]))
    if 0 < j < len(radii) - 1:
        y0, y1, y2 = costs[j - 1], costs[j], costs[j + 1]
        den = y0 - 2 * y1 + y2
        off = 0.5 * (y0 - y2) / den if den > 0 else 0.0
        best += float(np.clip(off, -0.5, 0.5)) * float(np.log(radii[1] / radii[0]))
    return float(np.exp(best)), runs[j][1], runs[j][2]


def estimate_radius_grey(grey_slices, mask_t, samp: np.ndarray, r_start: float, detect, *, n_slices: int = 6) -> float:
    """The fiber radius (pixels) whose blurred-disk model predicts the grey slices best.

    For each trial radius and each of ``n_slices`` slices, fiber centres are detected (``detect``,
    the tracer's own detection at that radius) and blurred disks of that radius fitted (centres, one
    amplitude and one background for all) on one half of the raw slices around it; the model's
    squared error against the other half, whose noise is independent, is the radius' cost
    (hold-out cross-validation: Hastie, Tibshirani and Friedman, *The Elements of Statistical
    Learning*, 2nd ed., 2009, sec. 7.10). The least cost wins: a coarse search in log(radius) from
    :data:`GREY_RADIUS_MIN_VOX` to 1.25 ``r_start``, a fine one around its minimum, refined by a
    parabola.

    Why the amplitude and background are fitted: the levels the slices are scaled by (the medians
    inside and outside the mask) are not the fibers' and the matrix's once the blur spreads each
    fiber into its neighbours' gaps (the real cross-ply example: 23 grey levels between the
    medians, about 60 between fiber and matrix), and a disk of a wrong amplitude fits best at a
    wrong radius. The price: a thinner disk of a higher amplitude predicts a blurred fiber almost
    as well, so the estimate runs 3-7 % low at the family's blur (0.8 voxel) and within 10 % at
    1.5-2 voxels (tests/imaging/test_dense.py).

    Why the held-out half: fitted on the same pixels it is scored on, the model's error falls with
    every disk it adds, and a trial radius below the fibers' finds more centres (noise peaks, two
    per fiber) and fits the noise with them (on a pack of r = 3 fibers blurred by 2 voxels at CNR
    2, that error is least at 1.2 voxels); disks fitted to noise predict nothing of the other half.

    ``grey_slices``: a ``trace._GreySlices`` (the raw grey with its levels); ``mask_t``: the mask,
    same axes; ``r_start``: the mask's estimate, which a merged pack overestimates;
    ``detect(mask_slice, grey_slice, r)``: the tracer's centre detection in one slice, (n, 2) pixel
    indices.
    """
    n = mask_t.shape[0]
    ks = np.unique(np.linspace(0.2 * (n - 1), 0.8 * (n - 1), n_slices).round().astype(int))
    slices = []
    for k in ks:
        sl = np.asarray(mask_t[k])
        if sl.any():
            # the grey of another region (a cross ply) is no fiber of the model
            slices.append((*_interleaved_halves(grey_slices, int(k)), sl, ndi.binary_dilation(sl, iterations=2)))
    if not slices:
        raise InputError("trace: no fiber cross-sections found in the grey slices")
    top = np.log(max(1.5 * GREY_RADIUS_MIN_VOX, 1.25 * float(r_start)))
    coarse = np.exp(np.arange(np.log(GREY_RADIUS_MIN_VOX), top + 1e-9, _LOG_STEP_COARSE))
    costs = [_cross_validated_cost(slices, detect, r, samp, fit_levels=True)[0] for r in coarse]
    around = np.log(coarse[int(np.argmin(costs))]) + _LOG_STEP_FINE * np.arange(-4, 5)
    return _least_cost_radius(slices, detect, np.exp(around), samp, fit_levels=True)[0]


#: Radius of the tube around a track whose grey structure gives the track's fiber direction
#: (:func:`structure_direction`), in fiber radii: the fiber and the matrix around it.
TUBE_RADII = 1.5


def structure_direction(grey, track_zyx_vox: np.ndarray, radius_vox: float, voxel_size_zyx_m) -> np.ndarray:
    """The fiber direction (unit, z y x) in the grey volume around a track: the eigenvector of the
    least eigenvalue of the structure tensor (the sum of the outer products of the grey gradient,
    Bigun and Granlund 1987) over the voxels within :data:`TUBE_RADII` radii of the track.

    ``grey``: anything read by boxes (an array, an HDF5 or Zarr dataset); ``track_zyx_vox``: the
    track's points (voxel indices, z y x, about one voxel apart).

    Why: a track through a ply at 40 degrees to the slicing axis can run at less than 30 degrees
    end to end (it steps from fiber to fiber as their cross-sections slide through the slices), but
    the grey around it still runs along the ply."""
    from scipy.spatial import cKDTree

    v = np.asarray(voxel_size_zyx_m, dtype=np.float64)
    tube = TUBE_RADII * float(radius_vox)
    pad = int(np.ceil(tube)) + 3
    lo = np.maximum(np.floor(track_zyx_vox.min(axis=0)).astype(int) - pad, 0)
    hi = np.minimum(np.ceil(track_zyx_vox.max(axis=0)).astype(int) + pad + 1, np.asarray(grey.shape))
    box = np.asarray(grey[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]], dtype=np.float32)
    if min(box.shape) < 3:
        return np.array([1.0, 0.0, 0.0])
    scale = v / v.min()
    g = np.gradient(ndi.gaussian_filter(box, 1.0 / scale), *scale)
    grid = np.stack(np.meshgrid(*[np.arange(n) for n in box.shape], indexing="ij"), axis=-1).reshape(-1, 3)
    dist, _ = cKDTree((track_zyx_vox - lo) * scale).query(grid * scale, distance_upper_bound=tube)
    inside = np.isfinite(dist)
    grads = np.stack([a.reshape(-1)[inside] for a in g], axis=1).astype(np.float64)
    if len(grads) < 3:
        return np.array([1.0, 0.0, 0.0])
    _, vecs = np.linalg.eigh(grads.T @ grads)
    return vecs[:, 0]
