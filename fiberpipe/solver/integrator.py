"""Run API: settings, the chunked driver around the jitted step loop, results and diagnosis.

``simulate`` calls :meth:`Integrator.advance` once per chunk; each call runs many steps inside one
jitted kernel (``_kernels_integrate.step_loop_for(hook)``), so Python only runs between chunks: output,
progress callback, checkpoints, signals, divergence diagnosis.

Chunk boundaries are a fixed grid of absolute step numbers (multiples of ``chunk_steps`` and of
``checkpoint_every``, plus the output-frame steps), independent of where the run started: a run
resumed from a checkpoint (taken at a boundary) makes exactly the same kernel calls from there on
as an uninterrupted run, so its results are the same bit for bit (``fiberpipe.solver.checkpoint``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Sequence

import numpy as np

from ..errors import FiberpipeError, SimulationDiverged
from ._kernels_integrate import damping_factors, no_record, record_energy, step_loop_for
from ._kernels_beam import EB_SIZE, PARALLEL_CHUNKS, beam_forces, new_element_forces, node_beams
from .checkpoint import Checkpoint, SimulationInterrupted, restore_into
from .layout import (ACC_SIZE, ACC_STORED0, DRIVEN, FIX_ROT, FIX_X, FIX_Y, FIX_Z, H_CONTACTS, H_FD, H_KE, H_KE_LF,
                     H_PLATE_DISP, H_PLATE_FORCE, H_PW, H_SE, H_SEGMENT, H_STORED, H_TIME, H_VD, H_VD_LF, H_WALL, H_WF,
                     H_WK, STATUS_ENERGY, STATUS_LEFT_BOX, STATUS_NAN, STATUS_OK, STATUS_PENETRATION, STATUS_RUNAWAY,
                     STATUS_SPEED)
from .model import Model
from .state import State
from .step_data import DriveArrays, Fixity, ModelArrays, SceneKernel, StepControl, StepState, WorkArrays
from .terms.base import NO_OWNER, SceneArrays, Term, no_forces
from .terms.planes import CHECKPOINT_FIELDS as PLANE_CHECKPOINT_FIELDS
from .terms.planes import plane_check, plane_energy, set_up_planes
from .timestep import (ADAPTIVE_LOOK_STEPS, DEFAULT_DT_SAFETY, AdaptiveStep, TimeStepReport, modal_time_step,
                       stable_time_step, step_change_kick)

ENERGY_NAMES = ("kinetic", "strain", "damping", "external", "contact", "friction", "contact_stored",
                "kinetic_leapfrog", "damping_leapfrog", "total", "residual")


def contiguous(a, dtype=np.float64) -> np.ndarray:
    """A model array as the kernels take it: contiguous, of the given dtype (no copy if it is)."""
    return np.ascontiguousarray(a, dtype=dtype)


@dataclass
class SimulationSettings:
    """Solver settings (SI).

    Parameters
    ----------
    dt_safety : float — fraction of the stable step used (default 0.9).
    dt_s : float, optional, s — a user time step; refused above the stable limit unless ``force_dt``.
    force_dt : bool — run with ``dt_s`` above the limit anyway (stops at blow-up with a diagnosis).
    end_time_s : float, optional, s — default: the loading time of plates/drives.
    output_frames : int — frames of node positions, evenly spaced over [0, end_time] (≥ 2).
    history_every : int, optional — steps between history rows (default: about 2000 rows).
    max_chunk_steps : int — steps per jitted call at most (progress granularity).
    speed_limit_m_s : float, optional — a node faster than this is a blow-up (default 0.2 c).
    runaway_m : float, optional — a node farther than this from its rest position is a blow-up
        (default 10 × the bounding-box diagonal + 1 mm).
    checkpoint_every : int, optional — steps between checkpoints (``on_checkpoint`` of :func:`simulate`).
    chunk_steps : int, optional — steps per jitted call (default: about 5e6 element-steps, ≤
        ``max_chunk_steps``): the granularity of progress, Ctrl-C and the plate/box checks.
    penetration_limit : float — a node deeper than this fraction of its radius into a plate or wall
        is a runaway penetration (default 0.5); more than 2 radii (centre a radius beyond the
        plane) is a fiber leaving the box.
    threads : int — ``solver.threads``: > 1 runs the beam pass and the node update as ``prange``
        tasks of contiguous nodes on up to this many numba threads (equal to the serial run to
        rounding; default 1, serial), and the contact hook's ``kernel_threads`` if it has one (the
        built-in hook's: the potential pass's pairs in tasks, bit for bit the serial forces). The
        friction pass stays serial.
    stable_step : str — ``solver.stable_step``: ``"element"`` (default) the element-by-element bound
        of :func:`~fiberpipe.solver.timestep.stable_time_step`; ``"modes"`` the constrained assembled
        system's (:func:`~fiberpipe.solver.timestep.modal_time_step`); ``"adaptive"`` the element
        bound, each step split into sub-steps that follow the contact's stiffness
        (:class:`~fiberpipe.solver.timestep.AdaptiveStep`).
    """

    dt_safety: float = DEFAULT_DT_SAFETY
    dt_s: float | None = None
    force_dt: bool = False
    end_time_s: float | None = None
    output_frames: int = 11
    history_every: int | None = None
    max_chunk_steps: int = 200_000
    speed_limit_m_s: float | None = None
    runaway_m: float | None = None
    checkpoint_every: int | None = None
    chunk_steps: int | None = None
    penetration_limit: float = 0.5
    threads: int = 1
    stable_step: str = "element"

    def __post_init__(self):
        if self.stable_step not in ("element", "modes", "adaptive"):
            raise FiberpipeError(f"solver.stable_step must be element, modes or adaptive, got {self.stable_step!r}")
        if not 0.0 < self.dt_safety <= 1.0:
            raise FiberpipeError(f"solver.dt_safety must be in (0, 1], got {self.dt_safety}")
        if self.output_frames < 2:
            raise FiberpipeError(f"solver.output_frames must be ≥ 2, got {self.output_frames}")
        if self.end_time_s is not None and not self.end_time_s > 0:
            raise FiberpipeError(f"solver.end_time must be > 0, got {self.end_time_s}")
        if self.dt_s is not None and not self.dt_s > 0:
            raise FiberpipeError(f"solver.dt must be > 0, got {self.dt_s}")
        if self.checkpoint_every is not None and not int(self.checkpoint_every) >= 1:
            raise FiberpipeError(f"solver.checkpoint_every must be ≥ 1, got {self.checkpoint_every}")
        if self.chunk_steps is not None and not int(self.chunk_steps) >= 1:
            raise FiberpipeError(f"chunk_steps must be ≥ 1, got {self.chunk_steps}")
        if not 0 < self.penetration_limit < 2:
            raise FiberpipeError(f"penetration_limit must be in (0, 2) radii, got {self.penetration_limit}")


@dataclass
class SimulationResult:
    """Outputs of :func:`simulate` (SI units).

    frames_time : (K,) s.  frames_positions : (K, N, 3) m, mesh node order.
    frames_rotations : (K, N, 4) node quaternions (w, x, y, z).
    history : dict of arrays over T rows — ``time`` (T,) s, ``plate_displacement`` (T, 2) m,
        ``plate_force`` (T, 2) N (lower, upper; positive when pressed), ``wall_force`` (T, W) N,
        ``contacts`` (T,), ``energy/<kinetic|strain|damping|external|contact|friction|contact_stored|total|residual>``
        (J; ``contact_stored`` the stored contact energy at t (plane penalties, fiber–fiber penalties
        and tangential springs), ``total`` Abaqus' ETOTAL with the booked ALLPW; ``residual`` is
        (E − E₀)/max(|ALLWK|, ALLSE + ALLKE) so far with the state functions
        E = K_lf + ALLSE + contact_stored + ALLVD_lf + ALLFD − ALLWK, dimensionless; ``kinetic_leapfrog``
        K_lf = ½ v_{n−½}·M v_{n+½}, the kinetic term central differences conserve; ``damping_leapfrog``
        ALLVD_lf, the mass damping's dissipation in step with K_lf, which differs from ALLVD by less
        than one step's).
    dt_s, steps, elements, wall_time_s, effects (names), timestep (TimeStepReport),
    final_state (State), completed (False for the partial result of a diverged run),
    wall_names (labels of the wall columns), warnings (what the effects' looks between chunks found,
    e.g. a contact law whose slope outgrew the step: one line each), friction_returned_J (the energy
    the scene's friction gave back, the sum of its contacts' negative dissipations, J; None without
    friction).
    """

    frames_time: np.ndarray
    frames_positions: np.ndarray
    frames_rotations: np.ndarray
    history: dict
    dt_s: float
    steps: int
    elements: int
    wall_time_s: float
    effects: list
    timestep: TimeStepReport
    final_state: State
    completed: bool = True
    wall_names: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    friction_returned_J: float | None = None


def choose_time_step(model: Model, effects: Sequence[Term], settings: SimulationSettings) -> tuple[float, TimeStepReport]:
    """The time step (s) the run will use and the stability report; refuses a user dt above the limit."""
    beta = max([getattr(e, "beta_s", 0.0) for e in effects if e.name == "damping"] or [0.0])
    rep = stable_time_step(model, beta_s=beta)
    if getattr(settings, "stable_step", "element") == "modes":
        rep = _modal_report(model, effects, rep, beta)
    if settings.dt_s is None:
        return settings.dt_safety * rep.dt_stable_s, rep
    if settings.dt_s > rep.dt_stable_s and not settings.force_dt:
        raise FiberpipeError(
            f"solver dt {settings.dt_s:.4g} s is above the stable limit {rep.dt_stable_s:.4g} s "
            f"({rep.governing_mode} mode of element {rep.governing_element}); the explicit scheme "
            f"would blow up. Use dt ≤ {rep.dt_stable_s:.4g} s, leave dt unset to use dt_safety × limit, "
            f"or set solver.force_dt: true to run anyway")
    return float(settings.dt_s), rep


def _modal_report(model: Model, effects: Sequence[Term], rep: TimeStepReport, beta_s: float) -> TimeStepReport:
    """``rep`` with the stable step of the constrained assembled system (``solver.stable_step: modes``):
    the fixity and the plane penalty factor of ``effects`` (set up on a probe; the contact hook's
    setup is not needed for them)."""
    probe = SceneArrays(model, 1.0)
    for term in effects:
        if term.kernels() is None:  # the folded terms: fixity and planes (not the per-step terms)
            term.setup(model, probe)
    mt = modal_time_step(model, probe.fix_mask, beta_s=beta_s, penalty_factor=probe.penalty_factor)
    per_mode = dict(rep.per_mode_s, modes=mt.dt_stable_s)
    return TimeStepReport(mt.dt_stable_s, "assembled constrained", -1, per_mode, rep.rotary_inertia_scale, rep.beta_s)


def _initial_energies(model: Model, state: State) -> tuple[float, float]:
    f = np.zeros((model.n_nodes, 3))
    mom = np.zeros((model.n_nodes, 3))
    se, _ = beam_forces(state.x, state.q, model.el_n1, model.el_invL0, model.el_C, model.el_Dk,
                        model.gamma_rest, model.theta_rest, f, mom, True, 0.0, np.zeros((0, 6)))
    ke = 0.5 * float(np.sum(model.mass[:, None] * state.v**2) + np.sum(model.J * state.w**2))
    return ke, float(se)


def fixity_of(fix_mask: np.ndarray, n_nodes: int) -> Fixity:
    """The update's factors of the ``layout.FIX_*`` / ``DRIVEN`` bits (:class:`Fixity`; all free for an
    empty mask)."""
    m = fix_mask.astype(np.int64) if fix_mask.shape[0] == n_nodes else np.zeros(n_nodes, np.int64)
    driven = (m & DRIVEN) != 0

    def free(bits):
        return np.where(((m & bits) != 0) | driven, 0.0, 1.0)

    return Fixity(free(FIX_X), free(FIX_Y), free(FIX_Z), free(FIX_ROT), np.zeros((n_nodes, 3)),
                  np.flatnonzero(driven).astype(np.int64))


class ScenePlan(NamedTuple):
    """The scene's terms as the step loop takes them: the per-step terms' chain and their owner."""

    terms: list        # (term, data, first energy column or -1) of each per-step term, in turn
    chain: tuple       # ((data, column), rest) ... () (_kernels_integrate.terms_chain)
    owner: object      # the data of the term whose force arrays the update applies (NO_OWNER when none)
    owner_index: int   # that term's index in ``terms`` (-1: none)
    loop: object       # the step loop specialised on them


def _set_up_terms(model: Model, terms: Sequence[Term], scene: SceneArrays) -> list:
    """Each term's setup in turn (the folded ones fill ``scene``); returns ``(term, data, kernels)`` of
    the per-step terms."""
    per_step = []
    for term in terms:
        data = term.setup(model, scene)
        kernels = term.kernels()
        if kernels is not None:
            if kernels.eval is None:
                raise FiberpipeError(f"term {term.name!r} has no eval kernel")
            if term.energies and not hasattr(data, "energy"):
                raise FiberpipeError(f"term {term.name!r} declares energies {list(term.energies)} but its data has no "
                                     "'energy' array")
            per_step.append((term, data, kernels))
    return per_step


def _scene_plan(per_step: list, first_column: int, threads: int) -> ScenePlan:
    """The chain, the owner and the step loop of the per-step terms ``(term, data, kernels)``; the
    terms' energy columns from ``first_column`` on."""
    owners = [i for i, (_, _, k) in enumerate(per_step) if k.forces_of is not None]
    if len(owners) > 1:
        raise FiberpipeError(f"terms {[per_step[i][0].name for i in owners]} both hand their forces to the node "
                             "update (forces_of): one may, the others add theirs to f")
    rows, column = [], first_column
    for term, data, k in per_step:
        rows.append((term, data, column if term.energies else -1))
        column += len(term.energies)
    evals = [k.eval_threads if threads > 1 and k.eval_threads is not None else k.eval for _, _, k in per_step]
    records = [record_energy if term.energies else no_record for term, _, _ in per_step]
    owner = per_step[owners[0]][2] if owners else None
    loop = step_loop_for(evals, records, forces_of=getattr(owner, "forces_of", None) or no_forces, threads=threads,
                         cache_names=[k.cache_name for _, _, k in per_step])
    owner_index = owners[0] if owners else -1
    return ScenePlan(rows, _chain_of(rows), rows[owner_index][1] if owners else NO_OWNER, owner_index, loop)


