"""The study's two most sensitive unknowns fitted to its curve with an ensemble objective, then the
parallel and oblique-6° models on the fitted family (``make study-fit-ensemble``).

    .venv/bin/python tools/study_fit.py [--grid specimen.bow.spool_radius=0.02604,0.05,0.1
        --grid specimen.volume_fraction=0.35,0.377 | --point KEY=v,KEY=v ...] [--seeds 4] [--workers 2]
        [--collect] [--laws-at KEY=v,KEY=v] [--out runs/study-fit]
        [--doc docs/results.md] [--figure docs/img/study_fit.png]

Without ``--grid`` or ``--point`` the points are ``DEFAULT_POINTS``. Each point is an ensemble (:mod:`fiberpipe.studies.ensemble`) of the prediction's config
(``configs/specimens/study-prediction.yaml``) at the fast settings with the point's values; all
points run in one pass of a local Dask cluster, their members side by side. The objective of a point
is the RMS difference of its ensemble-mean curve from the study's curve points
(``data-samples/paper-40-fit/target.csv``, 28 points from U = 0 to 1.15 mm). Every value must lie in
the range the study states for its unknown (``RANGES``): the bow radius between the 26 mm of Table 4
read in 1/cm (random planes) and 4 m (read in 1/m), v_f0 35–40 %. Points that are the prediction
itself or one of the sensitivity's variants (``tools/study_sensitivity.py``) reuse those runs.

On the best point the parallel model (Table 1, Φ = 0) compacts the same specimens as the oblique 6°
model the prediction uses; writes per seed the two final loads, their ratio and the largest
fiber–fiber penetration at U = 1.15 mm (``post/geometry.csv``). Writes ``OUT/fit.json``, the figure
and, with ``--doc``, the tables between ``<!-- study-fit: begin -->`` and ``<!-- study-fit: end -->``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

# the ranges the study states (docs/results.md): the bow radius from Table 4 read in 1/cm with the
# fibers bowed in random planes (2/(π · 24.45 1/m)) to Table 4 read in 1/m as the curvature itself;
# v_f0 37.7 % as the study measures it, ± the 2.5 points of a 15 µm voxel's edge over the pile
RANGES = {"specimen.bow.spool_radius": (0.02604, 4.0), "specimen.volume_fraction": (0.35, 0.40)}
PARALLEL = {"scene.contact": {"law": "scaled_stiffness", "preset": "table1_parallel"}}
# the default evaluations: the bow radius over the study's range at v_f0 37.7 %, and v_f0 35 % at
# the two radii whose loads bracket the study's 12 N closest from either side
DEFAULT_POINTS = [f"specimen.bow.spool_radius={r},specimen.volume_fraction={v}" for r, v in
                  [(0.02604, 0.377), (0.032, 0.377), (0.0409, 0.377), (0.05, 0.377), (0.1, 0.377), (4.0, 0.377),
                   (0.02604, 0.35), (0.05, 0.35)]]
BEGIN, END = "<!-- study-fit: begin", "<!-- study-fit: end -->"


def parse_grid(texts: list[str]) -> dict[str, list[float]]:
    """``KEY=v1,v2,...`` (SI values) per unknown, each value inside the study's range for KEY."""
    grid = {}
    for text in texts:
        key, _, values = text.partition("=")
        if key not in RANGES:
            raise SystemExit(f"--grid {text}: {key!r} has no range the study states (known: {', '.join(RANGES)})")
        numbers = [float(v) for v in values.split(",") if v.strip()]
        lo, hi = RANGES[key]
        outside = [v for v in numbers if not lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9)]
        if not numbers or outside:
            raise SystemExit(f"--grid {key}: values {outside or 'none'} outside the study's range {lo:g}–{hi:g}")
        grid[key] = numbers
    return grid


