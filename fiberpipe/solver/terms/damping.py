"""Rayleigh material damping, folded into the node update (mass-proportional) and the beam pass
(stiffness-proportional)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import FiberpipeError
from .base import Term, register_term


@register_term()
@dataclass
class Damping(Term):
    """Rayleigh material damping as Abaqus/Explicit applies it.

    Mass-proportional: force ``−α m v`` and moment ``−α J Ω`` (``alpha_per_s``, 1/s; the study
    uses 1e5). Stiffness-proportional: an extra stress ``β C Γ̇`` and moment ``β D κ̇``
    (``beta_s``, s; lowers the stable step by (√(1+ξ²) − ξ), ξ = βω_max/2). The dissipated
    energy is ALLVD.

    The mass-proportional force acts on the absolute velocity of every node, prescribed ones
    included (Abaqus: as if the model moved through a viscous fluid): a fiber translated rigidly
    at speed v by a :class:`Drive` dissipates ``α m v²`` per unit time (ALLVD), which the drive's
    reaction supplies (ALLWK).
    """

    alpha_per_s: float = 0.0
    beta_s: float = 0.0
    name = "damping"

    def __post_init__(self):
        for k in ("alpha_per_s", "beta_s"):
            val = float(getattr(self, k))
            if not (val >= 0.0 and math.isfinite(val)):
                raise FiberpipeError(f"damping.{k.split('_')[0]} must be ≥ 0, got {val}")
            setattr(self, k, val)

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        return cls(float(scene_cfg.damping.alpha), float(scene_cfg.damping.beta))

    def setup(self, model, scene):
        scene.alpha = self.alpha_per_s
        scene.beta = self.beta_s
