"""The shape every physical term has, the registry of terms and the scene the terms are set up in.

A term is one class (in its own module of this package, or anywhere) with

- ``name``: its ``scene.effects`` entry and config block (``scene.<name>``);
- ``from_config(scene_cfg, model, cfg)``: the term from its validated config block (SI values);
- ``config_block``: for a term the built-in schema does not list, the pydantic section of its block
  (``fiberpipe.config.Section``), which the config validates ``scene.<name>`` with;
- ``setup(model, scene) -> data``: its kernel data, a NamedTuple of arrays (``None`` for a term the
  node update folds in: constant loads, damping and fixed degrees of freedom fill ``scene``);
- ``eval``: its jitted per-step pass, one signature for every term,
  ``eval(x, q, v, w, f, mom, acc, t, dt, data) -> int``, called at t_n after the beam and plane
  forces: ``x`` (N, 3) m, ``q`` (N, 4), ``v`` (N, 3) m/s and ``w`` (N, 3) rad/s at t_n − Δt/2; it adds
  its forces (N) to ``f`` and its moments (N·m) to ``mom``, books its work in ``acc``
  (``layout.ACC_*``) and returns the number of contacts it counts (history column ``contacts``);
- ``energies``: the energy slots it declares, history keys ``energy/<slot>`` [J], which the step loop
  copies from ``data.energy`` (one entry per slot) at every history row;
- its checkpointed arrays: its whole ``data`` (saved and restored in place by
  :mod:`fiberpipe.solver.checkpoint`).

The step loop is specialised on the tuple of the scene's per-step terms
(:func:`fiberpipe.solver._kernels_integrate.step_loop_for`): each ``eval`` is called directly, and a
term a scene does not list costs nothing. Adding a term is one module and one registry line,
``@register_term`` (docs/solver.md, "Adding a term").
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
from numba import njit

from ...errors import FiberpipeError
from .._kernels_boundary import DEFAULT_ONSET_FRACTION, RAMP_LINEAR, RAMP_SMOOTH, RAMP_SMOOTHSTEP
from ..model import Model
from ..timestep import penalty_time_step, stable_time_step

_AXES = {"x": 0, "y": 1, "z": 2}
_RAMPS = {"linear": RAMP_LINEAR, "smooth": RAMP_SMOOTH, "smoothstep": RAMP_SMOOTHSTEP}
DEFAULT_PENALTY_FACTOR = 0.1
DEFAULT_KT_FACTOR = 0.02           # the friction's tangential penalty k_t = 0.02 m_min (2/Δt)²


def _vec3(v, what) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise FiberpipeError(f"{what} must be 3 finite numbers, got {v!r}")
    return a


def _ramp_code(ramp: str, what: str) -> int:
    if ramp not in _RAMPS:
        raise FiberpipeError(f"{what}: ramp must be one of {sorted(_RAMPS)}, got {ramp!r}")
    return _RAMPS[ramp]


def _plain(v):
    """A value as the user wrote it (numpy scalars shown as plain numbers in messages)."""
    return v.item() if isinstance(v, np.generic) else v


def _check_fiber(model: Model, key: str, fiber) -> int:
    """``fiber`` as an index of the model, or an error naming the config key (``scene.clamps[0]``)."""
    fiber = _plain(fiber)
    n = int(model.n_fibers)
    try:
        i = int(fiber)
    except (TypeError, ValueError):
        i = -1
    if not 0 <= i < n or i != fiber:
        raise FiberpipeError(f"{key}.fiber = {fiber!r}: the model has {n} fiber{'s' if n != 1 else ''} "
                             f"(indices 0..{n - 1})")
    return i


def _node_of(model: Model, key: str, fiber, at) -> int:
    """Global node of ``at`` (start | end | local index, negative from the end) on ``fiber``; errors
    name the config key (``scene.clamps[0].at``) and the valid range."""
    i = _check_fiber(model, key, fiber)
    at = _plain(at)
    if at in ("start", "end"):
        return model.fiber_node_index(i, at)
    m = int(model.node_offsets[i + 1] - model.node_offsets[i])
    try:
        k = int(at)
    except (TypeError, ValueError):
        k = None
    if k is None or isinstance(at, bool) or k != at:
        raise FiberpipeError(f"{key}.at = {at!r}: give start, end or a node index (0..{m - 1}, or -{m}..-1 "
                             f"from the end)")
    if not -m <= k < m:
        raise FiberpipeError(f"{key}.at = {at}: fiber {i} has {m} nodes (indices 0..{m - 1}, or -{m}..-1 from "
                             "the end; the count follows mesh.element_length)")
    return model.fiber_node_index(i, k)


def _widen(a: np.ndarray, n: int, keep_last: bool) -> np.ndarray:
    """``a`` padded along its last axis to ``n`` entries: repeating its last one, or with zeros."""
    extra = n - a.shape[-1]
    if extra <= 0:
        return a
    tail = np.repeat(a[..., -1:], extra, axis=-1) if keep_last else np.zeros(a.shape[:-1] + (extra,))
    return np.concatenate([a, tail], axis=-1)


def _append_rows(tables, rows):
    """The travel tables ``(move, T, ta)``, each (P, S), with one plane's rows appended; the narrower
    side is padded with entries of zero duration that keep the last travel (path_travel skips them)."""
    rows = [np.atleast_1d(np.asarray(r, dtype=np.float64)) for r in rows]
    width = max(tables[0].shape[1], rows[0].size)
    return tuple(np.vstack([_widen(tab, width, k == 0), _widen(row, width, k == 0)[None, :]])
                 for k, (tab, row) in enumerate(zip(tables, rows)))



class PlaneSurface(NamedTuple):
    """What a plane does to the nodes that touch it (:meth:`SceneArrays.add_plane`)."""

    penalty_factor: float = DEFAULT_PENALTY_FACTOR    # normal penalty k_i = factor · m_i (2/Δt)²
    onset_fraction: float = DEFAULT_ONSET_FRACTION    # the penalty's onset length, × the node's radius
    mu: float = 0.0                                   # Coulomb coefficient of its friction (0: none)
    friction_stiffness_n_per_m: float | None = None   # its tangential penalty k_t (None: the default)


class SceneArrays:
    """The arrays the step loop's own passes read, which the folded terms fill in their ``setup`` (sizes 0
    when a term is absent); ``dt``, the planes and the friction force array are what a per-step
    term's ``setup`` may read."""

    def __init__(self, model: Model, dt: float):
        n = model.n_nodes
        self.model = model
        self.dt = dt
        self.f_ext = np.zeros((0, 3))
        self.alpha = 0.0
        self.beta = 0.0
        self.fix_mask = np.zeros(0, np.uint8)
        self.node_drive = np.zeros(0, np.int64)
        self.drive_vec = np.zeros((0, 3))
        self.drive_T = np.zeros(0)
        self.drive_ta = np.zeros(0)
        self.drive_mode = np.zeros(0, np.int64)
        self.pl_axis = np.zeros(0, np.int64)
        self.pl_sign = np.zeros(0)
        self.pl_pos0 = np.zeros(0)
        # the planes' travel tables (P, S): see step_data.PlaneArrays and _kernels_boundary.path_travel
        self.pl_move = np.zeros((0, 1))
        self.pl_T = np.ones((0, 1))
        self.pl_ta = np.zeros((0, 1))
        self.pl_mode = np.zeros(0, np.int64)
        self.pl_hist_col = np.zeros(0, np.int64)
        self.pl_mu = np.zeros(0)  # (P,) Coulomb coefficient of each plane's friction (0: none)
        self.pl_kt = np.zeros(0)  # (P,) N/m, its tangential penalty (NaN: the scene's default)
        self.pl_rect_half = np.zeros((0, 2))  # (P, 2) m, a finite plate's half extents (0: infinite)
        self.pl_rect_centre = np.zeros((0, 2))  # (P, 2) m, its centre (_kernels_boundary.in_plane_axes)
        self.penalty_factor = 0.0
        self.onset_fraction = 0.0
        self.n_walls = 0
        self.wall_names: list[str] = []
        self.plate_axis = None
        self.end_time_hint = 0.0
        self.plane_arrays = None  # the step loop's PlaneArrays (terms.planes.plane_arrays, once every plane is added)
        self.friction_f = np.zeros((0, 3))
        self._friction_returned = np.zeros(1)
        self._n = n

    # helpers used by the effects
    def ext(self) -> np.ndarray:
        if self.f_ext.shape[0] == 0:
            self.f_ext = np.zeros((self._n, 3))
        return self.f_ext

    def mask(self) -> np.ndarray:
        if self.fix_mask.shape[0] == 0:
            self.fix_mask = np.zeros(self._n, np.uint8)
            self.node_drive = np.full(self._n, -1, np.int64)
        return self.fix_mask

    def add_plane(self, axis, sign, pos, travel, hist_col, surface: "PlaneSurface" = None, rect=None):
        """Add a plane normal to ``axis`` at ``pos`` [m], pushing towards ``sign``·axis; ``travel =
        (move, T, ta, mode)``: its travel table (scalars for one entry, or equal-length sequences,
        :func:`_kernels_boundary.path_travel`) and ramp code; ``hist_col``: the history column of its
        reaction; ``surface``: its penalty and friction (:class:`PlaneSurface`); ``rect``: a finite
        plate's rectangle ``(half extents, centre)`` [m] along the plane's two axes in x, y, z order
        (None: infinite). The penalty factor and the onset fraction are the scene's (the largest of
        its planes')."""
        surface = PlaneSurface() if surface is None else surface
        half, centre = ((0.0, 0.0), (0.0, 0.0)) if rect is None else rect
        self.pl_rect_half = np.vstack([self.pl_rect_half, np.asarray(half, dtype=np.float64).reshape(1, 2)])
        self.pl_rect_centre = np.vstack([self.pl_rect_centre, np.asarray(centre, dtype=np.float64).reshape(1, 2)])
        move, T, ta, mode = travel
        self.pl_axis = np.append(self.pl_axis, axis).astype(np.int64)
        self.pl_sign = np.append(self.pl_sign, sign)
        self.pl_pos0 = np.append(self.pl_pos0, pos)
        self.pl_move, self.pl_T, self.pl_ta = _append_rows((self.pl_move, self.pl_T, self.pl_ta), (move, T, ta))
        self.pl_mode = np.append(self.pl_mode, mode).astype(np.int64)
        self.pl_hist_col = np.append(self.pl_hist_col, hist_col).astype(np.int64)
        kt = surface.friction_stiffness_n_per_m
        self.pl_mu = np.append(self.pl_mu, float(surface.mu))
        self.pl_kt = np.append(self.pl_kt, np.nan if kt is None else float(kt))
        self.penalty_factor = max(self.penalty_factor, surface.penalty_factor)
        self.onset_fraction = max(self.onset_fraction, surface.onset_fraction)

    def friction_forces(self) -> np.ndarray:
        """The scene's friction force array (N, 3) [N]: every term with Coulomb friction adds its
        friction forces there in its ``eval`` (the contact term's fiber pairs, the planes'); the node
        update adds them to the nodes, books their work (ALLPW, ``energy/friction_work``, ALLFD; see
        ``_kernels_integrate._book_friction_work``) and clears the array. Made by the first term that
        asks; a scene without friction has a (0, 3) array, and its update books none."""
        if self.friction_f.shape[0] == 0:
            self.friction_f = np.zeros((self._n, 3))
        return self.friction_f

    def friction_returned(self) -> np.ndarray:
        """(1,) J: the energy the scene's friction gave back so far (the sum of its contacts' negative
        dissipations, :mod:`fiberpipe.solver.friction`), which every friction term adds to."""
        return self._friction_returned

    def default_friction_stiffness(self) -> float:
        """The tangential penalty ``k_t`` [N/m] of a friction without ``scene.friction.stiffness``:
        ``DEFAULT_KT_FACTOR m_min (2/Δt_pen)²`` (Δt_pen = :meth:`penalty_dt`)."""
        return DEFAULT_KT_FACTOR * float(np.min(self.model.mass)) * (2.0 / self.penalty_dt()) ** 2

    def penalty_dt(self) -> float:
        """The step [s] the step-scaled penalties are chosen against
        (:func:`fiberpipe.solver.timestep.penalty_time_step`; the element bound without damping, so
        it does not depend on the order the effects are set up in)."""
        return penalty_time_step(self.model, self.dt)

    def k_pen(self) -> np.ndarray:
        """Per-node plane penalty stiffness ``c_pen m_i (2/Δt_pen)²`` (N/m), Δt_pen = :meth:`penalty_dt`."""
        if self.pl_axis.size == 0:
            return np.zeros(0)
        return self.penalty_factor * self.model.mass * (2.0 / self.penalty_dt()) ** 2

    def pen_onset(self) -> np.ndarray:
        """Per-node onset length of the plane penalty, ``onset_fraction · r_i`` (m)
        (:func:`fiberpipe.solver._kernels_boundary.plane_onset`)."""
        if self.pl_axis.size == 0:
            return np.zeros(0)
        return self.onset_fraction * np.asarray(self.model.radius_node, dtype=np.float64)


