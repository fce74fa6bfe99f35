"""The study's contact models over specimen realisations (issue 5: is parallel above oblique?).

One paper-40 run is one trajectory of a chaotic bundle: the same settings with gravity × (1 ± 1e-8)
end 9 % apart at U = 1.15 mm (benchmarks/fast_settings.py). Whether the parallel contact model
(the study's 17 N) carries more than the oblique 6° model (9.5 N) is therefore a question about
the mean over specimens, not about one pair of runs. This study makes ``--seeds`` specimens with
the shipped generator (``data-samples/make_paper40.py``: the same deposit and settle, seed 0 is the
shipped ``data-samples/paper-40``), compacts each one with the three models of
``configs/paper-40/`` (``hertz_oriented``, the study's parallel ``table1_parallel`` and oblique
``table1_phi6``), and compares their load-cell (upper plate) force by pairs on the same specimen.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/contact_ensemble.py [--seeds 0-7] [--jobs 2]
        [--study] [--save DIR] [--out FILE.md] [--reuse]

By default the compactions run at the fast settings of ``fiberpipe.bench.FAST_OVERRIDES`` (mass
scaling 25 with α/25: the study settings' curve within its own run-to-run scatter, ≈ 30 s a run);
``--study`` runs the study settings (≈ 150 s a run). Each specimen's settle takes ≈ 4.5 min on one
core and is kept in ``DIR/seed-N/`` (default ``runs/contact_ensemble``) with every run's curves;
``--reuse`` only recomputes the table and the plot (``DIR/contact_ensemble.png``).
"""

from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LAWS = (("hertz_oriented", {}),
        ("parallel (table1_parallel)", {"scene.contact.law": "scaled_stiffness", "scene.contact.preset": "table1_parallel"}),
        ("oblique 6° (table1_phi6)", {"scene.contact.law": "scaled_stiffness", "scene.contact.preset": "table1_phi6"}))
FINAL_WINDOW_M = (1.10e-3, 1.15e-3)  # the final load: the mean over the last 0.05 mm (one row fluctuates by ±0.05 N)
READ_AT_M = (0.3e-3, 0.55e-3, 0.8e-3, 1.0e-3)


def _slug(name: str) -> str:
    return name.split(" ")[0]


def specimen_dir(seed: int, save: Path) -> Path:
    """Where the specimen of ``seed`` lives: the shipped ``data-samples/paper-40`` for seed 0."""
    return ROOT / "data-samples" / "paper-40" if seed == 0 else save / f"seed-{seed}"


def specimen(seed: int, save: Path) -> tuple[Path, float]:
    """The settled pile of ``seed`` (``data-samples/paper-40`` for seed 0) and its top (m)."""
    d = specimen_dir(seed, save)
    if seed != 0 and not (d / "fibers.h5").exists():
        sys.path.insert(0, str(ROOT / "data-samples"))
        import make_paper40 as mp  # the shipped generator, unchanged

        from fiberpipe.artifacts import write_fibers
        from fiberpipe.model.specimen import cassette_specimen

        fibers, info = cassette_specimen(**mp.parameters(seed=seed))
        fibers, info = mp.settle_pile(fibers, info, lock=mp.SETTLE_LOCK)
        d.mkdir(parents=True, exist_ok=True)
        write_fibers(d / "fibers.h5", fibers)
        (d / "specimen.json").write_text(json.dumps(info, indent=1) + "\n")
    info = json.loads((d / "specimen.json").read_text())
    return d / "fibers.h5", float(info["height_m"])


