"""The runner: which stages a config asks for, in order, skipping those that are up to date.

# Strategy: every stage has a cache key, sha256 of (stage name, artifact schema version, the
# validated SI config sections the stage reads, the sha256 of each input artifact, the sha256 of
# the package sources the stage runs, so that an upgrade or a fix of, say, the solver reruns
# simulate and post but keeps the traced fibers and the mesh). The key is
# stored in ``<run>/fiberpipe.lock.json`` beside the outputs; a stage whose key matches and whose
# outputs exist and open as artifacts of the right kind is skipped (``--force`` reruns; a damaged
# output reruns its stage, saying so). Since artifacts are written atomically and their
# hashes feed the next key, a rerun upstream invalidates exactly what depends on it.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from fiberpipe import __version__
from fiberpipe.artifacts import (SCHEMA_VERSIONS, ensure_output_dir, input_sha256, json_text, read_fibers,
                                 read_json_mapping, write_json_atomic)
from fiberpipe.config import Config
from fiberpipe.errors import ArtifactError, ConfigError, FiberpipeError, InputError

log = logging.getLogger("fiberpipe")

STAGE_ORDER = ("phantom", "input", "segment", "skeletonize", "trace", "mesh", "simulate", "post")


@dataclass
class Stage:
    """One step of the pipeline: what it reads and writes, and the function that does it."""

    name: str
    sections: tuple[str, ...]
    inputs: Callable[[Config, Path], dict[str, Path]]
    outputs: Callable[[Config, Path], list[Path]]
    func: Callable[[Config, Path, dict[str, Path], str], dict]
    artifact_kind: str | None = None
    #: package files and folders (relative to ``fiberpipe/``) whose sources are part of the key
    code: tuple[str, ...] = ()


def _volume_path(cfg: Config, run_dir: Path) -> Path:
    if cfg.input.phantom is not None:
        return run_dir / "phantom" / "volume.tif"
    return Path(cfg.input.volume)


def _truth_path(cfg: Config, run_dir: Path) -> Path | None:
    if cfg.input.truth:
        return Path(cfg.input.truth)
    if cfg.input.phantom is not None:
        return run_dir / "phantom" / "truth.h5"
    return None


def _fibers_path(cfg: Config, run_dir: Path) -> Path:
    if cfg.input.fibers is not None:
        return Path(cfg.input.fibers)
    return run_dir / "fibers.h5"


def _skeleton_needed(cfg: Config) -> bool:
    """skeletonize runs unless ``skeletonize.enabled: false`` (a run folder holds
    ``skeleton.h5``, docs/outputs.md); the skeleton tracer always needs it (config validation refuses false there)."""
    return cfg.trace.method == "skeleton" or cfg.skeletonize.enabled is not False


# -- stage functions (thin adapters from the runner's calling convention to the stage modules) --


def _do_phantom(cfg, run_dir, inputs, key):
    from fiberpipe.stages.phantom import run_phantom

    return run_phantom(cfg.input.phantom, run_dir / "phantom", config_sha256=key)


def _do_input(cfg, run_dir, inputs, key):
    from fiberpipe.stages.polylines import run_inline_polylines

    return run_inline_polylines(cfg, run_dir / "fibers.h5", config_sha256=key)


def _do_segment(cfg, run_dir, inputs, key):
    from fiberpipe.stages.segment import run_segment

    vs = cfg.input.phantom.voxel_size if cfg.input.phantom is not None else None
    return run_segment(cfg, inputs["volume"], run_dir / "mask.h5", voxel_size_m=vs, config_sha256=key)


def _do_skeletonize(cfg, run_dir, inputs, key):
    from fiberpipe.stages.skeletonize import run_skeletonize

    return run_skeletonize(cfg, inputs["mask"], run_dir / "skeleton.h5", config_sha256=key)


def _do_trace(cfg, run_dir, inputs, key):
    from fiberpipe.stages.trace import run_trace

    return run_trace(
        cfg,
        inputs["mask"],
        run_dir / "fibers.h5",
        skeleton_path=inputs.get("skeleton"),
        truth_path=_truth_path(cfg, run_dir),
        config_sha256=key,
        volume_path=_volume_path(cfg, run_dir) if cfg.trace.grey or cfg.trace.method in ("auto", "dense") else None,
    )


def _do_mesh(cfg, run_dir, inputs, key):
    from fiberpipe.stages.mesh import run_mesh

    return run_mesh(cfg, inputs["fibers"], run_dir / "mesh.h5", config_sha256=key)


def _do_simulate(cfg, run_dir, inputs, key, *, resume="auto", echo=None, progress=False):
    from fiberpipe.stages.simulate import run_simulate

    figures = run_simulate(cfg, inputs["mesh"], run_dir / "simulation.h5", config_sha256=key, resume=resume,
                           echo=echo, progress=progress)
    from fiberpipe.stages.mesh import write_deck

    write_deck(cfg, inputs["mesh"], run_dir / "model.inp")  # model.inp: the scene this simulation ran
    return figures


def _do_post(cfg, run_dir, inputs, key):
    from fiberpipe.stages.post import run_post

    return run_post(cfg, inputs["simulation"], run_dir / "post", config_sha256=key)


def _has_module(name: str) -> bool:
    return importlib.util.find_spec(name) is not None


STAGES: dict[str, Stage] = {
    "phantom": Stage(
        "phantom", ("input",), lambda c, d: {}, lambda c, d: [d / "phantom" / "volume.tif", d / "phantom" / "truth.h5"], _do_phantom,
        code=("imaging", "stages/phantom.py")
    ),
    "input": Stage("input", ("input",), lambda c, d: {}, lambda c, d: [d / "fibers.h5"], _do_input, "fibers",
                   code=("polylines.py", "stages/polylines.py")),
    "segment": Stage(
        "segment", ("input", "segment", "chunks"), lambda c, d: {"volume": _volume_path(c, d)}, lambda c, d: [d / "mask.h5"], _do_segment, "mask",
        code=("imaging", "stages/segment.py")
    ),
    "skeletonize": Stage(
        "skeletonize", ("skeletonize", "chunks"), lambda c, d: {"mask": d / "mask.h5"}, lambda c, d: [d / "skeleton.h5"], _do_skeletonize, "skeleton",
        code=("imaging", "stages/skeletonize.py")
    ),
    "trace": Stage(
        "trace",
        ("trace", "fiber", "mesh", "chunks"),
        lambda c, d: {"mask": d / "mask.h5", **({"skeleton": d / "skeleton.h5"} if c.trace.method == "skeleton" or (c.trace.method == "auto" and (d / "skeleton.h5").exists()) else {})},
        lambda c, d: [d / "fibers.h5"],
        _do_trace,
        "fibers",
        code=("imaging", "polylines.py", "stages/trace.py", "model/mesh.py"),
    ),
    "mesh": Stage(
        "mesh",
        ("mesh", "material", "fiber"),
        lambda c, d: {"fibers": _fibers_path(c, d)},
        lambda c, d: [d / "mesh.h5", d / "mesh.vtu", d / "model.inp"],
        _do_mesh,
        "mesh",
        code=("model", "polylines.py", "io", "stages/mesh.py"),
    ),
    "simulate": Stage(
        "simulate",
        ("material", "scene", "solver"),
        lambda c, d: {"mesh": d / "mesh.h5"},
        lambda c, d: [d / "simulation.h5", d / "simulation.pvd"],
        _do_simulate,
        "simulation",
        code=("solver", "model", "post/contact_field.py", "stages/simulate.py"),
    ),
    "post": Stage(
        "post", ("post",), lambda c, d: {"simulation": d / "simulation.h5"}, lambda c, d: [d / "post" / "summary.json"], _do_post,
        code=("post", "stages/post.py")
    ),
}


def planned_stages(cfg: Config) -> list[str]:
    """The stages this config asks for, in order."""
    src = cfg.input.source
    names: list[str] = []
    if src == "phantom":
        names.append("phantom")
    if src in ("phantom", "volume"):
        names += ["segment"] + (["skeletonize"] if _skeleton_needed(cfg) else []) + ["trace"]
    if src == "polylines":
        names.append("input")
    names.append("mesh")
    if cfg.scene.effects or cfg.solver.end_time is not None:
        names.append("simulate")
        names.append("post")
    return names


def select_stages(plan: list[str], from_stage: str | None = None, to_stage: str | None = None) -> list[str]:
    """The slice ``from_stage`` .. ``to_stage`` of ``plan``; a ConfigError names an unknown stage, a
    stage this config does not run, or a --from that comes after the --to."""
    runs = f"this config runs the stages {', '.join(plan)}"
    for label, name in (("--from", from_stage), ("--to", to_stage)):
        if name is None or name in plan:
            continue
        if name not in STAGE_ORDER:
            known = ", ".join(s for s in STAGE_ORDER if s != "input")
            raise ConfigError(f"{label} {name}: unknown stage; the stages are {known} ({runs})")
        hint = ""
        if name == "skeletonize":
            hint = "; set skeletonize.enabled: true (or trace.method: skeleton) to compute the skeleton"
        elif name in ("simulate", "post"):
            hint = "; give scene.effects (or solver.end_time) to simulate"
        what = f"the {name} stage" if from_stage == to_stage else f"{label} {name}"
        raise ConfigError(f"{what}: not part of this config's run, {runs}{hint}")
    lo = plan.index(from_stage) if from_stage else 0
    hi = plan.index(to_stage) if to_stage else len(plan) - 1
    if lo > hi:
        raise ConfigError(f"--from {from_stage} comes after --to {to_stage}: the stages run in the order {', '.join(plan)}")
    return plan[lo : hi + 1]


def available(name: str) -> bool:
    """Whether the code of a stage exists in this version (simulate and post arrive with the solver)."""
    mod = {"simulate": "fiberpipe.solver.build", "post": "fiberpipe.stages.post"}.get(name)
    return mod is None or _has_module(mod)


@functools.lru_cache(maxsize=None)
def code_sha256(paths: tuple[str, ...]) -> str:
    """sha256 of the ``*.py`` sources under ``paths`` (relative to the package folder), in path order."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for rel in paths:
        p = root / rel
        files = sorted(p.rglob("*.py")) if p.is_dir() else [p]
        for f in files:
            if f.is_file():
                h.update(str(f.relative_to(root)).encode())
                h.update(f.read_bytes())
    return h.hexdigest()


