"""The explicit central-difference step loop (many steps per jitted call).

Central difference / leapfrog (Belytschko, Liu & Moran, *Nonlinear Finite Elements*, 2000,
§6.2.1; Abaqus/Explicit, "Explicit dynamic analysis", Abaqus Analysis User's Guide 6.3.3):

    v_{n+½} = [ (1 − α Δt/2) v_{n−½} + Δt f_n / m ] / (1 + α Δt/2)
    x_{n+1} = x_n + Δt v_{n+½}

and for the rotations (Simo & Wong, IJNME 31, 1991, explicit variant; body angular velocity Ω,
Euler's equations ``J Ω̇ + Ω × J Ω = M_body``, gyroscopic term taken at ``Ω_{n−½}``):

    Ω_{n+½} = [ (1 − α Δt/2) Ω_{n−½} + Δt J⁻¹ (R_nᵀ M_n − Ω_{n−½} × J Ω_{n−½}) ] / (1 + α Δt/2)
    R_{n+1} = R_n exp(Δt Ω_{n+½})        (quaternion: q_{n+1} = q_n ⊗ exp_q(Δt Ω/2))

The mass-proportional damping force is ``−α m v̄`` with ``v̄`` the mean of the two half-step
velocities (so it never destabilises the step); its dissipation ``α m |v̄|² Δt`` goes to ALLVD.

Energy bookkeeping (Abaqus names): ALLKE and ALLSE at t_n from ``v̄`` and the element strains;
ALLWK = constant loads' work ``f_ext · (x_n − x_0)`` plus the reactions of prescribed motions
(plates, drives, clamps) times their displacement increments, the reaction of a prescribed node
being the whole force that imposes its motion, ``m (v_{n+½} − v_{n−½})/Δt − f_n + α m v̄`` (the
damping force acts on the absolute velocity of every node, driven ones included, and its
dissipation there is in ALLVD); ALLPW = work of the plane penalties
on the fibers minus the plates' prescribed work (plus whatever the per-step terms add); ALLFD from
the friction terms only (the contact term's fiber pairs, the planes' friction). Works over a step use ``f_n · v̄ Δt`` (trapezoid, second order).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._specialise import specialise
from ._kernels_beam import PARALLEL_CHUNKS, beam_pass_all, beam_pass_fibers, element_forces_exact
from ._kernels_boundary import ramp_fraction
from .layout import (ACC_FD, ACC_PW, ACC_SIZE, ACC_STORED, ACC_STORED0, ACC_V2_MAX, ACC_VD, ACC_WF, ACC_WF_NEXT, ACC_WK,
                     H_CONTACTS, H_FD, H_KE, H_KE_LF, H_PW, H_SE, H_SEGMENT, H_STORED, H_TIME, H_VD, H_VD_LF, H_WF, H_WK,
                     STATUS_ENERGY, STATUS_NAN, STATUS_OK, STATUS_RUNAWAY, STATUS_SPEED)
from .terms.base import no_forces
from .terms.planes import eval_planes, finish_planes, record_planes

_FLAGS = dict(cache=True, fastmath=True, error_model="numpy")


# ---- the passes of one step, in the manner of warp.sim's one eval_* per force term ------------------


@njit(inline="always", **_FLAGS)
def eval_external(f, mom, f_ext):
    """Reset the force and moment arrays to the constant loads ``f_ext`` (N, 3) (gravity, point and
    line loads) and zero."""
    # element by element: an array assignment compiles numba's shape-mismatch message (seconds of
    # compile time for a copy)
    for i in range(f.shape[0]):
        for c in range(3):
            f[i, c] = f_ext[i, c]
            mom[i, c] = 0.0


@njit(inline="always", **_FLAGS)
def eval_drives(drives, t, dt):
    """The drives' prescribed velocities over [t_n, t_{n+1}] (into ``drives.v``)."""
    for d in range(drives.vec.shape[0]):
        s1 = ramp_fraction(t + dt, drives.T[d], drives.ta[d], drives.mode[d])
        s0 = ramp_fraction(t, drives.T[d], drives.ta[d], drives.mode[d])
        for k in range(3):
            drives.v[d, k] = drives.vec[d, k] * (s1 - s0) / dt


@njit(inline="always", **_FLAGS)
def body_moment(qw, qx, qy, qz, mx, my, mz):
    """Body moment Rᵀ M = conj(q) M q, as M + w t + u' × t with u' = −u, t = 2 u' × M (fewer
    operations than building R)."""
    tx_ = 2.0 * (qz * my - qy * mz)
    ty_ = 2.0 * (qx * mz - qz * mx)
    tz_ = 2.0 * (qy * mx - qx * my)
    return (mx + qw * tx_ - (qy * tz_ - qz * ty_), my + qw * ty_ - (qz * tx_ - qx * tz_),
            mz + qw * tz_ - (qx * ty_ - qy * tx_))


