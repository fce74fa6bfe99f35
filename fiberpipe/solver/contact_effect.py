"""The fiber–fiber contact/friction hook of the step loop: ``contact_effect(model, scene_cfg, material)``.

Builds a :class:`fiberpipe.solver.effects.ContactHook` whose kernel :func:`contact_step` runs once per
step (see ``docs/solver.md``, "Contact hook", and ``docs/contact.md`` §5):

1. Verlet list: rebuilt when a node has moved more than skin/2 since the last build (or at the first
   call); the new list goes into the spare buffers, the friction history is remapped by pair key,
   then the buffers are swapped. Buffers live in numba typed lists inside ``data``, so the kernel
   grows them itself when :func:`fiberpipe.solver.neighbours.build_pairs` reports an overflow
   (no Python round trip, no lost contacts).
2. Normal contact forces (:func:`fiberpipe.solver.contact.contact_forces`) with the scene's law.
3. Friction (if ``friction`` is in ``scene.effects``): fiber–fiber
   (:func:`fiberpipe.solver.friction.friction_forces`) and fiber–plane for the plates and walls of
   the scene (:func:`fiberpipe.solver.friction.plane_friction`, normal force from the same penalty
   rule as ``_kernels_boundary.plane_contacts``; plane positions recomputed from the same ramps).
4. The contact and friction forces stay in the hook's force array (:func:`contact_forces_of`): the
   step loop's update adds them to the nodes, books their work ``Δt f_n·v̄_n`` to ALLPW and clears
   the array, in the same pass over the nodes. The friction forces' own work, the same
   ``Δt f_n·v̄_n``, is also booked apart (``ACC_WF``, history ``energy/friction_work``) by the hook:
   half with ``v_{n−½}`` when the forces are made, half with ``v_{n+½}`` at the next call (their
   values on the nodes they act on are kept in ``ff`` for it), so the step loop stays as it is. Energies: ALLPW += that work + the friction
   dissipation; ALLFD += friction dissipation. With ETOTAL = KE + SE + VD + FD − WK − PW this keeps the balance (PW holds the
   elastic contact energy and the friction loss, as Abaqus' ALLPW includes penalty friction).

Returns the number of fiber–fiber segment pairs in contact (history column ``contacts``).
Forces act on the centre lines (no moments; friction does not make fibers roll): see
``docs/contact.md`` "What's left".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.typed import List

from ..errors import FiberpipeError
from ._kernels_boundary import ramp_fraction
from ._kernels_integrate import ACC_FD, ACC_PW, ACC_WF, ACC_WK
from .contact import contact_forces_ex, gauss_points, pair_gap
from .friction import friction_forces_ex, plane_candidates, plane_friction, remap_history
from .laws import make_law
from .neighbours import build_pairs, max_displacement2_speed2

# integer state slots (data[I_STATE])
IS_LAW = 0
IS_FRICTION = 1       # 1: fiber–fiber friction on
IS_PLANE_FRICTION = 2  # 1: fiber–plane friction on
IS_NPAIRS = 3
IS_NBUILDS = 4
IS_NGROW = 5          # times the buffers grew
IS_NACTIVE = 6
IS_OVERLAP = 7        # 1: the initial overlaps have been recorded (first call done)
IS_STEP = 8           # calls so far (the friction histories' time stamps)
IS_NFF = 9            # nodes listed in ff_nodes (those the last step's friction forces act on)
IS_SIZE = 10
# float state slots (data[F_STATE])
FS_SKIN = 0
FS_SEXCL = 1
FS_MU = 2
FS_KT = 3
FS_FN_SUM = 4        # Σ normal force of the pairs in contact at the last step, N
FS_DELTA_MAX = 5     # largest penetration at the last step, m
FS_FRIC_SUM = 6      # Σ |f_t| (fiber–fiber) at the last step, N
FS_RELEASE = 7       # overlap release time, s (0: the initial overlaps are removed at once)
FS_E_CONTACT = 8     # stored normal contact energy at the last step, J
FS_E_SPRING = 9      # elastic energy of the fiber–fiber tangential springs at the last step, J
FS_OFF_MAX = 10      # largest initial-overlap offset still applied, m
FS_PATH = 11         # bound on the path of any node since the last build, Σ Δt max|v|, m
FS_SIZE = 12
D_FC = 14            # data slot of fc, this step's contact and friction forces (N, 3), N

DEFAULT_SKIN_FACTOR = 0.2          # skin = 0.2 r_max (0.05 r_max: 22 % fewer pairs, no measurable gain)
DEFAULT_KT_FACTOR = 0.02           # k_t = 0.02 m_min (2/Δt)²
DEFAULT_PAIRS_PER_SEGMENT = 16     # initial capacity per segment (grown by the kernel if needed)
DEFAULT_OVERLAP_RELEASE_S = 1e-4   # initial overlaps released linearly over 0.1 ms
OVERLAP_MIN_FRACTION = 0.05        # initial penetrations below 5 % of the smaller radius act at once
                                   # (pressed set-ups, verification cases): no offset


@njit(cache=True, error_model="numpy")
def _rebuild(x, seg_nodes, seg_radius, seg_fiber, seg_arc, istate, fstate, x_ref, L_pairs, L_keys, L_h2, L_h1,
             L_active):
    """Build the Verlet list into the spare buffers (growing them if needed), remap the friction
    history and the initial-overlap offsets, swap. L_h2 = [hist (C, 5), hist_spare, c_n (C, 3),
    off (C, 1), off_spare]; L_h1 = [c_fn, c_s, c_t, c_phi, c_delta, c_share, c_fsum, c_gap];
    L_active = [c_active (C,) int64]."""
    while True:
        n = build_pairs(x, seg_nodes, seg_radius, seg_fiber, seg_arc, fstate[FS_SKIN], fstate[FS_SEXCL],
                        L_pairs[1], L_keys[1])
        if n >= 0:
            break
        cap = int(1.5 * (-n)) + 64
        L_pairs[1] = np.zeros((cap, 2), np.int64)
        L_keys[1] = np.zeros(cap, np.int64)
        L_h2[1] = np.zeros((cap, 5))
        L_h2[4] = np.zeros((cap, 1))
        istate[IS_NGROW] += 1
    if L_h2[1].shape[0] < L_pairs[1].shape[0]:
        L_h2[1] = np.zeros((L_pairs[1].shape[0], 5))
    if L_h2[4].shape[0] < L_pairs[1].shape[0]:
        L_h2[4] = np.zeros((L_pairs[1].shape[0], 1))
    if L_h1[0].shape[0] < n:
        cap = L_pairs[1].shape[0]
        L_h2[2] = np.zeros((cap, 3))
        for k in range(len(L_h1)):
            L_h1[k] = np.zeros(cap)
        L_active[0] = np.zeros(cap, np.int64)
    if istate[IS_FRICTION] == 1:
        remap_history(L_keys[0], istate[IS_NPAIRS], L_h2[0], L_keys[1], n, L_h2[1])
    if fstate[FS_OFF_MAX] > 0.0:
        remap_history(L_keys[0], istate[IS_NPAIRS], L_h2[3], L_keys[1], n, L_h2[4])
    else:
        L_h2[4][:n, 0] = 0.0
    tp = L_pairs[0]
    L_pairs[0] = L_pairs[1]
    L_pairs[1] = tp
    tk = L_keys[0]
    L_keys[0] = L_keys[1]
    L_keys[1] = tk
    th = L_h2[0]
    L_h2[0] = L_h2[1]
    L_h2[1] = th
    to = L_h2[3]
    L_h2[3] = L_h2[4]
    L_h2[4] = to
    istate[IS_NPAIRS] = n
    istate[IS_NBUILDS] += 1
    x_ref[:, :] = x
    # each pair's gap at this build (clamped segment distance − r_i − r_j): the contact pass skips
    # a pair while the gap exceeds twice the path bound since (and refreshes it when it looks)
    pairs = L_pairs[0]
    gap = L_h1[7]
    for k in range(n):
        gap[k] = pair_gap(x, seg_nodes, seg_radius, pairs, k)


@njit(cache=True, error_model="numpy")
def contact_forces_of(data):
    """The force array (N, 3) [N] :func:`contact_step` leaves its forces in: the step loop adds it to
    the nodes in its update, books its work ``Δt f_n·v̄_n`` (``v̄_n`` the mean of the two half-step
    velocities, in phase with the kinetic energy and the plate work of the history row at t_n) and
    clears it (one pass over the nodes instead of three: add, power before, power after)."""
    return data[D_FC]


@njit(cache=True, fastmath=True, error_model="numpy")
def contact_step(x, q, v, w, f, mom, acc, t, dt, data):
    """The ContactHook kernel (signature of ``effects.ContactHook``); see the module docstring.

    Unlike other hooks it does not add its forces to ``f``: it leaves them in
    :func:`contact_forces_of` ``(data)``, which only the step loop specialised for this kernel
    applies (a hook that wraps this one must add that array to ``f`` itself).
    """
    (istate, fstate, seg_nodes, seg_radius, seg_fiber, seg_arc, law_params, gxi, gw, x_ref,
     L_pairs, L_keys, L_h2, L_h1, fc,
     radius_node, k_pen, pl_axis, pl_sign, pl_pos0, pl_move, pl_T, pl_ta, pl_mode, pl_pos, pl_vel,
     pl_hist, pl_tforce, L_active, cand_idx, cand_off, pl_pos_cand, ff, ff_nodes, ff_mark) = data
    step = istate[IS_STEP]
    istate[IS_STEP] = step + 1
    N = x.shape[0]
    P = pl_axis.shape[0]
    plane_fric = istate[IS_PLANE_FRICTION] == 1 and P > 0
    plane_moved = 0.0
    if plane_fric:
        for p in range(P):
            r0 = ramp_fraction(t, pl_T[p], pl_ta[p], pl_mode[p])
            pl_pos[p] = pl_pos0[p] + pl_sign[p] * pl_move[p] * r0
            vel = pl_sign[p] * pl_move[p] * (r0 - ramp_fraction(t - dt, pl_T[p], pl_ta[p], pl_mode[p])) / dt
            pl_vel[p, 0] = 0.0
            pl_vel[p, 1] = 0.0
            pl_vel[p, 2] = 0.0
            pl_vel[p, pl_axis[p]] = vel
            plane_moved = max(plane_moved, abs(pl_pos[p] - pl_pos_cand[p]))
    dm2, vm2 = max_displacement2_speed2(x, x_ref, v)
    # v holds v_{n−½}, the velocity that moved every node from x_{n−1} to x_n
    fstate[FS_PATH] += dt * math.sqrt(vm2)
    half_skin = 0.5 * fstate[FS_SKIN]
    # the path bound holds only while positions change through the velocities (x_n = x_{n−1} + Δt v);
    # a node farther from its build position than the bound allows was moved from outside (a new or
    # edited state): rebuild, which restarts every bound from the positions as they are
    path = fstate[FS_PATH]
    moved_outside = dm2 > (path * (1.0 + 1e-12) + 1e-15) ** 2
    rebuild = istate[IS_NBUILDS] == 0 or dm2 > half_skin * half_skin or moved_outside
    if rebuild:
        _rebuild(x, seg_nodes, seg_radius, seg_fiber, seg_arc, istate, fstate, x_ref, L_pairs, L_keys, L_h2, L_h1,
                 L_active)
        fstate[FS_PATH] = 0.0
    # the nodes near each plane, for its friction: a node touching now was within 1.5 skin of the
    # plane when the list was made (it moved < skin since: ≤ skin/2 since the neighbour-list build
    # before it and ≤ skin/2 after; the plane moved ≤ skin/2), so the list is remade with every
    # neighbour-list build and whenever a plane has moved skin/2 since
    if plane_fric and (rebuild or plane_moved > half_skin):
        plane_candidates(x, radius_node, pl_axis, pl_sign, pl_pos, 3.0 * half_skin, cand_idx, cand_off)
        for p in range(P):
            pl_pos_cand[p] = pl_pos[p]
    # pairs are re-evaluated only when the nodes may have closed their gap since the last look
    # (contact_forces_ex, c_gap): the path bound refreshes per pair, the displacement bound does not
    reach = 2.0 * fstate[FS_PATH]
    c_gap = L_h1[7]
    pairs = L_pairs[0]
    hist = L_h2[0]
    c_n = L_h2[2]
    c_fn = L_h1[0]
    c_s = L_h1[1]
    c_t = L_h1[2]
    c_phi = L_h1[3]
    c_delta = L_h1[4]
    n_pairs = istate[IS_NPAIRS]
    c_share = L_h1[5]
    c_fsum = L_h1[6]
    off0 = L_h2[3]
    c_active = L_active[0]
    # initial overlaps (first call): record each pair's penetration δ0 at t = 0 as its offset; the
    # contact then sees δ − δ0·(1 − t/T_release)⁺, so overlapping input is pushed apart gradually
    if istate[IS_OVERLAP] == 0:
        istate[IS_OVERLAP] = 1
        contact_forces_ex(x, seg_nodes, seg_radius, pairs, n_pairs, istate[IS_LAW], law_params,
                          gxi, gw, fc, c_fn, c_n, c_s, c_t, c_phi, c_delta, np.zeros(0), c_share, c_fsum,
                          c_gap, reach, c_active)
        omax = 0.0
        for k in range(n_pairs):
            i = pairs[k, 0]
            j = pairs[k, 1]
            o = c_delta[k] if c_fn[k] > 0.0 else 0.0
            if o < OVERLAP_MIN_FRACTION * min(seg_radius[i], seg_radius[j]):
                o = 0.0
            off0[k, 0] = o
            if o > omax:
                omax = o
        fstate[FS_OFF_MAX] = omax
        fc[:, :] = 0.0
    T_rel = fstate[FS_RELEASE]
    off = np.zeros(0)
    rel = 0.0
    rel_prev = 0.0
    use_off = fstate[FS_OFF_MAX] > 0.0
    if use_off:
        if T_rel > 0.0:
            rel = max(0.0, 1.0 - t / T_rel)
            rel_prev = max(0.0, 1.0 - (t - dt) / T_rel) if t > 0.0 else rel
        if rel > 0.0:
            off = np.empty(n_pairs)
            for k in range(n_pairs):
                off[k] = off0[k, 0] * rel
        else:
            fstate[FS_OFF_MAX] = 0.0  # released: no offsets any more (new pairs get none either)
            use_off = False
    # fc is all zeros here: the step loop's update cleared it after applying it (fused loops)
    energy, n_active = contact_forces_ex(x, seg_nodes, seg_radius, pairs, n_pairs, istate[IS_LAW], law_params,
                                         gxi, gw, fc, c_fn, c_n, c_s, c_t, c_phi, c_delta, off, c_share, c_fsum,
                                         c_gap, reach, c_active)
    # work of the release on the contacts (the offset shrinks at fixed positions: stored energy
    # grows by Σ|f|·Δoff); a prescribed "motion", booked as external work (ALLWK)
    if use_off and rel_prev > rel:
        wrel = 0.0
        for kk in range(n_active):
            k = c_active[kk]
            wrel += c_fsum[k] * off0[k, 0]
        acc[ACC_WK] += wrel * (rel_prev - rel)
    fstate[FS_E_CONTACT] = energy
    diss = 0.0
    mu = fstate[FS_MU]
    kt = fstate[FS_KT]
    if istate[IS_FRICTION] == 1 or plane_fric:
        # the friction forces' work Δt f_n·v̄_n = ½Δt f_n·(v_{n−½} + v_{n+½}), booked apart (ACC_WF), on
        # the nodes the forces act on (those of the pairs in contact and the plane candidates): ff still
        # holds the previous step's friction forces on the listed nodes, and v now holds their v_{n+½}
        wf = 0.0
        for kk in range(istate[IS_NFF]):
            i = ff_nodes[kk]
            wf += ff[i, 0] * v[i, 0] + ff[i, 1] * v[i, 1] + ff[i, 2] * v[i, 2]
        n_ff = 0
        if istate[IS_FRICTION] == 1:
            for kk in range(n_active):
                k = c_active[kk]
                for side in range(2):
                    for end in range(2):
                        i = seg_nodes[pairs[k, side], end]
                        if ff_mark[i] != step:
                            ff_mark[i] = step
                            ff_nodes[n_ff] = i
                            n_ff += 1
        if plane_fric:
            for c in range(cand_off[P]):
                i = cand_idx[c]
                if ff_mark[i] != step:
                    ff_mark[i] = step
                    ff_nodes[n_ff] = i
                    n_ff += 1
        istate[IS_NFF] = n_ff
        # the friction kernels add into fc as the normal forces do (the same sums, so the same
        # trajectory as without this bookkeeping); ff = fc after − fc before on the listed nodes
        for kk in range(n_ff):
            i = ff_nodes[kk]
            ff[i, 0] = -fc[i, 0]
            ff[i, 1] = -fc[i, 1]
            ff[i, 2] = -fc[i, 2]
        if istate[IS_FRICTION] == 1:
            dff, esp = friction_forces_ex(v, seg_nodes, pairs, n_pairs, c_fn, c_n, c_s, c_t, mu, kt, dt, hist, fc,
                                          c_share, c_active, n_active, step)
            diss += dff
            fstate[FS_E_SPRING] = esp
        if plane_fric:
            diss += plane_friction(x, v, radius_node, k_pen, pl_axis, pl_sign, pl_pos, pl_vel, mu, kt, dt, pl_hist,
                                   fc, pl_tforce, step, cand_idx, cand_off)
        for kk in range(n_ff):
            i = ff_nodes[kk]
            ff[i, 0] += fc[i, 0]
            ff[i, 1] += fc[i, 1]
            ff[i, 2] += fc[i, 2]
            wf += ff[i, 0] * v[i, 0] + ff[i, 1] * v[i, 1] + ff[i, 2] * v[i, 2]
        acc[ACC_WF] += 0.5 * dt * wf
    # the forces stay in fc: the step loop's update applies them, books their work and clears fc
    acc[ACC_PW] += diss
    acc[ACC_FD] += diss
    # statistics of this step
    fsum = 0.0
    dmax = 0.0
    for kk in range(n_active):
        k = c_active[kk]
        fsum += c_fn[k]
        if c_delta[k] > dmax:
            dmax = c_delta[k]
    fstate[FS_FN_SUM] = fsum
    fstate[FS_DELTA_MAX] = dmax
    istate[IS_NACTIVE] = n_active
    return n_active


def law_from_config(contact_cfg, material):
    """A :class:`fiberpipe.solver.laws.ContactLaw` from the scene's ``contact`` block (SI values)."""
    E = float(material.youngs_modulus_pa)
    nu = material.poisson_ratio
    if nu is None:  # from the shear modulus
        nu = E / (2.0 * float(material.shear_modulus_pa)) - 1.0
    kw = dict(E_pa=E, nu=float(nu))
    name = getattr(contact_cfg, "law", "hertz_oriented") if contact_cfg is not None else "hertz_oriented"
    if name == "linear":
        return make_law("linear", stiffness=float(contact_cfg.stiffness), **kw)
    if name == "scaled_stiffness":
        if contact_cfg.preset is not None:
            return make_law("scaled_stiffness", preset=contact_cfg.preset, **kw)
        return make_law("scaled_stiffness", d_m=float(contact_cfg.d), S=float(contact_cfg.s),
                        S0=float(contact_cfg.s0), K_def=float(contact_cfg.k_def), **kw)
    if name == "hertz_crossed":
        return make_law("hertz_crossed", phi_deg=math.degrees(float(contact_cfg.angle)), **kw)
    if name == "hertz_oriented" and getattr(contact_cfg, "blend_length", None) is not None:
        kw["blend_length_m"] = float(contact_cfg.blend_length)
    return make_law(name, **kw)


