"""Regularised Coulomb friction with per-contact history (fiber–fiber and fiber–plane).

Model (Wriggers, *Computational Contact Mechanics*, 2006, §5.2; Abaqus/Explicit penalty friction):
a tangential penalty spring ``k_t`` [N/m] (elastic stick) and a return map onto the Coulomb cone
``|f_t| ≤ μ f_n``:

1. history ``f_t`` (the elastic tangential force of the contact) is rotated into the current
   tangent plane: ``f_t ← f_t − (f_t·n)n``, rescaled to its old magnitude;
2. trial ``f_t* = f_t − k_t Δu_t``, with ``Δu_t`` the tangential part of the relative displacement
   increment of the contact points over the step, ``Δu = (v_A(s̄) − v_B(t̄)) Δt`` at the mean
   ``s̄``, ``t̄`` of this step's contact parameters and those the previous force acted at;
3. stick if ``|f_t*| ≤ μ f_n``; else slip: ``f_t = μ f_n f_t*/|f_t*|``;
4. an open contact (``f_n = 0``) forgets its history.

Dissipation, per contact and step: the energy the contact took from the fibers less what its
spring stored (the step loop's ALLFD is the same sum taken on the nodes, over the contacts that left
too: the node update books the friction forces' work, ``terms.contact._friction_pass`` the springs'), ``D = −½(f_{n−1}·Δu' + f_n·Δu) − (½|f_n|²/k_n − ½|f_{n−1}|²/k_{n−1})``, with ``Δu``
the relative displacement over the step at this step's contact point and ``Δu'`` at the point the
previous force acted at (the contact point slides along the segments). The first term is the
friction forces' work as the step loop books it (``½Δt f_n·(v_{n−½} + v_{n+½})``, summed by parts),
so ALLFD + the springs' energy equals minus that work and the state-function balance closes with
friction on. In steady slip ``D = μ f_n × slip``; where the slip direction turns or the cone
shrinks between steps (stick–slip chatter, a release) the end-of-step product ``μ f_n × slip``
would over- or under-book the force's work by ``½(|f_t*| − μ f_n)(μ f_n − f_{n−1}·t̂)/k_t``.
The spring stretches at the middle of the contact point's path (step 2): a stuck contact whose
point slides then books ``¼(f_{n−1} − f_n)·(Δu − Δu')``, second order in the step, where a
spring stretched at this step's point would book ``½ f_{n−1}·(Δu − Δu')``. ``D < 0`` is friction
giving energy back; its sum is kept apart (``returned``).

Fiber–fiber: one history per segment pair, keyed ``i·E + j`` (the Verlet list's sorted keys), applied
at the pair's force-weighted contact point (``c_s``, ``c_t`` from the contact kernel) along its
resultant normal ``c_n``; :func:`remap_history` carries it across neighbour-list rebuilds by
``searchsorted`` on the sorted keys. Fiber–plane (:func:`plane_friction`, the planes term's): one
history per (node, plane), so it needs no remap; its normal force is the plane penalty's.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._tasks import SCATTER_TASKS, task_count
from .contact_state import PairRecords
from .geometry import apply_pair_force, apply_pair_force_owned, pair_nodes


@njit(cache=True, fastmath=True, error_model="numpy")
def _return_map(h, k, n0, n1, n2, du0, du1, du2, fn, mu, kt):
    """Update history row h[k] in place; returns the new f_t vector (3)."""
    # rotate history into the current tangent plane, keep its magnitude
    h0 = h[k, 0]
    h1 = h[k, 1]
    h2 = h[k, 2]
    old2 = h0 * h0 + h1 * h1 + h2 * h2
    hn = h0 * n0 + h1 * n1 + h2 * n2
    if hn != 0.0:
        h0 -= hn * n0
        h1 -= hn * n1
        h2 -= hn * n2
        new2 = h0 * h0 + h1 * h1 + h2 * h2
        if new2 > 0.0:
            scale = math.sqrt(old2 / new2)
            h0 *= scale
            h1 *= scale
            h2 *= scale
    un = du0 * n0 + du1 * n1 + du2 * n2
    t0 = h0 - kt * (du0 - un * n0)
    t1 = h1 - kt * (du1 - un * n1)
    t2 = h2 - kt * (du2 - un * n2)
    tm2 = t0 * t0 + t1 * t1 + t2 * t2
    lim = mu * fn
    # stick (the common case of a compacted bundle) needs no square root
    if tm2 > lim * lim:
        scale = lim / math.sqrt(tm2)
        t0 *= scale
        t1 *= scale
        t2 *= scale
    h[k, 0] = t0
    h[k, 1] = t1
    h[k, 2] = t2
    return t0, t1, t2


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _dissipated(p0, p1, p2, q0, q1, q2, e_prev, f0, f1, f2, du0, du1, du2, e_new):
    """Energy a contact dissipated over the step (module docstring): minus the trapezoidal work of its
    forces, ``f_{n−1} = p`` on the relative displacement ``Δu' = q`` at the point it acted at and
    ``f_n = f`` on ``Δu`` at this step's, less the change of its spring's energy ``e_prev`` → ``e_new`` [J]."""
    return -0.5 * (p0 * q0 + p1 * q1 + p2 * q2 + f0 * du0 + f1 * du1 + f2 * du2) - (e_new - e_prev)


@njit(cache=True, fastmath=True, error_model="numpy")
def friction_forces(v, seg_nodes, pairs, n_pairs, c_fn, c_n, c_s, c_t, mu, k_t, dt, hist, f_out):
    """Fiber–fiber friction with the full ``k_t`` on every pair in contact (see :func:`friction_forces_ex`);
    returns the dissipated energy [J]."""
    e = np.zeros(0)
    rec = PairRecords(c_fn, c_n, c_s, c_t, e, e, e, e, e, np.zeros(0, np.int64))
    d, es, back = friction_forces_ex(v, seg_nodes, pairs, n_pairs, rec, mu, k_t, dt, hist, f_out, 0, -1)
    return d


@njit(cache=True, fastmath=True, error_model="numpy")
def friction_forces_ex(v, seg_nodes, pairs, n_pairs, rec, mu, k_t, dt, hist, f_out, n_active, step):
    """Fiber–fiber friction forces, accumulated into ``f_out``; returns the dissipated energy [J].

    Parameters
    ----------
    v : (N, 3) float64, m/s — node velocities (half step). seg_nodes : (E, 2) int64.
    pairs, n_pairs : the Verlet list (as passed to the contact kernel in the same step).
    rec : :class:`fiberpipe.solver.contact_state.PairRecords` of the contact kernel from this step:
        ``fn`` (normal force N), ``normal`` (unit normal from the second segment to the first), ``s``,
        ``t`` (contact parameters on the two segments), ``share`` and ``active`` (below).
    mu : Coulomb coefficient. k_t : N/m, tangential penalty stiffness. dt : s.
    hist : (C, 3) or (C, 4) float64 — elastic tangential force per pair [N] (in/out), aligned with
        ``pairs``; a 4th column holds the pair's k_t at its last update (N/m; with ``c_share``).
    f_out : (N, 3) float64 — accumulated into; +f_t on the first segment, −f_t on the second.
    rec.share : (P,) float64 — the pair's contact share (:func:`fiberpipe.solver.contact_potential.contact_forces_pot`);
        the pair's tangential stiffness is ``k_t × share`` (size 0: ``k_t``). Without it a contact
        split over several segment pairs (parallel fibers: each segment touches 2–3 of the other
        fiber) gets ``k_t`` per pair, so a node's tangential stiffness grew with the number of pairs
        and the tangential springs went unstable at ``dt_safety`` 0.9 (energy gain, tens of m/s).

    rec.active, n_active : (n_active,) int64 — the pairs in contact (``active`` of the contact kernel);
        size 0: visit all ``n_pairs`` and clear the history of the open ones. step : int — this
        step's number (< 0: no time stamps); with ``c_active``, ``step ≥ 0`` and a 5th ``hist``
        column (the step of the pair's last update) only the pairs in contact are visited, and a pair's history counts only if it was
        updated at ``step − 1`` (a contact that opened in between starts afresh, as if cleared).
        Columns 5 and 6 (optional): the ``s``, ``t`` the pair's force last acted at, for its work.
    Returns (dissipated energy [J], elastic energy of the tangential springs after the update [J],
    energy given back [J]: the sum of the contacts' negative dissipations, module docstring).
    """
    lazy, n_visit = _visits(rec, hist, step, n_active, n_pairs)
    return _friction_range(v, seg_nodes, pairs, rec, mu, k_t, dt, hist, f_out, step, lazy, 0, n_visit, hist[:0, :3])


@njit(cache=True, inline="always")
def _visits(rec, hist, step, n_active, n_pairs):
    """``(lazy, n_visit)`` of :func:`friction_forces_ex`: with an active list, time stamps (column 4)
    and ``step`` ≥ 0 only the ``n_active`` pairs in contact are visited, else all ``n_pairs``."""
    lazy = rec.active.shape[0] > 0 and hist.shape[1] > 4 and step >= 0
    return lazy, (n_active if lazy else n_pairs)


@njit(cache=True, fastmath=True, error_model="numpy")
def _friction_range(v, seg_nodes, pairs, rec, mu, k_t, dt, hist, f_out, step, lazy, lo, hi, fpair):
    """The pairs ``lo … hi − 1`` of :func:`friction_forces_ex` (of its active list if ``lazy``, else of
    the Verlet list): their forces into ``f_out`` at once (``fpair`` of size 0, a view: the serial
    pass runs without reference counts and allocates nothing), or into the rows
    ``kk`` of ``fpair`` (N, 3) for a merge in pair order (:func:`friction_forces_tasks`); returns the
    range's three sums."""
    c_fn, c_n, c_s, c_t, c_share, c_active = rec.fn, rec.normal, rec.s, rec.t, rec.share, rec.active
    scatter = fpair.shape[0] == 0
    diss = 0.0
    espring = 0.0
    returned = 0.0
    use_share = c_share.shape[0] > 0
    keep_k = use_share and hist.shape[1] > 3  # column 3: the pair's k_t at its last update
    at_st = hist.shape[1] > 6  # columns 5, 6: the contact parameters the force last acted at
    for kk in range(lo, hi):
        k = c_active[kk] if lazy else kk
        if not scatter:
            fpair[kk, 0] = 0.0
            fpair[kk, 1] = 0.0
            fpair[kk, 2] = 0.0
        fn = c_fn[k]
        if lazy:
            if hist[k, 4] != step - 1:
                for c in range(4):
                    hist[k, c] = 0.0
            hist[k, 4] = step
        elif fn <= 0.0:
            # open: the contact forgets its history. Its spring's energy, at most ½(μ f_n)²/k_t of its
            # last step in contact (f_n rises from zero over the onset), is not booked, as for a
            # pair that leaves the active list (not visited)
            for c in range(hist.shape[1]):
                hist[k, c] = 0.0
            continue
        i, j, a0, a1, b0, b1 = pair_nodes(pairs, seg_nodes, k)
        s = c_s[k]
        t = c_t[k]
        # the force applied at the previous step and its spring's energy, as booked then
        p0 = hist[k, 0]
        p1 = hist[k, 1]
        p2 = hist[k, 2]
        # the contact parameters it acted at (columns 5, 6; this step's for a new contact)
        held = at_st and (p0 != 0.0 or p1 != 0.0 or p2 != 0.0)
        sp = hist[k, 5] if held else s
        tp = hist[k, 6] if held else t
        # Δu(s, t) = u0 + s ga − t gb over the step: linear in the contact parameters
        u0 = (v[a0, 0] - v[b0, 0]) * dt
        u1 = (v[a0, 1] - v[b0, 1]) * dt
        u2 = (v[a0, 2] - v[b0, 2]) * dt
        ga0 = (v[a1, 0] - v[a0, 0]) * dt
        ga1 = (v[a1, 1] - v[a0, 1]) * dt
        ga2 = (v[a1, 2] - v[a0, 2]) * dt
        gb0 = (v[b1, 0] - v[b0, 0]) * dt
        gb1 = (v[b1, 1] - v[b0, 1]) * dt
        gb2 = (v[b1, 2] - v[b0, 2]) * dt
        du0 = u0 + s * ga0 - t * gb0
        du1 = u1 + s * ga1 - t * gb1
        du2 = u2 + s * ga2 - t * gb2
        # the spring stretches by Δu at the middle of the contact point's path over the step:
        # the previous force acted at (sp, tp), this one at (s, t), and with the midpoint their
        # trapezoidal work and the spring's energy differ only by ¼(f_{n−1} − f_n)·(Δu − Δu'),
        # second order in the step, instead of ½ f_{n−1}·(Δu − Δu')
        sm = 0.5 * (sp + s)
        tm = 0.5 * (tp + t)
        dm0 = u0 + sm * ga0 - tm * gb0
        dm1 = u1 + sm * ga1 - tm * gb1
        dm2 = u2 + sm * ga2 - tm * gb2
        ktp = k_t * c_share[k] if use_share else k_t
        k_prev = hist[k, 3] if keep_k and hist[k, 3] > 0.0 else ktp
        e_prev = 0.5 * (p0 * p0 + p1 * p1 + p2 * p2) / k_prev if k_prev > 0.0 else 0.0
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        e_new = 0.0
        if ktp > 0.0:
            if keep_k:
                # the pair's stiffness changed since its last update (the contact moved/grew/shrank):
                # softer: scale f_t by √(k_new/k_old), which keeps the stored energy ½|f_t|²/k;
                # stiffer: keep f_t (its energy falls, booked as dissipated with the step's)
                if 0.0 < ktp < k_prev:
                    scale = math.sqrt(ktp / k_prev)
                    hist[k, 0] *= scale
                    hist[k, 1] *= scale
                    hist[k, 2] *= scale
                hist[k, 3] = ktp
            f0, f1, f2 = _return_map(hist, k, c_n[k, 0], c_n[k, 1], c_n[k, 2], dm0, dm1, dm2, fn, mu, ktp)
            e_new = 0.5 * (f0 * f0 + f1 * f1 + f2 * f2) / ktp
            if scatter:
                apply_pair_force(f_out, (a0, a1, b0, b1), s, t, f0, f1, f2)
            else:
                fpair[kk, 0] = f0
                fpair[kk, 1] = f1
                fpair[kk, 2] = f2
        else:
            # no stiffness: the contact forgets its force (its energy, booked as dissipated)
            hist[k, 0] = 0.0
            hist[k, 1] = 0.0
            hist[k, 2] = 0.0
        # the previous force works on Δu(sp, tp), the point it acted at
        d = _dissipated(p0, p1, p2, u0 + sp * ga0 - tp * gb0, u1 + sp * ga1 - tp * gb1, u2 + sp * ga2 - tp * gb2,
                        e_prev, f0, f1, f2, du0, du1, du2, e_new)
        if at_st:
            hist[k, 5] = s
            hist[k, 6] = t
        diss += d
        returned -= min(d, 0.0)
        espring += e_new
    return diss, espring, returned


# tasks of the threaded friction (solver.threads > 1): consecutive pairs of the active list, at least
# this many each (below two tasks' worth the pairs run in one, as in the serial pass). A pair costs
# about 65 ns, and below a few hundred pairs the tasks cost more than they save: the second core
# reads the records and histories the first one wrote. paper-40 (140–250 pairs in contact) took 23
# instead of 9 µs per step in two tasks of 64 or more pairs each
FRICTION_TASKS = 8
FRICTION_TASK_MIN = 256


def _friction_tasks(v, seg_nodes, pairs, n_pairs, rec, mu, k_t, dt, hist, f_out, n_active, step):
    """:func:`friction_forces_ex` with its pairs in ``prange`` tasks (``solver.threads`` > 1): each
    pair's force goes to its row, and the rows are added to ``f_out`` after the tasks in pair order,
    so the forces are the serial pass's bit for bit; the sums are taken per task, then in order."""
    # Strategy: a pair writes only its own history row and its force row, so the tasks share nothing;
    # the scatter to the nodes (two pairs may share a node) stays serial, in the serial pass's order
    lazy, n_visit = _visits(rec, hist, step, n_active, n_pairs)
    n_tasks = task_count(n_visit, FRICTION_TASK_MIN, FRICTION_TASKS)
    if n_tasks < 2:
        return friction_forces_ex(v, seg_nodes, pairs, n_pairs, rec, mu, k_t, dt, hist, f_out, n_active, step)
    fpair = np.empty((n_visit, 3))
    sums = np.zeros((n_tasks, 3))
    _friction_task_pass(v, seg_nodes, pairs, rec, mu, k_t, dt, hist, f_out, step, lazy, n_visit, fpair, sums)
    _friction_scatter_pass(seg_nodes, pairs, rec, f_out, lazy, n_visit, fpair)
    diss = 0.0
    espring = 0.0
    returned = 0.0
    for task in range(sums.shape[0]):
        diss += sums[task, 0]
        espring += sums[task, 1]
        returned += sums[task, 2]
    return diss, espring, returned


# Not cached, as _kernels_beam.beam_pass_fibers (its comment). Without reference counts: both cores
# counting on the same arrays' records send those cache lines back and forth between them.
@njit(cache=False, fastmath=True, error_model="numpy", parallel=True, _nrt=False)
def _friction_task_pass(v, seg_nodes, pairs, rec, mu, k_t, dt, hist, f_out, step, lazy, n_visit, fpair, sums):
    """The tasks of :func:`_friction_tasks`: ``sums.shape[0]`` spans of the ``n_visit`` pairs, each
    pair's force into its row of ``fpair``, each task's sums into its row of ``sums``."""
    n_tasks = sums.shape[0]
    for task in prange(n_tasks):
        d, e, r = _friction_range(v, seg_nodes, pairs, rec, mu, k_t, dt, hist, f_out, step, lazy,
                                  task * n_visit // n_tasks, (task + 1) * n_visit // n_tasks, fpair)
        sums[task, 0] = d
        sums[task, 1] = e
        sums[task, 2] = r


@njit(cache=False, fastmath=True, error_model="numpy", parallel=True, _nrt=False)
def _friction_scatter_pass(seg_nodes, pairs, rec, f_out, lazy, n_visit, fpair):
    """The forces of :func:`_friction_tasks`'s rows onto the nodes in pair order, each task adding
    those on its share of the nodes (every node's additions in the serial pass's order: the same
    sums bit for bit). Not cached, as :func:`_friction_task_pass`."""
    c_s, c_t, c_active = rec.s, rec.t, rec.active
    n_nodes = f_out.shape[0]
    n_owners = SCATTER_TASKS
    for owner in prange(n_owners):
        owned = (owner * n_nodes // n_owners, (owner + 1) * n_nodes // n_owners)
        for kk in range(n_visit):
            k = c_active[kk] if lazy else kk
            i, j, a0, a1, b0, b1 = pair_nodes(pairs, seg_nodes, k)
            apply_pair_force_owned(f_out, (a0, a1, b0, b1), c_s[k], c_t[k], fpair[kk, 0], fpair[kk, 1],
                                   fpair[kk, 2], owned)


# Not cached: it links the parallel _friction_task_pass (see _kernels_beam.beam_pass_fibers's comment);
# only the solver.threads > 1 loops use it
friction_forces_tasks = njit(cache=False, fastmath=True, error_model="numpy", _nrt=True)(_friction_tasks)


@njit(cache=True, error_model="numpy")
def remap_history(old_keys, old_n, old_hist, new_keys, new_n, new_hist):
    """Carry friction history across a neighbour-list rebuild by matching sorted pair keys.

    ``new_hist[k] = old_hist[m]`` where ``old_keys[m] == new_keys[k]``, else 0. Both key arrays
    sorted ascending (as :func:`fiberpipe.solver.neighbours.build_pairs` writes them). Returns the
    number of histories carried over.
    """
    # both lists sorted: one merge walk, O(old_n + new_n) in memory order (a binary search per pair
    # cost 100 ns at 286 000 pairs, half a rebuild, in cache misses)
    kept = 0
    m = 0
    for k in range(new_n):
        key = new_keys[k]
        while m < old_n and old_keys[m] < key:
            m += 1
        if m < old_n and old_keys[m] == key:
            for c in range(new_hist.shape[1]):
                new_hist[k, c] = old_hist[m, c]
            kept += 1
        else:
            for c in range(new_hist.shape[1]):
                new_hist[k, c] = 0.0
    return kept


@njit(cache=True, fastmath=True, error_model="numpy")
def plane_friction(v, friction, dt, step):
    """Friction of rigid planes on the nodes touching them, from the plane pass of this step.

    ``friction`` : the planes' friction data (:class:`fiberpipe.solver.terms.planes.PlaneFrictionData`):
    its ``planes`` (:class:`fiberpipe.solver.step_data.PlaneArrays`) after the plane pass
    (:func:`fiberpipe.solver._kernels_boundary.plane_contacts_listed`), with the list of the nodes near
    each plane (``cand_idx``, ``cand_off``) and each listed node's normal force ``cand_fn`` [N]
    (``k_i g(δ) g'(δ)``, −1 where the node does not touch the plane); ``mu`` (P,) and
    ``kt_n_per_m`` (P,) per plane, the planes' velocities ``vel`` (P, 3) m/s, the history ``hist``
    (N, P, 4) [N] of each (node, plane) entry with the step of its last update in column 3, the
    tangential reaction ``tforce`` (P, 3) on each plane (out) and the friction force array ``ff``
    (N, 3) the forces are added to. ``step`` ≥ 0: this step's number; an entry's history counts only
    if it was updated at ``step − 1``, so a node that left the plane starts afresh when it comes
    back. Here only the tangential force, from the node's velocity relative to the plane, returned
    onto the cone ``μ f_n`` (the normal force is the plane pass's). Returns (the dissipated energy
    [J], the elastic energy of the tangential springs [J], the energy given back [J], as
    :func:`friction_forces_ex`).
    """
    planes = friction.planes  # one argument: each array a call passes is reference-counted on entry and exit
    pl_axis, pl_sign, cand_idx, cand_off, cand_fn = planes.axis, planes.sign, planes.cand_idx, planes.cand_off, planes.cand_fn
    pl_vel, hist, pl_tforce, f_out = friction.vel, friction.hist, friction.tforce, friction.ff
    diss = 0.0
    espring = 0.0
    returned = 0.0
    npl = pl_axis.shape[0]
    for p in range(npl):
        pl_tforce[p, 0] = 0.0
        pl_tforce[p, 1] = 0.0
        pl_tforce[p, 2] = 0.0
    hflat = hist.reshape(hist.shape[0] * npl, hist.shape[2])  # a view (C-contiguous): no per-node view
    # plane outer, node inner (one axis per plane: a tight loop over the listed nodes)
    for p in range(npl):
        mu = friction.mu[p]
        if mu == 0.0:
            continue
        k_t = friction.kt_n_per_m[p]
        ax = pl_axis[p]
        sg = pl_sign[p]
        n0 = 0.0
        n1 = 0.0
        n2 = 0.0
        if ax == 0:
            n0 = sg
        elif ax == 1:
            n1 = sg
        else:
            n2 = sg
        for c in range(cand_off[p], cand_off[p + 1]):
            i = cand_idx[c]
            fn = cand_fn[c]
            r = i * npl + p
            touched = hflat[r, 3] == step - 1  # the entry holds the force of the last step
            p0 = hflat[r, 0] if touched else 0.0
            p1 = hflat[r, 1] if touched else 0.0
            p2 = hflat[r, 2] if touched else 0.0
            if fn < 0.0 and p0 == 0.0 and p1 == 0.0 and p2 == 0.0:
                continue
            du0 = (v[i, 0] - pl_vel[p, 0]) * dt
            du1 = (v[i, 1] - pl_vel[p, 1]) * dt
            du2 = (v[i, 2] - pl_vel[p, 2]) * dt
            e_prev = 0.5 * (p0 * p0 + p1 * p1 + p2 * p2) / k_t
            if fn < 0.0:
                # off the plane: the entry forgets its force, whose energy is dissipated
                hflat[r, 0] = 0.0
                hflat[r, 1] = 0.0
                hflat[r, 2] = 0.0
                dd = _dissipated(p0, p1, p2, du0, du1, du2, e_prev, 0.0, 0.0, 0.0, du0, du1, du2, 0.0)
                diss += dd
                returned -= min(dd, 0.0)
                continue
            if not touched:  # a stale entry starts afresh
                hflat[r, 0] = 0.0
                hflat[r, 1] = 0.0
                hflat[r, 2] = 0.0
            hflat[r, 3] = step
            f0, f1, f2 = _return_map(hflat, r, n0, n1, n2, du0, du1, du2, fn, mu, k_t)
            e_new = 0.5 * (f0 * f0 + f1 * f1 + f2 * f2) / k_t
            dd = _dissipated(p0, p1, p2, du0, du1, du2, e_prev, f0, f1, f2, du0, du1, du2, e_new)
            diss += dd
            returned -= min(dd, 0.0)
            espring += e_new
            f_out[i, 0] += f0
            f_out[i, 1] += f1
            f_out[i, 2] += f2
            pl_tforce[p, 0] -= f0
            pl_tforce[p, 1] -= f1
            pl_tforce[p, 2] -= f2
    return diss, espring, returned
