"""What both contact passes share: Gauss points of the line part, the per-pair records and the
per-pair output buffers of the Python-side evaluation."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Gauss–Legendre nodes on [0, 1] and weights (sum 1), orders 1…6
_GL = {
    n: ((np.polynomial.legendre.leggauss(n)[0] + 1.0) / 2.0, np.polynomial.legendre.leggauss(n)[1] / 2.0)
    for n in range(1, 7)
}


def gauss_points(n: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes ξ ∈ (0, 1) and weights (summing to 1) of order ``n`` (1…6)."""
    if n not in _GL:
        raise ValueError(f"Gauss order must be 1…6, got {n}")
    xi, w = _GL[n]
    return xi.copy(), w.copy()



@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def record_pair(out, k, rec, phi, n_active, use_list, use_share):
    """The pair's records in ``out`` (:class:`~fiberpipe.solver.contact_state.PairRecords`) from its
    accumulator ``rec`` (Σ|f|, Σf, Σ|f|·s, Σ|f|·t, max δ, share); returns the count of pairs in contact."""
    fsum = rec[0]
    if not fsum > 0.0:
        return n_active
    if use_list:
        out.active[n_active] = k
    fv = math.sqrt(rec[1] * rec[1] + rec[2] * rec[2] + rec[3] * rec[3])
    out.fn[k] = fv
    if fv > 0.0:
        out.normal[k, 0] = rec[1] / fv
        out.normal[k, 1] = rec[2] / fv
        out.normal[k, 2] = rec[3] / fv
    out.s[k] = rec[4] / fsum
    out.t[k] = rec[5] / fsum
    out.phi[k] = phi
    out.delta[k] = rec[6]
    if use_share:
        out.share[k] = rec[7]
        out.fsum[k] = fsum
    return n_active + 1


class ContactBuffers:
    """Per-pair output arrays for :func:`contact_forces`, grown with the neighbour list capacity."""

    def __init__(self, capacity: int):
        self.resize(capacity)

    def resize(self, capacity: int):
        capacity = max(int(capacity), 1)
        self.capacity = capacity
        self.fn = np.zeros(capacity)
        self.n = np.zeros((capacity, 3))
        self.s = np.zeros(capacity)
        self.t = np.zeros(capacity)
        self.phi = np.zeros(capacity)
        self.delta = np.zeros(capacity)

    def ensure(self, capacity: int):
        if capacity > self.capacity:
            self.resize(int(capacity * 1.5) + 16)
