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
import types

import numpy as np
from numba import njit

from ._kernels_beam import EB_SIZE, beam_resultants, beam_resultants_fibers, node_resultant
from ._kernels_boundary import plane_contacts, penalty_power, ramp_fraction

# accumulator slots (float64 array ``acc``)
ACC_WK = 0   # prescribed-motion work (plates, drives, clamps), J
ACC_VD = 1   # damping dissipation, J
ACC_PW = 2   # contact penalty work (planes + fiber–fiber contact hook), J
ACC_FD = 3   # friction dissipation (contact hook), J
ACC_WF = 4   # work of the friction forces on the fibers (contact hook; part of ACC_PW), J
ACC_SIZE = 8

# history columns
H_TIME = 0
H_PLATE_DISP = 1   # 2 columns: lower, upper
H_PLATE_FORCE = 3  # 2 columns: lower, upper
H_KE = 5
H_SE = 6
H_VD = 7
H_WK = 8
H_PW = 9
H_FD = 10
H_CONTACTS = 11
H_WF = 12          # work of the friction forces on the fibers (ACC_WF), J
H_WALL = 13        # W columns

# node fixity bits
FIX_X = 1
FIX_Y = 2
FIX_Z = 4
FIX_ROT = 8
DRIVEN = 16

STATUS_OK = 0
STATUS_NAN = 1
STATUS_SPEED = 2
STATUS_RUNAWAY = 3
STATUS_ENERGY = 4


@njit(cache=True, error_model="numpy")
def no_contact(x, q, v, w, f, mom, acc, t, dt, data):
    """The default contact hook: does nothing, returns 0 active contacts."""
    return 0


