"""What the fiber–fiber contact pass shares with its callers: the line part's Gauss points and a
segment pair's records.

* :func:`gauss_points`: Gauss–Legendre nodes on (0, 1) and weights summing to 1, fixed on each
  segment by :func:`fiberpipe.solver.contact_potential.contact_forces_pot`'s line part
  (``scene.contact.gauss_points`` per segment).
* :func:`record_pair`: a pair's records (:class:`~fiberpipe.solver.contact_state.PairRecords`) from
  the accumulator the contact pass fills while it applies the pair's contact points
  (:func:`fiberpipe.solver.geometry.apply_line_point`).
"""

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
    """Pair ``k``'s records in ``out`` (:class:`~fiberpipe.solver.contact_state.PairRecords`) from its
    accumulator ``rec`` (Σ|f| [N], Σf from B to A (3) [N], Σ|f|·s, Σ|f|·t, max δ [m], contact share)
    and its crossing angle ``phi`` [rad]: the resultant normal force and its direction, the
    force-weighted contact parameters, the largest penetration; with ``use_list`` the pair's index
    appended to ``out.active``, with ``use_share`` its share and Σ|f|. Returns the count of pairs in
    contact (``n_active``, plus one if this one carries a force)."""
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
