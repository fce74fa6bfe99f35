"""Fiber–fiber normal contact in which every force is minus the gradient of one stored potential.

The normal contact pass of the step loop's contact hook (:mod:`fiberpipe.solver.terms.contact`). The
potential of a candidate segment pair (A = segment i, B = j) is

    Π_AB = (1 − w(Φ)) Π_line + w(Φ) s_joint Π_point

* **Onset.** Every law acts on the mapped penetration ``g(δ)``: ``g' = smoothstep(δ/δ_s)`` on
  ``[0, δ_s]`` (``g = δ_s(u³ − u⁴/2)``, ``u = δ/δ_s``) and ``g = δ − δ_s/2`` beyond, so the force
  ``F(g)·g'`` and its slope vanish at first touch and the potential is C² there (a stiffness that
  switches on with a jump makes central differences create or destroy ``~½ k (vΔt)²`` per touch,
  whatever the step: the penalty is chosen against Δt).
* **Line part** (Meier, Popp & Wall, CMAME 308, 2016, Gauss-point-to-segment): Gauss points at
  fixed parameters ξ_g of A (whole segment, weight ``w_g L0_A``, the reference length), each
  projected on B (clamped); the point belongs to the segment of B nearer to it than B's neighbour
  at the nearer end (ties: the later one; a free end keeps its clamped point, the hemispherical
  end cap), so the integrand is ``e_line`` of the distance to fiber B's polyline: a function of the
  node positions only, continuous across straight and kinked joints.
  ``Π_line = Σ_g w_g L0_A λ_AB e_line(g(δ_g))`` both ways (A on B and B on A), with the end weight
  ``λ_AB = (1 + a_A)(1 − a_B)/(2(1 − a_A a_B))`` (:func:`_line_part`): ½ away from fiber ends; over a fiber's end
  segment its own way takes the weight over smoothly (a = 3τ² − 2τ³ rising to 1 at the free end), so
  a fiber end moving past the other way's fixed points does not step the integral. The closest point
  is stationary (or clamped at a free end), so ``∂δ_g/∂x`` is the normal times the shape functions;
  λ's gradient enters through the projection parameter on the end segment.
* **Point part**: clamped segment–segment closest points, ``Π_point = e_point(g(δ_c), Φ)``, with
  the joint share ``s_joint`` of :func:`_joint_share`: smooth ramps, ±(0.3 δ_c + 1e-5 (r_i + r_j)),
  in the difference of each neighbouring pair's clamped distance and the pair's own, their gradient
  in the force, so the point part stays continuous and conservative while a crossing moves from one
  segment pair to the next.
* **Blend**: ``w = smoothstep((Φ − Φ_lo)/(Φ_hi − Φ_lo))`` on the crossing angle, times the patch
  criterion ``w_ξ(δ_c, Φ)`` from the Hertz ellipse against ℓ_blend (:func:`_patch_weight`; every law
  with a point part, from ``scene.contact.blend_length``), δ_c the pair's clamped penetration. The blend's derivatives and the law's own ``∂e_point/∂Φ`` (hertz_oriented:
  K(Φ)) enter the force: ``∂w/∂δ_c (s_joint Π_point − Π_line)`` along the closest points' normal, and
  ``G = ∂Π/∂Φ = ∂w/∂Φ (s_joint Π_point − Π_line) + w s_joint ∂Π_point/∂Φ`` through
  ``∂Φ/∂t_A = −σ (t̂_B − c t̂_A)/(|t_A| sin Φ)`` (``c = t̂_A·t̂_B``, ``σ = sign c``): a couple on
  each segment (no net force), the consistent variant of the all-angle blend (4C's
  ``CONSISTENTTRANSITION``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._prefetch import prefetch_row
from .._tasks import SCATTER_TASKS, task_count
from ._specialise import specialise
from .contact_pairs import record_pair
from .contact_state import PairRecords
from .geometry import apply_line_point, crossing_angle, segment_distance2_s
from .laws import (LAW_HERTZ_ORIENTED, LAW_HERTZ_PARALLEL, P_LBLEND, P_PHI_HI, P_PHI_LO, P_XI_HI, P_XI_LO,
                   hertz_crossed_point_d, law_line, law_point, law_weight_point)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def onset(delta, ds):
    """(g, dg/dδ) of the onset map: g(0) = g'(0) = g''(0) = 0, g' = 1 and g'' = 0 from δ_s on, so a law's
    potential e(g(δ)) is C² at touch (δ_s = 0: the identity)."""
    if delta >= ds:
        return delta - 0.5 * ds, 1.0
    u = delta / ds
    u2 = u * u
    return ds * u2 * u * (1.0 - 0.5 * u), u2 * (3.0 - 2.0 * u)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _prev_node(seg_nodes, e):
    """The far node of the segment before ``e`` on its fiber (−1: ``e`` starts the fiber)."""
    return seg_nodes[e - 1, 0] if e > 0 and seg_nodes[e - 1, 1] == seg_nodes[e, 0] else -1


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _next_node(seg_nodes, e):
    """The far node of the segment after ``e`` on its fiber (−1: ``e`` ends the fiber)."""
    return seg_nodes[e + 1, 1] if e + 1 < seg_nodes.shape[0] and seg_nodes[e + 1, 0] == seg_nodes[e, 1] else -1


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _point_segment_distance2(p0, p1, p2, x, n0, n1):
    """Squared distance [m²] of point p to the segment of nodes n0, n1 (clamped projection)."""
    t0 = x[n1, 0] - x[n0, 0]
    t1 = x[n1, 1] - x[n0, 1]
    t2 = x[n1, 2] - x[n0, 2]
    r0 = p0 - x[n0, 0]
    r1 = p1 - x[n0, 1]
    r2 = p2 - x[n0, 2]
    t = (r0 * t0 + r1 * t1 + r2 * t2) / (t0 * t0 + t1 * t1 + t2 * t2)
    t = min(max(t, 0.0), 1.0)
    r0 -= t * t0
    r1 -= t * t1
    r2 -= t * t2
    return r0 * r0 + r1 * r1 + r2 * r2


# columns of the line part's Gauss-point buffer (one row per Gauss point in contact): parameter on
# the integrating segment, clamped parameter on the other, distance vector and length, penetration,
# weight w_g·m (m: the direction's end weight, :func:`_end_weight`), the law's force magnitude and
# energy, then up to two terms of the end weight's gradient: which segment's parameter (_T_NONE,
# _T_OWN, _T_NEXT, _T_PREV) and ∂Π_g/∂τ (w_g ∂m/∂τ until the law is known)
_G_XI, _G_T, _G_D0, _G_D1, _G_D2, _G_D, _G_DELTA, _G_GW, _G_P, _G_E, _G_ENDS, _G_C1, _G_R1, _G_C2, _G_R2 = range(15)
N_GP_COLUMNS = 15
_T_NONE, _T_OWN, _T_NEXT, _T_PREV = 0.0, 1.0, 2.0, 3.0
# a segment's free ends as bit flags (:func:`_segment_ends`): its start is the fiber's start, its end
# the fiber's end, the segment before it starts the fiber, the segment after it ends the fiber
_START_FREE, _END_FREE, _PREV_FIRST, _NEXT_LAST = 1, 2, 4, 8


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _smoothstep(u):
    """``(S(u), S'(u))``, S = 3u² − 2u³ on [0, 1], 0 below and 1 above (C¹)."""
    if u <= 0.0:
        return 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0
    return u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _segment_ends(seg_nodes, e):
    """Segment ``e``'s bit flags of the fiber ends near it (``_START_FREE`` … ``_NEXT_LAST``): 0 for a
    segment with at least one segment on each side between it and either end."""
    flags = 0
    if _prev_node(seg_nodes, e) < 0:
        flags |= _START_FREE
    elif _prev_node(seg_nodes, e - 1) < 0:
        flags |= _PREV_FIRST
    if _next_node(seg_nodes, e) < 0:
        flags |= _END_FREE
    elif _next_node(seg_nodes, e + 1) < 0:
        flags |= _NEXT_LAST
    return flags


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _own_end_nearness(flags, xi):
    """a(ξ) of the fiber's material point at parameter ξ of a segment with end ``flags``: S(ξ) on a
    fiber's last segment, S(1 − ξ) on its first, S(|2ξ − 1|) on a fiber of one segment, 0 elsewhere
    (1 at a free end, 0 at the segment's inner joint, C¹)."""
    if flags & (_START_FREE | _END_FREE) == (_START_FREE | _END_FREE):
        return _smoothstep(abs(2.0 * xi - 1.0))[0]
    if flags & _START_FREE:
        return _smoothstep(1.0 - xi)[0]
    if flags & _END_FREE:
        return _smoothstep(xi)[0]
    return 0.0


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _projection(x, p0, p1, p2, n0, n1):
    """Parameter τ of the projection of point p on the line of the segment of nodes n0, n1 (unclamped)."""
    t0 = x[n1, 0] - x[n0, 0]
    t1 = x[n1, 1] - x[n0, 1]
    t2 = x[n1, 2] - x[n0, 2]
    return ((p0 - x[n0, 0]) * t0 + (p1 - x[n0, 1]) * t1 + (p2 - x[n0, 2]) * t2) / (t0 * t0 + t1 * t1 + t2 * t2)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _other_end_nearness(x, p, t_raw, nodes, flags):
    """``(a, ∂a/∂τ_own, ∂a/∂τ_near)``: the other fiber's end nearness a (:func:`_own_end_nearness`)
    at the projection of point ``p`` on it, from the parameter ``t_raw`` of p on segment B
    (``nodes = (b0, b1, b_prev, b_next)``, B's end ``flags``); where B's neighbour is the fiber's
    first or last segment and p lies on its side of B, a is read from p's projection τ_near on that
    segment (so a point that changes owner at a kinked joint sees the same a from both pairs)."""
    p0, p1, p2 = p
    nb0, nb1, b_prev, b_next = nodes
    tc = min(max(t_raw, 0.0), 1.0)
    a = 0.0
    da_own = 0.0
    if flags & (_START_FREE | _END_FREE) == (_START_FREE | _END_FREE):
        v = 2.0 * tc - 1.0
        a, da = _smoothstep(abs(v))
        da_own = 2.0 * da if v >= 0.0 else -2.0 * da
    elif flags & _START_FREE:
        a, da = _smoothstep(1.0 - tc)
        da_own = -da
    elif flags & _END_FREE:
        a, da = _smoothstep(tc)
        da_own = da
    da_near = 0.0
    if flags & _NEXT_LAST and t_raw > 0.5:
        an, da_near = _smoothstep(_projection(x, p0, p1, p2, nb1, b_next))
        a += an
    elif flags & _PREV_FIRST and t_raw <= 0.5:
        an, da = _smoothstep(1.0 - _projection(x, p0, p1, p2, b_prev, nb0))
        a += an
        da_near = -da
    return a, da_own, da_near


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _line_half_points(x, nodes, rr, gxi, gw, off, gbuf, n0):
    """Stage 1 of a line half: the Gauss points fixed on A, projected on segment B, that touch B and
    belong to it, written to ``gbuf`` rows from ``n0`` on (with their weight w_g·m, m the end
    weight of :func:`_line_part`); returns the new row count. ``nodes = (a0, a1, b0, b1, b_prev,
    b_next, a_ends, b_ends)``: the segments' nodes, the far nodes of the segments before and after B
    on its fiber (−1: B ends there, its clamped point is the end cap) and both segments' end flags
    (:func:`_segment_ends`)."""
    na0, na1, nb0, nb1, b_prev, b_next, a_ends, b_ends = nodes
    tb0 = x[nb1, 0] - x[nb0, 0]
    tb1 = x[nb1, 1] - x[nb0, 1]
    tb2 = x[nb1, 2] - x[nb0, 2]
    inv_lb2 = 1.0 / (tb0 * tb0 + tb1 * tb1 + tb2 * tb2)
    reach2 = (rr - off) * (rr - off) if rr > off else 0.0
    ends = a_ends != 0 or b_ends != 0
    n = n0
    for g in range(gxi.shape[0]):
        xi = gxi[g]
        p0 = x[na0, 0] + xi * (x[na1, 0] - x[na0, 0])
        p1 = x[na0, 1] + xi * (x[na1, 1] - x[na0, 1])
        p2 = x[na0, 2] + xi * (x[na1, 2] - x[na0, 2])
        r0 = p0 - x[nb0, 0]
        r1 = p1 - x[nb0, 1]
        r2 = p2 - x[nb0, 2]
        t_raw = (r0 * tb0 + r1 * tb1 + r2 * tb2) * inv_lb2
        t = min(max(t_raw, 0.0), 1.0)
        d0 = r0 - t * tb0
        d1 = r1 - t * tb1
        d2 = r2 - t * tb2
        dd2 = d0 * d0 + d1 * d1 + d2 * d2
        if dd2 >= reach2:  # out of contact (δ ≤ 0) without the square root
            continue
        d = math.sqrt(dd2)
        delta = rr - d - off
        # out of contact with this segment: no share of Π whichever segment owns the point
        if delta <= 0.0 or d <= 0.0:
            continue
        # ownership: the Gauss point belongs to the segment of B nearest to it, against B's neighbour
        # at the nearer end (ties to the later segment), so Π_line integrates e(min over B's segments
        # of the distance): continuous on kinked fibers too; at a free end the clamped point (end cap)
        if t_raw > 0.5:
            if b_next >= 0 and _point_segment_distance2(p0, p1, p2, x, nb1, b_next) <= dd2:
                continue
        elif b_prev >= 0 and _point_segment_distance2(p0, p1, p2, x, b_prev, nb0) < dd2:
            continue
        weight = gw[g]
        has_terms = 0.0  # the columns _G_ENDS … _G_R2 are written and read only near an end
        if ends:  # near a fiber end: the end weight m = 2 λ_AB (_line_part)
            a_b, da_own, da_near = _other_end_nearness(x, (p0, p1, p2), t_raw, (nb0, nb1, b_prev, b_next), b_ends)
            a_a = _own_end_nearness(a_ends, xi)  # < 1: Gauss points are inside their segment
            inv = 1.0 / (1.0 - a_a * a_b)
            m = (1.0 + a_a) * (1.0 - a_b) * inv
            if m <= 0.0:  # beyond the other fiber's end: this direction's points carry none of it
                continue
            weight = gw[g] * m
            if da_own != 0.0 or da_near != 0.0:
                dm_da = -(1.0 - a_a * a_a) * inv * inv  # ∂m/∂a_B
                has_terms = 1.0
                gbuf[n, _G_C1] = _T_OWN if da_own != 0.0 else _T_NONE
                gbuf[n, _G_R1] = gw[g] * dm_da * da_own
                gbuf[n, _G_C2] = _T_NONE if da_near == 0.0 else (_T_NEXT if t_raw > 0.5 else _T_PREV)
                gbuf[n, _G_R2] = gw[g] * dm_da * da_near
        gbuf[n, _G_XI] = xi
        gbuf[n, _G_T] = t
        gbuf[n, _G_D0] = d0
        gbuf[n, _G_D1] = d1
        gbuf[n, _G_D2] = d2
        gbuf[n, _G_D] = d
        gbuf[n, _G_DELTA] = delta
        gbuf[n, _G_GW] = weight
        if ends:
            gbuf[n, _G_ENDS] = has_terms
        n += 1
    return n


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _line_loads(gbuf, span, law_id, law_params, ra, rb, ds, scale, la0):
    """Stage 2: the line law at rows ``n0:n1`` of ``gbuf`` (A's radius ``ra``, B's ``rb``, A's
    reference length ``la0``): each Gauss point's force magnitude and energy, weighted by
    ``scale``·w_g·m·L0_A, and the end weight's gradient terms as ∂Π_g/∂τ. No row depends on
    another, so the law's evaluations (a logarithm and a table read each) overlap in the pipeline
    instead of waiting on each other's geometry. ``span = (n0, n1, ends)``: ``ends``, the rows carry
    the end-weight columns."""
    n0, n1, ends = span
    for n in range(n0, n1):
        gg, gp = onset(gbuf[n, _G_DELTA], ds)
        pl, el = law_line(law_id, law_params, gg, ra, rb)
        wl = scale * gbuf[n, _G_GW] * la0
        gbuf[n, _G_P] = pl * gp * wl
        gbuf[n, _G_E] = el * wl
        if ends and gbuf[n, _G_ENDS] != 0.0:
            gbuf[n, _G_R1] *= scale * la0 * el
            gbuf[n, _G_R2] *= scale * la0 * el


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _end_weight_force(x, f_out, rows, real, xi, dpi_dtau):
    """The force −∂Π_g/∂τ ∇τ of one end-weight term: τ the parameter of the Gauss point
    p = (1 − ξ) a0 + ξ a1 projected on the line of segment e0–e1, ``real = (a0, a1, e0, e1)`` the
    nodes, ``rows`` their rows of ``f_out``. With t_e = e1 − e0 and r = p − e0:
    ∂τ/∂p = t_e/|t_e|², ∂τ/∂e1 = (r − 2τ t_e)/|t_e|², ∂τ/∂e0 = −∂τ/∂p − ∂τ/∂e1 (the forces sum to 0)."""
    na0, na1, ne0, ne1 = real
    inv = 1.0 / ((x[ne1, 0] - x[ne0, 0]) ** 2 + (x[ne1, 1] - x[ne0, 1]) ** 2 + (x[ne1, 2] - x[ne0, 2]) ** 2)
    tau = _projection(x, x[na0, 0] + xi * (x[na1, 0] - x[na0, 0]), x[na0, 1] + xi * (x[na1, 1] - x[na0, 1]),
                      x[na0, 2] + xi * (x[na1, 2] - x[na0, 2]), ne0, ne1)
    for c in range(3):
        te = x[ne1, c] - x[ne0, c]
        r = x[na0, c] + xi * (x[na1, c] - x[na0, c]) - x[ne0, c]
        g_p = -dpi_dtau * te * inv
        g_e1 = -dpi_dtau * (r - 2.0 * tau * te) * inv
        f_out[rows[0], c] += (1.0 - xi) * g_p
        f_out[rows[1], c] += xi * g_p
        f_out[rows[3], c] += g_e1
        f_out[rows[2], c] -= g_p + g_e1


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _end_weight_forces(x, gbuf, n, f_out, rows, real):
    """Row ``n``'s end-weight terms as forces (:func:`_end_weight_force`); ``rows``/``real``: the block
    rows / node indices of (a0, a1, b0, b1, b_prev, b_next) of this half. Returns whether a far node
    (b_prev, b_next) got a force."""
    far = False
    for col in (_G_C1, _G_C2):
        code = gbuf[n, col]
        if code == _T_NONE:
            continue
        k = 2 if code == _T_OWN else (3 if code == _T_NEXT else 4)
        h = 3 if code == _T_OWN else (5 if code == _T_NEXT else 2)
        _end_weight_force(x, f_out, (rows[0], rows[1], rows[k], rows[h]), (real[0], real[1], real[k], real[h]),
                          gbuf[n, _G_XI], gbuf[n, col + 1])
        far = far or code != _T_OWN
    return far


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _line_half_apply(gbuf, n0, n1, nodes4, f_out, rec, sign, scale):
    """Stage 3: rows ``n0:n1`` of ``gbuf`` as forces on the nodes ``nodes4`` (A's two, B's two) and
    into the pair's accumulator ``rec``; returns the half's energy."""
    energy = 0.0
    for n in range(n0, n1):
        rec[7] += scale * gbuf[n, _G_GW]
        fm = gbuf[n, _G_P]
        energy += gbuf[n, _G_E]
        inv = fm / gbuf[n, _G_D]
        apply_line_point(f_out, nodes4, gbuf[n, _G_XI], gbuf[n, _G_T], gbuf[n, _G_D0] * inv, gbuf[n, _G_D1] * inv,
                         gbuf[n, _G_D2] * inv, fm, gbuf[n, _G_DELTA], rec, sign)
    return energy


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _end_weight_pass(x, seg_nodes, gbuf, counts, ij, blk):
    """The end weights' gradient terms of pair ``ij = (i, j)``'s Gauss points (rows of both ways,
    ``counts = (n_a, n_b)``, after :func:`_line_part`) as forces into its block ``blk`` (rows 0–3:
    a0, a1, b0, b1; 4–7: the far nodes of the segments before and after A, then B); returns whether
    a far node got a force."""
    i, j = ij
    na0, na1, nb0, nb1 = seg_nodes[i, 0], seg_nodes[i, 1], seg_nodes[j, 0], seg_nodes[j, 1]
    real_a = (na0, na1, nb0, nb1, _prev_node(seg_nodes, j), _next_node(seg_nodes, j))
    real_b = (nb0, nb1, na0, na1, _prev_node(seg_nodes, i), _next_node(seg_nodes, i))
    far = False
    for n in range(counts[1]):
        if gbuf[n, _G_ENDS] != 0.0:
            if n < counts[0]:
                far = _end_weight_forces(x, gbuf, n, blk, (0, 1, 2, 3, 6, 7), real_a) or far
            else:
                far = _end_weight_forces(x, gbuf, n, blk, (2, 3, 0, 1, 4, 5), real_b) or far
    return far


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _line_points(x, seg_nodes, i, j, rr, gxi, gw, off, gbuf):
    """Stage 1 of pair (i, j)'s line part, both ways (A on B, then B on A): ``(n_a, n_b, ends)``, the
    rows of ``gbuf`` that end each way's Gauss points and whether a fiber end is near (the rows then
    carry the end weight's columns)."""
    na0 = seg_nodes[i, 0]
    na1 = seg_nodes[i, 1]
    nb0 = seg_nodes[j, 0]
    nb1 = seg_nodes[j, 1]
    ends_i = _segment_ends(seg_nodes, i)
    ends_j = _segment_ends(seg_nodes, j)
    n_a = _line_half_points(x, (na0, na1, nb0, nb1, _prev_node(seg_nodes, j), _next_node(seg_nodes, j), ends_i,
                                ends_j), rr, gxi, gw, off, gbuf, 0)
    n_b = _line_half_points(x, (nb0, nb1, na0, na1, _prev_node(seg_nodes, i), _next_node(seg_nodes, i), ends_j,
                                ends_i), rr, gxi, gw, off, gbuf, n_a)
    return n_a, n_b, (ends_i | ends_j) != 0


@njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)
def _line_part(gbuf, counts, nodes4, geo, law_id, law_params, scale, ds, f_out, rec):
    """Stages 2 and 3 of the line part on the Gauss points of :func:`_line_points` (``counts = (n_a,
    n_b, ends)``), each way with weight ``scale`` times its end weight: forces into ``f_out`` at the
    nodes ``nodes4``, accumulator ``rec``; ``geo = (L0_A, L0_B, r_A, r_B)`` the reference lengths and
    radii; returns the weighted energy. The end weights' gradient terms are applied after it
    (:func:`_end_weight_pass`).

    **End weights.** Each way's Gauss points are fixed on its own segments, so the way from A onto
    fiber B integrates over fiber A's length exactly, while where B ends inside that length its
    integrand steps from e to 0 between two of A's points: a fiber sliding along another changed its
    contact length whenever a point passed the other's end (±5.6 % of the normal force). Near a free
    end the way whose points lie on the ending fiber therefore takes the weight over, smoothly:

        Π_line = Σ_g w_g L0_A (1 − w) λ_AB(p_g) e(g(δ_g))  +  (A ↔ B),
        λ_AB = (1 + a_A)(1 − a_B) / (2 (1 − a_A a_B)),

    with a_F the end nearness of fiber F (:func:`_own_end_nearness`): a = S(τ) = 3τ² − 2τ³ over the
    fiber's last segment (τ its parameter, 1 at the free end), S(1 − τ) over its first, 0 elsewhere.
    a_A is read at the Gauss point's own parameter (fixed, < 1: Gauss points lie inside their
    segment), a_B at its projection on fiber B's end segment. At one place λ_AB + λ_BA = 1, so the
    sum still integrates e once; in the interior λ = ½ (the forces of full overlaps are as before bit
    for bit). λ_AB is 0 where B ends (a_B = 1), with zero slope, whether or not A ends nearby too, so
    the integrand of the way whose points are fixed on A no longer steps there. Where only B ends,
    λ_BA = ½(1 + a_B), a cubic on B's end segment, integrated exactly by two or more Gauss points.
    The force carries λ's gradient, −w_g L0_A (1 − w) e ∂λ_AB/∂a_B ∂a_B/∂τ ∇τ, with τ the projection
    parameter on B's end segment (from the neighbouring pair, at a kinked joint, too: both owners
    read the same a_B). Beyond B's end λ_AB = 0: the line part has no end cap (a fiber end meets
    another fiber's side through its end segment, and a crossing through the point part)."""
    # Strategy: the Gauss points are found first (geometry, before the pair's blend, so it overlaps
    # the point part's), then the law runs on all of them, then the forces are applied: the same
    # arithmetic in the same order as one loop per point, but the law's latency (log, table) no
    # longer chains behind each point's square root and projection.
    n_a, n_b, ends = counts
    la0, lb0, ra, rb = geo
    na0, na1, nb0, nb1 = nodes4
    _line_loads(gbuf, (0, n_a, ends), law_id, law_params, ra, rb, ds, scale, la0)
    _line_loads(gbuf, (n_a, n_b, ends), law_id, law_params, rb, ra, ds, scale, lb0)
    el = _line_half_apply(gbuf, 0, n_a, (na0, na1, nb0, nb1), f_out, rec, 1.0, scale)
    el += _line_half_apply(gbuf, n_a, n_b, (nb0, nb1, na0, na1), f_out, rec, -1.0, scale)
    return el


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _patch_weight(law_params, a, da_dphi, da_dg):
    """The patch criterion's point share (:func:`fiberpipe.solver.laws.patch_weight`) and its partial
    derivatives ``(w, ∂w/∂Φ, ∂w/∂g)`` from the Hertz semi-major axis ``a`` and its derivatives;
    ``(1, 0, 0)`` when ℓ_blend is 0 (off).

    ``w = 1 − smoothstep((ξ − ξ_lo)/(ξ_hi − ξ_lo))``, ``ξ = a/ℓ_blend``, ``a = â(Φ)√(R_e g)``: the
    point law while the contact ellipse fits in ℓ_blend, the line law once it outgrows it."""
    if law_params[P_LBLEND] <= 0.0:
        return 1.0, 0.0, 0.0
    inv_l = 1.0 / law_params[P_LBLEND]
    xlo = law_params[P_XI_LO]
    span = law_params[P_XI_HI] - xlo
    u = (a * inv_l - xlo) / span
    if u <= 0.0:
        return 1.0, 0.0, 0.0
    if u >= 1.0:
        return 0.0, 0.0, 0.0
    dw_da = -6.0 * u * (1.0 - u) / span * inv_l
    return 1.0 - u * u * (3.0 - 2.0 * u), dw_da * da_dphi, dw_da * da_dg


@njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)
def _pair_blend_point(law_id, law_params, delta_c, ds, ra, rb, phi):
    """The point share of a pair, its partial derivatives and the point law at the pair's clamped
    penetration δ_c: ``(w, ∂w/∂Φ, ∂w/∂δ_c, F_point [N], e_point [J], ∂e_point/∂Φ [J/rad])``, the law
    taken at the mapped penetration g(δ_c).

    w: hertz_parallel 0; the others the angle window × the patch criterion (below Φ_lo no point law:
    at Φ → 0 the crossed-Hertz stiffness diverges and ∂w/∂δ would carry it). One crossed-Hertz
    evaluation gives the ellipse (patch criterion) and, for hertz_oriented, the point law with its
    angle derivative K'(Φ) (:func:`fiberpipe.solver.laws.hertz_crossed_point_d`)."""
    if law_id == LAW_HERTZ_PARALLEL:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    inv_span = 1.0 / (law_params[P_PHI_HI] - law_params[P_PHI_LO])
    u = (phi - law_params[P_PHI_LO]) * inv_span
    if u <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    wp, dwp = 1.0, 0.0
    if u < 1.0:
        wp = u * u * (3.0 - 2.0 * u)
        dwp = 6.0 * u * (1.0 - u) * inv_span
    if delta_c <= 0.0:
        return wp, dwp, 0.0, 0.0, 0.0, 0.0
    g, gp = onset(delta_c, ds)
    wx, dwx, dw_dg = 1.0, 0.0, 0.0
    fp, ep, dep = 0.0, 0.0, 0.0
    if law_id == LAW_HERTZ_ORIENTED or law_params[P_LBLEND] > 0.0:
        fh, eh, a, deh, dah = hertz_crossed_point_d(law_params, g, ra, rb, phi)
        wx, dwx, dw_dg = _patch_weight(law_params, a, dah, 0.5 * a / g)
        if law_id == LAW_HERTZ_ORIENTED:
            fp, ep, dep = fh, eh, deh
    if law_id != LAW_HERTZ_ORIENTED:
        fp, ep = law_point(law_id, law_params, g, ra, rb, phi)
    return wx * wp, dwx * wp + wx * dwp, dw_dg * gp * wp, fp, ep, dep


