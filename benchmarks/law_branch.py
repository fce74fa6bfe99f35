"""The contact law's own effect on the load, separated from the bundle's chaos (issue 5).

``benchmarks/contact_ensemble.py`` compares the study's contact models over whole compactions:
each law gives its own trajectory from U = 0, and the trajectories of a chaotic bundle part long
before the final load is read (the same settings with gravity × (1 ± 1e-8) end 9 % apart), so the
law's deterministic effect and the trajectory's chance are mixed. Here every law starts from the
*same* state instead.

# Strategy: one compaction per specimen with the shipped law (hertz_oriented) at the study's
# settings, checkpointed at U = ``--branch-mm`` (default 0.95 mm, inside the steep rise of most
# specimens); from that checkpoint's state, short continuations to U = 1.15 mm with
#   * the study's parallel (table1_parallel) and oblique 6° (table1_phi6) models, and
#   * two controls with the shipped law: restarted as the branches are (the contact hook starts
#     afresh: friction histories empty), and restarted with gravity × (1 + 1e-8).
# The paired difference parallel − oblique on the same state is the law's effect over the last
# 0.2 mm; the controls' differences from the unbranched run (and from each other) are what a
# restart and chance alone give over the same travel. Read: the load-cell (upper plate) mean over
# U ∈ [1.10, 1.15] mm, as the ensemble reads it; the largest fibre–fibre penetration at the end.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/law_branch.py [--seeds 0-7] [--jobs 2]
        [--branch-mm 0.95] [--save DIR] [--out FILE.md] [--reuse]

The specimens are those of ``contact_ensemble.py`` (seed 0: the shipped ``data-samples/paper-40``;
others are made, ≈ 4.5 min each, and kept in ``DIR/seed-N``, default ``runs/contact_ensemble``).
A seed costs one study-settings run plus four continuations: measured 237–410 s and 27–149 s each with
the two cores busy (8 seeds in 38 min with ``--jobs 2``, 2026-11-22).
Results per seed go to ``DIR/seed-N/branch-<U>.json``; ``--reuse`` only rewrites the table.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
import contact_ensemble as ens  # noqa: E402  (the specimens, the paired statistics)

FINAL_WINDOW_M = ens.FINAL_WINDOW_M
BRANCHES = (
    ("control: hertz_oriented, restarted", {}),
    ("control: hertz_oriented, restarted, gravity × (1 + 1e-8)", {"scene.gravity.acceleration": [0, "-9.8100001 m/s^2", 0]}),
    ("parallel (table1_parallel)", ens.LAWS[1][1]),
    ("oblique 6° (table1_phi6)", ens.LAWS[2][1]),
)
KEYS = ("unbranched", "control", "control_g", "parallel", "oblique")


def _config(overrides: dict):
    from fiberpipe.config import load_config

    return load_config(ROOT / "configs" / "paper-40.yaml", overrides)


def _final_load(h: dict) -> float:
    U = h["plate_displacement"][:, 0]
    F = h["plate_force"][:, 1]  # the fixed upper plate: the study's load cell
    return ens._window_mean(U, F, *FINAL_WINDOW_M)


def _delta_max(effects) -> float:

    for e in effects:
        info = getattr(e, "setup_info", None)
        if info is not None and info.data is not None:
            return info.max_penetration_m
    return float("nan")


def run_seed(seed: int, save: str, branch_m: float, fast: bool = False) -> dict:
    """The unbranched run and the four continuations of one specimen; returns (and saves) the figures."""
    from fiberpipe.solver import simulate
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.state import State

    save = Path(save)
    out = save / f"seed-{seed}" / f"branch-{branch_m * 1e3:.2f}mm{'-fast' if fast else ''}.json"
    if out.exists():
        return json.loads(out.read_text())
    fibers, top = ens.specimen(seed, save)
    from fiberpipe.bench import FAST_OVERRIDES

    base = {**(FAST_OVERRIDES if fast else {}), "solver.output_frames": 2, "input.fibers": str(fibers),
            "post.reference_fibers": str(fibers),
            "scene.plates.upper_position": top}
    from fiberpipe.bench import config_mesh

    cfg = _config(base)
    mesh = config_mesh(cfg)
    model, effects, settings = build_simulation(mesh, cfg)
    # the step at which the plate reaches branch_m (the ramp is the config's: read it off a probe run's
    # prescribed displacement, which is exact, instead of inverting the ramp here)
    from fiberpipe.solver.integrator import choose_time_step
    from fiberpipe.solver._kernels_boundary import ramp_fraction
    from fiberpipe.solver.effects import SceneArrays

    dt, _ = choose_time_step(model, effects, settings)
    probe = SceneArrays(model, dt)
    for e in effects:
        if e.name == "plates":
            e.setup(model, probe)
    p = int(np.flatnonzero(probe.pl_move != 0)[0])
    T, ta, mode, move = probe.pl_T[p], probe.pl_ta[p], probe.pl_mode[p], probe.pl_move[p]
    n_total = int(np.ceil(T / dt - 1e-9))
    n_branch = next(n for n in range(0, n_total, 100) if move * ramp_fraction(n * dt, T, ta, mode) >= branch_m)
    checkpoints = []
    t0 = time.perf_counter()
    run = simulate(model, effects, dataclasses.replace(settings, checkpoint_every=n_branch),
                   on_checkpoint=lambda ck: checkpoints.append(ck) if not checkpoints else None)
    fig = {"seed": seed, "branch_U_m": branch_m, "fast": fast, "branch_step": n_branch, "top_m": top,
           "unbranched": _final_load(run.history), "unbranched_delta_max_m": _delta_max(effects),
           "unbranched_wall_s": time.perf_counter() - t0}
    ck = checkpoints[0]
    rest_s = (n_total - ck.step) * dt
    for key, (name, ov) in zip(KEYS[1:], BRANCHES):
        cfg_b = _config({**base, **ov})
        model_b, effects_b, settings_b = build_simulation(mesh, cfg_b)
        st = State(ck.x.copy(), ck.q.copy(), ck.v.copy(), ck.w.copy(), float(ck.t), int(ck.step), ck.acc.copy())
        t1 = time.perf_counter()
        r = simulate(model_b, effects_b, dataclasses.replace(settings_b, end_time_s=rest_s), state=st)
        fig[key] = _final_load(r.history)
        fig[f"{key}_delta_max_m"] = _delta_max(effects_b)
        fig[f"{key}_wall_s"] = time.perf_counter() - t1
        fig[f"{key}_U_end_m"] = float(r.history["plate_displacement"][-1, 0])
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(fig, indent=1) + "\n")
    return fig


def table(figs: list[dict]) -> str:
    """The markdown tables: per specimen, then the paired statistics."""
    figs = sorted(figs, key=lambda f: f["seed"])
    b = figs[0]["branch_U_m"] * 1e3
    lines = [f"Load cell, mean over U ∈ [1.10, 1.15] mm (N); every column after the first continues from the "
             f"same state at U = {b:.2f} mm; largest fibre–fibre penetration at the end (µm).", "",
             "| specimen | unbranched | control (restart) | control (restart, g × (1 + 1e-8)) | parallel | oblique 6° "
             "| parallel − oblique | penetration: parallel / oblique / hertz_oriented |",
             "|---|---|---|---|---|---|---|---|"]
    for f in figs:
        d = 2 * (f["parallel"] - f["oblique"]) / (f["parallel"] + f["oblique"])
        lines.append(f"| seed {f['seed']} | {f['unbranched']:.3f} | {f['control']:.3f} | {f['control_g']:.3f} | "
                     f"{f['parallel']:.3f} | {f['oblique']:.3f} | {100 * d:+.1f} % | "
                     f"{f['parallel_delta_max_m'] * 1e6:.2f} / {f['oblique_delta_max_m'] * 1e6:.2f} / "
                     f"{f['control_delta_max_m'] * 1e6:.2f} |")
    col = {k: np.array([f[k] for f in figs]) for k in KEYS}
    rows = [("parallel − oblique 6° (the law's effect)", "parallel", "oblique"),
            ("control (restart) − unbranched (a restart and chance)", "control", "unbranched"),
            ("control (g × (1 + 1e-8)) − control (chance alone)", "control_g", "control")]
    lines += ["", f"Paired relative differences 2(a − b)/(a + b) over {len(figs)} specimens (mean ± s.e., "
                  "Student t, two-sided p; uncorrected for the three tests):", "",
              "| pair | mean | s.e. | t | p | a above b |", "|---|---|---|---|---|---|"]
    for label, a, bb in rows:
        m, se, t, p = ens.paired(col[a], col[bb])
        above = int(np.sum(col[a] > col[bb]))
        lines.append(f"| {label} | {100 * m:+.2f} % | {100 * se:.2f} % | {t:.2f} | {p:.2f} | {above} of {len(figs)} |")
    spread = np.abs(2 * (col["control_g"] - col["control"]) / (col["control_g"] + col["control"]))
    lines += ["", f"Chance alone over the last {1.15 - b:.2f} mm (|control g − control|): median "
                  f"{100 * np.median(spread):.1f} %, largest {100 * spread.max():.1f} %."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0-7")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--branch-mm", type=float, default=0.95)
    ap.add_argument("--save", default=str(ROOT / "runs" / "contact_ensemble"))
    ap.add_argument("--out", default=None, help="write the table here too (markdown)")
    ap.add_argument("--reuse", action="store_true", help="run nothing; tabulate the saved seeds")
    ap.add_argument("--fast", action="store_true", help="the fast settings (fiberpipe.bench.FAST_OVERRIDES) "
                    "instead of the study's")
    a = ap.parse_args(argv)
    seeds = ens._seeds(a.seeds)
    branch_m = a.branch_mm * 1e-3
    if not 0.0 < branch_m < 1.15e-3:
        ap.error("--branch-mm must be inside the loading (0, 1.15) mm")
    figs = []
    if a.reuse:
        for s in seeds:
            p = Path(a.save) / f"seed-{s}" / f"branch-{a.branch_mm:.2f}mm{'-fast' if a.fast else ''}.json"
            if p.exists():
                figs.append(json.loads(p.read_text()))
    elif a.jobs > 1:
        with ProcessPoolExecutor(a.jobs) as ex:
            for f in ex.map(run_seed, seeds, [a.save] * len(seeds), [branch_m] * len(seeds), [a.fast] * len(seeds)):
                print(f"seed {f['seed']}: parallel {f['parallel']:.3f} N, oblique {f['oblique']:.3f} N", flush=True)
                figs.append(f)
    else:
        for s in seeds:
            f = run_seed(s, a.save, branch_m, a.fast)
            print(f"seed {s}: parallel {f['parallel']:.3f} N, oblique {f['oblique']:.3f} N", flush=True)
            figs.append(f)
    if not figs:
        print("no results", file=sys.stderr)
        return 1
    text = table(figs)
    print(text)
    path = Path(a.out) if a.out else Path(a.save) / f"branch-{a.branch_mm:.2f}mm{'-fast' if a.fast else ''}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