def _chain_of(rows: list) -> tuple:
    """The nested ``((data, column), rest)`` tuple of the per-step terms' rows, ending in ``()``."""
    chain: tuple = ()
    for _, data, column in reversed(rows):
        chain = ((data, column), chain)
    return chain


class Integrator:
    """Holds the model, the terms' kernel data and the work buffers for repeated :meth:`advance`."""

    def __init__(self, model: Model, terms: Sequence[Term], dt: float, *, history_rows: int = 1,
                 history_every: int = 1, speed_limit_m_s: float | None = None,
                 runaway_m: float | None = None, e_ref_J: float = 1e-12, threads: int = 1):
        names = [e.name for e in terms]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise FiberpipeError(f"term listed twice: {sorted(dup)}")
        self.model = model
        self.effects = list(terms)
        self.dt = float(dt)
        scene = SceneArrays(model, self.dt)
        per_step = _set_up_terms(model, self.effects, scene)
        # the plane pass's arrays, and the planes' friction at the end of the chain (after the contact
        # term's: the friction forces add up in that order)
        self.planes, plane_terms = set_up_planes(model, scene)
        per_step += plane_terms
        self.scene = scene
        n = model.n_nodes
        self.f = np.zeros((n, 3))
        self.mom = np.zeros((n, 3))
        self.strain_prev = np.zeros((model.n_elements, 6)) if scene.beta > 0 else np.zeros((0, 6))
        self.drive_v = np.zeros_like(scene.drive_vec)
        self.history_every = int(history_every)
        # solver.threads > 1: the beam pass and the update run as prange tasks of contiguous nodes
        self.threads = max(1, int(threads))
        self.plan = _scene_plan(per_step, H_WALL + scene.n_walls, self.threads)
        self.energy_columns = {f"energy/{slot}": col + k for term, _, col in self.plan.terms
                               for k, slot in enumerate(term.energies)}
        self.hist = np.zeros((history_rows, H_WALL + scene.n_walls + len(self.energy_columns)))
        self.h_row = 0
        # solver.stable_step adaptive: each step of dt taken as substeps[0] sub-steps; the sub-step of each row
        self.substeps = np.ones(1, np.int64)
        self.dt_prev = np.zeros(1)  # the last sub-step taken (0: none yet)
        self.dt_rows = np.zeros(history_rows)
        self.step_change_J = np.zeros(1)  # the leapfrog kinetic term's shift at the step changes so far
        self.step_change_rows = np.zeros(history_rows)
        c = model.material.wave_speed_m_s
        self.v_limit = 0.2 * c if speed_limit_m_s is None else float(speed_limit_m_s)
        if runaway_m is None:
            span = np.ptp(model.nodes_m, axis=0)
            runaway_m = 10.0 * float(np.linalg.norm(span)) + 1e-3
        self.x_limit = float(runaway_m)
        # floor of the blow-up check's energy scale: the kinetic energy one step of the constant loads
        # gives from rest (at the first history row the loads' work f·(x_n − x_0) is still 0)
        one_step = (float(np.sum(np.sum(scene.f_ext**2, axis=1) * self.dt**2 / model.mass))
                    if scene.f_ext.size else 0.0)
        self.e_ref = max(float(e_ref_J), one_step)
        self.model_arrays = model_arrays(model)
        self.eb = np.zeros((model.n_elements, EB_SIZE))
        self.task_sums = np.zeros((PARALLEL_CHUNKS, 9))
        self.acc_before = np.zeros(ACC_SIZE)
        self.zeros = np.zeros((model.n_nodes, 3))
        self.ef = new_element_forces(n)
        self.fixity = fixity_of(scene.fix_mask, n)

    def term_data(self, name: str):
        """The kernel data of the per-step term ``name`` (KeyError if the scene runs none)."""
        for term, data, _ in self.plan.terms:
            if term.name == name:
                return data
        raise KeyError(name)

    def _kernel_args(self):
        """The scene and work structures of the step loop (views of this integrator's arrays)."""
        scene = self.scene
        drives = DriveArrays(scene.drive_vec, scene.drive_T, scene.drive_ta, scene.drive_mode, self.drive_v)
        scene_kernel = SceneKernel(float(scene.alpha), float(scene.beta), scene.f_ext, scene.fix_mask,
                                   scene.node_drive, drives, self.planes, self.fixity, scene.friction_f)
        work = WorkArrays(self.f, self.mom, self.ef, self.eb, self.strain_prev, self.hist, self.task_sums,
                          self.acc_before, self.zeros)
        return scene_kernel, work

    def advance(self, state: State, n_steps: int) -> tuple[int, int, int]:
        """Run ``n_steps`` steps in one jitted call; returns ``(status, steps_done, bad_node)``."""
        # the step loop keeps |q| = 1 by one Newton step per step (exact for |q|² = 1 + O(1e-16)) and
        # the beam pass assumes unit quaternions: a state handed in with other norms is normalised here
        if state.acc.shape != (ACC_SIZE,):  # the kernels index it without bounds checks
            raise FiberpipeError(f"State.acc must have {ACC_SIZE} entries (layout.ACC_SIZE), got {state.acc.shape}")
        qn2 = np.einsum("ij,ij->i", state.q, state.q)
        if qn2.size and not np.all(np.abs(qn2 - 1.0) < 1e-12):
            if not np.all(qn2 > 0.0) or not np.all(np.isfinite(qn2)):
                raise FiberpipeError("State.q holds a zero or non-finite quaternion")
            state.q /= np.sqrt(qn2)[:, None]
        if self.threads > 1:
            import numba
            numba.set_num_threads(_usable_threads(self.threads))
        sub = int(self.substeps[0])  # the loop counts sub-steps: a history row every history_every steps still
        dt_sub = self.dt / sub
        row_before = self.h_row
        if self.dt_prev[0] > 0.0 and self.dt_prev[0] != dt_sub and n_steps > 0:
            # the step changed (solver.stable_step adaptive): the first sub-step alone, then its kick set right
            v_before, w_before = state.v.copy(), state.w.copy()
            status, done, bad = self._substep_loop(state, 1, 0, sub)
            if status == STATUS_OK:
                self.step_change_J[0] += step_change_kick(state, v_before, w_before, float(self.dt_prev[0]), dt_sub,
                                                          damping_factors(float(self.scene.alpha), dt_sub),
                                                          self.fixity, self.model.mass, self.model.J)
                status, rest, bad = self._substep_loop(state, int(n_steps) * sub - 1, 1, sub)
                done += rest
        else:
            status, done, bad = self._substep_loop(state, int(n_steps) * sub, 0, sub)
        self.dt_prev[0] = dt_sub
        self.dt_rows[row_before:self.h_row] = dt_sub
        self.step_change_rows[row_before:self.h_row] = self.step_change_J[0]
        done //= sub
        state.step += int(done)
        state.t = state.step * self.dt
        if status == STATUS_OK and not (np.isfinite(state.x).all() and np.isfinite(state.v).all()):
            # The kernels are compiled with fastmath, which lets LLVM assume no NaN and drop the
            # in-loop NaN test: check the state once per chunk here (a few µs for 2000 nodes).
            bad_nodes = np.flatnonzero(~(np.isfinite(state.x).all(axis=1) & np.isfinite(state.v).all(axis=1)))
            return int(STATUS_NAN), int(done), int(bad_nodes[0])
        return int(status), int(done), int(bad)

    def _substep_loop(self, state: State, n_sub: int, offset: int, sub: int) -> tuple[int, int, int]:
        """``n_sub`` sub-steps of ``dt / sub`` in one call of the step loop, ``offset`` sub-steps into the
        current step; returns ``(status, sub-steps done, bad node)``."""
        scene_kernel, work = self._kernel_args()
        dt_sub = self.dt / sub
        control = StepControl(dt_sub, n_sub, float(state.t) + offset * dt_sub, int(state.step) * sub + offset,
                              int(self.h_row), self.history_every * sub, float(self.v_limit), self.x_limit,
                              float(self.e_ref))
        status, done, self.h_row, bad = self.plan.loop(
            self.model_arrays, scene_kernel, StepState(state.x, state.q, state.v, state.w, state.acc), work, control,
            self.plan.chain, self.plan.owner)
        return status, done, bad

    def _mutable_arrays(self) -> dict:
        """The integrator's arrays the step loop changes, by checkpoint name (the planes' by
        ``planes.CHECKPOINT_FIELDS``)."""
        arrays = {"strain_prev": self.strain_prev, "drive_v": self.drive_v, "substeps": self.substeps,
                  "dt_prev": self.dt_prev, "dt_rows": self.dt_rows, "step_change": self.step_change_J,
                  "step_change_rows": self.step_change_rows}
        arrays.update({name: getattr(self.planes, f) for f, name in PLANE_CHECKPOINT_FIELDS.items()})
        return arrays

    def snapshot_arrays(self) -> dict:
        """Copies of the integrator's mutable arrays (for a checkpoint)."""
        return {k: a.copy() for k, a in self._mutable_arrays().items()}

    def restore_arrays(self, arrays: dict) -> None:
        """Copy saved mutable arrays back in place (shapes must agree)."""
        for k, cur in self._mutable_arrays().items():
            if k in ("substeps", "dt_prev", "dt_rows", "step_change", "step_change_rows") and k not in arrays:
                continue  # a checkpoint of a version without sub-steps: one sub-step throughout
            new = np.asarray(arrays[k])
            if cur.shape != new.shape:
                raise FiberpipeError(f"checkpoint does not fit this scene: integrator array {k} has shape "
                                     f"{new.shape}, the scene needs {cur.shape}")
            cur[...] = new

    def snapshot_terms(self) -> dict:
        """Copies of the per-step terms' data, by term name (for a checkpoint)."""
        return {term.name: _copy_tree(data) for term, data, _ in self.plan.terms}

    def restore_terms(self, saved: dict) -> None:
        """The per-step terms' data from a checkpoint, copied in place (the step loop's chain keeps
        the arrays it holds)."""
        rows = []
        for term, data, col in self.plan.terms:
            if term.name in saved:
                data = restore_into(data, saved[term.name])
            rows.append((term, data, col))
        index = self.plan.owner_index
        self.plan = self.plan._replace(terms=rows, chain=_chain_of(rows), owner=rows[index][1] if index >= 0 else NO_OWNER)


