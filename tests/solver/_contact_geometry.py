"""Small straight-fibre geometry builders for contact tests and benchmarks (static poses)."""

import numpy as np

R = 0.25e-3
LE = 0.3e-3


def fiber(p0, direction, n, le=LE):
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return np.asarray(p0, float)[None, :] + np.arange(n + 1)[:, None] * le * d[None, :]


def assemble(*fibers, radius=R):
    """Stack polylines into nodes, segments, radius, fibre id; returns (x, seg, rad, fib, node_ranges)."""
    xs, segs, fib, ranges = [], [], [], []
    off = 0
    for k, xf in enumerate(fibers):
        n = len(xf)
        xs.append(xf)
        segs += [[off + i, off + i + 1] for i in range(n - 1)]
        fib += [k] * (n - 1)
        ranges.append((off, off + n))
        off += n
    seg = np.array(segs, np.int64)
    return np.vstack(xs), seg, np.full(len(seg), radius), np.array(fib, np.int64), ranges


def all_pairs_between(fib, a, b):
    ia = np.flatnonzero(fib == a)
    ib = np.flatnonzero(fib == b)
    return np.array([[i, j] for i in ia for j in ib], np.int64)


def central_gradient(energy, x, h):
    """∂energy/∂x by central differences of step ``h`` [m] in every coordinate of ``x`` (N, 3)."""
    g = np.zeros_like(x)
    for i in range(x.shape[0]):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, c] += h
            xm[i, c] -= h
            g[i, c] = (energy(xp) - energy(xm)) / (2 * h)
    return g
