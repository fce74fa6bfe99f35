"""Segment geometry shared by the contact, friction and neighbour-list kernels (a leaf module).

Straight two-node segments: the clamped closest distance of two segments (Ericson, *Real-Time
Collision Detection*, 2005, §5.1.9), the crossing angle of their lines, and the nodes and gap of a
candidate pair.
"""

from __future__ import annotations

import math

from numba import njit

# sin²(15°): below it the crossing angle comes from sin²Φ = |t_A × t_B|²/(|t_A|²|t_B|²) and the
# series of asin(y)/y (asin_tail, 11 terms: relative error < 1e-13), above it from acos(|cos Φ|)
_S2_SERIES = math.sin(math.radians(15.0)) ** 2


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def asin_tail(s2):
    """(asin(y)/y − 1)/y² = Σ_{n≥1} c_n y^{2(n−1)} at s2 = y², c_n = (2n)!/(4ⁿ (n!)² (2n+1)): eleven
    terms, the first omitted one below 7e-14 of the sum at y² = 0.1 (Horner, written out: a loop over
    the coefficients would keep a caller's loop from vectorising)."""
    t = 88179.0 / 12058624.0
    t = t * s2 + 46189.0 / 5505024.0
    t = t * s2 + 12155.0 / 1245184.0
    t = t * s2 + 6435.0 / 557056.0
    t = t * s2 + 143.0 / 10240.0
    t = t * s2 + 231.0 / 13312.0
    t = t * s2 + 63.0 / 2816.0
    t = t * s2 + 35.0 / 1152.0
    t = t * s2 + 5.0 / 112.0
    t = t * s2 + 3.0 / 40.0
    return t * s2 + 1.0 / 6.0


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def crossing_angle(ta0, ta1, ta2, tb0, tb1, tb2, aa, bb, ab):
    """Angle Φ ∈ [0, π/2] [rad] between the lines of two segments (tangents ``ta``, ``tb``; ``aa``,
    ``bb``, ``ab`` their dot products).

    Contacts of quasi-parallel fibers cross at a few degrees: there Φ = y·asin(y)/y with
    y = sin Φ from the cross product (one square root and a polynomial: Σ cₙ y²ⁿ, cₙ = (2n)!/(4ⁿ(n!)²(2n+1)))
    instead of ``acos`` — cheaper, and more accurate at small angles, where acos(|cos Φ|) loses
    half of the digits of Φ (cos Φ = 1 − Φ²/2).
    """
    c0 = ta1 * tb2 - ta2 * tb1
    c1 = ta2 * tb0 - ta0 * tb2
    c2 = ta0 * tb1 - ta1 * tb0
    s2 = (c0 * c0 + c1 * c1 + c2 * c2) / (aa * bb)
    if s2 < _S2_SERIES:
        return math.sqrt(s2) * (1.0 + s2 * asin_tail(s2))
    cphi = abs(ab) / math.sqrt(aa * bb)
    if cphi > 1.0:
        cphi = 1.0
    return math.acos(cphi)



@njit(cache=True, fastmath=True, error_model="numpy")
def segment_distance2(a0, a1, b0, b1, ta, tb):
    """Squared closest distance between segments [a0,a1] and [b0,b1] (clamped), and (s, t)."""
    return segment_distance2_s(a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2], ta[0], ta[1], ta[2], tb[0], tb[1], tb[2])


@njit(cache=True, fastmath=True, error_model="numpy")
def segment_distance2_s(r0, r1, r2, ta0, ta1, ta2, tb0, tb1, tb2):
    """:func:`segment_distance2` on scalars: r = a0 − b0, ta = a1 − a0, tb = b1 − b0."""
    aa = ta0 * ta0 + ta1 * ta1 + ta2 * ta2
    bb = tb0 * tb0 + tb1 * tb1 + tb2 * tb2
    ab = ta0 * tb0 + ta1 * tb1 + ta2 * tb2
    ar = ta0 * r0 + ta1 * r1 + ta2 * r2
    br = tb0 * r0 + tb1 * r1 + tb2 * r2
    den = aa * bb - ab * ab
    if den > 1e-12 * aa * bb:
        s = (ab * br - ar * bb) / den
        s = min(max(s, 0.0), 1.0)
    else:
        s = 0.0
    t = (ab * s + br) / bb
    if t < 0.0:
        t = 0.0
        s = min(max(-ar / aa, 0.0), 1.0)
    elif t > 1.0:
        t = 1.0
        s = min(max((ab - ar) / aa, 0.0), 1.0)
    d0 = r0 + s * ta0 - t * tb0
    d1 = r1 + s * ta1 - t * tb1
    d2 = r2 + s * ta2 - t * tb2
    return d0 * d0 + d1 * d1 + d2 * d2, s, t