def stage_key(stage: Stage, cfg: Config, inputs: dict[str, Path]) -> str:
    h = hashlib.sha256()
    h.update(stage.name.encode())
    h.update(code_sha256(stage.code).encode())
    h.update(str(SCHEMA_VERSIONS.get(stage.artifact_kind or "", 0)).encode())
    h.update(cfg.section_sha256(*stage.sections).encode())
    for name in sorted(inputs):
        p = inputs[name]
        h.update(name.encode())
        h.update((input_sha256(p) or "missing").encode())
    return h.hexdigest()


#: Artifacts a stage writes whose kind is not the stage's own ``artifact_kind``.
OUTPUT_KINDS = {"truth.h5": "fibers"}


def _touch(name, obj) -> None:
    """Read an HDF5 object's header and attributes (not its data): fails on a damaged file."""
    dict(obj.attrs)


def _pvd_files(path: Path) -> list[str]:
    """The files a ParaView collection (``.pvd``) lists."""
    import xml.etree.ElementTree as ET

    return [d.get("file") for d in ET.parse(path).getroot().iter("DataSet") if d.get("file")]


def outputs_problem(stage: Stage, outputs: list[Path]) -> str | None:
    """Why the outputs of an up-to-date stage cannot be trusted (None when they can): an HDF5 output
    must open as an artifact of the right kind and schema version with every object's header and
    attributes readable (the data themselves are not read: a corruption inside a dataset's data is
    not seen), a JSON output must parse and the files it lists as its ``outputs`` must exist, a
    ParaView collection's frames must exist, any other output must not be empty. Read-only."""
    from fiberpipe.artifacts import open_checked

    for o in map(Path, outputs):
        try:
            if o.suffix == ".h5":
                kind = OUTPUT_KINDS.get(o.name, stage.artifact_kind)
                with open_checked(o, kind or tuple(SCHEMA_VERSIONS)) as f:
                    f.visititems(_touch)
            elif o.suffix == ".json":
                data = json.loads(o.read_text())
                # a summary that lists the files made beside it (post/summary.json's outputs)
                listed = data.get("outputs", []) if isinstance(data, dict) else []
                missing = [n for n in listed if isinstance(n, str) and not (o.parent / n).exists()]
                if missing:
                    return f"output {o.parent / missing[0]} is missing"
            elif o.stat().st_size == 0:
                return f"output {o.name} is empty"
            elif o.suffix == ".pvd":
                listed = _pvd_files(o)
                missing = [f for f in listed if not (o.parent / f).exists()]
                if missing:
                    return f"output {o.parent / missing[0]} is missing ({len(missing)} of the {len(listed)} frames {o.name} lists)"
        except ArtifactError as exc:
            return f"output {exc}"
        except Exception as exc:  # noqa: BLE001 — h5py raises RuntimeError/KeyError on damaged headers too
            return f"output {o} is unreadable ({exc.__class__.__name__}: {exc})"
    return None