def _advance_template(
    # model (static)
    el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest,
    mass, inv_mass, J, inv_J, radius_node, x0,
    # state (in/out)
    x, q, v, w, acc, t_start, step_start,
    # work arrays: f, mom (N, 3) for the forces and moments of everything but the beams, eb (E, 9) for
    # the beams' element resultants (gathered per node in the update)
    f, mom, eb,
    # step
    dt, n_steps,
    # damping
    alpha, beta, strain_prev,
    # constant external forces (gravity + loads), (N,3) or (0,3)
    f_ext,
    # fixity and drives
    fix_mask, node_drive, drive_vec, drive_T, drive_ta, drive_mode, drive_v,
    # planes
    pl_axis, pl_sign, pl_pos0, pl_move, pl_T, pl_ta, pl_mode, pl_hist_col, k_pen,
    pl_pos, pl_force, pen_idx, pen_f,
    # contact hook (the hook kernel itself is the module global ``_contact_hook`` of the
    # specialisation, see ``step_loop_for``)
    contact_on, contact_data,
    # history
    hist, h_row, history_every,
    # checks
    v_limit, x_limit, e_ref,
    # threads: > 1 runs the beam pass per fiber in a prange (``node_offsets``: CSR fiber offsets)
    threads, node_offsets,
):
    """Advance the state by up to ``n_steps`` steps of ``dt`` (s).

    Returns ``(status, steps_done, h_row, bad_node)``; ``status`` is STATUS_OK or the reason the
    run stopped (then the state is the one at the check that failed).
    """
    N = x.shape[0]
    P = pl_axis.shape[0]
    ND = drive_vec.shape[0]
    has_ext = f_ext.shape[0] == N
    has_fix = fix_mask.shape[0] == N
    use_damp = alpha > 0.0
    a_half = 0.5 * alpha * dt
    c_old = 1.0 - a_half
    c_inv = 1.0 / (1.0 + a_half)
    # v_{n+½} = c_keep v_{n−½} + (Δt c_inv / m) f: the constant factors folded once per call
    c_keep = c_old * c_inv
    dt_c = dt * c_inv if use_damp else dt
    vd_scale = alpha * dt
    beta_over_dt = beta / dt if beta > 0.0 else 0.0
    NF = node_offsets.shape[0] - 1
    # isotropic rotary inertia (build_model's): Ω × JΩ = 0, the gyroscopic term is skipped
    gyro = False
    for i in range(N):
        if J[i, 0] != J[i, 1] or J[i, 0] != J[i, 2]:
            gyro = True
            break
    acc_before = np.zeros(ACC_SIZE)
    # the contact hook's force array (contact_effect: it leaves each step's fiber–fiber contact and
    # friction forces there instead of adding them to f; the update adds them, books their work
    # Δt f_n·v̄_n and clears the array, in its own pass over the nodes); (0, 3) for other hooks
    fc = _contact_forces_of(contact_data)
    has_fc = fc.shape[0] == N
    status = STATUS_OK
    bad = -1
    done = 0
    for it in range(n_steps):
        step = step_start + it
        t = t_start + it * dt
        record = ((step + 1) % history_every == 0) and h_row < hist.shape[0]
        if record:
            for k in range(ACC_SIZE):
                acc_before[k] = acc[k]
        # ---- forces at t_n -------------------------------------------------------------
        if has_ext:
            for i in range(N):
                f[i, 0] = f_ext[i, 0]
                f[i, 1] = f_ext[i, 1]
                f[i, 2] = f_ext[i, 2]
        else:
            f[:, :] = 0.0
        mom[:, :] = 0.0
        # _beam_pass: beam_resultants (serial) or beam_resultants_fibers (prange per fiber), bound per
        # loop variant by _specialise; it fills eb, the update below gathers it
        se, vd_beta = _beam_pass(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest,
                                 eb, record, beta_over_dt, strain_prev, node_offsets)
        acc[ACC_VD] += vd_beta
        n_pen = 0
        if P > 0:
            for p in range(P):
                pl_pos[p] = pl_pos0[p] + pl_sign[p] * pl_move[p] * ramp_fraction(t, pl_T[p], pl_ta[p], pl_mode[p])
            n_pen = plane_contacts(x, radius_node, k_pen, pl_axis, pl_sign, pl_pos, f, pl_force, pen_idx, pen_f)
            wk = 0.0
            for p in range(P):
                if pl_move[p] != 0.0:
                    du = pl_move[p] * 0.5 * (ramp_fraction(t + dt, pl_T[p], pl_ta[p], pl_mode[p])
                                             - ramp_fraction(t - dt, pl_T[p], pl_ta[p], pl_mode[p]))
                    wk += pl_force[p] * du
            acc[ACC_WK] += wk
            acc[ACC_PW] += 0.5 * dt * penalty_power(v, pen_idx, pen_f, n_pen) - wk
        n_contacts = 0
        if contact_on:
            # >>> CONTACT/FRICTION HOOK: adds fiber–fiber contact and friction forces (N) into f
            # and moments (N·m) into mom at time t_n, from x_n, q_n and the half-step velocities
            # v_{n−½}, w_{n−½}; adds its penalty work to acc[ACC_PW] and its friction dissipation
            # to acc[ACC_FD]; returns the number of active contacts.
            n_contacts = _contact_hook(x, q, v, w, f, mom, acc, t, dt, contact_data)
        for d in range(ND):
            s1 = ramp_fraction(t + dt, drive_T[d], drive_ta[d], drive_mode[d])
            s0 = ramp_fraction(t, drive_T[d], drive_ta[d], drive_mode[d])
            for k in range(3):
                drive_v[d, k] = drive_vec[d, k] * (s1 - s0) / dt
        # ---- update ------------------------------------------------------------------
        ke = 0.0
        vd = 0.0
        wk_fix = 0.0
        pw_c = 0.0
        vmax2 = 0.0
        # the nodes of fiber `fib` are node_lo … node_end − 1 (the beam resultants gather per fiber)
        fib = 0
        node_lo = 0
        node_end = node_offsets[1] if NF > 0 else N
        for i in range(N):
            if i == node_end:
                fib += 1
                node_lo = node_end
                node_end = node_offsets[fib + 1]
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
            mx_i = mom[i, 0] + bmx
            my_i = mom[i, 1] + bmy
            mz_i = mom[i, 2] + bmz
            m = mass[i]
            im = inv_mass[i]
            mask = fix_mask[i] if has_fix else 0
            v0x = v[i, 0]
            v0y = v[i, 1]
            v0z = v[i, 2]
            b = dt_c * im
            if use_damp:
                v1x = c_keep * v0x + b * fx_i
                v1y = c_keep * v0y + b * fy_i
                v1z = c_keep * v0z + b * fz_i
            else:
                v1x = v0x + b * fx_i
                v1y = v0y + b * fy_i
                v1z = v0z + b * fz_i
            # rotations: body moment
            w0x = w[i, 0]
            w0y = w[i, 1]
            w0z = w[i, 2]
            qw, qx, qy, qz = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
            # body moment Rᵀ M = conj(q) M q, as M + w t + u' × t with u' = −u, t = 2 u' × M
            # (fewer operations than building R)
            tx_ = 2.0 * (qz * my_i - qy * mz_i)
            ty_ = 2.0 * (qx * mz_i - qz * mx_i)
            tz_ = 2.0 * (qy * mx_i - qx * my_i)
            mbx = mx_i + qw * tx_ - (qy * tz_ - qz * ty_)
            mby = my_i + qw * ty_ - (qz * tx_ - qx * tz_)
            mbz = mz_i + qw * tz_ - (qx * ty_ - qy * tx_)
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
                # prescribed translations: velocity imposed, reaction work to ALLWK
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
                # reaction = the force that imposes the motion: m (v1 − v0)/Δt − f_n + α m v̄ (the
                # damping force −α m v̄ acts on prescribed nodes too and is booked in ALLVD, so the
                # reaction overcoming it must be in ALLWK); its work over the step is R · v̄ Δt
                if fx:
                    v1x = px
                    vb = 0.5 * (v1x + v0x)
                    wk_fix += (m * (v1x - v0x) / dt - fx_i + alpha * m * vb) * vb * dt
                if fy:
                    v1y = py
                    vb = 0.5 * (v1y + v0y)
                    wk_fix += (m * (v1y - v0y) / dt - fy_i + alpha * m * vb) * vb * dt
                if fz:
                    v1z = pz
                    vb = 0.5 * (v1z + v0z)
                    wk_fix += (m * (v1z - v0z) / dt - fz_i + alpha * m * vb) * vb * dt
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
                if not (v2 <= vmax2):
                    if not (v2 == v2) or v2 > vmax2:
                        vmax2 = v2 if v2 == v2 else np.inf
                        bad = i
            v[i, 0] = v1x
            v[i, 1] = v1y
            v[i, 2] = v1z
            w[i, 0] = w1x
            w[i, 1] = w1y
            w[i, 2] = w1z
            x[i, 0] += dt * v1x
            x[i, 1] += dt * v1y
            x[i, 2] += dt * v1z
            # q ⊗ exp(Ω dt / 2)
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
            # renormalise: |q|² = 1 + ε with ε ~ 1e-16 (a product of unit quaternions), so one
            # Newton step for 1/√(1 + ε), (3 − |q|²)/2, is exact to O(ε²): no square root, no division
            inv = 0.5 * (3.0 - (nw * nw + nx * nx + ny * ny + nz * nz))
            q[i, 0] = nw * inv
            q[i, 1] = nx * inv
            q[i, 2] = ny * inv
            q[i, 3] = nz * inv
        acc[ACC_VD] += vd_scale * vd
        acc[ACC_WK] += wk_fix
        if n_pen > 0:
            acc[ACC_PW] += 0.5 * dt * penalty_power(v, pen_idx, pen_f, n_pen)
        if has_fc:
            acc[ACC_PW] += dt * pw_c
        done = it + 1
        # ---- history and checks ---------------------------------------------------------
        if record:
            # works at t_n: mean of the accumulators before and after this step
            wext = 0.0
            if has_ext:
                for i in range(N):
                    xi0 = x[i, 0] - dt * v[i, 0]
                    xi1 = x[i, 1] - dt * v[i, 1]
                    xi2 = x[i, 2] - dt * v[i, 2]
                    wext += (f_ext[i, 0] * (xi0 - x0[i, 0]) + f_ext[i, 1] * (xi1 - x0[i, 1])
                             + f_ext[i, 2] * (xi2 - x0[i, 2]))
            hist[h_row, H_TIME] = t
            for p in range(P):
                c = pl_hist_col[p]
                if c >= 0:
                    hist[h_row, c] = pl_force[p]
                    if c < H_PLATE_FORCE + 2:
                        hist[h_row, c - 2] = pl_move[p] * ramp_fraction(t, pl_T[p], pl_ta[p], pl_mode[p])
            hist[h_row, H_KE] = ke
            hist[h_row, H_SE] = se
            hist[h_row, H_VD] = 0.5 * (acc_before[ACC_VD] + acc[ACC_VD])
            hist[h_row, H_WK] = 0.5 * (acc_before[ACC_WK] + acc[ACC_WK]) + wext
            hist[h_row, H_PW] = 0.5 * (acc_before[ACC_PW] + acc[ACC_PW])
            hist[h_row, H_FD] = 0.5 * (acc_before[ACC_FD] + acc[ACC_FD])
            hist[h_row, H_WF] = 0.5 * (acc_before[ACC_WF] + acc[ACC_WF])
            hist[h_row, H_CONTACTS] = n_contacts
            h_row += 1
            if not (ke == ke) or not (se == se) or vmax2 == np.inf:
                status = STATUS_NAN
                break
            if vmax2 > v_limit * v_limit:
                status = STATUS_SPEED
                break
            emax = e_ref
            if abs(hist[h_row - 1, H_WK]) > emax:
                emax = abs(hist[h_row - 1, H_WK])
            if abs(hist[h_row - 1, H_PW]) > emax:
                emax = abs(hist[h_row - 1, H_PW])
            if ke > 1e3 * emax:
                status = STATUS_ENERGY
                break
            for i in range(N):
                ddx = x[i, 0] - x0[i, 0]
                ddy = x[i, 1] - x0[i, 1]
                ddz = x[i, 2] - x0[i, 2]
                if ddx * ddx + ddy * ddy + ddz * ddz > x_limit * x_limit:
                    status = STATUS_RUNAWAY
                    bad = i
                    break
            if status != STATUS_OK:
                break
    return status, done, h_row, bad


