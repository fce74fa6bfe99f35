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
on the fibers minus the plates' prescribed work (plus whatever the contact hook adds); ALLFD from
the contact hook only. Works over a step use ``f_n · v̄ Δt`` (trapezoid, second order).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._specialise import specialise
from ._kernels_beam import beam_resultants, beam_resultants_fibers, node_resultant
from ._kernels_boundary import path_delta, path_travel, plane_contacts, plane_position, penalty_power, ramp_fraction
from .layout import (ACC_FD, ACC_PW, ACC_SIZE, ACC_STORED, ACC_STORED0, ACC_VD, ACC_WF, ACC_WK, DRIVEN, FIX_ROT, FIX_X, FIX_Y, FIX_Z,
                     H_CONTACTS, H_FD, H_KE, H_KE_LF, H_PLATE_DISP, H_PLATE_FORCE, H_PW, H_SE, H_SEGMENT, H_STORED, H_TIME, H_VD, H_WF, H_WK,
                     STATUS_ENERGY, STATUS_NAN, STATUS_OK, STATUS_RUNAWAY, STATUS_SPEED)

_FLAGS = dict(cache=True, fastmath=True, error_model="numpy")


@njit(cache=True, error_model="numpy")
def no_contact(x, q, v, w, f, mom, acc, t, dt, data):
    """The default contact hook: does nothing, returns 0 active contacts."""
    return 0


@njit(cache=True)
def no_contact_forces(data):
    """The force array of a hook that adds its forces to ``f`` itself: an empty (0, 3) array."""
    return np.zeros((0, 3))


# ---- the passes of one step, in the manner of warp.sim's one eval_* per force term ------------------


@njit(inline="always", **_FLAGS)
def eval_external(f, mom, f_ext):
    """Reset the step's force and moment arrays to the constant loads (gravity, point and line loads)."""
    N = f.shape[0]
    if f_ext.shape[0] == N:
        for i in range(N):
            f[i, 0] = f_ext[i, 0]
            f[i, 1] = f_ext[i, 1]
            f[i, 2] = f_ext[i, 2]
    else:
        f[:, :] = 0.0
    mom[:, :] = 0.0


@njit(inline="always", **_FLAGS)
def eval_planes(planes, x, v, radius_node, f, acc, t, dt):
    """Plane penalties at t_n into ``f``; their stored energy to ``acc[ACC_STORED]``, the moving
    plates' prescribed work to ALLWK and the first half of the penalty work ``½Δt f_n·v_{n−½}`` to
    ALLPW. Returns the number of touching nodes."""
    P = planes.axis.shape[0]
    for p in range(P):
        planes.pos[p] = plane_position(t, planes.pos0[p], planes.sign[p], planes.move[p], planes.T[p], planes.ta[p],
                                       planes.mode[p])
    n_pen, stored = plane_contacts(x, radius_node, planes.k_pen, planes.axis, planes.sign, planes.pos, f,
                                   planes.force, planes.pen_idx, planes.pen_f)
    acc[ACC_STORED] += stored
    wk = 0.0
    for p in range(P):
        if planes.move[p, 0] != 0.0:
            du = 0.5 * path_delta(t + dt, t - dt, planes.move[p], planes.T[p], planes.ta[p], planes.mode[p])
            wk += planes.force[p] * du
    acc[ACC_WK] += wk
    acc[ACC_PW] += 0.5 * dt * penalty_power(v, planes.pen_idx, planes.pen_f, n_pen) - wk
    return n_pen


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
def rotate_node(q, i, dt, w1x, w1y, w1z):
    """q_{n+1} = q_n ⊗ exp(Ω_{n+½} Δt / 2), renormalised, in place."""
    qw, qx, qy, qz = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
    hx = 0.5 * dt * w1x
    hy = 0.5 * dt * w1y
    hz = 0.5 * dt * w1z
    h2 = hx * hx + hy * hy + hz * hz
    if h2 < 1e-8:
        cw = 1.0 - 0.5 * h2
        sf = 1.0 - h2 / 6.0
    else:
        hn = math.sqrt(h2)
        cw = math.cos(hn)
        sf = math.sin(hn) / hn
    dx_ = sf * hx
    dy_ = sf * hy
    dz_ = sf * hz
    nw = qw * cw - qx * dx_ - qy * dy_ - qz * dz_
    nx = qw * dx_ + cw * qx + (qy * dz_ - qz * dy_)
    ny = qw * dy_ + cw * qy + (qz * dx_ - qx * dz_)
    nz = qw * dz_ + cw * qz + (qx * dy_ - qy * dx_)
    # renormalise: |q|² = 1 + ε with ε ~ 1e-16 (a product of unit quaternions), so one Newton step
    # for 1/√(1 + ε), (3 − |q|²)/2, is exact to O(ε²): no square root, no division
    inv = 0.5 * (3.0 - (nw * nw + nx * nx + ny * ny + nz * nz))
    q[i, 0] = nw * inv
    q[i, 1] = nx * inv
    q[i, 2] = ny * inv
    q[i, 3] = nz * inv


