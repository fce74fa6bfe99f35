"""Run API entry point: ``from fiberpipe.solver.simulate import simulate``.

Re-exports :func:`fiberpipe.solver.integrator.simulate` and its types.
"""

from .integrator import SimulationResult, SimulationSettings, advance, choose_time_step, simulate

__all__ = ["simulate", "SimulationResult", "SimulationSettings", "advance", "choose_time_step"]
