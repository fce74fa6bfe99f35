"""Small straight-fiber geometry builders for contact tests and benchmarks (static poses)."""

import numpy as np

R = 0.25e-3
LE = 0.3e-3


def fiber(p0, direction, n, le=LE):
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return np.asarray(p0, float)[None, :] + np.arange(n + 1)[:, None] * le * d[None, :]


def assemble(*fibers, radius=R):
    """Stack polylines into nodes, segments, radius, fiber id; returns (x, seg, rad, fib, node_ranges)."""
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


def two_fiber_segments(n, le):
    """Segments, candidate pairs (every segment of fiber 0 with every one of fiber 1) and reference
    arc lengths of two fibers of ``n`` segments of length ``le`` each (nodes 0…n and n+1…2n+1)."""
    seg = np.array([[k, k + 1] for k in range(n)] + [[n + 1 + k, n + 2 + k] for k in range(n)], np.int64)
    pairs = np.array([[i, n + j] for i in range(n) for j in range(n)], np.int64)
    arc = np.zeros((2 * n, 2))
    for f in range(2):
        arc[f * n:(f + 1) * n, 0] = np.arange(n) * le
        arc[f * n:(f + 1) * n, 1] = (np.arange(n) + 1) * le
    return seg, pairs, arc


def pot_energy_forces(x, seg, pairs, arc, law, ds=0.0, n_gauss=2, radius=None):
    """``(energy [J], forces (N, 3) [N], pairs in contact)`` of the potential formulation's kernel
    on every candidate pair (onset ``ds`` [m], no initial-overlap offsets)."""
    from fiberpipe.solver.contact_pairs import gauss_points
    from fiberpipe.solver.contact_potential import contact_forces_pot
    from fiberpipe.solver.contact_state import new_records

    P = pairs.shape[0]
    gxi, gw = gauss_points(n_gauss)
    f = np.zeros_like(x)
    radius = np.full(seg.shape[0], R) if radius is None else radius
    e, n_act = contact_forces_pot(x, seg, radius, arc, pairs, P, law.law_id, law.params(), gxi, gw, ds, f,
                                  new_records(P), np.zeros(0), 0.0)
    return e, f, n_act


def contact_pass(x, seg, rad, pairs, n_pairs, law, f_out, n_gauss=4):
    """``(energy [J], pairs in contact, records)`` of the contact pass on the first ``n_pairs``
    candidate pairs, forces added into ``f_out``; each segment's reference length is its length at
    ``x`` (no onset, no initial-overlap offsets)."""
    from fiberpipe.solver.contact_pairs import gauss_points
    from fiberpipe.solver.contact_potential import potential_kernels_for
    from fiberpipe.solver.contact_state import new_records

    x = np.ascontiguousarray(x, dtype=np.float64)
    seg = np.ascontiguousarray(seg, dtype=np.int64)
    arc = np.zeros((seg.shape[0], 2))
    arc[:, 1] = np.linalg.norm(x[seg[:, 1]] - x[seg[:, 0]], axis=1)
    gxi, gw = gauss_points(n_gauss)
    records = new_records(max(int(n_pairs), 1))
    e, n_act = potential_kernels_for(law)(x, seg, np.ascontiguousarray(rad, dtype=np.float64), arc,
                                          np.ascontiguousarray(pairs, dtype=np.int64), int(n_pairs), law.law_id,
                                          law.params(), gxi, gw, 0.0, f_out, records, np.zeros(0), 0.0)
    return e, n_act, records
