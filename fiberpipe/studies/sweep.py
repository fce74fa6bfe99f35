"""``fiberpipe study STUDY.yaml``: run a grid of config variants, measure error against a reference
and wall time, and write a table and a Pareto plot.

A study file (cf. configs/studies/rearrangement-velocity-alpha.yaml)::

    name: rearrangement-velocity-alpha
    base: ../verify/study-rearrangement.yaml  # any fiberpipe config, relative to this file
    sweep:                                    # cartesian product of dotted config keys
      scene.drives.0.velocity: ["100 mm/min", "1000 mm/min"]
      scene.damping.alpha: [0, "1e4 1/s", "1e5 1/s"]
    reference:                                # a named slow/fine run: overrides of the base
      overrides: {scene.drives.0.velocity: "10 mm/min"}
      # or  run: path/to/simulation.h5         (an existing run, relative to this file)
      # or  extrapolate: {key: mesh.element_length, order: 2}   (the converged limit: Richardson
      #     extrapolation of the sweep's two finest values of ``key``; order "auto" estimates it
      #     from the three finest; only for curve and final_load)
    measures: [curve, final_load, positions]  # error measures, the first is the Pareto axis
    # measures: curve (F(U) of the plates, relative L2), final_load, positions (mean node distance
    # at the end / fiber diameter), rearrangement (u_y(u_z) of the study's 3-beam case: max error
    # / max u_y,ref, driven fiber 0 against the mean outward motion of the others)
    workers: 2                                # points in parallel: a local Dask cluster of that many
                                              # processes (fiberpipe[dask]), else a local process pool;
                                              # --scheduler ADDRESS: an existing Dask cluster instead

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
from pathlib import Path
from typing import Any, Literal, Optional, Union

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from fiberpipe.artifacts import write_text_atomic
from fiberpipe.config import _DuplicateKey, _StrictLoader, load_raw, set_dotted, validate_config
from fiberpipe.errors import ConfigError
from fiberpipe.studies.runner import _execute, _run_point, _warm_up, execute, numba_threads  # noqa: F401  (re-exported)

Measure = Literal["curve", "final_load", "positions", "tip", "rearrangement"]


class ExtrapolateSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    key: str
    order: Union[float, Literal["auto"]] = 2.0

    @model_validator(mode="after")
    def _order(self):
        if self.order != "auto" and not self.order > 0:
            raise ValueError(f"reference.extrapolate.order must be > 0 or 'auto', got {self.order}")
        return self


class ReferenceSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    overrides: dict[str, Any] = Field(default_factory=dict)
    run: Optional[str] = None
    extrapolate: Optional[ExtrapolateSpec] = None

    @model_validator(mode="after")
    def _one(self):
        if self.run is not None and self.extrapolate is not None:
            raise ValueError("give reference.run or reference.extrapolate, not both")
        return self


class StudySpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = "study"
    base: str
    sweep: dict[str, list[Any]]
    reference: ReferenceSpec = Field(default_factory=ReferenceSpec)
    measures: list[Measure] = Field(default_factory=lambda: ["curve"])
    workers: int = Field(1, ge=1)

    @model_validator(mode="after")
    def _values(self):
        empty = [k for k, v in self.sweep.items() if not v]
        if not self.sweep or empty:
            raise ValueError(f"sweep.{empty[0]} has no values" if empty else "sweep has no keys")
        return self


def load_study(path: str | Path) -> tuple[StudySpec, dict]:
    path = Path(path)
    if not path.exists():
        raise ConfigError("study file not found", where=str(path))
    try:
        # config.py's loader: a key given twice is refused (PyYAML's safe_load keeps the last)
        data = yaml.load(path.read_text(), Loader=_StrictLoader)
    except _DuplicateKey as exc:
        raise ConfigError(f"duplicate key '{exc.key}' at line {exc.line} (first given at line "
                          f"{exc.first_line}); keep only one", where=str(path)) from None
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


def _point(base: dict, overrides: dict, where: str, label: str = "point") -> dict:
    raw = copy.deepcopy(base)
    for k, v in overrides.items():
        try:
            set_dotted(raw, k, v)
        except ConfigError as exc:
            raise ConfigError(str(exc), where=f"{where} {label}") from None
    cfg = validate_config(copy.deepcopy(raw), where=f"{where} {label} {overrides}")
    pid = hashlib.sha256(json.dumps(overrides, sort_keys=True, default=str).encode()).hexdigest()[:10]
    return {"id": pid, "overrides": overrides, "raw": raw, "config_sha256": cfg.sha256()}


def _key_value(raw: dict, dotted: str, where: str) -> float:
    """The SI value of a dotted key in a raw config (validated, so units are converted)."""
    cfg = validate_config(copy.deepcopy(raw), where=where)
    cur: Any = cfg
    for part in dotted.split("."):
        cur = cur[int(part)] if isinstance(cur, (list, tuple)) else getattr(cur, part)
    return float(cur)


def rearrangement_curve(sim) -> tuple[np.ndarray, np.ndarray]:
    """u_z (K,) of the driven fiber 0 (its mean downward displacement along z) and u_y (K,): the mean
    outward (away from fiber 0, along y) displacement of the other fibers, on the output frames (m).
    The study's 3-beam rearrangement case (its Figs. 8–10: u_y = u_y2 = −u_y3)."""
    X = np.asarray(sim.frames_positions)
    off = np.asarray(sim.mesh.node_offsets)
    fib = [slice(int(off[i]), int(off[i + 1])) for i in range(len(off) - 1)]
    z0 = X[:, fib[0], 2].mean(axis=1)
    uz = -(z0 - z0[0])
    y0 = X[0, fib[0], 1].mean()
    uys = []
    for f in fib[1:]:
        y = X[:, f, 1].mean(axis=1)
        uys.append((y - y[0]) * np.sign(y[0] - y0 or 1.0))
    return uz, np.mean(uys, axis=0) if uys else np.zeros_like(uz)