@dataclass
class RunReport:
    run_dir: Path
    stages: dict[str, dict] = field(default_factory=dict)


def check_user_inputs(cfg: Config, plan: list[str]) -> None:
    """The files the config names as inputs of the stages in ``plan`` must exist (before anything
    runs); the error names the key and the file, not an earlier stage."""
    given = []
    if "segment" in plan and cfg.input.phantom is None and cfg.input.volume is not None:
        given.append(("input.volume", cfg.input.volume))
    if "trace" in plan and cfg.input.truth:
        given.append(("input.truth", cfg.input.truth))
    if "mesh" in plan and cfg.input.fibers is not None:
        given.append(("input.fibers", cfg.input.fibers))
    if "post" in plan and cfg.post.reference_fibers:
        given.append(("post.reference_fibers", cfg.post.reference_fibers))
    for key, p in given:
        if not Path(p).exists():
            raise InputError(f"file {p} does not exist (set in {cfg.source_path}; a relative path is relative "
                             "to the config's folder)", where=key)
        if key != "input.volume":  # a fibers artifact: its layout and positions, before any stage writes
            try:
                read_fibers(p)
            except FiberpipeError as exc:
                raise InputError(str(exc), where=key) from None


def _maker(cfg: Config, run_dir: Path, path: Path) -> str | None:
    """The stage of this config that writes ``path`` into the run folder, if any."""
    for name in planned_stages(cfg):
        if any(Path(o) == path for o in STAGES[name].outputs(cfg, run_dir)):
            return name
    return None


