"""The study's compaction predicted from its own statistics, nothing fitted (``make study-prediction``).

    .venv/bin/python tools/study_prediction.py [--config configs/specimens/study-prediction.yaml]
        [--seeds 8] [--fast-only] [--out runs/study-prediction] [--figure docs/img/study_prediction.png]
        [--doc docs/results.md]

Compacts one specimen per seed of ``--config`` (an ensemble, :mod:`fiberpipe.studies.ensemble`) at
the fast settings (mass scaling 100 with α/100: docs/benchmarks.md, "Fast settings") and, unless
``--fast-only``, its first two seeds again at the study's settings on the same specimens, which
measures what the fast settings cost in accuracy here. Writes ``OUT/ensemble.json`` (per seed: v_f0,
the final load, the closing's residual load; the mean with its 95 % interval; the fast settings'
error; the RMS against the study's curve points) and the F(U) band against the study's curve as its
text gives it (``data-samples/paper-40-fit/target.csv``) into ``--figure``; with ``--doc``, the
figures between the markers ``<!-- prediction: begin -->`` and ``<!-- prediction: end -->``. A seed
whose simulation diverges is named (``diverged``: seed, step, the solver's diagnosis) and left out
of the mean and band.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

FAST = {"solver.mass_scaling": 100, "scene.damping.alpha": "1e3 1/s"}  # docs/benchmarks.md, "Fast settings"
TARGET = ROOT / "data-samples" / "paper-40-fit" / "target.csv"
BEGIN, END = "<!-- prediction: begin", "<!-- prediction: end -->"


def _with(raw: dict, overrides: dict) -> dict:
    from fiberpipe.config import set_dotted

    raw = copy.deepcopy(raw)
    for key, value in overrides.items():
        set_dotted(raw, key, value)
    return raw


def fast_settings_error(fast: dict, study: dict) -> dict:
    """The fast settings against the study's on the same specimens, per seed both finished: the final
    loads, their difference (N and relative), and the RMS of the curves' difference over the study's
    curve points (N and over the study-settings curve's RMS there). A seed either run diverged in is
    left out (``diverged`` of each ensemble names it)."""
    from fiberpipe.studies.fit import load_curve, read_target

    U_t, _ = read_target(TARGET)
    both = [seed for seed in study["seeds"] if seed in fast["seeds"]]
    per_seed = []
    for seed in both:
        U_s, F_s = load_curve(Path(study["runs"][study["seeds"].index(seed)]))
        U_f, F_f = load_curve(Path(fast["runs"][fast["seeds"].index(seed)]))
        diff = np.interp(U_s, U_f, F_f) - F_s
        at_points = np.interp(U_t, U_f, F_f) - np.interp(U_t, U_s, F_s)
        per_seed.append({"seed": seed, "study_settings_N": float(F_s[-1]), "fast_N": float(F_f[-1]),
                         "final_load_difference_N": float(F_f[-1] - F_s[-1]),
                         "final_load_difference": float(F_f[-1] / F_s[-1] - 1) if F_s[-1] else float("nan"),
                         "curve_points_rms_difference_N": float(np.sqrt(np.mean(at_points**2))),
                         "curve_rms_difference": float(np.sqrt(np.mean(diff**2)) / max(np.sqrt(np.mean(F_s**2)), 1e-300))})
    return {"seeds": per_seed,
            "study_settings_solver_wall_time_s": [study["solver_wall_time_s"][study["seeds"].index(s)] for s in both],
            "fast_solver_wall_time_s": [fast["solver_wall_time_s"][fast["seeds"].index(s)] for s in both],
            "diverged": {"study_settings": study.get("diverged", []), "fast": fast.get("diverged", [])}}


def against_study(folder: Path) -> dict:
    """The ensemble mean's RMS difference from the study's curve points (``target.csv``), over 12 N;
    and the same for the mean curve times the factor that fits it best (least squares,
    c = Σ F_mean F_study / Σ F_mean²): the RMS no unknown that scales the load without changing the
    curve's shape can go below."""
    from fiberpipe.studies.fit import read_target

    U_t, F_t = read_target(TARGET)
    table = np.genfromtxt(folder / "ensemble.csv", delimiter=",", names=True)
    mean = np.interp(U_t, table["U_m"], table["load_mean_N"])
    rms = float(np.sqrt(np.mean((mean - F_t) ** 2)))
    scale = float(mean @ F_t / (mean @ mean)) if np.any(mean) else float("nan")
    return {"rms_N": rms, "rms_over_12N": rms / 12.0, "mean_at_1.15mm_N": float(mean[-1]),
            "mean_at_0.55mm_N": float(np.interp(0.55e-3, U_t, mean)), "best_scale": scale,
            "best_scaled_rms_N": float(np.sqrt(np.mean((scale * mean - F_t) ** 2)))}


def geometry_per_seed(ensemble: dict) -> list[dict]:
    """Each run's ``post/geometry.csv`` at U = 0 and at its end: v_f (the study's definition) and the
    Table 4 measure, the mean projected curvatures (the study: 0.241 / 0.248 at U = 0 and 0.228 /
    0.221 at U = 1.15 mm, in its "m⁻¹")."""
    rows = []
    for seed, run in zip(ensemble["seeds"], ensemble["runs"]):
        table = np.genfromtxt(Path(run) / "post" / "geometry.csv", delimiter=",", names=True)
        pick = {"v_f": "volume_fraction", "curvature_xz_per_m": "curvature_xz_per_m",
                "curvature_yz_per_m": "curvature_yz_per_m", "contacts_per_fiber": "contacts_per_fiber",
                "max_penetration_m": "max_penetration_m"}
        rows.append({"seed": seed, **{f"{k}_U0": float(table[c][0]) for k, c in pick.items()},
                     **{f"{k}_end": float(table[c][-1]) for k, c in pick.items()}})
    return rows


def plot(folder: Path, figure: Path, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fiberpipe.post.plots import _save
    from fiberpipe.studies.fit import read_target

    table = np.genfromtxt(folder / "ensemble.csv", delimiter=",", names=True)
    U = table["U_m"] * 1e3
    seeds = [c for c in table.dtype.names if c.startswith("load_seed_")]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for k, c in enumerate(seeds):
        ax.plot(U, table[c], color="0.65", lw=0.7, label="one specimen seed" if k == 0 else None)
    mean, sd = table["load_mean_N"], table["load_sd_N"]
    ax.fill_between(U, mean - sd, mean + sd, color="C0", alpha=0.3, label="ensemble mean ± 1 sd")
    ax.plot(U, mean, "C0-", label=f"ensemble mean ({len(seeds)} seeds)")
    U_t, F_t = read_target(TARGET)
    ax.plot(U_t * 1e3, F_t, "k--", lw=1, label="the study's curve as its text gives it")
    ax.plot([0.55, 1.12, 1.15], [0.24, 9.31, 12.0], "ko", ms=4, label="the study's stated points")
    ax.set_xlabel("U [mm]")
    ax.set_ylabel("load [N]")
    left = [d["seed"] for d in summary.get("diverged", [])]
    ax.set_title(f"prediction from the study's statistics: {summary['final_load_mean_N']:.2f} N at 1.15 mm (study ≈ 12 N)"
                 + (f"\nseed(s) {', '.join(map(str, left))} diverged, left out" if left else ""), fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, figure)


def _diverged_words(diverged: list[dict]) -> str:
    return "; ".join(f"seed {d['seed']} diverged in the {d['stage']}"
                     + (f" at step {d['step']} (t = {d['time_s']:.4g} s)" if d.get("step") is not None else "")
                     + f", left out ({d['diagnosis'].split(': ', 1)[-1].split(';')[0]})" for d in diverged)


def _span(values, scale: float = 1.0, digits: str = ".3g") -> str:
    low, high = min(values) * scale, max(values) * scale
    return f"{low:{digits}}" if f"{low:{digits}}" == f"{high:{digits}}" else f"{low:{digits}}–{high:{digits}}"


def specimen_lines(summary: dict) -> list[str]:
    """The finished seeds' specimens and runs, as ranges over the seeds: v_f at U = 0 and at the end,
    what closing the pile left on the plate and the walls, the neighbour angles, the Table 4 curvatures."""
    import json

    infos = [json.loads((Path(d) / "specimen.json").read_text()) for d in summary["specimens"]]
    closing = [info.get("closing") or {} for info in infos]
    geometry = summary["geometry"]
    lines = [f"- **Volume fractions.** The runs start at v_f {_span([g['v_f_U0'] for g in geometry])} "
             f"(`post/geometry.csv`, the study's definition) and end at {_span([g['v_f_end'] for g in geometry])} "
             "(the study: 37.7 % → 45 %)."]
    if all(c.get("residual_load_N") is not None for c in closing):
        lines.append(f"- **What closing left.** {_span([c['residual_load_N'] for c in closing], digits='.2g')} N on the "
                     f"upper plate and {_span([c.get('wall_load_N', float('nan')) for c in closing], digits='.2g')} N on "
                     "the walls after the closing's relaxation (not in the compaction's curve, which starts from the "
                     "closed shape as its rest shape).")
    lines.append(f"- **Neighbour angles.** The closed piles measure Φ "
                 f"{_span([i['statistics']['phi_mean_deg'] for i in infos], digits='.3g')}° on average (the study: 6°).")
    lines.append("- **Curvature under load** (Table 4's measure, XZ and YZ projections). At U = 0 "
                 f"{_span([g['curvature_xz_per_m_U0'] for g in geometry] + [g['curvature_yz_per_m_U0'] for g in geometry])}"
                 f" 1/m, at the end {_span([g['curvature_xz_per_m_end'] for g in geometry] + [g['curvature_yz_per_m_end'] for g in geometry])}"
                 " 1/m (the study, read in 1/cm: 24.1 / 24.8 → 22.8 / 22.1 1/m).")
    return lines


def doc_markdown(summary: dict, command: str) -> str:
    """The generated section of docs/results.md: the band at U = 1.15 mm, the RMS from the study's
    points, the seeds left out, the fast settings' error where measured."""
    stats, study = summary["final_load_statistics"], summary["against_study"]
    loads = summary["final_load_N"]
    lines = [f"{BEGIN} (generated by tools/study_prediction.py from {command}) -->", "",
             f"**Result ({stats['n']} seeds: {', '.join(str(s) for s in summary['seeds'])}; {summary['settings']}).** "
             f"At U = 1.15 mm the ensemble carries {stats['mean_N']:.3g} N (95 % interval of the mean "
             f"± {stats['mean_ci95_half_width_N']:.2g} N; sample sd {stats['sd_N']:.3g} N; per seed "
             f"{', '.join(f'{v:.3g}' for v in loads)} N; range {min(loads):.3g}–{max(loads):.3g} N); the study's "
             f"experiment carries about 12 N. The ensemble mean's RMS difference from the study's 28 curve points is "
             f"{study['rms_N']:.3g} N ({100 * study['rms_over_12N']:.0f} % of 12 N); at U = 0.55 mm it carries "
             f"{study['mean_at_0.55mm_N']:.3g} N (the study: near zero). Scaled by the factor that fits it best "
             f"({study['best_scale']:.3g}), the mean curve would still miss the points by {study['best_scaled_rms_N']:.3g} N "
             f"RMS ({100 * study['best_scaled_rms_N'] / 12:.0f} % of 12 N): its shape's own error.",
             ""]
    diverged = summary.get("diverged", [])
    lines.append(f"- **Seeds left out.** {_diverged_words(diverged)}." if diverged
                 else "- **Seeds left out.** None: every seed ran to U = 1.15 mm.")
    lines += specimen_lines(summary)
    error = summary.get("fast_settings_error")
    if error is None:
        lines += ["", "The fast settings' error is not measured by this command (run it without `FAST=1`)."]
    elif "error" in error:
        lines += ["", f"The study's settings did not run: {error['error']}."]
    elif error is not None:
        lines += ["", "| seed | study's settings F(1.15 mm) (N) | fast F(1.15 mm) (N) | difference (N) | "
                  "RMS difference over the 28 curve points (N) | solver wall time, study's / fast (s) |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for k, row in enumerate(error["seeds"]):
            lines.append(f"| {row['seed']} | {row['study_settings_N']:.3g} | {row['fast_N']:.3g} | "
                         f"{row['final_load_difference_N']:+.3g} ({100 * row['final_load_difference']:+.0f} %) | "
                         f"{row['curve_points_rms_difference_N']:.3g} | {error['study_settings_solver_wall_time_s'][k]:.0f} / "
                         f"{error['fast_solver_wall_time_s'][k]:.0f} |")
        left = error["diverged"]["study_settings"]
        if left:
            lines += ["", f"At the study's settings: {_diverged_words(left)}."]
    return "\n".join(lines + ["", END])


def main(argv=None) -> int:
    from fiberpipe.artifacts import write_json_atomic
    from fiberpipe.config import load_raw
    from fiberpipe.errors import ConfigError, SimulationDiverged
    from fiberpipe.studies.ensemble import final_load_statistics, run_ensembles

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "specimens" / "study-prediction.yaml"))
    ap.add_argument("--seeds", type=int, help="the first N seeds of specimen.seeds (default: all)")
    ap.add_argument("--fast-only", action="store_true", help="skip the study-settings runs of the first two seeds")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "runs" / "study-prediction"))
    ap.add_argument("--figure", help="the F(U) band against the study's points (default: OUT/prediction.png)")
    ap.add_argument("--doc", help="a page whose prediction markers get the figures (docs/results.md)")
    ap.add_argument("--command", default="make study-prediction", help="the command the --doc section names")
    args = ap.parse_args(argv)
    raw = load_raw(args.config)
    seeds = list(raw["specimen"]["seeds"])[: args.seeds or None]
    out = Path(args.out)
    # the study-settings runs first (the longest), the fast ones after
    ensembles = {} if args.fast_only else {"study-settings": (raw, seeds[:2], out / "study-settings")}
    ensembles["fast"] = (_with(raw, FAST), seeds, out / "fast")
    # keep_going: the study-settings seeds diverging (or refused) leave the fast ensemble standing
    results = run_ensembles(ensembles, workers=args.workers, specimen_store=out / "specimens", where=args.config,
                            keep_going=True)
    fast = results["fast"]
    if "error" in fast:  # no fast seed finished
        raise (SimulationDiverged if "diverged" in fast else ConfigError)(fast["error"])
    summary = {**fast, "settings": "fast: " + ", ".join(f"{k} = {v}" for k, v in FAST.items()),
               "final_load_statistics": final_load_statistics(fast["final_load_N"]),
               "against_study": against_study(out / "fast"), "geometry": geometry_per_seed(fast)}
    if "error" in results.get("study-settings", {}):
        summary["fast_settings_error"] = {"error": results["study-settings"]["error"]}
    elif "study-settings" in results:
        summary["fast_settings_error"] = fast_settings_error(fast, results["study-settings"])
    write_json_atomic(out / "ensemble.json", summary)
    plot(out / "fast", Path(args.figure) if args.figure else out / "prediction.png", fast)
    stats = summary["final_load_statistics"]
    left = f"; {_diverged_words(fast['diverged'])}" if fast.get("diverged") else ""
    print(f"F(U = 1.15 mm) = {stats['mean_N']:.3g} ± {stats['mean_ci95_half_width_N']:.2g} N (95 % interval of the "
          f"mean, {stats['n']} seeds, sd {stats['sd_N']:.3g} N){left}; the study ≈ 12 N; {out}/ensemble.json")
    if args.doc:
        from generated import replace_marked

        replace_marked(Path(args.doc), BEGIN, END, doc_markdown(summary, args.command))
    return 0


def cli(argv=None) -> int:
    """:func:`main`, a problem the user can fix as one line (:func:`generated.run_cli`)."""
    from generated import run_cli

    return run_cli(main, argv)


if __name__ == "__main__":
    sys.exit(cli())
