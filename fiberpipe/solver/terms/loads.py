"""Constant point and line loads, folded into the constant loads the node update resets the forces to."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ...errors import FiberpipeError
from .base import Term, _check_fiber, _node_of, _vec3, register_term


@dataclass
class PointLoad:
    """A constant force (N) on one node of a fiber (``at`` = start | end | node index)."""

    fiber: int
    force_n: Sequence[float]
    at: object = "end"


@dataclass
class LineLoad:
    """A constant force per unit length (N/m) along a whole fiber, lumped to its nodes
    (each node gets half the rest length of each adjacent element)."""

    fiber: int
    force_n_per_m: Sequence[float]


@register_term()
@dataclass
class Loads(Term):
    """Constant point and line forces (applied from t = 0; quasi-static cases add damping)."""

    loads: Sequence[object] = field(default_factory=list)
    name = "loads"

    def __post_init__(self):
        out = []
        for ld in self.loads:
            if isinstance(ld, dict):
                ld = dict(ld)
                if "line_force" in ld:
                    ld = LineLoad(ld["fiber"], ld["line_force"])
                else:
                    ld = PointLoad(ld["fiber"], ld["force"], ld.get("at", "end"))
            if isinstance(ld, PointLoad):
                ld.force_n = _vec3(ld.force_n, "loads.force")
            elif isinstance(ld, LineLoad):
                ld.force_n_per_m = _vec3(ld.force_n_per_m, "loads.line_force")
            else:
                raise FiberpipeError(f"unknown load {ld!r}")
            out.append(ld)
        self.loads = out

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        return cls([LineLoad(ld.fiber, list(ld.line_force)) if ld.line_force is not None
                    else PointLoad(ld.fiber, list(ld.force), ld.at) for ld in scene_cfg.loads])

    def setup(self, model, scene):
        f = scene.ext()
        for k, ld in enumerate(self.loads):
            if isinstance(ld, PointLoad):
                f[_node_of(model, f"scene.loads[{k}]", ld.fiber, ld.at)] += ld.force_n
            else:
                _check_fiber(model, f"scene.loads[{k}]", ld.fiber)
                sel = model.el_fiber == ld.fiber
                n1 = model.el_n1[sel]
                half = 0.5 * model.el_L0[sel]
                for k in (0, 1):
                    np.add.at(f, n1 + k, half[:, None] * ld.force_n_per_m[None, :])
