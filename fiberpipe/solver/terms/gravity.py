"""Gravity: a uniform acceleration of the physical lumped masses, folded into the constant loads."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from .base import Term, _vec3, register_term


@register_term()
@dataclass
class Gravity(Term):
    """Uniform gravity on the physical lumped mass: f_i = m_i g.

    Parameters
    ----------
    acceleration_m_s2 : (3,) m/s², e.g. (0, 0, −9.81).
    """

    acceleration_m_s2: Sequence[float] = (0.0, 0.0, -9.81)
    name = "gravity"

    def __post_init__(self):
        self.acceleration_m_s2 = _vec3(self.acceleration_m_s2, "gravity.acceleration")

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        return cls(list(scene_cfg.gravity.acceleration))

    def setup(self, model, scene):
        scene.ext()[:] += (model.mass / model.mass_scale)[:, None] * self.acceleration_m_s2[None, :]