@njit(cache=True, fastmath=True, error_model="numpy")
def _pair_blend_point_of_law(law_id, law_params, delta_c, ds, ra, rb, phi):
    """:func:`_pair_blend_point` for a law with its own jitted ``weight_point`` and ``point`` (bound by
    :func:`potential_kernels_for`): its weight and point law at the mapped penetration, the
    derivatives by central differences."""
    g, gp = onset(delta_c, ds) if delta_c > 0.0 else (0.0, 0.0)
    w, fp, ep = law_weight_point(law_id, law_params, g, ra, rb, phi)
    h = 1e-6 * phi + 1e-9
    lo = max(phi - h, 0.0)
    wa, fa, ea = law_weight_point(law_id, law_params, g, ra, rb, phi + h)
    wb, fb, eb = law_weight_point(law_id, law_params, g, ra, rb, lo)
    hd = 1e-6 * g + 1e-15
    wc, fc, ec = law_weight_point(law_id, law_params, g + hd, ra, rb, phi)
    wd, fd, ed = law_weight_point(law_id, law_params, max(g - hd, 0.0), ra, rb, phi)
    pa, qa = law_point(law_id, law_params, g, ra, rb, phi + h)
    pb, qb = law_point(law_id, law_params, g, ra, rb, lo)
    return (w, (wa - wb) / (phi + h - lo), (wc - wd) / (g + hd - max(g - hd, 0.0)) * gp, fp, ep,
            (qa - qb) / (phi + h - lo))


