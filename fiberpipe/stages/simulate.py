"""Stage ``simulate``: ``mesh.h5`` + scene -> ``simulation.h5``, ``frames/*.vtu``, ``simulation.pvd``.

Layout of ``simulation.h5`` (docs/outputs.md): ``/frames/time`` (K,), ``/frames/positions``
(K, N, 3) in mesh node order, ``/history/time`` (T,), ``/history/plate_displacement`` (T, 2),
``/history/plate_force`` (T, 2), ``/history/wall_force`` (T, W), ``/history/energy/<name>`` (T,),
plus whatever else the solver records under ``/history``; the mesh itself under ``/mesh``;
root attributes ``dt_s``, ``steps``, ``elements``, ``wall_time_s``, ``effects`` (JSON list).

Reliability (docs/reliability.md): every ``solver.checkpoint_every`` steps, and on SIGINT/SIGTERM
(handlers installed only around the step loop), the run writes ``simulation.checkpoint.h5`` beside
the output; Ctrl-C then exits with status 130 (SIGTERM 143) and a one-line message naming the
resume command. ``resume="auto"`` (``fiberpipe run``) continues from a checkpoint of the same config
and mesh, ``"require"`` (``fiberpipe simulate --resume``) insists on one, ``"discard"``
(``--force``) deletes it. A diverged run keeps its last good frames in ``simulation_diverged.h5``
(+ ``frames_diverged/``) and leaves the last checkpoint in place. The checkpoint is removed once
``simulation.h5`` is written.
"""

from __future__ import annotations

import logging
import signal
import threading
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_mesh, write_artifact
from fiberpipe.config import Config
from fiberpipe.errors import ArtifactError, FiberpipeError, SimulationDiverged
from fiberpipe.io.output_size import check_free_space
from fiberpipe.io.vtk import mesh_vtu, write_pvd
from fiberpipe.progress import terminal_bar
from fiberpipe.stages._common import input_hashes

log = logging.getLogger(__name__)

#: Units of the history series the solver may record (anything else is stored as given).
HISTORY_UNITS = {
    "time": "s",
    "dt_s": "s",
    "plate_displacement": "m",
    "plate_force": "N",
    "wall_force": "N",
    "plate_position": "m",
    "contacts": "1",
    "segment": "index",
}

#: Units of ``/history/energy/<name>``: joules, except the relative balance residual
#: ((E_total - E_total,0) / max(|W_ext|, E_strain + E_kinetic), solver/integrator.py).
ENERGY_UNITS = {"residual": "1"}


def _energy_units(name: str) -> str:
    return ENERGY_UNITS.get(name, "J")


def write_simulation(path: Path, mesh, result, *, config_sha256: str = "", inputs=None, extra_attrs=None,
                     effects=None) -> Path:
    """Write a :class:`SimulationResult` (complete or partial) as a ``simulation`` artifact.

    ``effects``: the ``effects`` attribute, the config's ``scene.effects`` as the user listed them
    (default: the solver's effect objects, which fold friction into the contact hook).
    """
    datasets = {
        "frames/time": np.asarray(result.frames_time, dtype=np.float64),
        "frames/positions": np.asarray(result.frames_positions, dtype=np.float64),
        "mesh/nodes": mesh.nodes_m,
        "mesh/node_offsets": mesh.node_offsets,
        "mesh/radius": mesh.radius_m,
    }
    units = {"frames/time": "s", "frames/positions": "m", "mesh/nodes": "m", "mesh/node_offsets": "index",
             "mesh/radius": "m"}
    for name, series in result.history.items():
        if isinstance(series, dict):  # e.g. energy/<name>
            for sub, arr in series.items():
                datasets[f"history/{name}/{sub}"] = np.asarray(arr)
                units[f"history/{name}/{sub}"] = _energy_units(sub) if name == "energy" else ""
        else:
            key = f"history/{name}"
            datasets[key] = np.asarray(series)
            units[key] = (_energy_units(name[len("energy/"):]) if name.startswith("energy/")
                          else HISTORY_UNITS.get(name, ""))
    field_units = {"contact_force": "N", "max_normal_force": "N", "max_penetration": "m"}
    for name, arr in (getattr(result, "fields", None) or {}).items():
        datasets[f"frames/{name}"] = np.asarray(arr)
        units[f"frames/{name}"] = field_units.get(name, "")
    attrs = {
        "dt_s": float(result.dt_s),
        "steps": int(result.steps),
        "elements": int(mesh.n_elements),
        "wall_time_s": float(result.wall_time_s),
        "effects": list(result.effects if effects is None else effects),
    }
    attrs.update(extra_attrs or {})
    # frames and histories gzip-compressed in per-frame chunks (artifacts.chunk_shape): a 4000-fiber
    # run reads one frame without the others
    return write_artifact(path, "simulation", datasets, units=units, attrs=attrs, config_sha256=config_sha256, inputs=inputs,
                          compression="gzip", chunks="rows")