def parse_point(text: str, keys: list[str]) -> dict[str, float]:
    """``KEY=v,KEY=v``: one point of the grid's unknowns, each value inside the study's range."""
    point = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
        point.update(parse_grid([f"{key.strip()}={value}"]))
    if sorted(point) != sorted(keys):
        raise SystemExit(f"--point {text}: give a value for each of {', '.join(keys)}")
    return {k: point[k][0] for k in keys}


def changed_values(point: dict, base: dict) -> dict:
    """The point's values that differ from the base config's (in SI, after units): the others stay
    as the base gives them, so that the point shares the base's specimens (their key hashes the raw
    config)."""
    import copy

    from fiberpipe.config import validate_config
    from fiberpipe.studies.fit import _dotted_value

    probe = copy.deepcopy(base)
    probe.setdefault("input", {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]})
    cfg = validate_config(probe, where="base")
    return {k: v for k, v in point.items() if not np.isclose(float(_dotted_value(cfg, k)), v, rtol=1e-6, atol=0)}


def point_folders(points: list[dict], base: dict, seeds: list[int], prediction: Path, sensitivity: Path,
                  out: Path) -> list[Path]:
    """Where each point's ensemble goes: the prediction's own runs for the prediction (when it ran
    these seeds), a sensitivity variant's folder for its overrides, else ``out/points/<id>``."""
    import json

    from study_sensitivity import RERUN, VARIANTS

    summary = prediction / "fast" / "ensemble.json"
    same_seeds = summary.is_file() and json.loads(summary.read_text())["seeds"] == seeds
    folders = []
    for point in points:
        changed = changed_values(point, base)
        if not changed:  # the prediction's own runs, or (other seeds than its) the sensitivity's rerun of them
            folders.append(prediction / "fast" if same_seeds else sensitivity / RERUN)
            continue
        same = [name for name, _, _, overrides in VARIANTS if overrides == changed and name != RERUN]
        ident = "-".join(f"{k.rsplit('.', 1)[1]}{v:g}" for k, v in point.items())
        folders.append(sensitivity / same[0] if same else out / "points" / ident)
    return folders


def objective(folder: Path) -> dict:
    from study_prediction import against_study

    return against_study(folder)


def penetrations(runs: list[str]) -> list[float]:
    """The largest fiber–fiber penetration at each run's last frame (m)."""
    values = []
    for run in runs:
        table = np.genfromtxt(Path(run) / "post" / "geometry.csv", delimiter=",", names=True)
        values.append(float(np.atleast_1d(table["max_penetration_m"])[-1]))
    return values


def table_markdown(rows: list[dict], grid: dict, best: dict, laws: dict | None, seeds: list[int]) -> str:
    keys = list(grid)
    head = " | ".join(k.rsplit(".", 1)[1] for k in keys)
    lines = [f"{BEGIN} (generated by tools/study_fit.py from make study-fit-ensemble) -->", "",
             f"| {head} | seeds | F(1.15 mm) per seed (N) | mean ± sd (N) | F(0.55 mm) mean (N) | RMS from the study's points (N) | "
             "RMS / 12 N | RMS / 12 N at the best scale (the scale) |",
             "| " + " | ".join("---" for _ in range(len(keys) + 7)) + " |"]
    for row in rows:
        values = " | ".join(f"{row['point'][k]:.4g}" for k in keys)
        if "error" in row:
            lines.append(f"| {values} | {len(seeds)} | not run: {row['error']} | | | | | |")
            continue
        mark = " **(best)**" if row is best else ""
        left = "".join(f" (seed {d['seed']} diverged in the {d['stage']}, left out)" for d in row.get("diverged", []))
        lines.append(f"| {values}{mark} | {len(row['final_load_N'])}{left} | {', '.join(f'{v:.3g}' for v in row['final_load_N'])} | "
                     f"{row['mean_N']:.3g} ± {row['sd_N']:.2g} | {row['mean_at_0.55mm_N']:.3g} | {row['rms_N']:.3g} | "
                     f"{100 * row['rms_N'] / 12:.0f} % | {100 * row['best_scaled_rms_N'] / 12:.0f} % (× {row['best_scale']:.3g}) |")
    if laws is not None:
        where = ", ".join(f"{k.rsplit('.', 1)[1]} = {v:.4g}" for k, v in laws["point"].items())
        lines += ["", f"The study's two contact models on the family at {where}:", "", "| seed | oblique 6° (N) | parallel (N) | parallel / oblique | largest fiber–fiber penetration, "
                  "oblique / parallel (µm) |", "| --- | --- | --- | --- | --- |"]
        for k, seed in enumerate(laws["seeds"]):
            lines.append(f"| {seed} | {laws['oblique_N'][k]:.3g} | {laws['parallel_N'][k]:.3g} | {laws['ratio'][k]:.3f} | "
                         f"{laws['oblique_penetration_m'][k] * 1e6:.2g} / {laws['parallel_penetration_m'][k] * 1e6:.2g} |")
    return "\n".join(lines + ["", END])


