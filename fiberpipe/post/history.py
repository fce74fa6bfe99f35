"""Read a ``simulation`` artifact into plain arrays for post-processing."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_artifact
from fiberpipe.model.mesh import Mesh


@dataclass
class SimulationData:
    """What post-processing needs from ``simulation.h5`` (all SI)."""

    path: Path
    attrs: dict
    mesh: Mesh
    frames_time: np.ndarray  # (K,) s
    frames_positions: np.ndarray  # (K, N, 3) m
    history: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T, ...) arrays
    energy: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T,) J
    frame_fields: dict[str, np.ndarray] = field(default_factory=dict)  # e.g. contact_force (K, N, 3) N

    @property
    def effects(self) -> list[str]:
        e = self.attrs.get("effects", "[]")
        return json.loads(e) if isinstance(e, str) else list(e)


def load_simulation(path: str | Path) -> SimulationData:
    art = read_artifact(path, "simulation")
    mesh = Mesh(art["mesh/nodes"], art["mesh/node_offsets"], art["mesh/radius"])
    history, energy, fields = {}, {}, {}
    for name, arr in art.data.items():
        if name.startswith("frames/") and name not in ("frames/time", "frames/positions"):
            fields[name[len("frames/") :]] = arr
        if name.startswith("history/energy/"):
            energy[name[len("history/energy/") :]] = arr
        elif name.startswith("history/"):
            history[name[len("history/") :]] = arr
    return SimulationData(
        path=Path(path),
        attrs=art.attrs,
        mesh=mesh,
        frames_time=art["frames/time"],
        frames_positions=art["frames/positions"],
        history=history,
        energy=energy,
        frame_fields=fields,
    )
