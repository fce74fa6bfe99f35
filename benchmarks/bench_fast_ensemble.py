"""paper-40's load-cell curve at fast settings against the study settings, ensemble mean against
ensemble mean, with each setting's wall time.

One run of paper-40 is one chaotic trajectory: a change of rounding moves its contact bursts, so
one run against another may differ by a few per cent in window means of the load cell. Each setting
is therefore run ``--runs`` times with gravity scaled by ``1 + k·step`` (k = 0, 1, −1, 2, −2, …;
``--gravity-step``, 1e-8 by default), and
the settings are compared on the mean of their runs' window means (0.23 mm windows of U by default:
five over the 1.15 mm loading). The error of a setting is the largest |ΔF̄| over the windows relative
to the largest window mean of the study settings' ensemble; the scatter of the study settings is the
same measure of each of its runs against the mean of the others.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_fast_ensemble.py \\
        --out runs/bench/fast-ensemble --runs 6 \\
        --setting study: \\
        --setting ms100:solver.mass_scaling=100,scene.damping.alpha=1e3 1/s

A setting is ``NAME:KEY=VALUE,KEY=VALUE`` (config overrides; ``NAME:`` alone: the study settings,
the first setting is the reference). Each run's curve is kept in ``OUT/NAME_k.npz``, so a rerun
only runs what is missing; ``--report`` prints the table from what is there.

With ``--config`` (repeatable) the runs are of those run configs instead of paper-40's, one
specimen each (a specimen's seed, built by ``fiberpipe specimen --seed``), kept in
``OUT/<the config's folder name>/NAME_k.npz``. The reference (first) setting runs on the first
``--reference-specimens`` configs only (it is the slow one); the other settings on all. The table
then gives, per window of U, the window means of each setting on the reference specimens, their
difference, and the spread (standard deviation and range) of each other setting's window means over
all the specimens; the headline is the largest |ΔF| over the windows relative to the reference's
largest window mean, against the largest spread over the windows relative to that setting's
largest window mean over the specimens (``make yarn-100-accuracy``):

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_fast_ensemble.py \\
        --out runs/bench/yarn-100-accuracy --runs 1 --window-mm 0.2378 --reference-specimens 2 \\
        --config runs/specimens/yarn-100-s0/config.yaml ... --config runs/specimens/yarn-100-s3/config.yaml \\
        --setting "study:solver.mass_scaling=1,scene.damping.alpha=1e5 1/s,solver.stable_step=element,solver.dt_safety=0.95" \\
        --setting fast:
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

G_M_S2 = 9.81


def gravity_factor(run: int, step: float = 1e-8) -> float:
    """Run ``run``'s gravity factor 1 + k·``step``, k = 0, 1, −1, 2, −2, …"""
    k = (run + 1) // 2 * (1 if run % 2 else -1)
    return 1.0 + k * step


def parse_setting(text: str) -> tuple[str, dict]:
    """``NAME:KEY=VALUE,KEY=VALUE`` as (name, overrides); numbers stay strings the config reads."""
    name, _, rest = text.partition(":")
    overrides = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, _, value = item.partition("=")
        try:
            overrides[key.strip()] = float(value) if "." in value or "e" in value else int(value)
        except ValueError:
            overrides[key.strip()] = value.strip()
    return name, overrides


def run_one(overrides: dict, run: int, path: Path, gravity_step: float = 1e-8, config: Path | None = None) -> None:
    """One run of paper-40 (or of ``config``) at ``overrides`` with run ``run``'s gravity, its
    load-cell curve, wall and CPU time kept in ``path``."""
    from fiberpipe.artifacts import atomic_path
    from fiberpipe.bench import paper40_run

    g = -G_M_S2 * gravity_factor(run, gravity_step)
    cpu0 = time.process_time()
    r = paper40_run({**overrides, "scene.gravity.acceleration": [0, f"{g!r} m/s^2", 0]}, config=config)
    cpu_s = time.process_time() - cpu0
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, U=r["U_curve"], F_cell=r["F_cell_curve"], wall_s=r["wall_s"], wall_steady_s=r["wall_steady_s"],
                 cpu_s=cpu_s, steps=r["steps"], completed=r["completed"])


