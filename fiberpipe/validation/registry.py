"""The validation cases (one module each, a ``validate(quick)`` function) and their runner.

``run_cases`` runs the chosen cases, writes ``summary.json`` (every row: reference, source,
tolerance, the value per seed, mean, spread, pass or fail) and, for a full run, the generated section
of docs/validation.md with its table and figure."""

from __future__ import annotations

import importlib
import math
import time
from pathlib import Path

from ..errors import FiberpipeError

#: case name → (module of fiberpipe.validation, one-line description); the order of docs/validation.md
CASES = {
    "wavy_fiber": ("wavy_fiber", "1: one wavy fiber between frictionless plates vs the continuous beam"),
    "network_3d": ("network_cases", "2: random 3D network: van Wyk/Toll exponent, contacts per fiber vs Toll"),
    "planar_mat": ("network_cases", "3: planar random mat: Toll's planar exponent"),
    "wavy_bundle": ("network_cases", "4: aligned wavy bundle: Gutowski's law, span/rise from A_s"),
    "friction_cycles": ("friction_cycles", "5: friction shift, a load-unload-reload loop's energy balance and area"),
    "janssen": ("janssen", "6: wall friction in the confined cassette vs Janssen"),
    "quasi_static": ("quasi_static", "7: quasi-static: half the loading speed, K_e against S_e"),
    "wall_correction": ("wall_correction", "8: the walls' share: case 4 at three cassette widths, extrapolated to infinite width"),
}

DOCS_PAGE = Path(__file__).resolve().parents[2] / "docs" / "validation.md"
BEGIN, END = "<!-- validation: begin", "<!-- validation: end"


def case_function(name: str):
    """The ``validate`` function of case ``name`` (one-line error for an unknown name)."""
    if name not in CASES:
        raise FiberpipeError(f"validate: unknown case {name!r}; the cases are {', '.join(CASES)}")
    module = importlib.import_module(f"fiberpipe.validation.{CASES[name][0]}")
    return getattr(module, f"validate_{name}", None) or module.validate


def run_cases(names=None, *, quick: bool = False, echo=print, work: Path | None = None, seeds=None,
              reuse_only: bool = False) -> dict:
    """Run the cases ``names`` (default all) and return the summary: rows (as dicts) and wall times.
    ``work``: the folder of the specimens and runs (default a temporary one); ``seeds``: the
    specimen seeds of the compaction cases (default 0, 1, 2); ``reuse_only``: read the runs already in
    ``work`` and leave out the seeds without one (nothing is run)."""
    from .compaction_runs import SEEDS, WORK, seeds_for

    names = list(names or CASES)
    for name in names:
        case_function(name)  # refuse an unknown name before anything runs
    if seeds is not None and (not seeds or any(s < 0 for s in seeds)):
        raise FiberpipeError(f"validate: --seeds must be one or more seeds >= 0, got {list(seeds)}")
    SEEDS["seeds"] = tuple(seeds) if seeds is not None else None
    if work is not None:
        WORK["dir"] = Path(work)
    WORK["reuse_only"] = reuse_only
    summary = {"quick": quick, "seeds": seeds_for(quick), "reuse_only": reuse_only, "cases": {}}
    for name in names:
        t0, c0 = time.perf_counter(), time.process_time()
        rows = case_function(name)(quick=quick)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        summary["cases"][name] = {"description": CASES[name][1], "wall_time_s": wall, "cpu_time_s": cpu,
                                  "rows": [r.as_dict() for r in rows]}
        for r in rows:
            echo(f"{r.status:14s} {r.case}: {r.quantity}: {format_value(r.measured, r.unit)} "
                 f"(reference {format_value(r.reference, r.unit)}, error {format_error(r)})")
    checked = [r for c in summary["cases"].values() for r in c["rows"] if not r["informational"]]
    summary["passed"] = sum(r["passed"] for r in checked)
    summary["checked"] = len(checked)
    return summary


def format_value(value: float, unit: str = "") -> str:
    if value is None or not math.isfinite(value):
        return "–"
    return f"{value:.4g}" + (f" {unit}" if unit else "")


def format_error(row) -> str:
    get = row.get if isinstance(row, dict) else (lambda k: getattr(row, k))
    error, tolerance = get("error"), get("tolerance")
    if error is None or not math.isfinite(error):
        return "–"
    if get("bounds"):
        return f"quick range {get('bounds')[0]:.3g} to {get('bounds')[1]:.3g}"
    if get("relative"):
        return f"{100 * error:.3g} % (tolerance {100 * tolerance:.3g} %)"
    return f"{error:.3g} (bound {tolerance:.3g})"


