"""Explicit dynamics of fiber bundles: geometrically exact 3D beams, central difference, effects.

Model (static) / State (dynamic) / Integrator (step loop) split; see docs/solver.md.
"""

from . import _jitcache  # noqa: F401  (first: cache freshness of every solver kernel)
from .. import _vectorise  # noqa: F401  (before any kernel compiles: the vectoriser's limits and width)
from .effects import (Clamp, Clamps, ContactHook, Damping, Drive, Drives, Gravity, LineLoad, Loads,
                      Plates, PointLoad, Walls)
from .integrator import (ENERGY_NAMES, Integrator, SimulationResult, SimulationSettings, advance,
                         choose_time_step)
from .simulate import simulate  # the module fiberpipe.solver.simulate re-exports the run API
from .model import Material, Model, build_model, model_from_mesh
from .state import State
from .timestep import TimeStepReport, stable_time_step

__all__ = [
    "Clamp", "Clamps", "ContactHook", "Damping", "Drive", "Drives", "Gravity", "LineLoad", "Loads",
    "Plates", "PointLoad", "Walls", "ENERGY_NAMES", "Integrator", "SimulationResult",
    "SimulationSettings", "advance", "choose_time_step", "simulate", "Material", "Model",
    "build_model", "model_from_mesh", "State", "TimeStepReport", "stable_time_step",
]