class ContactSetup:
    """Everything ``prepare`` builds, kept for inspection after a run (``hook.setup_info``)."""

    def __init__(self, law, contact_on, friction_on, mu, k_t, skin, n_gauss):
        self.law = law
        self.contact_on = contact_on
        self.friction_on = friction_on
        self.mu = mu
        self.k_t = k_t
        self.skin = skin
        self.n_gauss = n_gauss
        self.data = None

    # convenient views of the kernel state
    @property
    def n_pairs(self) -> int:
        return int(self.data[0][IS_NPAIRS])

    @property
    def n_builds(self) -> int:
        return int(self.data[0][IS_NBUILDS])

    @property
    def n_active(self) -> int:
        return int(self.data[0][IS_NACTIVE])

    @property
    def normal_force_sum(self) -> float:
        return float(self.data[1][FS_FN_SUM])

    def records(self):
        """(pairs, c_fn, c_n, c_s, c_t, c_phi, c_delta) of the last step (copies, first n_pairs rows)."""
        n = self.n_pairs
        L_pairs, L_h2, L_h1 = self.data[10], self.data[12], self.data[13]
        return (np.array(L_pairs[0][:n]), np.array(L_h1[0][:n]), np.array(L_h2[2][:n]), np.array(L_h1[1][:n]),
                np.array(L_h1[2][:n]), np.array(L_h1[3][:n]), np.array(L_h1[4][:n]))