def _checkpoint_to_resume(name: str, run_dir: Path, key: str, resume: str | None) -> bool:
    """Whether the simulate stage has a checkpoint to resume even though its output is up to date: a
    ``--force`` rerun interrupted by Ctrl-C leaves the earlier simulation.h5 beside the checkpoint,
    and its resume command must resume rather than skip. ``--resume`` takes any checkpoint (a bad one
    is then refused by the stage, saying why); ``fiberpipe run`` one of this stage key."""
    if name != "simulate" or resume == "discard":
        return False
    from fiberpipe.artifacts import open_checked
    from fiberpipe.solver.checkpoint import CHECKPOINT_NAME

    ck = run_dir / CHECKPOINT_NAME
    if not ck.exists():
        return False
    if resume == "require":
        return True
    try:
        with open_checked(ck, "checkpoint") as f:
            got = f.attrs.get("config_sha256")
    except FiberpipeError:
        return False
    return (got.decode() if isinstance(got, bytes) else got) == key


def _setup_run_log(run_dir: Path) -> logging.Handler:
    handler = logging.FileHandler(run_dir / "run.log")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logging.getLogger("fiberpipe").addHandler(handler)
    logging.getLogger("fiberpipe").setLevel(logging.INFO)
    return handler


def run_pipeline(
    cfg: Config,
    run_dir: str | Path,
    *,
    from_stage: str | None = None,
    to_stage: str | None = None,
    force: bool = False,
    echo: Callable[[str], None] | None = None,
    resume: str | None = None,
    progress: bool = False,
) -> RunReport:
    """Run the stages of ``cfg`` into ``run_dir``; return what each stage did.

    Parameters
    ----------
    from_stage, to_stage : str, optional
        Restrict to a slice of the planned stages (names of :data:`STAGE_ORDER`).
    force : bool
        Rerun even the stages whose cache key is unchanged.
    echo : callable, optional
        Receives one human-readable line per stage (the CLI prints them).
    resume : str, optional
        What the simulate stage does with a checkpoint (``simulation.checkpoint.h5``): ``"auto"``
        (default) resumes from one of the same config and mesh, ``"require"`` insists on one,
        ``"discard"`` deletes it (the default with ``force``).
    progress : bool
        Show a progress bar for the long stages (the CLI asks for one on a terminal without --quiet).
    """
    echo = echo or (lambda s: None)
    plan = select_stages(planned_stages(cfg), from_stage, to_stage)
    check_user_inputs(cfg, plan)
    run_dir = ensure_output_dir(run_dir)

    handler = _setup_run_log(run_dir)
    lock_path = run_dir / "fiberpipe.lock.json"
    summary_path = run_dir / "summary.json"
    lock = _read_state(lock_path, echo)
    summary = _read_state(summary_path, echo)
    summary.update({"name": cfg.name, "fiberpipe_version": __version__, "config": cfg.source_path})
    if not isinstance(summary.get("stages"), dict):
        summary["stages"] = {}
    _warn_stale_upstream(cfg, run_dir, plan, lock, echo)
    report = RunReport(run_dir)
    log.info("run %s -> %s: stages %s", cfg.source_path, run_dir, ", ".join(plan))
    try:
        for name in plan:
            stage = STAGES[name]
            if not available(name):
                msg = f"{name}: not available in fiberpipe {__version__} yet, stopping after the previous stage"
                log.warning(msg)
                echo(msg)
                break
            inputs = stage.inputs(cfg, run_dir)
            _require_inputs(cfg, run_dir, name, inputs)
            key = stage_key(stage, cfg, inputs)
            outputs = stage.outputs(cfg, run_dir)
            entry = lock.get(name) if isinstance(lock.get(name), dict) else {}
            if not force and _is_up_to_date(stage, run_dir, key, entry, outputs, resume, echo):
                report.stages[name] = {"skipped": True, **summary["stages"].get(name, {})}
                continue
            t0 = time.perf_counter()
            log.info("%s: started", name)
            # the stage's old key goes before it rewrites anything: a stage interrupted or failed
            # half-way (a new simulation.h5 beside the old frames) is not up to date the next time;
            # a stage that stops before touching its outputs (a refused resume) gets it back
            old_entry, before = lock.pop(name, None), _outputs_state(outputs)
            if old_entry is not None:
                write_json_atomic(lock_path, lock)
            try:
                if name == "simulate":
                    mode = resume or ("discard" if force else "auto")
                    figures = stage.func(cfg, run_dir, inputs, key, resume=mode, echo=echo, progress=progress) or {}
                else:
                    figures = stage.func(cfg, run_dir, inputs, key) or {}
            except BaseException as exc:
                log.error("%s: stopped: %s", name, "interrupted" if isinstance(exc, KeyboardInterrupt)
                          else f"{exc.__class__.__name__}: {exc}")
                if old_entry is not None and _outputs_state(outputs) == before:
                    lock[name] = old_entry
                    write_json_atomic(lock_path, lock)
                raise
            wall = time.perf_counter() - t0
            figures = {"wall_time_s": round(wall, 3), **figures}
            log.info("%s: done in %.2f s %s", name, wall, json_text(figures, indent=None).strip())
            echo(f"{name:12s} done in {wall:7.2f} s  " + _short(figures))
            lock[name] = {"key": key, "outputs": [str(Path(o).relative_to(run_dir)) if Path(o).is_relative_to(run_dir) else str(o) for o in outputs]}
            summary["stages"][name] = figures
            report.stages[name] = figures
            write_json_atomic(lock_path, lock)
            write_json_atomic(summary_path, summary)
    finally:
        logging.getLogger("fiberpipe").removeHandler(handler)
        handler.close()
    return report