# ---- specialisations of the step loop, one per contact hook -----------------------------------------
#
# The hook is NOT a first-class function argument: each specialisation is a copy of
# ``_advance_template`` whose global ``_contact_hook`` is bound to one hook kernel, so numba compiles
# the call directly (inlined, no indirect call) and never pickles a dispatcher type into its cache.
# The built-in hooks (none, and ``contact_effect.contact_step``) are cached on disk under their own
# names; their freshness covers every module of the package (``_jitcache``), so an edit of a contact
# module recompiles them. A user hook (tests, scripts) gets an uncached specialisation, compiled
# once per process and hook.

_contact_hook = no_contact


@njit(cache=True)
def no_contact_forces(data):
    """A hook that adds its forces to ``f`` itself has no force array for the update (the
    ``_contact_forces_of`` default): an empty (0, 3) array."""
    return np.zeros((0, 3))


_contact_forces_of = no_contact_forces


def _specialise(name: str, hook, cache: bool, parallel: bool = False):
    g = dict(globals())
    g["_contact_hook"] = hook
    g["_contact_forces_of"] = no_contact_forces
    if hook is not no_contact:
        from .contact_effect import contact_forces_of, contact_step
        if hook is contact_step:
            g["_contact_forces_of"] = contact_forces_of
    g["_beam_pass"] = beam_resultants_fibers if parallel else beam_resultants
    tmpl = _advance_template
    fn = types.FunctionType(tmpl.__code__, g, name, tmpl.__defaults__, tmpl.__closure__)
    fn.__qualname__ = name
    fn.__module__ = __name__
    fn.__doc__ = tmpl.__doc__
    return njit(cache=cache, fastmath=True, error_model="numpy")(fn)


advance_plain = _specialise("advance_plain", no_contact, True)
_LOOPS: dict = {}


def step_loop_for(hook, threads: int = 1):
    """The jitted step loop calling ``hook`` as its contact pass (``no_contact``: none).

    ``threads > 1``: the variant whose beam pass runs one prange task per fiber; it is compiled in
    every process (not cached, see :func:`fiberpipe.solver._kernels_beam.beam_resultants_fibers`).
    """
    parallel = threads > 1
    if hook is no_contact and not parallel:
        return advance_plain
    loop = _LOOPS.get((hook, parallel))
    if loop is None:
        from .contact_effect import contact_step
        if hook is contact_step and not parallel:
            loop = _specialise("advance_contact", hook, True)
        else:
            name = "advance_plain" if hook is no_contact else "advance_contact" if hook is contact_step else "advance_hook"
            loop = _specialise(name + ("_threads" if parallel else ""), hook, False, parallel)
        _LOOPS[(hook, parallel)] = loop
    return loop