def penalty_step_bound(model, dt: float, k: float, modes=("shear", "bending"), *,
                       rep=None) -> tuple[float, float, float]:
    """``((ωΔt)², dt_ok [s], k_lim [N/m])`` of a penalty ``k`` [N/m] on the lightest node at step ``dt``.

    A penalty k on a node of mass m adds (ωΔt)² = 2kΔt²/m to the node's relative mode (two bodies
    of that mass); central differences stay stable while the beam's element modes it couples with
    (:func:`fiberpipe.solver.timestep.stable_time_step`: shear and bending for the normal contact,
    and axial too for the tangential spring, which acts along the fiber) plus this stay below
    (ωΔt)² = 4, i.e. while Δt ≤ dt_ok = 2/√(ω_beam² + 2k/m); ``k_lim`` is the penalty at that
    bound. A mode whose element bound the step already exceeds is locked in the scene (the modal
    step checked it) and does not couple. ``rep``: the model's
    :func:`~fiberpipe.solver.timestep.stable_time_step` report, when the caller holds it.
    """
    rep = stable_time_step(model) if rep is None else rep
    m_min = float(np.min(model.mass))
    used = [(2.0 * dt / rep.per_mode_s[mo]) ** 2 for mo in modes]
    beam = max([u for u in used if u < 4.0] or [0.0])
    total = beam + 2.0 * k * dt * dt / m_min
    return total, 2.0 * dt / math.sqrt(total) if total > 0 else math.inf, (4.0 - beam) * m_min / (2.0 * dt * dt)


