"""Numba kernels for rigid planes (plates, walls), prescribed-motion ramps and external forces.

Penalty contact of the fiber surface against a rigid plane (node-to-plane, lumped): for node ``i``
with radius ``r_i`` and plane ``p`` (axis ``a``, position ``s_p``, outward sign ``σ_p = +1`` when
the plane pushes towards +a, i.e. a lower plane), the penetration is
``δ = r_i − σ_p (x_{i,a} − s_p)``; if ``δ > 0`` the node stores ``½ k_i g(δ)²`` (:func:`plane_onset`,
onset length ``δ_s,i``), gets ``σ_p k_i g g'`` along ``a``, and the plane's reaction (positive when
pressed) grows by ``k_i g g'``. ``k_i`` is chosen against the time step (Belytschko, Liu & Moran,
*Nonlinear Finite Elements*, 2000, §9.4: the penalty adds ``k/m`` to the node's ``ω²``):
``k_i = c_pen m_i (2/Δt)²`` with ``c_pen`` = 0.1 by default; ``δ_s,i`` is a fraction of the node's
radius (0.02 by default).
"""

from __future__ import annotations

import math

from numba import njit

RAMP_LINEAR = 0
RAMP_SMOOTH = 1
RAMP_SMOOTHSTEP = 2

# onset length of the plane penalty as a fraction of the node's radius (5 µm at r = 0.25 mm): the
# stiffness must switch on over many steps of the fastest approach, or nodes rattling on a plane at
# a step near the stability limit gain energy (six undamped fibers pressed at once by 1000 N/m, every
# law, dt_safety 0.9: +3–4 % of the loads' work at 0.004 r, ≤ −0.0001 at 0.02 r); a longer onset
# leaves the fibers deeper in the planes (the static penetration grows by up to half of it)
DEFAULT_ONSET_FRACTION = 0.02

@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def plane_onset(delta, ds):
    """The mapped penetration (g, dg/dδ) of the plane penalty ½ k g(δ)²: g' = 3u² − 2u³ (u = δ/δ_s)
    on [0, δ_s], g = δ − δ_s/2 beyond. g(0) = g'(0) = 0, so force k g g' and stiffness rise from
    zero at first touch and the potential is C²; a penalty ½ k δ₊² switched on at once makes each
    touch or release inside a step create or destroy ½ k (vΔt)² θ(1 − θ) (θ: the fraction of the
    step after touch), a fixed fraction of the impact energy since k ∝ 1/Δt²."""
    if delta >= ds:
        return delta - 0.5 * ds, 1.0
    u = delta / ds
    u2 = u * u
    return ds * u2 * u * (1.0 - 0.5 * u), u2 * (3.0 - 2.0 * u)


def plane_static_penetration(force_over_k_m: float, ds: float) -> float:
    """The penetration δ [m] at which the plane penalty of onset length ``ds`` [m] holds a static force
    F, given F/k [m]: k g(δ) g'(δ) = F (:func:`plane_onset`; g g' is increasing, so the root is unique)."""
    if force_over_k_m <= 0.0:
        return 0.0
    if force_over_k_m >= 0.5 * ds:
        return force_over_k_m + 0.5 * ds
    lo, hi = 0.0, ds
    for _ in range(200):  # bisection to rounding
        mid = 0.5 * (lo + hi)
        g, gp = plane_onset(mid, ds)
        lo, hi = (mid, hi) if g * gp < force_over_k_m else (lo, mid)
    return 0.5 * (lo + hi)


@njit(cache=True, fastmath=True, error_model="numpy")
def ramp_fraction(t, duration, t_accel, mode):
    """Fraction (0…1) of a prescribed displacement reached at time ``t`` (s).

    ``mode`` RAMP_LINEAR: constant velocity ``1/duration`` from t = 0.
    RAMP_SMOOTH: velocity rises from 0 to ``v = 1/(duration − t_accel)`` over ``t_accel`` with a
    smoothstep ``3τ² − 2τ³`` in velocity, stays constant, and falls back to 0 symmetrically, so the
    displacement is ``v t_accel S(τ)``, ``S(τ) = τ³ − τ⁴/2`` during the rises.
    RAMP_SMOOTHSTEP: ``3τ² − 2τ³`` in displacement, τ = t/duration (zero start and end velocity,
    peak velocity 1.5× the mean).
    """
    if t <= 0.0:
        return 0.0
    if t >= duration:
        return 1.0
    if mode == RAMP_LINEAR:
        return t / duration
    if mode == RAMP_SMOOTHSTEP:
        tau = t / duration
        return tau * tau * (3.0 - 2.0 * tau)
    ta = t_accel
    v = 1.0 / (duration - ta)
    if t < ta:
        tau = t / ta
        return v * ta * tau * tau * tau * (1.0 - 0.5 * tau)
    if t > duration - ta:
        tau = (duration - t) / ta
        return 1.0 - v * ta * tau * tau * tau * (1.0 - 0.5 * tau)
    return v * (0.5 * ta + (t - ta))


