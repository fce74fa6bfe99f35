"""Dynamic state of a beam model (changes every step)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .layout import ACC_SIZE
from .model import Model


@dataclass
class State:
    """Positions, rotations and velocities of all nodes at one instant.

    Attributes (N nodes)
    ----------
    x : (N, 3) float64, m — node positions at t.
    q : (N, 4) float64 — node rotations as unit quaternions (w, x, y, z), material frame to space.
    v : (N, 3) float64, m/s — translational velocities at t − Δt/2 (leapfrog half step).
    w : (N, 3) float64, rad/s — body-frame angular velocities at t − Δt/2.
    t : float, s.  step : int.
    acc : (layout.ACC_SIZE,) float64 — the step loop's accumulators (``layout.ACC_*``: prescribed
        work, damping dissipation, contact penalty work, friction dissipation and work [J]...).
    """

    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    w: np.ndarray
    t: float = 0.0
    step: int = 0
    acc: np.ndarray = field(default_factory=lambda: np.zeros(ACC_SIZE))

    @classmethod
    def at_rest(cls, model: Model) -> "State":
        """The model's rest configuration with zero velocities at t = 0."""
        n = model.n_nodes
        return cls(model.nodes_m.copy(), model.quats0.copy(), np.zeros((n, 3)), np.zeros((n, 3)))

    def copy(self) -> "State":
        return State(self.x.copy(), self.q.copy(), self.v.copy(), self.w.copy(), self.t, self.step, self.acc.copy())