def run_seed(seed: int, save: str, study: bool) -> list[str]:
    """Make (or read) the specimen of ``seed`` and run the three laws on it; returns log lines."""
    from fiberpipe.bench import FAST_OVERRIDES, paper40_run

    save = Path(save)
    t0 = time.perf_counter()
    fibers, top = specimen(seed, save)
    log = [f"seed {seed}: specimen {fibers} (top {top * 1e3:.4f} mm) in {time.perf_counter() - t0:.0f} s"]
    out = save / f"seed-{seed}"
    out.mkdir(parents=True, exist_ok=True)
    for name, law in LAWS:
        path = out / f"{_slug(name)}{'-study' if study else ''}.npz"
        if path.exists():
            continue
        ov = {**({} if study else FAST_OVERRIDES), **law, "solver.output_frames": 2, "input.fibers": str(fibers),
              "post.reference_fibers": str(fibers), "scene.plates.upper_position": top}
        r = paper40_run(ov)
        np.savez(path, U=r["U_curve"], F_cell=r["F_cell_curve"], F_lower=r["F_curve"], wall_s=r["wall_s"],
                 completed=r["completed"], overrides=json.dumps(ov, default=str))
        log.append(f"seed {seed} {name}: F_cell(1.15 mm) {r['F_cell_final_N']:.3f} N, {r['wall_s']:.0f} s")
    return log


def _window_mean(U: np.ndarray, F: np.ndarray, lo: float, hi: float) -> float:
    """Mean load over lo ≤ U ≤ hi (NaN if the run has no sample there)."""
    k = (U >= lo) & (U <= hi + 1e-9)
    return float(F[k].mean()) if k.any() else float("nan")


def figures(U: np.ndarray, F: np.ndarray) -> dict:
    """Load-cell figures of one run (loading branch): final-window mean, window means of ±0.025 mm
    at ``READ_AT_M`` (single rows fluctuate by ±0.05 N), peak, and the phases of
    :func:`fiberpipe.post.phases.compaction_phases` (U in m; NaN where absent or not reached)."""
    from fiberpipe.post.phases import compaction_phases

    k = int(np.argmax(U)) + 1
    U, F = U[:k], F[:k]
    ph = compaction_phases(U, F)
    nan = lambda v: float("nan") if v is None else float(v)  # noqa: E731
    return {"final": _window_mean(U, F, *FINAL_WINDOW_M),
            "reads": [_window_mean(U, F, u - 0.025e-3, u + 0.025e-3) for u in READ_AT_M],
            "peak": float(F.max()), "rearrangement_end": nan(ph["rearrangement_end_U_m"]),
            "steep_start": nan(ph["steep_start_U_m"]), "steep_censored": bool(ph["steep_start_censored"]),
            "steepness": nan(ph["steepness"])}


STUDY_VF0 = 0.377
STUDY_HEIGHT_M = 40 * np.pi * 0.25e-3**2 / (STUDY_VF0 * 3e-3)  # the cassette gap that makes 37.7 %: 6.94 mm
STUDY_PHASES_M = (0.55e-3, 1.12e-3)  # rearrangement until, locking from (the study, section 4)


def vf_at(U_m: float, vf0: float, height_m: float) -> float:
    """Volume fraction of the cassette box (fiber volume / (width × plate gap × length), the study's
    37.7 % measure) after a plate travel ``U_m``."""
    return vf0 * height_m / (height_m - U_m)


def paired(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float, float]:
    """Relative paired difference d = 2(a − b)/(a + b) on the same specimens: its mean, standard
    error, Student t (±inf when every pair differs by the same amount) and two-sided p (n − 1
    degrees of freedom; NaN for fewer than two pairs)."""
    from scipy import stats

    d = 2 * (a - b) / (a + b)
    m = float(d.mean())
    if d.size < 2:
        return m, float("nan"), float("nan"), float("nan")
    se = float(d.std(ddof=1) / np.sqrt(d.size))
    if se <= 1e-12 * max(abs(m), 1e-300):
        t = float("nan") if m == 0 else float(np.copysign(np.inf, m))
    else:
        t = m / se
    p = float(2 * stats.t.sf(abs(t), d.size - 1)) if np.isfinite(t) else (0.0 if np.isinf(t) else float("nan"))
    return m, se, t, p