def check_friction_stiffness(model, dt: float, k_t: float) -> None:
    """Refuse a friction's tangential penalty ``k_t`` [N/m] too stiff for the time step ``dt`` [s]
    (:func:`penalty_step_bound`: it acts along the fiber too, so with the axial modes)."""
    total, dt_ok, k_lim = penalty_step_bound(model, dt, k_t, ("axial", "shear", "bending"))
    if total > 4.0:
        raise FiberpipeError(f"friction.stiffness {k_t:.3g} N/m is too stiff for the time step: {k_t:.3g} N/m per "
                             f"node needs dt ≤ {dt_ok:.3g} s, the run uses {dt:.3g} s; use friction.stiffness ≤ "
                             f"{k_lim:.3g} N/m or a smaller solver.dt_safety")


@njit(cache=True, error_model="numpy")
def no_eval(x, q, v, w, f, mom, acc, t, dt, data):
    """The per-step pass of no term: does nothing, counts 0 contacts."""
    return 0


#: the step loop's owner data when no term hands its forces to the update (:func:`no_forces`)
NO_OWNER = np.zeros((0, 3))


@njit(cache=True, inline="always")
def no_forces(data):
    """The owner's force array when no term hands its forces to the update: the owner data is then
    :data:`NO_OWNER`, an empty (0, 3) array, returned as it is (the step loop allocates nothing)."""
    return data


