"""``fiberpipe study STUDY.yaml``: run a grid of config variants, measure error against a reference
and wall time, and write a table and a Pareto plot.

A study file::

    name: rearrangement-velocity-alpha
    base: ../verify/rearrangement.yaml        # any fiberpipe config, relative to this file
    sweep:                                    # cartesian product of dotted config keys
      scene.drives.0.velocity: ["100 mm/min", "1000 mm/min"]
      scene.damping.alpha: [0, "1e4 1/s", "1e5 1/s"]
    reference:                                # a named slow/fine run: overrides of the base
      overrides: {scene.drives.0.velocity: "10 mm/min"}
    measures: [curve, final_load, positions]  # error measures, the first is the Pareto axis
    workers: 2                                # local processes (or Dask with --scheduler)

# Strategy: each point is the base config with its overrides applied, validated up front (so a
# typo fails before anything runs), and run by the ordinary cached runner into
# ``<out>/points/<id>/``; rerunning a study only runs new points. Errors are computed from the
# points' ``simulation.h5`` against the reference's.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Literal, Optional

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fiberpipe.artifacts import write_text_atomic
from fiberpipe.config import load_raw, validate_config
from fiberpipe.errors import ConfigError

Measure = Literal["curve", "final_load", "positions", "tip"]


class ReferenceSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    overrides: dict[str, Any] = Field(default_factory=dict)
    run: Optional[str] = None


class StudySpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = "study"
    base: str
    sweep: dict[str, list[Any]]
    reference: ReferenceSpec = Field(default_factory=ReferenceSpec)
    measures: list[Measure] = Field(default_factory=lambda: ["curve"])
    workers: int = Field(1, ge=1)


def _set_dotted(data: dict, dotted: str, value) -> None:
    parts = dotted.split(".")
    cur: Any = data
    for i, p in enumerate(parts[:-1]):
        nxt = parts[i + 1]
        if isinstance(cur, list):
            cur = cur[int(p)]
            continue
        if p not in cur or cur[p] is None:
            cur[p] = [] if nxt.isdigit() else {}
        cur = cur[p]
    last = parts[-1]
    if isinstance(cur, list):
        cur[int(last)] = value
    else:
        cur[last] = value


def load_study(path: str | Path) -> tuple[StudySpec, dict]:
    path = Path(path)
    if not path.exists():
        raise ConfigError("study file not found", where=str(path))
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError:
        raise ConfigError("is not valid YAML", where=str(path)) from None
    if not isinstance(data, dict):
        raise ConfigError("a study must be a YAML mapping", where=str(path))
    try:
        spec = StudySpec.model_validate(data)
    except ValidationError as exc:
        e = exc.errors()[0]
        raise ConfigError(f"'{'.'.join(map(str, e['loc']))}': {e['msg']}", where=str(path)) from None
    base_path = (path.parent / spec.base).resolve()
    base = load_raw(base_path)
    return spec, {"base": base, "base_path": str(base_path)}


def study_points(spec: StudySpec, base: dict, where: str) -> list[dict]:
    """The grid: one dict per point with ``id``, ``overrides`` and the merged raw config."""
    keys = list(spec.sweep)
    points = []
    for values in itertools.product(*(spec.sweep[k] for k in keys)):
        overrides = dict(zip(keys, values))
        points.append(_point(base, overrides, where))
    return points


def _point(base: dict, overrides: dict, where: str) -> dict:
    raw = copy.deepcopy(base)
    for k, v in overrides.items():
        _set_dotted(raw, k, v)
    cfg = validate_config(copy.deepcopy(raw), where=f"{where} point {overrides}")
    pid = hashlib.sha256(json.dumps(overrides, sort_keys=True, default=str).encode()).hexdigest()[:10]
    return {"id": pid, "overrides": overrides, "raw": raw, "config_sha256": cfg.sha256()}


def _run_point(raw: dict, run_dir: str, where: str) -> dict:
    """Run one point in this process (also used by worker processes)."""
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from fiberpipe.pipeline import run_pipeline

    cfg = validate_config(copy.deepcopy(raw), where=where)
    t0 = time.perf_counter()
    report = run_pipeline(cfg, Path(run_dir))
    wall = time.perf_counter() - t0
    sim = report.stages.get("simulate", {})
    return {"wall_time_s": wall, "solver_wall_time_s": sim.get("solver_wall_time_s"), "steps": sim.get("steps"), "elements": sim.get("elements")}


def _errors(measures, ref_sim: Path, sim: Path) -> dict:
    from fiberpipe.post.curves import curve_error, force_displacement
    from fiberpipe.post.history import load_simulation

    r, s = load_simulation(ref_sim), load_simulation(sim)
    out = {}
    for m in measures:
        if m == "curve":
            Ur, Fr = force_displacement(r)
            U, F = force_displacement(s)
            out["curve_error"] = curve_error(Ur, Fr, U, F, scale=float(np.max(np.abs(Fr))) or None)
        elif m == "final_load":
            _, Fr = force_displacement(r)
            _, F = force_displacement(s)
            out["final_load_error"] = float(abs(F[-1] - Fr[-1]) / max(abs(Fr[-1]), 1e-300))
        elif m in ("positions", "tip"):
            pr, ps = r.frames_positions[-1], s.frames_positions[-1]
            if pr.shape == ps.shape:
                d = np.linalg.norm(pr - ps, axis=1)
                scale = 2 * float(np.mean(r.mesh.radius_m))
                out["position_error"] = float(np.mean(d) / scale)
            else:
                from fiberpipe.post.positions import position_error

                e = position_error(ps, s.mesh.node_offsets, pr, r.mesh.node_offsets)
                out["position_error"] = e["mean_m"] / (2 * float(np.mean(r.mesh.radius_m)))
    return out


def run_study(path: str | Path, out: str | Path, *, workers: int | None = None, scheduler: str | None = None, echo=print) -> Path:
    """Run a study; write ``<out>/study.csv``, ``study.md`` and ``pareto.png``."""
    path = Path(path)
    spec, ctx = load_study(path)
    base = ctx["base"]
    points = study_points(spec, base, str(path))
    ref = _point(base, spec.reference.overrides, str(path)) if spec.reference.run is None else None
    out = Path(out)
    (out / "points").mkdir(parents=True, exist_ok=True)
    jobs = []
    if ref is not None:
        jobs.append(("reference", ref["raw"], str(out / "reference")))
    jobs += [(p["id"], p["raw"], str(out / "points" / p["id"])) for p in points]
    nworkers = workers or spec.workers
    echo(f"study {spec.name}: {len(points)} points + reference, {nworkers} worker(s)" + (f" on {scheduler}" if scheduler else ""))
    results = _execute(jobs, nworkers, scheduler, str(path), echo)
    ref_sim = Path(spec.reference.run) if spec.reference.run else out / "reference" / "simulation.h5"
    if spec.reference.run and not ref_sim.is_absolute():
        ref_sim = (path.parent / ref_sim).resolve()
    rows = []
    for p in points:
        res = results[p["id"]]
        err = _errors(spec.measures, ref_sim, out / "points" / p["id"] / "simulation.h5")
        steps, elements = res.get("steps") or 0, res.get("elements") or 0
        solver_wall = res.get("solver_wall_time_s") or float("nan")
        row = {**{k: str(v) for k, v in p["overrides"].items()}, **err, "wall_time_s": solver_wall, "steps": steps,
               "element_steps_per_s": steps * elements / solver_wall if solver_wall and solver_wall == solver_wall else float("nan"), "id": p["id"]}
        rows.append(row)
    ref_res = results.get("reference", {})
    _write_outputs(out, spec, rows, ref_res, echo)
    return out


def _execute(jobs, nworkers, scheduler, where, echo) -> dict:
    results = {}
    if scheduler or nworkers > 1:
        try:
            from dask.distributed import Client, LocalCluster  # optional extra: fiberpipe[dask]

            if scheduler:
                client = Client(scheduler)
            else:
                client = Client(LocalCluster(n_workers=nworkers, threads_per_worker=1, processes=True, env={"NUMBA_NUM_THREADS": "1"}))
            with client:
                futures = {jid: client.submit(_run_point, raw, d, where, pure=False) for jid, raw, d in jobs}
                for jid, fut in futures.items():
                    results[jid] = fut.result()
                    echo(f"  {jid}: {results[jid]['wall_time_s']:.1f} s")
            return results
        except ImportError:
            if scheduler:
                raise ConfigError("--scheduler needs Dask: pip install 'fiberpipe[dask]'") from None
        with ProcessPoolExecutor(max_workers=nworkers) as pool:
            futures = {jid: pool.submit(_run_point, raw, d, where) for jid, raw, d in jobs}
            for jid, fut in futures.items():
                results[jid] = fut.result()
                echo(f"  {jid}: {results[jid]['wall_time_s']:.1f} s")
        return results
    for jid, raw, d in jobs:
        results[jid] = _run_point(raw, d, where)
        echo(f"  {jid}: {results[jid]['wall_time_s']:.1f} s")
    return results


def _write_outputs(out: Path, spec: StudySpec, rows: list[dict], ref: dict, echo) -> None:
    from fiberpipe.post.report import write_csv

    if not rows:
        return
    cols = list(rows[0])
    write_csv(out / "study.csv", {c: [r.get(c) for r in rows] for c in cols})
    err_cols = [c for c in cols if c.endswith("_error")]
    lines = [f"# Study {spec.name}", "", f"Reference: {spec.reference.run or spec.reference.overrides} "
             f"(solver wall time {ref.get('solver_wall_time_s', float('nan')):.3g} s)" if ref else "", "",
             "| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r.get(c)) for c in cols) + " |")
    write_text_atomic(out / "study.md", "\n".join(lines) + "\n")
    echo("\n".join(lines))
    if err_cols:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        e = np.array([r[err_cols[0]] for r in rows], float)
        w = np.array([r["wall_time_s"] for r in rows], float)
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.scatter(w, e)
        for r, wi, ei in zip(rows, w, e):
            ax.annotate(", ".join(str(r[k]) for k in spec.sweep), (wi, ei), fontsize=6)
        order = np.argsort(w)
        front, best = [], np.inf
        for i in order:
            if e[i] < best:
                best = e[i]
                front.append(i)
        ax.plot(w[front], e[front], "r--", label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("solver wall time [s]")
        ax.set_ylabel(f"{err_cols[0]} [-]")
        ax.grid(alpha=0.3, which="both")
        ax.legend()
        from fiberpipe.post.plots import _save

        _save(fig, out / "pareto.png")


def _cell(v):
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)