@njit(cache=True, fastmath=True, error_model="numpy")
def path_entry(t, u_end, duration):
    """``(k, t_start, u_start)``: the entry of a travel table (:func:`path_travel`) that time ``t``
    falls in, with its start time (s) and start travel (m); the last entry from its start on."""
    t0 = 0.0
    u0 = 0.0
    last = u_end.shape[0] - 1
    for k in range(last):
        if t < t0 + duration[k]:
            return k, t0, u0
        t0 += duration[k]
        u0 = u_end[k]
    return last, t0, u0


@njit(cache=True, fastmath=True, error_model="numpy")
def path_travel(t, u_end, duration, t_accel, mode):
    """Travel (m) at time ``t`` (s) of a prescribed path, and the entry of the path it is in.

    The path is a table of entries run in turn from t = 0 and u = 0: entry ``k`` lasts
    ``duration[k]`` and takes the travel from the previous entry's end value (0 for the first) to
    ``u_end[k]`` with :func:`ramp_fraction` (``t_accel[k]``, ``mode``); a hold is an entry that keeps
    its travel. After the last entry the travel stays at ``u_end[-1]``. With one entry this is
    ``u_end[0] · ramp_fraction(t, duration[0], t_accel[0], mode)``.

    Returns ``(travel, k)``; before t = 0, ``(0, 0)``.
    """
    k, t0, u0 = path_entry(t, u_end, duration)
    return u0 + (u_end[k] - u0) * ramp_fraction(t - t0, duration[k], t_accel[k], mode), k


@njit(cache=True, fastmath=True, error_model="numpy")
def plane_position(t, pos0, sign, u_end, duration, t_accel, mode):
    """A plane's position (m) at time ``t`` on its travel table (:func:`path_travel`), ``pos0 + sign·u``,
    evaluated as ``(pos0 + sign·u_start) + sign·Δu_k·r`` (for one entry ``pos0 + sign·U·r``)."""
    k, t0, u0 = path_entry(t, u_end, duration)
    return (pos0 + sign * u0) + sign * (u_end[k] - u0) * ramp_fraction(t - t0, duration[k], t_accel[k], mode)


@njit(cache=True, fastmath=True, error_model="numpy")
def path_delta(t1, t0, u_end, duration, t_accel, mode):
    """The travel from time ``t0`` to ``t1`` (m) of a path (:func:`path_travel`): within one entry
    ``Δu_k (r(t1) − r(t0))`` with r its ramp fraction (for one entry ``U (r(t1) − r(t0))``, the
    one-segment ramp's increment); across entries u(t1) − u(t0)."""
    k1, s1, v1 = path_entry(t1, u_end, duration)
    k0, _, _ = path_entry(t0, u_end, duration)
    if k1 == k0:
        return (u_end[k1] - v1) * (ramp_fraction(t1 - s1, duration[k1], t_accel[k1], mode)
                                   - ramp_fraction(t0 - s1, duration[k1], t_accel[k1], mode))
    return (path_travel(t1, u_end, duration, t_accel, mode)[0]
            - path_travel(t0, u_end, duration, t_accel, mode)[0])


#: margin of the step loop's list of nodes near each plane, × the largest fiber radius: a node
#: 0.2 r away from touching needs ≈ 2000 steps at 0.3 m/s to touch (paper-40), so the list is taken
#: again about that often, at the cost of one pass over all nodes per plane
PLANE_LIST_MARGIN = 0.2


@njit(cache=True, fastmath=True, error_model="numpy")
def plane_contacts(x, radius_node, k_pen, onset_m, pl_axis, pl_sign, pl_pos, f, pl_force, pen_idx, pen_f, rect):
    """Penalty forces of rigid planes on the nodes.

    Parameters
    ----------
    x : (N, 3) float64, m — node positions.
    radius_node : (N,) float64, m — fiber radius at each node.
    k_pen : (N,) float64, N/m — penalty stiffness per node.
    onset_m : (N,) float64, m — penalty onset length per node (:func:`plane_onset`).
    pl_axis : (P,) int64 — axis (0, 1, 2) normal to each plane.
    pl_sign : (P,) float64 — +1 if the plane pushes towards +axis (lower), −1 otherwise.
    pl_pos : (P,) float64, m — current plane positions.
    f : (N, 3) float64, N — accumulated into.
    pl_force : (P,) float64, N — out: reaction on each plane, positive when pressed.
    pen_idx : (M,) int64, pen_f : (M,) float64 — out: the touching nodes' indices and the force
        component along their plane's axis (signed), for the work bookkeeping; M ≥ N·P.
    rect : ``(half, centre)``, (P, 2) float64 each, m — a finite plane's rectangle: its half extents
        and centre along the plane's two axes in x, y, z order (:func:`in_plane_axes`); a node whose
        centre lies outside it does not touch the plane. ``half[p, 0] = 0``: plane p is infinite.

    Returns
    -------
    (int, float) — the number of (node, plane) contacts written to ``pen_idx`` (the plane of contact
    ``c`` is encoded as ``pen_idx[c] = node * 3 + axis``) and the stored penalty energy Σ ½ k g² [J]
    (:func:`plane_onset`).
    """
    return _plane_pass(x, radius_node, k_pen, onset_m, pl_axis, pl_sign, pl_pos, f, pl_force, pen_idx, pen_f,
                       pen_idx, pen_idx, pen_f, rect, False)