def table_markdown(summary: dict) -> str:
    """The table of every row: case, quantity, reference and source, measured (mean ± spread over
    the seeds), error, tolerance, result."""
    lines = ["| case | quantity | reference | source | measured (mean ± spread, seeds) | error | tolerance | result |",
             "|---|---|---|---|---|---|---|---|"]
    def cell(text: str) -> str:  # a cell's own bars (|sin γ|) would split the row
        return str(text).replace("|", "\\|")

    for case in summary["cases"].values():
        for r in case["rows"]:
            spread = f" ± {r['spread']:.3g}" if r["seeds"] > 1 and math.isfinite(r["spread"]) else ""
            tol = f"{100 * r['tolerance']:.3g} %" if r["relative"] else f"≤ {r['tolerance']:.3g}"
            if r.get("bounds"):
                tol = f"{r['bounds'][0]:.3g} to {r['bounds'][1]:.3g} (quick)"
            err = f"{100 * r['error']:.3g} %" if r["relative"] and not r.get("bounds") and math.isfinite(r["error"]) else (
                f"{r['error']:.3g}" if math.isfinite(r["error"]) else "–")
            note = f" — {r['note']}" if r["note"] else ""
            flag = " (seed spread above the tolerance)" if r["spread_exceeds_tolerance"] else ""
            reference = format_value(r["reference"], r["unit"]) if r["relative"] else "–"
            lines.append(f"| {cell(r['case'])} | {cell(r['quantity'] + note)} | {reference} | "
                         f"{cell(r['source'])} | {format_value(r['measured'], r['unit'])}{spread} ({r['seeds']}){flag} | "
                         f"{err} | {tol} | {r['status']} |")
    return "\n".join(lines)


def write_outputs(summary: dict, out: Path, *, docs_page: Path | None = None) -> None:
    """``out``/summary.json, ``out``/validation.md (the table) and the figure; with ``docs_page`` the
    table and figure also go into its generated section."""
    from ..artifacts import write_json_atomic, write_text_atomic

    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "summary.json", summary)
    table = table_markdown(summary)
    figure = write_figure(summary, out / "validation.png")
    curves = write_curves_figure(summary, out / "validation_curves.png")
    write_text_atomic(out / "validation.md", table + "\n")
    if docs_page is not None:
        image_dir = docs_page.parent / "img"
        image_dir.mkdir(exist_ok=True)
        command = "fiberpipe validate" + (" --quick" if summary["quick"] else "") + (" --reuse" if summary.get("reuse_only") else "")
        times = ("the compaction cases read from the runs in the work folder; " if summary.get("reuse_only") else "") + \
            "CPU (wall) time per case: " + ", ".join(
                f"{name} {c.get('cpu_time_s', float('nan')):.0f} s ({c['wall_time_s']:.0f} s)"
                for name, c in summary["cases"].items())
        seeds = f" (seeds {', '.join(map(str, summary['seeds']))})" if summary.get("seeds") else ""
        text = [f"`{command}`{seeds}: {summary['passed']} of "
                f"{summary['checked']} checked rows pass; {times}. A seed count below 3 in the table: the seeds "
                "whose runs were not in the work folder are left out.", "", table]
        if figure is not None:
            target = image_dir / "validation.png"
            target.write_bytes(figure.read_bytes())
            text += ["", "![measured against reference, each row's error over its tolerance](img/validation.png)"]
        if curves is not None:
            (image_dir / "validation_curves.png").write_bytes(curves.read_bytes())
            text += ["", "![pressure against v_f of every compaction run, one colour per seed](img/validation_curves.png)"]
        replace_section(docs_page, "\n".join(text))


def write_figure(summary: dict, path: Path) -> Path | None:
    """Each row's error as a fraction of its tolerance (1 = the tolerance), one bar per row."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    rows = [r for c in summary["cases"].values() for r in c["rows"]
            if math.isfinite(r["error"]) and not r.get("bounds")]  # a quick row's range has no ratio
    if not rows:
        return None
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(rows) + 1.2))
    ratio = [max(r["error"] / r["tolerance"], 1e-3) for r in rows]
    colours = ["tab:green" if r["passed"] else ("tab:gray" if r["informational"] else "tab:red") for r in rows]
    ax.barh(range(len(rows)), ratio, color=colours)
    ax.set_xscale("log")
    ax.axvline(1.0, color="k", lw=1)
    ax.set_yticks(range(len(rows)), [f"{r['case'].split()[0]}: {r['quantity'][:60]}" for r in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("error / tolerance (pass below 1; rows without a value left out)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_curves_figure(summary: dict, path: Path) -> Path | None:
    """log p against log v_f of the compaction runs behind the law rows, one panel per row."""
    panels = [(r["case"], r["data"]["curves"]) for c in summary["cases"].values() for r in c["rows"]
              if r.get("data", {}).get("curves")]
    if not panels:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(4 * len(panels), 3.4), squeeze=False)
    for ax, (case, curves) in zip(axes[0], panels):
        for curve in curves:
            kept = [(v, q) for v, q in zip(curve["vf"], curve["pressure_pa"]) if q > 0]
            ax.loglog([v for v, _ in kept], [q for _, q in kept], label=f"seed {curve['seed']}")
        ax.set_title(case, fontsize=9)
        ax.set_xlabel("fiber volume fraction v_f [-]")
        ax.set_ylabel("pressure p [Pa]")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def replace_section(page: Path, text: str) -> None:
    """Write ``text`` between the page's begin and end markers (atomic); the prose around is kept."""
    from ..artifacts import write_text_atomic

    lines = page.read_text().splitlines(keepends=True)
    try:
        i = next(k for k, ln in enumerate(lines) if ln.startswith(BEGIN))
        j = next(k for k, ln in enumerate(lines) if k > i and ln.startswith(END))
    except StopIteration:
        raise FiberpipeError(f"markers '{BEGIN}' … '{END}' not found", where=str(page)) from None
    write_text_atomic(page, "".join(lines[: i + 1]) + "\n" + text.strip("\n") + "\n\n" + "".join(lines[j:]))
