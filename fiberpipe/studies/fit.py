"""``fiberpipe fit CONFIG --target CURVE.csv --param KEY=LO:HI ...``: identify parameters from a
measured force-displacement curve.

The objective is the RMS load difference over the target's U samples,

    J(p) = sqrt( (1/n) Σ_k ( F̄(U_k; p) − F_k )² ),

with F̄ the simulated load (the run's ``post/force_displacement.csv``, linear in U) averaged
over ``--seeds`` specimen seeds when CONFIG has a ``specimen`` section (one run of a bundle is
one chaotic trajectory; the seeds are ``specimen.seed``, ``specimen.seed`` + 1, ...). Parameters
are any numeric config keys, specimen keys included, with units accepted (``"10 GPa"``).

# Strategy: one parameter is searched by bounded Brent minimisation
# (:func:`scipy.optimize.minimize_scalar`, ``method="bounded"``), several by Nelder-Mead on the
# box mapped to [0, 1]^d with bounds (:func:`scipy.optimize.minimize`), both stopped after
# ``--budget`` evaluations. Each evaluation runs its seeds through the study runner
# (:func:`fiberpipe.studies.sweep.execute`: in this process, on a local process pool with
# ``--workers`` > 1, on a Dask cluster with ``--scheduler``) into ``DIR/evaluations/<id>/``, by
# the ordinary cached pipeline, so a rerun reuses what it has. Outputs: ``DIR/fit.json``,
# ``DIR/history.csv``, ``DIR/fit.png``.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from fiberpipe.artifacts import write_json_atomic
from fiberpipe.config import load_raw, set_dotted, validate_config
from fiberpipe.errors import ConfigError, InputError


# ---------------------------------------------------------------------------------------------
# inputs


def read_target(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The target curve: columns ``U_m`` and ``load_N`` of a CSV (other columns ignored); U must
    be non-decreasing (a run's own curve repeats U = 0 before the plate moves) and finite."""
    path = Path(path)
    if not path.is_file():
        raise InputError("target curve not found", where=str(path))
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"is not a CSV file ({exc})", where=str(path)) from None
    if not rows:
        raise InputError("is empty (expected columns U_m,load_N)", where=str(path))
    head = [h.strip() for h in rows[0]]
    missing = [c for c in ("U_m", "load_N") if c not in head]
    if missing:
        raise InputError(f"missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)} (has: "
                         f"{', '.join(head) or 'none'}; expected U_m,load_N as post/force_displacement.csv writes them)",
                         where=str(path))
    iu, iload = head.index("U_m"), head.index("load_N")
    U, F = [], []
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        try:
            U.append(float(row[iu]))
            F.append(float(row[iload]))
        except (ValueError, IndexError):
            raise InputError(f"line {n}: U_m and load_N must be numbers, got {row!r}", where=str(path)) from None
    U, F = np.asarray(U, float), np.asarray(F, float)
    if len(U) < 2:
        raise InputError(f"needs at least 2 samples, has {len(U)}", where=str(path))
    bad = ~(np.isfinite(U) & np.isfinite(F))
    if bad.any():
        raise InputError(f"line {int(np.argmax(bad)) + 2}: NaN or infinite value ({int(bad.sum())} such line"
                         f"{'s' if bad.sum() > 1 else ''})", where=str(path))
    dec = np.flatnonzero(np.diff(U) < 0)
    if dec.size:
        k = int(dec[0]) + 1
        raise InputError(f"U_m is not monotonic: line {k + 2} has U = {U[k]:.6g} m after {U[k - 1]:.6g} m (give the "
                         "loading branch only, U increasing)", where=str(path))
    if U[-1] <= U[0]:
        raise InputError("U_m does not increase (all samples at one displacement)", where=str(path))
    return U, F


def _dotted_value(cfg, dotted: str):
    cur: Any = cfg
    for part in dotted.split("."):
        if isinstance(cur, (list, tuple)):
            cur = cur[int(part)]
        elif cur is None or not hasattr(cur, part):
            return None
        else:
            cur = getattr(cur, part)
    return cur