#: the terms a scene may list (``scene.effects``), by config name: one class each, added by
#: :func:`register_term`; ``build.build_simulation`` calls ``TERMS[name].from_config``
TERMS: dict = {}


def register_term(*names):
    """Class decorator: ``scene.effects`` entries ``names`` (default: the class's ``name``) build
    this term with its ``from_config(scene_cfg, model, cfg)``; entries sharing one class (contact
    and friction) give one term. A term the config schema does not list brings its block's section
    as ``config_block``."""
    def deco(cls):
        for n in names or (cls.name,):
            TERMS[n] = cls
        return cls
    return deco


class TermKernels(NamedTuple):
    """A per-step term's jitted functions, as the step loop is specialised on them."""

    eval: Callable                  # eval(x, q, v, w, f, mom, acc, t, dt, data) -> int
    eval_threads: Callable | None   # the same with prange tasks inside, for solver.threads > 1 (None: eval)
    forces_of: Callable | None      # forces_of(data) -> (N, 3): forces the update applies (None: eval adds to f)
    cache_name: str | None          # a built-in term's name in the on-disk cache (None: compiled per process)


def _static(obj, name):
    """Attribute ``name`` of ``obj`` without binding (a jitted function stored on a class is a
    descriptor); a ``staticmethod`` unwrapped."""
    value = inspect.getattr_static(obj, name, None)
    return value.__func__ if isinstance(value, staticmethod) else value