def write_frames_vtk(out_dir: Path, mesh, frames_time, frames_positions, *, stem: str = "simulation",
                     frames_dir_name: str = "frames", contact_force=None) -> Path:
    """One VTU per frame in ``out_dir/<frames_dir_name>/`` plus ``out_dir/<stem>.pvd`` for ParaView
    (each file written atomically). ``contact_force`` (K, N, 3), N: the fiber–fiber normal contact
    force on each node, written as point data ``contact_force`` and ``contact_force_magnitude``."""
    frames_dir = out_dir / frames_dir_name
    frames_dir.mkdir(parents=True, exist_ok=True)
    entries = []
    for k, (t, pos) in enumerate(zip(frames_time, frames_positions)):
        name = f"frame_{k:05d}.vtu"
        point_data = {"displacement": pos - mesh.nodes_m}
        if contact_force is not None:
            point_data["contact_force"] = contact_force[k]
            point_data["contact_force_magnitude"] = np.linalg.norm(contact_force[k], axis=1)
        mesh_vtu(frames_dir / name, mesh, points_m=pos, point_data=point_data)
        entries.append((float(t), f"{frames_dir_name}/{name}"))
    return write_pvd(out_dir / f"{stem}.pvd", entries)


@contextmanager
def stop_on_signals():
    """Catch SIGINT and SIGTERM while the block runs: the first one only sets a flag (the run finishes
    its jitted chunk, writes a checkpoint and stops); a second Ctrl-C interrupts at once. Yields a
    callable returning the signal number received (or None). Outside the main thread, no handlers."""
    got: dict = {"sig": None}

    def handler(signum, frame):
        if got["sig"] is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        got["sig"] = signum
        log.warning("received signal %d: stopping after the current chunk and writing a checkpoint", signum)

    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield lambda: got["sig"]
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


def _resume_command(cfg: Config, run_dir: Path) -> str:
    src = getattr(cfg, "source_path", None) or "CONFIG.yaml"
    return f"fiberpipe simulate {src} --out {run_dir} --resume"


def load_resume_checkpoint(ck_path: Path, config_sha256: str, mode: str, echo=None):
    """The checkpoint to resume from (or None) according to ``mode`` (auto | require | discard)."""
    from fiberpipe.solver.checkpoint import read_checkpoint

    say = echo or (lambda s: None)
    if mode == "discard":
        if ck_path.exists():
            ck_path.unlink()
            log.info("simulate: discarded checkpoint %s (--force)", ck_path)
        return None
    if not ck_path.exists():
        if mode == "require":
            raise FiberpipeError("no checkpoint to resume from (run without --resume to start the simulation)",
                                 where=str(ck_path))
        return None
    try:
        ck = read_checkpoint(ck_path, config_sha256=config_sha256 or None)
    except ArtifactError as exc:
        if mode == "require":
            raise
        msg = f"simulate: ignoring {exc}; starting from t = 0"
        (log.info if echo else log.warning)(msg)
        say(f"warning: {msg}")
        return None
    msg = (f"simulate: resuming from checkpoint {ck_path.name} at t = {ck.t:.6g} s "
           f"(step {ck.step} of {ck.origin_step + ck.total_steps})")
    log.info(msg)
    say(msg)
    return ck


def scene_planes(cfg: Config) -> list[tuple[int, float, float]]:
    """The scene's rigid planes at t = 0 as ``(axis, position_m, sign)`` (sign +1: lower plane),
    for :func:`fiberpipe.model.mesh.resolve_overlaps`; plates without a set position are placed
    on the fibers by the solver, so they cannot overlap and are left out."""
    scene_cfg = cfg.scene
    effects = set(scene_cfg.effects or ())
    axes = {"x": 0, "y": 1, "z": 2}
    planes = []
    if "plates" in effects and scene_cfg.plates is not None:
        p = scene_cfg.plates
        if p.lower != "none" and p.lower_position is not None:
            planes.append((axes[p.axis], float(p.lower_position), 1.0))
        if p.upper != "none" and p.upper_position is not None:
            planes.append((axes[p.axis], float(p.upper_position), -1.0))
    if "walls" in effects and scene_cfg.walls is not None:
        for name, ax in axes.items():
            w = getattr(scene_cfg.walls, name)
            if w is not None:
                planes.append((ax, float(w[0]), 1.0))
                planes.append((ax, float(w[1]), -1.0))
    return planes