def make_contact_hook(model, *, law=None, contact: bool = True, friction: bool = False, mu: float = 0.2,
                      k_t: float | None = None, skin_m: float | None = None, n_gauss: int = 2,
                      plane_friction_on: bool = True, overlap_release_s: float = DEFAULT_OVERLAP_RELEASE_S):
    """A :class:`ContactHook` for ``model`` (Python API; :func:`contact_effect` maps a config onto it).

    law : ContactLaw (default hertz_oriented for the model's material). contact : fiber–fiber normal
    contact on. friction : Coulomb friction on (fiber–fiber if ``contact``, and fiber–plane for the
    scene's plates/walls if ``plane_friction_on``). mu : coefficient. k_t : N/m, tangential penalty
    (default 0.02 m_min (2/Δt)², chosen against the time step). skin_m : Verlet skin (default 0.2 r_max).
    n_gauss : Gauss points per segment in the line part. overlap_release_s : s, the initial overlap
    of each segment pair (its penetration at the first step) is subtracted from its penetration and
    released linearly to 0 over this time (0: no offset, the overlap acts at once).
    """
    from .effects import ContactHook

    mat = model.material
    if law is None:
        law = make_law("hertz_oriented", E_pa=mat.youngs_modulus_pa,
                       nu=mat.poisson_ratio if mat.poisson_ratio is not None else 0.3)
    E = model.n_elements
    seg_nodes = np.empty((E, 2), np.int64)
    seg_nodes[:, 0] = model.el_n1
    seg_nodes[:, 1] = model.el_n1 + 1
    seg_radius = np.ascontiguousarray(model.el_radius, dtype=np.float64)
    seg_fiber = np.ascontiguousarray(model.el_fiber, dtype=np.int64)
    L0 = np.asarray(model.el_L0, dtype=np.float64)
    arc = np.empty((E, 2))
    acc = 0.0
    for e in range(E):
        if e == 0 or seg_fiber[e] != seg_fiber[e - 1]:
            acc = 0.0
        arc[e, 0] = acc
        acc += L0[e]
        arc[e, 1] = acc
    rmax = float(seg_radius.max()) if E else 0.0
    skin = float(skin_m) if skin_m is not None else DEFAULT_SKIN_FACTOR * rmax
    if not skin > 0:
        raise FiberpipeError(f"contact.skin must be > 0, got {skin}")
    if mu < 0:
        raise FiberpipeError(f"friction.mu must be >= 0, got {mu}")
    if not (overlap_release_s >= 0 and math.isfinite(overlap_release_s)):
        raise FiberpipeError(f"contact.overlap_release must be >= 0, got {overlap_release_s}")
    info = ContactSetup(law, contact, friction, mu, k_t, skin, n_gauss)

    def prepare(model_, scene):
        dt = float(scene.dt)
        kt = float(k_t) if k_t is not None else DEFAULT_KT_FACTOR * float(np.min(model_.mass)) * (2.0 / dt) ** 2
        info.k_t = kt
        N = model_.n_nodes
        cap = max(DEFAULT_PAIRS_PER_SEGMENT * E, 64) if contact else 1
        istate = np.zeros(IS_SIZE, np.int64)
        fstate = np.zeros(FS_SIZE)
        istate[IS_LAW] = law.law_id
        istate[IS_FRICTION] = 1 if (friction and contact) else 0
        P = scene.pl_axis.size
        istate[IS_PLANE_FRICTION] = 1 if (friction and plane_friction_on and P > 0) else 0
        fstate[FS_SKIN] = skin
        fstate[FS_SEXCL] = 2.0 * rmax
        fstate[FS_MU] = mu
        fstate[FS_KT] = kt
        fstate[FS_RELEASE] = float(overlap_release_s)
        gxi, gw = gauss_points(n_gauss)
        L_pairs = List([np.zeros((cap, 2), np.int64), np.zeros((cap, 2), np.int64)])
        L_keys = List([np.zeros(cap, np.int64), np.zeros(cap, np.int64)])
        L_h2 = List([np.zeros((cap, 5)), np.zeros((cap, 5)), np.zeros((cap, 3)), np.zeros((cap, 1)),
                     np.zeros((cap, 1))])
        L_h1 = List([np.zeros(cap) for _ in range(8)])
        k_pen = scene.k_pen() if P > 0 else np.zeros(0)
        seg_nodes_u = seg_nodes if contact else seg_nodes[:0]
        data = (istate, fstate, seg_nodes_u, seg_radius[: len(seg_nodes_u)], seg_fiber[: len(seg_nodes_u)],
                arc[: len(seg_nodes_u)], law.params(), gxi, gw, np.array(model_.nodes_m, dtype=np.float64),
                L_pairs, L_keys, L_h2, L_h1, np.zeros((N, 3)),
                np.ascontiguousarray(model_.radius_node, dtype=np.float64), np.ascontiguousarray(k_pen),
                scene.pl_axis.astype(np.int64), scene.pl_sign.astype(np.float64), scene.pl_pos0.astype(np.float64),
                scene.pl_move.astype(np.float64), scene.pl_T.astype(np.float64), scene.pl_ta.astype(np.float64),
                scene.pl_mode.astype(np.int64), scene.pl_pos0.astype(np.float64).copy(), np.zeros((P, 3)),
                np.zeros((N, max(P, 1), 4)), np.zeros((max(P, 1), 3)), List([np.zeros(cap, np.int64)]),
                np.zeros(N * P, np.int64), np.zeros(P + 1, np.int64), scene.pl_pos0.astype(np.float64).copy(),
                np.zeros((N, 3)), np.zeros(N, np.int64), np.full(N, -1, np.int64))
        info.data = data
        return data

    hook = ContactHook(kernel=contact_step, prepare=prepare)
    hook.setup_info = info
    if not contact:
        hook.name = "friction"
    return hook


