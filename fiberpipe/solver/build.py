"""Map a validated config (``fiberpipe.config.Config``, SI floats) and a mesh to (model, effects, settings).

Config sections used (docs/config.md): ``material`` (youngs_modulus, poisson_ratio | shear_modulus,
density), ``fiber.radius`` (overrides the mesh's per-fiber radius), ``scene`` (effects + blocks),
``solver`` (dt_safety, dt, end_time, output_frames, history_every, rotational_inertia_scaling,
mass_scaling). Only the effects listed in ``scene.effects`` are built.
"""

from __future__ import annotations

from .integrator import SimulationSettings
from .model import Material, Model, build_model
from .terms import TERMS, Clamps, Drives, Loads, SceneArrays, Term
from .terms.planes import check_scene_geometry


def material_from_config(cfg) -> Material:
    m = cfg.material
    if m.shear_modulus is not None:
        return Material(float(m.youngs_modulus), float(m.density), None, float(m.shear_modulus))
    return Material(float(m.youngs_modulus), float(m.density), float(m.poisson_ratio_value))


def build_simulation(mesh, cfg) -> tuple[Model, list[Term], SimulationSettings]:
    """Build the beam model, the scene's effects and the solver settings.

    Parameters
    ----------
    mesh : object with ``nodes_m`` (N,3) m, ``node_offsets`` (F+1,), ``radius_m`` (F,) m
        (``fiberpipe.model.mesh.Mesh``).
    cfg : fiberpipe.config.Config (validated, SI).

    Returns
    -------
    (Model, list of Term, SimulationSettings)
    """
    material = material_from_config(cfg)
    radius = cfg.fiber.radius if getattr(cfg.fiber, "radius", None) is not None else mesh.radius_m
    solver = cfg.solver
    model = build_model(mesh.nodes_m, mesh.node_offsets, radius, material,
                        rotary_inertia_scale=float(getattr(solver, "rotational_inertia_scaling", 1.0) or 1.0),
                        mass_scale=float(getattr(solver, "mass_scaling", 1.0) or 1.0))
    terms = terms_from_config(cfg.scene, model, cfg)
    for term in terms:
        if isinstance(term, (Clamps, Loads, Drives)):
            term.setup(model, SceneArrays(model, 1.0))  # checks fiber/node indices now, with a clear error
    check_scene_geometry(model, terms)
    settings = SimulationSettings(
        dt_safety=float(solver.dt_safety), dt_s=getattr(solver, "dt", None), end_time_s=solver.end_time,
        force_dt=bool(getattr(solver, "force_dt", False)),
        output_frames=int(solver.output_frames), history_every=getattr(solver, "history_every", None),
        checkpoint_every=getattr(solver, "checkpoint_every", None),
        threads=int(getattr(solver, "threads", 1) or 1),
        stable_step=str(getattr(solver, "stable_step", "element")),
    )
    return model, terms, settings


def terms_from_config(scene_cfg, model: Model, cfg) -> list[Term]:
    """The terms ``scene.effects`` lists, each from its class's ``from_config`` (``TERMS``); entries
    sharing one class (contact and friction) give one term, and an entry whose ``from_config``
    returns None gives none (``friction`` without ``contact``: the plates and walls carry it). The
    per-step terms come last, in the order listed."""
    folded: list[Term] = []
    per_step: list[Term] = []
    built = set()
    for name in scene_cfg.effects:
        cls = TERMS[name]
        if cls in built:
            continue
        built.add(cls)
        term = cls.from_config(scene_cfg, model, cfg)
        if term is None:
            continue
        (per_step if term.kernels() is not None else folded).append(term)
    return folded + per_step