def summarise(seeds, save: Path, study: bool) -> str:
    from fiberpipe.bench import FAST_OVERRIDES

    suffix = "-study" if study else ""
    res: dict = {}
    for s in seeds:
        for name, _ in LAWS:
            p = save / f"seed-{s}" / f"{_slug(name)}{suffix}.npz"
            if p.exists():
                d = np.load(p)
                if "completed" in d.files and not bool(d["completed"]):
                    print(f"seed {s} {name}: the run stopped before the end; left out")
                    continue
                res[(s, name)] = (d["U"], d["F_cell"], float(d["wall_s"]))
    done = [s for s in seeds if all((s, n) in res for n, _ in LAWS)]
    box = {}
    for s in done:
        d = specimen_dir(s, save)
        info = json.loads((d / "specimen.json").read_text())
        box[s] = (float(info["volume_fraction"]), float(info["height_m"]))
    lines = [f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} by `benchmarks/contact_ensemble.py"
             f"{' --study' if study else ''}`: {len(done)} specimens (seeds {', '.join(map(str, done))}; seed 0 is "
             f"the shipped `data-samples/paper-40`), {'study settings' if study else 'fast settings (mass scaling 25, α = 4e3 1/s)'}, "
             "load-cell (upper plate) force; final = mean over U = 1.10–1.15 mm.", "",
             "Phases by `fiberpipe.post.phases` (docs/outputs.md): rearrangement until the 0.05 mm window means exceed "
             "2 % of their peak; a steep rise where a two-segment fit's last slope is ≥ 1.5× the mean slope since then "
             "(the study: rearrangement 0–0.55 mm, transition 0.55–1.12 mm, locking from 1.12 mm).", "",
             f"v_f: the cassette box's (the study's 37.7 % measure); the study's phase boundaries are at "
             f"v_f = {100 * vf_at(STUDY_PHASES_M[0], STUDY_VF0, STUDY_HEIGHT_M):.1f} % and "
             f"{100 * vf_at(STUDY_PHASES_M[1], STUDY_VF0, STUDY_HEIGHT_M):.1f} %.", "",
             "| seed | v_f0 | law | F at U = 0.3 / 0.55 / 0.8 / 1.0 mm (N) | final (N) | peak (N) | rearrangement until U (mm) "
             "[v_f] | steep rise from U (mm) [v_f] | steepness | wall (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
    table = {name: [] for name, _ in LAWS}
    for s in done:
        for name, _ in LAWS:
            U, F, wall = res[(s, name)]
            f = figures(U, F)
            f["vf_rearrangement_end"] = vf_at(f["rearrangement_end"], *box[s])
            f["vf_steep_start"] = vf_at(f["steep_start"], *box[s])
            table[name].append(f)
            lines.append(f"| {s} | {100 * box[s][0]:.1f} % | {name} | {' / '.join(f'{v:.3f}' for v in f['reads'])} | "
                         f"{f['final']:.3f} | {f['peak']:.3f} | {f['rearrangement_end'] * 1e3:.2f} "
                         f"[{100 * f['vf_rearrangement_end']:.1f} %] | {f['steep_start'] * 1e3:.2f}{'+' if f['steep_censored'] else ''} "
                         f"[{100 * f['vf_steep_start']:.1f} %] | {f['steepness']:.2f} | {wall:.0f} |")
    if len(done) >= 2:
        lines += ["", "| law | final, mean ± s.e. (N) | range (N) | rearrangement until U, mean (mm) [v_f, mean ± s.d.] | "
                      "runs with a steep rise | its start, mean (mm) [v_f, mean ± s.d.] |", "|---|---|---|---|---|---|"]
        for name, _ in LAWS:
            fin = np.array([f["final"] for f in table[name]])
            steep = np.array([f["steep_start"] for f in table[name]])
            ok = np.isfinite(steep)
            v1 = np.array([f["vf_rearrangement_end"] for f in table[name]])
            v2 = np.array([f["vf_steep_start"] for f in table[name]])[ok]
            sd = lambda v: float(v.std(ddof=1)) if v.size > 1 else float("nan")  # noqa: E731
            lines.append(f"| {name} | {fin.mean():.3f} ± {fin.std(ddof=1) / np.sqrt(fin.size):.3f} | "
                         f"{fin.min():.3f}–{fin.max():.3f} | "
                         f"{np.mean([f['rearrangement_end'] for f in table[name]]) * 1e3:.2f} "
                         f"[{100 * v1.mean():.1f} ± {100 * sd(v1):.1f} %] | {int(ok.sum())} of {ok.size} | "
                         f"{(np.mean(steep[ok]) * 1e3 if ok.any() else float('nan')):.2f} "
                         f"[{(100 * v2.mean() if v2.size else float('nan')):.1f} ± {100 * sd(v2):.1f} %] |")
        names = [n for n, _ in LAWS]
        fin = {n: np.array([f["final"] for f in table[n]]) for n in names}
        lines += ["", "| pair, same specimens | mean relative difference of the final load ± s.e. | t (n − 1 dof) | "
                      "two-sided p | first above in |", "|---|---|---|---|---|"]
        for a, b in ((names[1], names[2]), (names[1], names[0]), (names[2], names[0])):
            m, se, t, p = paired(fin[a], fin[b])
            lines.append(f"| {a} − {b} | {100 * m:+.1f} % ± {100 * se:.1f} % | {t:+.2f} ({fin[a].size - 1}) | {p:.2f} | "
                         f"{int(np.sum(fin[a] > fin[b]))} of {fin[a].size} |")
        lines += ["", "Three pairs tested on the same runs, uncorrected; the final load is the mean over "
                  "U = 1.10–1.15 mm; d = 2(a − b)/(a + b) per specimen."]
        _plot(done, res, save / f"contact_ensemble{suffix}.png")
    return "\n".join(lines) + "\n"


def _plot(seeds, res, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    grid = np.linspace(0, FINAL_WINDOW_M[1], 116)
    for (name, _), c in zip(LAWS, ("C0", "C3", "C2")):
        curves = []
        for s in seeds:
            U, F, _ = res[(s, name)]
            k = int(np.argmax(U)) + 1
            u, i = np.unique(U[:k], return_index=True)
            curves.append(np.interp(grid, u, F[:k][i]))
            ax.plot(U[:k] * 1e3, F[:k], color=c, lw=0.4, alpha=0.35)
        ax.plot(grid * 1e3, np.mean(curves, axis=0), color=c, lw=2, label=f"{name}, mean of {len(seeds)}")
    ax.set_xlabel("U, lower plate travel (mm)")
    ax.set_ylabel("F, load cell (upper plate) (N)")
    ax.set_title("paper-40 specimens (seeds) under the study's contact models")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=120)
    os.replace(tmp, path)
    plt.close(fig)


def _seeds(text: str) -> list[int]:
    """``0-7``, ``1,3,5`` or both (``0-3,6``) as a list of seeds."""
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out += list(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    return out


def main(argv=None) -> str:
    argv = list(sys.argv[1:] if argv is None else argv)
    opt = lambda k, d: argv[argv.index(k) + 1] if k in argv else d  # noqa: E731
    seeds = _seeds(opt("--seeds", "0-7"))
    jobs = int(opt("--jobs", "2"))
    save = Path(opt("--save", str(ROOT / "runs" / "contact_ensemble")))
    out = opt("--out", None)
    study = "--study" in argv
    if "--reuse" not in argv:
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for log in pool.map(run_seed, seeds, [str(save)] * len(seeds), [study] * len(seeds)):
                print("\n".join(log), flush=True)
    text = summarise(seeds, save, study)
    print(text)
    if out:
        Path(out).write_text(text)
    return text


if __name__ == "__main__":
    main()
