"""Small numba kernels for the imaging stages (pure array functions, no Python objects)."""

from __future__ import annotations

import math

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


@njit(cache=True)
def fit_disk_centres(img, centres, amplitude, radius, sigma, samp_y, samp_x, n_iter, fit_amplitude):
    """Least-squares centres and amplitudes of blurred disks in a grey slice, all fitted together.

    The slice is modelled as ``sum_k a_k T(|x - c_k|)`` with the blurred-disk template
    ``T(rho) = erfc((rho - radius) / (sqrt(2) sigma)) / 2`` (a disk of ``radius`` convolved with a
    Gaussian of ``sigma``, to first order in sigma / radius). Each iteration renders the model of
    all disks, then moves every disk by its own Gauss-Newton step on the common residual (block
    Jacobi: a neighbour's overlap is in the model, so touching disks do not pull each other's
    centres), a step of at most half a pixel.

    Parameters
    ----------
    img : (H, W) float32 ndarray, background 0, fiber 1
    centres : (n, 2) float64 ndarray, pixel indices (row, col), start values
    amplitude : (n,) float64 ndarray, start values
    radius, sigma : float, units of the smallest pixel size
    samp_y, samp_x : float, pixel sizes relative to the smallest
    n_iter : int
    fit_amplitude : bool
        Fit each disk's amplitude too (else kept at its start value).

    Returns
    -------
    centres : (n, 2) float64 ndarray, amplitude : (n,) float64 ndarray, and the sum of squared
    residuals of the last iteration's model (float)
    """
    H, W = img.shape
    n = centres.shape[0]
    c = centres.copy()
    a = amplitude.copy()
    hy = int(np.ceil((radius + 3.0 * sigma) / samp_y)) + 1
    hx = int(np.ceil((radius + 3.0 * sigma) / samp_x)) + 1
    s2 = np.sqrt(2.0) * sigma
    norm = 1.0 / (np.sqrt(2.0 * np.pi) * sigma)
    model = np.zeros((H, W), dtype=np.float64)
    ssr = 0.0
    for _ in range(n_iter):
        model[:, :] = 0.0
        for k in range(n):
            y0 = int(np.floor(c[k, 0]))
            x0 = int(np.floor(c[k, 1]))
            for y in range(max(0, y0 - hy), min(H, y0 + hy + 2)):
                dy = (y - c[k, 0]) * samp_y
                for x in range(max(0, x0 - hx), min(W, x0 + hx + 2)):
                    dx = (x - c[k, 1]) * samp_x
                    rho = np.sqrt(dy * dy + dx * dx)
                    model[y, x] += a[k] * 0.5 * math.erfc((rho - radius) / s2)
        ssr = 0.0
        for y in range(H):
            for x in range(W):
                e = img[y, x] - model[y, x]
                ssr += e * e
        step = np.zeros((n, 3))
        for k in range(n):
            y0 = int(np.floor(c[k, 0]))
            x0 = int(np.floor(c[k, 1]))
            A = np.zeros((3, 3))
            b = np.zeros(3)
            for y in range(max(0, y0 - hy), min(H, y0 + hy + 2)):
                dy = (y - c[k, 0]) * samp_y
                for x in range(max(0, x0 - hx), min(W, x0 + hx + 2)):
                    dx = (x - c[k, 1]) * samp_x
                    rho = np.sqrt(dy * dy + dx * dx)
                    u = (rho - radius) / s2
                    t = 0.5 * math.erfc(u)
                    dt = -norm * np.exp(-u * u)
                    jy = 0.0
                    jx = 0.0
                    if rho > 1e-9:
                        jy = -a[k] * dt * dy * samp_y / rho
                        jx = -a[k] * dt * dx * samp_x / rho
                    j = (jy, jx, t)
                    res = img[y, x] - model[y, x]
                    for p in range(3):
                        b[p] += j[p] * res
                        for q in range(3):
                            A[p, q] += j[p] * j[q]
            for p in range(3):
                A[p, p] *= 1.05  # Levenberg-Marquardt damping
                A[p, p] += 1e-9
            if fit_amplitude:
                step[k] = np.linalg.solve(A, b)
            else:
                step[k, :2] = np.linalg.solve(A[:2, :2], b[:2])
        for k in range(n):
            for p in range(2):
                s = step[k, p]
                c[k, p] += min(0.5, max(-0.5, s))
            a[k] = min(3.0, max(0.2, a[k] + step[k, 2]))
    return c, a, ssr


@njit(cache=True)
def render_disks(shape_hw, centres, radius, sigma, samp_y, samp_x):
    """The blurred-disk model of :func:`fit_disk_centres` (unit amplitude) as an image:
    ``sum_k T(|x - c_k|)``, ``T(rho) = erfc((rho - radius) / (sqrt(2) sigma)) / 2``.

    Parameters
    ----------
    shape_hw : (2,) int64 ndarray, the image's shape
    centres : (n, 2) float64 ndarray, pixel indices (row, col)
    radius, sigma : float, units of the smallest pixel size
    samp_y, samp_x : float, pixel sizes relative to the smallest

    Returns
    -------
    (H, W) float64 ndarray
    """
    H, W = shape_hw[0], shape_hw[1]
    model = np.zeros((H, W), dtype=np.float64)
    hy = int(np.ceil((radius + 3.0 * sigma) / samp_y)) + 1
    hx = int(np.ceil((radius + 3.0 * sigma) / samp_x)) + 1
    s2 = np.sqrt(2.0) * sigma
    for k in range(centres.shape[0]):
        y0 = int(np.floor(centres[k, 0]))
        x0 = int(np.floor(centres[k, 1]))
        for y in range(max(0, y0 - hy), min(H, y0 + hy + 2)):
            dy = (y - centres[k, 0]) * samp_y
            for x in range(max(0, x0 - hx), min(W, x0 + hx + 2)):
                dx = (x - centres[k, 1]) * samp_x
                model[y, x] += 0.5 * math.erfc((np.sqrt(dy * dy + dx * dx) - radius) / s2)
    return model