def contact_effect(model, scene_cfg, material=None):
    """The scene's fiber–fiber contact (and friction) as a :class:`ContactHook`.

    Reads ``scene_cfg.effects`` (``contact``, ``friction``), ``scene_cfg.contact`` (``law``,
    ``preset``/``k_def``/``s0``/``s``/``d``, ``stiffness``, ``angle``, ``skin``) and
    ``scene_cfg.friction`` (``mu``, ``stiffness`` = k_t in N/m). ``material``: the solver's
    :class:`fiberpipe.solver.model.Material` (default: the model's).
    """
    material = material if material is not None else model.material
    effects = list(getattr(scene_cfg, "effects", []) or [])
    contact_on = "contact" in effects
    friction_on = "friction" in effects
    ccfg = getattr(scene_cfg, "contact", None)
    fcfg = getattr(scene_cfg, "friction", None)
    law = law_from_config(ccfg, material)
    skin = getattr(ccfg, "skin", None) if ccfg is not None else None
    mu = float(getattr(fcfg, "mu", 0.2)) if fcfg is not None else 0.2
    kt = getattr(fcfg, "stiffness", None) if fcfg is not None else None
    rel = getattr(ccfg, "overlap_release", None) if ccfg is not None else None
    rel = DEFAULT_OVERLAP_RELEASE_S if rel is None else float(rel)
    return make_contact_hook(model, law=law, contact=contact_on, friction=friction_on, mu=mu,
                             k_t=None if kt is None else float(kt), skin_m=None if skin is None else float(skin),
                             overlap_release_s=rel)
