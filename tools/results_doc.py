"""Regenerate the generated section of docs/results.md from the runs of `make reproduce`.

    .venv/bin/python tools/results_doc.py [--runs runs/reproduce]

For each run: the final and peak load, the three phases of the study's compaction curve
(:func:`fiberpipe.post.phases.compaction_phases`: rearrangement until the 0.05 mm window means of
the load exceed 2 % of their peak, a steep rise where a two-segment fit's last slope is ≥ 1.5× the
mean slope since then), energy figures and wall time; beside them the study's figures (its
section 4: experiment ≈ 12 N, parallel model 17 N, oblique 6° 9.5 N; rearrangement 0–0.55 mm,
transition 0.55–1.12 mm, locking from 1.12 mm). Only the section between the page's `results`
markers is rewritten.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from generated import replace_section  # noqa: E402

BEGIN, END = "<!-- results: begin", "<!-- results: end"

STUDY = {
    "paper-40": "experiment ≈ 12 N at U = 1.15 mm; rise from U ≈ 0.55 mm",
    "paper-40-parallel": "17 N (parallel model, Φ = 0) at U = 1.15 mm",
    "paper-40-oblique-6": "9.5 N (oblique model, Φ = 6°) at U = 1.15 mm, below parallel",
    "paper-40-alpha-0": "(α = 0: the study's Table 2 asks what damping costs)",
    "paper-40-alpha-1e4": "",
    "paper-40-compaction": "— (orientation-aware law: the study's open problem)",
    "paper-40-compaction-parallel": "(U = 3 mm) parallel model, Φ = 0",
    "paper-40-compaction-oblique-6": "(U = 3 mm) oblique model, Φ = 6°",
    "paper-40-compaction-identified": "within ≈ 11 % of the experiment (identified model)",
}


def main(argv=None):
    from fiberpipe.post.curves import force_displacement
    from fiberpipe.post.history import load_simulation
    from fiberpipe.post.phases import compaction_phases

    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", default=str(ROOT / "runs" / "reproduce"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "results.md"))
    a = ap.parse_args(argv)
    runs = sorted(p for p in Path(a.runs).iterdir() if (p / "simulation.h5").exists())
    diverged = sorted(p for p in Path(a.runs).iterdir() if not (p / "simulation.h5").exists() and (p / "simulation_diverged.h5").exists())
    rows = []
    for d in runs:
        sim = load_simulation(d / "simulation.h5")
        U, F = force_displacement(sim)
        s = json.loads((d / "post" / "summary.json").read_text()) if (d / "post" / "summary.json").exists() else {}
        ph = compaction_phases(U, F)
        mm = lambda v: float("nan") if v is None else 1e3 * v  # noqa: E731
        rows.append({
            "run": d.name,
            "final U (mm)": 1e3 * float(U[-1]),
            "final load (N)": float(F[-1]),
            "peak load (N)": float(np.max(F)),
            "rearrangement until U (mm)": mm(ph["rearrangement_end_U_m"]),
            "steep rise from U (mm)": mm(ph["steep_start_U_m"]),
            "steepness": float("nan") if ph["steepness"] is None else ph["steepness"],
            "v_f0 → v_f": f"{s.get('vf_initial', float('nan')):.3f} → {s.get('vf_final', float('nan')):.3f}",
            "peak K_e/S_e": s.get("peak_ke_over_se", float("nan")),
            "energy residual": s.get("energy_balance_residual_max", float("nan")),
            "contacts/fiber (final)": s.get("contacts_per_fiber_final", float("nan")),
            "solver wall time (s)": float(sim.attrs.get("wall_time_s", float("nan"))),
            "study": STUDY.get(d.name, ""),
        })
    cols = list(rows[0]) if rows else []
    fmt = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)  # noqa: E731
    table = ["| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]
    table += ["| " + " | ".join(fmt(r[c]) for c in cols) + " |" for r in rows]
    img = ROOT / "docs" / "img"
    img.mkdir(parents=True, exist_ok=True)
    comp = Path(a.runs) / "comparison" / "comparison.png"
    if comp.exists():
        shutil.copyfile(comp, img / "reproduce_comparison.png")
    p40 = Path(a.runs) / "paper-40" / "post" / "force_displacement.png"  # its phases shaded
    if p40.exists():
        shutil.copyfile(p40, img / "paper40_force_displacement.png")
    text = ["## The runs of `make reproduce`", "", *table, "", "![F(U) of every run](img/reproduce_comparison.png)", ""]
    if diverged:
        text += ["### Runs that diverged", ""]
        for d in diverged:
            log = (d / "run.log").read_text() if (d / "run.log").exists() else ""
            why = next((ln.split("stopped: ", 1)[1] for ln in log.splitlines() if "simulate stopped: " in ln), "see run.log")
            text += [f"- `{d.name}`: {why}", ""]
    replace_section(Path(a.out), BEGIN, END, "\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