@njit(inline="always", **_FLAGS)
def damping_factors(alpha, dt):
    """``(c_keep, dt_c)`` of v_{n+½} = c_keep v_{n−½} + (dt_c / m) f with mass-proportional damping α:
    c_keep = (1 − αΔt/2)/(1 + αΔt/2), dt_c = Δt/(1 + αΔt/2) (1 and Δt without damping)."""
    a_half = 0.5 * alpha * dt
    c_inv = 1.0 / (1.0 + a_half)
    return (1.0 - a_half) * c_inv, dt * c_inv if alpha > 0.0 else dt


# (½Δt|Ω|)² below which the update's series of cos and sin(h)/h hold to rounding (the first omitted
# terms, h¹⁰/10! and h¹⁰/11!, are < 3e-17): a node spinning faster is rotated by the exact formula
ROTATION_SERIES_MAX_H2 = 1e-2


@njit(inline="always", **_FLAGS)
def _take3(a, i):
    """Entries 3i … 3i + 2 of the flat view ``a``, which it clears (the hook's force arrays, applied
    once per step)."""
    x, y, z = a[3 * i], a[3 * i + 1], a[3 * i + 2]
    a[3 * i] = 0.0
    a[3 * i + 1] = 0.0
    a[3 * i + 2] = 0.0
    return x, y, z