@njit(inline="always", **_FLAGS)
def prescribe_node(node_drive, drive_v, i, mask, m, alpha, dt, v0x, v0y, v0z, v1x, v1y, v1z, fx_i, fy_i, fz_i):
    """Impose a fixed or driven node's translations; returns the new velocity and the reaction's
    work over the step.

    The reaction is the force that imposes the motion: m (v1 − v0)/Δt − f_n + α m v̄ (the damping
    force −α m v̄ acts on prescribed nodes too and is booked in ALLVD, so the reaction overcoming it
    must be in ALLWK); its work over the step is R · v̄ Δt.
    """
    wk = 0.0
    if mask & DRIVEN:
        d = node_drive[i]
        px = drive_v[d, 0]
        py = drive_v[d, 1]
        pz = drive_v[d, 2]
        fx = 1
        fy = 1
        fz = 1
    else:
        px = 0.0
        py = 0.0
        pz = 0.0
        fx = mask & FIX_X
        fy = mask & FIX_Y
        fz = mask & FIX_Z
    if fx:
        v1x = px
        vb = 0.5 * (v1x + v0x)
        wk += (m * (v1x - v0x) / dt - fx_i + alpha * m * vb) * vb * dt
    if fy:
        v1y = py
        vb = 0.5 * (v1y + v0y)
        wk += (m * (v1y - v0y) / dt - fy_i + alpha * m * vb) * vb * dt
    if fz:
        v1z = pz
        vb = 0.5 * (v1z + v0z)
        wk += (m * (v1z - v0z) / dt - fz_i + alpha * m * vb) * vb * dt
    return v1x, v1y, v1z, wk


@njit(inline="always", **_FLAGS)
def damping_factors(alpha, dt):
    """``(c_keep, dt_c)`` of v_{n+½} = c_keep v_{n−½} + (dt_c / m) f with mass-proportional damping α:
    c_keep = (1 − αΔt/2)/(1 + αΔt/2), dt_c = Δt/(1 + αΔt/2) (Δt without damping)."""
    a_half = 0.5 * alpha * dt
    c_inv = 1.0 / (1.0 + a_half)
    return (1.0 - a_half) * c_inv, dt * c_inv if alpha > 0.0 else dt