@njit(cache=True, inline="always")
def pair_nodes(pairs, seg_nodes, k):
    """Segments ``(i, j)`` of candidate pair ``k`` and their node indices ``(a0, a1, b0, b1)``."""
    i = pairs[k, 0]
    j = pairs[k, 1]
    return i, j, seg_nodes[i, 0], seg_nodes[i, 1], seg_nodes[j, 0], seg_nodes[j, 1]



@njit(cache=True, fastmath=True, error_model="numpy")
def pair_gap(x, seg_nodes, seg_radius, pairs, k):
    """Gap [m] of candidate pair ``k``: clamped segment–segment centre-line distance − r_i − r_j."""
    i, j, a0, a1, b0, b1 = pair_nodes(pairs, seg_nodes, k)
    d2, s, t = segment_distance2_s(x[a0, 0] - x[b0, 0], x[a0, 1] - x[b0, 1], x[a0, 2] - x[b0, 2],
                                    x[a1, 0] - x[a0, 0], x[a1, 1] - x[a0, 1], x[a1, 2] - x[a0, 2],
                                    x[b1, 0] - x[b0, 0], x[b1, 1] - x[b0, 1], x[b1, 2] - x[b0, 2])
    return math.sqrt(d2) - seg_radius[i] - seg_radius[j]


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def line_closest_params(a0, b0, ta, tb, aa, bb, ab, den):
    """Parameters (s, t) of the closest points of the infinite lines a0 + s·ta and b0 + t·tb
    (``aa, bb, ab`` their dot products, ``den = aa bb − ab² > 0``)."""
    r0 = a0[0] - b0[0]
    r1 = a0[1] - b0[1]
    r2 = a0[2] - b0[2]
    ar = ta[0] * r0 + ta[1] * r1 + ta[2] * r2
    br = tb[0] * r0 + tb[1] * r1 + tb[2] * r2
    return (ab * br - ar * bb) / den, (aa * br - ab * ar) / den


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def apply_pair_force(f_out, nodes4, s, t, f0, f1, f2):
    """+f on segment A at parameter s, −f on segment B at t, linearly shared by each segment's nodes."""
    na0, na1, nb0, nb1 = nodes4
    f_out[na0, 0] += (1.0 - s) * f0
    f_out[na0, 1] += (1.0 - s) * f1
    f_out[na0, 2] += (1.0 - s) * f2
    f_out[na1, 0] += s * f0
    f_out[na1, 1] += s * f1
    f_out[na1, 2] += s * f2
    f_out[nb0, 0] -= (1.0 - t) * f0
    f_out[nb0, 1] -= (1.0 - t) * f1
    f_out[nb0, 2] -= (1.0 - t) * f2
    f_out[nb1, 0] -= t * f0
    f_out[nb1, 1] -= t * f1
    f_out[nb1, 2] -= t * f2


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def apply_pair_force_owned(f_out, nodes4, s, t, f0, f1, f2, owned):
    """:func:`apply_pair_force` onto those of the four nodes in ``owned = (lo, hi)`` only, with the
    same expression per node (the tasks of a scatter split by nodes add what one task adds)."""
    na0, na1, nb0, nb1 = nodes4
    lo, hi = owned
    if lo <= na0 < hi:
        f_out[na0, 0] += (1.0 - s) * f0
        f_out[na0, 1] += (1.0 - s) * f1
        f_out[na0, 2] += (1.0 - s) * f2
    if lo <= na1 < hi:
        f_out[na1, 0] += s * f0
        f_out[na1, 1] += s * f1
        f_out[na1, 2] += s * f2
    if lo <= nb0 < hi:
        f_out[nb0, 0] -= (1.0 - t) * f0
        f_out[nb0, 1] -= (1.0 - t) * f1
        f_out[nb0, 2] -= (1.0 - t) * f2
    if lo <= nb1 < hi:
        f_out[nb1, 0] -= t * f0
        f_out[nb1, 1] -= t * f1
        f_out[nb1, 2] -= t * f2


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def apply_line_point(f_out, nodes4, s, t, f0, f1, f2, fm, delta, rec, sign):
    """One contact point of a pair (a Gauss point of a line part, or the point part's closest
    points): the force (f0, f1, f2) of magnitude ``fm`` as :func:`apply_pair_force`, and its share
    of the pair's accumulator ``rec`` (Σ|f|, Σf from B to A, Σ|f|·s_first, Σ|f|·t_second, max δ;
    ``sign`` −1 when A is the pair's second segment)."""
    apply_pair_force(f_out, nodes4, s, t, f0, f1, f2)
    rec[0] += fm
    rec[1] += sign * f0
    rec[2] += sign * f1
    rec[3] += sign * f2
    if sign > 0.0:
        rec[4] += fm * s
        rec[5] += fm * t
    else:
        rec[4] += fm * t
        rec[5] += fm * s
    if delta > rec[6]:
        rec[6] = delta
