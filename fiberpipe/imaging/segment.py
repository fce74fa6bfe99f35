"""Segmentation: grey CT volume -> boolean fiber mask."""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi
from skimage.filters import threshold_otsu

from ..errors import InputError

#: Largest number of voxels used to compute the Otsu threshold (a strided subsample above that).
_OTSU_SAMPLE = 4_000_000


def _strided_sample(a: np.ndarray, n_max: int) -> np.ndarray:
    """A regular strided view of ``a`` with at most about ``n_max`` elements (no copy)."""
    step = max(1, int(np.ceil((a.size / n_max) ** (1.0 / a.ndim))))
    return a[(slice(None, None, step),) * a.ndim]


def _remove_small_and_fill(mask: np.ndarray, min_object_vox: int, fill_holes: bool) -> int:
    """Remove components smaller than ``min_object_vox`` and fill enclosed cavities, in place.

    Returns the number of foreground components left (26-connectivity).
    """
    # Strategy: one labelling pass for objects (26-connected, as fibers are thin and may touch only
    # diagonally), and one of the background (6-connected, the dual connectivity) for holes: a
    # background component that does not touch the volume's border is a cavity and is filled. This
    # is O(N), unlike ndimage.binary_fill_holes, which iterates dilations.
    struct26 = np.ones((3, 3, 3), dtype=bool)
    labels, n = ndi.label(mask, structure=struct26)
    if n and min_object_vox > 1:
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        small = sizes < min_object_vox
        small[0] = False
        if small.any():
            mask[small[labels]] = False
            n = int((~small[1:]).sum())
    del labels
    if fill_holes:
        bg_labels, nb = ndi.label(~mask)
        if nb > 1:
            border = np.zeros(nb + 1, dtype=bool)
            for ax in range(mask.ndim):
                for idx in (0, -1):
                    border[np.unique(np.take(bg_labels, idx, axis=ax))] = True
            hole = ~border
            hole[0] = False
            if hole.any():
                mask[hole[bg_labels]] = True
    return int(n)


#: Otsu's separability (between-class over total grey variance, Otsu 1979 eq. 12) below which a
#: volume split near its median has no fiber phase: a unimodal Gaussian histogram gives 2/pi = 0.64,
#: dense composite phantoms at CNR 2 give 0.78, the real polymer scaffold 0.72.
MIN_SEPARABILITY = 0.7
#: Only a split this balanced is judged by separability: a sparse fiber phase (a few % of the
#: voxels) has a low separability however clear its contrast.
_BALANCED_SPLIT = 0.3


def otsu_threshold(sample: np.ndarray) -> float:
    """Otsu's threshold of a grey sample, refused when the sample has no second phase: constant, or
    split near its median with a separability below :data:`MIN_SEPARABILITY` (noise or a
    homogeneous sample: no fiber phase to segment)."""
    if np.ptp(sample) == 0:
        raise InputError("segment: the volume is constant, nothing to threshold")
    t = float(threshold_otsu(sample))
    upper = sample > t
    share = float(np.count_nonzero(upper)) / sample.size
    if _BALANCED_SPLIT < share < 1.0 - _BALANCED_SPLIT:
        between = share * (1.0 - share) * (float(sample[upper].mean()) - float(sample[~upper].mean())) ** 2
        separability = between / float(sample.var())
        if separability < MIN_SEPARABILITY:
            raise InputError(f"segment: the volume has no fiber phase (Otsu's threshold explains {separability:.0%} "
                             f"of the grey variance, a single-phase histogram below {MIN_SEPARABILITY:.0%}): "
                             "check input.volume, or set segment.method: fixed with segment.threshold")
    return t


def segment(volume: np.ndarray, *, method: str = "otsu", threshold: float | None = None,
            smooth_sigma_vox: float = 1.0, min_object_vox: int = 64, fill_holes: bool = True,
            invert: bool = False):
    """Threshold a grey CT volume into a fiber mask.

    Parameters
    ----------
    volume : (Z, Y, X) ndarray, any real dtype
        Grey values; fibers brighter than the background (else pass ``invert=True``).
    method : {"otsu", "fixed"}
        Otsu's threshold on the smoothed volume, or the given ``threshold``.
    threshold : float, optional
        Grey level (same unit as ``volume``) for ``method="fixed"``.
    smooth_sigma_vox : float
        Gaussian denoising before thresholding, voxels (0: none). Computed in float32.
    min_object_vox : int
        Connected components (26-connectivity) with fewer voxels are removed.
    fill_holes : bool
        Fill background cavities not connected to the volume's border.
    invert : bool
        Fibers darker than the background.

    Returns
    -------
    mask : (Z, Y, X) bool ndarray
    info : dict
        ``threshold`` (grey level), ``volume_fraction`` (fiber voxels / all voxels),
        ``n_components`` (26-connected foreground components), ``method``.

    Raises
    ------
    InputError
        If the volume is not 3D, the method is unknown, a fixed threshold is missing, or the mask is
        empty or fills the whole volume.
    """
    if volume.ndim != 3:
        raise InputError(f"segment: expected a 3D volume, got shape {volume.shape}")
    if method not in ("otsu", "fixed"):
        raise InputError(f"segment: unknown method {method!r} (use 'otsu' or 'fixed')")
    if method == "fixed" and threshold is None:
        raise InputError("segment: method 'fixed' needs a threshold")
    # one float32 working copy; smoothing writes into it (no float64 volume)
    if smooth_sigma_vox and smooth_sigma_vox > 0:
        work = ndi.gaussian_filter(volume, smooth_sigma_vox, output=np.float32, mode="nearest")
    else:
        work = volume if volume.dtype.kind == "f" else volume.astype(np.float32)
    if method == "otsu":
        sample = _strided_sample(work, _OTSU_SAMPLE)
        sample = np.asarray(sample, dtype=np.float64).ravel()
        t = otsu_threshold(sample)
    else:
        t = float(threshold)
    mask = (work < t) if invert else (work > t)
    del work
    n = _remove_small_and_fill(mask, int(min_object_vox), fill_holes)
    n_fg = int(np.count_nonzero(mask))
    if n_fg == 0:
        raise InputError(f"segment: the mask is empty (threshold {t:.6g}); check the threshold or invert")
    if n_fg == mask.size:
        raise InputError(f"segment: the mask fills the whole volume (threshold {t:.6g}); check the threshold")
    info = {"method": method, "threshold": t, "volume_fraction": n_fg / mask.size, "n_components": n,
            "smooth_sigma_vox": float(smooth_sigma_vox), "min_object_vox": int(min_object_vox)}
    return mask, info
