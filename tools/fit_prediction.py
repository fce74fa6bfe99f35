"""Predict the study's contact-law comparison on the fitted study specimen, over specimen seeds.

    .venv/bin/python tools/fit_prediction.py [--config configs/specimens/paper-40-fitted.yaml]
        [--fit runs/fits/paper-40-spool] [--seeds 0 1 2] [--out runs/fits/paper-40-fitted]

For each seed the specimen of ``--config`` (its spool radius the one ``make study-fit`` found) is
built once (``fiberpipe specimen``: deposited, settled with the config's orientation-aware law) and
compacted with each of the study's contact models: the orientation-aware law of the config, the
study's parallel model (Φ = 0) and its oblique model (Φ = 6°), the laws of
``configs/paper-40/parallel.yaml`` and ``configs/paper-40/oblique-6.yaml``. Nothing is fitted
here. The seed the fit ran with, at the fitted spool radius, is the fit's best evaluation: that
specimen and its orientation-aware run are taken from ``--fit`` instead of being run again (they
are the same inputs; the reuse needs the config's spool radius to equal the fit's best in SI, bit for
bit, and the fit to have run one seed).

Writes ``OUT/prediction.csv`` (one row per law and seed: final and peak load, phase boundaries,
v_f0 → v_f, contacts per fiber), ``OUT/prediction.json`` (each law's final load over the seeds:
mean, sample standard deviation, min, max) and ``OUT/prediction.png`` (the laws' curves against the
target). Runs are cached: a rerun only runs what is missing.
"""

from __future__ import annotations

import argparse
import copy
import csv
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# the study's contact models (its Table 1), as configs/paper-40/*.yaml select them; None = the config's own
LAWS = {
    "oriented": None,
    "parallel": {"law": "scaled_stiffness", "preset": "table1_parallel"},
    "oblique-6": {"law": "scaled_stiffness", "preset": "table1_phi6"},
}
STUDY_N = {"experiment": 12.0, "parallel": 17.0, "oblique-6": 9.5}  # the study's loads at U = 1.15 mm


def spool_radius_m(raw: dict, where: str) -> float:
    from fiberpipe.config import validate_config

    probe = copy.deepcopy(raw)
    probe.setdefault("input", {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]})
    return float(validate_config(probe, where=where).specimen.bow.spool_radius)


def specimen_dir(raw: dict, seed: int, out: Path, where: str, reuse: Path | None) -> Path:
    """The built specimen of ``seed`` (cached in ``out/seed-N/specimen``, or the fit's own)."""
    from fiberpipe.config import set_dotted
    from fiberpipe.model.virtual_specimen import build_specimen

    if reuse is not None:
        return reuse / "specimen"
    d = out / f"seed-{seed}" / "specimen"
    if not (d / "config.yaml").exists():
        tmp = d.with_name("specimen.partial")
        raw = copy.deepcopy(raw)
        set_dotted(raw, "specimen.seed", int(seed))
        build_specimen(raw, tmp, where=where, echo=lambda *_: None)
        tmp.replace(d)
    return d


def run_law(spec: Path, law: dict | None, run_dir: Path, where: str) -> Path:
    from fiberpipe.config import load_raw, set_dotted
    from fiberpipe.studies.sweep import _run_point

    raw = load_raw(spec / "config.yaml")
    if law is not None:
        set_dotted(raw, "scene.contact", dict(law))
    _run_point(raw, str(run_dir), where)
    return run_dir


def measure(run_dir: Path) -> dict:
    from fiberpipe.post.curves import force_displacement
    from fiberpipe.post.history import load_simulation
    from fiberpipe.post.phases import compaction_phases

    sim = load_simulation(run_dir / "simulation.h5")
    U, F = force_displacement(sim)
    s = json.loads((run_dir / "post" / "summary.json").read_text())
    ph = compaction_phases(U, F)
    mm = lambda v: float("nan") if v is None else 1e3 * v  # noqa: E731
    return {
        "final_U_mm": 1e3 * float(U[-1]), "final_load_N": float(F[-1]), "peak_load_N": float(np.max(F)),
        "rearrangement_end_U_mm": mm(ph["rearrangement_end_U_m"]), "steep_start_U_mm": mm(ph["steep_start_U_m"]),
        "vf_initial": s.get("vf_initial", float("nan")), "vf_final": s.get("vf_final", float("nan")),
        "contacts_per_fiber_final": s.get("contacts_per_fiber_final", float("nan")),
        "solver_wall_time_s": float(sim.attrs.get("wall_time_s", float("nan"))),
    }