def plot(rows: list[dict], best: dict, figure: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fiberpipe.post.plots import _save
    from fiberpipe.studies.fit import read_target
    from study_prediction import TARGET

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    U_t, F_t = read_target(TARGET)
    for row in rows:
        if "error" in row:
            continue
        table = np.genfromtxt(Path(row["folder"]) / "ensemble.csv", delimiter=",", names=True)
        label = ", ".join(f"{k.rsplit('.', 1)[1]} {v:.3g}" for k, v in row["point"].items())
        style = dict(lw=2.0, color="C3") if row is best else dict(lw=0.8, alpha=0.7)
        ax.plot(table["U_m"] * 1e3, table["load_mean_N"], label=label + (" (best)" if row is best else ""), **style)
        if row is best:
            sd = table["load_sd_N"]
            ax.fill_between(table["U_m"] * 1e3, table["load_mean_N"] - sd, table["load_mean_N"] + sd, color="C3", alpha=0.2)
    ax.plot(U_t * 1e3, F_t, "ko", ms=3, label="the study's curve points")
    ax.set_xlabel("U [mm]")
    ax.set_ylabel("ensemble-mean load [N]")
    ax.set_ylim(0, max(30.0, 1.3 * float(np.max(F_t))))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6)
    _save(fig, figure)