def _rearrangement_error(ref_sim, sim) -> float:
    uz_r, uy_r = rearrangement_curve(ref_sim)
    uz, uy = rearrangement_curve(sim)
    o = np.argsort(uz_r)
    sel = uz <= np.max(uz_r) + 1e-12
    ref = np.interp(uz[sel], uz_r[o], uy_r[o])
    return float(np.max(np.abs(uy[sel] - ref)) / max(float(np.max(np.abs(uy_r))), 1e-300))


def _errors(measures, ref, sim_path: Path) -> dict:
    """Errors of the run at ``sim_path`` against ``ref``: a ``SimulationData`` (reference run) or a
    dict ``{"U", "F"}`` (an extrapolated limit curve)."""
    from fiberpipe.post.curves import curve_error, force_displacement
    from fiberpipe.post.history import load_simulation

    s = load_simulation(sim_path)
    r = ref if isinstance(ref, dict) else None
    out = {}
    for m in measures:
        if m in ("curve", "final_load"):
            Ur, Fr = (r["U"], r["F"]) if r is not None else force_displacement(ref)
            U, F = force_displacement(s)
            if m == "curve":
                out["curve_error"] = curve_error(Ur, Fr, U, F, scale=float(np.max(np.abs(Fr))) or None)
            else:
                out["final_load_error"] = float(abs(F[-1] - Fr[-1]) / max(abs(Fr[-1]), 1e-300))
                out["final_load_N"] = float(F[-1])
        elif m == "rearrangement":
            if r is not None:
                raise ConfigError("the rearrangement measure needs a reference run, not an extrapolated limit")
            out["rearrangement_error"] = _rearrangement_error(ref, s)
        elif m in ("positions", "tip"):
            if r is not None:
                out["position_error"] = float("nan")  # no extrapolated positions
                continue
            pr, ps = ref.frames_positions[-1], s.frames_positions[-1]
            if pr.shape == ps.shape:
                d = np.linalg.norm(pr - ps, axis=1)
                scale = 2 * float(np.mean(ref.mesh.radius_m))
                out["position_error"] = float(np.mean(d) / scale)
            else:
                from fiberpipe.post.positions import position_error

                e = position_error(ps, s.mesh.node_offsets, pr, ref.mesh.node_offsets)
                out["position_error"] = e["mean_m"] / (2 * float(np.mean(ref.mesh.radius_m)))
    return out