@njit(inline="always", **_FLAGS)
def update_fiber(model, prescribed, state, work, fc, dt, coef, record, gyro, fib):
    """The central-difference update of the nodes of fiber ``fib`` (module docstring), gathering
    the beam resultants per node and adding the contact hook's force array ``fc`` (cleared here).

    Returns ``(ke, ke_lf, vd, wk_fix, pw_c, vmax2, bad)`` over the fiber's nodes: the kinetic
    energy at t_n and the leapfrog's kinetic term ½ v_{n−½}·M v_{n+½} (if ``record``),
    Σ m|v̄|² + J|Ω̄|² for the damping dissipation, the prescribed nodes' reaction work, Σ fc·v̄
    (the hook's power), the largest |v_{n+½}|² and its node. ``coef = (c_keep, dt_c)``: the damped
    update's constant factors, v_{n+½} = c_keep v_{n−½} + (dt_c / m) f (:func:`damping_factors`);
    ``prescribed = (α [1/s], fix_mask, node_drive, the drives' velocities)`` from the scene (flat: a
    parallel loop takes no nested structure).
    """
    alpha, fix_mask, node_drive, drive_v = prescribed
    x, q, v, w = state.x, state.q, state.v, state.w
    f, mom, eb = work.f, work.mom, work.eb
    mass, inv_mass, J, inv_J = model.mass, model.inv_mass, model.J, model.inv_J
    node_offsets = model.node_offsets
    N = x.shape[0]
    use_damp = alpha > 0.0
    has_fix = fix_mask.shape[0] == N
    has_fc = fc.shape[0] == N
    c_keep, dt_c = coef
    ke = 0.0
    ke_lf = 0.0
    vd = 0.0
    wk_fix = 0.0
    pw_c = 0.0
    vmax2 = 0.0
    bad = -1
    node_lo = node_offsets[fib]
    node_end = node_offsets[fib + 1]
    for i in range(node_lo, node_end):
        bfx, bfy, bfz, bmx, bmy, bmz = node_resultant(eb, node_lo, node_end, fib, i)
        fx_i = f[i, 0] + bfx
        fy_i = f[i, 1] + bfy
        fz_i = f[i, 2] + bfz
        cfx = 0.0
        cfy = 0.0
        cfz = 0.0
        if has_fc:
            cfx = fc[i, 0]
            cfy = fc[i, 1]
            cfz = fc[i, 2]
            fc[i, 0] = 0.0
            fc[i, 1] = 0.0
            fc[i, 2] = 0.0
            fx_i += cfx
            fy_i += cfy
            fz_i += cfz
        m = mass[i]
        mask = fix_mask[i] if has_fix else 0
        v0x = v[i, 0]
        v0y = v[i, 1]
        v0z = v[i, 2]
        b = dt_c * inv_mass[i]
        if use_damp:
            v1x = c_keep * v0x + b * fx_i
            v1y = c_keep * v0y + b * fy_i
            v1z = c_keep * v0z + b * fz_i
        else:
            v1x = v0x + b * fx_i
            v1y = v0y + b * fy_i
            v1z = v0z + b * fz_i
        w0x = w[i, 0]
        w0y = w[i, 1]
        w0z = w[i, 2]
        mbx, mby, mbz = body_moment(q[i, 0], q[i, 1], q[i, 2], q[i, 3],
                                    mom[i, 0] + bmx, mom[i, 1] + bmy, mom[i, 2] + bmz)
        jx = J[i, 0]
        jy = J[i, 1]
        jz = J[i, 2]
        # gyroscopic Ω × JΩ (zero for isotropic J)
        gx = 0.0
        gy = 0.0
        gz = 0.0
        if gyro:
            gx = w0y * jz * w0z - w0z * jy * w0y
            gy = w0z * jx * w0x - w0x * jz * w0z
            gz = w0x * jy * w0y - w0y * jx * w0x
        if use_damp:
            w1x = c_keep * w0x + dt_c * (mbx - gx) * inv_J[i, 0]
            w1y = c_keep * w0y + dt_c * (mby - gy) * inv_J[i, 1]
            w1z = c_keep * w0z + dt_c * (mbz - gz) * inv_J[i, 2]
        else:
            w1x = w0x + dt * (mbx - gx) * inv_J[i, 0]
            w1y = w0y + dt * (mby - gy) * inv_J[i, 1]
            w1z = w0z + dt * (mbz - gz) * inv_J[i, 2]
        if mask != 0:
            v1x, v1y, v1z, wk = prescribe_node(node_drive, drive_v, i, mask, m, alpha, dt, v0x, v0y, v0z, v1x,
                                               v1y, v1z, fx_i, fy_i, fz_i)
            wk_fix += wk
            if mask & (FIX_ROT | DRIVEN):
                w1x = 0.0
                w1y = 0.0
                w1z = 0.0
        # averages at t_n
        vax = 0.5 * (v0x + v1x)
        vay = 0.5 * (v0y + v1y)
        vaz = 0.5 * (v0z + v1z)
        wax = 0.5 * (w0x + w1x)
        way = 0.5 * (w0y + w1y)
        waz = 0.5 * (w0z + w1z)
        # contact work over the step, Δt f_n·v̄_n (in phase with the kinetic energy, as the plates')
        pw_c += cfx * vax + cfy * vay + cfz * vaz
        if use_damp:
            vd += (m * (vax * vax + vay * vay + vaz * vaz)
                   + jx * wax * wax + jy * way * way + jz * waz * waz)
        if record:
            v2 = v1x * v1x + v1y * v1y + v1z * v1z
            # K_e at t_n: the mean of the half-step energies ½(K_{n−½} + K_{n+½}), not ½m v̄_n²:
            # K_{n+½} − K_{n−½} = Δt F_n·v̄_n exactly, so with every work booked as Δt f_n·v̄_n
            # (plates, walls, contact, drives) the balance has no O((ωΔt)²) swing in stiff bounces
            ke += 0.25 * (m * (v0x * v0x + v0y * v0y + v0z * v0z + v1x * v1x + v1y * v1y + v1z * v1z)
                          + jx * (w0x * w0x + w1x * w1x) + jy * (w0y * w0y + w1y * w1y)
                          + jz * (w0z * w0z + w1z * w1z))
            # ½ v_{n−½}·M v_{n+½}: exactly conserved with a quadratic potential (the leapfrog's own
            # kinetic term), it differs from the mean of the half-step energies by ¼Δt² Σ|f|²/m
            ke_lf += 0.5 * (m * (v0x * v1x + v0y * v1y + v0z * v1z) + jx * w0x * w1x + jy * w0y * w1y
                            + jz * w0z * w1z)
            vmax2, bad = merge_speed(vmax2, bad, v2, i)
        v[i, 0] = v1x
        v[i, 1] = v1y
        v[i, 2] = v1z
        w[i, 0] = w1x
        w[i, 1] = w1y
        w[i, 2] = w1z
        x[i, 0] += dt * v1x
        x[i, 1] += dt * v1y
        x[i, 2] += dt * v1z
        rotate_node(q, i, dt, w1x, w1y, w1z)
    return ke, ke_lf, vd, wk_fix, pw_c, vmax2, bad