def parse_param(text: str, base: dict, where: str) -> dict:
    """``KEY=LO:HI`` (units accepted, e.g. ``material.youngs_modulus=10 GPa:20 GPa``) -> ``{key,
    lo, hi}`` in SI, checked against the config: the key must exist and be numeric, LO < HI."""
    key, sep, rng = text.partition("=")
    key = key.strip()
    if not sep or not key or rng.count(":") != 1:
        raise ConfigError(f"--param {text!r}: expected KEY=LO:HI (e.g. material.youngs_modulus=10GPa:20GPa)")
    lo_txt, hi_txt = (v.strip() for v in rng.split(":"))
    values = []
    for txt in (lo_txt, hi_txt):
        raw = copy.deepcopy(base)
        set_dotted(raw, key, _number_or_text(txt))
        raw.setdefault("input", {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]})
        try:
            cfg = validate_config(raw, where=where)
        except ConfigError as exc:
            raise ConfigError(f"--param {key}: {exc}") from None
        v = _dotted_value(cfg, key)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError(f"--param {key}: not a numeric config key (its value is {v!r})")
        values.append(float(v))
    lo, hi = values
    if not lo < hi:
        raise ConfigError(f"--param {key}: LO must be below HI, got {lo_txt} ({lo:.6g}) >= {hi_txt} ({hi:.6g}) in SI")
    return {"key": key, "lo": lo, "hi": hi}


def _number_or_text(txt: str):
    try:
        return float(txt)
    except ValueError:
        return txt


# ---------------------------------------------------------------------------------------------
# one evaluation


def run_point(raw: dict, run_dir: str, where: str) -> dict:
    """One run of the fit: with a ``specimen`` section, build the specimen into
    ``run_dir/specimen`` and run its ready config into ``run_dir``; else run ``raw`` itself."""
    from fiberpipe.studies.sweep import _run_point, numba_threads

    os.environ.setdefault("NUMBA_NUM_THREADS", numba_threads([raw]))

    if raw.get("specimen") is None:
        return _run_point(raw, run_dir, where)
    from fiberpipe.model.virtual_specimen import build_specimen

    spec_dir = Path(run_dir) / "specimen"
    if not (spec_dir / "config.yaml").exists():
        tmp = Path(run_dir) / "specimen.partial"
        build_specimen(raw, tmp, where=where, echo=lambda *_: None)
        tmp.replace(spec_dir)
    ready = load_raw(spec_dir / "config.yaml")
    return _run_point(ready, run_dir, where)


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


# ---------------------------------------------------------------------------------------------
# the fit


class _Evaluator:
    """The objective: runs a parameter vector's seeds, interpolates onto the target's U."""

    def __init__(self, base, params, U_t, F_t, seeds, out, workers, scheduler, where, echo):
        self.base, self.params, self.U_t, self.F_t = base, params, U_t, F_t
        self.seeds, self.out, self.workers, self.scheduler = seeds, out, workers, scheduler
        self.where, self.echo = where, echo
        self.history: list[dict] = []
        self.cache: dict = {}

    def overrides(self, x) -> dict:
        return {p["key"]: float(v) for p, v in zip(self.params, x)}

    def raw_for(self, x, seed) -> dict:
        raw = copy.deepcopy(self.base)
        for k, v in self.overrides(x).items():
            set_dotted(raw, k, v)
        if seed is not None:
            set_dotted(raw, "specimen.seed", int(seed))
        return raw

    def __call__(self, x) -> float:
        x = [float(v) for v in np.atleast_1d(x)]
        key = tuple(x)
        if key in self.cache:
            return self.cache[key]["objective_N"]
        from fiberpipe.studies.sweep import execute

        jobs = []
        for s in self.seeds:
            raw = self.raw_for(x, s)
            pid = hashlib.sha256(json.dumps({"x": self.overrides(x), "seed": s}, sort_keys=True).encode()).hexdigest()[:10]
            jobs.append((pid, raw, str(self.out / "evaluations" / pid)))
        stamps = [Path(d) / "evaluation_wall_time.json" for _, _, d in jobs]
        new = [not Path(d).exists() for _, _, d in jobs]
        t0 = time.perf_counter()
        execute(jobs, self.workers, self.scheduler, self.where, lambda *_: None, fn=run_point)
        wall_s = time.perf_counter() - t0
        for p, is_new in zip(stamps, new):
            if is_new:
                write_json_atomic(p, {"wall_time_s": wall_s})
        if not any(new):  # runs of an earlier fit: what they cost then (NaN if it did not record it)
            wall_s = (max(json.loads(p.read_text())["wall_time_s"] for p in stamps)
                      if all(p.exists() for p in stamps) else float("nan"))
        curves = np.array([self.interp(Path(d)) for _, _, d in jobs])
        mean = curves.mean(axis=0)
        obj = float(np.sqrt(np.mean((mean - self.F_t) ** 2)))
        spread = curves.std(axis=0, ddof=1) if len(curves) > 1 else np.zeros_like(mean)
        row = {**self.overrides(x), "objective_N": obj, "spread_rms_N": float(np.sqrt(np.mean(spread**2))),
               "wall_time_s": wall_s, "runs": [j[0] for j in jobs]}
        self.cache[key] = {**row, "curve": mean, "curves": curves}
        self.history.append(row)
        self.echo(f"  evaluation {len(self.history)}: " + ", ".join(f"{k} = {v:.6g}" for k, v in self.overrides(x).items())
                  + f" -> RMS {obj:.4g} N ({row['wall_time_s']:.1f} s)")
        return obj

    def interp(self, run_dir: Path) -> np.ndarray:
        U, F = load_curve(run_dir)
        if U[-1] < self.U_t[-1] * (1 - 1e-6) - 1e-12:
            raise ConfigError(f"the run {run_dir} reaches U = {U[-1] * 1e3:.4g} mm, the target goes to "
                              f"{self.U_t[-1] * 1e3:.4g} mm: raise scene.loading.displacement")
        return np.interp(self.U_t, U, F)