@njit(**_FLAGS)
def update_range(model, fixity, state, f, mom, f_ext, ef, hook_f, dt, coef, alpha, lo, hi):
    """The central-difference update (module docstring) of the nodes ``lo … hi − 1``: gathers each
    node's beam resultants from ``ef`` (:class:`~fiberpipe.solver.step_data.ElementForces`), adds the
    constant and plane forces ``f``, the moments ``mom`` and the contact hook's forces and friction
    forces ``hook_f = (fc, ff)`` (cleared here), then imposes the fixed and driven degrees of freedom
    through ``fixity``'s factors. It leaves ``f`` = the constant loads ``f_ext`` (N, 3) and ``mom`` = 0
    for the next step (what :func:`eval_external` sets).

    Returns ``(ke, ke_lf, vd, wk_fix, pw_c, wf_0, wf_1, n_large, v2_max)``: K at t_n (the mean of the
    half-step energies), ½ v_{n−½}·M v_{n+½}, Σ m|v̄|² + J|Ω̄|² (damping), the prescribed degrees of
    freedom's reaction work, Σ fc·v̄, Σ ff·v_{n−½}, Σ ff·v_{n+½}, the nodes left for :func:`rotate_large`
    and the largest |v_{n+½}|² [m²/s²]. ``coef = (c_keep, dt_c)`` (:func:`damping_factors`)."""
    # Strategy: one loop without branches over flat views of the (N, 3) and (N, 4) arrays, so that
    # LLVM vectorises it (_vectorise): fixity by 0/1 factors and a prescribed velocity, the gyroscopic
    # term as w × (J w) with exact zeros for isotropic J, the rotation's cos and sin by their series
    # (a select keeps q where they would not hold), every sum taken every step (a few flops).
    # every array through a flat view starting at node lo, the loop counting from 0 (beam_pass_nodes)
    xs, qs = state.x.reshape(-1)[3 * lo:], state.q.reshape(-1)[4 * lo:]
    vs, ws = state.v.reshape(-1)[3 * lo:], state.w.reshape(-1)[3 * lo:]
    fc, ff = hook_f
    fs, ms, fcs = f.reshape(-1)[3 * lo:], mom.reshape(-1)[3 * lo:], fc.reshape(-1)[3 * lo:]
    ffs = ff.reshape(-1)[3 * lo:]
    fes = f_ext.reshape(-1)[3 * lo:]
    Js, iJs = model.J.reshape(-1)[3 * lo:], model.inv_J.reshape(-1)[3 * lo:]
    mass, inv_mass = model.mass[lo:], model.inv_mass[lo:]
    n0, n1, n2, m0, m1, m2, h0, h1, h2 = ef
    n0, n1, n2, m0, m1, m2 = n0[lo:], n1[lo:], n2[lo:], m0[lo:], m1[lo:], m2[lo:]
    h0, h1, h2 = h0[lo:], h1[lo:], h2[lo:]
    FX, FY, FZ, FR = fixity.free_x[lo:], fixity.free_y[lo:], fixity.free_z[lo:], fixity.free_rot[lo:]
    vps = fixity.v_pres.reshape(-1)[3 * lo:]
    c_keep, dt_c = coef
    inv_dt = 1.0 / dt
    ke = 0.0
    ke_lf = 0.0
    vd = 0.0
    wk = 0.0
    pw = 0.0
    wf0 = 0.0
    wf1 = 0.0
    n_large = 0
    for i in range(hi - lo):
        j = i + 1  # the element starting at node i; entry i: the one ending there
        cfx, cfy, cfz = _take3(fcs, i)
        ffx, ffy, ffz = _take3(ffs, i)
        fx = fs[3 * i] + (n0[j] - n0[i]) + (cfx + ffx)
        fy = fs[3 * i + 1] + (n1[j] - n1[i]) + (cfy + ffy)
        fz = fs[3 * i + 2] + (n2[j] - n2[i]) + (cfz + ffz)
        mx = ms[3 * i] + (m0[j] + h0[j]) + (h0[i] - m0[i])
        my = ms[3 * i + 1] + (m1[j] + h1[j]) + (h1[i] - m1[i])
        mz = ms[3 * i + 2] + (m2[j] + h2[j]) + (h2[i] - m2[i])
        # the next step's force starts from the constant loads, its moment from 0 (one pass less
        # over the node arrays than resetting them at the start of the step)
        fs[3 * i] = fes[3 * i]
        fs[3 * i + 1] = fes[3 * i + 1]
        fs[3 * i + 2] = fes[3 * i + 2]
        ms[3 * i] = 0.0
        ms[3 * i + 1] = 0.0
        ms[3 * i + 2] = 0.0
        m = mass[i]
        v0x = vs[3 * i]
        v0y = vs[3 * i + 1]
        v0z = vs[3 * i + 2]
        b = dt_c * inv_mass[i]
        ux = FX[i]
        uy = FY[i]
        uz = FZ[i]
        v1x = ux * (c_keep * v0x + b * fx) + (1.0 - ux) * vps[3 * i]
        v1y = uy * (c_keep * v0y + b * fy) + (1.0 - uy) * vps[3 * i + 1]
        v1z = uz * (c_keep * v0z + b * fz) + (1.0 - uz) * vps[3 * i + 2]
        vax = 0.5 * (v0x + v1x)
        vay = 0.5 * (v0y + v1y)
        vaz = 0.5 * (v0z + v1z)
        # a prescribed component's reaction m (v1 − v0)/Δt − f + α m v̄ (the damping force acts on it
        # too and is booked in ALLVD), its work R·v̄ Δt
        wk += ((1.0 - ux) * (m * (v1x - v0x) * inv_dt - fx + alpha * m * vax) * vax
               + (1.0 - uy) * (m * (v1y - v0y) * inv_dt - fy + alpha * m * vay) * vay
               + (1.0 - uz) * (m * (v1z - v0z) * inv_dt - fz + alpha * m * vaz) * vaz) * dt
        qw = qs[4 * i]
        qx = qs[4 * i + 1]
        qy = qs[4 * i + 2]
        qz = qs[4 * i + 3]
        mbx, mby, mbz = body_moment(qw, qx, qy, qz, mx, my, mz)
        w0x = ws[3 * i]
        w0y = ws[3 * i + 1]
        w0z = ws[3 * i + 2]
        jx = Js[3 * i]
        jy = Js[3 * i + 1]
        jz = Js[3 * i + 2]
        ur = FR[i]
        w1x = ur * (c_keep * w0x + dt_c * (mbx - w0y * w0z * (jz - jy)) * iJs[3 * i])
        w1y = ur * (c_keep * w0y + dt_c * (mby - w0z * w0x * (jx - jz)) * iJs[3 * i + 1])
        w1z = ur * (c_keep * w0z + dt_c * (mbz - w0x * w0y * (jy - jx)) * iJs[3 * i + 2])
        wax = 0.5 * (w0x + w1x)
        way = 0.5 * (w0y + w1y)
        waz = 0.5 * (w0z + w1z)
        # contact work over the step, Δt f_n·v̄_n (in phase with the kinetic energy, as the plates')
        pw += cfx * vax + cfy * vay + cfz * vaz
        wf0 += ffx * v0x + ffy * v0y + ffz * v0z
        wf1 += ffx * v1x + ffy * v1y + ffz * v1z
        vd += m * (vax * vax + vay * vay + vaz * vaz) + jx * wax * wax + jy * way * way + jz * waz * waz
        # K_e at t_n: the mean of the half-step energies ½(K_{n−½} + K_{n+½}), not ½m v̄_n²:
        # K_{n+½} − K_{n−½} = Δt F_n·v̄_n exactly, so with every work booked as Δt f_n·v̄_n
        # (plates, walls, contact, drives) the balance has no O((ωΔt)²) swing in stiff bounces
        ke += 0.25 * (m * (v0x * v0x + v0y * v0y + v0z * v0z + v1x * v1x + v1y * v1y + v1z * v1z)
                      + jx * (w0x * w0x + w1x * w1x) + jy * (w0y * w0y + w1y * w1y) + jz * (w0z * w0z + w1z * w1z))
        # ½ v_{n−½}·M v_{n+½}: exactly conserved with a quadratic potential (the leapfrog's own
        # kinetic term), it differs from the mean of the half-step energies by ¼Δt² Σ|f|²/m
        ke_lf += 0.5 * (m * (v0x * v1x + v0y * v1y + v0z * v1z) + jx * w0x * w1x + jy * w0y * w1y + jz * w0z * w1z)
        vs[3 * i] = v1x
        vs[3 * i + 1] = v1y
        vs[3 * i + 2] = v1z
        ws[3 * i] = w1x
        ws[3 * i + 1] = w1y
        ws[3 * i + 2] = w1z
        xs[3 * i] += dt * v1x
        xs[3 * i + 1] += dt * v1y
        xs[3 * i + 2] += dt * v1z
        # q_{n+1} = q_n ⊗ exp(Ω_{n+½} Δt / 2), renormalised by one Newton step for 1/√(1 + ε)
        # (|q|² = 1 + O(1e-16): exact to O(ε²), no square root)
        hx = 0.5 * dt * w1x
        hy = 0.5 * dt * w1y
        hz = 0.5 * dt * w1z
        hh = hx * hx + hy * hy + hz * hz
        small = hh < ROTATION_SERIES_MAX_H2
        n_large += 0 if small else 1
        cw = 1.0 - hh * (0.5 - hh * (1.0 / 24.0 - hh * (1.0 / 720.0 - hh * (1.0 / 40320.0))))
        sf = 1.0 - hh * (1.0 / 6.0 - hh * (1.0 / 120.0 - hh * (1.0 / 5040.0 - hh * (1.0 / 362880.0))))
        nw, nx, ny, nz = _rotated(qw, qx, qy, qz, cw, sf * hx, sf * hy, sf * hz)
        qs[4 * i] = nw if small else qw
        qs[4 * i + 1] = nx if small else qx
        qs[4 * i + 2] = ny if small else qy
        qs[4 * i + 3] = nz if small else qz
    # the largest speed, for the contact hook's path bound (layout.ACC_V2_MAX), in a loop of its own
    # over the velocities just written: a max in the loop above keeps LLVM from vectorising it
    v2_max = 0.0
    for i in range(hi - lo):
        v2 = vs[3 * i] * vs[3 * i] + vs[3 * i + 1] * vs[3 * i + 1] + vs[3 * i + 2] * vs[3 * i + 2]
        v2_max = max(v2_max, v2)
    return ke, ke_lf, vd, wk, pw, wf0, wf1, n_large, v2_max