def main(argv=None):
    from fiberpipe.artifacts import write_text_atomic
    from fiberpipe.config import load_raw
    from fiberpipe.studies.fit import load_curve, read_target

    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "specimens" / "paper-40-fitted.yaml"))
    ap.add_argument("--fit", default=str(ROOT / "runs" / "fits" / "paper-40-spool"))
    ap.add_argument("--target", default=str(ROOT / "data-samples" / "paper-40-fit" / "target.csv"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", default=str(ROOT / "runs" / "fits" / "paper-40-fitted"))
    ap.add_argument("--doc", help="Rewrite the fit section of this page (docs/results.md) and copy its figures.")
    a = ap.parse_args(argv)
    where = a.config
    raw = load_raw(a.config)
    radius = spool_radius_m(raw, where)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    fit_dir = Path(a.fit)
    fit = json.loads((fit_dir / "fit.json").read_text()) if (fit_dir / "fit.json").exists() else None
    fit_run = None
    if fit is not None:
        best = fit["best"].get("specimen.bow.spool_radius")
        if best == radius and len(fit["seeds"]) == 1:  # the same inputs, bit for bit
            fit_run = (int(fit["seeds"][0]), fit_dir / "evaluations" / fit["best_runs"][0])
    rows = []
    for seed in a.seeds:
        reuse = fit_run[1] if fit_run is not None and fit_run[0] == seed else None
        spec = specimen_dir(raw, seed, out, where, reuse)
        for name, law in LAWS.items():
            if reuse is not None and law is None:
                run_dir = reuse  # the fit's best evaluation: this specimen with the config's own law
            else:
                run_dir = run_law(spec, law, out / f"seed-{seed}" / name, where)
            m = measure(run_dir)
            rows.append({"law": name, "seed": seed, "run": os.path.relpath(run_dir, out), **m})
            print(f"seed {seed}, {name}: {m['final_load_N']:.4g} N at U = {m['final_U_mm']:.4g} mm", flush=True)
    cols = list(rows[0])
    with (out / "prediction.csv.tmp").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    (out / "prediction.csv.tmp").replace(out / "prediction.csv")
    summary = {"config": a.config, "spool_radius_m": radius, "seeds": a.seeds, "laws": {}, "study_N": STUDY_N}
    for name in LAWS:
        f = np.array([r["final_load_N"] for r in rows if r["law"] == name])
        summary["laws"][name] = {"final_load_N": f.tolist(), "mean_N": float(f.mean()),
                                 "sd_N": float(f.std(ddof=1)) if len(f) > 1 else 0.0,
                                 "min_N": float(f.min()), "max_N": float(f.max())}
    per_seed = {s: {r["law"]: r["final_load_N"] for r in rows if r["seed"] == s} for s in a.seeds}
    summary["parallel_above_oblique_seeds"] = sum(v["parallel"] > v["oblique-6"] for v in per_seed.values())
    write_text_atomic(out / "prediction.json", json.dumps(summary, indent=2) + "\n")
    plot(out, rows, read_target(a.target))
    print(json.dumps(summary["laws"], indent=1))
    if a.doc:
        if fit is None:
            raise SystemExit(f"{fit_dir}/fit.json not found: run make study-fit first")
        write_doc(Path(a.doc), fit, fit_dir, summary, rows, out, radius)


def plot(out: Path, rows: list[dict], target) -> None:
    """The laws' curves over the seeds: against the target (left) and on their own scale (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fiberpipe.post.plots import _save
    from fiberpipe.studies.fit import load_curve

    U_t, F_t = target
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    axes[0].plot(U_t * 1e3, F_t, "ko", ms=3, label="target (the study's text)")
    styles = {"oriented": "-", "parallel": "--", "oblique-6": ":"}
    for k, name in enumerate(LAWS):
        mine = [r for r in rows if r["law"] == name]
        for j, r in enumerate(mine):
            U, F = load_curve(out / r["run"])
            for ax in axes:
                ax.plot(U * 1e3, F, color=f"C{k}", ls=styles.get(name, "-"), lw=1.0,
                        label=f"{name} ({len(mine)} seeds)" if j == 0 else None)
    for ax, title in zip(axes, ("against the target", "the simulated loads")):
        ax.set_xlabel("U [mm]")
        ax.set_ylabel("load [N]")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    _save(fig, out / "prediction.png")


def write_doc(page: Path, fit: dict, fit_dir: Path, summary: dict, rows: list[dict], out: Path, radius: float) -> None:
    """The generated fit section of ``page``: the fit, its history, the laws' final loads over the
    seeds beside the study's, and the two figures (copied to the page's img/ folder)."""
    import shutil

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from generated import replace_section

    img = page.parent / "img"
    img.mkdir(parents=True, exist_ok=True)
    plot_fit(fit_dir, fit, out)
    shutil.copyfile(out / "fit_evaluations.png", img / "paper40_fit.png")
    shutil.copyfile(out / "prediction.png", img / "paper40_fitted_laws.png")
    key = "specimen.bow.spool_radius"
    lo, hi = fit["bounds"][key]
    best_mm = 1e3 * fit["best"][key]
    L = 15e-3  # the fibers' length: the bow's sagitta over it, L^2 / (8 R)
    best_row = next(r for r in rows if r["law"] == "oriented" and r["seed"] == fit["seeds"][0])
    text = [
        "### The fit (`make study-fit`)", "",
        "| parameter | range | evaluations | seed | best | sagitta over 15 mm | RMS load error | final load at U = 1.15 mm |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        f"| `{key}` | {1e3 * lo:.4g}–{1e3 * hi:.4g} mm | {fit['evaluations']} (`{fit['method']}`) | "
        f"{', '.join(str(s) for s in fit['seeds'])} | {best_mm:.4g} mm | {1e3 * L**2 / (8 * fit['best'][key]):.3g} mm | "
        f"{fit['objective_N']:.3g} N ({100 * fit['objective_relative']:.3g} % of the target's RMS load) | "
        f"{best_row['final_load_N']:.3g} N (target 12 N) |", "",
        "| evaluation | spool radius (mm) | sagitta (mm) | v_f0 → v_f | final load (N) | RMS load error (N) | settle steps | compaction solver wall time (s) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *evaluation_rows(fit_dir, key, L), "",
        "![the fitted specimen's curve against the target](img/paper40_fit.png)", "",
        f"### The laws on the fitted specimen ({len(summary['seeds'])} seeds)", "",
        "| contact model | final load at U = 1.15 mm, per seed (N) | mean ± sd (N) | min–max (N) | the study (N) |",
        "| --- | --- | --- | --- | --- |",
    ]
    study = {"oriented": "— (the experiment: ≈ 12)", "parallel": "17", "oblique-6": "9.5"}
    for name, v in summary["laws"].items():
        text.append(f"| {name} | {', '.join(f'{f:.3g}' for f in v['final_load_N'])} | {v['mean_N']:#.3g} ± {v['sd_N']:#.3g} | "
                    f"{v['min_N']:.3g}–{v['max_N']:.3g} | {study[name]} |")
    n = len(summary["seeds"])
    ratio = [next(r["final_load_N"] for r in rows if r["seed"] == s and r["law"] == "parallel")
             / next(r["final_load_N"] for r in rows if r["seed"] == s and r["law"] == "oblique-6") for s in summary["seeds"]]
    text += ["", f"The parallel model carries more than the oblique one on {summary['parallel_above_oblique_seeds']} of {n} "
             f"seeds; parallel / oblique-6 per seed: {', '.join(f'{q:.3f}' for q in ratio)} (the study: 17 N against "
             "9.5 N, 1.79).", "",
             "| seed | contact model | rearrangement until U (mm) | steep rise from U (mm) | v_f0 → v_f | contacts/fiber at U = 1.15 mm |",
             "| --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        steep = "none" if np.isnan(r["steep_start_U_mm"]) else f"{r['steep_start_U_mm']:.3g}"
        text.append(f"| {r['seed']} | {r['law']} | {r['rearrangement_end_U_mm']:.3g} | {steep} | "
                    f"{r['vf_initial']:.3f} → {r['vf_final']:.3f} | {r['contacts_per_fiber_final']:.3g} |")
    text += ["", "The study: rearrangement until U = 0.55 mm, steep rise from 1.12 mm, v_f 37.7 % → 45 % (phase criteria "
             "in [outputs.md](outputs.md#compaction-phases); v_f from `post/geometry.csv`; \"none\": no steep phase).", "",
             "![the laws' curves on the fitted specimen](img/paper40_fitted_laws.png)", ""]
    replace_section(page, FIT_BEGIN, FIT_END, "\n".join(text))


def plot_fit(fit_dir: Path, fit: dict, out: Path) -> None:
    """The target and every evaluation's curve (the best one bold): ``out/fit_evaluations.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fiberpipe.post.plots import _save
    from fiberpipe.studies.fit import load_curve, read_target

    key = "specimen.bow.spool_radius"
    U_t, F_t = read_target(fit["target"])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(U_t * 1e3, F_t, "ko", ms=3, label="target (the study's text)")
    evals = []
    for d in (fit_dir / "evaluations").iterdir():
        sj = d / "specimen" / "specimen.json"
        if sj.exists() and (d / "post" / "force_displacement.csv").exists():
            evals.append((json.loads(sj.read_text())["generator"]["spool_radius_m"], d))
    for R, d in sorted(evals):
        U, F = load_curve(d)
        best = d.name in fit["best_runs"]
        ax.plot(U * 1e3, F, lw=2 if best else 0.9, label=f"R = {1e3 * R:.4g} mm" + (" (best)" if best else ""))
    ax.set_xlabel("U [mm]")
    ax.set_ylabel("load [N]")
    ax.set_title(f"fit of {key}, {fit['evaluations']} evaluations, seed {', '.join(map(str, fit['seeds']))}", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, out / "fit_evaluations.png")


def evaluation_rows(fit_dir: Path, key: str, L: float) -> list[str]:
    """One table row per evaluation of the fit (history.csv's order), its figures read from its run."""
    with (fit_dir / "history.csv").open(newline="") as fh:
        hist = list(csv.DictReader(fh))
    runs = {}
    for d in sorted((fit_dir / "evaluations").iterdir()):
        if (d / "specimen" / "specimen.json").exists() and (d / "post" / "summary.json").exists():
            sj = json.loads((d / "specimen" / "specimen.json").read_text())
            runs[sj["generator"]["spool_radius_m"]] = (d, sj)
    out = []
    for h in hist:
        R = float(h[key])
        match = [v for r, v in runs.items() if abs(r - R) <= 1e-8 * R]
        if len(match) != 1:
            raise SystemExit(f"{fit_dir}: no single evaluation folder for {key} = {R}")
        d, sj = match[0]
        m = measure(d)
        out.append(f"| {h['evaluation']} | {1e3 * R:.4g} | {1e3 * L**2 / (8 * R):.3g} | {m['vf_initial']:.3f} → "
                   f"{m['vf_final']:.3f} | {m['final_load_N']:.3g} | {float(h['objective_N']):.4g} | "
                   f"{sj['settle']['steps']} | {m['solver_wall_time_s']:.0f} |")
    return out


FIT_BEGIN, FIT_END = "<!-- fit: begin", "<!-- fit: end"


if __name__ == "__main__":
    sys.exit(main())