def model_arrays(model: Model) -> ModelArrays:
    """The step loop's :class:`ModelArrays` of ``model`` (contiguous, typed; no copy where they are)."""
    node_offsets = np.ascontiguousarray(model.node_offsets, dtype=np.int64)
    # the update gathers each node's beam resultants from the elements of its fiber: the CSR
    # layout of build_model (fiber k owns nodes node_offsets[k] … and elements node − k …)
    n = model.n_nodes
    k = np.repeat(np.arange(model.n_fibers), np.diff(node_offsets) - 1)
    if node_offsets[-1] != n or k.size != model.n_elements or not np.array_equal(model.el_n1, np.arange(k.size) + k):
        raise FiberpipeError("the model's elements are not in the CSR order of build_model "
                             "(fiber k: nodes node_offsets[k]…, elements node − k)")
    return ModelArrays(
        contiguous(model.el_n1, np.int64), contiguous(model.el_invL0), contiguous(model.el_C),
        contiguous(model.el_Dk), contiguous(model.gamma_rest), contiguous(model.theta_rest), contiguous(model.mass),
        contiguous(model.inv_mass), contiguous(model.J), contiguous(model.inv_J), contiguous(model.radius_node),
        contiguous(model.nodes_m), node_offsets,
        node_beams(model.el_n1, model.el_invL0, model.el_C, model.el_Dk, model.gamma_rest, model.theta_rest, n))