@njit(inline="always", **_FLAGS)
def _rotated(qw, qx, qy, qz, cw, dx_, dy_, dz_):
    """q ⊗ (cw, d), renormalised: |q|² = 1 + ε with ε ~ 1e-16 (a product of unit quaternions), so one
    Newton step for 1/√(1 + ε), (3 − |q|²)/2, is exact to O(ε²)."""
    nw = qw * cw - qx * dx_ - qy * dy_ - qz * dz_
    nx = qw * dx_ + cw * qx + (qy * dz_ - qz * dy_)
    ny = qw * dy_ + cw * qy + (qz * dx_ - qx * dz_)
    nz = qw * dz_ + cw * qz + (qx * dy_ - qy * dx_)
    inv = 0.5 * (3.0 - (nw * nw + nx * nx + ny * ny + nz * nz))
    return nw * inv, nx * inv, ny * inv, nz * inv


@njit(**_FLAGS)
def rotate_large(q, w, dt, lo, hi):
    """Rotate the nodes that :func:`update_range` left unrotated (``(½Δt|Ω|)² ≥ ROTATION_SERIES_MAX_H2``)
    by the exact q ⊗ exp(Ω Δt / 2), ``w`` holding Ω_{n+½}."""
    for i in range(lo, hi):
        hx = 0.5 * dt * w[i, 0]
        hy = 0.5 * dt * w[i, 1]
        hz = 0.5 * dt * w[i, 2]
        hh = hx * hx + hy * hy + hz * hz
        if hh >= ROTATION_SERIES_MAX_H2:
            hn = math.sqrt(hh)
            sf = math.sin(hn) / hn
            q[i, 0], q[i, 1], q[i, 2], q[i, 3] = _rotated(q[i, 0], q[i, 1], q[i, 2], q[i, 3], math.cos(hn),
                                                          sf * hx, sf * hy, sf * hz)


@njit(inline="always", **_FLAGS)
def merge_speed(vmax2, bad, v2, i):
    """The largest squared speed so far and its node, with ``v2`` of node(s) ``i`` (NaN: inf)."""
    if not (v2 <= vmax2):
        if not (v2 == v2) or v2 > vmax2:
            return (v2 if v2 == v2 else np.inf), i
    return vmax2, bad


@njit(**_FLAGS)
def half_step_kinetic(model, state):
    """½ v·M v + ½ Ω·J Ω of the velocities in ``state`` (after an update: K_{n+½}), J."""
    v, w, J = state.v, state.w, model.J
    k = 0.0
    for i in range(v.shape[0]):
        k += (model.mass[i] * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
              + J[i, 0] * w[i, 0] * w[i, 0] + J[i, 1] * w[i, 1] * w[i, 1] + J[i, 2] * w[i, 2] * w[i, 2])
    return 0.5 * k


@njit(**_FLAGS)
def max_speed2(v):
    """The largest |v_i|² (NaN: inf) and its node."""
    vmax2 = 0.0
    bad = -1
    for i in range(v.shape[0]):
        vmax2, bad = merge_speed(vmax2, bad, v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2], i)
    return vmax2, bad