@njit(inline="always", **_FLAGS)
def merge_speed(vmax2, bad, v2, i):
    """The largest squared speed so far and its node, with ``v2`` of node(s) ``i`` (NaN: inf)."""
    if not (v2 <= vmax2):
        if not (v2 == v2) or v2 > vmax2:
            return (v2 if v2 == v2 else np.inf), i
    return vmax2, bad


def _update_nodes(model, scene, state, work, fc, dt, coef, record, gyro):
    """:func:`update_fiber` for every fiber (one ``prange`` task per fiber in the parallel copy,
    ``update_nodes_fibers``; in the serial one ``prange`` is ``range``): every node is updated
    alike, the sums are taken per fiber, then in fiber order. Returns the sums over all nodes (the
    speed's maximum and node)."""
    nf = model.node_offsets.shape[0] - 1
    sums = np.empty((nf, 7))
    prescribed = (scene.alpha_per_s, scene.fix_mask, scene.node_drive, scene.drives.v)
    for fib in prange(nf):
        a, b, c, d, e, v2, i = update_fiber(model, prescribed, state, work, fc, dt, coef, record, gyro, fib)
        sums[fib, 0] = a
        sums[fib, 1] = b
        sums[fib, 2] = c
        sums[fib, 3] = d
        sums[fib, 4] = e
        sums[fib, 5] = v2
        sums[fib, 6] = i
    ke = 0.0
    ke_lf = 0.0
    vd = 0.0
    wk_fix = 0.0
    pw_c = 0.0
    vmax2 = 0.0
    bad = -1
    for fib in range(nf):
        ke += sums[fib, 0]
        ke_lf += sums[fib, 1]
        vd += sums[fib, 2]
        wk_fix += sums[fib, 3]
        pw_c += sums[fib, 4]
        vmax2, bad = merge_speed(vmax2, bad, sums[fib, 5], int(sums[fib, 6]))
    return ke, ke_lf, vd, wk_fix, pw_c, vmax2, bad


update_nodes = njit(inline="always", **_FLAGS)(_update_nodes)
# Not cached, as beam_resultants_fibers (its comment): only the solver.threads > 1 loops use it.
update_nodes_fibers = specialise(_update_nodes, "update_nodes_fibers", {}, cache=False, fastmath=True,
                                 error_model="numpy", parallel=True)


