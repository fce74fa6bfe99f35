"""Small numba kernels for the imaging stages (pure array functions, no Python objects)."""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import _vectorise  # noqa: F401  (before any kernel compiles: the vector width)


@njit(cache=True)
def render_segments_max(out, starts, ends, radius, shape_zyx):
    """Rasterise capsules (segments with a radius) into ``out`` with a soft edge.

    Parameters
    ----------
    out : (Z, Y, X) float32 ndarray
        Occupancy in [0, 1], updated in place with ``max(out, occupancy)``.
    starts, ends : (S, 3) float64 ndarray, voxel units, order z y x
        Segment end points (voxel centres are at integer coordinates).
    radius : (S,) float64 ndarray, voxel units
        Capsule radius of each segment.
    shape_zyx : (3,) int64 ndarray
        Shape of ``out``.

    Notes
    -----
    Occupancy is ``clip(r + 0.5 - d, 0, 1)`` with ``d`` the distance from the voxel centre to the
    segment: a linear ramp one voxel wide, which is what a box-filtered (partial-volume) edge of a
    large cylinder looks like to first order. Only each segment's bounding box is visited, so the
    cost is proportional to the fibers' volume, not to the volume size.
    """
    nz, ny, nx = shape_zyx[0], shape_zyx[1], shape_zyx[2]
    for s in range(starts.shape[0]):
        r = radius[s]
        a0, a1, a2 = starts[s, 0], starts[s, 1], starts[s, 2]
        b0, b1, b2 = ends[s, 0], ends[s, 1], ends[s, 2]
        d0, d1, d2 = b0 - a0, b1 - a1, b2 - a2
        L2 = d0 * d0 + d1 * d1 + d2 * d2
        pad = r + 1.0
        z0 = max(0, int(np.floor(min(a0, b0) - pad)))
        z1 = min(nz - 1, int(np.ceil(max(a0, b0) + pad)))
        y0 = max(0, int(np.floor(min(a1, b1) - pad)))
        y1 = min(ny - 1, int(np.ceil(max(a1, b1) + pad)))
        x0 = max(0, int(np.floor(min(a2, b2) - pad)))
        x1 = min(nx - 1, int(np.ceil(max(a2, b2) + pad)))
        for k in range(z0, z1 + 1):
            for j in range(y0, y1 + 1):
                for i in range(x0, x1 + 1):
                    p0, p1, p2 = k - a0, j - a1, i - a2
                    t = 0.0
                    if L2 > 0.0:
                        t = (p0 * d0 + p1 * d1 + p2 * d2) / L2
                        if t < 0.0:
                            t = 0.0
                        elif t > 1.0:
                            t = 1.0
                    q0, q1, q2 = p0 - t * d0, p1 - t * d1, p2 - t * d2
                    dist = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
                    occ = r + 0.5 - dist
                    if occ > 0.0:
                        if occ > 1.0:
                            occ = 1.0
                        if occ > out[k, j, i]:
                            out[k, j, i] = occ


@njit(cache=True)
def voronoi_centroids(weights, sites, nb, R, hw, sy, sx):
    """One step of the local-Voronoi centroid refinement (``trace._refine_centroids``).

    Parameters
    ----------
    weights : (H, W) float32 ndarray
        Pixel weights (1/0 for a mask, grey in [0, 1]).
    sites : (n, 2) float64 ndarray
        Current centres, pixel indices (row, col).
    nb : (n, k) int64 ndarray
        Each site's k nearest sites, itself first (column 0 is skipped).
    R : float
        Window radius (relative pixel units); hw: half-width of the pixel window.
    sy, sx : float
        Relative pixel sizes along rows and columns.

    Returns
    -------
    (n, 2) float64 ndarray: the weighted centroid of each site's pixels within R that are nearer
    to it than to any of its neighbours (the site itself where it has none).
    """
    H, W = weights.shape
    n = sites.shape[0]
    out = sites.copy()
    R2 = R * R
    for i in range(n):
        cy = int(np.rint(sites[i, 0]))
        cx = int(np.rint(sites[i, 1]))
        sw = 0.0
        syy = 0.0
        sxx = 0.0
        for yy in range(cy - hw, cy + hw + 1):
            if yy < 0 or yy >= H:
                continue
            for xx in range(cx - hw, cx + hw + 1):
                if xx < 0 or xx >= W:
                    continue
                v = weights[yy, xx]
                if v == 0.0:
                    continue
                fy = (yy - sites[i, 0]) * sy
                fx = (xx - sites[i, 1]) * sx
                d0 = fy * fy + fx * fx
                if d0 > R2:
                    continue
                ok = True
                for jj in range(1, nb.shape[1]):
                    s = nb[i, jj]
                    gy = (yy - sites[s, 0]) * sy
                    gx = (xx - sites[s, 1]) * sx
                    if gy * gy + gx * gx < d0:
                        ok = False
                        break
                if ok:
                    sw += v
                    syy += v * yy
                    sxx += v * xx
        if sw > 0.0:
            out[i, 0] = syy / sw
            out[i, 1] = sxx / sw
    return out
