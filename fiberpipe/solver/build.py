"""Map a validated config (``fiberpipe.config.Config``, SI floats) and a mesh to (model, effects, settings).

Config sections used (docs/config.md): ``material`` (youngs_modulus, poisson_ratio | shear_modulus,
density), ``fiber.radius`` (overrides the mesh's per-fiber radius), ``scene`` (effects + blocks),
``solver`` (dt_safety, dt, end_time, output_frames, history_every, rotational_inertia_scaling,
mass_scaling). Only the effects listed in ``scene.effects`` are built.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import FiberpipeError
from ..model.mesh import plane_penetration
from . import contact_effect  # noqa: F401  (registers the contact and friction effect)
from .effects import EFFECTS, Clamps, ContactHook, Drives, Effect, Loads, Plates, SceneArrays, Walls
from .integrator import SimulationSettings
from .model import Material, Model, build_model

log = logging.getLogger(__name__)

#: an initial penetration of a plate or wall deeper than this fraction of the fiber radius is an error
#: (deeper than 1 % a warning)
CUT_TOLERANCE = 0.25


def _mm(v: float) -> str:
    return f"{v * 1e3:.4g} mm"


def check_scene_geometry(model: Model, effects) -> list[str]:
    """Plates and walls against the bundle, before anything runs.

    Errors (``FiberpipeError`` naming the key): a plate or wall that cuts through the bundle (a node
    more than ``CUT_TOLERANCE`` radii past it: the penalty would blow the fibers apart at t = 0);
    plates that never touch the fibers (their gaps to the bundle add up to more than their travel).
    Returns warnings (also logged): a plate that starts away from the bundle, a slight overlap.
    """
    warnings: list[str] = []
    x, r = model.nodes_m, model.radius_node
    axes = {"x": 0, "y": 1, "z": 2}

    def cut(key: str, ax: int, pos: float, low_side: bool) -> None:
        depth = plane_penetration(x, r, ax, pos, 1.0 if low_side else -1.0)
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

    for e in effects:
        if isinstance(e, Walls):
            for axn, (lo, hi) in e.planes.items():
                cut(f"scene.walls.{axn}", axes[axn], lo, True)
                cut(f"scene.walls.{axn}", axes[axn], hi, False)
        elif isinstance(e, Plates):
            ax = axes[e.axis]
            lo_b, hi_b = float(np.min(x[:, ax] - r)), float(np.max(x[:, ax] + r))
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
                cut(key, ax, float(pos), low_side)
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


def material_from_config(cfg) -> Material:
    m = cfg.material
    if m.shear_modulus is not None:
        return Material(float(m.youngs_modulus), float(m.density), None, float(m.shear_modulus))
    return Material(float(m.youngs_modulus), float(m.density), float(m.poisson_ratio_value))


def build_simulation(mesh, cfg) -> tuple[Model, list[Effect], SimulationSettings]:
    """Build the beam model, the scene's effects and the solver settings.

    Parameters
    ----------
    mesh : object with ``nodes_m`` (N,3) m, ``node_offsets`` (F+1,), ``radius_m`` (F,) m
        (``fiberpipe.model.mesh.Mesh``).
    cfg : fiberpipe.config.Config (validated, SI).

    Returns
    -------
    (Model, list of Effect, SimulationSettings)
    """
    mat = material_from_config(cfg)
    radius = cfg.fiber.radius if getattr(cfg.fiber, "radius", None) is not None else mesh.radius_m
    s = cfg.solver
    model = build_model(mesh.nodes_m, mesh.node_offsets, radius, mat,
                        rotary_inertia_scale=float(getattr(s, "rotational_inertia_scaling", 1.0) or 1.0),
                        mass_scale=float(getattr(s, "mass_scaling", 1.0) or 1.0))
    sc = cfg.scene
    effects: list[Effect] = []
    hooks: list[Effect] = []
    built = set()
    for name in sc.effects:
        cls = EFFECTS[name]
        if cls in built:  # contact and friction share one hook
            continue
        built.add(cls)
        e = cls.from_config(sc, model, cfg)
        # the contact hook sets up last: it reads the planes the other effects define
        (hooks if isinstance(e, ContactHook) else effects).append(e)
    effects += hooks
    for e in effects:
        if isinstance(e, (Clamps, Loads, Drives)):
            e.setup(model, SceneArrays(model, 1.0))  # checks fiber/node indices now, with a clear error
    check_scene_geometry(model, effects)
    settings = SimulationSettings(
        dt_safety=float(s.dt_safety), dt_s=getattr(s, "dt", None), end_time_s=s.end_time,
        output_frames=int(s.output_frames), history_every=getattr(s, "history_every", None),
        checkpoint_every=getattr(s, "checkpoint_every", None),
        threads=int(getattr(s, "threads", 1) or 1),
        stable_step=str(getattr(s, "stable_step", "element")),
    )
    return model, effects, settings