#: Fiber surfaces up to this fraction of the radius inside a plate or wall at t = 0 are moved out
#: (strain-free, like the mesh stage's fiber–fiber overlaps); deeper cuts are a wrong plate/wall
#: position, which the scene check reports.
PLANE_CLEARANCE_MAX_FRACTION = 0.05


def clear_scene_planes(mesh, cfg: Config) -> float:
    """Move nodes whose surface starts slightly inside a plate or wall back inside the box, in place.

    A traced or generated specimen that touches a plate leaves some nodes a fraction of a µm inside
    it; the plane penalty would throw them off at the first step (paper-40: 65 nodes 0.28 µm inside
    the upper plate, 1.2e-5 J of kinetic energy, never lost at α = 0). Returns the largest initial
    penetration (m); nothing is moved when it is 0 or deeper than ``PLANE_CLEARANCE_MAX_FRACTION`` r
    (then :func:`fiberpipe.solver.terms.planes.check_scene_geometry` names the plane that cuts the bundle).
    """
    from fiberpipe.model.mesh import plane_penetration, resolve_overlaps

    planes = scene_planes(cfg)
    if not planes or not cfg.mesh.resolve_overlaps:
        return 0.0
    r = np.asarray(mesh.radius_m)[mesh.node_fiber()]
    depth = max(float(np.max(plane_penetration(mesh.nodes_m, r, ax, pos, sign))) for ax, pos, sign in planes)
    if depth <= 0.0 or depth > PLANE_CLEARANCE_MAX_FRACTION * float(np.min(mesh.radius_m)):
        return max(depth, 0.0)
    resolve_overlaps(mesh, planes=planes)
    return depth


def run_simulate(cfg: Config, mesh_path: Path, out: Path, *, config_sha256: str = "", resume: str = "auto",
                 echo=None, progress: bool = False) -> dict:
    """Run the simulate stage into ``out`` (``simulation.h5``); see the module docstring for
    checkpoints, signals and ``resume`` (auto | require | discard). ``progress``: show a progress
    bar (on a terminal only)."""
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.checkpoint import CHECKPOINT_NAME, SimulationInterrupted, write_checkpoint
    from fiberpipe.solver.integrator import simulate

    if resume not in ("auto", "require", "discard"):
        raise ValueError(f"resume must be auto, require or discard, got {resume!r}")
    mesh = read_mesh(mesh_path)
    out = Path(out)
    run_dir = out.parent
    ck_path = run_dir / CHECKPOINT_NAME
    inputs = input_hashes({"mesh": Path(mesh_path)})
    check_free_space(run_dir, int(mesh.nodes_m.shape[0]), int(mesh.n_elements), int(cfg.solver.output_frames),
                     where=str(getattr(cfg, "source_path", None) or ""))
    plane_overlap = clear_scene_planes(mesh, cfg)
    model, effects, settings = build_simulation(mesh, cfg)
    asked = list(cfg.scene.effects)  # what the user asked for is what is recorded (friction included)
    ck = load_resume_checkpoint(ck_path, config_sha256, resume, echo)
    saved = {"step": None}

    def on_checkpoint(c):
        write_checkpoint(ck_path, c, config_sha256=config_sha256, inputs=inputs)
        saved["step"] = c.step
        log.info("simulate: checkpoint at t = %.6g s (step %d) -> %s", c.t, c.step, ck_path)

    settle = None
    if cfg.solver.settle_time > 0 and ck is None:
        settle = settle_under_gravity(mesh, cfg)
        log.info("simulate: settled for %.3g s, nodes moved by up to %.3g m", cfg.solver.settle_time, settle["max_displacement_m"])
    bar = terminal_bar("simulate") if progress else None  # closed below, however the run ends
    try:
        with stop_on_signals() as should_stop:
            result = simulate(model, effects, settings, progress=bar, resume=ck, state=None if settle is None else settle["state"],
                              on_checkpoint=on_checkpoint, should_stop=should_stop)
    except SimulationInterrupted as exc:
        msg = (f"simulation {exc}; checkpoint saved to {ck_path}; resume with: {_resume_command(cfg, run_dir)} "
               f"(or fiberpipe run, which picks it up)")
        log.info(msg)  # run.log; the CLI prints the message itself as the one error line
        raise SimulationInterrupted(msg, signum=exc.exit_code - 128) from None
    except SimulationDiverged as exc:
        log.info("simulate stopped: %s", exc)  # run.log; the CLI prints the one error line
        partial = getattr(exc, "partial_result", None)
        kept = []
        if partial is not None and len(partial.frames_time):
            keep = out.with_name("simulation_diverged.h5")
            write_simulation(keep, mesh, partial, config_sha256=config_sha256, inputs=inputs,
                             extra_attrs={"diverged": str(exc), "completed": False}, effects=asked)
            write_frames_vtk(run_dir, mesh, partial.frames_time, partial.frames_positions,
                             stem="simulation_diverged", frames_dir_name="frames_diverged")
            kept.append(f"last good frames kept in {keep}")
        if ck_path.exists():
            kept.append(f"last checkpoint {ck_path.name} kept")
        raise SimulationDiverged(f"{exc}" + (f" ({'; '.join(kept)})" if kept else ""), step=exc.step,
                                 time_s=exc.time_s) from None
    finally:
        if bar is not None:
            bar.close()
    for w in result.warnings:
        log.warning("simulate: %s", w)
    contact = None
    if "contact" in cfg.scene.effects:
        from fiberpipe.post.contact_field import frame_contact_forces

        contact = frame_contact_forces(mesh, np.asarray(result.frames_positions), cfg.scene, cfg.material)
        result.fields = {**(getattr(result, "fields", None) or {}), **contact}
    write_simulation(out, mesh, result, config_sha256=config_sha256, inputs=inputs, effects=asked)
    write_frames_vtk(run_dir, mesh, result.frames_time, result.frames_positions,
                     contact_force=None if contact is None else contact["contact_force"])
    if ck_path.exists():
        ck_path.unlink()
    steps = int(result.steps)
    figures = {
        "dt_s": float(result.dt_s),
        "steps": steps,
        "elements": int(mesh.n_elements),
        "solver_wall_time_s": float(result.wall_time_s),
        "element_steps_per_s": float(steps * mesh.n_elements / max(result.wall_time_s, 1e-12)),
        "effects": asked,
        "frames": int(len(result.frames_time)),
        "initial_plane_overlap_max_m": plane_overlap,
        "warnings": list(result.warnings),
    }
    if ck is not None:
        figures["resumed_from_step"] = int(ck.step)
    if settle is not None:
        figures["settle_time_s"] = float(cfg.solver.settle_time)
        figures["settle_max_displacement_m"] = settle["max_displacement_m"]
        figures["settle_wall_time_s"] = settle["wall_time_s"]
    hist = result.history
    if "plate_force" in hist and len(hist["plate_force"]):
        figures["final_plate_force_N"] = [float(v) for v in np.asarray(hist["plate_force"])[-1]]
    figures.update(_friction_returned(result.friction_returned_J, hist))
    return figures