@njit(**_FLAGS)
def write_history(model, scene, state, work, h_row, acc_before, t, dt, energies, n_contacts):
    """One history row at t_n (``energies`` = (ALLKE, the leapfrog kinetic term, ALLSE)); the works
    are the mean of the accumulators before and after the step."""
    ke, ke_lf, se = energies
    x, v, acc, hist = state.x, state.v, state.acc, work.hist
    f_ext, x0 = scene.f_ext, model.x0
    planes = scene.planes
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
    segment = 0
    for p in range(planes.axis.shape[0]):
        c = planes.hist_col[p]
        if c >= 0:
            hist[h_row, c] = planes.force[p]
            if H_PLATE_FORCE <= c < H_PLATE_FORCE + 2:  # a plate: its travel and path segment too
                u, k = path_travel(t, planes.move[p], planes.T[p], planes.ta[p], planes.mode[p])
                hist[h_row, H_PLATE_DISP + c - H_PLATE_FORCE] = u
                segment = max(segment, k // 2)  # the path's entries: moves, each but the last followed by a hold
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
    hist[h_row, H_SEGMENT] = segment


@njit(**_FLAGS)
def check_row(model, state, row, ke, se, vmax2, ctl):
    """The blow-up checks at a history row: ``(status, bad node or -1)``."""
    if not (ke == ke) or not (se == se) or vmax2 == np.inf:
        return STATUS_NAN, -1
    if vmax2 > ctl.v_limit_m_s * ctl.v_limit_m_s:
        return STATUS_SPEED, -1
    emax = ctl.e_ref_J
    if abs(row[H_WK]) > emax:
        emax = abs(row[H_WK])
    if abs(row[H_PW]) > emax:
        emax = abs(row[H_PW])
    if ke > 1e3 * emax:
        return STATUS_ENERGY, -1
    x, x0 = state.x, model.x0
    lim2 = ctl.x_limit_m * ctl.x_limit_m
    for i in range(x.shape[0]):
        ddx = x[i, 0] - x0[i, 0]
        ddy = x[i, 1] - x0[i, 1]
        ddz = x[i, 2] - x0[i, 2]
        if ddx * ddx + ddy * ddy + ddz * ddz > lim2:
            return STATUS_RUNAWAY, i
    return STATUS_OK, -1


def _advance_template(model, scene, state, work, ctl, contact_data):
    """Advance ``state`` by up to ``ctl.n_steps`` steps of ``ctl.dt_s`` (s).

    Returns ``(status, steps_done, h_row, bad_node)``; ``status`` is a ``layout.STATUS_*`` code
    (not OK: the state is the one at the check that failed).
    """
    x, q, v, w, acc = state
    dt = ctl.dt_s
    h_row = ctl.h_row
    hist = work.hist
    P = scene.planes.axis.shape[0]
    beta = scene.beta_s
    beta_over_dt = beta / dt if beta > 0.0 else 0.0
    vd_scale = scene.alpha_per_s * dt
    J = model.J
    # isotropic rotary inertia (build_model's): Ω × JΩ = 0, the gyroscopic term is skipped
    gyro = False
    for i in range(x.shape[0]):
        if J[i, 0] != J[i, 1] or J[i, 0] != J[i, 2]:
            gyro = True
            break
    # the constant factors of the update, folded once per call
    coef = damping_factors(scene.alpha_per_s, dt)
    acc_before = np.zeros(ACC_SIZE)
    # the hook's own force array (a hook that declares one leaves its forces there; the update adds
    # them, books their work Δt f_n·v̄_n and clears the array); (0, 3) for hooks that add into f
    fc = _hook_forces(contact_data)
    has_fc = fc.shape[0] == x.shape[0]
    status = STATUS_OK
    bad = -1
    done = 0
    for it in range(ctl.n_steps):
        step = ctl.step_start + it
        t = ctl.t_start_s + it * dt
        record = ((step + 1) % ctl.history_every == 0) and h_row < hist.shape[0]
        if record:
            for k in range(ACC_SIZE):
                acc_before[k] = acc[k]
        # ---- forces at t_n ----
        acc[ACC_STORED] = 0.0  # a state at t_n: the planes and the hook add their stored energy
        eval_external(work.f, work.mom, scene.f_ext)
        # _beam_pass: beam_resultants (serial) or beam_resultants_fibers (prange per fiber), bound per
        # loop variant by _specialise; it fills eb, the update gathers it
        se, vd_beta = _beam_pass(x, q, model.el_n1, model.el_invL0, model.el_C, model.el_Dk, model.gamma_rest,
                                 model.theta_rest, work.eb, record, beta_over_dt, work.strain_prev,
                                 model.node_offsets)
        acc[ACC_VD] += vd_beta
        n_pen = 0
        if P > 0:
            n_pen = eval_planes(scene.planes, x, v, model.radius_node, work.f, acc, t, dt)
        # the hook adds its forces (or leaves them in its own array) and moments at t_n from x_n, q_n
        # and the half-step velocities v_{n−½}, w_{n−½}; books its work and friction dissipation
        stored_planes = acc[ACC_STORED]
        n_contacts = _hook(x, q, v, w, work.f, work.mom, acc, t, dt, contact_data)
        if acc[ACC_STORED0] < 0.0:  # −1: the run's first step; the hook's stored energy at t_0 (≥ 0)
            acc[ACC_STORED0] = acc[ACC_STORED] - stored_planes
        eval_drives(scene.drives, t, dt)
        # ---- update ----
        ke, ke_lf, vd, wk_fix, pw_c, vmax2, bad = _update_pass(model, scene, state, work, fc, dt, coef, record, gyro)
        acc[ACC_VD] += vd_scale * vd
        acc[ACC_WK] += wk_fix
        if n_pen > 0:
            acc[ACC_PW] += 0.5 * dt * penalty_power(v, scene.planes.pen_idx, scene.planes.pen_f, n_pen)
        if has_fc:
            acc[ACC_PW] += dt * pw_c
        done = it + 1
        # ---- history and checks ----
        if record:
            write_history(model, scene, state, work, h_row, acc_before, t, dt, (ke, ke_lf, se), n_contacts)
            h_row += 1
            status, bad_x = check_row(model, state, hist[h_row - 1], ke, se, vmax2, ctl)
            if bad_x >= 0:
                bad = bad_x
            if status != STATUS_OK:
                break
    return status, done, h_row, bad


# ---- specialisations of the step loop, one per contact hook -----------------------------------------
#
# The hook is NOT a first-class function argument: each specialisation is a copy of
# ``_advance_template`` whose globals ``_hook`` and ``_hook_forces`` are bound to one hook kernel and
# its force-array accessor, so numba compiles the call directly (inlined, no indirect call) and never
# pickles a dispatcher type into its cache. The built-in hooks are cached on disk under their own
# names (``step_loop_for(cache_name=...)``); their freshness covers every module of the package
# (``_jitcache``), so an edit of a contact module recompiles them. Any other hook gets an uncached
# specialisation, compiled once per process and hook.

_hook = no_contact
_hook_forces = no_contact_forces
_update_pass = update_nodes


def _specialise(name: str, hook, forces_of, cache: bool, parallel: bool = False):
    return specialise(_advance_template, name, {
        "_hook": hook, "_hook_forces": forces_of,
        "_beam_pass": beam_resultants_fibers if parallel else beam_resultants,
        "_update_pass": update_nodes_fibers if parallel else update_nodes,
    }, cache=cache, fastmath=True, error_model="numpy")


advance_plain = _specialise("advance_plain", no_contact, no_contact_forces, True)
_LOOPS: dict = {}


def step_loop_for(hook=no_contact, forces_of=no_contact_forces, threads: int = 1, cache_name: str | None = None):
    """The jitted step loop calling ``hook`` as its contact pass (``no_contact``: none).

    forces_of : the jitted accessor of the hook's own force array (``no_contact_forces``: the hook
        adds into ``f``). cache_name : a built-in hook's name for the on-disk cache (None: compiled
        in every process). ``threads > 1``: the variant whose beam pass runs one prange task per
        fiber; compiled in every process (see ``_kernels_beam.beam_resultants_fibers``).
    """
    parallel = threads > 1
    if hook is no_contact and not parallel:
        return advance_plain
    key = (hook, forces_of, parallel)
    loop = _LOOPS.get(key)
    if loop is None:
        cache = cache_name is not None and not parallel
        name = cache_name or ("advance_plain" if hook is no_contact else "advance_hook")
        loop = _specialise(name + ("_threads" if parallel else ""), hook, forces_of, cache, parallel)
        _LOOPS[key] = loop
    return loop
