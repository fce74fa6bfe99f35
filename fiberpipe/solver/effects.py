"""Effects a scene may list: one small class each, holding its parameters and their checks.

An effect only fills the arrays the step kernel reads (``SceneArrays``); an effect that a scene does
not list leaves its arrays empty (size 0), so its kernel is never called and costs nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..errors import FiberpipeError
from ._kernels_boundary import DEFAULT_ONSET_FRACTION, RAMP_LINEAR, RAMP_SMOOTH, RAMP_SMOOTHSTEP
from ._kernels_integrate import no_contact, no_contact_forces
from .layout import DRIVEN, FIX_ROT, FIX_X, FIX_Y, FIX_Z, H_PLATE_FORCE, H_WALL
from .model import Model
from .timestep import penalty_time_step

_AXES = {"x": 0, "y": 1, "z": 2}
_RAMPS = {"linear": RAMP_LINEAR, "smooth": RAMP_SMOOTH, "smoothstep": RAMP_SMOOTHSTEP}
DEFAULT_PENALTY_FACTOR = 0.1


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


class SceneArrays:
    """The arrays the step kernel reads for the effects (sizes 0 when an effect is absent)."""

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
        self.penalty_factor = 0.0
        self.onset_fraction = 0.0
        self.n_walls = 0
        self.wall_names: list[str] = []
        self.plate_axis = None
        self.contact_on = False
        self.contact_fn = no_contact
        self.contact_forces_of = no_contact_forces
        self.contact_friction_of = no_contact_forces
        self.contact_cache_name = None
        self.contact_fn_threads = None  # the hook's variant for solver.threads > 1 (None: contact_fn)
        self.contact_hook_name = ""
        self.contact_data = (np.zeros(0),)
        self.end_time_hint = 0.0
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

    def add_plane(self, axis, sign, pos, move, T, ta, mode, hist_col, penalty_factor,
                  onset_fraction=DEFAULT_ONSET_FRACTION):
        """Add a plane; ``move``, ``T``, ``ta``: its travel table (scalars for one entry, or
        equal-length sequences, :func:`_kernels_boundary.path_travel`). The penalty factor and the
        onset fraction are the scene's (the largest of its planes')."""
        self.pl_axis = np.append(self.pl_axis, axis).astype(np.int64)
        self.pl_sign = np.append(self.pl_sign, sign)
        self.pl_pos0 = np.append(self.pl_pos0, pos)
        self.pl_move, self.pl_T, self.pl_ta = _append_rows((self.pl_move, self.pl_T, self.pl_ta), (move, T, ta))
        self.pl_mode = np.append(self.pl_mode, mode).astype(np.int64)
        self.pl_hist_col = np.append(self.pl_hist_col, hist_col).astype(np.int64)
        self.penalty_factor = max(self.penalty_factor, penalty_factor)
        self.onset_fraction = max(self.onset_fraction, onset_fraction)

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


#: the effects a scene may list (``scene.effects``), by config name: one class each, added by
#: :func:`register_effect`; ``build.build_simulation`` calls ``EFFECTS[name].from_config``
EFFECTS: dict = {}


def register_effect(*names):
    """Class decorator: ``scene.effects`` entries ``names`` (default: the class's ``name``) build
    this effect with its ``from_config(scene_cfg, model, cfg)``; entries sharing one class (contact
    and friction) give one effect."""
    def deco(cls):
        for n in names or (cls.name,):
            EFFECTS[n] = cls
        return cls
    return deco


class Effect:
    """Base class: ``name``, ``setup(model, scene)`` filling the kernel arrays, and
    ``from_config(scene_cfg, model, cfg)`` building it from the config (SI values)."""

    name = "effect"

    @classmethod
    def from_config(cls, scene_cfg, model, cfg) -> "Effect":  # pragma: no cover - interface
        raise NotImplementedError

    def setup(self, model: Model, scene: SceneArrays) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def describe(self) -> str:
        return repr(self)


@register_effect()
@dataclass
class Gravity(Effect):
    """Uniform gravity on the physical lumped mass: f_i = m_i g.

    Parameters
    ----------
    acceleration_m_s2 : (3,) m/s², e.g. (0, 0, −9.81).
    """

    acceleration_m_s2: Sequence[float] = (0.0, 0.0, -9.81)
    name = "gravity"

    def __post_init__(self):
        self.acceleration_m_s2 = _vec3(self.acceleration_m_s2, "gravity.acceleration")

    @classmethod
    def from_config(cls, sc, model, cfg):
        return cls(list(sc.gravity.acceleration))

    def setup(self, model, scene):
        scene.ext()[:] += (model.mass / model.mass_scale)[:, None] * self.acceleration_m_s2[None, :]


@register_effect()
@dataclass
class Damping(Effect):
    """Rayleigh material damping as Abaqus/Explicit applies it.

    Mass-proportional: force ``−α m v`` and moment ``−α J Ω`` (``alpha_per_s``, 1/s; the study
    uses 1e5). Stiffness-proportional: an extra stress ``β C Γ̇`` and moment ``β D κ̇``
    (``beta_s``, s; lowers the stable step by (√(1+ξ²) − ξ), ξ = βω_max/2). The dissipated
    energy is ALLVD.

    The mass-proportional force acts on the absolute velocity of every node, prescribed ones
    included (Abaqus: as if the model moved through a viscous fluid): a fiber translated rigidly
    at speed v by a :class:`Drive` dissipates ``α m v²`` per unit time (ALLVD), which the drive's
    reaction supplies (ALLWK).
    """

    alpha_per_s: float = 0.0
    beta_s: float = 0.0
    name = "damping"

    def __post_init__(self):
        for k in ("alpha_per_s", "beta_s"):
            val = float(getattr(self, k))
            if not (val >= 0.0 and math.isfinite(val)):
                raise FiberpipeError(f"damping.{k.split('_')[0]} must be ≥ 0, got {val}")
            setattr(self, k, val)

    @classmethod
    def from_config(cls, sc, model, cfg):
        return cls(float(sc.damping.alpha), float(sc.damping.beta))

    def setup(self, model, scene):
        scene.alpha = self.alpha_per_s
        scene.beta = self.beta_s


@dataclass
class Clamp:
    """One clamped node: ``fiber`` index, ``at`` = "start" | "end" | local node index;
    ``dofs`` = "all" (6 DOF fixed) or a subset of "xyz" (translations only, rotations free: a pin
    along those axes)."""

    fiber: int
    at: object = "start"
    dofs: str = "all"


@register_effect()
@dataclass
class Clamps(Effect):
    """Nodes with all (or chosen translational) DOF fixed at their initial values."""

    clamps: Sequence[Clamp] = field(default_factory=list)
    name = "clamps"

    def __post_init__(self):
        out = []
        for c in self.clamps:
            if isinstance(c, dict):
                c = Clamp(**c)
            if c.dofs != "all" and (not c.dofs or set(c.dofs) - set("xyz")):
                raise FiberpipeError(f"clamp dofs must be 'all' or letters of 'xyz', got {c.dofs!r}")
            out.append(c)
        self.clamps = out

    @classmethod
    def from_config(cls, sc, model, cfg):
        return cls([Clamp(c.fiber, c.at) for c in sc.clamps])

    def setup(self, model, scene):
        m = scene.mask()
        for k, c in enumerate(self.clamps):
            i = _node_of(model, f"scene.clamps[{k}]", c.fiber, c.at)
            if c.dofs == "all":
                m[i] |= FIX_X | FIX_Y | FIX_Z | FIX_ROT
            else:
                for ch in c.dofs:
                    m[i] |= {"x": FIX_X, "y": FIX_Y, "z": FIX_Z}[ch]


@register_effect('constraints')
@dataclass
class AxialLock(Effect):
    """The study's boundary condition, "the movement is locked in the fiber orientation": the
    translation along ``axis`` of every node (``nodes="all"``) or of each fiber's first and last
    node (``"ends"``) is fixed at its initial value; rotations and the other translations are free."""

    axis: str = "z"
    nodes: str = "all"
    name = "constraints"

    def __post_init__(self):
        if self.axis not in _AXES:
            raise FiberpipeError(f"constraints axis must be x, y or z, got {self.axis!r}")
        if self.nodes not in ("all", "ends"):
            raise FiberpipeError(f"constraints lock_axial must be all or ends, got {self.nodes!r}")

    @classmethod
    def from_config(cls, sc, model, cfg):
        return cls(axis=sc.constraints.axis, nodes=sc.constraints.lock_axial)

    def setup(self, model, scene):
        m = scene.mask()
        bit = {"x": FIX_X, "y": FIX_Y, "z": FIX_Z}[self.axis]
        if self.nodes == "all":
            m |= np.uint8(bit)
        else:
            off = np.asarray(model.node_offsets, dtype=np.int64)
            m[off[:-1]] |= np.uint8(bit)
            m[off[1:] - 1] |= np.uint8(bit)

    def describe(self) -> str:
        return f"constraints: {self.axis} translation of {self.nodes} nodes fixed"


@dataclass
class PointLoad:
    """A constant force (N) on one node of a fiber (``at`` = start | end | node index)."""

    fiber: int
    force_n: Sequence[float]
    at: object = "end"


@dataclass
class LineLoad:
    """A constant force per unit length (N/m) along a whole fiber, lumped to its nodes
    (each node gets half the rest length of each adjacent element)."""

    fiber: int
    force_n_per_m: Sequence[float]


@register_effect()
@dataclass
class Loads(Effect):
    """Constant point and line forces (applied from t = 0; quasi-static cases add damping)."""

    loads: Sequence[object] = field(default_factory=list)
    name = "loads"

    def __post_init__(self):
        out = []
        for ld in self.loads:
            if isinstance(ld, dict):
                ld = dict(ld)
                if "line_force" in ld:
                    ld = LineLoad(ld["fiber"], ld["line_force"])
                else:
                    ld = PointLoad(ld["fiber"], ld["force"], ld.get("at", "end"))
            if isinstance(ld, PointLoad):
                ld.force_n = _vec3(ld.force_n, "loads.force")
            elif isinstance(ld, LineLoad):
                ld.force_n_per_m = _vec3(ld.force_n_per_m, "loads.line_force")
            else:
                raise FiberpipeError(f"unknown load {ld!r}")
            out.append(ld)
        self.loads = out

    @classmethod
    def from_config(cls, sc, model, cfg):
        return cls([LineLoad(ld.fiber, list(ld.line_force)) if ld.line_force is not None
                    else PointLoad(ld.fiber, list(ld.force), ld.at) for ld in sc.loads])

    def setup(self, model, scene):
        f = scene.ext()
        for k, ld in enumerate(self.loads):
            if isinstance(ld, PointLoad):
                f[_node_of(model, f"scene.loads[{k}]", ld.fiber, ld.at)] += ld.force_n
            else:
                _check_fiber(model, f"scene.loads[{k}]", ld.fiber)
                sel = model.el_fiber == ld.fiber
                n1 = model.el_n1[sel]
                half = 0.5 * model.el_L0[sel]
                for k in (0, 1):
                    np.add.at(f, n1 + k, half[:, None] * ld.force_n_per_m[None, :])


@register_effect()
@dataclass
class Plates(Effect):
    """Two rigid planes normal to ``axis`` (lower at the low side, upper at the high side).

    Parameters
    ----------
    axis : "x" | "y" | "z"
    lower, upper : "moving" | "fixed" | "none"
    displacement_m : float, m — travel of each moving plate towards the other (loading).
    velocity_m_s : float, m/s — mean loading speed; the loading lasts ``displacement/velocity``
        (plus the acceleration time for ``ramp = smooth``).
    ramp : "smooth" (default: constant velocity with smoothstep accelerations over
        ``ramp_fraction`` of the loading time at both ends, zero velocity at start and end) |
        "smoothstep" (3τ² − 2τ³ in displacement) | "linear" (constant velocity from t = 0).
    lower_position_m, upper_position_m : optional, m — plane positions; by default each plate
        touches the bundle (min/max over nodes of the coordinate ∓ radius).
    path_m : optional sequence of travels, m — a loading path: each moving plate travels to these
        displacements in turn at ``velocity_m_s``, each move with its own ramp (``smooth``: zero
        velocity at every turning point), holding ``hold_s`` after each move but the last; replaces
        ``displacement_m`` (which is then the path's largest travel).
    hold_s : float, s — the hold at each turning point of ``path_m``.
    penalty_factor : float — plane penalty per node ``k_i = factor · m_i (2/Δt)²`` (default 0.1:
        raises the touching node's ω² by 10 % of the stability bound).
    onset_fraction : float — the penalty's force and stiffness rise from zero over a penetration of
        this fraction of the fiber radius (default 0.02, :func:`_kernels_boundary.plane_onset`).

    Outputs: ``plate_force`` (T, 2) N, positive when the fibers press the plate;
    ``plate_displacement`` (T, 2) m, travel of each plate towards the bundle.
    """

    axis: str = "z"
    lower: str = "moving"
    upper: str = "fixed"
    displacement_m: float = 0.0
    velocity_m_s: float = 0.0
    ramp: str = "smooth"
    ramp_fraction: float = 0.1
    lower_position_m: float | None = None
    upper_position_m: float | None = None
    penalty_factor: float = DEFAULT_PENALTY_FACTOR
    onset_fraction: float = DEFAULT_ONSET_FRACTION
    path_m: Sequence[float] | None = None
    hold_s: float = 0.0
    name = "plates"

    def __post_init__(self):
        if self.path_m is not None:
            self.path_m = [float(u) for u in self.path_m]
            _check_path(self.path_m, float(self.hold_s))
            self.displacement_m = max(self.path_m)
        if self.axis not in _AXES:
            raise FiberpipeError(f"plates.axis must be x, y or z, got {self.axis!r}")
        for k in ("lower", "upper"):
            if getattr(self, k) not in ("moving", "fixed", "none"):
                raise FiberpipeError(f"plates.{k} must be moving, fixed or none, got {getattr(self, k)!r}")
        moving = "moving" in (self.lower, self.upper)
        if moving and not (self.displacement_m > 0 and self.velocity_m_s > 0):
            raise FiberpipeError("a moving plate needs loading.displacement > 0 and loading.velocity > 0")
        _ramp_code(self.ramp, "loading")
        if not 0.0 < self.ramp_fraction < 0.5:
            raise FiberpipeError(f"loading ramp_fraction must be in (0, 0.5), got {self.ramp_fraction}")
        _check_plane_penalty("plates", self.penalty_factor, self.onset_fraction)

    def _move_time(self, du_m: float) -> float:
        if "moving" not in (self.lower, self.upper):
            return 0.0
        T = abs(du_m) / self.velocity_m_s
        if self.ramp == "smooth":
            T = T / (1.0 - self.ramp_fraction)  # so that the plateau speed is the given one
        return T

    def travel_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The moving plates' travel table ``(u_end, duration, t_accel)`` (m, s, s) for
        :func:`_kernels_boundary.path_travel`: one entry for ``displacement_m``; for ``path_m`` its
        moves, each but the last followed by a hold of ``hold_s`` (an entry that keeps the travel)."""
        path = [self.displacement_m] if self.path_m is None else list(self.path_m)
        u, T, ta, prev = [], [], [], 0.0
        for k, target in enumerate(path):
            if k > 0:
                u.append(prev)
                T.append(self.hold_s)
                ta.append(0.0)
            Tk = max(self._move_time(target - prev), 1e-30)
            u.append(target)
            T.append(Tk)
            ta.append(self.ramp_fraction * Tk)
            prev = target
        return np.array(u), np.array(T), np.array(ta)

    @property
    def loading_time_s(self) -> float:
        if self.path_m is None or "moving" not in (self.lower, self.upper):
            return self._move_time(self.displacement_m)
        total = 0.0
        for T in self.travel_table()[1]:  # summed in the order path_travel sums them
            total += T
        return total

    @classmethod
    def from_config(cls, sc, model, cfg):
        p, ld = sc.plates, sc.loading
        return cls(axis=p.axis, lower=p.lower, upper=p.upper, displacement_m=float(ld.displacement),
                   velocity_m_s=float(ld.velocity), ramp=ld.ramp, ramp_fraction=float(ld.ramp_fraction),
                   lower_position_m=p.lower_position, upper_position_m=p.upper_position,
                   path_m=None if ld.path is None else [float(u) for u in ld.path], hold_s=float(ld.hold),
                   penalty_factor=float(p.penalty_factor), onset_fraction=float(p.onset_fraction))

    def setup(self, model, scene):
        ax = _AXES[self.axis]
        c = model.nodes_m[:, ax]
        lo = float(np.min(c - model.radius_node)) if self.lower_position_m is None else float(self.lower_position_m)
        hi = float(np.max(c + model.radius_node)) if self.upper_position_m is None else float(self.upper_position_m)
        self._check_gap(lo, hi)
        u_end, T, ta = self.travel_table()
        mode = _ramp_code(self.ramp, "loading")
        for k, (kind, sign, pos) in enumerate((("lower", 1.0, lo), ("upper", -1.0, hi))):
            state = getattr(self, kind)
            if state == "none":
                continue
            move = u_end if state == "moving" else np.zeros_like(u_end)
            scene.add_plane(ax, sign, pos, move, T, ta, mode, H_PLATE_FORCE + k, self.penalty_factor,
                            self.onset_fraction)
        scene.plate_axis = ax
        scene.end_time_hint = max(scene.end_time_hint, self.loading_time_s)

    def _check_gap(self, lo: float, hi: float) -> None:
        """A path whose plates would meet or cross (travel summed over the moving plates ≥ their
        gap) is refused, naming the key."""
        n_moving = sum(getattr(self, k) == "moving" for k in ("lower", "upper"))
        if self.path_m is None or n_moving == 0 or "none" in (self.lower, self.upper):
            return
        gap, far = hi - lo, max(self.path_m)
        if n_moving * far >= gap:
            movers = "both plates move" if n_moving == 2 else "one plate moves"
            raise FiberpipeError(
                f"reverses at {far * 1e3:.4g} mm but the plates are {gap * 1e3:.4g} mm apart and {movers}: "
                f"keep every entry below {gap / n_moving * 1e3:.4g} mm", where="scene.loading.path")


def _check_plane_penalty(kind: str, penalty_factor: float, onset_fraction: float) -> None:
    """The plane penalty's factor in (0, 0.25] and onset fraction in (0, 0.5]."""
    if not 0 < penalty_factor <= 0.25:
        raise FiberpipeError(f"{kind} penalty_factor must be in (0, 0.25], got {penalty_factor}")
    if not 0 < onset_fraction <= 0.5:
        raise FiberpipeError(f"{kind} onset_fraction must be in (0, 0.5], got {onset_fraction}")


def _check_path(path_m: Sequence[float], hold_s: float) -> None:
    """The loading path's entries: finite, ≥ 0, the first > 0, no two in a row equal; hold ≥ 0."""
    if not path_m:
        raise FiberpipeError("is empty: give the plate displacements in turn, e.g. ['1 mm', '0.4 mm']",
                             where="scene.loading.path")
    prev = 0.0
    for k, u in enumerate(path_m):
        if not math.isfinite(u) or u < 0.0:
            raise FiberpipeError(f"entry {k} is {u * 1e3:.4g} mm: the travel is measured from the start "
                                 "position towards the bundle, so every entry is ≥ 0", where="scene.loading.path")
        if u == prev:
            raise FiberpipeError(f"entry {k} ({u * 1e3:.4g} mm) equals the travel before it: each entry moves "
                                 "the plate (use scene.loading.hold for a stop)", where="scene.loading.path")
        prev = u
    if not (math.isfinite(hold_s) and hold_s >= 0.0):
        raise FiberpipeError(f"must be ≥ 0, got {hold_s} s", where="scene.loading.hold")


@register_effect()
@dataclass
class Walls(Effect):
    """Fixed rigid confining planes: ``planes`` maps an axis to the (low, high) plane positions (m);
    nodes are pushed inside by a penalty (as :class:`Plates`). One reaction column per plane in the
    order given (low then high for each axis), N, positive when pressed."""

    planes: dict = field(default_factory=dict)
    penalty_factor: float = DEFAULT_PENALTY_FACTOR
    onset_fraction: float = DEFAULT_ONSET_FRACTION
    name = "walls"

    def __post_init__(self):
        _check_plane_penalty("walls", self.penalty_factor, self.onset_fraction)
        out = {}
        for ax, pair in dict(self.planes).items():
            if ax not in _AXES:
                raise FiberpipeError(f"walls: axis must be x, y or z, got {ax!r}")
            lo, hi = (float(p) for p in pair)
            if not lo < hi:
                raise FiberpipeError(f"walls.{ax}: low plane {lo} must be below high plane {hi}")
            out[ax] = (lo, hi)
        self.planes = out

    @classmethod
    def from_config(cls, sc, model, cfg):
        w = sc.walls
        return cls({ax: tuple(getattr(w, ax)) for ax in ("x", "y", "z") if getattr(w, ax) is not None},
                   penalty_factor=float(w.penalty_factor), onset_fraction=float(w.onset_fraction))

    def setup(self, model, scene):
        for ax, (lo, hi) in self.planes.items():
            for sign, pos, tag in ((1.0, lo, "lo"), (-1.0, hi, "hi")):
                scene.add_plane(_AXES[ax], sign, pos, 0.0, 1.0, 0.0, 0, H_WALL + scene.n_walls, self.penalty_factor,
                                self.onset_fraction)
                scene.n_walls += 1
                scene.wall_names.append(f"{ax}_{tag}")


@dataclass
class Drive:
    """A fiber moved rigidly (all nodes' translations prescribed, rotations fixed) by
    ``displacement_m`` (3,) at mean speed ``velocity_m_s`` with the given ramp."""

    fiber: int
    displacement_m: Sequence[float]
    velocity_m_s: float
    ramp: str = "smooth"
    ramp_fraction: float = 0.1


@register_effect()
@dataclass
class Drives(Effect):
    """Prescribed rigid motions of whole fibers (the study's rearrangement case); the reactions'
    work goes to ALLWK. A node's reaction is the whole force that imposes its motion: inertia minus
    the beam, load and contact forces on it, plus the mass-proportional damping force it overcomes
    (see :class:`Damping`)."""

    drives: Sequence[Drive] = field(default_factory=list)
    name = "drives"

    def __post_init__(self):
        out = []
        for d in self.drives:
            if isinstance(d, dict):
                d = Drive(d["fiber"], d["displacement"], d["velocity"], d.get("ramp", "smooth"))
            d.displacement_m = _vec3(d.displacement_m, "drives.displacement")
            if not d.velocity_m_s > 0:
                raise FiberpipeError(f"drives.velocity must be > 0, got {d.velocity_m_s}")
            _ramp_code(d.ramp, "drives")
            out.append(d)
        self.drives = out

    def duration_s(self, d: Drive) -> float:
        T = float(np.linalg.norm(d.displacement_m)) / d.velocity_m_s
        return T / (1.0 - d.ramp_fraction) if d.ramp == "smooth" else T

    @classmethod
    def from_config(cls, sc, model, cfg):
        return cls([Drive(d.fiber, list(d.displacement), float(d.velocity)) for d in sc.drives])

    def setup(self, model, scene):
        m = scene.mask()
        vec, Ts, tas, modes = [], [], [], []
        for k, d in enumerate(self.drives):
            sl = model.fiber_nodes(_check_fiber(model, f"scene.drives[{k}]", d.fiber))
            m[sl] |= DRIVEN
            scene.node_drive[sl] = k
            T = max(self.duration_s(d), 1e-30)
            vec.append(d.displacement_m)
            Ts.append(T)
            tas.append(d.ramp_fraction * T)
            modes.append(_ramp_code(d.ramp, "drives"))
            scene.end_time_hint = max(scene.end_time_hint, T)
        scene.drive_vec = np.array(vec, dtype=np.float64).reshape(-1, 3)
        scene.drive_T = np.array(Ts, dtype=np.float64)
        scene.drive_ta = np.array(tas, dtype=np.float64)
        scene.drive_mode = np.array(modes, dtype=np.int64)


@dataclass
class ContactHook(Effect):
    """Fiber–fiber contact/friction pass plugged into the step loop (see docs/solver.md).

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
    friction_of : optional, a jitted ``friction_of(data) -> (N, 3) array`` of the friction forces the
        kernel leaves there: the update adds them to the nodes, books their work ``Δt f_n·v̄_n`` to
        ALLPW, the same work as ``½Δt (f_{n−1} + f_n)·v_{n−½}`` (in phase with the friction springs)
        to the friction work (``energy/friction_work``) and minus it to ALLFD, and clears the array.
        The kernel books what its friction springs store: ALLFD and ALLPW −= their energy change.
    cache_name : a built-in hook's name for the on-disk compilation cache (None: the step loop
        specialised for this kernel is compiled once per process).
    kernel_threads : optional variant of ``kernel`` for ``solver.threads`` > 1 (parallel ``prange``
        tasks inside; same signature and results). None: ``kernel`` runs with any number of threads.

    A scene runs one hook: a second one is refused (combine the passes in one kernel).
    """

    kernel: Callable = no_contact
    data: tuple = (np.zeros(0),)
    prepare: Callable | None = None
    forces_of: Callable | None = None
    friction_of: Callable | None = None
    cache_name: str | None = None
    kernel_threads: Callable | None = None
    name = "contact"

    def setup(self, model, scene):
        if scene.contact_on:
            raise FiberpipeError(f"the scene has two contact hooks ({scene.contact_hook_name} and {self.name}); "
                                 "the step loop runs one: combine their passes in one kernel")
        scene.contact_on = True
        scene.contact_hook_name = self.name
        scene.contact_fn = self.kernel
        scene.contact_forces_of = self.forces_of if self.forces_of is not None else no_contact_forces
        scene.contact_friction_of = self.friction_of if self.friction_of is not None else no_contact_forces
        scene.contact_cache_name = self.cache_name
        scene.contact_fn_threads = self.kernel_threads
        scene.contact_data = self.prepare(model, scene) if self.prepare is not None else self.data
