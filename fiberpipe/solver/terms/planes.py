"""The planes term: plates and walls, the one owner of the planes' positions, penalty, candidate list,
friction, reactions, energy and checks.

``Plates`` (``scene.plates`` with ``scene.loading``) and ``Walls`` (``scene.walls``) each add their
planes to the scene (``SceneArrays.add_plane``), with their Coulomb coefficient when
``scene.effects`` lists ``friction``; the step loop then runs one plane pass over all of them
(:func:`eval_planes`: positions at t_n, the candidate list, the penalty forces, the stored energy and
the works; :func:`finish_planes` after the update; :func:`record_planes` at a history row). When a
plane has friction, the planes' friction runs as a per-step term of the chain
(:class:`PlaneFriction`, :func:`eval_plane_friction`, after the scene's other per-step terms): it
visits the nodes the plane pass listed near each plane and takes their normal force from that pass
(``PlaneArrays.cand_idx``, ``cand_off``, ``cand_fn``: the same arrays). The penalty kernels and the
loading ramps are in :mod:`fiberpipe.solver._kernels_boundary`, the friction kernel in
:mod:`fiberpipe.solver.friction`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np
from numba import njit

from ...errors import FiberpipeError
from ...model.mesh import plane_penetration
from .._kernels_boundary import (DEFAULT_ONSET_FRACTION, PLANE_LIST_MARGIN, in_plane_axes, path_delta, path_travel,
                                 penalty_power, plane_candidates, plane_contacts, plane_contacts_listed, plane_position)
from ..friction import plane_friction
from ..layout import (ACC_FD, ACC_PW, ACC_STORED, ACC_V2_MAX, ACC_WK, H_PLATE_DISP, H_PLATE_FORCE, H_WALL,
                      STATUS_LEFT_BOX, STATUS_OK, STATUS_PENETRATION)
from ..step_data import PlaneArrays
from .base import (_AXES, DEFAULT_PENALTY_FACTOR, PlaneSurface, SceneArrays, Term, _ramp_code, check_friction_stiffness,
                   register_term)

log = logging.getLogger(__name__)

_FLAGS = dict(cache=True, fastmath=True, error_model="numpy")


# ---- the plane pass of the step loop --------------------------------------------------------------


@njit(inline="always", **_FLAGS)
def eval_planes(planes, x, v, radius_node, f, acc, t, dt):
    """Plane penalties at t_n into ``f``; their stored energy to ``acc[ACC_STORED]``, the moving
    plates' prescribed work to ALLWK and the first half of the penalty work ``½Δt f_n·v_{n−½}`` to
    ALLPW. Returns the number of touching nodes."""
    P = planes.axis.shape[0]
    for p in range(P):
        planes.pos[p] = plane_position(t, planes.pos0[p], planes.sign[p], planes.move[p], planes.T[p], planes.ta[p],
                                       planes.mode[p])
    _keep_plane_list(planes, x, radius_node, acc, dt)
    n_pen, stored = plane_contacts_listed(x, radius_node, planes.k_pen, planes.onset, planes.axis, planes.sign,
                                          planes.pos, f, planes.force, planes.pen_idx, planes.pen_f, planes.cand_idx,
                                          planes.cand_off, planes.cand_fn, (planes.rect_half, planes.rect_centre))
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
def _keep_plane_list(planes, x, radius_node, acc, dt):
    """List the nodes near each plane again when one could have closed the list's margin since it was
    taken: each step every node moves by at most Δt max|v_{n−½}| (``acc[ACC_V2_MAX]``, which the
    previous update left; < 0 at a call's first step, whose state may have been set from outside)
    and each plane by its travel since."""
    slack = planes.cand_slack
    v2 = acc[ACC_V2_MAX]
    if v2 >= 0.0:
        slack[0] -= dt * math.sqrt(v2)
        moved = 0.0
        for p in range(planes.axis.shape[0]):
            moved = max(moved, abs(planes.pos[p] - planes.cand_pos[p]))
        if slack[0] - moved > 0.0:
            return
    plane_candidates(x, radius_node, planes.axis, planes.sign, planes.pos, slack[1], planes.cand_idx, planes.cand_off)
    for p in range(planes.axis.shape[0]):
        planes.cand_pos[p] = planes.pos[p]
    slack[0] = slack[1]




@njit(inline="always", **_FLAGS)
def finish_planes(planes, v, acc, dt, n_pen):
    """After the update: the second half of the penalty work, ``½Δt f_n·v_{n+½}``, to ALLPW."""
    if n_pen > 0:
        acc[ACC_PW] += 0.5 * dt * penalty_power(v, planes.pen_idx, planes.pen_f, n_pen)


@njit(inline="always", **_FLAGS)
def record_planes(row, planes, t):
    """The planes' columns of a history row at t_n: each reaction, and a plate's travel; returns the
    loading path's segment (0 for the one-segment loading)."""
    segment = 0
    for p in range(planes.axis.shape[0]):
        c = planes.hist_col[p]
        if c >= 0:
            row[c] = planes.force[p]
            if H_PLATE_FORCE <= c < H_PLATE_FORCE + 2:  # a plate: its travel and path segment too
                u, k = path_travel(t, planes.move[p], planes.T[p], planes.ta[p], planes.mode[p])
                row[H_PLATE_DISP + c - H_PLATE_FORCE] = u
                segment = max(segment, k // 2)  # the path's entries: moves, each but the last followed by a hold
    return segment


# ---- the terms ----------------------------------------------------------------------------------


@register_term()
@dataclass
class Plates(Term):
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
    mu : float — Coulomb coefficient of the plates' friction on the fibers (default 0: none;
        :class:`PlaneFriction`).
    friction_stiffness_n_per_m : optional, N/m — its tangential penalty k_t (default
        ``SceneArrays.default_friction_stiffness``, 0.02 m_min (2/Δt)²).
    size_m : optional (2,), m — finite rectangular plates: their extents along the plate plane's two
        axes in x, y, z order (axis y: along x, then z); a node whose centre lies outside the rectangle
        feels no plate. Default: infinite planes. Each extent at least a fiber diameter.
    centre_m : optional (2,), m — the rectangle's centre in that plane (default: the centre of the
        fibers' bounding box there).

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
    mu: float = 0.0
    friction_stiffness_n_per_m: float | None = None
    size_m: Sequence[float] | None = None
    centre_m: Sequence[float] | None = None
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
        _check_friction("plates", self.mu, self.friction_stiffness_n_per_m)
        for key in ("size_m", "centre_m"):
            v = getattr(self, key)
            if v is not None:
                v = [float(c) for c in v]
                if len(v) != 2 or not all(math.isfinite(c) for c in v):
                    raise FiberpipeError(f"must be two finite lengths, got {v}", where=f"scene.plates.{key[:-2]}")
                setattr(self, key, v)
        if self.size_m is not None and not min(self.size_m) > 0.0:
            raise FiberpipeError(f"must be > 0 along both axes, got {self.size_m}", where="scene.plates.size")

    def rectangle(self, model) -> tuple | None:
        """The plates' rectangle ``((half extents), (centre))`` [m] along the plate plane's two axes in x,
        y, z order, or None for infinite plates; refuses a plate smaller than a fiber diameter."""
        if self.size_m is None:
            return None
        diameter = 2.0 * float(np.max(model.radius_node))
        if min(self.size_m) < diameter:
            raise FiberpipeError(f"{[f'{s * 1e3:.4g} mm' for s in self.size_m]} is smaller than a fiber diameter "
                                 f"({diameter * 1e3:.4g} mm) along one axis: no fiber could rest on it",
                                 where="scene.plates.size")
        axes = in_plane_axes(_AXES[self.axis])
        x = model.nodes_m
        centre = self.centre_m or [0.5 * float(np.min(x[:, a]) + np.max(x[:, a])) for a in axes]
        return tuple(0.5 * s for s in self.size_m), tuple(float(c) for c in centre)

    def inside(self, model, x: np.ndarray) -> np.ndarray:
        """(N,) bool: the nodes at ``x`` whose centre lies on the plates' rectangle (all for infinite plates)."""
        rect = self.rectangle(model)
        if rect is None:
            return np.ones(x.shape[0], bool)
        (hu, hw), (cu, cw) = rect
        u, w = in_plane_axes(_AXES[self.axis])
        return (np.abs(x[:, u] - cu) <= hu) & (np.abs(x[:, w] - cw) <= hw)

    def surface(self) -> PlaneSurface:
        """What the plates do to the nodes that touch them: penalty and friction."""
        return PlaneSurface(self.penalty_factor, self.onset_fraction, self.mu, self.friction_stiffness_n_per_m)

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
    def from_config(cls, scene_cfg, model, cfg):
        p, ld = scene_cfg.plates, scene_cfg.loading
        return cls(axis=p.axis, lower=p.lower, upper=p.upper, displacement_m=float(ld.displacement),
                   velocity_m_s=float(ld.velocity), ramp=ld.ramp, ramp_fraction=float(ld.ramp_fraction),
                   lower_position_m=p.lower_position, upper_position_m=p.upper_position,
                   path_m=None if ld.path is None else [float(u) for u in ld.path], hold_s=float(ld.hold),
                   penalty_factor=float(p.penalty_factor), onset_fraction=float(p.onset_fraction),
                   size_m=getattr(p, "size", None), centre_m=getattr(p, "centre", None),
                   **_friction_of_config(scene_cfg))

    def setup(self, model, scene):
        ax = _AXES[self.axis]
        rect = self.rectangle(model)
        # by default each plate touches the bundle: its nodes over the plates' rectangle, if any
        over = self.inside(model, model.nodes_m)
        over = over if np.any(over) else np.ones_like(over)
        c, r = model.nodes_m[over, ax], model.radius_node[over]
        lo = float(np.min(c - r)) if self.lower_position_m is None else float(self.lower_position_m)
        hi = float(np.max(c + r)) if self.upper_position_m is None else float(self.upper_position_m)
        self._check_gap(lo, hi)
        u_end, T, ta = self.travel_table()
        mode = _ramp_code(self.ramp, "loading")
        for k, (kind, sign, pos) in enumerate((("lower", 1.0, lo), ("upper", -1.0, hi))):
            state = getattr(self, kind)
            if state == "none":
                continue
            move = u_end if state == "moving" else np.zeros_like(u_end)
            scene.add_plane(ax, sign, pos, (move, T, ta, mode), H_PLATE_FORCE + k, self.surface(), rect)
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


def _check_friction(kind: str, mu: float, stiffness_n_per_m: float | None) -> None:
    """A plane's Coulomb coefficient ≥ 0 and its tangential penalty > 0 (when given)."""
    if not (mu >= 0.0 and math.isfinite(mu)):
        raise FiberpipeError(f"{kind} mu must be ≥ 0, got {mu}")
    if stiffness_n_per_m is not None and not (stiffness_n_per_m > 0.0 and math.isfinite(stiffness_n_per_m)):
        raise FiberpipeError(f"{kind} friction stiffness must be > 0 N/m, got {stiffness_n_per_m}")


def _friction_of_config(scene_cfg, own_mu: float | None = None) -> dict:
    """A plane term's friction arguments from the config when ``scene.effects`` lists ``friction``:
    its own coefficient ``own_mu`` (the walls' ``scene.walls.mu``), else ``scene.friction.mu``, and
    ``scene.friction.stiffness``; none (μ = 0) otherwise."""
    if "friction" not in scene_cfg.effects:
        return {}
    mu = scene_cfg.friction.mu if own_mu is None else own_mu
    stiffness = scene_cfg.friction.stiffness
    return {"mu": float(mu), "friction_stiffness_n_per_m": None if stiffness is None else float(stiffness)}


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


@register_term()
@dataclass
class Walls(Term):
    """Fixed rigid confining planes: ``planes`` maps an axis to the (low, high) plane positions (m);
    nodes are pushed inside by a penalty (as :class:`Plates`). One reaction column per plane in the
    order given (low then high for each axis), N, positive when pressed. ``mu``: the walls' Coulomb
    coefficient (default 0: none; from the config ``scene.walls.mu``, else ``scene.friction.mu``),
    ``friction_stiffness_n_per_m`` its tangential penalty (as :class:`Plates`)."""

    planes: dict = field(default_factory=dict)
    penalty_factor: float = DEFAULT_PENALTY_FACTOR
    onset_fraction: float = DEFAULT_ONSET_FRACTION
    mu: float = 0.0
    friction_stiffness_n_per_m: float | None = None
    name = "walls"

    def __post_init__(self):
        _check_plane_penalty("walls", self.penalty_factor, self.onset_fraction)
        _check_friction("walls", self.mu, self.friction_stiffness_n_per_m)
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
    def from_config(cls, scene_cfg, model, cfg):
        w = scene_cfg.walls
        return cls({ax: tuple(getattr(w, ax)) for ax in ("x", "y", "z") if getattr(w, ax) is not None},
                   penalty_factor=float(w.penalty_factor), onset_fraction=float(w.onset_fraction),
                   **_friction_of_config(scene_cfg, getattr(w, "mu", None)))

    def setup(self, model, scene):
        surface = PlaneSurface(self.penalty_factor, self.onset_fraction, self.mu, self.friction_stiffness_n_per_m)
        for ax, (lo, hi) in self.planes.items():
            for sign, pos, tag in ((1.0, lo, "lo"), (-1.0, hi, "hi")):
                scene.add_plane(_AXES[ax], sign, pos, (0.0, 1.0, 0.0, 0), H_WALL + scene.n_walls, surface)
                scene.n_walls += 1
                scene.wall_names.append(f"{ax}_{tag}")


# ---- the planes' friction: a per-step term of the chain ----------------------------------------------


class PlaneFrictionData(NamedTuple):
    """The planes' friction's kernel data (P planes, N nodes)."""

    planes: PlaneArrays         # the plane pass's arrays: positions, travel, the listed nodes and their normal force
    mu: np.ndarray              # (P,) Coulomb coefficient of each plane (0: no friction)
    kt_n_per_m: np.ndarray      # (P,) N/m, tangential penalty of each plane
    vel: np.ndarray             # (P, 3) m/s, the planes' velocities at t_n
    hist: np.ndarray            # (N, P, 4) tangential spring force (3) per (node, plane), step of its last update
    tforce: np.ndarray          # (P, 3) N, tangential reaction on each plane
    ff: np.ndarray              # (N, 3) N, the scene's friction forces (SceneArrays.friction_forces)
    calls: np.ndarray           # (1,) int64, calls so far (the histories' time stamps)
    e_spring_J: np.ndarray      # (1,) J, elastic energy of the planes' friction springs
    friction_returned_J: np.ndarray  # (1,) J, the scene's friction's energy given back (SceneArrays.friction_returned)


@njit(inline="always", **_FLAGS)
def eval_plane_friction(x, q, v, w, f, mom, acc, t, dt, data):
    """The planes' friction at t_n (the signature of every term's eval, ``terms.base``): the planes'
    velocities over the step, the tangential forces of the nodes the plane pass found touching
    (:func:`fiberpipe.solver.friction.plane_friction`) into the scene's friction array, which the
    node update applies and books; the springs' stored energy to ``acc[ACC_STORED]`` and minus its
    change to ALLPW and ALLFD (as the contact term's fiber–fiber friction). Counts no contacts."""
    calls = data.calls[0]
    data.calls[0] = calls + 1
    planes = data.planes
    for p in range(planes.axis.shape[0]):
        vel = planes.sign[p] * path_delta(t, t - dt, planes.move[p], planes.T[p], planes.ta[p], planes.mode[p]) / dt
        data.vel[p, 0] = 0.0
        data.vel[p, 1] = 0.0
        data.vel[p, 2] = 0.0
        data.vel[p, planes.axis[p]] = vel
    _, e_springs, back = plane_friction(v, data, dt, calls)
    data.friction_returned_J[0] += back
    diss = -(e_springs - data.e_spring_J[0])
    data.e_spring_J[0] = e_springs
    acc[ACC_STORED] += e_springs
    acc[ACC_PW] += diss
    acc[ACC_FD] += diss
    return 0


class PlaneFriction(Term):
    """Coulomb friction of the plates and walls on the fibers (regularised, with per-contact history:
    :mod:`fiberpipe.solver.friction`): the planes term's per-step pass, which the integrator adds to
    the end of the chain when a plane of the scene has a coefficient μ > 0 (:func:`set_up_planes`;
    ``Plates(mu=...)``, ``Walls(mu=...)``, from the config ``scene.friction.mu`` and
    ``scene.walls.mu`` when ``scene.effects`` lists ``friction``). Its normal force is the plane
    pass's, at the nodes that pass lists near each plane."""

    name = "plane_friction"
    eval = staticmethod(eval_plane_friction)
    cache_name = "plane_friction"

    def setup(self, model, scene):
        planes = plane_arrays(scene)
        P, N = planes.axis.size, model.n_nodes
        default = scene.default_friction_stiffness()
        kt = np.where(np.isnan(scene.pl_kt), default, scene.pl_kt)
        for k in np.unique(kt[scene.pl_mu > 0.0]):
            check_friction_stiffness(model, float(scene.dt), float(k))
        return PlaneFrictionData(planes, scene.pl_mu.astype(np.float64), kt.astype(np.float64), np.zeros((P, 3)),
                                 np.zeros((N, P, 4)), np.zeros((P, 3)), scene.friction_forces(), np.zeros(1, np.int64),
                                 np.zeros(1), scene.friction_returned())


def set_up_planes(model, scene: SceneArrays) -> tuple[PlaneArrays, list]:
    """The step loop's plane arrays of the scene (every plane added) and the planes' per-step terms:
    ``[(PlaneFriction, its data, its kernels)]`` when a plane has friction, else ``[]``."""
    planes = plane_arrays(scene)
    if not np.any(scene.pl_mu > 0.0):
        return planes, []
    term = PlaneFriction()
    return planes, [(term, term.setup(model, scene), term.kernels())]


# ---- the planes' arrays, energy and checks, for the integrator and the run --------------------------

#: the plane pass's mutable arrays a checkpoint holds: PlaneArrays field -> dataset name under
#: ``integrator/`` (the candidate lists are not: every call of the step loop lists the nodes anew)
CHECKPOINT_FIELDS = {"pos": "pl_pos", "force": "pl_force", "pen_idx": "pen_idx", "pen_f": "pen_f"}


def plane_arrays(scene: SceneArrays) -> PlaneArrays:
    """The step loop's :class:`~fiberpipe.solver.step_data.PlaneArrays` of the scene's planes, made
    once every plane is added (``scene.plane_arrays``: the planes' friction reads the same arrays)."""
    model = scene.model
    n, P = model.n_nodes, scene.pl_axis.size
    if scene.plane_arrays is not None and scene.plane_arrays.axis.size == P:
        return scene.plane_arrays
    r_max = float(np.max(model.radius_node)) if n else 0.0
    scene.plane_arrays = PlaneArrays(
        scene.pl_axis, scene.pl_sign, scene.pl_pos0, scene.pl_move, scene.pl_T, scene.pl_ta, scene.pl_mode,
        scene.pl_hist_col, scene.k_pen(), scene.pen_onset(), scene.pl_pos0.astype(np.float64), np.zeros(P),
        np.zeros(n * P, np.int64), np.zeros(n * P), np.zeros(n * P, np.int64), np.zeros(P + 1, np.int64),
        np.zeros(n * P), np.zeros(P), np.array([-1.0, PLANE_LIST_MARGIN * r_max]), scene.pl_rect_half,
        scene.pl_rect_centre)
    return scene.plane_arrays


def plane_energy(scene: SceneArrays, x: np.ndarray) -> float:
    """The plane penalties' stored energy at positions ``x`` (planes at their start), from the
    step loop's own plane kernel on scratch arrays."""
    P = scene.pl_axis.size
    if P == 0:
        return 0.0
    n = x.shape[0]
    _, energy = plane_contacts(np.ascontiguousarray(x, dtype=np.float64),
                               np.ascontiguousarray(scene.model.radius_node, dtype=np.float64), scene.k_pen(),
                               scene.pen_onset(), scene.pl_axis, scene.pl_sign, scene.pl_pos0, np.zeros((n, 3)),
                               np.zeros(P), np.zeros(n * P, np.int64), np.zeros(n * P),
                               (scene.pl_rect_half, scene.pl_rect_centre))
    return float(energy)


def _plane_name(scene: SceneArrays, p: int) -> str:
    c = int(scene.pl_hist_col[p])
    if c in (H_PLATE_FORCE, H_PLATE_FORCE + 1):
        return ("lower", "upper")[c - H_PLATE_FORCE] + " plate"
    k = c - H_WALL
    return f"wall {scene.wall_names[k]}" if 0 <= k < len(scene.wall_names) else f"plane {p}"


def plane_check(scene: SceneArrays, planes: PlaneArrays, x: np.ndarray, limit: float) -> tuple[int, int, str]:
    """Runaway penetration into (depth > ``limit`` radii) or escape through (centre beyond by more than a
    radius) a plate or wall at positions ``x`` (a finite plate: the nodes over its rectangle);
    returns ``(status, node, detail)`` (``layout.STATUS_*``)."""
    if scene.pl_axis.size == 0:
        return STATUS_OK, -1, ""
    r = scene.model.radius_node
    worst, node, plane = -np.inf, -1, -1
    with np.errstate(invalid="ignore"):
        for p in range(scene.pl_axis.size):
            depth = (r - scene.pl_sign[p] * (x[:, scene.pl_axis[p]] - planes.pos[p])) / r
            depth = np.where(_over_plane(planes, p, x), depth, -np.inf)
            i = int(np.nanargmax(depth)) if np.any(np.isfinite(depth)) else -1
            if i >= 0 and depth[i] > worst:
                worst, node, plane = float(depth[i]), i, p
    if node < 0 or worst <= limit:
        return STATUS_OK, -1, ""
    name = _plane_name(scene, plane)
    ax = "xyz"[int(scene.pl_axis[plane])]
    where = f"{name} ({ax} = {planes.pos[plane] * 1e3:.4g} mm)"
    if worst > 2.0:
        return (STATUS_LEFT_BOX, node,
                f"its centre is {(worst - 1.0) * r[node] * 1e3:.3g} mm beyond the {where}")
    return (STATUS_PENETRATION, node,
            f"it is {worst:.2f} radii ({worst * r[node] * 1e3:.3g} mm) into the {where}")


def _over_plane(planes: PlaneArrays, p: int, x: np.ndarray) -> np.ndarray:
    """(N,) bool: the nodes at ``x`` over plane ``p`` (its rectangle for a finite plate; all otherwise)."""
    (hu, hw), (cu, cw) = planes.rect_half[p], planes.rect_centre[p]
    if not hu > 0.0:
        return np.ones(x.shape[0], bool)
    u, w = in_plane_axes(int(planes.axis[p]))
    return (np.abs(x[:, u] - cu) <= hu) & (np.abs(x[:, w] - cw) <= hw)


#: an initial penetration of a plate or wall deeper than this fraction of the fiber radius is an error
#: (deeper than 1 % a warning)
CUT_TOLERANCE = 0.25


def _mm(v: float) -> str:
    return f"{v * 1e3:.4g} mm"


def check_scene_geometry(model, terms) -> list[str]:
    """Plates and walls against the bundle, before anything runs.

    Errors (``FiberpipeError`` naming the key): a plate or wall that cuts through the bundle (a node
    more than ``CUT_TOLERANCE`` radii past it: the penalty would blow the fibers apart at t = 0);
    plates that never touch the fibers (their gaps to the bundle add up to more than their travel).
    Returns warnings (also logged): a plate that starts away from the bundle, a slight overlap.
    """
    warnings: list[str] = []
    x, r = model.nodes_m, model.radius_node
    axes = {"x": 0, "y": 1, "z": 2}

    def cut(key: str, ax: int, pos: float, low_side: bool, over=None) -> None:
        depth = plane_penetration(x, r, ax, pos, 1.0 if low_side else -1.0)
        if over is not None:  # a finite plate: the nodes over its rectangle
            depth = np.where(over, depth, -np.inf)
        i = int(np.argmax(depth / r))
        if depth[i] > CUT_TOLERANCE * r[i]:
            ext = float(np.min(x[:, ax] - r)) if low_side else float(np.max(x[:, ax] + r))
            raise FiberpipeError(
                f"the plane at {_mm(pos)} cuts through the bundle: fiber {int(model.node_fiber[i])} (node {i}) reaches "
                f"{_mm(depth[i])} past it with its radius; positions are those of the planes, not of fiber axes: put it "
                f"{'at or below' if low_side else 'at or above'} {_mm(ext)}"
                + (" or leave it unset (the plate then touches the bundle)" if "plates" in key else ""), where=key)
        if depth[i] > 0.01 * r[i]:
            warnings.append(f"{key}: the plane at {_mm(pos)} overlaps fiber {int(model.node_fiber[i])} by "
                            f"{_mm(depth[i])} at the start (pushed out in the first steps)")

    for e in terms:
        if isinstance(e, Walls):
            for axn, (lo, hi) in e.planes.items():
                cut(f"scene.walls.{axn}", axes[axn], lo, True)
                cut(f"scene.walls.{axn}", axes[axn], hi, False)
        elif isinstance(e, Plates):
            ax = axes[e.axis]
            over = e.inside(model, x)  # refuses a plate smaller than a fiber (scene.plates.size)
            over = over if np.any(over) else np.ones_like(over)
            lo_b, hi_b = float(np.min(x[over, ax] - r[over])), float(np.max(x[over, ax] + r[over]))
            gaps, travel = 0.0, 0.0
            for kind, pos, low_side, ext in (("lower", e.lower_position_m, True, lo_b),
                                             ("upper", e.upper_position_m, False, hi_b)):
                mode = getattr(e, kind)
                if mode == "none":
                    continue
                travel += e.displacement_m if mode == "moving" else 0.0
                if pos is None:
                    continue
                key = f"scene.plates.{kind}_position"
                cut(key, ax, float(pos), low_side, over)
                gap = (ext - float(pos)) if low_side else (float(pos) - ext)
                if gap > 0:
                    gaps += gap
                if gap > 0.01 * float(np.min(r)):  # below 1 % of r: touching (e.g. after the plane clearance)
                    warnings.append(f"{key}: the {kind} plate starts {_mm(gap)} away from the bundle "
                                    f"(nothing is compressed until it has travelled that far)")
            if "moving" in (e.lower, e.upper) and gaps > 0 and gaps >= travel:
                raise FiberpipeError(
                    f"the plates never touch the fibers: their gaps to the bundle add up to {_mm(gaps)} but they "
                    f"travel only {_mm(travel)} (loading.displacement); move them closer or leave the positions "
                    "unset (plates then start touching the bundle)", where="scene.plates")
    for w in warnings:
        log.warning(w)
    return warnings


