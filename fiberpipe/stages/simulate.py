"""Stage ``simulate``: ``mesh.h5`` + scene -> ``simulation.h5``, ``frames/*.vtu``, ``simulation.pvd``.

Layout of ``simulation.h5`` (SPEC section 4): ``/frames/time`` (K,), ``/frames/positions``
(K, N, 3) in mesh node order, ``/history/time`` (T,), ``/history/plate_displacement`` (T, 2),
``/history/plate_force`` (T, 2), ``/history/wall_force`` (T, W), ``/history/energy/<name>`` (T,),
plus whatever else the solver records under ``/history``; the mesh itself under ``/mesh``;
root attributes ``dt_s``, ``steps``, ``elements``, ``wall_time_s``, ``effects`` (JSON list).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_mesh, write_artifact
from fiberpipe.config import Config
from fiberpipe.errors import SimulationDiverged
from fiberpipe.io.vtk import mesh_vtu, write_pvd
from fiberpipe.stages._common import input_hashes

log = logging.getLogger(__name__)

#: Units of the history series the solver may record (anything else is stored as given).
HISTORY_UNITS = {
    "time": "s",
    "plate_displacement": "m",
    "plate_force": "N",
    "wall_force": "N",
    "plate_position": "m",
    "contacts": "",
}


def write_simulation(path: Path, mesh, result, *, config_sha256: str = "", inputs=None, extra_attrs=None) -> Path:
    """Write a :class:`SimulationResult` (complete or partial) as a ``simulation`` artifact."""
    datasets = {
        "frames/time": np.asarray(result.frames_time, dtype=np.float64),
        "frames/positions": np.asarray(result.frames_positions, dtype=np.float64),
        "mesh/nodes": mesh.nodes_m,
        "mesh/node_offsets": mesh.node_offsets,
        "mesh/radius": mesh.radius_m,
    }
    units = {"frames/time": "s", "frames/positions": "m", "mesh/nodes": "m", "mesh/radius": "m"}
    for name, series in result.history.items():
        if isinstance(series, dict):  # e.g. energy/<name>
            for sub, arr in series.items():
                datasets[f"history/{name}/{sub}"] = np.asarray(arr)
                units[f"history/{name}/{sub}"] = "J" if name == "energy" else ""
        else:
            key = f"history/{name}"
            datasets[key] = np.asarray(series)
            units[key] = "J" if name.startswith("energy/") else HISTORY_UNITS.get(name, "")
    for name, arr in (getattr(result, "fields", None) or {}).items():
        datasets[f"frames/{name}"] = np.asarray(arr)
    attrs = {
        "dt_s": float(result.dt_s),
        "steps": int(result.steps),
        "elements": int(mesh.n_elements),
        "wall_time_s": float(result.wall_time_s),
        "effects": list(result.effects),
    }
    attrs.update(extra_attrs or {})
    return write_artifact(path, "simulation", datasets, units=units, attrs=attrs, config_sha256=config_sha256, inputs=inputs)


def write_frames_vtk(out_dir: Path, mesh, frames_time, frames_positions, *, stem: str = "simulation") -> Path:
    """One VTU per frame in ``out_dir/frames/`` plus ``out_dir/<stem>.pvd`` for ParaView."""
    frames_dir = out_dir / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    entries = []
    for k, (t, pos) in enumerate(zip(frames_time, frames_positions)):
        name = f"frame_{k:05d}.vtu"
        disp = pos - mesh.nodes_m
        mesh_vtu(frames_dir / name, mesh, points_m=pos, point_data={"displacement": disp})
        entries.append((float(t), f"frames/{name}"))
    return write_pvd(out_dir / f"{stem}.pvd", entries)


def run_simulate(cfg: Config, mesh_path: Path, out: Path, *, config_sha256: str = "") -> dict:
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.simulate import simulate

    mesh = read_mesh(mesh_path)
    out = Path(out)
    inputs = input_hashes({"mesh": Path(mesh_path)})
    model, effects, settings = build_simulation(mesh, cfg)
    try:
        result = simulate(model, effects, settings, progress=_progress_callback())
    except SimulationDiverged as exc:
        partial = getattr(exc, "partial_result", None)
        if partial is not None and len(partial.frames_time):
            keep = out.with_name("simulation_diverged.h5")
            write_simulation(keep, mesh, partial, config_sha256=config_sha256, inputs=inputs, extra_attrs={"diverged": str(exc)})
            raise SimulationDiverged(f"{exc} (last good frames kept in {keep})") from None
        raise
    write_simulation(out, mesh, result, config_sha256=config_sha256, inputs=inputs)
    write_frames_vtk(out.parent, mesh, result.frames_time, result.frames_positions)
    steps = int(result.steps)
    figures = {
        "dt_s": float(result.dt_s),
        "steps": steps,
        "elements": int(mesh.n_elements),
        "solver_wall_time_s": float(result.wall_time_s),
        "element_steps_per_s": float(steps * mesh.n_elements / max(result.wall_time_s, 1e-12)),
        "effects": list(result.effects),
        "frames": int(len(result.frames_time)),
    }
    hist = result.history
    if "plate_force" in hist and len(hist["plate_force"]):
        figures["final_plate_force_N"] = [float(v) for v in np.asarray(hist["plate_force"])[-1]]
    return figures


def _progress_callback():
    """A rich progress bar on a terminal, nothing otherwise (CI, logs)."""
    import sys

    if not sys.stderr.isatty():
        return None
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    state = {}

    def callback(done_steps: int, total_steps: int):
        if "bar" not in state:
            bar = Progress(TextColumn("simulate"), BarColumn(), TextColumn("{task.percentage:>5.1f}%"), TimeRemainingColumn(), transient=True)
            bar.start()
            state["bar"] = bar
            state["task"] = bar.add_task("simulate", total=total_steps)
        state["bar"].update(state["task"], completed=done_steps)
        if done_steps >= total_steps:
            state["bar"].stop()

    return callback