def observed_order(h: list[float], f: list[np.ndarray]) -> float:
    """Observed order of convergence from three solutions ``f`` at ``h`` (finest first), by the
    fixed-point iteration of Celik et al. (J. Fluids Eng. 130, 2008, the GCI procedure), which allows
    unequal refinement ratios; clamped to [0.5, 4]. Returns 2 if two solutions coincide."""
    r21, r32 = h[1] / h[0], h[2] / h[1]
    e21 = float(np.linalg.norm(np.asarray(f[1]) - np.asarray(f[0])))
    e32 = float(np.linalg.norm(np.asarray(f[2]) - np.asarray(f[1])))
    if e21 <= 0 or e32 <= 0:
        return 2.0
    sgn = 1.0  # norms: monotone convergence assumed
    p = 2.0
    for _ in range(100):
        q = np.log((r21**p - sgn) / (r32**p - sgn))
        p_new = float(np.clip(abs(np.log(e32 / e21) + q) / np.log(r21), 0.5, 4.0))
        done = abs(p_new - p) <= 1e-13 * max(1.0, p)
        p = p_new
        if done:
            break
    return p


def richardson_extrapolate(h: list[float], curves: list[tuple[np.ndarray, np.ndarray]], order: Union[float, str] = 2.0) -> dict:
    """The converged limit of F(U) by Richardson extrapolation from curves ``(U, F)`` at mesh sizes
    ``h`` (finest first; two for a given ``order``, three for ``order="auto"``, which estimates it by
    :func:`observed_order`): F_lim = F_1 + (F_1 − F_2)/(r^p − 1) on the finest curve's U, with
    r = h_2/h_1 and the coarser curves interpolated linearly in U onto it.
    Returns ``{"U", "F", "order", "h"}``."""
    need = 3 if order == "auto" else 2
    if len(h) < need or len(curves) < need:
        raise ValueError(f"Richardson extrapolation with order {order!r} needs {need} solutions")
    h = [float(v) for v in h[:need]]
    if any(b <= a * (1 + 1e-9) for a, b in zip(h, h[1:])):
        raise ValueError(f"Richardson extrapolation needs distinct sizes, finest first, got {h}")
    U1, F1 = (np.asarray(a, dtype=float) for a in curves[0])
    Fs = [F1]
    for U, F in curves[1:need]:
        U, F = np.asarray(U, dtype=float), np.asarray(F, dtype=float)
        o = np.argsort(U)
        Fs.append(np.interp(U1, U[o], F[o]))
    p = observed_order(h, Fs) if order == "auto" else float(order)
    r = h[1] / h[0]
    F_lim = Fs[0] + (Fs[0] - Fs[1]) / (r**p - 1.0)
    return {"U": U1, "F": F_lim, "order": p, "h": h}


def _extrapolation_points(spec: StudySpec, points: list[dict], where: str) -> list[tuple[float, dict]]:
    """The points ``reference.extrapolate`` uses, ``(h, point)`` finest first; checked before any
    point runs (a sweep of the key only, enough distinct values, no per-node measure)."""
    ex = spec.reference.extrapolate
    if list(spec.sweep) != [ex.key]:
        raise ConfigError(f"reference.extrapolate over {ex.key!r} needs a sweep of that key only", where=where)
    if "rearrangement" in spec.measures:
        raise ConfigError("the rearrangement measure needs a reference run, not an extrapolated limit", where=where)
    hs = sorted(((_key_value(p["raw"], ex.key, where), p) for p in points), key=lambda t: t[0])
    need = 3 if ex.order == "auto" else 2

    def distinct(vals):  # "0.3 mm" and "0.0003 m" are one size (to rounding of the unit conversion)
        return sum(1 for i, v in enumerate(vals) if i == 0 or not np.isclose(v, vals[i - 1], rtol=1e-9, atol=0.0))

    if distinct([h for h, _ in hs]) < need:
        raise ConfigError(f"reference.extrapolate needs at least {need} distinct values of {ex.key}", where=where)
    if distinct([h for h, _ in hs[:need]]) < need:
        raise ConfigError(f"reference.extrapolate: the {need} finest values of {ex.key} must be distinct", where=where)
    return hs[:need]