def advance(model: Model, state: State, n_steps: int, effects: Sequence[Term] = (), *, dt: float | None = None) -> State:
    """Advance ``state`` in place by ``n_steps`` steps (one jitted call) and return it.

    A convenience for scripts and tests; :func:`simulate` is the full run with output and checks.
    Raises :class:`SimulationDiverged` on NaN/runaway.
    """
    if dt is None:
        dt, _ = choose_time_step(model, effects, SimulationSettings())
    integrator = Integrator(model, effects, dt, history_every=max(1, n_steps))
    status, done, bad = integrator.advance(state, n_steps)
    if status != STATUS_OK:
        raise SimulationDiverged(_diagnose(model, state, status, bad, dt, None), step=state.step, time_s=state.t)
    return state


_STATUS_TEXT = {
    STATUS_NAN: "NaN or inf in the state",
    STATUS_SPEED: "a node moved faster than the speed limit",
    STATUS_RUNAWAY: "a node ran away from its rest position",
    STATUS_ENERGY: "kinetic energy blew up (> 1000 × the energy put in)",
    STATUS_PENETRATION: "runaway penetration into a plate or wall",
    STATUS_LEFT_BOX: "a fiber left the box (through a plate or wall)",
}


def _diagnose(model: Model, state: State, status: int, bad: int, dt: float, rep: TimeStepReport | None,
              detail: str = "", last_row: np.ndarray | None = None) -> str:
    x = state.x
    finite = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(state.v), axis=1)
    if bad < 0 or bad >= model.n_nodes:
        if not np.all(finite):
            bad = int(np.argmin(finite))
        else:
            bad = int(np.argmax(np.einsum("ij,ij->i", state.v, state.v)))
    fiber = int(model.node_fiber[bad])
    els = np.nonzero((model.el_n1 == bad) | (model.el_n1 + 1 == bad))[0]
    el = int(els[0]) if els.size else -1
    speed = float(np.linalg.norm(state.v[bad])) if finite[bad] else float("nan")
    quantity = _STATUS_TEXT.get(status, f"status {status}")
    energy = ""
    if last_row is not None and last_row.size > H_FD:
        ke, se = last_row[H_KE], last_row[H_SE]
        wk, pw = last_row[H_WK], last_row[H_PW]
        if status == STATUS_NAN:
            bad_e = [n for n, v in (("kinetic", ke), ("strain", se)) if not np.isfinite(v)]
            energy = f"; {' and '.join(bad_e) or 'no'} energy non-finite"
        else:
            energy = (f"; energies: kinetic {ke:.3g} J, strain {se:.3g} J, external work {wk:.3g} J, "
                      f"contact work {pw:.3g} J")
    hint = []
    if rep is not None and dt > rep.dt_stable_s:
        hint.append(f"dt {dt:.4g} s is above the stable limit {rep.dt_stable_s:.4g} s: leave solver.dt unset "
                    f"or lower it")
    elif status == STATUS_PENETRATION:
        hint.append("the plane penalty cannot hold the load: lower loading.velocity or the loads, raise "
                    "plates/walls penalty_factor (≤ 0.25), lower solver.dt_safety, or add damping")
    elif status == STATUS_LEFT_BOX:
        hint.append("a fiber was pushed through a plate or wall: check the loads and drives (too large for "
                    "the plane penalty), the plate/wall positions, lower solver.dt_safety, or add damping")
    else:
        hint.append("lower solver.dt_safety (e.g. 0.5), add damping (scene.damping.alpha), soften the penalty "
                    "(plates/walls penalty_factor, contact stiffness), check the loads, drives and loading velocity "
                    "for a wrong unit, or the input for overlapping fibers")
    return (f"simulation diverged at t = {state.t:.6g} s (step {state.step}): {quantity}; node {bad} "
            f"(fiber {fiber}, element {el}), speed {speed:.3g} m/s" + (f", {detail}" if detail else "")
            + f"{energy}. Suggested fix: {'; '.join(hint)}")