def report(out: Path, names: list[str], window_m: float) -> str:
    """The table: per setting its runs, steps, wall time and error against the first setting."""
    from fiberpipe.bench import window_means

    runs = {n: [np.load(p) for p in sorted(out.glob(f"{n}_[0-9][0-9].npz"))] for n in names}
    u_end = max(float(r["U"].max()) for rs in runs.values() for r in rs)
    edges = np.arange(0.0, u_end + 0.5 * window_m, window_m)
    means = {n: np.array([window_means(r["U"], r["F_cell"], edges) for r in rs]) for n, rs in runs.items() if rs}
    ref = names[0]
    ref_mean = np.nanmean(means[ref], axis=0)
    scale = np.nanmax(np.abs(ref_mean))
    lines = [f"windows of {window_m * 1e3:.3g} mm; error: largest |mean F - study mean F| / largest study window mean",
             "", "| setting | runs | steps | wall per run (s, median) | load-cell window means, ensemble (N) | "
             "error vs study ensemble | one run vs the others' mean (range) |", "|---|---|---|---|---|---|---|"]
    for n in names:
        if n not in means:
            continue
        m = np.nanmean(means[n], axis=0)
        err = np.nanmax(np.abs(m - ref_mean)) / scale
        rs = runs[n]
        spread = ""
        if len(rs) > 1:
            e1 = []
            for i in range(len(rs)):
                others = np.nanmean(np.delete(means[n], i, axis=0), axis=0)
                e1.append(np.nanmax(np.abs(means[n][i] - others)) / np.nanmax(np.abs(others)))
            spread = f"{min(e1) * 100:.2f}–{max(e1) * 100:.2f} %"
        walls = np.median([float(r["wall_s"]) for r in rs])
        lines.append(f"| {n} | {len(rs)} | {int(rs[0]['steps'])} | {walls:.1f} | "
                     f"{', '.join(f'{v:.4f}' for v in m)} | {err * 100:.2f} % | {spread} |")
    return "\n".join(lines)


def _specimen_means(out: Path, labels: list[str], name: str, edges) -> dict:
    """{specimen label: window means of setting ``name``'s runs on it, averaged over its runs}, and
    its runs' wall and CPU times, for the specimens that have runs of it."""
    from fiberpipe.bench import window_means

    found = {}
    for label in labels:
        runs = [np.load(p) for p in sorted((out / label).glob(f"{name}_[0-9][0-9].npz"))]
        if runs:
            means = np.nanmean([window_means(r["U"], r["F_cell"], edges) for r in runs], axis=0)
            found[label] = (means, [float(r["wall_s"]) for r in runs],
                            [float(r["cpu_s"]) if "cpu_s" in r else float("nan") for r in runs], int(runs[0]["steps"]))
    return found