@njit(cache=True, fastmath=True, error_model="numpy")
def plane_contacts_listed(x, radius_node, k_pen, onset_m, pl_axis, pl_sign, pl_pos, f, pl_force, pen_idx, pen_f,
                          cand_idx, cand_off, cand_fn, rect):
    """:func:`plane_contacts` over the nodes :func:`plane_candidates` listed near each plane (in node
    order, so the sums are the same to the last bit), the caller keeping the list valid; each listed
    node's normal force ``k g g'`` [N] into ``cand_fn`` (−1 where it does not touch), which the
    planes' friction reads (:func:`fiberpipe.solver.friction.plane_friction`)."""
    return _plane_pass(x, radius_node, k_pen, onset_m, pl_axis, pl_sign, pl_pos, f, pl_force, pen_idx, pen_f,
                       cand_idx, cand_off, cand_fn, rect, True)


@njit(inline="always", cache=True, fastmath=True, error_model="numpy")
def _plane_pass(x, radius_node, k_pen, onset_m, pl_axis, pl_sign, pl_pos, f, pl_force, pen_idx, pen_f, cand_idx,
                cand_off, cand_fn, rect, listed):
    """The body of :func:`plane_contacts` (every node, ``listed`` False) and of
    :func:`plane_contacts_listed` (the nodes ``cand_idx[cand_off[p]:cand_off[p + 1]]`` of plane p)."""
    n_pen = 0
    energy = 0.0
    half, centre = rect
    # plane outer, node inner: a tight loop over the nodes per plane (most nodes do not touch)
    for p in range(pl_axis.shape[0]):
        ax = pl_axis[p]
        sg = pl_sign[p]
        pos = pl_pos[p]
        finite = half[p, 0] > 0.0
        u, w = in_plane_axes(ax)
        fsum = 0.0
        lo = cand_off[p] if listed else 0
        hi = cand_off[p + 1] if listed else x.shape[0]
        for c in range(lo, hi):
            i = cand_idx[c] if listed else c
            d = radius_node[i] - sg * (x[i, ax] - pos)
            if finite and d > 0.0:
                # a finite plate: a node whose centre lies outside its rectangle does not touch it
                if abs(x[i, u] - centre[p, 0]) > half[p, 0] or abs(x[i, w] - centre[p, 1]) > half[p, 1]:
                    d = 0.0
            if d > 0.0:
                g, gp = plane_onset(d, onset_m[i])
                fn = k_pen[i] * g * gp
                energy += 0.5 * k_pen[i] * g * g
                f[i, ax] += sg * fn
                fsum += fn
                pen_idx[n_pen] = i * 3 + ax
                pen_f[n_pen] = sg * fn
                n_pen += 1
                if listed:
                    cand_fn[c] = fn
            elif listed:
                cand_fn[c] = -1.0
        pl_force[p] = fsum
    return n_pen, energy


@njit(cache=True, inline="always")
def in_plane_axes(axis):
    """The two axes of a plane normal to ``axis``, in x, y, z order (axis y: x, then z)."""
    return (1 if axis == 0 else 0), (1 if axis == 2 else 2)


@njit(cache=True, fastmath=True, error_model="numpy")
def plane_candidates(x, radius_node, pl_axis, pl_sign, pl_pos, margin, cand_idx, cand_off):
    """The nodes within ``margin`` [m] of touching each plane: ``cand_idx[cand_off[p]:cand_off[p + 1]]``
    for plane ``p`` (gap ``σ(x_{i,a} − s_p) − r_i < margin``; same planes as :func:`plane_contacts`).

    A node can touch plane ``p`` later only if its gap closed by more than ``margin``, i.e. if the
    node and the plane moved by more than ``margin`` together since: while they have not,
    :func:`plane_contacts_listed` and the planes' friction (:func:`fiberpipe.solver.friction.plane_friction`)
    visit these nodes only (a few hundred) instead of all N per plane.
    cand_idx : (N·P,) int64, cand_off : (P + 1,) int64 — out. Returns the number of candidates.
    """
    n = 0
    cand_off[0] = 0
    for p in range(pl_axis.shape[0]):
        ax = pl_axis[p]
        sg = pl_sign[p]
        pos = pl_pos[p]
        for i in range(x.shape[0]):
            if sg * (x[i, ax] - pos) - radius_node[i] < margin:
                cand_idx[n] = i
                n += 1
        cand_off[p + 1] = n
    return n


@njit(cache=True, fastmath=True, error_model="numpy")
def penalty_power(v, pen_idx, pen_f, n_pen):
    """Σ f·v over the plane contacts written by :func:`plane_contacts` (W)."""
    s = 0.0
    for c in range(n_pen):
        k = pen_idx[c]
        s += pen_f[c] * v[k // 3, k % 3]
    return s