def run_fit(config: str | Path, target: str | Path, params: list[str], *, seeds: int = 1, budget: int = 20,
            out: str | Path | None = None, workers: int = 1, scheduler: str | None = None, echo=print) -> dict:
    """Fit ``params`` (``KEY=LO:HI`` strings) of ``config`` to the ``target`` curve; writes
    ``out/fit.json``, ``out/history.csv`` and ``out/fit.png``; returns fit.json's dict."""
    where = str(config)
    base = load_raw(config)
    U_t, F_t = read_target(target)
    if not params:
        raise ConfigError("give at least one --param KEY=LO:HI")
    fit_params = [parse_param(p, base, where) for p in params]
    keys = [p["key"] for p in fit_params]
    if len(set(keys)) != len(keys):
        raise ConfigError("--param: a key is given twice")
    if seeds < 1 or budget < 1:
        raise ConfigError("--seeds and --budget must be at least 1")
    if seeds > 1 and base.get("specimen") is None:
        raise ConfigError(f"--seeds {seeds}: the config has no specimen section, so there are no specimen seeds "
                          "to average over", where=where)
    probe = copy.deepcopy(base)
    probe.setdefault("input", {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]})
    cfg = validate_config(probe, where=where)
    if "plates" not in cfg.scene.effects:
        raise ConfigError("the config has no plates: no force-displacement curve to fit", where=where)
    travel = float(cfg.scene.loading.displacement)
    if travel < U_t[-1] * (1 - 1e-6):
        raise ConfigError(f"scene.loading.displacement = {travel * 1e3:.4g} mm is short of the target's last U "
                          f"({U_t[-1] * 1e3:.4g} mm)", where=where)
    seed0 = cfg.specimen.seed if cfg.specimen is not None else None
    seed_list = [seed0 + k for k in range(seeds)] if seed0 is not None else [None]
    out = Path(out) if out else Path("runs") / "fits" / Path(config).stem
    out.mkdir(parents=True, exist_ok=True)
    # before this process or its workers start numba: the threads the config's runs ask for
    from fiberpipe.studies.sweep import numba_threads

    os.environ.setdefault("NUMBA_NUM_THREADS", numba_threads([base]))
    cluster = _local_cluster(workers) if scheduler is None and workers > 1 and len(seed_list) > 1 else None
    try:
        evaluator = _Evaluator(base, fit_params, U_t, F_t, seed_list, out, workers,
                               cluster.scheduler_address if cluster is not None else scheduler, where, echo)
        return _search(evaluator, config, target, budget)
    finally:
        if cluster is not None:
            cluster.close()


def _local_cluster(workers: int):
    """One local Dask cluster for the whole fit (not one per evaluation); None without Dask (each
    evaluation then runs its seeds on a local process pool)."""
    try:
        from dask.distributed import LocalCluster
    except ImportError:
        return None
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                        env={"NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS", "1")})


