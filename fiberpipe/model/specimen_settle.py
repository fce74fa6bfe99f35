"""Settling a deposited pile in the solver: gravity, contact, Coulomb friction and the axial lock.

The deposit (:func:`fiberpipe.model.specimen.cassette_specimen`, ``placement="deposit"``) leaves a
frictionless rest state of rigid fibers, which is not an equilibrium of the beam model with point
contacts and friction; a short damped run under gravity settles it, and its end positions become
the specimen's mid-lines (the rest shape of the compaction run).
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import numpy as np

from fiberpipe.polylines import Polylines


def settle_scene(raw: dict, *, width_m: float, alpha_per_s: float, time_s: float, mu: float, lock: str | None,
                 frames: int, mass_scaling: float | None = None, gravity_scale: float | None = None,
                 contact: dict | None = None) -> dict:
    """The raw config of the settling run made from the compaction config ``raw``: its material,
    fiber, mesh, contact law and solver settings; the lower plate fixed at y = 0, no upper plate,
    walls at x = ±``width_m``/2, gravity along −y (× ``gravity_scale``), the mass scaling
    ``mass_scaling`` (not the compaction's), damping α =
    ``alpha_per_s``, friction μ = ``mu``, with ``lock`` = "all" | "ends" the axial lock, and
    ``contact`` (a scene.contact section) instead of the compaction's if given."""
    from fiberpipe.config import GravityConfig
    from fiberpipe.units import to_si

    raw = copy.deepcopy(raw)
    raw.pop("specimen", None)
    sc = raw.setdefault("scene", {})
    if contact is not None:  # the settling's own contact section (specimen.settle.contact)
        sc["contact"] = copy.deepcopy(contact)
    # the compaction scene's effects in its order (the force sums run in that order), the loads and
    # drives left out, what settling needs added, then the plates and the lock
    effects = [e for e in sc.get("effects", []) if e not in ("plates", "constraints", "clamps", "loads", "drives")]
    effects += [e for e in ("gravity", "damping", "contact", "friction", "walls") if e not in effects]
    sc["effects"] = effects + ["plates"] + (["constraints"] if lock else [])
    for name in ("clamps", "loads", "drives"):
        sc.pop(name, None)
    sc.pop("constraints", None)
    sc["plates"] = {"axis": "y", "lower": "fixed", "upper": "none", "lower_position": 0.0}
    sc["walls"] = {"x": [-width_m / 2, width_m / 2]}
    sc["loading"] = {"displacement": 0.0}
    sc["damping"] = {"alpha": float(alpha_per_s), "beta": 0.0}
    sc["friction"] = {**(sc.get("friction") or {}), "mu": float(mu)}
    if lock:
        sc["constraints"] = {"lock_axial": lock}
    given = (sc.get("gravity") or {}).get("acceleration")
    g = float(np.linalg.norm([to_si(a, "acceleration") for a in (given or GravityConfig().acceleration)]))
    sc["gravity"] = {"acceleration": [0.0, -g * float(gravity_scale or 1.0), 0.0]}
    # the compaction's mass scaling and its step scheme (solver.stable_step) are settings of the
    # compaction: the settling has its own mass scaling and the element step, so that compactions
    # that differ in them share their specimens
    solver = {k: v for k, v in (raw.get("solver") or {}).items()
              if k not in ("checkpoint_every", "settle_time", "mass_scaling", "stable_step")}
    raw["solver"] = {**solver, "end_time": float(time_s), "output_frames": int(frames)}
    if mass_scaling is not None and mass_scaling != 1.0:
        raw["solver"]["mass_scaling"] = float(mass_scaling)
    raw.setdefault("post", {})["plots"] = False
    return raw


def settle_pile(fibers: Polylines, raw: dict, *, width_m: float, alpha_per_s: float, time_s: float, mu: float = 0.2,
                lock: str | None = "all", frames: int = 9, mass_scaling: float | None = None,
                gravity_scale: float | None = None, where: str = "settle", progress=None) -> tuple[Polylines, dict]:
    """Settle ``fibers`` (a deposited pile) in the solver (:func:`settle_scene` of ``raw``); returns
    the settled Polylines (the node positions of the last frame, per fiber) and the settling
    figures (time step, steps, displacements, kinetic energy per frame, contacts, wall time).
    ``progress``: the solver's ``progress(t_s, end_time_s, steps)``, called as it advances."""
    sraw = settle_scene(raw, width_m=width_m, alpha_per_s=alpha_per_s, time_s=time_s, mu=mu, lock=lock,
                        frames=frames, mass_scaling=mass_scaling, gravity_scale=gravity_scale)
    cfg, mesh, res, wall = _run_scene(sraw, fibers, where, progress)
    X = np.asarray(res.frames_positions)
    off = np.asarray(mesh.node_offsets)
    r = float(cfg.fiber.radius)
    x = X[-1]
    settled = Polylines.from_list([x[off[i]:off[i + 1]] for i in range(len(off) - 1)], r)
    moved = np.linalg.norm(x - mesh.nodes_m, axis=1)
    dtf = float(res.frames_time[-1] - res.frames_time[-2])
    last = np.linalg.norm(X[-1] - X[-2], axis=1)
    h = res.history
    out = {
        "alpha_per_s": float(alpha_per_s), "time_s": float(time_s), "mu": float(mu), "lock_axial": lock,
        **({"mass_scaling": float(mass_scaling)} if mass_scaling not in (None, 1.0) else {}),
        **({"gravity_scale": float(gravity_scale)} if gravity_scale not in (None, 1.0) else {}),
        "dt_s": float(res.dt_s), "steps": int(res.steps),
        "max_displacement_m": float(moved.max()), "median_fiber_max_displacement_m":
            float(np.median([moved[off[i]:off[i + 1]].max() for i in range(len(off) - 1)])),
        "last_frame_interval_s": dtf, "max_speed_last_interval_m_s": float(last.max() / dtf),
        "kinetic_energy_end_J": float(h["energy/kinetic"][-1]), "strain_energy_end_J": float(h["energy/strain"][-1]),
        "kinetic_energy_max_J": float(np.max(h["energy/kinetic"])),
        "frame_times_s": [float(t) for t in res.frames_time],
        "kinetic_energy_at_frames_J": [float(np.interp(t, h["time"], h["energy/kinetic"])) for t in res.frames_time],
        "max_speed_per_frame_interval_m_s": [float(v) for v in np.max(np.linalg.norm(np.diff(X, axis=0), axis=2), axis=1)
                                             / np.diff(res.frames_time)],
        "contacts_end": int(h["contacts"][-1]) if "contacts" in h and len(h["contacts"]) else None,
        "wall_time_s": wall,
    }
    return settled, out


def fiber_contacts(x, off, r, tol_m=1e-7) -> int:
    """Fiber pairs whose centre lines (node-to-node segments) come within 2r + ``tol_m``."""
    from scipy.spatial import cKDTree

    from fiberpipe.model.specimen_stats import segment_distances

    fib = np.repeat(np.arange(len(off) - 1), np.diff(off))
    seg = np.flatnonzero(np.r_[fib[1:] == fib[:-1], False])  # segment k: nodes k, k+1
    if len(seg) == 0:
        return 0
    mid = 0.5 * (x[seg] + x[seg + 1])
    half = float(np.max(np.linalg.norm(x[seg + 1] - x[seg], axis=1)))
    pairs = cKDTree(mid).query_pairs(2 * r + half + tol_m, output_type="ndarray")
    a, b = seg[pairs[:, 0]], seg[pairs[:, 1]]
    keep = fib[a] != fib[b]
    a, b = a[keep], b[keep]
    d, _, _ = segment_distances(x[a], x[a + 1], x[b], x[b + 1])
    hit = d <= 2 * r + tol_m
    return len({(min(i, j), max(i, j)) for i, j in zip(fib[a[hit]], fib[b[hit]])})


class ClosingPlan(NamedTuple):
    """Where the cassette closes: the upper plate from ``start_m`` (the settled pile's top plus the
    clearance) down to ``target_m`` (the target v_f0's height) at ``velocity_m_s``, then held
    ``relax_time_s``; the cassette ``width_m`` wide."""

    width_m: float
    start_m: float
    target_m: float
    velocity_m_s: float
    relax_time_s: float


def closing_scene(raw: dict, plan: ClosingPlan, close_cfg, settle_cfg) -> dict:
    """The raw config of the closing run: :func:`settle_scene`'s (gravity, friction μ and the axial
    lock of the settling), with the closing's damping and mass scaling, the lower plate fixed at
    y = 0 and the upper one moving down from ``plan.start_m`` to ``plan.target_m`` (a smooth ramp,
    10 % of the travel time accelerating and 10 % decelerating), then held."""
    travel = plan.start_m - plan.target_m
    ramp_fraction = 0.1
    end_time = travel / plan.velocity_m_s / (1 - ramp_fraction) + plan.relax_time_s
    lock = None if settle_cfg.lock_axial == "none" else settle_cfg.lock_axial
    closing = settle_scene(raw, width_m=plan.width_m, alpha_per_s=close_cfg.damping_alpha, time_s=end_time,
                           mu=settle_cfg.mu, lock=lock, frames=close_cfg.frames, mass_scaling=close_cfg.mass_scaling,
                           contact=settle_cfg.contact)
    closing["scene"]["plates"] = {"axis": "y", "lower": "fixed", "upper": "moving", "lower_position": 0.0,
                                  "upper_position": float(plan.start_m)}
    closing["scene"]["loading"] = {"displacement": float(travel), "velocity": float(plan.velocity_m_s),
                                   "ramp": "smooth", "ramp_fraction": ramp_fraction}
    return closing


def close_pile(fibers: Polylines, raw: dict, plan: ClosingPlan, close_cfg, settle_cfg, *, where: str = "close",
               progress=None) -> tuple[Polylines, dict]:
    """Close the cassette onto the settled pile ``fibers`` (:func:`closing_scene`) and let it relax;
    returns the closed pile (the last frame) and the closing's figures: the residual load on the
    upper plate at the end (the elastic load the closed pile still carries, which the compaction
    run, whose rest shape is the closed pile, does not), the pile's top and its v_f. A pile whose
    top stays above the target height by more than ``close_cfg.tolerance`` (fibers held in the
    plate's penalty) cannot reach the target: a one-line error with the densest v_f it reached."""
    from fiberpipe.errors import ConfigError

    scene = closing_scene(raw, plan, close_cfg, settle_cfg)
    cfg, mesh, res, wall, dt_safety = _run_closing(scene, fibers, where, progress)
    radius = float(cfg.fiber.radius)
    X = np.asarray(res.frames_positions)
    off = np.asarray(mesh.node_offsets)
    tops = X[:, :, 1].max(axis=1) + radius
    area = (len(off) - 1) * np.pi * radius**2
    history = res.history
    force = np.asarray(history["plate_force"])[:, 1]
    out = {
        "start_height_m": float(plan.start_m), "target_height_m": float(plan.target_m),
        "velocity_m_s": float(plan.velocity_m_s), "relax_time_s": float(plan.relax_time_s),
        "alpha_per_s": float(close_cfg.damping_alpha), "mass_scaling": float(close_cfg.mass_scaling),
        "dt_s": float(res.dt_s), "steps": int(res.steps), "wall_time_s": wall, "dt_safety": dt_safety,
        "residual_load_N": float(force[-1]), "peak_load_N": float(force.max()),
        "lower_load_N": float(np.asarray(history["plate_force"])[-1, 0]),
        "wall_load_N": float(np.abs(np.asarray(history["wall_force"])[-1]).sum()),
        "pile_top_m": float(tops[-1]), "volume_fraction_reached": float(area / (plan.width_m * tops[-1])),
        "kinetic_energy_end_J": float(history["energy/kinetic"][-1]),
        "strain_energy_end_J": float(history["energy/strain"][-1]),
    }
    if tops[-1] > plan.target_m + close_cfg.tolerance:
        densest = float(area / (plan.width_m * tops.min()))
        target_vf = float(area / (plan.width_m * plan.target_m))
        raise ConfigError(f"specimen.volume_fraction = {target_vf:.4g}: closing the cassette does not reach it (the "
                          f"pile's top stays {(tops[-1] - plan.target_m) * 1e6:.3g} um above the plate, more than "
                          f"specimen.close.tolerance; the densest it reached is v_f0 = {densest:.4g}): lower the target",
                          where=where)
    closed = Polylines.from_list([X[-1][off[i]:off[i + 1]] for i in range(len(off) - 1)], radius)
    return closed, out


CLOSING_RETRY_STEP_FACTOR = 0.5  # the step of a closing run again after it diverged, × its own


def _run_closing(scene_raw: dict, fibers: Polylines, where: str, progress=None):
    """:func:`_run_scene` of the closing; run once more at half the step (``solver.dt_safety`` × 0.5)
    when it diverges. A stiffening law (the study's Table 1 presets: the slope × S per d of
    penetration) can outgrow the step where the closing load presses fibers deepest, at its peak;
    the same pile closes at a smaller step. Returns ``_run_scene``'s tuple and the dt_safety used."""
    from fiberpipe.config import SolverConfig
    from fiberpipe.errors import SimulationDiverged

    dt_safety = float((scene_raw.get("solver") or {}).get("dt_safety", SolverConfig().dt_safety))
    try:
        return (*_run_scene(copy.deepcopy(scene_raw), fibers, where, progress), dt_safety)
    except SimulationDiverged:
        retry = copy.deepcopy(scene_raw)
        retry.setdefault("solver", {})["dt_safety"] = dt_safety * CLOSING_RETRY_STEP_FACTOR
        return (*_run_scene(retry, fibers, where, progress), dt_safety * CLOSING_RETRY_STEP_FACTOR)


def _run_scene(scene_raw: dict, fibers: Polylines, where: str, progress=None):
    """Validate a settling or closing scene, mesh ``fibers`` and run it: (config, mesh, result,
    solver wall time in s)."""
    import time as _time

    from fiberpipe.config import validate_config
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.solver import simulate
    from fiberpipe.solver.build import build_simulation

    scene_raw["input"] = {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]}  # the fibers are given directly
    cfg = validate_config(scene_raw, where=where)
    mesh = mesh_polylines(fibers, float(cfg.mesh.element_length), radius_m=float(cfg.fiber.radius))
    model, effects, settings = build_simulation(mesh, cfg)
    t0 = _time.perf_counter()
    result = simulate(model, effects, settings, progress=progress)
    return cfg, mesh, result, _time.perf_counter() - t0
