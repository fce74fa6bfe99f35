"""The scenes the benchmarks run, built through the package's public paths: a run config's scene
(``configs/paper-40.yaml`` by default; its mesh built in memory), a saved state of it, and the
contact a run config's ``scene.effects: [contact, friction]`` gets with the schema's defaults.

The scripts of the source checkout's ``benchmarks/`` folder (profiles, A/B runs) start from these
too: a state saved by ``benchmarks/paper40_states.py`` loads here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def scene(overrides: dict | None = None, config: Path | None = None):
    """``(model, effects, settings, dt)`` of the run config ``config`` (None: paper-40), its mesh
    built in memory and the planes placed as ``fiberpipe run`` places them."""
    from ..bench import config_mesh, default_paper40_config
    from ..config import load_config
    from ..solver.build import build_simulation
    from ..solver.integrator import choose_time_step
    from ..stages.simulate import clear_scene_planes

    cfg = load_config(config or default_paper40_config(), overrides or {})
    mesh = config_mesh(cfg)
    clear_scene_planes(mesh, cfg)
    model, effects, settings = build_simulation(mesh, cfg)
    dt, _ = choose_time_step(model, effects, settings)
    return model, effects, settings, dt


def scene_and_state(state: str | Path | None = None, config: str | Path | None = None):
    """``(model, effects, dt, state)``: the scene of the run config ``config`` (None: paper-40) from
    the state saved at ``state`` (:func:`save_state`; None: from rest). A state of another node count
    than the scene's stops with a one-line error."""
    from ..solver import State

    model, effects, _, dt = scene(config=Path(config) if config is not None else None)
    if state is None:
        return model, effects, dt, State.at_rest(model)
    saved = load_state(state)
    if saved.x.shape[0] != model.n_nodes:
        raise SystemExit(f"error: {state}: a state of {saved.x.shape[0]} nodes, the scene has {model.n_nodes} "
                         "(give the state's config)")
    return model, effects, dt, saved


def save_state(path, state) -> None:
    """The state's motion (x, q, v, w), energy accumulators, time and step as one ``.npz`` file."""
    np.savez(path, x=state.x, q=state.q, v=state.v, w=state.w, acc=state.acc, t=state.t, step=state.step)


def load_state(path):
    """A saved state; its energy accumulators fitted to this version's ``layout.ACC_SIZE`` (a state saved
    by a version with fewer slots gets zeros in the new ones: the profiles need its motion only)."""
    from ..solver.layout import ACC_SIZE
    from ..solver.state import State

    saved = np.load(path)
    acc = np.zeros(ACC_SIZE)
    n = min(ACC_SIZE, saved["acc"].size)
    acc[:n] = saved["acc"][:n]
    return State(saved["x"].copy(), saved["q"].copy(), saved["v"].copy(), saved["w"].copy(), float(saved["t"]),
                 int(saved["step"]), acc)


def default_contact(model, friction: bool = False):
    """The effect a run config's ``scene.effects: [contact]`` (``[contact, friction]`` with
    ``friction``) builds for ``model``, every other key at the config schema's default (the law
    ``hertz_oriented`` for the model's material, μ = 0.2)."""
    from ..config import validate_config
    from ..solver.terms import TERMS

    material = model.material
    cfg = validate_config({
        "input": {"fibers": "unused.h5"},  # the scene's model is given: no mesh is read
        "material": {"youngs_modulus": float(material.youngs_modulus_pa), "density": float(material.density_kg_m3),
                     "poisson_ratio": float(material.nu)},
        "scene": {"effects": ["contact", "friction"] if friction else ["contact"]},
    })
    return TERMS["contact"].from_config(cfg.scene, model, cfg)