def _search(evaluator: _Evaluator, config, target, budget: int) -> dict:
    """The search of :func:`run_fit` with its evaluator; writes the outputs."""
    from scipy.optimize import minimize, minimize_scalar

    fit_params, U_t, F_t = evaluator.params, evaluator.U_t, evaluator.F_t
    seed_list, out, echo = evaluator.seeds, evaluator.out, evaluator.echo
    keys = [p["key"] for p in fit_params]
    echo(f"fit {', '.join(keys)} of {config} to {target} ({len(U_t)} samples), {len(seed_list)} seed(s), "
         f"budget {budget} evaluations")
    lo, hi = np.array([p["lo"] for p in fit_params]), np.array([p["hi"] for p in fit_params])
    if len(fit_params) == 1:
        # Brent's bounded search: one evaluation per iteration; xatol a 1e-4 of the interval
        res = minimize_scalar(lambda v: evaluator([v]), bounds=(lo[0], hi[0]), method="bounded",
                              options={"maxiter": budget, "xatol": 1e-4 * (hi[0] - lo[0])})
        method = "scipy.optimize.minimize_scalar(method='bounded')"
    else:
        res = minimize(lambda u: evaluator(lo + np.clip(u, 0, 1) * (hi - lo)), x0=np.full(len(fit_params), 0.5), method="Nelder-Mead",
                       bounds=[(0.0, 1.0)] * len(fit_params),
                       options={"maxfev": budget, "xatol": 1e-4, "fatol": 1e-9 * max(float(np.max(np.abs(F_t))), 1e-30),
                                "initial_simplex": _simplex(len(fit_params))})
        method = "scipy.optimize.minimize(method='Nelder-Mead', bounds in [0, 1]^d)"
    best_key = min(evaluator.cache, key=lambda k: evaluator.cache[k]["objective_N"])
    best = evaluator.cache[best_key]
    result = {
        "config": str(config), "target": str(target), "method": method,
        "best": {k: float(v) for k, v in zip(keys, best_key)},
        "objective_N": best["objective_N"],
        "objective_relative": best["objective_N"] / max(float(np.sqrt(np.mean(F_t**2))), 1e-300),
        "evaluations": len(evaluator.history),
        "seeds": [s for s in seed_list if s is not None],
        "spread_over_seeds": {
            "rms_N": best["spread_rms_N"],
            "max_N": float(np.max(best["curves"].std(axis=0, ddof=1))) if len(best["curves"]) > 1 else 0.0,
            "final_load_N": [float(c[-1]) for c in best["curves"]],
        },
        "bounds": {p["key"]: [p["lo"], p["hi"]] for p in fit_params},
        "converged": bool(getattr(res, "success", True)),
        "message": str(getattr(res, "message", "")),
        "best_runs": best["runs"],
    }
    _write(out, result, evaluator, U_t, F_t, best)
    echo("best: " + ", ".join(f"{k} = {v:.6g}" for k, v in result["best"].items())
         + f"; RMS {result['objective_N']:.4g} N ({100 * result['objective_relative']:.3g} % of the target's RMS) after "
         f"{result['evaluations']} evaluations; {out}/fit.json, fit.png, history.csv")
    return result


def _simplex(d: int) -> np.ndarray:
    """A start simplex in [0, 1]^d around its centre, a quarter of the box wide."""
    s = np.full((d + 1, d), 0.5)
    for i in range(d):
        s[i + 1, i] = 0.75
    return s


def _write(out: Path, result: dict, evaluator: _Evaluator, U_t, F_t, best) -> None:
    from fiberpipe.post.tables import write_csv

    keys = [p["key"] for p in evaluator.params]
    cols = {k: [h[k] for h in evaluator.history] for k in keys}
    cols.update({c: [h[c] for h in evaluator.history] for c in ("objective_N", "spread_rms_N", "wall_time_s")})
    cols["evaluation"] = list(range(1, len(evaluator.history) + 1))
    write_csv(out / "history.csv", {"evaluation": cols.pop("evaluation"), **cols})
    write_json_atomic(out / "fit.json", result)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fiberpipe.post.plots import _save

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(U_t * 1e3, F_t, "ko", ms=3, label="target")
    for c in best["curves"][1:] if len(best["curves"]) > 1 else []:
        ax.plot(U_t * 1e3, c, color="C0", alpha=0.25, lw=0.8)
    ax.plot(U_t * 1e3, best["curve"], "C0-", label="best fit" + (f" (mean of {len(best['curves'])} seeds)"
                                                                 if len(best["curves"]) > 1 else ""))
    ax.set_xlabel("U [mm]")
    ax.set_ylabel("load [N]")
    ax.set_title(", ".join(f"{k} = {v:.4g}" for k, v in result["best"].items()) + " (SI units)", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, out / "fit.png")