# Half-width of the joint share's ramps in the difference of two clamped distances: 0.3 of the
# pair's penetration δ_c plus 1e-5 (r_i + r_j) (5 nm for paper-40's fibers). The ramp's stiffness
# in that difference is at most Π_point · 3/(2e²); with Π_point = (2/5) K δ^{5/2} and e = c δ that
# is (0.4/c²) times the law's own normal tangent 3/2 K δ^{1/2}: 4.4× at c = 0.3, 40× at 0.1, which
# the step did not carry (paper-40/compaction-blend created 1.2 % of its work with 0.1, 13 % with
# 0.03, none with 0.3). The floor keeps the ramp wide against the change of that difference in one
# step where two fibers' distance is nearly flat (≈ 1e-9 m a step at 1.7° and δ_c ≈ 5e-9 m on
# paper-40), where a ramp of 1e-9 (r_i + r_j) was crossed within a step and without a force. Inside a
# ramp the pairs, whose depths differ by < 2e, share the crossing and the shallower one's energy
# counts for part of it (docs/contact.md).
_JOINT_RAMP = 0.3
_JOINT_RAMP_FLOOR = 1e-5


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _ramp(u, e):
    """``(smoothstep((u + e)/2e), its derivative in u)``: 0 for u ≤ −e, ½ at u = 0, 1 for u ≥ e, and
    ramp(u) + ramp(−u) = 1."""
    v = (u + e) / (2.0 * e)
    if v <= 0.0:
        return 0.0, 0.0
    if v >= 1.0:
        return 1.0, 0.0
    return v * v * (3.0 - 2.0 * v), 3.0 * v * (1.0 - v) / e


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _rival(x, nodes, d_own, shift, e, geo):
    """One factor of the joint share: the ramp (:func:`_ramp`) of d_nb − d_own + ``shift``, d_nb the
    clamped distance of the rival segments ``nodes = (n0, n1, m0, m1)``; ``geo[0:5]`` gets that
    distance's closest points and unit normal ``(s_n, t_n, n)`` for its gradient, ``geo[7]``
    d_nb − d_own. ``(f, ∂f/∂d_nb)``; (1, 0) without a rival (a node −1: a free end)."""
    n0, n1, m0, m1 = nodes
    if n0 < 0 or n1 < 0 or m0 < 0 or m1 < 0:
        return 1.0, 0.0
    c0 = x[n0, 0]
    c1 = x[n0, 1]
    c2 = x[n0, 2]
    d2, sn, tn = segment_distance2_s(c0 - x[m0, 0], c1 - x[m0, 1], c2 - x[m0, 2], x[n1, 0] - c0, x[n1, 1] - c1,
                                      x[n1, 2] - c2, x[m1, 0] - x[m0, 0], x[m1, 1] - x[m0, 1], x[m1, 2] - x[m0, 2])
    d = math.sqrt(d2)
    f, fp = _ramp(d - d_own + shift, e)
    if fp == 0.0 or d <= 0.0:
        return f, 0.0
    geo[0] = sn
    geo[1] = tn
    geo[7] = d - d_own
    for c in range(3):
        geo[2 + c] = (x[n0, c] + sn * (x[n1, c] - x[n0, c]) - x[m0, c] - tn * (x[m1, c] - x[m0, c])) / d
    return f, fp


