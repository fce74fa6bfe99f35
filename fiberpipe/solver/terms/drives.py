"""Prescribed rigid motions of whole fibers: the drive table the step loop reads and the driven
nodes' fixity bits."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ...errors import FiberpipeError
from ..layout import DRIVEN
from .base import Term, _check_fiber, _ramp_code, _vec3, register_term


@dataclass
class Drive:
    """A fiber moved rigidly (all nodes' translations prescribed, rotations fixed) by
    ``displacement_m`` (3,) at mean speed ``velocity_m_s`` with the given ramp."""

    fiber: int
    displacement_m: Sequence[float]
    velocity_m_s: float
    ramp: str = "smooth"
    ramp_fraction: float = 0.1


@register_term()
@dataclass
class Drives(Term):
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
    def from_config(cls, scene_cfg, model, cfg):
        return cls([Drive(d.fiber, list(d.displacement), float(d.velocity)) for d in scene_cfg.drives])

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
