"""The contact term: fiber–fiber normal contact and friction (``scene.effects`` entries ``contact``
and ``friction``, blocks ``scene.contact`` and ``scene.friction``; the fibers' friction on the plates
and walls is the planes term's, :mod:`fiberpipe.solver.terms.planes`).

:class:`ContactEffect` builds a :class:`~fiberpipe.solver.terms.base.ContactHook` whose kernel
:func:`contact_step` runs once per step on a :class:`fiberpipe.solver.contact_state.ContactData`
(see ``docs/solver.md`` and ``docs/contact.md``):

1. Verlet list: rebuilt when a node has moved more than skin/2 since the last build (or at the first
   call); the new list goes into the spare buffers, the friction history is remapped by pair key,
   then the buffers are swapped. Buffers live in numba typed lists inside ``data``, so the kernel
   grows them itself when :func:`fiberpipe.solver.neighbours.build_pairs` reports an overflow
   (no Python round trip, no lost contacts).
2. Normal contact forces (:func:`fiberpipe.solver.contact_potential.contact_forces_pot`) with the
   scene's law (one class each in ``laws.LAWS``).
3. Friction (if ``friction`` is in ``scene.effects``): fiber–fiber
   (:func:`fiberpipe.solver.friction.friction_forces`).
4. The normal contact forces stay in the term's force array (``data.fc``, declared by its
   ``forces_of``), the friction forces go to the scene's friction array (``data.ff``,
   ``SceneArrays.friction_forces``): the step loop's update adds both to the nodes, books their work
   ``Δt f_n·v̄_n`` to ALLPW, and clears them, in the same pass over the nodes. The friction forces'
   work is also booked to the friction work (``energy/friction_work``, W_f) and, as a loss, to
   ALLFD, by halves over the displacement the friction springs' energy changes by:
   ``½Δt (f_{n−1} + f_n)·v_{n−½}`` at step n (``layout.ACC_WF_NEXT`` carries the second half). The
   term books the springs' energy change: ALLFD −= ΔE_springs and ALLPW −= ΔE_springs, so ALLFD =
   −W_f − ΔE_springs, and ALLPW = W_normal + W_f + ALLFD. With ETOTAL = KE + SE + VD + FD − WK − PW
   this keeps the balance (PW holds the elastic contact energy and the friction loss, as Abaqus'
   ALLPW includes penalty friction).

Returns the number of fiber–fiber segment pairs in contact (history column ``contacts``).
Forces act on the centre lines (no moments; friction does not make fibers roll): see
``docs/contact.md`` "What's left".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.typed import List

from ...errors import FiberpipeError
from ..contact_pairs import gauss_points
from ..contact_potential import contact_forces_pot, contact_forces_pot_threads, onset, potential_kernels_for
from .base import ContactHook, check_friction_stiffness, penalty_step_bound, register_term  # noqa: F401 (penalty_step_bound: this module's API)
from .._specialise import specialise
from ..contact_state import (ContactData, ContactParams, Segments, borrowed_item, new_pair_list, new_records,
                            new_stats)
from ..friction import friction_forces_ex, friction_forces_tasks, remap_history
from ..geometry import pair_gap
from ..layout import ACC_FD, ACC_PW, ACC_STORED, ACC_V2_MAX, ACC_WK
from ..neighbours import build_pairs, build_pairs_threads, max_displacement2, max_displacement2_speed2

DEFAULT_SKIN_FACTOR = 0.2          # skin = 0.2 r_max (0.05 r_max: 22 % fewer pairs, no measurable gain)
DEFAULT_PAIRS_PER_SEGMENT = 16     # initial capacity per segment (grown by the kernel if needed)
OVERLAP_MIN_FRACTION = 0.05        # initial penetrations below 5 % of the smaller radius act at once
                                   # (pressed set-ups, verification cases): no offset

_FLAGS = dict(cache=True, fastmath=True, error_model="numpy")
_NO_COUNTS = dict(_nrt=False, no_cpython_wrapper=True)  # see _step_forces_pass below


@njit(cache=True, error_model="numpy", _nrt=True)
def _rebuild(x, data):
    """Build the Verlet list into the spare buffers (growing them if needed), remap the friction
    history and the initial-overlap offsets, swap."""
    params, st, segs = data.params, data.stats, data.segs
    while True:
        spare = data.lists[1]
        n = build_pairs(x, segs.nodes, segs.radius, segs.fiber, segs.arc, params.skin_m, params.exclusion_m,
                        spare.pairs, spare.keys)
        if n >= 0:
            break
        data.lists[1] = new_pair_list(int(1.5 * (-n)) + 64)
        st.n_grow[0] += 1
    if data.records[0].fn.shape[0] < n:
        data.records[0] = new_records(spare.pairs.shape[0])
    cur = data.lists[0]
    if params.friction_on:
        remap_history(cur.keys, st.n_pairs[0], cur.friction, spare.keys, n, spare.friction)
    if st.offset_max_m[0] > 0.0:
        remap_history(cur.keys, st.n_pairs[0], cur.offset, spare.keys, n, spare.offset)
    else:
        spare.offset[:n, 0] = 0.0
    data.lists[0] = spare
    data.lists[1] = cur
    st.n_pairs[0] = n
    st.n_builds[0] += 1
    x_ref = data.x_ref
    for i in range(x.shape[0]):  # not x_ref[:, :] = x: see _kernels_integrate.eval_external
        for c in range(3):
            x_ref[i, c] = x[i, c]
    # each pair's gap at this build (clamped segment distance − r_i − r_j): the contact pass skips
    # a pair while the gap exceeds twice the path bound since (and refreshes it when it looks)
    # (the potential kernel leaves fn alone for the pairs it skips: every pair starts at fn = 0)
    rec = data.records[0]
    gap = rec.gap
    for k in range(n):
        gap[k] = pair_gap(x, segs.nodes, segs.radius, spare.pairs, k)
        rec.fn[k] = 0.0


@njit(inline="always", **_FLAGS)
def _update_neighbours(x, v, dt, acc, data):
    """Rebuild the Verlet list when needed (step 1 of the module docstring); returns whether it was.

    ``acc[ACC_V2_MAX]`` ≥ 0 is the largest |v|² of ``v``, as the step loop's update left it; < 0
    (the first step of a step-loop call, whose state may have been set from outside) takes it and
    the displacement test from ``v`` and ``x`` here."""
    st = data.stats
    half_skin = 0.5 * data.params.skin_m
    vm2 = acc[ACC_V2_MAX]
    known = vm2 >= 0.0
    if not known:
        dm2, vm2 = max_displacement2_speed2(x, data.x_ref, v)
    # v holds v_{n−½}, the velocity that moved every node from x_{n−1} to x_n
    st.path_m[0] += dt * math.sqrt(vm2)
    # the path bound holds only while positions change through the velocities (x_n = x_{n−1} + Δt v);
    # a node farther from its build position than the bound allows was moved from outside (a new or
    # edited state): rebuild, which restarts every bound from the positions as they are
    path = st.path_m[0]
    bound = path * (1.0 + 1e-12) + 1e-15
    if known:
        # within a call x moved only through v, so no node is farther than the bound from its build
        # position: the pass over the nodes is needed only once the bound exceeds half the skin
        dm2 = max_displacement2(x, data.x_ref) if bound > half_skin else 0.0
    moved_outside = dm2 > bound * bound
    rebuild = st.n_builds[0] == 0 or dm2 > half_skin * half_skin or moved_outside
    if rebuild:
        _rebuild(x, data)
        st.path_m[0] = 0.0
    return rebuild


@njit(inline="always", **_FLAGS)
def _normal_forces(x, data, plist, rec, off, reach):
    """The normal contact pass (:func:`fiberpipe.solver.contact_potential.contact_forces_pot`: every
    force minus the gradient of the stored potential): forces into ``data.fc``, per-pair records into
    ``data.records[0]``; returns (energy, n_active)."""
    params, st, segs = data.params, data.stats, data.segs
    return contact_forces_pot(x, segs.nodes, segs.radius, segs.arc, plist.pairs, st.n_pairs[0], params.law_id,
                              params.law_params, params.gauss_xi, params.gauss_w, params.onset_m, data.fc, rec, off, reach)


@njit(**_FLAGS)
def _record_initial_overlaps(x, data, reach):
    """First call: each pair's penetration at t = 0 becomes its offset (released over
    ``params.release_s``), so overlapping input is pushed apart gradually."""
    st, segs = data.stats, data.segs
    plist, rec = data.lists[0], data.records[0]
    n_pairs = st.n_pairs[0]
    _normal_forces(x, data, plist, rec, np.zeros(0), reach)
    omax = 0.0
    for k in range(n_pairs):
        i = plist.pairs[k, 0]
        j = plist.pairs[k, 1]
        o = rec.delta[k] if rec.fn[k] > 0.0 else 0.0
        if o < OVERLAP_MIN_FRACTION * min(segs.radius[i], segs.radius[j]):
            o = 0.0
        plist.offset[k, 0] = o
        if o > omax:
            omax = o
    st.offset_max_m[0] = omax
    data.fc[:, :] = 0.0


@njit(inline="always", **_FLAGS)
def _overlap_offsets(data, t, dt):
    """The offsets at t_n, ``δ0·(1 − t/T_release)⁺`` per pair: ``(off, rel, rel_prev)`` (off of size 0
    once released)."""
    st = data.stats
    T_rel = data.params.release_s
    off = np.zeros(0)
    rel = 0.0
    rel_prev = 0.0
    if st.offset_max_m[0] > 0.0:
        if T_rel > 0.0:
            rel = max(0.0, 1.0 - t / T_rel)
            rel_prev = max(0.0, 1.0 - (t - dt) / T_rel) if t > 0.0 else rel
        if rel > 0.0:
            n_pairs = st.n_pairs[0]
            off0 = data.lists[0].offset
            off = np.empty(n_pairs)
            for k in range(n_pairs):
                off[k] = off0[k, 0] * rel
        else:
            st.offset_max_m[0] = 0.0  # released: no offsets any more (new pairs get none either)
    return off, rel, rel_prev


@njit(inline="always", **_FLAGS)
def _friction_pass(v, dt, data, plist, rec, n_active, calls):
    """Fiber–fiber friction into ``ff`` (step 3). Returns the springs' part of the dissipation: minus
    the change of their energy (``stats.e_spring_J``).

    The friction forces' work is booked by the step loop's update, which applies ``ff`` (the
    scene's friction array; module docstring, item 4), on every node the forces act on, so a contact
    that leaves (out of contact, out of the neighbour list) leaves none of its work unbooked. ALLFD
    is then ``−W_f − ΔE_springs``. The contacts' own sums (the kernel's first return, module
    ``friction``) are not used for it; their negative parts are summed apart
    (``friction_returned_J``)."""
    params, st = data.params, data.stats
    _, e_springs, back = friction_forces_ex(v, data.segs.nodes, plist.pairs, st.n_pairs[0], rec, params.mu,
                                            params.kt_n_per_m, dt, plist.friction, data.ff, n_active, calls)
    st.friction_returned_J[0] += back
    diss = -(e_springs - st.e_spring_J[0])
    st.e_spring_J[0] = e_springs
    return diss


@njit(inline="always", **_FLAGS)
def _statistics(data, rec, n_active):
    """Σ normal force, the largest penetration and the largest secant stiffness F_n/δ of this step's
    contacts (the last two as peaks for the run's slope watch)."""
    st = data.stats
    fsum = 0.0
    dmax = 0.0
    ks = st.secant_peak_n_per_m[0]
    for kk in range(n_active):
        k = rec.active[kk]
        fsum += rec.fn[k]
        if rec.delta[k] > dmax:
            dmax = rec.delta[k]
        if rec.fn[k] > ks * rec.delta[k]:  # no division for the pairs below the peak
            ks = rec.fn[k] / rec.delta[k]
    st.fn_sum_n[0] = fsum
    st.delta_max_m[0] = dmax
    st.secant_peak_n_per_m[0] = ks
    if dmax > st.delta_peak_m[0]:
        st.delta_peak_m[0] = dmax
    st.n_active[0] = n_active


@njit(cache=True, inline="always")
def contact_forces_of(data):
    """The force array (N, 3) [N] :func:`contact_step` leaves its forces in (the hook's ``forces_of``):
    the step loop's update adds it to the nodes, books its work ``Δt f_n·v̄_n`` (``v̄_n`` the mean
    of the two half-step velocities, in phase with the kinetic energy and the plate work of the
    history row at t_n) and clears it."""
    return data.fc


@njit(**_FLAGS, **_NO_COUNTS)
def contact_step(x, q, v, w, f, mom, acc, t, dt, data):
    """The contact term's eval (the signature every term's has, ``terms.base``); see the module docstring.

    It does not add its forces to ``f``: it leaves them in ``data.fc`` (:func:`contact_forces_of`)
    and ``data.ff`` (the scene's friction array), which the step loop applies (a hook that wraps
    this one must add ``data.fc`` to ``f`` itself).
    """
    params, st = data.params, data.stats
    calls = st.calls[0]
    st.calls[0] = calls + 1
    _update_neighbours(x, v, dt, acc, data)
    # pairs are re-evaluated only when the nodes may have closed their gap since the last look
    # (contact_forces_ex, records.gap): the path bound refreshes per pair, the displacement bound does not
    reach = 2.0 * st.path_m[0]
    if st.overlaps_done[0] == 0 or st.offset_max_m[0] > 0.0:
        return _first_steps_pass(x, v, acc, t, dt, data, calls, reach)
    # no offsets: an empty array (a view, not an allocation), as _overlap_offsets returns then; the
    # list in use and the records read without a reference (borrowed_item): the lists hold them
    return _step_forces_pass(x, v, acc, dt, data, borrowed_item(data.lists, 0), borrowed_item(data.records, 0),
                             (st.path_m[:0], 0.0, 0.0), reach, calls)


def _first_steps(x, v, acc, t, dt, data, calls, reach):
    """The rest of :func:`contact_step` while the initial overlaps are recorded (first call) or
    released (offsets > 0): with reference counts, as it allocates the offsets."""
    st = data.stats
    if st.overlaps_done[0] == 0:
        st.overlaps_done[0] = 1
        _record_initial_overlaps(x, data, reach)
    off, rel, rel_prev = _overlap_offsets(data, t, dt)
    return _step_forces_pass(x, v, acc, dt, data, data.lists[0], data.records[0], (off, rel, rel_prev), reach, calls)


def _step_forces(x, v, acc, dt, data, plist, rec, release, reach, calls):
    """Steps 3–5 of :func:`contact_step` (module docstring): the normal pass, the friction, the energies
    and the statistics; ``plist``, ``rec``: the Verlet list in use and the records; ``release``: the
    initial overlaps' offsets and release factors ``(off, rel, rel_prev)`` (:func:`_overlap_offsets`);
    returns the number of pairs in contact."""
    params, st = data.params, data.stats
    off, rel, rel_prev = release
    # fc is all zeros here: the step loop's update cleared it after applying it (fused loops)
    energy, n_active = _normal_forces(x, data, plist, rec, off, reach)
    # work of the release on the contacts (the offset shrinks at fixed positions: stored energy
    # grows by Σ|f|·Δoff); a prescribed "motion", booked as external work (ALLWK)
    if off.shape[0] > 0 and rel_prev > rel:
        wrel = 0.0
        for kk in range(n_active):
            k = rec.active[kk]
            wrel += rec.fsum[k] * plist.offset[k, 0]
        acc[ACC_WK] += wrel * (rel_prev - rel)
    st.e_contact_J[0] = energy
    diss = 0.0
    if params.friction_on:
        diss = _friction_pass(v, dt, data, plist, rec, n_active, calls)
    # the stored energy at x_n: the normal penalties' and the fiber–fiber tangential springs'
    acc[ACC_STORED] += energy + st.e_spring_J[0]
    # the forces stay in fc: the step loop's update applies them, books their work and clears fc
    acc[ACC_PW] += diss
    acc[ACC_FD] += diss
    _statistics(data, rec, n_active)
    return n_active


# contact_step and its normal pass, friction and statistics (_step_forces) run without reference
# counts (``_nrt=False``; numba takes and releases a reference, an atomic count, to every array of a
# structure it binds or hands to an inlined function, and the term's functions take the whole
# ContactData, some fifty arrays). They allocate nothing and are called only from jitted code (no
# Python wrapper, which would need the counts to unbox the typed lists). The functions that allocate
# set ``_nrt=True`` (a function compiled from one without counts inherits that unless it sets its
# own): _rebuild, _first_steps (the offsets) and the potential pass.
_step_forces_pass = njit(**_FLAGS, **_NO_COUNTS)(_step_forces)
_first_steps_pass = njit(**_FLAGS, _nrt=True)(_first_steps)


class ContactSetup:
    """Everything ``prepare`` builds, kept for inspection after a run (``hook.setup_info``)."""

    def __init__(self, law, friction_on, mu, k_t, skin, n_gauss):
        self.law = law
        self.friction_on = friction_on
        self.mu = mu
        self.k_t = k_t
        self.skin = skin
        self.n_gauss = n_gauss
        self.data: ContactData | None = None

    # convenient views of the kernel state
    @property
    def n_pairs(self) -> int:
        return int(self.data.stats.n_pairs[0])

    @property
    def n_builds(self) -> int:
        return int(self.data.stats.n_builds[0])

    @property
    def n_grow(self) -> int:
        return int(self.data.stats.n_grow[0])

    @property
    def n_active(self) -> int:
        return int(self.data.stats.n_active[0])

    @property
    def normal_force_sum(self) -> float:
        return float(self.data.stats.fn_sum_n[0])

    @property
    def max_penetration_m(self) -> float:
        return float(self.data.stats.delta_max_m[0])

    def records(self):
        """(pairs, fn, normal, s, t, phi, delta) of the last step (copies, first n_pairs rows)."""
        n = self.n_pairs
        pairs, rec = self.data.lists[0].pairs, self.data.records[0]
        return (np.array(pairs[:n]), np.array(rec.fn[:n]), np.array(rec.normal[:n]), np.array(rec.s[:n]),
                np.array(rec.t[:n]), np.array(rec.phi[:n]), np.array(rec.delta[:n]))


def _segments(model) -> Segments:
    """The model's elements as contact segments, with the arc length of their ends along the fiber."""
    E = model.n_elements
    nodes = np.empty((E, 2), np.int64)
    nodes[:, 0] = model.el_n1
    nodes[:, 1] = model.el_n1 + 1
    fiber = np.ascontiguousarray(model.el_fiber, dtype=np.int64)
    L0 = np.asarray(model.el_L0, dtype=np.float64)
    arc = np.empty((E, 2))
    acc = 0.0
    for e in range(E):
        if e == 0 or fiber[e] != fiber[e - 1]:
            acc = 0.0
        arc[e, 0] = acc
        acc += L0[e]
        arc[e, 1] = acc
    return Segments(nodes, np.ascontiguousarray(model.el_radius, dtype=np.float64), fiber, arc)


_CUSTOM_KERNELS: dict = {}


_SPEC = dict(fastmath=True, error_model="numpy")


def _potential_pass(forces, tag: str):
    """:func:`_normal_forces` calling ``forces`` (a copy of ``contact_forces_pot``)."""
    return specialise(_normal_forces, f"_normal_forces_{tag}", {"contact_forces_pot": forces}, cache=False,
                      inline="always", **_SPEC)


def _step_with(normal_pass, tag: str, overlaps, friction_pass=_friction_pass, update_neighbours=_update_neighbours):
    """A copy of :func:`contact_step` with ``normal_pass`` as its normal pass, ``friction_pass`` as its
    friction, ``overlaps`` recording the initial overlaps and ``update_neighbours`` keeping the Verlet
    list (not cached)."""
    forces = specialise(_step_forces, f"_step_forces_{tag}",
                        {"_normal_forces": normal_pass, "_friction_pass": friction_pass}, cache=False,
                        **_NO_COUNTS, **_SPEC)
    first = specialise(_first_steps, f"_first_steps_{tag}",
                       {"_step_forces_pass": forces, "_record_initial_overlaps": overlaps}, cache=False, _nrt=True,
                       **_SPEC)
    return specialise(contact_step, f"contact_step_{tag}", {"_step_forces_pass": forces, "_first_steps_pass": first,
                                                           "_update_neighbours": update_neighbours},
                      cache=False, **_NO_COUNTS, **_SPEC)


# solver.threads > 1 with the built-in laws: the pairs in prange tasks
# (a parfor kernel, not cached: see _kernels_beam.beam_pass_fibers); the initial overlaps, recorded
# once, by the serial pass
# the fiber–fiber friction's pairs in prange tasks too (friction.friction_forces_tasks: the same forces)
_friction_pass_threads = specialise(_friction_pass, "_friction_pass_threads",
                                    {"friction_forces_ex": friction_forces_tasks}, cache=False, inline="always",
                                    **_SPEC)
# and the Verlet list's build (neighbours.build_pairs_threads: the same list)
_rebuild_threads = specialise(_rebuild, "_rebuild_threads", {"build_pairs": build_pairs_threads}, cache=False,
                              error_model="numpy", _nrt=True)
_update_neighbours_threads = specialise(_update_neighbours, "_update_neighbours_threads",
                                        {"_rebuild": _rebuild_threads}, cache=False, inline="always", **_SPEC)
contact_step_potential_threads = _step_with(_potential_pass(contact_forces_pot_threads, "potential_threads"),
                                            "potential_threads", _record_initial_overlaps,
                                            friction_pass=_friction_pass_threads,
                                            update_neighbours=_update_neighbours_threads)


def contact_kernel_for(law, threads: bool = False):
    """``(contact_step kernel, cache name)`` for ``law``: the built-in kernel (cached on disk) for a law
    without ``kernels``; else copies of the contact kernels specialised on the law's own jitted
    ``(line, point, weight_point)`` functions (compiled once per process and law class). ``threads``:
    the variant for ``solver.threads`` > 1, whose normal pass evaluates its pairs in parallel tasks
    (same result bit for bit; not cached)."""
    if law.kernels is None:
        return (contact_step_potential_threads, None) if threads else (contact_step, "contact")
    key = (type(law), threads)
    if key not in _CUSTOM_KERNELS:
        tag = f"{type(law).__name__}_potential"
        nf = _potential_pass(potential_kernels_for(law), tag)
        # the initial overlaps, recorded once, by the law's serial pass (also with threads)
        overlaps = specialise(_record_initial_overlaps, f"_record_initial_overlaps_{tag}", {"_normal_forces": nf},
                              cache=False, **_SPEC)
        friction, update = _friction_pass, _update_neighbours
        if threads:
            tag += "_threads"
            nf = _potential_pass(potential_kernels_for(law, threads=True), tag)
            friction, update = _friction_pass_threads, _update_neighbours_threads
        _CUSTOM_KERNELS[key] = _step_with(nf, tag, overlaps, friction_pass=friction, update_neighbours=update)
    return _CUSTOM_KERNELS[key], None


def _max_element_length(model) -> float:
    return float(np.max(model.el_L0)) if model.n_elements else 0.0


def check_penalty_stiffness(model, dt: float, law, k_t: float | None, onset_m: float = 0.0) -> None:
    """Refuse a contact law or tangential penalty too stiff for the time step ``dt`` [s]
    (:func:`penalty_step_bound`). Checked for laws whose stiffness is bounded a priori
    (``node_stiffness_n_per_m``; ×1.17, the onset map's largest slope, with an onset; a law that
    stiffens with the penetration is checked at its first slope here and during the run by
    :class:`ContactSlopeWatch`) and for ``k_t``. Several contacts on one node add up; that is not
    counted here.
    """
    def check(k, modes, what, fix):
        total, dt_ok, k_lim = penalty_step_bound(model, dt, k, modes)
        if total > 4.0:
            raise FiberpipeError(f"{what} is too stiff for the time step: {k:.3g} N/m per node needs dt ≤ "
                                 f"{dt_ok:.3g} s, the run uses {dt:.3g} s; {fix(k_lim)} or a smaller solver.dt_safety")

    if law is not None:
        k = law.node_stiffness_n_per_m(_max_element_length(model))
        if k is not None:
            k *= 1.17 if onset_m > 0 else 1.0
            check(k, ("shear", "bending"), f"contact law {law.name!r}",
                  lambda k_lim: f"make its stiffness {k / k_lim:.3g}× smaller (contact.stiffness or k_def)")
    if k_t is not None:
        check_friction_stiffness(model, dt, k_t)


class ContactSlopeWatch:
    """The run's look at a law's stiffness: between chunks, the largest node stiffness the contact
    reached since the last look against the step (:func:`penalty_step_bound`). The first stiffness
    the step cannot carry gives one warning. The stiffness is the law's slope at the largest
    penetration (``ContactStats.delta_peak_m``) for a law whose slope is known at every
    penetration (the study's Eq. 1), and ``law.tangent_over_secant`` × the largest F_n/δ of a pair
    in contact (``ContactStats.secant_peak_n_per_m``) for a law without (Hertz: the tangent of
    F ∝ δ^{3/2} is 3/2 of its secant); both peaks are reset at each look. The contact keeps the
    margin the run's step keeps below the beams' limit: it warns once (ωΔt)² passes
    4 ``dt_safety``² (the run's ``solver.dt_safety``; 1: the stability limit itself). A law whose
    slope is fixed (``linear``) was checked before the run.
    """

    def __init__(self, model, dt: float, law, stats, onset_m: float, dt_safety: float = 1.0):
        from ..timestep import stable_time_step

        self.model, self.dt, self.law, self.stats, self.onset_m = model, float(dt), law, stats, float(onset_m)
        self.dt_safety = min(float(dt_safety), 1.0)
        self.L_max = _max_element_length(model)
        self.rep = stable_time_step(model)  # the beam modes the bound couples with, once per run
        self.warning: str | None = None

    @staticmethod
    def watched(law) -> bool:
        return bool(getattr(law, "stiffens", False)) or getattr(law, "tangent_over_secant", None) is not None

    @staticmethod
    def for_hook(model, dt: float, hook, dt_safety: float = 1.0) -> "ContactSlopeWatch | None":
        info = getattr(hook, "setup_info", None)
        law = getattr(info, "law", None)
        data = getattr(info, "data", None)
        if law is None or data is None or not ContactSlopeWatch.watched(law):
            return None
        return ContactSlopeWatch(model, dt, law, data.stats, data.params.onset_m, dt_safety)

    def stiffness(self) -> tuple[float, float]:
        """``(k [N/m] per node, the penetration [m] it was reached at or 0)`` since the last look; resets the peaks."""
        peak = float(self.stats.delta_peak_m[0])
        secant = float(self.stats.secant_peak_n_per_m[0])
        self.stats.delta_peak_m[0] = 0.0
        self.stats.secant_peak_n_per_m[0] = 0.0
        if getattr(self.law, "stiffens", False):
            if peak <= 0.0:
                return 0.0, 0.0
            # the law acts on the mapped penetration of the onset (contact_potential.onset)
            g = float(onset(peak, self.onset_m)[0]) if self.onset_m > 0.0 else peak
            return self.law.node_stiffness_n_per_m(self.L_max, delta_m=g), peak
        return self.law.tangent_over_secant * secant, 0.0

    def __call__(self, t_s: float) -> str | None:
        """The warning, the first time the contact's stiffness outgrows the step (None otherwise)."""
        k, peak = self.stiffness()
        if self.warning is not None or k <= 0.0:
            return None
        total, dt_ok, _ = penalty_step_bound(self.model, self.dt, k, rep=self.rep)
        s = self.dt_safety
        if total <= 4.0 * s * s:
            return None
        where = f"reached a penetration of {peak:.3g} m, where its slope" if peak > 0.0 else "reached a tangent that"
        self.warning = (f"by t = {t_s:.4g} s the contact law {self.law.name!r} {where} ({k:.3g} N/m per node) "
                        f"needs dt ≤ {s * dt_ok:.3g} s ({s:g} of its stable step {dt_ok:.3g} s, the run's dt_safety); "
                        f"the run uses {self.dt:.3g} s: from there the step cannot carry the contact (energy is "
                        f"created or the run diverges); use a smaller solver.dt_safety or a law that stiffens less")
        return self.warning


def make_contact_hook(model, *, law, friction: bool = False, mu: float, overlap_release_s: float,
                      k_t: float | None = None, skin_m: float | None = None, n_gauss: int = 2, onset_m: float = 0.0):
    """A :class:`ContactHook` for ``model`` (Python API; ``build.build_simulation`` maps a config onto it).

    law : ContactLaw. friction : fiber–fiber Coulomb friction on (the fibers' friction on plates and
    walls is theirs: ``Plates(mu=...)``, ``Walls(mu=...)``). mu : coefficient. k_t : N/m, tangential
    penalty (default 0.02 m_min (2/Δt)², chosen against the time step). skin_m : Verlet skin
    (default 0.2 r_max). n_gauss : Gauss points per segment in the line part. overlap_release_s : s,
    the initial overlap of each segment pair (its penetration at the first step) is subtracted from
    its penetration and released linearly to 0 over this time (0: no offset, the overlap acts at
    once). onset_m : m, the penetration over which force and stiffness rise from zero (0: the laws as
    they are). The normal pass is :func:`fiberpipe.solver.contact_potential.contact_forces_pot`
    (every force minus the gradient of the stored potential).
    """
    segs = _segments(model)
    E = model.n_elements
    rmax = float(segs.radius.max()) if E else 0.0
    skin = float(skin_m) if skin_m is not None else DEFAULT_SKIN_FACTOR * rmax
    if not skin > 0:
        raise FiberpipeError(f"contact.skin must be > 0, got {skin}")
    if mu < 0:
        raise FiberpipeError(f"friction.mu must be >= 0, got {mu}")
    if not (overlap_release_s >= 0 and math.isfinite(overlap_release_s)):
        raise FiberpipeError(f"contact.overlap_release must be >= 0, got {overlap_release_s}")
    if not (onset_m >= 0 and math.isfinite(onset_m)):
        raise FiberpipeError(f"contact.onset must be >= 0, got {onset_m}")
    kernel, cache_name = contact_kernel_for(law)
    info = ContactSetup(law, friction, mu, k_t, skin, n_gauss)

    def prepare(model_, scene):
        dt = float(scene.dt)
        kt = float(k_t) if k_t is not None else scene.default_friction_stiffness()
        info.k_t = kt
        check_penalty_stiffness(model_, dt, law, kt if friction else None, float(onset_m))
        N = model_.n_nodes
        cap = max(DEFAULT_PAIRS_PER_SEGMENT * E, 64)
        gxi, gw = gauss_points(n_gauss)
        params = ContactParams(int(law.law_id), law.params(), bool(friction), skin, 2.0 * rmax, float(mu), kt,
                               float(overlap_release_s), gxi, gw, float(onset_m))
        stats = new_stats()
        if friction:  # the scene's friction array and returned-energy sum, shared with the planes' friction
            stats = stats._replace(friction_returned_J=scene.friction_returned())
        data = ContactData(params, stats, segs, np.array(model_.nodes_m, dtype=np.float64),
                           List([new_pair_list(cap), new_pair_list(cap)]), List([new_records(cap)]), np.zeros((N, 3)),
                           scene.friction_forces() if friction else np.zeros((0, 3)))
        info.data = data
        return data

    hook = ContactHook(kernel=kernel, prepare=prepare, forces_of=contact_forces_of, cache_name=cache_name,
                       kernel_threads=contact_kernel_for(law, threads=True)[0])
    hook.setup_info = info
    hook.make_watch = lambda model_, dt, dt_safety=1.0: ContactSlopeWatch.for_hook(model_, dt, hook, dt_safety)
    return hook


@register_term("contact", "friction")
class ContactEffect:
    """``scene.effects`` entries ``contact`` and ``friction``: one :class:`ContactHook` for both, the
    fiber–fiber contact with its friction if ``friction`` is listed too. ``friction`` without
    ``contact`` builds no contact term: the plates and walls then carry the friction alone
    (:class:`~fiberpipe.solver.terms.planes.Plates`, :class:`~fiberpipe.solver.terms.planes.Walls`)."""

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        """The term of ``scene.contact`` (law, skin, overlap_release, onset, gauss_points) and
        ``scene.friction`` (mu, stiffness = k_t in N/m), for the material of ``cfg.material``; None
        when ``scene.effects`` lists no ``contact``."""
        from ..laws import law_from_config

        effects = list(scene_cfg.effects)
        if "contact" not in effects:
            return None
        ccfg, fcfg = scene_cfg.contact, scene_cfg.friction
        return make_contact_hook(model, law=law_from_config(ccfg, cfg.material), friction="friction" in effects,
                                 mu=float(fcfg.mu), overlap_release_s=float(ccfg.overlap_release),
                                 k_t=None if fcfg.stiffness is None else float(fcfg.stiffness),
                                 skin_m=None if ccfg.skin is None else float(ccfg.skin),
                                 n_gauss=int(ccfg.gauss_points), onset_m=float(ccfg.onset))