# the joint share's rivals of pair (i, j) as rows of the pair's force block (0–3: a0, a1, b0, b1;
# 4–7: the far nodes of the segments before and after i, before and after j): (i−1, j), (i+1, j),
# (i, j−1), (i, j+1), then the diagonals (i∓1, j∓1)
_RIVAL_ROWS = np.array([[4, 0, 2, 3], [1, 5, 2, 3], [0, 1, 6, 2], [0, 1, 3, 7],
                        [4, 0, 6, 2], [4, 0, 3, 7], [1, 5, 6, 2], [1, 5, 3, 7]], np.int64)
N_RIVALS = 8


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _joint_share(x, seg_nodes, i, j, d_own, e, jgeo):
    """The point part's joint share H of segment pair (i, j): the product of ramps (:func:`_rival`) of
    the clamped distance of each neighbouring pair less the pair's own d_own, of half-width ``e``
    (0.3 δ_c and a floor, ``_JOINT_RAMP``); ``jgeo[r, 6]`` gets ``∂H/∂d_r`` at fixed e and
    ``jgeo[r, 0:5]`` rival r's closest points and normal.

    Across a joint of a straight fiber the two pairs' shares sum to 1 (their ramps see the same
    difference with opposite signs), equal distances giving ½ each; a free end has no rival (its
    cap is a contact surface). A diagonal rival (both segments moved on) cuts the pair only once it is
    closer by more than the ramp (its ramp shifted by e): at a crossing on a joint of each fiber the
    four pairs then share it by ¼, and a pair whose clamped points sit on both joints while the
    crossing is on the diagonal pair gets nothing. With the ramps of finite width and their gradient
    in the force (:func:`_joint_share_forces`), ``H Π_point`` is continuous and conservative where
    a crossing moves from one pair to the next, and where two crossings of bent fibers merge (a
    secondary minimum of the distance fades as its depth below the rival's goes to 0)."""
    nodes = (seg_nodes[i, 0], seg_nodes[i, 1], seg_nodes[j, 0], seg_nodes[j, 1], _prev_node(seg_nodes, i),
             _next_node(seg_nodes, i), _prev_node(seg_nodes, j), _next_node(seg_nodes, j))
    h = 1.0
    for r in range(N_RIVALS):
        rw = _RIVAL_ROWS[r]
        f, fp = _rival(x, (nodes[rw[0]], nodes[rw[1]], nodes[rw[2]], nodes[rw[3]]), d_own, e if r >= 4 else 0.0,
                       e, jgeo[r])
        if f == 0.0:  # a rival owns the crossing (its ramp is flat there): no share, no gradient
            for q in range(N_RIVALS):
                jgeo[q, 6] = 0.0
            return 0.0
        jgeo[r, 5] = f
        jgeo[r, 6] = fp
        h *= f
    for r in range(N_RIVALS):
        g = jgeo[r, 6]
        if g != 0.0:
            for q in range(N_RIVALS):
                if q != r:
                    g *= jgeo[q, 5]
        jgeo[r, 6] = g
    return h


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _joint_share_forces(blk, jgeo, own, ce, k):
    """The forces ``k ∇H`` (k = −w Π_point) of the joint share (:func:`_joint_share`, its derivatives in
    ``jgeo``) into the pair's block ``blk`` (rows as ``_RIVAL_ROWS``). Each ramp sees (d_r − d_own)/e
    with e = c δ_c + e_0, δ_c = r_i + r_j − d_own (``ce`` = c/e), so ∇ of its argument is
    (∇d_r − (1 − c (d_r − d_own)/e) ∇d_own)/e; ∇d: each clamped distance's unit normal at its closest
    points (``own = (s_c, t_c, n)``), shared linearly by its segments' nodes."""
    gown = 0.0
    for r in range(N_RIVALS):
        g = k * jgeo[r, 6]
        if g == 0.0:
            continue
        gown += g * (1.0 - ce * jgeo[r, 7])
        sn = jgeo[r, 0]
        tn = jgeo[r, 1]
        rw = _RIVAL_ROWS[r]
        for c in range(3):
            nc = g * jgeo[r, 2 + c]
            blk[rw[0], c] += (1.0 - sn) * nc
            blk[rw[1], c] += sn * nc
            blk[rw[2], c] -= (1.0 - tn) * nc
            blk[rw[3], c] -= tn * nc
    if gown != 0.0:
        sc = own[0]
        tc = own[1]
        for c in range(3):
            nc = gown * own[2 + c]
            blk[0, c] -= (1.0 - sc) * nc
            blk[1, c] -= sc * nc
            blk[2, c] += (1.0 - tc) * nc
            blk[3, c] += tc * nc


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def _blend_forces(f_out, nodes4, a0, b0, ta, tb, geo, gd, G):
    """The blend's forces: ``gd = ∂Π/∂δ_c`` through w (hertz_oriented's ellipse) along the clamped
    closest points' normal, like the point force, and ``G = ∂Π/∂Φ`` (the blend's derivative and the
    point law's own angle dependence) as a couple on each segment through
    ``∂Φ/∂t_A = −σ(t̂_B − c t̂_A)/(|t_A| sin Φ)``. ``geo = (s_c, t_c, dist², r_i + r_j, aa, bb, ab)``."""
    na0, na1, nb0, nb1 = nodes4
    sc, tc, dist2, rr, aa, bb, ab = geo
    if gd != 0.0:
        d_own = math.sqrt(dist2)
        if d_own > 1e-14 * rr:
            inv = gd / d_own
            for c in range(3):
                fc_ = (a0[c] + sc * ta[c] - b0[c] - tc * tb[c]) * inv
                f_out[na0, c] += (1.0 - sc) * fc_
                f_out[na1, c] += sc * fc_
                f_out[nb0, c] -= (1.0 - tc) * fc_
                f_out[nb1, c] -= tc * fc_
    if G != 0.0:
        la = math.sqrt(aa)
        lb = math.sqrt(bb)
        sg = 1.0 if ab >= 0.0 else -1.0
        sphi = math.sqrt(max(aa * bb - ab * ab, 0.0)) / (la * lb)
        if sphi > 1e-12:
            fa = G * sg / (sphi * la * lb)   # −G ∂Φ/∂t_A = fa (t_B − (ab/aa) t_A)
            ca = ab / aa
            cb = ab / bb
            for c in range(3):
                ga = fa * (tb[c] - ca * ta[c])  # force on a1 (−∂Π/∂t_A), −ga on a0
                gb = fa * (ta[c] - cb * tb[c])
                f_out[na1, c] += ga
                f_out[na0, c] -= ga
                f_out[nb1, c] += gb
                f_out[nb0, c] -= gb


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _compact_look(out):
    """Whether the look list sits at the front of ``out.active``: the records keep both a gap and an
    active list (:func:`_look_list`)."""
    return out.gap.shape[0] > 0 and out.active.shape[0] > 0


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _look_list(out, n_pairs, reach):
    """The number of pairs to evaluate this step. With both a gap and an active list
    (:func:`_compact_look`), one branch-free pass lists the pairs within reach at the front of
    ``out.active`` (most candidates of a bundle are beyond reach; their fn stays 0 from their last
    look, or from the neighbour-list build); otherwise every candidate, in order."""
    if not _compact_look(out):
        return n_pairs
    c_gap = out.gap
    n_look = 0
    look = out.active
    for k in range(n_pairs):
        look[n_look] = k
        n_look += 1 if c_gap[k] <= reach else 0
    return n_look


# record_pair inlined into the merge (the serial pass has no reference counts to take for its arguments)
_record_pair = njit(cache=True, fastmath=True, error_model="numpy", inline="always")(record_pair.py_func)