def _require_inputs(cfg: Config, run_dir: Path, name: str, inputs: dict) -> None:
    """A one-line error naming the first missing input of stage ``name`` and the run that makes it."""
    for iname, p in inputs.items():
        if not Path(p).exists():
            maker = _maker(cfg, run_dir, Path(p))
            conf = cfg.source_path or "CONFIG"
            todo = f"run `fiberpipe run {conf} --out {run_dir} --to {maker}` first" if maker else "run the earlier stages first"
            raise FiberpipeError(f"stage {name} needs {iname} at {p}, which does not exist; {todo}")


def _is_up_to_date(stage, run_dir: Path, key: str, entry: dict, outputs, resume: str | None, echo) -> bool:
    """Whether the stage may be skipped: its lock entry has this cache key, its outputs exist and
    read back, and no checkpoint of this key is left to resume; says why when it reruns."""
    name = stage.name
    if not (entry.get("key") == key and all(Path(o).exists() for o in outputs)
            and not _checkpoint_to_resume(name, run_dir, key, resume)):
        return False
    problem = outputs_problem(stage, outputs)
    if problem is None:
        log.info("%s: up to date, skipped", name)
        echo(f"{name:12s} up to date (skipped)")
        return True
    log.info("%s: %s; rerunning the stage", name, problem)
    echo(f"{name:12s} {problem}; rerunning")
    return False


