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


def run_one(overrides: dict, run: int, path: Path, gravity_step: float = 1e-8) -> None:
    from fiberpipe.artifacts import atomic_path
    from fiberpipe.bench import paper40_run

    g = -G_M_S2 * gravity_factor(run, gravity_step)
    r = paper40_run({**overrides, "scene.gravity.acceleration": [0, f"{g!r} m/s^2", 0]})
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, U=r["U_curve"], F_cell=r["F_cell_curve"], wall_s=r["wall_s"], wall_steady_s=r["wall_steady_s"],
                 steps=r["steps"], completed=r["completed"])


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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--setting", action="append", required=True, help="NAME:KEY=VALUE,... (first: the reference)")
    ap.add_argument("--window-mm", type=float, default=0.23)
    ap.add_argument("--gravity-step", type=float, default=1e-8, help="the runs' gravity factors 1 + k·STEP")
    ap.add_argument("--report", action="store_true", help="only print the table from the runs kept in --out")
    args = ap.parse_args(argv)
    settings = [parse_setting(s) for s in args.setting]
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.report:
        # runs interleaved across the settings, so an interrupted ensemble still has every setting
        for run in range(args.runs):
            for name, overrides in settings:
                path = args.out / f"{name}_{run:02d}.npz"
                if path.exists():
                    continue
                t0 = time.perf_counter()
                run_one(overrides, run, path, args.gravity_step)
                print(f"{name} run {run}: {time.perf_counter() - t0:.1f} s", flush=True)
    print(report(args.out, [n for n, _ in settings], args.window_mm * 1e-3))


if __name__ == "__main__":
    main()
