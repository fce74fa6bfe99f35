"""Gather the curves of several runs into one comparison plot and table (``make reproduce``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_json_mapping, write_text_atomic
from fiberpipe.errors import ArtifactError, InputError
from fiberpipe.post.curves import force_displacement
from fiberpipe.post.energies import contact_energy_created_figures
from fiberpipe.post.history import load_simulation
from fiberpipe.post.phases import compaction_phases
from fiberpipe.post.plots import plot_force_displacement


def _post_summary(path: Path) -> dict:
    """A run's ``post/summary.json`` ({} without one); one that is not a JSON mapping is an
    InputError naming it (rerun the run's post stage)."""
    try:
        return read_json_mapping(path)
    except ArtifactError as exc:
        raise InputError(f"{exc}; rerun its post stage (fiberpipe post CONFIG --out RUN)") from None


def compare_runs(run_dirs: list[Path], out_dir: Path) -> str:
    """Write ``comparison.png`` (F(U) of every run) and ``comparison.md`` (key figures); return the table."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    curves, rows = {}, []
    for d in run_dirs:
        d = Path(d)
        sim_path = d / "simulation.h5"
        if not sim_path.exists():
            if (d / "simulation_diverged.h5").exists():
                rows.append({"run": d.name, "final_load_N": float("nan"), "max_load_N": float("nan"),
                             "rearrangement_end_U_mm": float("nan"), "steep_start_U_mm": float("nan"),
                             "peak_ke_over_se": float("nan"), "energy_residual": float("nan"),
                             "contact_energy_created_over_WK": float("nan"), "steps": 0,
                             "solver_wall_time_s": float("nan"), "note": "diverged (see its run.log)"})
                continue
            raise InputError(f"{d} has no simulation.h5: run it first")
        sim = load_simulation(sim_path)
        name = d.name
        summary = _post_summary(d / "post" / "summary.json")
        try:
            U, F = force_displacement(sim)
            curves[name] = (U, F)
            final = float(F[-1])
            peak = float(np.max(F))
            ph = compaction_phases(U, F)
            u1, u2 = (float("nan") if ph[k] is None else 1e3 * ph[k] for k in ("rearrangement_end_U_m", "steep_start_U_m"))
        except KeyError:
            final = peak = u1 = u2 = float("nan")
        # from the run's history, not its summary.json: runs post-processed before the figure existed have it too
        created = contact_energy_created_figures(sim.energy)[1] if sim.energy else float("nan")
        rows.append(
            {
                "run": name,
                "final_load_N": final,
                "max_load_N": peak,
                "rearrangement_end_U_mm": u1,
                "steep_start_U_mm": u2,
                "peak_ke_over_se": summary.get("peak_ke_over_se", float("nan")),
                "energy_residual": summary.get("energy_balance_residual_max", float("nan")),
                "contact_energy_created_over_WK": created,
                "steps": int(sim.attrs.get("steps", 0)),
                "solver_wall_time_s": float(sim.attrs.get("wall_time_s", float("nan"))),
                "note": "",
            }
        )
    if curves:
        plot_force_displacement(out_dir / "comparison.png", curves, title="compaction load, all runs")
    cols = list(rows[0]) if rows else []
    lines = ["| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r.values()) + " |")
    table = "\n".join(lines)
    write_text_atomic(out_dir / "comparison.md", "# Comparison\n\n" + table + "\n\n![F(U)](comparison.png)\n")
    return table
