"""Small scenes and CLI helpers shared by the tests (a module, not a test file: pytest does not collect it)."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml
from click.testing import CliRunner

from fiberpipe.cli import main

# four straight fibers 3 mm long in a 0.8 mm wide box, pressed by 0.015 mm along z: plates, walls,
# gravity, mass- and stiffness-proportional damping; seconds to run, checkpoints every 5000 steps
SMALL_SCENE = {
    "name": "small",
    "input": {"polylines": [
        [[0, 0, 0], ["3 mm", 0, 0]],
        [[0, 0, "0.5 mm"], ["3 mm", "0.05 mm", "0.5 mm"]],
        [[0, "0.05 mm", "1 mm"], ["3 mm", 0, "1 mm"]],
        [[0, 0, "1.5 mm"], ["3 mm", 0, "1.5 mm"]],
    ]},
    "fiber": {"radius": "0.25 mm"},
    "mesh": {"element_length": "0.3 mm"},
    "material": {"youngs_modulus": "15 GPa", "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
    "scene": {
        "effects": ["gravity", "damping", "plates", "walls"],
        "gravity": {"acceleration": [0, 0, "-9.81 m/s^2"]},
        "damping": {"alpha": "1e4 1/s", "beta": "1e-9 s"},
        "plates": {"axis": "z", "lower": "moving", "upper": "fixed"},
        "walls": {"y": ["-0.4 mm", "0.4 mm"]},
        "loading": {"displacement": "0.015 mm", "velocity": "60 mm/min", "ramp": "smooth"},
    },
    "solver": {"output_frames": 6, "checkpoint_every": 5000},
    "post": {"plots": False},
}


def small_scene(**scene) -> dict:
    """A deep copy of SMALL_SCENE with the given ``scene`` keys replaced."""
    cfg = copy.deepcopy(SMALL_SCENE)
    cfg["scene"].update(copy.deepcopy(scene))
    return cfg


def write_cfg(path: Path, cfg: dict) -> Path:
    """Write a config dict as YAML; returns the path."""
    path.write_text(yaml.safe_dump(cfg))
    return path


def cli(*args):
    """``fiberpipe ARGS...`` in process (click's runner); paths may be Path objects."""
    return CliRunner().invoke(main, [str(a) for a in args])


def run_small(d: Path, cfg: dict, to: str = "simulate") -> tuple[Path, Path]:
    """``fiberpipe run`` of ``cfg`` (written to ``d/small.yaml``) into ``d/run`` up to stage ``to``;
    asserts it succeeded; returns (config path, run folder)."""
    path = write_cfg(d / "small.yaml", cfg)
    r = cli("run", path, "--out", d / "run", "--to", to)
    assert r.exit_code == 0, r.output
    return path, d / "run"


def _bow(y0_mm: float, sagitta_mm: float, angle_deg: float, length_mm: float = 3.0) -> list:
    """A fiber bowed in the xz plane (z = s sin(πx/L)), along x turned by ``angle_deg`` about z."""
    import numpy as np

    x = np.linspace(0.0, length_mm, 11)
    y = y0_mm + (x - length_mm / 2) * np.tan(np.deg2rad(angle_deg))
    z = sagitta_mm * np.sin(np.pi * x / length_mm)
    return [[f"{a:.6f} mm", f"{b:.6f} mm", f"{c:.6f} mm"] for a, b, c in zip(x, y, z)]


# three bowed fibers 3 mm long (sagittas 0.08–0.12 mm, the middle one turned by 4°, so it touches its
# neighbours) flattened between plates with friction on a load–unload–reload path; ~10 s to run
CYCLE_SCENE = {
    "name": "cycle",
    "input": {"polylines": [_bow(0.0, 0.10, 0.0), _bow(0.52, 0.08, 4.0), _bow(1.04, 0.12, 0.0)]},
    "fiber": {"radius": "0.25 mm"},
    "mesh": {"element_length": "0.3 mm"},
    "material": {"youngs_modulus": "15 GPa", "poisson_ratio": 0.3, "density": "1380 kg/m^3"},
    "scene": {
        "effects": ["damping", "contact", "friction", "plates", "walls"],
        "damping": {"alpha": "1e4 1/s"},
        "friction": {"mu": 0.3},
        "plates": {"axis": "z", "lower": "moving", "upper": "fixed"},
        "walls": {"y": ["-0.4 mm", "1.45 mm"]},
        "loading": {"path": ["0.06 mm", "0.02 mm", "0.08 mm"], "hold": "0.2 ms", "velocity": "1200 mm/min"},
    },
    "solver": {"output_frames": 4},
}
