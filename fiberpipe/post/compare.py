"""Gather the curves of several runs into one comparison plot and table (``make reproduce``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import ensure_output_dir, read_json_mapping, write_text_atomic
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


def _figure(summary: dict, key: str) -> float:
    """A number of a post summary; NaN where it is missing or null (a figure that could not be computed)."""
    v = summary.get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else float("nan")


def _diverged_row(name: str) -> dict:
    nan = float("nan")
    return {"run": name, "final_load_N": nan, "max_load_N": nan, "rearrangement_end_U_mm": nan, "steep_start_U_mm": nan,
            "peak_ke_over_se": nan, "energy_residual": nan, "contact_energy_created_over_WK": nan, "steps": 0,
            "solver_wall_time_s": nan, "note": "diverged (see its run.log)"}


def _run_row(d: Path) -> tuple[dict, tuple | None]:
    """A run folder's row of the table and its (U, F) curve (None without plates)."""
    sim = load_simulation(d / "simulation.h5")
    summary = _post_summary(d / "post" / "summary.json")
    curve = None
    try:
        U, F = force_displacement(sim)
        curve = (U, F)
        final, peak = float(F[-1]), float(np.max(F))
        ph = compaction_phases(U, F)
        u1, u2 = (float("nan") if ph[k] is None else 1e3 * ph[k] for k in ("rearrangement_end_U_m", "steep_start_U_m"))
    except KeyError:
        final = peak = u1 = u2 = float("nan")
    # from the run's history, not its summary.json: runs post-processed before the figure existed have it too
    created = contact_energy_created_figures(sim.energy)[1] if sim.energy else float("nan")
    row = {
        "run": d.name,
        "final_load_N": final,
        "max_load_N": peak,
        "rearrangement_end_U_mm": u1,
        "steep_start_U_mm": u2,
        "peak_ke_over_se": _figure(summary, "peak_ke_over_se"),
        "energy_residual": _figure(summary, "energy_balance_residual_max"),
        "contact_energy_created_over_WK": created,
        "steps": int(sim.attrs.get("steps", 0)),
        "solver_wall_time_s": float(sim.attrs.get("wall_time_s", float("nan"))),
        "note": "",
    }
    return row, curve


def compare_runs(run_dirs: list[Path], out_dir: Path) -> str:
    """Write ``comparison.png`` (F(U) of every run) and ``comparison.md`` (key figures); return the table."""
    # every run read (one at a time) before the output folder is made: a refused comparison leaves
    # nothing behind
    curves, rows = {}, []
    for d in map(Path, run_dirs):
        if (d / "simulation.h5").exists():
            row, curve = _run_row(d)
            rows.append(row)
            if curve is not None:
                curves[d.name] = curve
        elif (d / "simulation_diverged.h5").exists():
            rows.append(_diverged_row(d.name))
        else:
            raise InputError(f"{d} has no simulation.h5: run it first")
    out_dir = ensure_output_dir(out_dir)
    if curves:
        plot_force_displacement(out_dir / "comparison.png", curves, title="compaction load, all runs")
    cols = list(rows[0]) if rows else []
    lines = ["| " + " | ".join(cols) + " |", "|" + " --- |" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in r.values()) + " |")
    table = "\n".join(lines)
    write_text_atomic(out_dir / "comparison.md", "# Comparison\n\n" + table + "\n\n![F(U)](comparison.png)\n")
    return table
