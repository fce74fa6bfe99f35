"""Fixed degrees of freedom: clamped nodes and the axial lock, folded into the node update as
fixity bits (``layout.FIX_*``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ...errors import FiberpipeError
from ..layout import FIX_ROT, FIX_X, FIX_Y, FIX_Z
from .base import _AXES, Term, _node_of, register_term


@dataclass
class Clamp:
    """One clamped node: ``fiber`` index, ``at`` = "start" | "end" | local node index;
    ``dofs`` = "all" (6 DOF fixed) or a subset of "xyz" (translations only, rotations free: a pin
    along those axes)."""

    fiber: int
    at: object = "start"
    dofs: str = "all"


@register_term()
@dataclass
class Clamps(Term):
    """Nodes with all (or chosen translational) DOF fixed at their initial values."""

    clamps: Sequence[Clamp] = field(default_factory=list)
    name = "clamps"

    def __post_init__(self):
        out = []
        for c in self.clamps:
            if isinstance(c, dict):
                c = Clamp(**c)
            if c.dofs != "all" and (not c.dofs or set(c.dofs) - set("xyz")):
                raise FiberpipeError(f"clamp dofs must be 'all' or letters of 'xyz', got {c.dofs!r}")
            out.append(c)
        self.clamps = out

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        return cls([Clamp(c.fiber, c.at) for c in scene_cfg.clamps])

    def setup(self, model, scene):
        m = scene.mask()
        for k, c in enumerate(self.clamps):
            i = _node_of(model, f"scene.clamps[{k}]", c.fiber, c.at)
            if c.dofs == "all":
                m[i] |= FIX_X | FIX_Y | FIX_Z | FIX_ROT
            else:
                for ch in c.dofs:
                    m[i] |= {"x": FIX_X, "y": FIX_Y, "z": FIX_Z}[ch]


@register_term('constraints')
@dataclass
class AxialLock(Term):
    """The study's boundary condition, "the movement is locked in the fiber orientation": the
    translation along ``axis`` of every node (``nodes="all"``) or of each fiber's first and last
    node (``"ends"``) is fixed at its initial value; rotations and the other translations are free."""

    axis: str = "z"
    nodes: str = "all"
    name = "constraints"

    def __post_init__(self):
        if self.axis not in _AXES:
            raise FiberpipeError(f"constraints axis must be x, y or z, got {self.axis!r}")
        if self.nodes not in ("all", "ends"):
            raise FiberpipeError(f"constraints lock_axial must be all or ends, got {self.nodes!r}")

    @classmethod
    def from_config(cls, scene_cfg, model, cfg):
        return cls(axis=scene_cfg.constraints.axis, nodes=scene_cfg.constraints.lock_axial)

    def setup(self, model, scene):
        m = scene.mask()
        bit = {"x": FIX_X, "y": FIX_Y, "z": FIX_Z}[self.axis]
        if self.nodes == "all":
            m |= np.uint8(bit)
        else:
            off = np.asarray(model.node_offsets, dtype=np.int64)
            m[off[:-1]] |= np.uint8(bit)
            m[off[1:] - 1] |= np.uint8(bit)

    def describe(self) -> str:
        return f"constraints: {self.axis} translation of {self.nodes} nodes fixed"