def specimens_report(out: Path, labels: list[str], names: list[str], window_m: float) -> str:
    """Each setting against the first (the reference) on the specimens both ran, and each setting's
    spread over the specimens, window by window of U (docstring above)."""
    u_end = max(float(np.load(p)["U"].max()) for label in labels for p in (out / label).glob("*_[0-9][0-9].npz"))
    edges = np.arange(0.0, u_end + 0.5 * window_m, window_m)
    found = {n: _specimen_means(out, labels, n, edges) for n in names}
    ref = names[0]
    lines = [f"windows of {window_m * 1e3:.3g} mm of U; load cell (fixed plate) window means in N", ""]
    header = ["window of U (mm)"] + [f"{ref} on {label}" for label in found[ref]]
    rows = [[f"{lo * 1e3:.3f}–{hi * 1e3:.3f}"] + [f"{found[ref][label][0][w]:.4f}" for label in found[ref]]
            for w, (lo, hi) in enumerate(zip(edges[:-1], edges[1:]))]
    headline = []
    for n in names[1:]:
        shared = [label for label in found[n] if label in found[ref]]
        for label in shared:
            delta = found[n][label][0] - found[ref][label][0]
            header += [f"{n} on {label}", "Δ"]
            for w, row in enumerate(rows):
                row += [f"{found[n][label][0][w]:.4f}", f"{delta[w]:+.4f}"]
            headline.append(f"{n} vs {ref} on {label}: max |ΔF| {np.nanmax(np.abs(delta)):.4f} N = "
                            f"{np.nanmax(np.abs(delta)) / np.nanmax(np.abs(found[ref][label][0])) * 100:.2f} % "
                            f"of {ref}'s largest window mean")
        if len(found[n]) > 1:
            over_seeds = np.array([m for m, *_ in found[n].values()])
            sd = np.nanstd(over_seeds, axis=0, ddof=1)
            spread = np.nanmax(over_seeds, axis=0) - np.nanmin(over_seeds, axis=0)
            header += [f"{n}: mean over {len(found[n])} specimens", "sd", "range"]
            for w, row in enumerate(rows):
                row += [f"{np.nanmean(over_seeds[:, w]):.4f}", f"{sd[w]:.4f}", f"{spread[w]:.4f}"]
            scale = np.nanmax(np.abs(np.nanmean(over_seeds, axis=0)))
            headline.append(f"{n} over {len(found[n])} specimens: max sd {np.nanmax(sd) / scale * 100:.2f} %, "
                            f"max range {np.nanmax(spread) / scale * 100:.2f} % of its largest mean window mean")
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in rows]
    lines += ["", *headline, "", "| setting | specimen | steps | wall (s) | CPU (s) |", "|---|---|---|---|---|"]
    for n in names:
        for label, (_, walls, cpus, steps) in found[n].items():
            lines.append(f"| {n} | {label} | {steps} | {np.median(walls):.1f} | {np.median(cpus):.1f} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--setting", action="append", required=True, help="NAME:KEY=VALUE,... (first: the reference)")
    ap.add_argument("--window-mm", type=float, default=0.23)
    ap.add_argument("--gravity-step", type=float, default=1e-8, help="the runs' gravity factors 1 + k·STEP")
    ap.add_argument("--report", action="store_true", help="only print the table from the runs kept in --out")
    ap.add_argument("--config", type=Path, action="append", default=[],
                    help="a run config (one specimen) instead of paper-40's; repeatable: the specimens' spread")
    ap.add_argument("--reference-specimens", type=int, default=None,
                    help="run the first (reference) setting on the first N configs only (default: all)")
    args = ap.parse_args(argv)
    settings = [parse_setting(s) for s in args.setting]
    args.out.mkdir(parents=True, exist_ok=True)
    configs = args.config or [None]
    labels = [c.resolve().parent.name if c else "" for c in configs]
    n_reference = len(configs) if args.reference_specimens is None else args.reference_specimens
    if not args.report:
        # runs interleaved across the settings and specimens, so an interrupted ensemble still has every setting
        for run in range(args.runs):
            for index, (config, label) in enumerate(zip(configs, labels)):
                for k, (name, overrides) in enumerate(settings):
                    path = args.out / label / f"{name}_{run:02d}.npz"
                    if path.exists() or (k == 0 and index >= n_reference):
                        continue
                    path.parent.mkdir(parents=True, exist_ok=True)
                    t0 = time.perf_counter()
                    run_one(overrides, run, path, args.gravity_step, config)
                    print(f"{name}{' on ' + label if label else ''} run {run}: {time.perf_counter() - t0:.1f} s",
                          flush=True)
    names = [n for n, _ in settings]
    if args.config:
        print(specimens_report(args.out, labels, names, args.window_mm * 1e-3))
    else:
        print(report(args.out, names, args.window_mm * 1e-3))


if __name__ == "__main__":
    main()