# columns of a pair's result row in the contact pass (:func:`_pairs_pass`): its force block (rows
# a0, a1, b0, b1 of the pair's nodes, then the far nodes of the segments before and after each,
# 3 components each), its accumulator
# (:func:`fiberpipe.solver.contact_pairs.record_pair`), its crossing angle, its new skip threshold, and
# for the merge after the tasks its energy and its outcome, and whether the joint share's forces
# reach the far nodes (rows 4–7 of the block; zeros otherwise, which the merge then skips)
_R_BLOCK, _R_REC, _R_PHI, _R_GAP, _R_ENERGY, _R_OUTCOME, _R_FAR, _R_PAIR = 0, 24, 32, 33, 34, 35, 36, 37
N_ROW = 38
# what a pair's evaluation found: beyond reach (nothing to do), beyond touch (a new threshold in the
# row), within touch but no force, in contact
_SKIPPED, _APART, _CLOSE, _TOUCHING = 0, 1, 2, 3


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _merge_forces(f_out, seg_nodes, pairs, k, rows, r, owned):
    """Pair ``k``'s force block ``rows[r]`` onto its four nodes and, where the joint share's forces
    reach them, the far nodes of their neighbouring segments: those of the nodes ``owned = (lo, hi)``
    (``lo ≤ n < hi``), each node's additions in the same order whatever the range."""
    i = pairs[k, 0]
    j = pairs[k, 1]
    lo, hi = owned
    for q, n in enumerate((seg_nodes[i, 0], seg_nodes[i, 1], seg_nodes[j, 0], seg_nodes[j, 1])):
        if lo <= n < hi:
            for c in range(3):
                f_out[n, c] += rows[r, _R_BLOCK + 3 * q + c]
    # rows 4–7: the far nodes of the neighbouring segments, through the joint share's gradient (only
    # with the point part in touch: zeros for the other pairs, most of a bundle's line contacts)
    if rows[r, _R_FAR] == 0.0:
        return
    for q, n in enumerate((_prev_node(seg_nodes, i), _next_node(seg_nodes, i), _prev_node(seg_nodes, j),
                           _next_node(seg_nodes, j))):
        if n >= 0 and lo <= n < hi:
            for c in range(3):
                f_out[n, c] += rows[r, _R_BLOCK + 12 + 3 * q + c]


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _merge_pair(f_out, seg_nodes, pairs, out, k, rows, r, outcome, n_active, use_list, use_share):
    """Pair ``k``'s result row ``rows[r]`` into the records ``out`` and its force block onto its four
    nodes and the far nodes of their neighbouring segments (the pair's fn is reset first: 0 unless in
    contact); returns the count of pairs in contact."""
    out.fn[k] = 0.0
    if outcome == _APART:
        if out.gap.shape[0] > 0:
            out.gap[k] = rows[r, _R_GAP]
        return n_active
    if outcome != _TOUCHING:
        return n_active
    _merge_forces(f_out, seg_nodes, pairs, k, rows, r, (0, f_out.shape[0]))
    return _record_pair(out, k, rows[r, _R_REC:_R_REC + 8], rows[r, _R_PHI], n_active, use_list, use_share)


# pairs ahead whose nodes' positions the pass prefetches (their segments' node rows twice as far)
_AHEAD = 2
# pairs per task of the threaded pass, at least: a task costs its start and its scratch arrays
PAIR_TASK_MIN = 32
# tasks of the threaded pass: more than the threads, so a task that meets many contacts is
# balanced by the others
_PAIR_TASKS = 8
# look-list entries per chunk of the threaded pass: result rows of 2.4 MB
_PAIR_CHUNK = 8192


def _pairs_range(x, seg_nodes, seg_radius, seg_arc, pairs, law_id, law_params, gxi, gw, ds, f_out, out, c_off,
                 span, sink, scratch):
    """Entries ``lo`` … ``hi − 1`` of the look list (:func:`_look_list`) of :func:`contact_forces_pot`
    (``span = (lo, hi, reach)``), with one task's scratch (``rec``, ``geo``, ``blk``, ``gbuf``, ``jgeo``
    of :func:`_pass_work`): each pair merged at once (``_THREADS`` False; returns the energy and the
    count of pairs in contact), or (``_THREADS``) each pair's records written in place (``sink =
    (rows, touch, recs, base)``: ``recs`` the records built from their arrays in the task, as a
    structure passed into it loses its writes) and a pair with a force or an energy written to its
    result row ``rows[kk − base]`` and listed in ``touch[lo − base:]`` for the merge after the tasks,
    which lists the pairs in contact in order and adds their forces (returns zero energy and the
    length of that list)."""
    lo, hi, reach = span
    rows, touch, recs, base = sink
    n_touch = 0
    rec, geo, blk, gbuf, jgeo = scratch
    use_list = out.active.shape[0] > 0
    use_share = out.share.shape[0] > 0
    look = out.active
    c_gap = out.gap
    use_gap = c_gap.shape[0] > 0
    compact = _compact_look(out)
    use_off = c_off.shape[0] > 0
    energy = 0.0
    n_active = 0
    a0 = geo[0]
    b0 = geo[1]
    ta = geo[2]
    tb = geo[3]
    loc = (0, 1, 2, 3)  # the block's rows: the pair's nodes a0, a1, b0, b1
    for kk in range(lo, hi):
        k = look[kk] if compact else kk
        ri = kk - base if _THREADS else 0  # the pair's result row (rows from the chunk's first entry on)
        # the positions of the pairs a few places ahead, on their way while this one is evaluated
        # (fiberpipe._prefetch; a hint, without effect on the results)
        if kk + 2 * _AHEAD < hi:
            k2 = look[kk + 2 * _AHEAD] if compact else kk + 2 * _AHEAD
            prefetch_row(seg_nodes, pairs[k2, 0])
            prefetch_row(seg_nodes, pairs[k2, 1])
        if kk + _AHEAD < hi:
            k1 = look[kk + _AHEAD] if compact else kk + _AHEAD
            prefetch_row(x, seg_nodes[pairs[k1, 0], 0])
            prefetch_row(x, seg_nodes[pairs[k1, 0], 1])
            prefetch_row(x, seg_nodes[pairs[k1, 1], 0])
            prefetch_row(x, seg_nodes[pairs[k1, 1], 1])
        outcome = _SKIPPED
        e = 0.0
        for _ in range(1):  # one pass; a break ends the pair's evaluation at its outcome
            if use_gap and c_gap[k] > reach:
                break
            i = pairs[k, 0]
            j = pairs[k, 1]
            ra = seg_radius[i]
            rb = seg_radius[j]
            rr = ra + rb
            off = c_off[k] if use_off else 0.0
            for c in range(3):
                a0[c] = x[seg_nodes[i, 0], c]
                b0[c] = x[seg_nodes[j, 0], c]
                ta[c] = x[seg_nodes[i, 1], c] - a0[c]
                tb[c] = x[seg_nodes[j, 1], c] - b0[c]
            dist2, sc, tc = segment_distance2_s(a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2],
                                                 ta[0], ta[1], ta[2], tb[0], tb[1], tb[2])
            if dist2 >= rr * rr:
                if _THREADS:  # settled here: the merge visits only the pairs with a force or an energy
                    if recs.gap.shape[0] > 0:
                        recs.gap[k] = reach + math.sqrt(dist2) - rr
                else:
                    rows[ri, _R_GAP] = reach + math.sqrt(dist2) - rr
                outcome = _APART
                break
            for c in range(8):
                rec[c] = 0.0
            for r in range(8):
                for c in range(3):
                    blk[r, c] = 0.0
            aa = ta[0] * ta[0] + ta[1] * ta[1] + ta[2] * ta[2]
            bb = tb[0] * tb[0] + tb[1] * tb[1] + tb[2] * tb[2]
            ab = ta[0] * tb[0] + ta[1] * tb[1] + ta[2] * tb[2]
            phi = crossing_angle(ta[0], ta[1], ta[2], tb[0], tb[1], tb[2], aa, bb, ab)
            d_own = math.sqrt(dist2)
            delta = rr - d_own - off
            n_a, n_b, near_end = _line_points(x, seg_nodes, i, j, rr, gxi, gw, off, gbuf)
            w, dw, dw_dd, fp, ep, dep = _pair_blend_point(law_id, law_params, delta, ds, ra, rb, phi)
            e_point = 0.0   # s_joint Π_point (unweighted by w)
            de_point = 0.0  # its ∂/∂Φ at fixed positions of the closest points
            far = 0.0
            if w > 0.0:
                ej = _JOINT_RAMP * delta + _JOINT_RAMP_FLOOR * rr  # the ramps' half-width
                wst = _joint_share(x, seg_nodes, i, j, d_own, ej, jgeo) if delta > 0.0 else 1.0
                if wst > 0.0 and delta > 0.0 and d_own > 1e-14 * rr:
                    gp = onset(delta, ds)[1]
                    e_point = wst * ep
                    de_point = wst * dep
                    inv = 1.0 / d_own  # the closest points' unit normal, B to A
                    nx = (a0[0] + sc * ta[0] - b0[0] - tc * tb[0]) * inv
                    ny = (a0[1] + sc * ta[1] - b0[1] - tc * tb[1]) * inv
                    nz = (a0[2] + sc * ta[2] - b0[2] - tc * tb[2]) * inv
                    _joint_share_forces(blk, jgeo, (sc, tc, nx, ny, nz), _JOINT_RAMP / ej, -w * ep)
                    far = 1.0
                    rec[7] += w * wst
                    fm = w * wst * fp * gp
                    apply_line_point(blk, loc, sc, tc, fm * nx, fm * ny, fm * nz, fm, delta, rec, 1.0)
            e_line = 0.0  # Π_line (unweighted by 1 − w)
            if w < 1.0:
                half = 0.5 * (1.0 - w)
                el = _line_part(gbuf, (n_a, n_b, near_end), loc,
                                (seg_arc[i, 1] - seg_arc[i, 0], seg_arc[j, 1] - seg_arc[j, 0], ra, rb), law_id,
                                law_params, half, ds, blk, rec)
                if near_end and _end_weight_pass(x, seg_nodes, gbuf, (n_a, n_b), (i, j), blk):
                    far = 1.0
                e_line = el / (1.0 - w)
            _blend_forces(blk, loc, a0, b0, ta, tb, (sc, tc, dist2, rr, aa, bb, ab),
                          dw_dd * (e_point - e_line), dw * (e_point - e_line) + w * de_point)
            e = (1.0 - w) * e_line + w * e_point
            if not rec[0] > 0.0:  # record_pair's test: no contact point carries a force
                outcome = _CLOSE
                break
            outcome = _TOUCHING
            for r in range(8):
                for c in range(3):
                    rows[ri, _R_BLOCK + 3 * r + c] = blk[r, c]
            if _THREADS:  # the records at once; the merge adds the forces and lists the pair
                _record_pair(recs, k, rec, phi, 0, False, use_share)
            else:
                for c in range(8):
                    rows[ri, _R_REC + c] = rec[c]
                rows[ri, _R_PHI] = phi
            rows[ri, _R_FAR] = far
        if _THREADS:
            if outcome != _TOUCHING:
                recs.fn[k] = 0.0
            if outcome == _TOUCHING or e != 0.0:
                rows[ri, _R_OUTCOME] = outcome
                rows[ri, _R_ENERGY] = e
                touch[lo - base + n_touch] = ri
                n_touch += 1
        else:  # one task: merged at once, in the same order
            n_active = _merge_pair(f_out, seg_nodes, pairs, out, k, rows, ri, outcome, n_active, use_list,
                                   use_share)
            energy += e
    if _THREADS:
        return 0.0, n_touch
    return energy, n_active