def _residual_start(state: State, ke0: float, se0: float) -> float:
    """The state energy at t = 0 the residual counts from: kinetic, strain and the planes' penalties
    (``ke0 + se0``) plus the contact hook's stored energy at the first step (``ACC_STORED0``: fiber
    pairs whose initial overlap acts at once), once the step loop has recorded it."""
    stored0 = float(state.acc[ACC_STORED0])
    return ke0 + se0 + max(stored0, 0.0)


def state_energy(kinetic_lf, strain, stored, damping_lf, friction, external):
    """E = K_lf + ALLSE + Π + ALLVD_lf + ALLFD − ALLWK [J] from state functions (arrays or floats): the
    leapfrog kinetic term, the strain energy, the stored contact energy Π and the dissipations booked
    in step with K_lf, less the loads' work. Central differences keep it constant for a quadratic
    potential, so it grows only where a force creates energy (the history's ``energy/residual``,
    ``fiberpipe.post.energies.state_total``)."""
    return kinetic_lf + strain + stored + damping_lf + friction - external


def _history_dict(hist: np.ndarray, n_rows: int, n_walls: int, e0: float, energy_columns: dict) -> dict:
    h = hist[:n_rows]
    KE, SE, VD, WK, PW, FD, ST, KL, VL = (h[:, c] for c in (H_KE, H_SE, H_VD, H_WK, H_PW, H_FD, H_STORED, H_KE_LF,
                                                            H_VD_LF))
    # Abaqus' ETOTAL books the contact forces' work (ALLPW), so it closes whatever the contact does;
    # the residual uses the stored contact energy instead, a state function, so it shows energy
    # that no load supplied
    total = KE + SE + VD + FD - WK - PW
    # with the leapfrog's own kinetic term, which the scheme conserves exactly for a quadratic potential,
    # and the damping booked in step with it (_kernels_integrate.write_history)
    state_total = state_energy(KL, SE, ST, VL, FD, WK)
    # over the run's largest external work or mechanical energy (not the running one: early rows, with
    # almost nothing moved yet, would divide by almost nothing)
    scale = max(float(np.max(np.maximum(np.abs(WK), SE + KE))) if n_rows else 0.0, 1e-300)
    out = {
        "time": h[:, H_TIME].copy(),
        "plate_displacement": h[:, H_PLATE_DISP:H_PLATE_DISP + 2].copy(),
        "plate_force": h[:, H_PLATE_FORCE:H_PLATE_FORCE + 2].copy(),
        "wall_force": h[:, H_WALL:H_WALL + n_walls].copy(),
        "contacts": h[:, H_CONTACTS].copy(),
        "segment": h[:, H_SEGMENT].copy(),
        "energy/kinetic": KE.copy(), "energy/strain": SE.copy(), "energy/damping": VD.copy(),
        "energy/external": WK.copy(), "energy/contact": PW.copy(), "energy/friction": FD.copy(),
        # the friction forces' work on the fibers (part of ALLPW): ALLPW − ALLFD − this is the normal forces'
        "energy/friction_work": h[:, H_WF].copy(),
        "energy/contact_stored": ST.copy(), "energy/kinetic_leapfrog": KL.copy(), "energy/damping_leapfrog": VL.copy(),
        "energy/total": total, "energy/residual": (state_total - e0) / scale,
    }
    out.update({key: h[:, column].copy() for key, column in energy_columns.items()})  # the terms' own slots
    return out