def _update_nodes(model, fixity, state, work, f_ext, fc, ff, dt, coef, alpha):
    """:func:`update_range` over every node: in the serial copy one call for all nodes; in the
    parallel one (``update_nodes_fibers``) ``PARALLEL_CHUNKS`` ``prange`` tasks of contiguous nodes, the
    sums taken per task and then in order. Returns the sums of :func:`update_range` (its largest speed²,
    the largest over the tasks)."""
    offs = model.node_offsets
    nf = offs.shape[0] - 1
    f, mom = work.f, work.mom
    if not _PARALLEL:
        return update_range(model, fixity, state, f, mom, f_ext, work.ef, (fc, ff), dt, coef, alpha, 0, offs[nf])
    # a parallel loop takes a tuple built in this function, not one nested in another structure
    n0, n1, n2, m0, m1, m2, h0, h1, h2 = work.ef
    ef = (n0, n1, n2, m0, m1, m2, h0, h1, h2)
    hook_f = (fc, ff)
    n = offs[nf]
    nch = PARALLEL_CHUNKS
    sums = work.task_sums
    for k in prange(nch):  # contiguous node ranges (beam_pass_fibers)
        a, b, c, d, e, g0, g1, nl, v2 = update_range(model, fixity, state, f, mom, f_ext, ef, hook_f, dt, coef,
                                                     alpha, k * n // nch, (k + 1) * n // nch)
        sums[k, 0] = a
        sums[k, 1] = b
        sums[k, 2] = c
        sums[k, 3] = d
        sums[k, 4] = e
        sums[k, 5] = g0
        sums[k, 6] = g1
        sums[k, 7] = nl
        sums[k, 8] = v2
    ke = ke_lf = vd = wk = pw = wf0 = wf1 = 0.0
    n_large = 0
    v2_max = 0.0
    for k in range(nch):
        ke += sums[k, 0]
        ke_lf += sums[k, 1]
        vd += sums[k, 2]
        wk += sums[k, 3]
        pw += sums[k, 4]
        wf0 += sums[k, 5]
        wf1 += sums[k, 6]
        n_large += int(sums[k, 7])
        v2_max = max(v2_max, sums[k, 8])
    return ke, ke_lf, vd, wk, pw, wf0, wf1, n_large, v2_max


_PARALLEL = False
update_nodes = njit(inline="always", **_FLAGS)(_update_nodes)
# Not cached on its own, and without reference counts (update_range inherits it), as
# _kernels_beam.beam_pass_fibers (its comments).
update_nodes_fibers = specialise(_update_nodes, "update_nodes_fibers", {"_PARALLEL": True}, cache=False,
                                 fastmath=True, error_model="numpy", parallel=True, _nrt=False)


@njit(**_FLAGS)
def write_history(model, scene, state, work, h_row, acc_before, t, dt, energies, n_contacts):
    """One history row at t_n (``energies`` = (ALLKE, the leapfrog kinetic term, ALLSE, the shift of
    the mass damping's booking below)); the works are the mean of the accumulators before and after
    the step.

    The step's damping is booked twice. The mean of the half-step kinetic energies changes by
    Δt F·v̄ − D each step, D = αΔt v̄·M v̄, so ALLVD counts half of step n's D (``H_VD``). The
    leapfrog term ½ v_{n−½}·M v_{n+½} changes from t_n to t_{n+1} by the trapezoidal work less
    ½αΔt v_{n+½}·M (v̄_n + v̄_{n+1}): its dissipation counts ½αΔt v_{n−½}·M v̄_n of step n
    (``H_VD_LF`` = ``H_VD`` + the shift), the rest with step n + 1. Both sum to ALLVD over whole
    steps; the state-function residual takes the second, which leaves no error of order αΔt in it
    (a suddenly loaded pair of fibers under α = 2e6 1/s showed one of 1.7e-3 in its first steps)."""
    ke, ke_lf, se, vd_lf_shift = energies
    x, v, acc, hist = state.x, state.v, state.acc, work.hist
    f_ext, x0 = scene.f_ext, model.x0
    N = x.shape[0]
    wext = 0.0
    if f_ext.shape[0] == N:
        for i in range(N):
            xi0 = x[i, 0] - dt * v[i, 0]
            xi1 = x[i, 1] - dt * v[i, 1]
            xi2 = x[i, 2] - dt * v[i, 2]
            wext += (f_ext[i, 0] * (xi0 - x0[i, 0]) + f_ext[i, 1] * (xi1 - x0[i, 1])
                     + f_ext[i, 2] * (xi2 - x0[i, 2]))
    hist[h_row, H_TIME] = t
    segment = record_planes(hist[h_row], scene.planes, t)
    hist[h_row, H_KE] = ke
    hist[h_row, H_SE] = se
    hist[h_row, H_VD] = 0.5 * (acc_before[ACC_VD] + acc[ACC_VD])
    hist[h_row, H_WK] = 0.5 * (acc_before[ACC_WK] + acc[ACC_WK]) + wext
    hist[h_row, H_PW] = 0.5 * (acc_before[ACC_PW] + acc[ACC_PW])
    hist[h_row, H_FD] = 0.5 * (acc_before[ACC_FD] + acc[ACC_FD])
    hist[h_row, H_WF] = 0.5 * (acc_before[ACC_WF] + acc[ACC_WF])
    hist[h_row, H_CONTACTS] = n_contacts
    hist[h_row, H_STORED] = acc[ACC_STORED]
    hist[h_row, H_KE_LF] = ke_lf
    hist[h_row, H_VD_LF] = hist[h_row, H_VD] + vd_lf_shift
    hist[h_row, H_SEGMENT] = segment


@njit(**_FLAGS)
def check_row(model, state, row, ke, se, vmax2, control):
    """The blow-up checks at a history row: ``(status, bad node or -1)``."""
    if not (ke == ke) or not (se == se) or vmax2 == np.inf:
        return STATUS_NAN, -1
    if vmax2 > control.v_limit_m_s * control.v_limit_m_s:
        return STATUS_SPEED, -1
    emax = control.e_ref_J
    if abs(row[H_WK]) > emax:
        emax = abs(row[H_WK])
    if abs(row[H_PW]) > emax:
        emax = abs(row[H_PW])
    if ke > 1e3 * emax:
        return STATUS_ENERGY, -1
    x, x0 = state.x, model.x0
    lim2 = control.x_limit_m * control.x_limit_m
    for i in range(x.shape[0]):
        ddx = x[i, 0] - x0[i, 0]
        ddy = x[i, 1] - x0[i, 1]
        ddz = x[i, 2] - x0[i, 2]
        if ddx * ddx + ddy * ddy + ddz * ddz > lim2:
            return STATUS_RUNAWAY, i
    return STATUS_OK, -1


@njit(inline="always", **_FLAGS)
def _node_array(a, zeros):
    """``(a, True)`` for an (N, 3) force array of the scene or a term, else ``(zeros, False)`` (the
    work's (N, 3) zeros): the update reads one for every node."""
    if a.shape[0] == zeros.shape[0]:
        return a, True
    return zeros, False


def _advance_template(model, scene, state, work, control, terms, owner):
    """Advance ``state`` by up to ``control.n_steps`` steps of ``control.dt_s`` (s).

    ``terms``: the per-step terms' entries as a chain ``((data, history column), rest)`` ending in
    ``()`` (:func:`terms_chain`); ``owner``: the data of the term whose force arrays the update applies
    (``terms.base.NO_OWNER``: none). Returns ``(status, steps_done, h_row, bad_node)``; ``status`` is a
    ``layout.STATUS_*`` code (not OK: the state is the one at the check that failed).
    """
    x, q, v, w, acc = state
    dt = control.dt_s
    h_row = control.h_row
    hist = work.hist
    P = scene.planes.axis.shape[0]
    beta_over_dt = scene.beta_s / dt if scene.beta_s > 0.0 else 0.0
    vd_scale = scene.alpha_per_s * dt
    N = x.shape[0]
    coef = damping_factors(scene.alpha_per_s, dt)  # the constant factors of the update, folded once per call
    acc_before = work.acc_before
    # the owner term's force array and the scene's friction force array, which the update adds to the
    # nodes, books (Δt f_n·v̄_n; the friction's as friction work too) and clears ((0, 3): none)
    fc, has_fc = _node_array(_owner_forces(owner), work.zeros)
    ff, has_ff = _node_array(scene.friction_f, work.zeros)
    fixity = scene.fixity
    f_ext, _ = _node_array(scene.f_ext, work.zeros)  # the update resets f to it for every node
    # the forces of the first step; the update resets f and mom for each next one
    eval_external(work.f, work.mom, f_ext)
    # the largest node speed is not known until the first update (the state may have been set
    # between calls): the terms take it from v itself then
    acc[ACC_V2_MAX] = -1.0
    status = STATUS_OK
    bad = -1
    done = 0
    for it in range(control.n_steps):
        step = control.step_start + it
        t = control.t_start_s + it * dt
        record = ((step + 1) % control.history_every == 0) and h_row < hist.shape[0]
        if record:
            for k in range(ACC_SIZE):
                acc_before[k] = acc[k]
        # ---- forces at t_n ----
        acc[ACC_STORED] = 0.0  # a state at t_n: the planes and the terms add their stored energy
        # work.f holds the constant loads and work.mom zeros here (the previous update set them)
        # _beam_pass: beam_pass_all (serial) or beam_pass_fibers (prange per fiber), bound per loop
        # variant by _specialise; it fills ef, the update gathers it. A step with an element rotated
        # beyond the vector pass's series, or with stiffness-proportional damping, takes the exact pass
        se, n_large = _beam_pass(x, q, model, work)
        if n_large > 0 or beta_over_dt > 0.0:
            se, vd_beta = element_forces_exact(x, q, model, work, record, beta_over_dt)
            acc[ACC_VD] += vd_beta
        n_pen = 0
        if P > 0:
            n_pen = eval_planes(scene.planes, x, v, model.radius_node, work.f, acc, t, dt)
        # the per-step terms, in turn, at t_n from x_n, q_n and the half-step velocities v_{n−½}, w_{n−½}
        stored_planes = acc[ACC_STORED]
        n_contacts = _terms_eval(x, q, v, w, work.f, work.mom, acc, t, dt, terms)
        if acc[ACC_STORED0] < 0.0:  # −1: the run's first step; the terms' stored energy at t_0 (≥ 0)
            acc[ACC_STORED0] = acc[ACC_STORED] - stored_planes
        _prescribe_drives(scene, fixity, t, dt)
        # ---- update ----
        ke, ke_lf, vd, wk_fix, pw_c, wf_0, wf_1, n_spin, v2_max = _update_pass(model, fixity, state, work, f_ext,
                                                                               fc, ff, dt, coef, scene.alpha_per_s)
        acc[ACC_V2_MAX] = v2_max
        if n_spin > 0:
            rotate_large(q, w, dt, 0, N)
        acc[ACC_VD] += vd_scale * vd
        acc[ACC_WK] += wk_fix
        finish_planes(scene.planes, v, acc, dt, n_pen)
        _book_update_work(acc, dt, has_fc, has_ff, pw_c, wf_0, wf_1)
        done = it + 1
        # ---- history and checks ----
        if record:
            vmax2, bad = max_speed2(v)
            # the damping in step with the leapfrog term (write_history): ½αΔt v_{n−½}·M v̄_n = ½αΔt Σ m|v̄|²
            # − ½αΔt (K_{n+½} − K̄_n), from K_{n+½} at the rows only (the update's loop stays as it is)
            shift = -0.5 * vd_scale * (half_step_kinetic(model, state) - ke)
            write_history(model, scene, state, work, h_row, acc_before, t, dt, (ke, ke_lf, se, shift), n_contacts)
            _terms_record(hist[h_row], terms)
            h_row += 1
            status, bad_x = check_row(model, state, hist[h_row - 1], ke, se, vmax2, control)
            if bad_x >= 0:
                bad = bad_x
            if status != STATUS_OK:
                break
    return status, done, h_row, bad


@njit(inline="always", **_FLAGS)
def _prescribe_drives(scene, fixity, t, dt):
    """The driven nodes' prescribed velocities over [t_n, t_{n+1}] (into ``fixity.v_pres``)."""
    eval_drives(scene.drives, t, dt)
    for k in range(fixity.driven.shape[0]):
        i = fixity.driven[k]
        for c in range(3):
            fixity.v_pres[i, c] = scene.drives.v[scene.node_drive[i], c]


@njit(inline="always", **_FLAGS)
def _book_update_work(acc, dt, has_fc, has_ff, pw_c, wf_0, wf_1):
    """The work of the forces the update applied from the owner term's and the friction arrays
    (:func:`update_range`'s sums)."""
    if has_fc:
        acc[ACC_PW] += dt * pw_c
    if has_ff:
        # the friction forces' work: to ALLPW as every contact force's, Δt f_n·v̄_n; to the
        # friction work and, as a loss, to ALLFD as ½Δt (f_{n−1} + f_n)·v_{n−½}, the work over the
        # displacement the friction springs' energy at t_n changed by (the term books that change)
        w_half = 0.5 * dt * wf_0 + acc[ACC_WF_NEXT]
        acc[ACC_WF_NEXT] = 0.5 * dt * wf_1
        acc[ACC_PW] += 0.5 * dt * (wf_0 + wf_1) - w_half
        acc[ACC_WF] += w_half
        acc[ACC_FD] -= w_half


# ---- the per-step terms as a chain of direct calls ---------------------------------------------------
#
# A scene's per-step terms are a tuple of kernels known when the integrator is built. The step loop
# calls them through a chain of small functions, each a copy of a template whose globals are bound
# to one term's functions and to the rest of the chain (_specialise), so numba compiles every call
# directly (inlined, no indirect call, nothing pickled into its cache). The data travels as the
# nested tuple ((data_0, column_0), ((data_1, column_1), ... ())), column the term's first energy
# column of the history (-1: it declares none).


@njit(inline="always", **_FLAGS)
def _end_eval(x, q, v, w, f, mom, acc, t, dt, terms):
    return 0


@njit(inline="always", **_FLAGS)
def _end_record(row, terms):
    return None


@njit(inline="always", **_FLAGS)
def record_energy(row, column, data):
    """A term's energy slots into the history row: ``data.energy[k]`` to column ``column + k``."""
    for k in range(data.energy.shape[0]):
        row[column + k] = data.energy[k]


@njit(inline="always", **_FLAGS)
def no_record(row, column, data):
    return None


def _link_eval(x, q, v, w, f, mom, acc, t, dt, terms):
    n = _head_eval(x, q, v, w, f, mom, acc, t, dt, terms[0][0])
    return n + _rest_eval(x, q, v, w, f, mom, acc, t, dt, terms[1])


def _link_record(row, terms):
    _head_record(row, terms[0][1], terms[0][0])
    _rest_record(row, terms[1])


_head_eval = _rest_eval = _end_eval
_head_record = no_record
_rest_record = _end_record


def _with_counts(kernel, name: str):
    """``kernel`` as the loop's body may call it: a kernel that does not choose numba's reference
    counts (``_nrt``) or inlining would inherit the body's (none) and could not allocate, so it gets
    a copy of its own that keeps them (a term's eval written without regard to the loop)."""
    options = getattr(kernel, "targetoptions", {})
    if "_nrt" in options or options.get("inline", "never") != "never":
        return kernel
    flags = {k: v for k, v in options.items() if k in ("fastmath", "error_model", "boundscheck")}
    return specialise(kernel, name, {}, cache=False, _nrt=True, **flags)


def terms_chain(kernels, records, tag: str):
    """``(eval chain, record chain)``: jitted functions calling each of ``kernels`` (the terms' evals)
    and ``records`` (:func:`record_energy` or :func:`no_record`) in turn; ``tag`` names the copies."""
    chain_eval, chain_record = _end_eval, _end_record
    for k in range(len(kernels) - 1, -1, -1):
        head = _with_counts(kernels[k], f"_eval_{tag}_{k}_counted")
        chain_eval = specialise(_link_eval, f"_eval_{tag}_{k}", {"_head_eval": head, "_rest_eval": chain_eval},
                                cache=False, inline="always", fastmath=True, error_model="numpy")
        chain_record = specialise(_link_record, f"_record_{tag}_{k}",
                                  {"_head_record": records[k], "_rest_record": chain_record}, cache=False,
                                  inline="always", fastmath=True, error_model="numpy")
    return chain_eval, chain_record


# ---- specialisations of the step loop, one per tuple of per-step terms ----------------------------
#
# Each specialisation is a copy of ``_advance_template`` whose globals ``_terms_eval`` and
# ``_terms_record`` are bound to the chain of the scene's terms and ``_owner_forces`` to the force
# array's accessor of the term that hands its forces to the update. Scenes whose terms are all built
# in are cached on disk under a name made of the terms' cache names and the accessor's name (so an
# entry is found only with what it was compiled with); their freshness
# covers every module of the package (``_jitcache``), so an edit of a term's module recompiles them.
# Any other tuple gets an uncached specialisation, compiled once per process.

_terms_eval = _end_eval
_terms_record = _end_record
# The loop's body runs without reference counts (numba's ``nrt`` flag off; called from jitted
# code only, as unboxing the terms' typed lists needs the counts): it allocates nothing (its scratch
# is the work arrays'), and with counts numba takes and releases a reference, an atomic count, to
# every array of each structure it hands to a kernel it calls, per step (the beam pass and the update
# alone take about a hundred arrays). Its entry, called from Python, takes them once per call.
_NO_COUNTS = dict(_nrt=False, no_cpython_wrapper=True)
_beam_pass = beam_pass_all
_owner_forces = no_forces
_update_pass = update_nodes


def _loop_entry(model, scene, state, work, control, terms, owner):
    return _loop_body(model, scene, state, work, control, terms, owner)


_loop_body = _advance_template


def _specialise(name: str, chain, forces_of, cache: bool, parallel: bool = False):
    chain_eval, chain_record = chain
    flags = dict(cache=cache, fastmath=True, error_model="numpy")
    if getattr(forces_of, "targetoptions", {}).get("inline", "never") == "never":
        # an accessor returns an array of its data: without reference counts only an inlined one may
        forces_of = specialise(forces_of, name + "_forces_of", {}, cache=False, inline="always")
    body = specialise(_advance_template, name + "_body", {
        "_terms_eval": chain_eval, "_terms_record": chain_record, "_owner_forces": forces_of,
        "_beam_pass": beam_pass_fibers if parallel else beam_pass_all,
        "_update_pass": update_nodes_fibers if parallel else update_nodes,
    }, **flags, **_NO_COUNTS)
    return specialise(_loop_entry, name, {"_loop_body": body}, **flags)


advance_plain = _specialise("advance_plain", (_end_eval, _end_record), no_forces, True)
_LOOPS: dict = {}


def step_loop_for(kernels=(), records=(), *, forces_of=no_forces, threads: int = 1, cache_names=()):
    """The jitted step loop calling the per-step terms' ``kernels`` in turn (none: ``advance_plain``).

    records : per kernel, :func:`record_energy` (the term declares energy slots) or :func:`no_record`.
    forces_of : the accessor of the owner term's force array (``no_forces``: none). The friction forces
    come from the scene's array (``SceneKernel.friction_f``), whichever terms add to it.
    cache_names : per kernel, its built-in name for the on-disk cache; the loop is cached when every
    kernel has one (else compiled in every process). ``threads > 1``: the variant whose beam pass and
    update run as prange tasks of contiguous nodes; cached whole under its own name, its parallel
    kernels never on their own (see ``_kernels_beam.beam_pass_fibers``).
    """
    parallel = threads > 1
    kernels, records = tuple(kernels), tuple(records) or (no_record,) * len(kernels)
    if not kernels and not parallel:
        return advance_plain
    cache = len(cache_names) == len(kernels) and all(cache_names)
    key = (kernels, records, forces_of, parallel, tuple(cache_names) if cache else None)
    loop = _LOOPS.get(key)
    if loop is None:
        name = "advance_" + ("_".join(cache_names) if cache else "terms") if kernels else "advance_plain"
        if cache and kernels:
            name += f"_{forces_of.__name__}"
        tag = f"{name}{len(_LOOPS)}"
        loop = _specialise(name + ("_threads" if parallel else ""), terms_chain(kernels, records, tag),
                           forces_of, cache, parallel)
        _LOOPS[key] = loop
    return loop