def _pairs_pass(x, seg_nodes, seg_radius, seg_arc, pairs, law_id, law_params, gxi, gw, ds, f_out, out, c_off, reach,
                chunk, work):
    """The pairs of the look list (:func:`_look_list`) of :func:`contact_forces_pot`: one task
    (``_THREADS`` False; ``chunk = (0, n_look, 0.0, 0)``), or the entries ``lo … hi − 1`` of
    ``chunk = (lo, hi, energy, n_active)`` (the sums of the chunks before) in ``prange`` tasks of
    consecutive pairs, merged after them in order. ``work``: the pass's scratch arrays
    (:func:`_pass_work`), one set per task."""
    # Strategy: each pair writes only its own result row (its forces summed in a 4-node block, its
    # records, its new skip threshold) and the rows are merged in the order of the pairs, at once
    # (one task) or after the tasks, so the sums are the same whichever task evaluated a pair. A task
    # settles the pairs that add no force and no energy itself (most of a bundle's candidates: their
    # fn reset, their new threshold), so the serial merge visits only the pairs in touch. The
    # records are written in the merge: an array reached through a structure passed into a prange
    # body, or through a tuple holding it, loses the body's writes (numba 0.68). A pair listed as in
    # contact is written at a slot of the look list the merge has already read (n_active ≤ kk).
    # Each task's pairs run in _pairs_range, compiled without reference counts in both passes: the
    # prange body takes its counts once per task, not per pair and Gauss point.
    rows, t_rec, t_geo, t_blk, t_gbuf, t_jgeo, touch, n_touch = work
    fn, normal, s, t, phi, delta, share, fsum, gap, active = out
    base, end, energy_before, n_active_before = chunk
    if not _THREADS:
        return _pairs_range_of(x, seg_nodes, seg_radius, seg_arc, pairs, law_id, law_params, gxi, gw, ds, f_out, out,
                               c_off, (0, end, reach), (rows, touch, out, 0),
                               (t_rec[0], t_geo[0], t_blk[0], t_gbuf[0], t_jgeo[0]))
    n_tasks = t_rec.shape[0]
    n_rows = end - base
    for task in prange(n_tasks):
        n_touch[task] = _pairs_range_of(x, seg_nodes, seg_radius, seg_arc, pairs, law_id, law_params, gxi, gw, ds,
                                        f_out, out, c_off,
                                        (base + task * n_rows // n_tasks, base + (task + 1) * n_rows // n_tasks, reach),
                                        (rows, touch, PairRecords(fn, normal, s, t, phi, delta, share, fsum, gap,
                                                                  active), base),
                                        (t_rec[task], t_geo[task], t_blk[task], t_gbuf[task], t_jgeo[task]))[1]
    listed = (touch, n_touch, n_rows, base)
    energy, n_active = _merge_rows(out, rows, listed, (energy_before, n_active_before))
    # the forces in pair order, each task adding those on its share of the nodes (every node's
    # additions in the serial pass's order: the same sums bit for bit)
    n_nodes = f_out.shape[0]
    n_owners = SCATTER_TASKS
    for owner in prange(n_owners):
        _scatter_owned(f_out, seg_nodes, pairs, rows, listed,
                       (owner * n_nodes // n_owners, (owner + 1) * n_nodes // n_owners))
    return energy, n_active


@njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)
def _scatter_owned(f_out, seg_nodes, pairs, rows, listed, owned):
    """The forces of the pairs in contact that :func:`_merge_rows` listed (``listed``, its pair
    indices in the rows' ``_R_PAIR`` column), in pair order, onto the nodes ``owned = (lo, hi)``."""
    touch, n_touch, n_rows, _ = listed
    n_tasks = n_touch.shape[0]
    for task in range(n_tasks):
        lo = task * n_rows // n_tasks
        for m in range(lo, lo + n_touch[task]):
            r = touch[m]
            if rows[r, _R_OUTCOME] == _TOUCHING:
                _merge_forces(f_out, seg_nodes, pairs, int(rows[r, _R_PAIR]), rows, r, owned)


@njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)
def _merge_rows(out, rows, listed, sums):
    """The threaded pass's merge after its tasks (:func:`_pairs_pass`): the result rows its tasks
    listed (``listed = (touch, n_touch, n_rows, base)``: each task's rows from its first entry of
    the chunk on, ``n_touch`` per task; row r is the look list's entry ``base + r``) into the list of
    pairs in contact, in pair order (the tasks wrote the records), each row's pair index into its
    ``_R_PAIR`` column for the forces' scatter (:func:`_scatter_owned`); returns ``(energy,
    n_active)`` continued from ``sums`` (those of the chunks before). The pairs the tasks did not list add
    nothing: no force, and an energy of 0, which leaves the sum's bits as they are.
    Compiled without reference counts, as the serial pass (a count per pair for the row slice it
    hands to the records otherwise; LLVM removes most of them, and the threaded pass measured the
    same either way within ±4 % on the compacted 400-fiber bundle)."""
    use_list = out.active.shape[0] > 0
    look = out.active
    compact = _compact_look(out)
    touch, n_touch, n_rows, base = listed
    n_tasks = n_touch.shape[0]
    energy, n_active = sums
    for task in range(n_tasks):
        lo = task * n_rows // n_tasks
        for m in range(lo, lo + n_touch[task]):
            r = touch[m]
            k = look[base + r] if compact else base + r
            rows[r, _R_PAIR] = k
            if rows[r, _R_OUTCOME] == _TOUCHING:  # in contact: its records are written (record_pair's count)
                if use_list:
                    out.active[n_active] = k
                n_active += 1
            energy += rows[r, _R_ENERGY]
    return energy, n_active


def _contact_forces_pot(x, seg_nodes, seg_radius, seg_arc, pairs, n_pairs, law_id, law_params, gxi, gw, ds, f_out,
                        out, c_off, reach):
    """Normal contact forces as minus the gradient of Σ_pairs Π_AB (module docstring), accumulated into
    ``f_out``.

    Parameters
    ----------
    x : (N, 3) float64, m — node positions.
    seg_nodes : (E, 2) int64 — node indices of each segment. seg_radius : (E,) float64, m.
    seg_arc : (E, 2) float64, m — the arc length of each segment's ends along its fiber (their
        difference, the reference length, weighs the line part's Gauss points).
    pairs : (P, 2) int64 — candidate segment pairs (i, j), only the first ``n_pairs`` rows are used.
    law_id : int, law_params : float64 array — see :mod:`fiberpipe.solver.laws`.
    gxi, gw : Gauss nodes on (0, 1) and weights summing to 1
        (:func:`fiberpipe.solver.contact_pairs.gauss_points`).
    ds : float, m — the onset length δ_s (0: the laws as they are).
    f_out : (N, 3) float64, N — accumulated into (not zeroed).
    out : :class:`fiberpipe.solver.contact_state.PairRecords` — per pair, out: ``fn``, ``normal``,
        ``s``, ``t``, ``phi``, ``delta``; if size > 0, ``share`` (the pair's contact share: point part
        its blend weight × joint share, line part the weighted fraction of the segment length in
        contact; a full-length parallel contact or a crossing counts 1), ``fsum`` (Σ|f| of its
        contact points [N]) and ``active`` (the indices of the pairs in contact, in order, so that
        friction and statistics visit only those). ``gap`` (size > 0): in/out, each pair's skip
        threshold, with ``reach``.
    c_off : (P,) float64, m — per-pair initial-overlap offset subtracted from every penetration of
        the pair (size 0: none).
    reach : float, m — twice a bound on the path any node has travelled since the last
        neighbour-list build (``2 Σ Δt max_i |v_i|``, non-decreasing). A pair with ``gap > reach``
        is skipped: when it was last evaluated, at reach ``R_c``, its clamped centre-line distance
        minus ``r_i + r_j`` was ``g_c`` and ``gap = R_c + g_c``; every point of a segment is a convex
        combination of its nodes, so since then the gap closed by at most ``reach − R_c``. The
        build sets ``gap = g_b`` at reach 0; every evaluated pair found apart sets it anew.

    Returns ``(energy, n_active)``: the potential itself [J] and the number of pairs in contact.

    ``contact_forces_pot`` runs the pairs in one task; ``contact_forces_pot_threads``
    (``solver.threads`` > 1) in ``prange`` tasks once there are pairs for two, with the same
    forces, records and energy bit for bit."""
    n_look = _look_list(out, n_pairs, reach)
    if _THREADS and n_look >= 2 * PAIR_TASK_MIN:
        # chunks of the look list: the result rows stay a few MB, which the allocator reuses from step
        # to step (a larger block is mapped afresh each step, and its first writes fault every page:
        # a squeezed 1000-fiber bundle ran no faster on two threads than on one)
        n_chunk = min(n_look, _PAIR_CHUNK)
        work = _pass_work(n_chunk, task_count(n_chunk, PAIR_TASK_MIN, _PAIR_TASKS), gxi.shape[0])
        energy = 0.0
        n_active = 0
        for lo in range(0, n_look, n_chunk):
            energy, n_active = _pairs_tasks(x, seg_nodes, seg_radius, seg_arc, pairs, law_id, law_params, gxi, gw, ds,
                                            f_out, out, c_off, reach,
                                            (lo, min(n_look, lo + n_chunk), energy, n_active), work)
        return energy, n_active
    return _pairs_serial(x, seg_nodes, seg_radius, seg_arc, pairs, law_id, law_params, gxi, gw, ds, f_out, out, c_off,
                         reach, (0, n_look, 0.0, 0), _pass_work(0, 1, gxi.shape[0]))


@njit(cache=True, _nrt=True)
def _pass_work(n_rows, n_tasks, n_gauss):
    """Scratch arrays of :func:`_pairs_pass`: ``n_rows`` result rows kept for the merge after the tasks
    (0: one row, reused; the serial pass merges each pair at once), and per task a pair's accumulator,
    its segments' start nodes and tangents (a0, b0, ta, tb), its force block, its Gauss-point buffer
    and its joint share's rivals (:func:`_joint_share`); the threaded pass's rows to merge (the look
    list's entries with a force or an energy, per task from its first entry on) and their count per
    task."""
    m = max(n_rows, 1)
    return (np.empty((m, N_ROW)), np.zeros((n_tasks, 8)),
            np.empty((n_tasks, 4, 3)), np.empty((n_tasks, 8, 3)), np.empty((n_tasks, 2 * n_gauss, N_GP_COLUMNS)),
            np.empty((n_tasks, N_RIVALS, 8)), np.empty(m, np.int64), np.zeros(n_tasks, np.int64))


_THREADS = False
# The serial pass and its two calls (_line_part, _pair_blend_point) run without reference counts
# (``_nrt=False``; the scratch comes from the caller): numba takes and releases a reference, an
# atomic count, for every array it hands to a call or an inlined function or slices, per pair and
# per Gauss point, and LLVM removes only the pairs whose release post-dominates the take. On
# paper-40's saved states the pass costs 30 / 73 µs instead of 61 / 178 µs (early / compacted). The
# two calls stay calls: the serial and the threaded pass then run the same code for them, and their
# results stay equal bit for bit. A function compiled from one without reference counts inherits
# that unless it sets its own (numba's ``nrt`` flag), so every kernel here that allocates, or calls a
# law's own functions, sets ``_nrt=True``.
_pairs_range_of = njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)(_pairs_range)
_pairs_serial = njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)(_pairs_pass)
# Not cached (a parfor kernel linked into a step loop compiled in another process: see
# _kernels_beam.beam_pass_fibers); only the solver.threads > 1 loops use it. Its tasks' pairs run
# in the rows variant of _pairs_range, without reference counts as in the serial pass.
_pairs_range_rows = specialise(_pairs_range, "_pairs_range_rows", {"_THREADS": True}, cache=False, fastmath=True,
                               error_model="numpy", _nrt=False)