def _outputs_state(outputs) -> list:
    """Size and modification time of each output (None when absent), and of the files a frames
    folder holds: what tells whether a stage has written anything."""
    state = []
    for o in map(Path, outputs):
        try:
            file_stat = o.stat()
            state.append((str(o), file_stat.st_size, file_stat.st_mtime_ns))
        except OSError:
            state.append((str(o), None))
    frames = [Path(o).parent / "frames" for o in outputs if Path(o).suffix == ".pvd"]
    for d in frames:
        if d.is_dir():
            for f in sorted(d.iterdir()):
                file_stat = f.stat()
                state.append((f.name, file_stat.st_size, file_stat.st_mtime_ns))
    return state


def _read_state(path: Path, echo) -> dict:
    """The run folder's ``fiberpipe.lock.json`` or ``summary.json`` (empty when missing); a file
    that is not a JSON mapping is ignored with a warning, so its stages rerun."""
    try:
        return read_json_mapping(path)
    except ArtifactError as exc:
        msg = f"warning: {path} {exc.message}: ignored, the stages it records run again"
        log.warning(msg)
        echo(msg)
        return {}


def _warn_stale_upstream(cfg: Config, run_dir: Path, plan: list[str], lock: dict, echo) -> None:
    """With ``--from``, the stages before it are not run: say so when the outputs the first stage
    reads were made with other settings, inputs or code than this config's (their stage's recorded
    key differs), instead of using them in silence. Only the stages that make the first stage's
    inputs are checked: their keys hash files the first stage hashes anyway (not a whole volume
    further up)."""
    if not plan:
        return
    first_inputs = {Path(p) for p in STAGES[plan[0]].inputs(cfg, run_dir).values()}
    for name in planned_stages(cfg):
        if STAGE_ORDER.index(name) >= STAGE_ORDER.index(plan[0]):
            continue
        stage = STAGES[name]
        inputs = stage.inputs(cfg, run_dir)
        outputs = stage.outputs(cfg, run_dir)
        if not first_inputs & {Path(o) for o in outputs} or not all(Path(p).exists() for p in [*inputs.values(), *outputs]):
            continue
        entry = lock.get(name) if isinstance(lock.get(name), dict) else {}
        if entry.get("key") != stage_key(stage, cfg, inputs):
            msg = (f"warning: {name}'s outputs in {run_dir} were made with other settings, inputs or code than "
                   f"{cfg.source_path or 'this config'} gives; {plan[0]} uses them as they are (run from {name} "
                   "to remake them)")
            log.warning(msg)
            echo(msg)


def _short(figures: dict) -> str:
    keep = []
    for k, v in figures.items():
        if k == "wall_time_s" or isinstance(v, (dict, list)):
            continue
        if isinstance(v, float):
            v = f"{v:.4g}"
        keep.append(f"{k}={v}")
    return ", ".join(keep[:6])