def richardson_limit(spec: StudySpec, points: list[dict], out: Path, where: str) -> dict:
    """The converged limit of F(U) by Richardson extrapolation over ``reference.extrapolate.key``
    from the study's finest runs in ``out`` (:func:`richardson_extrapolate`)."""
    from fiberpipe.post.curves import force_displacement
    from fiberpipe.post.history import load_simulation

    hs = _extrapolation_points(spec, points, where)
    curves = [force_displacement(load_simulation(out / "points" / p["id"] / "simulation.h5")) for _, p in hs]
    return richardson_extrapolate([h for h, _ in hs], curves, spec.reference.extrapolate.order)


def digit_cost(rows: list[dict], err_col: str) -> Optional[dict]:
    """What one more digit of accuracy costs: a least-squares fit log10(error) = a + b log10(wall) over
    the Pareto front (points with error > 0); factor = 10^(−1/b), the wall-time multiplier for a 10×
    smaller error. None if the front has fewer than two points or the error does not fall with time."""
    e = np.array([r.get(err_col, np.nan) for r in rows], float)
    w = np.array([r["wall_time_s"] for r in rows], float)
    ok = np.isfinite(e) & np.isfinite(w) & (e > 0) & (w > 0)
    idx = [i for i in np.argsort(w) if ok[i]]
    front, best = [], np.inf
    for i in idx:
        if e[i] < best:
            best = e[i]
            front.append(i)
    if len(front) < 2:
        return None
    b, a = np.polyfit(np.log10(w[front]), np.log10(e[front]), 1)
    if b >= 0:
        return None
    return {"slope": float(b), "factor": float(10 ** (-1.0 / b)), "front": [rows[i]["id"] for i in front]}


def run_study(path: str | Path, out: str | Path, *, workers: int | None = None, scheduler: str | None = None, echo=print,
              seeds: str | None = None) -> Path:
    """Run a study; write ``<out>/study.csv``, ``study.md`` and ``pareto.png``. ``seeds`` (``--seeds``)
    or the base's ``specimen.seeds``: every point an ensemble of specimens
    (:func:`fiberpipe.studies.ensemble.study_ensemble_rows`)."""
    from fiberpipe.studies.ensemble import ensemble_seeds, study_ensemble_rows

    path = Path(path)
    spec, ctx = load_study(path)
    base = ctx["base"]
    points = study_points(spec, base, str(path))
    use_ref_run = spec.reference.run is None and spec.reference.extrapolate is None
    ref = _point(base, spec.reference.overrides, str(path), "reference.overrides") if use_ref_run else None
    seed_list = ensemble_seeds(base, seeds, str(path))
    if seed_list is not None:
        out = Path(out)
        echo(f"study {spec.name}: {len(points)} points + reference, each {len(seed_list)} specimen seeds")
        rows, ref_summary = study_ensemble_rows(spec, points, ref, out, seed_list, workers=workers or spec.workers,
                                                scheduler=scheduler, where=str(path), echo=echo)
        _write_outputs(out, spec, rows, {"solver_wall_time_s": float(np.mean(ref_summary["solver_wall_time_s"])),
                                         "steps": f"{len(seed_list)} seeds"}, echo)
        return out
    if spec.reference.extrapolate is not None:
        _extrapolation_points(spec, points, str(path))  # fail before running anything
    given_ref = None
    if spec.reference.run:  # read before any point runs: a wrong file fails before the points' work
        from fiberpipe.post.history import load_simulation

        given_ref = load_simulation(_reference_run_path(spec, path))
    out = Path(out)
    (out / "points").mkdir(parents=True, exist_ok=True)
    jobs = []
    if ref is not None:
        jobs.append(("reference", ref["raw"], str(out / "reference")))
    jobs += [(p["id"], p["raw"], str(out / "points" / p["id"])) for p in points]
    nworkers = workers or spec.workers
    echo(f"study {spec.name}: {len(points)} points" + (" + reference" if ref else "") + f", {nworkers} worker(s)" + (f" on {scheduler}" if scheduler else ""))
    results = _execute(jobs, nworkers, scheduler, str(path), echo)
    from fiberpipe.post.history import load_simulation

    limit = None
    if spec.reference.extrapolate is not None:
        limit = richardson_limit(spec, points, out, str(path))
        ref_data = limit
    elif given_ref is not None:
        ref_data = given_ref
    else:
        ref_sim = out / "reference" / "simulation.h5"
        if not ref_sim.exists():
            raise ConfigError("reference run not found", where=str(ref_sim))
        ref_data = load_simulation(ref_sim)
    rows = []
    for p in points:
        res = results[p["id"]]
        err = _errors(spec.measures, ref_data, out / "points" / p["id"] / "simulation.h5")
        steps, elements = res.get("steps") or 0, res.get("elements") or 0
        solver_wall = res.get("solver_wall_time_s") or float("nan")
        row = {**{k: str(v) for k, v in p["overrides"].items()}, **err, "wall_time_s": solver_wall, "steps": steps,
               "element_steps_per_s": steps * elements / solver_wall if solver_wall and solver_wall == solver_wall else float("nan"), "id": p["id"]}
        rows.append(row)
    ref_res = dict(results.get("reference", {}))
    if limit is not None:
        ref_res["limit"] = limit
    _write_outputs(out, spec, rows, ref_res, echo)
    return out


