"""Explicit dynamics of fiber bundles: geometrically exact 3D beams, central difference, physical terms.

Model (static) / State (dynamic) / Integrator (step loop) split; see docs/solver.md.
"""

from . import _jitcache  # noqa: F401  (first: cache freshness of every solver kernel)
from .. import _vectorise  # noqa: F401  (before any kernel compiles: the vectoriser's limits and width)
from .integrator import (ENERGY_NAMES, Integrator, SimulationResult, SimulationSettings, advance,
                         choose_time_step, simulate)
from .model import Material, Model, build_model, model_from_mesh
from .state import State
from .terms import (TERMS, Clamp, Clamps, ContactHook, Damping, Drive, Drives, Gravity, LineLoad, Loads, Plates,
                    PointLoad, Term, Walls, register_term)
from .timestep import TimeStepReport, stable_time_step

__all__ = [
    "TERMS", "Term", "register_term", "Clamp", "Clamps", "ContactHook", "Damping", "Drive", "Drives", "Gravity", "LineLoad", "Loads",
    "Plates", "PointLoad", "Walls", "ENERGY_NAMES", "Integrator", "SimulationResult",
    "SimulationSettings", "advance", "choose_time_step", "simulate", "Material", "Model",
    "build_model", "model_from_mesh", "State", "TimeStepReport", "stable_time_step",
]