def main(argv=None) -> int:
    from fiberpipe.artifacts import write_json_atomic
    from generated import replace_marked
    from fiberpipe.config import load_raw
    from fiberpipe.studies.ensemble import collect_ensemble, run_ensembles
    from study_prediction import FAST, _with

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "specimens" / "study-prediction.yaml"))
    ap.add_argument("--grid", action="append", default=None, help="KEY=v1,v2,... (SI), one per unknown")
    ap.add_argument("--point", action="append", default=None,
                    help="KEY=v,KEY=v (SI): one point; given, the points are these instead of the grid's product")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--prediction", default=str(ROOT / "runs" / "study-prediction"))
    ap.add_argument("--sensitivity", default=str(ROOT / "runs" / "study-sensitivity"))
    ap.add_argument("--out", default=str(ROOT / "runs" / "study-fit"))
    ap.add_argument("--collect", action="store_true",
                    help="tables from the finished runs alone, running nothing (a point without them: not run)")
    ap.add_argument("--laws-at", help="KEY=v,KEY=v: the point the laws compact (default: the best)")
    ap.add_argument("--no-laws", action="store_true", help="skip the parallel model on the best point")
    ap.add_argument("--doc")
    ap.add_argument("--figure")
    args = ap.parse_args(argv)
    grid = parse_grid(args.grid or ["specimen.bow.spool_radius=0.02604,0.032,0.0409,0.05,0.1,4",
                                    "specimen.volume_fraction=0.35,0.377"])
    if not args.grid and not args.point:
        args.point = DEFAULT_POINTS
    raw = _with(load_raw(args.config), FAST)
    seeds = list(raw["specimen"]["seeds"])[: args.seeds]
    out, prediction = Path(args.out), Path(args.prediction)
    keys = list(grid)
    points = [dict(zip(keys, values)) for values in itertools.product(*(grid[k] for k in keys))]
    if args.point:
        points = [parse_point(text, keys) for text in args.point]
    folders = point_folders(points, raw, seeds, prediction, Path(args.sensitivity), out)
    ensembles = {str(folder): (_with(raw, changed_values(point, raw)), seeds, folder) for point, folder in zip(points, folders)}
    if args.collect:  # the finished runs alone, nothing run
        results = {name: collect_ensemble(folder, seeds) for name, (_, _, folder) in ensembles.items()}
    else:
        results = run_ensembles(ensembles, workers=args.workers, specimen_store=prediction / "specimens",
                                where=args.config, keep_going=True)
    rows = []
    for point, folder in zip(points, folders):
        result = results[str(folder)]
        if "error" in result:
            rows.append({"point": point, "folder": str(folder), "error": result["error"]})
            continue
        loads = result["final_load_N"]
        rows.append({"point": point, "folder": str(folder), "seeds": result["seeds"], "diverged": result.get("diverged", []),
                     "final_load_N": loads, "v_f0": result["v_f0"],
                     "mean_N": float(np.mean(loads)), "sd_N": float(np.std(loads, ddof=1)), "runs": result["runs"],
                     **objective(folder)})
    done = [r for r in rows if "error" not in r]
    best = min(done, key=lambda r: r["rms_N"])
    laws, parallel = None, {"error": "not run (--no-laws)"}
    family = best
    if args.laws_at:  # the laws on another evaluated point than the best
        wanted = parse_point(args.laws_at, keys)
        family = next(r for r in done if all(np.isclose(r["point"][k], wanted[k]) for k in keys))
    if not args.no_laws:
        folder = Path(family["folder"]).with_name(Path(family["folder"]).name + "-parallel")
        if args.collect:
            parallel = collect_ensemble(folder, seeds)
        else:
            parallel = run_ensembles({"parallel": (_with(_with(raw, changed_values(family["point"], raw)), PARALLEL), seeds,
                                                   folder)}, workers=args.workers, specimen_store=prediction / "specimens",
                                     where=args.config, keep_going=True)["parallel"]
    if laws is None and "error" not in parallel:
        both = [s for s in family["seeds"] if s in parallel["seeds"]]  # a seed either law diverged in: left out
        oblique = {s: (load, run) for s, load, run in zip(family["seeds"], family["final_load_N"], family["runs"])}
        other = {s: (load, run) for s, load, run in zip(parallel["seeds"], parallel["final_load_N"], parallel["runs"])}
        laws = {"seeds": both, "point": family["point"], "oblique_N": [oblique[s][0] for s in both],
                "parallel_N": [other[s][0] for s in both],
                "ratio": [other[s][0] / oblique[s][0] for s in both],
                "oblique_penetration_m": penetrations([oblique[s][1] for s in both]),
                "parallel_penetration_m": penetrations([other[s][1] for s in both]),
                "parallel_runs": [other[s][1] for s in both], "parallel_diverged": parallel.get("diverged", [])}
    summary = {"grid": grid, "seeds": seeds, "evaluations": len(rows), "settings": "fast: " + ", ".join(f"{k} = {v}" for k, v in FAST.items()),
               "points": rows, "best": best, "laws": laws}
    write_json_atomic(out / "fit.json", summary)
    plot(rows, best, Path(args.figure) if args.figure else out / "fit.png")
    text = table_markdown(rows, grid, best, laws, seeds)
    print(text)
    if args.doc:
        replace_marked(Path(args.doc), BEGIN, END, text)
    return 0


def cli(argv=None) -> int:
    """:func:`main`, a problem the user can fix as one line (:func:`generated.run_cli`)."""
    from generated import run_cli

    return run_cli(main, argv)


if __name__ == "__main__":
    sys.exit(cli())