def _friction_returned(back, hist) -> dict:
    """The energy the friction gave back over the run (``back``, J: the sum of its contacts' negative
    dissipations, solver.friction; None without friction), in J and over ALLFD: friction only
    dissipates when it is ≈ 0."""
    if back is None:
        return {}
    fd = np.asarray(hist.get("energy/friction", []), float)
    fd = float(fd[-1]) if fd.size else 0.0
    return {"friction_returned_J": back, "friction_returned_over_dissipated": back / fd if fd > 0 else 0.0}


def settle_under_gravity(mesh, cfg: Config) -> dict:
    """Let the specimen settle before loading, as the study checks its specimen under gravity.

    The scene runs for ``solver.settle_time`` with every effect but the prescribed motions (plates
    hold still, drives are left out); its final state starts the loaded run. Returns the state, the
    largest node displacement it caused (the study's Fig. 15 check: it should be negligible) and
    the wall time.
    """
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.integrator import simulate

    scfg = cfg.model_copy(deep=True)
    scfg.scene.effects = [e for e in scfg.scene.effects if e != "drives"]
    if scfg.scene.plates is not None:  # plates hold still where the loading will start
        for side in ("lower", "upper"):
            if getattr(scfg.scene.plates, side) == "moving":
                setattr(scfg.scene.plates, side, "fixed")
    scfg.solver.end_time = cfg.solver.settle_time
    scfg.solver.output_frames = 2
    model, effects, settings = build_simulation(mesh, scfg)
    res = simulate(model, effects, settings)
    moved = float(np.max(np.linalg.norm(np.asarray(res.frames_positions[-1]) - mesh.nodes_m, axis=1)))
    # The loaded run starts its clock, its step count and its energy accounts from this state (the
    # loading ramp is timed from t = 0; the settled strain and kinetic energy are its baseline).
    state = res.final_state.copy()
    state.t, state.step = 0.0, 0
    state.acc[:] = 0.0
    return {"state": state, "max_displacement_m": moved, "wall_time_s": float(res.wall_time_s)}
