"""Fiber–fiber contact kinematics: line-to-line (Gauss point) plus closest-point contact, blended in Φ.

Penetration ``δ = r_i + r_j − d``, ``d`` the centre-line distance. For each candidate segment pair
(A = segment i, B = segment j, straight 2-node segments):

1. **Reject** if the segments' closest distance (Ericson, *Real-Time Collision Detection* §5.1.9)
   is ≥ r_i + r_j: no part can touch. This is the common path of a Verlet candidate.
2. **Orientation** ``Φ = acos(|t_A·t_B|)`` in [0, π/2]; the law's point share ``w(δ_c, Φ)``
   (:func:`fiberpipe.solver.laws.law_weight`).
3. **Point part** (weight w; crossing fibers): closest points of the two infinite lines,
   parameters (s*, t*); it belongs to this pair with weight win(s*)·win(t*), win = 1 on
   (ε, 1 − ε) and linear ramps over [−ε, ε] at both ends (ε = 1e-6), a partition of unity over
   collinear neighbours, so a contact crossing an element joint is counted exactly once whatever the
   rounding, and moves continuously from one pair to the next. Force ``F = law_point(δ_c, Φ)``
   along the line joining the points.
4. **Line part** (weight 1 − w; near-parallel fibers; Meier, Popp & Wall, CMAME 308, 2016,
   Gauss-point-to-segment with integration-interval segmentation): Gauss points on A projected
   orthogonally onto the *line* of B. The projection ``t(s) = t0 + s t1`` is affine, so the
   sub-interval of A that projects into B's [0, 1] and whose distance to B's line is below
   r_i + r_j (a quadratic in s) is found exactly and the Gauss points are placed in it only
   (no integration error from the contact ends, none from element joints). Each Gauss point
   carries the line load ``p(δ(s))`` [N/m] × its weight × L_A. Done both ways (A onto B and B onto
   A) with half weight each, so the formulation is symmetric.

Every force is applied as +f on one segment and −f on the other, both linearly interpolated to the
segment's two nodes by the contact point's parameter, so Σf = 0 exactly (linear momentum conserved).

Per-pair records (for friction and output): total normal force ``c_fn`` [N], unit normal ``c_n``
(direction of the resultant, from B to A), force-weighted contact parameters ``c_s``, ``c_t``,
orientation ``c_phi`` [rad] and the largest penetration ``c_delta`` [m]. Pairs not in contact get
``c_fn = 0``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .geometry import apply_line_point, crossing_angle, line_closest_params, segment_distance2_s
from ._specialise import specialise
from .contact_pairs import ContactBuffers, gauss_points, record_pair  # noqa: F401  (shared with the potential formulation)
from .contact_state import PairRecords
from .laws import law_line, law_point, law_weight_point

JOINT_EPS = 1e-6



@njit(cache=True, fastmath=True, error_model="numpy")
def _window(s):
    """1 inside (ε, 1 − ε), linear ramps to 0 at −ε and 1 + ε; win(s) + win(s − 1) = 1 near s = 1."""
    if s <= -JOINT_EPS or s >= 1.0 + JOINT_EPS:
        return 0.0
    lo = (s + JOINT_EPS) / (2.0 * JOINT_EPS)
    hi = (1.0 + JOINT_EPS - s) / (2.0 * JOINT_EPS)
    return min(lo, hi, 1.0)


@njit(cache=True, fastmath=True, error_model="numpy")
def _joint_share(x, seg_nodes, e, s, d_own, o0, to, rr):
    """Share of the point contact owned by segment ``e`` (against the other segment, from node
    position ``o0`` along ``to``).

    The neighbouring segment of the same fiber at the end nearer to the line closest parameter
    ``s`` competes for the contact: the segment whose clamped segment–segment distance is smaller
    owns it, with a linear ramp over ``1e-9 (r_i + r_j)`` so that the two shares sum to 1 exactly
    (both pairs evaluate the same two distances with the same arguments) and equal distances give
    ½ each: a crossing exactly on a straight joint, or on a kinked joint (convex: both line
    closest points fall outside the segments; concave: both inside), is counted once. A fiber's
    free end has no competitor: the end segment always owns its clamped closest point, i.e. the
    hemispherical end cap is a contact surface. (Owning it only while the line closest point was
    inside the segment made the force appear or vanish at full penetration when that point crossed
    the end; in undamped bundles this pumped energy until they diverged:
    tests/solver/test_contact_ends.py.)
    """
    E = seg_nodes.shape[0]
    if s > 0.5:
        nj = seg_nodes[e, 1]
        if e + 1 >= E or seg_nodes[e + 1, 0] != nj:
            return 1.0
        n0 = nj
        n1 = seg_nodes[e + 1, 1]
    else:
        nj = seg_nodes[e, 0]
        if e - 1 < 0 or seg_nodes[e - 1, 1] != nj:
            return 1.0
        n0 = seg_nodes[e - 1, 0]
        n1 = nj
    c0x = x[n0, 0]
    c0y = x[n0, 1]
    c0z = x[n0, 2]
    d2, sn, tn = segment_distance2_s(c0x - o0[0], c0y - o0[1], c0z - o0[2],
                                      x[n1, 0] - c0x, x[n1, 1] - c0y, x[n1, 2] - c0z, to[0], to[1], to[2])
    tol = 1e-9 * rr
    wgt = 0.5 + (math.sqrt(d2) - d_own) / (2.0 * tol)
    return min(max(wgt, 0.0), 1.0)


@njit(cache=True, fastmath=True, error_model="numpy")
def _line_half(
    x, na0, na1, nb0, nb1, ra, rb, law_id, law_params, gxi, gw, scale, f_out, rec, sign, off=0.0
):
    """Gauss points on segment A projected on segment B's line, weight ``scale``; accumulates forces.

    rec[0..7] accumulates (Σ|f|, Σf_vec(3) B→A, Σ|f|·s_A, Σ|f|·t_B, max δ, contact share);
    ``sign`` = +1 if A is the pair's first segment, −1 if swapped (so the record stays oriented
    first→second). ``off`` [m]: initial-overlap offset subtracted from δ (0: none).
    Returns the stored energy.
    """
    ta0 = x[na1, 0] - x[na0, 0]
    ta1 = x[na1, 1] - x[na0, 1]
    ta2 = x[na1, 2] - x[na0, 2]
    tb0 = x[nb1, 0] - x[nb0, 0]
    tb1 = x[nb1, 1] - x[nb0, 1]
    tb2 = x[nb1, 2] - x[nb0, 2]
    la2 = ta0 * ta0 + ta1 * ta1 + ta2 * ta2
    lb2 = tb0 * tb0 + tb1 * tb1 + tb2 * tb2
    la = math.sqrt(la2)
    r0 = x[na0, 0] - x[nb0, 0]
    r1 = x[na0, 1] - x[nb0, 1]
    r2 = x[na0, 2] - x[nb0, 2]
    # t(s) = t0 + s t1
    t0 = (r0 * tb0 + r1 * tb1 + r2 * tb2) / lb2
    t1 = (ta0 * tb0 + ta1 * tb1 + ta2 * tb2) / lb2
    # s-interval where 0 <= t <= 1
    s_lo = 0.0
    s_hi = 1.0
    if abs(t1) < 1e-14:
        if t0 < 0.0 or t0 >= 1.0:
            return 0.0
    else:
        u0 = -t0 / t1
        u1 = (1.0 - t0) / t1
        if u0 > u1:
            u0, u1 = u1, u0
        s_lo = max(s_lo, u0)
        s_hi = min(s_hi, u1)
        if s_hi <= s_lo:
            return 0.0
    # distance vector to B's line: c0 + s c1; restrict to |c| < ra + rb
    c00 = r0 - t0 * tb0
    c01 = r1 - t0 * tb1
    c02 = r2 - t0 * tb2
    c10 = ta0 - t1 * tb0
    c11 = ta1 - t1 * tb1
    c12 = ta2 - t1 * tb2
    rr = ra + rb
    qa = c10 * c10 + c11 * c11 + c12 * c12
    qb = c00 * c10 + c01 * c11 + c02 * c12
    qc = c00 * c00 + c01 * c01 + c02 * c02 - rr * rr
    if qa > 1e-14 * la2:
        disc = qb * qb - qa * qc
        if disc <= 0.0:
            return 0.0
        sq = math.sqrt(disc)
        v0 = (-qb - sq) / qa
        v1 = (-qb + sq) / qa
        s_lo = max(s_lo, v0)
        s_hi = min(s_hi, v1)
        if s_hi <= s_lo:
            return 0.0
    elif qc >= 0.0:
        return 0.0
    span = s_hi - s_lo
    energy = 0.0
    for g in range(gxi.shape[0]):
        s = s_lo + span * gxi[g]
        t = t0 + s * t1
        d0 = c00 + s * c10
        d1 = c01 + s * c11
        d2 = c02 + s * c12
        d = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        delta = rr - d - off
        if delta <= 0.0 or d <= 0.0:
            continue
        p, e = law_line(law_id, law_params, delta, ra, rb)
        rec[7] += scale * gw[g] * span
        wl = scale * gw[g] * span * la
        fm = p * wl
        energy += e * wl
        inv = fm / d
        f0 = d0 * inv
        f1 = d1 * inv
        f2 = d2 * inv
        apply_line_point(f_out, (na0, na1, nb0, nb1), s, t, f0, f1, f2, fm, delta, rec, sign)
    return energy


@njit(cache=True, fastmath=True, error_model="numpy")
def contact_forces(x, seg_nodes, seg_radius, pairs, n_pairs, law_id, law_params, gxi, gw, f_out,
                   c_fn, c_n, c_s, c_t, c_phi, c_delta):
    """Normal contact forces of all candidate segment pairs, accumulated into ``f_out``: the plain
    array form of :func:`contact_forces_ex`, without initial-overlap offsets, contact shares, skip
    thresholds or an active list (same returns ``(energy, n_active)``)."""
    rec = PairRecords(c_fn, c_n, c_s, c_t, c_phi, c_delta, np.zeros(0), np.zeros(0), np.zeros(0),
                      np.zeros(0, np.int64))
    return contact_forces_ex(x, seg_nodes, seg_radius, pairs, n_pairs, law_id, law_params, gxi, gw, f_out,
                             rec, np.zeros(0), 0.0)


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def _point_part(x, seg_nodes, law_params, f_out, rec, ints, scal, a0, b0, ta, tb):
    """The point part of a pair (module docstring, item 3): its force into ``f_out`` and ``rec``;
    returns the stored energy [J].

    a0, b0 : 3-tuples, the first node of each segment; ta, tb : 3-tuples, their tangents;
    ints = (i, j, a0, a1, b0, b1, law_id): the segments and their nodes;
    scal = (r_i, r_j, aa, bb, ab, dist2, sc, tc, w, F(δ_c), E(δ_c), Φ, offset): radii, the tangents'
    dot products, the clamped closest points, the point share and law at δ_c, the crossing angle and
    the pair's initial-overlap offset (scalars only: no reference counting in the pair loop).
    """
    i, j, na0, na1, nb0, nb1, law_id = ints
    ra, rb, aa, bb, ab, dist2, sc, tc, w, fp_c, ep_c, phi, off = scal
    nodes4 = (na0, na1, nb0, nb1)
    rr = ra + rb
    den = aa * bb - ab * ab
    s, t = line_closest_params(a0, b0, ta, tb, aa, bb, ab, den)  # closest points of the infinite lines
    r0 = a0[0] - b0[0]
    r1 = a0[1] - b0[1]
    r2 = a0[2] - b0[2]
    # ownership across element joints (partition of unity): compare with the neighbouring
    # segment at the nearer end, on each fiber (see _joint_share)
    d_own = math.sqrt(dist2)
    ws_ = _joint_share(x, seg_nodes, i, s, d_own, b0, tb, rr)
    wt_ = _joint_share(x, seg_nodes, j, t, d_own, a0, ta, rr)
    wst = ws_ * wt_
    if not wst > 0.0:
        return 0.0
    s = sc
    t = tc
    d0 = r0 + s * ta[0] - t * tb[0]
    d1 = r1 + s * ta[1] - t * tb[1]
    d2 = r2 + s * ta[2] - t * tb[2]
    d = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    delta = rr - d - off
    if not delta > 0.0:
        return 0.0
    rec[7] += w * wst
    if d > 1e-14 * rr:
        inv = 1.0 / d
        n0 = d0 * inv
        n1 = d1 * inv
        n2 = d2 * inv
    else:  # axes intersect: normal to both tangents, oriented arbitrarily but consistently
        n0 = ta[1] * tb[2] - ta[2] * tb[1]
        n1 = ta[2] * tb[0] - ta[0] * tb[2]
        n2 = ta[0] * tb[1] - ta[1] * tb[0]
        inv = 1.0 / math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        n0 *= inv
        n1 *= inv
        n2 *= inv
    if off != 0.0:
        fp, ep = law_point(law_id, law_params, delta, ra, rb, phi)
    else:  # δ = δ_c: the same closest points (sc, tc) as dist2
        fp, ep = fp_c, ep_c
    fm = w * wst * fp
    f0 = fm * n0
    f1 = fm * n1
    f2 = fm * n2
    apply_line_point(f_out, nodes4, s, t, f0, f1, f2, fm, delta, rec, 1.0)
    return w * wst * ep


@njit(cache=True, fastmath=True, error_model="numpy")
def contact_forces_ex(x, seg_nodes, seg_radius, pairs, n_pairs, law_id, law_params, gxi, gw, f_out, out, c_off,
                      reach):
    """Normal contact forces of all candidate segment pairs, accumulated into ``f_out``.

    Parameters
    ----------
    x : (N, 3) float64, m — node positions.
    seg_nodes : (E, 2) int64 — node indices of each segment. seg_radius : (E,) float64, m.
    pairs : (P, 2) int64 — candidate segment pairs (i, j), only the first ``n_pairs`` rows are used.
    law_id : int, law_params : float64 array — see :mod:`fiberpipe.solver.laws`.
    gxi, gw : Gauss nodes on (0, 1) and weights summing to 1 (:func:`gauss_points`).
    f_out : (N, 3) float64, N — accumulated into (not zeroed).
    out : :class:`fiberpipe.solver.contact_state.PairRecords` — per pair, out: ``fn``, ``normal``,
        ``s``, ``t``, ``phi``, ``delta``; if size > 0, ``share`` (the pair's contact share: point part
        its blend weight × joint share, line part the fraction of the segment length in contact,
        halves averaged; a full-length parallel contact or a crossing counts 1), ``fsum`` (Σ|f| of
        its contact points [N]) and ``active`` (the indices of the pairs in contact, in order, so
        that friction and statistics visit only those). ``gap`` (size > 0): in/out, each pair's skip
        threshold, with ``reach``.
    c_off : (P,) float64, m — per-pair initial-overlap offset subtracted from every penetration of
        the pair (``δ_eff = δ − c_off[k]``; size 0: none).
    reach : float, m — twice a bound on the path any node has travelled since the last
        neighbour-list build (``2 Σ Δt max_i |v_i|``, non-decreasing). A pair with ``gap > reach``
        is skipped: when it was last evaluated, at reach ``R_c``, its clamped centre-line distance
        minus ``r_i + r_j`` was ``g_c`` and ``gap = R_c + g_c``; every point of a segment is a convex
        combination of its nodes, so since then the gap closed by at most ``reach − R_c``
        (Verlet-list reasoning with a per-pair refresh: one comparison per pair instead of a
        segment–segment distance, and a pair far from touching stays skipped for many steps). The
        build sets ``gap = g_b`` at reach 0; every evaluated pair found apart sets it anew.

    Returns
    -------
    (energy, n_active) : stored penalty energy Σ∫F dδ [J] (exact for laws with a potential and a
    constant blend weight), number of pairs in contact.
    """
    # the fields as local arrays: no attribute access in the pair loop
    c_fn, c_gap = out.fn, out.gap
    use_gap = c_gap.shape[0] > 0
    use_list = out.active.shape[0] > 0
    use_off = c_off.shape[0] > 0
    use_share = out.share.shape[0] > 0
    energy = 0.0
    n_active = 0
    rec = np.zeros(8)
    a0 = np.empty(3)
    a1 = np.empty(3)
    b0 = np.empty(3)
    b1 = np.empty(3)
    ta = np.empty(3)
    tb = np.empty(3)
    for k in range(n_pairs):
        c_fn[k] = 0.0
        if use_gap and c_gap[k] > reach:
            continue  # before any gather: most pairs stop here
        i = pairs[k, 0]
        j = pairs[k, 1]
        na0 = seg_nodes[i, 0]
        na1 = seg_nodes[i, 1]
        nb0 = seg_nodes[j, 0]
        nb1 = seg_nodes[j, 1]
        ra = seg_radius[i]
        rb = seg_radius[j]
        rr = ra + rb
        off = c_off[k] if use_off else 0.0
        # reject path on scalars (the common case: a Verlet candidate not touching)
        xa0 = x[na0, 0]
        ya0 = x[na0, 1]
        za0 = x[na0, 2]
        xb0 = x[nb0, 0]
        yb0 = x[nb0, 1]
        zb0 = x[nb0, 2]
        dist2, sc, tc = segment_distance2_s(xa0 - xb0, ya0 - yb0, za0 - zb0,
                                            x[na1, 0] - xa0, x[na1, 1] - ya0, x[na1, 2] - za0,
                                            x[nb1, 0] - xb0, x[nb1, 1] - yb0, x[nb1, 2] - zb0)
        if dist2 >= rr * rr:
            if use_gap:
                c_gap[k] = reach + math.sqrt(dist2) - rr
            continue
        for c in range(3):
            a0[c] = x[na0, c]
            a1[c] = x[na1, c]
            b0[c] = x[nb0, c]
            b1[c] = x[nb1, c]
            ta[c] = a1[c] - a0[c]
            tb[c] = b1[c] - b0[c]
        for c in range(8):
            rec[c] = 0.0
        aa = ta[0] * ta[0] + ta[1] * ta[1] + ta[2] * ta[2]
        bb = tb[0] * tb[0] + tb[1] * tb[1] + tb[2] * tb[2]
        ab = ta[0] * tb[0] + ta[1] * tb[1] + ta[2] * tb[2]
        phi = crossing_angle(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2], aa, bb, ab)
        delta_c = rr - math.sqrt(dist2)
        # the point force at δ_c comes with the weight (one Hertz evaluation for both)
        w, fp_c, ep_c = law_weight_point(law_id, law_params, delta_c, ra, rb, phi)
        den = aa * bb - ab * ab
        if w > 0.0 and den > 1e-10 * aa * bb:
            energy += _point_part(x, seg_nodes, law_params, f_out, rec, (i, j, na0, na1, nb0, nb1, law_id),
                                  (ra, rb, aa, bb, ab, dist2, sc, tc, w, fp_c, ep_c, phi, off),
                                  (a0[0], a0[1], a0[2]), (b0[0], b0[1], b0[2]), (ta[0], ta[1], ta[2]),
                                  (tb[0], tb[1], tb[2]))
        elif w > 0.0:
            w = 0.0
        if w < 1.0:
            half = 0.5 * (1.0 - w)
            energy += _line_half(x, na0, na1, nb0, nb1, ra, rb, law_id, law_params, gxi, gw, half, f_out, rec, 1.0,
                                 off)
            energy += _line_half(x, nb0, nb1, na0, na1, rb, ra, law_id, law_params, gxi, gw, half, f_out, rec, -1.0,
                                 off)
        n_active = record_pair(out, k, rec, phi, n_active, use_list, use_share)
    return energy, n_active


_LAW_KERNELS: dict = {}


def contact_kernels_for(law):
    """``(contact_forces_ex, contact_forces)`` for ``law``: the built-in kernels for a law without
    ``kernels``; else copies specialised on the law's own jitted ``(line, point, weight_point)``
    (compiled once per process and law class; see ``_specialise``)."""
    if law.kernels is None:
        return contact_forces_ex, contact_forces
    key = type(law)
    if key not in _LAW_KERNELS:
        line, point, weight_point = law.kernels
        tag = type(law).__name__
        flags = dict(fastmath=True, error_model="numpy")
        lh = specialise(_line_half, f"_line_half_{tag}", {"law_line": line}, cache=False, **flags)
        pp = specialise(_point_part, f"_point_part_{tag}", {"law_point": point}, cache=False, inline="always", **flags)
        cf = specialise(contact_forces_ex, f"contact_forces_ex_{tag}",
                        {"_line_half": lh, "_point_part": pp, "law_weight_point": weight_point}, cache=False, **flags)
        plain = specialise(contact_forces, f"contact_forces_{tag}", {"contact_forces_ex": cf}, cache=False, **flags)
        _LAW_KERNELS[key] = (cf, plain)
    return _LAW_KERNELS[key]


def compute_contact(x, seg_nodes, seg_radius, pairs, n_pairs, law, f_out, buffers=None, n_gauss=4):
    """Python convenience wrapper: evaluate :func:`contact_forces` with a law object.

    Returns ``(energy, n_active, buffers)``; ``f_out`` is accumulated into.
    """
    gxi, gw = gauss_points(n_gauss)
    if buffers is None:
        buffers = ContactBuffers(max(n_pairs, 1))
    buffers.ensure(n_pairs)
    e, na = contact_kernels_for(law)[1](
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(seg_nodes, dtype=np.int64),
        np.ascontiguousarray(seg_radius, dtype=np.float64),
        np.ascontiguousarray(pairs, dtype=np.int64),
        int(n_pairs),
        law.law_id,
        law.params(),
        gxi,
        gw,
        f_out,
        buffers.fn,
        buffers.n,
        buffers.s,
        buffers.t,
        buffers.phi,
        buffers.delta,
    )
    return e, na, buffers