def _copy_tree(obj):
    if isinstance(obj, tuple):
        items = [_copy_tree(o) for o in obj]
        return type(obj)(*items) if hasattr(obj, "_fields") else tuple(items)
    if type(obj).__name__ == "List" and type(obj).__module__.startswith("numba"):
        from numba.typed import List

        return List([_copy_tree(a) for a in obj])
    return obj.copy() if isinstance(obj, np.ndarray) else obj


#: a run longer than this many steps is refused as a probable unit mistake (≈ 1 day for 40 fibers)
MAX_STEPS = 1e11


def default_chunk_steps(model: Model, settings: SimulationSettings) -> int:
    """Steps per jitted call: about 5e6 element-steps (≈ 0.3 s on one core), at most ``max_chunk_steps``."""
    if settings.chunk_steps is not None:
        return int(settings.chunk_steps)
    if settings.stable_step == "adaptive":  # the sub-steps are chosen between chunks
        return ADAPTIVE_LOOK_STEPS
    return int(max(100, min(settings.max_chunk_steps, 5_000_000 // max(model.n_elements, 1))))


class RunPlan(NamedTuple):
    """What a run will do, decided before its first step."""

    dt_s: float
    timestep: TimeStepReport
    state: State
    end_time_s: float
    total_steps: int
    history_every: int
    history_rows: int
    chunk_steps: int
    checkpoint_every: int  # 0: none


def _plan_run(model: Model, effects: Sequence[Term], settings: SimulationSettings, state: State | None,
              resume: Checkpoint | None) -> RunPlan:
    """The run's time step, initial state, end time and step grid (checked against ``resume``)."""
    dt, rep = choose_time_step(model, effects, settings)
    if resume is not None:
        if resume.x.shape != (model.n_nodes, 3):
            raise FiberpipeError(f"checkpoint has {resume.x.shape[0]} nodes, the model {model.n_nodes}: it belongs "
                                 "to another mesh")
        if resume.dt_s != dt:
            raise FiberpipeError(f"checkpoint was run with dt = {resume.dt_s:.6g} s, this run would use {dt:.6g} s: "
                                 "it belongs to another config")
        state = State(resume.x.copy(), resume.q.copy(), resume.v.copy(), resume.w.copy(), float(resume.t),
                      int(resume.step), resume.acc.copy())
    else:
        state = State.at_rest(model) if state is None else state
    # end time
    probe = SceneArrays(model, dt)
    for term in effects:
        if term.name in ("plates", "drives"):
            term.setup(model, probe)
    end_time = settings.end_time_s if settings.end_time_s is not None else probe.end_time_hint
    if not end_time or end_time <= 0:
        raise FiberpipeError("no end time: set solver.end_time or a loading (moving plate) / drive")
    n = end_time / dt
    if not (math.isfinite(n) and n <= MAX_STEPS):
        raise FiberpipeError(f"the run would take {n:.3g} steps (end time {end_time:.4g} s / dt {dt:.4g} s), more "
                             f"than {MAX_STEPS:.0e}: check solver.end_time, solver.dt / dt_safety, damping.beta "
                             "(which lowers the stable step) and the loading velocity")
    total_steps = int(math.ceil(n - 1e-9))
    every = settings.history_every or max(1, total_steps // 2000)
    rows = total_steps // every + 1
    chunk = default_chunk_steps(model, settings)
    checkpoint_every = int(settings.checkpoint_every or 0)
    if resume is not None:
        got = (resume.total_steps, resume.history_every, resume.chunk_steps, resume.checkpoint_every)
        if got != (total_steps, every, chunk, checkpoint_every):
            raise FiberpipeError(f"checkpoint (total steps, history_every, chunk, checkpoint_every) = {got} does not "
                                 f"match this run's {(total_steps, every, chunk, checkpoint_every)}: it belongs to "
                                 "another config")
    return RunPlan(dt, rep, state, end_time, total_steps, every, rows, chunk, checkpoint_every)


def _usable_threads(threads: int) -> int:
    """The threads a run asking for ``threads`` gets: numba runs at most ``NUMBA_NUM_THREADS``, a
    limit it reads once, when it starts."""
    if threads <= 1:
        return max(1, threads)
    import numba
    return min(threads, numba.config.NUMBA_NUM_THREADS)


def threads_warning(threads: int) -> str | None:
    """The run's warning when numba allows fewer threads than ``solver.threads`` asks for (None when
    it allows them all)."""
    usable = _usable_threads(threads)
    if usable >= threads:
        return None
    return (f"solver.threads is {threads} but NUMBA_NUM_THREADS allows {usable}: the run uses {usable} (set "
            "NUMBA_NUM_THREADS before fiberpipe starts)")


class _Run:
    """One run of :func:`simulate`: the integrator, the frames so far, the energy reference and the
    checkpoints' constants."""

    def __init__(self, model: Model, effects: Sequence[Term], settings: SimulationSettings, plan: RunPlan,
                 resume: Checkpoint | None):
        self.model, self.effects, self.settings, self.plan, self.resume = model, list(effects), settings, plan, resume
        self.t_wall = time.perf_counter()
        state = plan.state
        if resume is not None:
            self.origin, self.ke0, self.se0 = resume.origin_step, resume.e0_ke, resume.e0_se
            self.wall_before = resume.wall_time_s
        else:
            self.origin = state.step
            self.ke0, self.se0 = _initial_energies(model, state)
            self.wall_before = 0.0
        self.integrator = Integrator(model, effects, plan.dt_s, history_rows=plan.history_rows,
                                     history_every=plan.history_every, speed_limit_m_s=settings.speed_limit_m_s,
                                     runaway_m=settings.runaway_m, e_ref_J=max(self.ke0 + self.se0, 1e-12),
                                     threads=settings.threads)
        if resume is None:
            self.se0 += plane_energy(self.integrator.scene, state.x)  # the stored energy at t = 0, the residual's start
            state.acc[ACC_STORED0] = -1.0  # the step loop records the terms' there (_residual_start)
        self.frame_times: list = []
        self.frame_positions: list = []
        self.frame_rotations: list = []
        if resume is not None:
            self._restore(resume)
        # the terms' own looks at the run between chunks (a stiffening contact law against the step)
        watches = (term.make_watch(model, plan.dt_s, settings.dt_safety) for term in effects
                   if hasattr(term, "make_watch"))
        self.watches = [w for w in watches if w is not None]
        self.adaptive = None
        if settings.stable_step == "adaptive":  # the sub-steps follow the watched stiffness instead of warning
            scene = self.integrator.scene
            self.adaptive = AdaptiveStep(model, plan.dt_s, settings.dt_safety, scene.penalty_factor,
                                         scene.penalty_dt(), self.watches[0] if self.watches else None)
            self.watches = []
        self.warnings: list[str] = []
        few_threads = threads_warning(settings.threads)
        if few_threads:
            self.warnings.append(few_threads)

    def _restore(self, resume: Checkpoint) -> None:
        """Put a checkpoint's integrator arrays, history, term data, term arrays and frames back."""
        integrator = self.integrator
        integrator.restore_arrays(resume.integrator_arrays)
        h = np.asarray(resume.hist)
        if h.shape[0] > self.plan.history_rows or h.shape[1] != integrator.hist.shape[1]:
            raise FiberpipeError(f"checkpoint history has shape {h.shape}, this run records {integrator.hist.shape}")
        integrator.hist[:h.shape[0]] = h
        integrator.h_row = int(h.shape[0])
        integrator.restore_terms(resume.term_data)
        for term in self.effects:
            if term.name in resume.effect_arrays and hasattr(term, "restore_arrays"):
                term.restore_arrays(resume.effect_arrays[term.name])
        self.frame_times = [float(t) for t in resume.frames_time]
        self.frame_positions = [np.array(a) for a in resume.frames_positions]
        self.frame_rotations = [np.array(a) for a in resume.frames_rotations]

    def take_frame(self, state: State, on_frame: Callable | None) -> None:
        self.frame_times.append(state.t)
        self.frame_positions.append(state.x.copy())
        self.frame_rotations.append(state.q.copy())
        if on_frame is not None:
            on_frame(len(self.frame_times) - 1, state.t, self.frame_positions[-1])

    def _frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k, n = len(self.frame_times), self.model.n_nodes
        return (np.array(self.frame_times), np.array(self.frame_positions).reshape(k, n, 3),
                np.array(self.frame_rotations).reshape(k, n, 4))

    def capture(self, state: State) -> Checkpoint:
        plan, integrator = self.plan, self.integrator
        times, positions, rotations = self._frames()
        return Checkpoint(
            x=state.x.copy(), q=state.q.copy(), v=state.v.copy(), w=state.w.copy(), acc=state.acc.copy(),
            t=state.t, step=state.step, origin_step=self.origin, total_steps=plan.total_steps, dt_s=plan.dt_s,
            history_every=plan.history_every, chunk_steps=plan.chunk_steps, checkpoint_every=plan.checkpoint_every,
            e0_ke=self.ke0, e0_se=self.se0, wall_time_s=self.wall_before + time.perf_counter() - self.t_wall,
            effects=[term.name for term in self.effects], integrator_arrays=integrator.snapshot_arrays(),
            hist=integrator.hist[:integrator.h_row].copy(), frames_time=times, frames_positions=positions,
            frames_rotations=rotations, term_data=integrator.snapshot_terms(),
            effect_arrays={term.name: dict(term.checkpoint_arrays()) for term in self.effects
                           if hasattr(term, "checkpoint_arrays")},
        )

    def result(self, state: State, completed: bool) -> SimulationResult:
        plan, integrator, model, rep = self.plan, self.integrator, self.model, self.plan.timestep
        times, positions, rotations = self._frames()
        notes = [rep.summary(), f"dt = {plan.dt_s:.4g} s ({plan.dt_s / rep.dt_stable_s:.3g} × stable)"]
        if self.adaptive is not None and integrator.substeps[0] > 1:
            notes.append(f"adaptive step: {int(integrator.substeps[0])} sub-steps of {plan.dt_s / integrator.substeps[0]:.4g} s "
                         "per step at the end (history dt_s)")
        if self.resume is not None:
            notes.append(f"resumed from a checkpoint at t = {self.resume.t:.6g} s (step {self.resume.step})")
        if model.rotary_inertia_scale != 1.0:
            notes.append(f"rotary inertia scaled by {model.rotary_inertia_scale:g}: rotational dynamics are slowed "
                         "(accuracy trade-off)")
        return SimulationResult(
            frames_time=times, frames_positions=positions, frames_rotations=rotations,
            history=dict(_history_dict(integrator.hist, integrator.h_row, integrator.scene.n_walls,
                                       _residual_start(state, self.ke0, self.se0), integrator.energy_columns),
                         dt_s=integrator.dt_rows[:integrator.h_row].copy(),
                         **{"energy/step_change": integrator.step_change_rows[:integrator.h_row].copy()}),
            dt_s=plan.dt_s, steps=state.step, elements=model.n_elements,
            wall_time_s=self.wall_before + time.perf_counter() - self.t_wall,
            effects=[term.name for term in self.effects], timestep=rep, final_state=state, completed=completed,
            wall_names=list(integrator.scene.wall_names), warnings=list(self.warnings), notes=notes,
            friction_returned_J=(float(integrator.scene.friction_returned()[0])
                                 if integrator.scene.friction_f.shape[0] else None))

    def diverged(self, state: State, last_good: State, status: int, bad: int, detail: str) -> SimulationDiverged:
        """The exception of a run that failed a check: its partial result ends at the last good state."""
        integrator = self.integrator
        row = integrator.hist[integrator.h_row - 1] if integrator.h_row > 0 else None
        msg = _diagnose(self.model, state, status, bad, self.plan.dt_s, self.plan.timestep, detail, row)
        at_step, at_time_s = state.step, state.t
        # keep the last good state as the partial result's final state (and last frame)
        state.x[:], state.q[:], state.v[:], state.w[:] = last_good.x, last_good.q, last_good.v, last_good.w
        state.t, state.step, state.acc[:] = last_good.t, last_good.step, last_good.acc
        if not self.frame_times or state.t > self.frame_times[-1]:
            self.take_frame(state, None)
        exc = SimulationDiverged(msg, step=at_step, time_s=at_time_s)
        exc.partial_result = self.result(state, False)
        exc.partial_result.notes.append(f"diverged; the last frame is the last good state (t = {state.t:.6g} s)")
        exc.diagnosis = msg
        exc.bad_node = bad
        exc.status = status
        return exc

    def advance_chunk(self, state: State, n_steps: int) -> None:
        """``n_steps`` steps in one call of the step loop, then the planes' check and the terms' looks;
        raises :class:`SimulationDiverged` when a check fails."""
        last_good = state.copy()
        integrator = self.integrator
        status, _, bad = integrator.advance(state, n_steps)
        detail = ""
        if status == STATUS_OK:
            status, bad, detail = plane_check(integrator.scene, integrator.planes, state.x,
                                              self.settings.penetration_limit)
        if status != STATUS_OK:
            raise self.diverged(state, last_good, status, bad, detail)
        self.warnings += [m for m in (w(state.t) for w in self.watches) if m]
        if self.adaptive is not None:
            self.adaptive.look(self.integrator.substeps, state.t)
            if self.adaptive.warning and self.adaptive.warning not in self.warnings:
                self.warnings.append(self.adaptive.warning)


def simulate(model: Model, effects: Sequence[Term], settings: SimulationSettings | None = None, *,
             state: State | None = None, progress: Callable | None = None,
             on_frame: Callable | None = None, resume: Checkpoint | None = None,
             on_checkpoint: Callable | None = None, should_stop: Callable | None = None) -> SimulationResult:
    """Run the explicit dynamics of ``model`` under ``effects`` (the scene's terms).

    Parameters
    ----------
    model : Model
    effects : sequence of Term — only these are computed.
    settings : SimulationSettings
    state : State, optional — initial state (default: at rest in the rest geometry).
    progress : callable ``progress(t_s, end_time_s, steps)``, optional — called between jitted chunks.
    on_frame : callable ``on_frame(k, t_s, positions (N,3))``, optional — called at each output frame.
    resume : Checkpoint, optional — continue the run saved in this checkpoint (same model, terms
        and settings); the result equals the uninterrupted run's bit for bit.
    on_checkpoint : callable ``on_checkpoint(Checkpoint)``, optional — called every
        ``settings.checkpoint_every`` steps and when ``should_stop`` asks to stop.
    should_stop : callable ``() -> signal number or None``, optional — polled between chunks; when it
        returns a truthy value the run saves a checkpoint and raises :class:`SimulationInterrupted`.

    Returns
    -------
    SimulationResult

    Raises
    ------
    FiberpipeError — a user dt above the stable limit (unless ``force_dt``), no end time, a
        checkpoint that does not fit.
    SimulationDiverged — NaN, speed or runaway displacement, kinetic energy blow-up, runaway
        penetration into a plate/wall or a fiber leaving the box; the exception's
        ``partial_result`` holds the frames (plus the last good state as a final frame) and history.
    SimulationInterrupted — ``should_stop`` asked to stop (a checkpoint was passed to ``on_checkpoint``).
    """
    settings = settings or SimulationSettings()
    plan = _plan_run(model, effects, settings, state, resume)
    run = _Run(model, effects, settings, plan, resume)
    state, total, every_checkpoint = plan.state, plan.total_steps, plan.checkpoint_every
    frame_steps = np.unique(np.round(np.linspace(0, total, settings.output_frames)).astype(np.int64))
    frame_set = {int(k) for k in frame_steps}
    if resume is None and 0 in frame_set:
        run.take_frame(state, on_frame)
    done = state.step - run.origin
    beyond = total + 1
    while done < total:
        next_frame = int(frame_steps[np.searchsorted(frame_steps, done, side="right")]) if done < frame_steps[-1] else beyond
        next_checkpoint = (done // every_checkpoint + 1) * every_checkpoint if every_checkpoint else beyond
        target = min(next_frame, (done // plan.chunk_steps + 1) * plan.chunk_steps, next_checkpoint, total)
        run.advance_chunk(state, target - done)
        done = state.step - run.origin
        if done in frame_set:
            run.take_frame(state, on_frame)
        if progress is not None:
            progress(state.t, plan.end_time_s, state.step)
        stop = should_stop() if should_stop is not None else None
        if done < total and (stop or (every_checkpoint and done % every_checkpoint == 0)):
            checkpoint = run.capture(state)
            if on_checkpoint is not None:
                on_checkpoint(checkpoint)
            if stop:
                raise SimulationInterrupted(f"interrupted at t = {state.t:.6g} s (step {state.step} of "
                                            f"{run.origin + total})",
                                            signum=int(stop) if not isinstance(stop, bool) else None,
                                            checkpoint=checkpoint)
    return run.result(state, True)
