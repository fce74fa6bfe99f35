"""Small helpers shared by the imaging modules."""

from __future__ import annotations

import numpy as np


def voxel_size_zyx(voxel_size_m) -> np.ndarray:
    """Voxel size as a (3,) float64 array (dz, dy, dx), m, from a scalar or a 3-sequence.

    Raises ``ValueError`` if a value is not finite and positive.
    """
    v = np.asarray(voxel_size_m, dtype=np.float64).reshape(-1)
    if v.size == 1:
        v = np.repeat(v, 3)
    if v.size != 3 or not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise ValueError(f"voxel size must be a positive scalar or (dz, dy, dx), got {voxel_size_m!r}")
    return v


def voxel_to_xyz_m(zyx_vox: np.ndarray, voxel_size_m) -> np.ndarray:
    """Voxel index coordinates (N, 3) ordered z y x -> points (N, 3) ordered x y z, m."""
    v = voxel_size_zyx(voxel_size_m)
    zyx = np.asarray(zyx_vox, dtype=np.float64).reshape(-1, 3)
    return (zyx * v)[:, ::-1].copy()


def xyz_m_to_voxel(xyz_m: np.ndarray, voxel_size_m) -> np.ndarray:
    """Points (N, 3) x y z in m -> voxel index coordinates (N, 3) ordered z y x."""
    v = voxel_size_zyx(voxel_size_m)
    xyz = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
    return xyz[:, ::-1] / v


def resample_polyline(p: np.ndarray, spacing: float) -> np.ndarray:
    """Resample a polyline (n, d) at a constant arc-length ``spacing`` (same unit), ends kept
    (:func:`fiberpipe.polylines.resample_arclength`)."""
    from fiberpipe.polylines import resample_arclength

    return resample_arclength(p, spacing)


def smooth_polyline(p: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian-smooth a polyline (n, d) along its index, keeping straight ends unbiased.

    Strategy: pad each end by a point reflection (2 p0 - p[k]) before filtering, so a straight or
    uniformly tilted run stays exactly where it is up to the ends (plain 'nearest' padding would pull
    the ends of a tilted fiber back toward the vertical).
    """
    from scipy.ndimage import gaussian_filter1d

    p = np.asarray(p, dtype=np.float64)
    n = len(p)
    if sigma <= 0 or n < 3:
        return p.copy()
    m = min(n - 1, int(np.ceil(4 * sigma)))
    head = 2 * p[0] - p[m:0:-1]
    tail = 2 * p[-1] - p[-2 : -m - 2 : -1]
    q = np.concatenate([head, p, tail])
    q = gaussian_filter1d(q, sigma, axis=0, mode="nearest")
    return q[m : m + n]