# The tasks' loop without reference counts too: both cores counting on the same arrays' records (each
# task's scratch views and arguments) send those cache lines back and forth between them.
_pairs_tasks = specialise(_pairs_pass, "_pairs_tasks", {"_THREADS": True, "_pairs_range_of": _pairs_range_rows},
                          cache=False, fastmath=True, error_model="numpy", parallel=True, _nrt=False)
contact_forces_pot = njit(cache=True, fastmath=True, error_model="numpy", _nrt=True)(_contact_forces_pot)
contact_forces_pot_threads = specialise(_contact_forces_pot, "contact_forces_pot_threads", {"_THREADS": True},
                                        cache=False, fastmath=True, error_model="numpy", _nrt=True)


_LAW_KERNELS: dict = {}


def potential_kernels_for(law, threads: bool = False):
    """:func:`contact_forces_pot` (``threads``: :func:`contact_forces_pot_threads`) for ``law``: the
    built-in kernel for a law without ``kernels``; else a copy specialised on the law's own jitted
    ``line``, ``point`` and ``weight_point`` functions (the derivatives of its point share and of its
    point energy in Φ by central differences; compiled once per process and law class, see
    ``_specialise``)."""
    if law.kernels is None:
        return contact_forces_pot_threads if threads else contact_forces_pot
    key = (type(law), bool(threads))
    if key not in _LAW_KERNELS:
        line, point, weight_point = law.kernels
        tag = type(law).__name__
        flags = dict(fastmath=True, error_model="numpy")
        loads = specialise(_line_loads, f"_line_loads_{tag}", {"law_line": line}, cache=False, _nrt=True, **flags)
        lh = specialise(_line_part, f"_line_part_{tag}", {"_line_loads": loads}, cache=False, _nrt=False, **flags)
        blend = specialise(_pair_blend_point_of_law, f"_pair_blend_point_{tag}",
                           {"law_weight_point": weight_point, "law_point": point}, cache=False, _nrt=True, **flags)
        calls = {"_line_part": lh, "_pair_blend_point": blend}
        pairs_range = specialise(_pairs_range, f"_pairs_range_{tag}", calls, cache=False, _nrt=False, **flags)
        passes = {"_pairs_serial": specialise(_pairs_pass, f"_pairs_serial_{tag}", {"_pairs_range_of": pairs_range},
                                              cache=False, _nrt=False, **flags)}
        if threads:
            rows = specialise(_pairs_range, f"_pairs_range_rows_{tag}", {**calls, "_THREADS": True}, cache=False,
                              _nrt=False, **flags)
            passes["_pairs_tasks"] = specialise(_pairs_pass, f"_pairs_tasks_{tag}",
                                                {"_pairs_range_of": rows, "_THREADS": True}, cache=False,
                                                parallel=True, _nrt=False, **flags)
        _LAW_KERNELS[key] = specialise(_contact_forces_pot, f"contact_forces_pot{'_threads' if threads else ''}_{tag}",
                                       {**passes, "_THREADS": bool(threads)}, cache=False, _nrt=True, **flags)
    return _LAW_KERNELS[key]
