"""Specimen ensembles: one config, N specimen seeds, F(U) as the seeds' mean with a band.

One compaction of a fiber bundle is one chaotic trajectory: two specimens drawn from the same
statistics (``specimen.seed`` apart) carry loads a factor of several apart. ``specimen.seeds``
(or ``--seeds`` of ``fiberpipe run``, ``study`` and ``fit``) builds and compacts one specimen per
seed and reports the ensemble: ``ensemble.csv`` (U, mean, standard deviation, min, max and every
seed's load), ``ensemble.json`` (per seed: v_f0, the final load, the run folder; the mean and sample
standard deviation of the final load), ``ensemble.png`` (the mean, the ±1 sd band and every seed)
and ``summary.json``.

# Strategy: the members run on Dask (a local cluster of ``workers`` processes by default, or the
# scheduler at ``--scheduler ADDRESS``), each by the ordinary cached pipeline into
# ``OUT/seed-<s>/``; the specimens are built into ``OUT/specimens/seed-<s>-<key>/``, the key a hash
# of everything the deposit and the settling read (not the compaction's loading, plates, damping,
# mass scaling, step scheme, nor its contact law when ``specimen.settle.contact`` gives the settling's own), so
# variants that differ only in how they compact share their specimens. A worker
# killed mid-run loses nothing: Dask runs its tasks again on another worker, and a task run again
# finds the specimen and the pipeline stages its first attempt finished (content hashes) and redoes
# only the rest. A rerun of the command does the same for the whole ensemble.
# A member whose simulation diverges (its settling, closing or compaction) is one chaotic trajectory
# the explicit step did not hold: it is reported (seed, step, time, the solver's diagnosis; in
# ``ensemble.json``'s ``diverged`` and its run folder's ``diverged.json``) and left out of the mean
# and band, and the other members run to their end; only an ensemble with no member left is an error.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import math
import os
import shutil
import time
from pathlib import Path

import numpy as np
import yaml

from fiberpipe.artifacts import write_json_atomic
from fiberpipe.config import PATH_KEYS, check_seeds, set_dotted, validate_config
from fiberpipe.errors import ConfigError, FiberpipeError, InputError, SimulationDiverged

# what the deposit and the settling do not read: the compaction's own settings
# (fiberpipe.model.specimen_settle.settle_scene replaces or drops these)
_COMPACTION_ONLY = {
    None: ("name", "input", "post"),
    "scene": ("loading", "plates", "walls", "damping", "constraints", "clamps", "loads", "drives"),
    "solver": ("mass_scaling", "stable_step", "end_time", "output_frames", "checkpoint_every", "settle_time"),
    "specimen": ("seeds", "strain"),
}


def parse_seeds_option(text: str | None, first_seed: int, key: str = "--seeds") -> list[int] | None:
    """``--seeds``: ``N`` (N seeds from ``specimen.seed`` on) or a comma list ``0,3,7``; None: not given."""
    if text is None:
        return None
    parts = [p.strip() for p in str(text).split(",")]
    if not any(parts):
        raise ConfigError(f"{key} is empty: give a number of seeds (4) or a list (0,1,2,3)")
    try:
        values = [int(p) for p in parts if p]
    except ValueError:
        raise ConfigError(f"{key} {text!r}: expected a number of seeds (4) or a comma list of seeds (0,1,2,3)") from None
    if len(parts) == 1:
        if values[0] < 1:
            raise ConfigError(f"{key} {text}: the number of seeds must be at least 1")
        return list(range(first_seed, first_seed + values[0]))
    try:
        check_seeds(values, key)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return values


def ensemble_seeds(raw: dict, seeds_option: str | None, where: str) -> list[int] | None:
    """The ensemble's seeds: ``--seeds`` over ``specimen.seeds``; None if neither asks for one.
    An ensemble needs a specimen section."""
    specimen = raw.get("specimen") if isinstance(raw, dict) else None
    if seeds_option is None and not (isinstance(specimen, dict) and specimen.get("seeds") is not None):
        return None
    if not isinstance(specimen, dict):
        raise ConfigError("--seeds: the config has no specimen section, so there are no specimen seeds to draw",
                          where=where)
    probe = copy.deepcopy(raw)
    probe.setdefault("input", {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]})
    cfg = validate_config(probe, where=where)
    given = parse_seeds_option(seeds_option, cfg.specimen.seed)
    return given if given is not None else list(cfg.specimen.seeds)


def specimen_key(raw: dict) -> str:
    """A hash of what building the specimen of ``raw`` reads (its seed included)."""
    keep = copy.deepcopy(raw)
    for section, names in _COMPACTION_ONLY.items():
        holder = keep if section is None else keep.get(section)
        if isinstance(holder, dict):
            for name in names:
                holder.pop(name, None)
    scene = keep.get("scene")
    settle = (keep.get("specimen") or {}).get("settle")
    if isinstance(scene, dict) and isinstance(settle, dict) and settle.get("contact") is not None:
        scene.pop("contact", None)  # the settling and closing use their own (specimen.settle.contact)
    if isinstance(scene, dict) and isinstance(scene.get("friction"), dict):
        scene["friction"] = {k: v for k, v in scene["friction"].items() if k != "mu"}  # the settling's own mu
    if isinstance(scene, dict) and isinstance(scene.get("effects"), list):
        scene["effects"] = [e for e in scene["effects"] if e not in ("plates", "constraints", "clamps", "loads", "drives")]
    return hashlib.sha256(json.dumps(keep, sort_keys=True, default=str).encode()).hexdigest()[:12]


def member_config(raw: dict, specimen_dir: Path, info: dict, where: str) -> dict:
    """``raw``'s compaction on the specimen in ``specimen_dir`` (its ``specimen.json`` ``info``):
    the ready config of :func:`fiberpipe.model.virtual_specimen.ready_config_text` with absolute paths."""
    from fiberpipe.model.virtual_specimen import ready_config_text

    cfg = validate_config({**copy.deepcopy(raw), "input": {"fibers": str(specimen_dir / "fibers.h5")}}, where=where)
    text = ready_config_text(raw, specimen_dir, info["height_m"], info["width_m"], where, strain=cfg.specimen.strain)
    ready = yaml.safe_load(text)
    for section, key in PATH_KEYS:
        holder = ready.get(section)
        if isinstance(holder, dict) and isinstance(holder.get(key), str) and not os.path.isabs(holder[key]):
            holder[key] = str((specimen_dir / holder[key]).resolve())
    return ready


def build_member_specimen(raw: dict, specimen_dir: Path, where: str) -> dict:
    """The specimen of ``raw`` in ``specimen_dir``: built there (atomically: in a folder of this
    process, then renamed) unless an earlier run left it; returns its ``specimen.json``."""
    from fiberpipe.model.virtual_specimen import build_specimen

    info_path = specimen_dir / "specimen.json"
    if not info_path.is_file():
        partial = specimen_dir.with_name(f"{specimen_dir.name}.partial-{os.getpid()}")
        shutil.rmtree(partial, ignore_errors=True)  # what a killed attempt of this process id left
        build_specimen(raw, partial, where=where, echo=lambda *_: None)
        try:
            partial.replace(specimen_dir)
        except OSError:  # another worker finished the same specimen first: keep its copy
            shutil.rmtree(partial, ignore_errors=True)
    return json.loads(info_path.read_text())


def run_member(raw: dict, run_dir: str, where: str, specimen_store: str) -> dict:
    """One member of an ensemble (a worker's task): build (or find) its specimen, compact it into
    ``run_dir``; returns the run's figures and the specimen's v_f0."""
    from fiberpipe.studies.runner import _run_point, numba_threads

    os.environ.setdefault("NUMBA_NUM_THREADS", numba_threads([raw]))
    specimen_dir = Path(specimen_store) / f"seed-{int(raw['specimen'].get('seed', 0))}-{specimen_key(raw)}"
    specimen_dir.parent.mkdir(parents=True, exist_ok=True)
    try:
        info = build_member_specimen(raw, specimen_dir, where)
    except SimulationDiverged as exc:
        exc.stage = "specimen"  # its settling or closing, not the compaction
        raise
    result = _run_point(member_config(raw, specimen_dir, info, where), run_dir, where)
    closing = info.get("closing") or {}
    return {**result, "specimen_dir": str(specimen_dir), "v_f0": float(info["volume_fraction"]),
            "closing_residual_load_N": closing.get("residual_load_N")}


def member_jobs(raw: dict, seeds: list[int], out: Path) -> list[tuple[str, dict, str]]:
    """``(id, raw, run folder)`` per seed: ``raw`` with ``specimen.seed`` set, its ensemble keys dropped."""
    jobs = []
    for seed in seeds:
        member = copy.deepcopy(raw)
        member["specimen"].pop("seeds", None)
        set_dotted(member, "specimen.seed", int(seed))
        jobs.append((f"seed-{seed}", member, str(out / f"seed-{seed}")))
    return jobs


DIVERGED_FILE = "diverged.json"  # in a member's run folder: why its last attempt diverged


def divergence_record(seed: int, exc: SimulationDiverged, stage: str) -> dict:
    """A diverged member as ``ensemble.json`` lists it: the seed, the stage that diverged (the
    specimen's settling or closing, or the compaction), the step and time where the solver found it,
    and its diagnosis (the first line)."""
    diagnosis = str(exc)
    first = diagnosis.splitlines()[0] if diagnosis else "simulation diverged"
    step, time_s = getattr(exc, "step", None), getattr(exc, "time_s", None)
    return {"seed": int(seed), "stage": stage, "step": None if step is None else int(step),
            "time_s": None if time_s is None else float(time_s), "diagnosis": first}


def member_outcome(raw: dict, run_dir: str, where: str, specimen_store: str, member=None,
                   keep_going: bool = False) -> dict:
    """``member`` (:func:`run_member` unless given); ``{"diverged": divergence_record}`` (also
    written to ``run_dir/diverged.json``) when its simulation diverges; with ``keep_going``,
    ``{"error": its one-line message}`` when the member's input is bad (another
    :class:`fiberpipe.errors.FiberpipeError`: a v_f0 its pile cannot reach), which without it ends the pass."""
    record_path = Path(run_dir) / DIVERGED_FILE
    record_path.unlink(missing_ok=True)  # the record of an earlier attempt: this one decides
    started = time.perf_counter()
    try:
        return (member or run_member)(raw, run_dir, where, specimen_store=specimen_store)
    except SimulationDiverged as exc:
        record = divergence_record(int(raw["specimen"].get("seed", 0)), exc, getattr(exc, "stage", "compaction"))
        record_path.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(record_path, record)
        return {"diverged": record, "wall_time_s": time.perf_counter() - started}
    except FiberpipeError as exc:
        if not keep_going:
            raise
        return {"error": str(exc).splitlines()[0] if str(exc) else type(exc).__name__,
                "wall_time_s": time.perf_counter() - started}


def _diverged_text(record: dict) -> str:
    """``seed 3 diverged in the compaction at step 70028 (t = 0.0596 s)``."""
    at = f" at step {record['step']} (t = {record['time_s']:.4g} s)" if record.get("step") is not None else ""
    return f"seed {record['seed']} diverged in the {record['stage']}{at}"


def _all_diverged(out: Path, seeds: list[int], diverged: list[dict]) -> dict:
    """An ensemble none of whose members finished: the one-line error naming the first divergence."""
    first = diverged[0]
    return {"error": f"{out}: every member diverged ({_diverged_text(first)}: {first['diagnosis']})",
            "seeds": [int(s) for s in seeds], "diverged": diverged}


def run_ensembles(ensembles: dict[str, tuple[dict, list[int], Path]], *, workers: int | None = None,
                  scheduler: str | None = None, specimen_store: Path | None = None, where: str = "ensemble",
                  echo=print, member=None, keep_going: bool = False) -> dict[str, dict]:
    """Run several ensembles ``{name: (raw, seeds, out)}`` in one pass of the scheduler (their members
    side by side); write each one's outputs (:func:`write_ensemble`); returns ``{name: ensemble.json}``.
    ``specimen_store``: where the specimens go (default: ``specimens/`` beside the first ensemble);
    ``member``: the members' task, ``member(raw, run_dir, where, specimen_store)``, :func:`run_member`
    unless given (a function the workers can import or unpickle). ``keep_going``: an ensemble whose
    member stops on bad input returns ``{"error": the first member's message, "seeds": ...}`` (and
    writes nothing) while the others finish; without it the first such error ends the pass. A
    member that diverges is left out of its ensemble (listed in ``diverged``) while the others
    finish; an ensemble whose every member diverged is an error the same way (with ``keep_going``
    its ``{"error": ...}``, without it a one-line :class:`SimulationDiverged` once the pass has
    written the others)."""
    from fiberpipe.studies.runner import execute

    names = list(ensembles)
    store = Path(specimen_store) if specimen_store is not None else Path(ensembles[names[0]][2]) / "specimens"
    jobs, owner = [], {}
    for name in names:
        raw, seeds, out = ensembles[name]
        for job_id, member_raw, run_dir in member_jobs(raw, seeds, Path(out)):
            jobs.append((f"{name}/{job_id}", member_raw, run_dir))
            owner[f"{name}/{job_id}"] = name
    n_workers = workers or max(1, min(len(jobs), os.cpu_count() or 1))
    echo(f"ensemble: {len(jobs)} runs ({', '.join(f'{n}: {len(ensembles[n][1])} seeds' for n in names)})")
    task = functools.partial(member_outcome, member=member, keep_going=keep_going, specimen_store=str(store.resolve()))
    results = execute(jobs, n_workers, scheduler, where, echo, fn=task)
    summaries = {}
    for name in names:
        raw, seeds, out = ensembles[name]
        members = {job_id.rsplit("/", 1)[1]: res for job_id, res in results.items() if owner[job_id] == name}
        errors = [f"seed {job_id.split('-', 1)[1]}: {res['error']}" for job_id, res in members.items() if "error" in res]
        if errors:
            echo(f"  {out}: not run ({errors[0]})")
            summaries[name] = {"error": errors[0], "seeds": [int(s) for s in seeds]}
            continue
        diverged = [members[f"seed-{s}"]["diverged"] for s in seeds if "diverged" in members[f"seed-{s}"]]
        for record in diverged:
            echo(f"  {out}: {_diverged_text(record)}, left out of the mean and band: {record['diagnosis']}")
        finished = [s for s in seeds if "diverged" not in members[f"seed-{s}"]]
        summaries[name] = (write_ensemble(Path(out), finished, members, echo, diverged=diverged) if finished
                           else _all_diverged(Path(out), seeds, diverged))
    failed = [summary["error"] for summary in summaries.values() if "error" in summary]
    if failed and not keep_going:
        raise SimulationDiverged(failed[0])
    return summaries


def collect_ensemble(out: Path, seeds: list[int], echo=print) -> dict:
    """An ensemble's outputs (:func:`write_ensemble`) from the member runs ``out/seed-<s>/`` an earlier
    pass finished, running nothing (a pass killed part way, or runs whose cache keys a change of the
    package's code has made stale); ``{"error": ...}`` naming the first seed without a finished run.
    A member whose last attempt diverged (its ``diverged.json``) is left out, as :func:`run_ensembles`
    leaves it out. Each member's specimen is the one its run's ``config.yaml`` reads."""
    members, diverged = {}, []
    for seed in seeds:
        run = Path(out) / f"seed-{seed}"
        if (run / DIVERGED_FILE).is_file():
            diverged.append(json.loads((run / DIVERGED_FILE).read_text()))
            continue
        if not (run / "post" / "force_displacement.csv").is_file():
            return {"error": f"seed {seed}: no finished run in {run}", "seeds": [int(s) for s in seeds]}
        fibers = (yaml.safe_load((run / "config.yaml").read_text()).get("input") or {}).get("fibers")
        specimen_dir = Path(fibers).parent
        info = json.loads((specimen_dir / "specimen.json").read_text())
        summary_path = run / "summary.json"
        simulate = (json.loads(summary_path.read_text()).get("stages") or {}).get("simulate", {}) \
            if summary_path.is_file() else {}
        members[f"seed-{seed}"] = {"v_f0": float(info["volume_fraction"]), "specimen_dir": str(specimen_dir),
                                   "closing_residual_load_N": (info.get("closing") or {}).get("residual_load_N"),
                                   "solver_wall_time_s": simulate.get("solver_wall_time_s")}
    finished = [s for s in seeds if f"seed-{s}" in members]
    if not finished:
        return _all_diverged(Path(out), seeds, diverged)
    return write_ensemble(Path(out), finished, members, echo, diverged=diverged)


def run_ensemble(raw: dict, seeds: list[int], out: Path, **kwargs) -> dict:
    """One ensemble (:func:`run_ensembles`); returns its ``ensemble.json``."""
    return run_ensembles({"ensemble": (raw, seeds, Path(out))}, **kwargs)["ensemble"]


def load_curve(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """The loading branch of the run's ``post/force_displacement.csv`` (U_m, load_N): the samples
    up to the largest U, repeated U averaged."""
    path = Path(run_dir) / "post" / "force_displacement.csv"
    if not path.is_file():
        raise InputError("the run wrote no force-displacement curve (no plates?)", where=str(path))
    data = np.genfromtxt(path, delimiter=",", names=True)
    U, F = np.atleast_1d(data["U_m"]), np.atleast_1d(data["load_N"])
    ok = np.isfinite(U) & np.isfinite(F)
    U, F = U[ok], F[ok]
    end = int(np.argmax(U)) + 1
    Uu, inv = np.unique(U[:end], return_inverse=True)
    F = F[:end]
    Fu = np.bincount(inv, weights=F) / np.bincount(inv)
    return Uu, Fu


def ensemble_curves(run_dirs: list[Path], samples: int = 201) -> tuple[np.ndarray, np.ndarray]:
    """The members' loading branches on one U grid (0 to the shortest run's largest U): (U, F[seed, U])."""
    curves = [load_curve(d) for d in run_dirs]
    u_end = min(float(U[-1]) for U, _ in curves)
    grid = np.linspace(0.0, u_end, samples)
    return grid, np.array([np.interp(grid, U, F) for U, F in curves])


def write_ensemble(out: Path, seeds: list[int], members: dict[str, dict], echo=print,
                   diverged: list[dict] | None = None) -> dict:
    """``ensemble.csv``, ``ensemble.json``, ``summary.json`` and ``ensemble.png`` of the finished
    members ``seeds``; ``diverged``: the members left out (:func:`divergence_record`), listed as they are."""
    from fiberpipe.post.tables import write_csv

    run_dirs = [out / f"seed-{s}" for s in seeds]
    grid, loads = ensemble_curves(run_dirs)
    mean = loads.mean(axis=0)
    sd = loads.std(axis=0, ddof=1) if len(seeds) > 1 else np.zeros_like(mean)
    columns = {"U_m": grid, "load_mean_N": mean, "load_sd_N": sd, "load_min_N": loads.min(axis=0),
               "load_max_N": loads.max(axis=0)}
    columns.update({f"load_seed_{s}_N": loads[k] for k, s in enumerate(seeds)})
    write_csv(out / "ensemble.csv", columns)
    ends = [load_curve(d) for d in run_dirs]  # each run's load at its own largest U (not the common grid's)
    finals = [float(F[-1]) for _, F in ends]
    summary = {
        "seeds": [int(s) for s in seeds],
        "v_f0": [members[f"seed-{s}"]["v_f0"] for s in seeds],
        "final_U_m": [float(U[-1]) for U, _ in ends],
        "final_load_N": finals,
        "final_load_mean_N": float(np.mean(finals)),
        "final_load_sd_N": float(np.std(finals, ddof=1)) if len(finals) > 1 else 0.0,
        "closing_residual_load_N": [members[f"seed-{s}"].get("closing_residual_load_N") for s in seeds],
        "runs": [str(d) for d in run_dirs],
        "specimens": [members[f"seed-{s}"]["specimen_dir"] for s in seeds],
        "solver_wall_time_s": [members[f"seed-{s}"].get("solver_wall_time_s") for s in seeds],
        "diverged": list(diverged or []),
    }
    write_json_atomic(out / "ensemble.json", summary)
    write_json_atomic(out / "summary.json", {"ensemble": summary})
    _plot(out / "ensemble.png", grid, loads, seeds)
    spread = f" ± {summary['final_load_sd_N']:.4g}" if len(seeds) > 1 else ""
    echo(f"  {out}: F(U = {max(summary['final_U_m']) * 1e3:.4g} mm) = {summary['final_load_mean_N']:.4g}{spread} N over "
         f"{len(seeds)} seed(s) (min {min(finals):.4g}, max {max(finals):.4g})"
         + "".join(f"; seed {d['seed']} diverged, left out" for d in summary["diverged"])
         + "; ensemble.csv, ensemble.json, ensemble.png")
    return summary


def _plot(path: Path, grid: np.ndarray, loads: np.ndarray, seeds: list[int]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fiberpipe.post.plots import _save

    mean = loads.mean(axis=0)
    sd = loads.std(axis=0, ddof=1) if len(seeds) > 1 else np.zeros_like(mean)
    fig, ax = plt.subplots(figsize=(6, 4))
    for k, seed in enumerate(seeds):
        ax.plot(grid * 1e3, loads[k], color="0.6", lw=0.7, label="one seed" if k == 0 else None)
    ax.fill_between(grid * 1e3, mean - sd, mean + sd, color="C0", alpha=0.3, label="mean ± 1 sd")
    ax.plot(grid * 1e3, mean, "C0-", label=f"mean of {len(seeds)} seeds")
    ax.set_xlabel("U [mm]")
    ax.set_ylabel("load [N]")
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, path)


def final_load_statistics(loads: list[float]) -> dict:
    """Mean, sample sd and the half-width of the mean's 95 % interval (Student t) of final loads."""
    from scipy.stats import t

    n = len(loads)
    mean = float(np.mean(loads))
    sd = float(np.std(loads, ddof=1)) if n > 1 else 0.0
    half = float(t.ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else float("nan")
    return {"n": n, "mean_N": mean, "sd_N": sd, "mean_ci95_half_width_N": half}


def study_ensemble_rows(spec, points: list[dict], reference: dict | None, out: Path, seeds: list[int], *,
                        workers: int | None, scheduler: str | None, where: str, echo) -> tuple[list[dict], dict]:
    """``fiberpipe study --seeds``: every point (and the reference run) as an ensemble in
    ``out/points/<id>/`` (``out/reference/``), their specimens shared in ``out/specimens``; the
    errors are the points' ensemble-mean curves against the reference's (measures curve and
    final_load), each over its finished members (a diverged one left out: the row's ``seeds`` counts
    the finished, ``diverged_seeds`` names the others). Returns the study table's rows and the
    reference's ensemble.json."""
    from fiberpipe.post.curves import curve_error

    other = [m for m in spec.measures if m not in ("curve", "final_load")]
    if other:
        raise ConfigError(f"measures {other}: an ensemble study compares mean curves (measures curve, final_load)",
                          where=where)
    if reference is None:
        raise ConfigError("an ensemble study needs a reference given by reference.overrides", where=where)
    for point in [reference, *points]:
        if not isinstance(point["raw"].get("specimen"), dict):
            raise ConfigError("--seeds: the base config has no specimen section", where=where)
    ensembles = {"reference": (reference["raw"], seeds, out / "reference")}
    ensembles.update({p["id"]: (p["raw"], seeds, out / "points" / p["id"]) for p in points})
    summaries = run_ensembles(ensembles, workers=workers, scheduler=scheduler, specimen_store=out / "specimens",
                              where=where, echo=echo)
    U_ref, loads_ref = _ensemble_table(out / "reference")
    F_ref = loads_ref.mean(axis=0)
    rows = []
    for point in points:
        U, loads = _ensemble_table(out / "points" / point["id"])
        mean, summary = loads.mean(axis=0), summaries[point["id"]]
        row = {k: str(v) for k, v in point["overrides"].items()}
        if "curve" in spec.measures:
            row["curve_error"] = curve_error(U_ref, F_ref, U, mean, scale=float(np.max(np.abs(F_ref))) or None)
        if "final_load" in spec.measures:
            row["final_load_error"] = float(abs(mean[-1] - F_ref[-1]) / max(abs(F_ref[-1]), 1e-300))
        walls = [w for w in summary["solver_wall_time_s"] if w is not None]
        row.update(final_load_mean_N=summary["final_load_mean_N"], final_load_sd_N=summary["final_load_sd_N"],
                   seeds=len(summary["seeds"]), diverged_seeds=" ".join(str(d["seed"]) for d in summary["diverged"]),
                   wall_time_s=float(np.mean(walls)) if walls else float("nan"), id=point["id"])
        rows.append(row)
    return rows, summaries["reference"]


def _ensemble_table(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """An ensemble's ``ensemble.csv``: U and the seeds' loads (seed, U)."""
    table = np.genfromtxt(folder / "ensemble.csv", delimiter=",", names=True)
    columns = [c for c in table.dtype.names if c.startswith("load_seed_")]
    return np.atleast_1d(table["U_m"]), np.array([np.atleast_1d(table[c]) for c in columns])