def _reference_run_path(spec: StudySpec, path: Path) -> Path:
    """The study's ``reference.run`` (relative to the study file): an existing simulation artifact."""
    ref_sim = Path(spec.reference.run)
    if not ref_sim.is_absolute():
        ref_sim = (path.parent / ref_sim).resolve()
    if not ref_sim.is_file():
        raise ConfigError(f"reference.run {ref_sim}: reference run not found", where=str(path))
    return ref_sim


def _write_outputs(out: Path, spec: StudySpec, rows: list[dict], ref: dict, echo) -> None:
    from fiberpipe.post.tables import write_csv

    if not rows:
        return
    cols = list(rows[0])
    write_csv(out / "study.csv", {c: [r.get(c) for r in rows] for c in cols})
    err_cols = [c for c in cols if c.endswith("_error")]
    rs = spec.reference
    if rs.extrapolate is not None:
        lim = ref.get("limit", {})
        ref_txt = (f"Reference: the converged limit, Richardson extrapolation over `{rs.extrapolate.key}` from its two "
                   f"finest values ({', '.join(f'{h:.4g}' for h in lim.get('h', [])[:2])}), order p = "
                   f"{lim.get('order', float('nan')):.2f}" + (" (observed, from the three finest)" if rs.extrapolate.order == "auto" else ""))
    elif rs.run:
        ref_txt = f"Reference: the run `{rs.run}`"
    else:
        ov = ", ".join(f"`{k}` = {v}" for k, v in rs.overrides.items()) or "the base config"
        ref_txt = f"Reference: {ov} (solver wall time {ref.get('solver_wall_time_s', float('nan')):.3g} s, {ref.get('steps')} steps)"
    lines = [f"# Study {spec.name}", "", ref_txt, ""]
    for c in err_cols:
        dc = digit_cost(rows, c)
        if dc is None:
            lines.append(f"- `{c}`: no Pareto trade-off (the error does not fall as wall time grows over this sweep)")
        else:
            lines.append(f"- `{c}`: one more digit of accuracy (10× smaller error) costs ×{dc['factor']:.3g} in wall time "
                         f"(fit over the Pareto front, {len(dc['front'])} points, slope {dc['slope']:.2f})")
    lines += ["", "| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]
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
        # log axes need a positive value (a study whose errors are all 0 or NaN gets linear ones)
        ax.set_xscale("log" if np.any(np.isfinite(w) & (w > 0)) else "linear")
        ax.set_yscale("log" if np.any(np.isfinite(e) & (e > 0)) else "linear")
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