class Term:
    """Base class of every physical term (module docstring): parameters as dataclass fields (SI,
    names with units) checked in ``__post_init__``, ``from_config``, ``setup`` and, for a per-step
    term, the class attributes ``eval`` (and optionally ``eval_threads``, ``forces_of``,
    ``cache_name``) and ``energies``. A term with Coulomb friction adds its friction forces to the
    scene's friction array (:meth:`SceneArrays.friction_forces`, held in its data)."""

    name = "term"
    config_block = None
    energies: tuple = ()
    eval = None
    eval_threads = None
    forces_of = None
    cache_name = None

    @classmethod
    def from_config(cls, scene_cfg, model, cfg) -> "Term":  # pragma: no cover - interface
        raise NotImplementedError

    def setup(self, model: Model, scene: SceneArrays):
        """The term's kernel data (a NamedTuple), or None for a term the node update folds in (it
        fills ``scene`` instead)."""
        return None

    def kernels(self) -> TermKernels | None:
        """The per-step pass's jitted functions (None: the term has none)."""
        kernel = _static(self, "eval")
        if kernel is None:
            return None
        return TermKernels(kernel, _static(self, "eval_threads"), _static(self, "forces_of"),
                           _static(self, "cache_name"))

    def describe(self) -> str:
        return repr(self)


@dataclass
class ContactHook(Term):
    """A per-step term given by its kernel and data (the contact term is one; see docs/solver.md).

    Parameters
    ----------
    kernel : a numba ``@njit`` function
        ``kernel(x, q, v, w, f, mom, acc, t, dt, data) -> int`` called once per step at t_n after
        the beam and plane forces: ``x`` (N,3) m, ``q`` (N,4), ``v`` (N,3) m/s and ``w`` (N,3)
        rad/s (body frame) at t_n − Δt/2. It writes its forces (N) and moments (N·m, spatial) into
        the arrays it declares (below), adds its penalty work on the fibers (J) to
        ``acc[layout.ACC_PW]`` and its friction dissipation (J) to ``acc[layout.ACC_FD]``, and returns
        the number of active contacts. ``data`` is any numba-compatible tuple (NamedTuples of
        arrays, typed lists of them: neighbour lists, friction history...).
    data : tuple — passed through unchanged.
    prepare : optional callable ``prepare(model, scene) -> data`` run at setup (e.g. to build the
        neighbour list against ``model`` and size buffers with ``scene.dt``).
    forces_of : the force arrays the kernel writes. ``None`` (default): it ADDS its forces into ``f``
        and its moments into ``mom``. Otherwise a jitted ``forces_of(data) -> (N, 3) array``: the
        kernel leaves its forces there and the step loop's update adds them to the nodes, books their
        work ``Δt f_n·v̄_n`` to ALLPW and clears the array (one pass over the nodes instead of three).
    Friction forces go to the scene's friction array (:meth:`SceneArrays.friction_forces`, which
        ``prepare`` puts in the data): the update adds them to the nodes, books their work ``Δt f_n·v̄_n``
        to ALLPW, the same work as ``½Δt (f_{n−1} + f_n)·v_{n−½}`` (in phase with the friction springs)
        to the friction work (``energy/friction_work``) and minus it to ALLFD, and clears the array.
        The kernel books what its friction springs store: ALLFD and ALLPW −= their energy change.
    cache_name : a built-in hook's name for the on-disk compilation cache (None: the step loop
        specialised for this kernel is compiled once per process).
    kernel_threads : optional variant of ``kernel`` for ``solver.threads`` > 1 (parallel ``prange``
        tasks inside; same signature and results). None: ``kernel`` runs with any number of threads.

    A scene runs any number of these, in the order listed; at most one of them may hand its forces
    to the update (``forces_of``).
    """

    kernel: Callable = no_eval
    data: tuple = (np.zeros(0),)
    prepare: Callable | None = None
    forces_of: Callable | None = None
    cache_name: str | None = None
    kernel_threads: Callable | None = None
    name = "contact"

    def setup(self, model, scene):
        return self.prepare(model, scene) if self.prepare is not None else self.data

    def kernels(self) -> TermKernels:
        return TermKernels(self.kernel, self.kernel_threads, self.forces_of, self.cache_name)
