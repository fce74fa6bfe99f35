"""The solver against a reference commit, in one run: two worker processes (reference and current
code) advance the same scene alternately by equal spans of simulated time; each span is timed by
the worker's own CPU clock, so the ratio holds on a shared machine (both see the same load).

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ab.py \\
        --reference /path/to/reference/checkout [--until 12ms] [--spans 20] [--new KEY=VALUE ...]

``--reference`` is a checkout of the reference commit with its own ``.venv`` (``make setup`` there);
the reference runs its own ``configs/paper-40.yaml``, the current code this checkout's (or
``--config``). ``--new KEY=VALUE`` overrides the current side's config only (e.g.
``solver.stable_step=modes``): the sides then take different steps, and the figure is the ratio
of CPU time to the same simulated time. The load cell's force at the end of each side is printed
too: paper-40 is chaotic, so it agrees only within the run-to-run scatter.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

WORKER = Path(__file__).resolve().with_name("ab_worker.py")


def _start(python: str, config: Path, overrides: list[str], threads: int = 1) -> tuple[subprocess.Popen, tuple]:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    env.pop("PYTHONPATH", None)
    p = subprocess.Popen([python, str(WORKER), str(config), *overrides], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         text=True, env=env, cwd=str(config.parent))
    head = p.stdout.readline().split()
    if not head or head[0] != "ready":
        raise RuntimeError(f"worker {python} {config} did not start (output {head!r})")
    return p, (int(head[1]), float(head[2]), float(head[3]))


def _ask(p: subprocess.Popen, t: float) -> tuple:
    p.stdin.write(f"to {t!r}\n")
    p.stdin.flush()
    w = p.stdout.readline().split()
    return float(w[0]), float(w[1]), int(w[2]), float(w[3]), float(w[4])


def measure(reference: Path, config: Path, ref_config: Path, until_s: float | None, spans: int,
            new_overrides: list[str], ref_python: str | None = None, new_python: str | None = None,
            new_threads: int = 1) -> dict:
    """CPU seconds of both sides over ``spans`` alternating spans up to ``until_s`` (None: the
    scene's end time), in one run."""
    ref_python = ref_python or str(reference / ".venv" / "bin" / "python")
    new_python = new_python or sys.executable
    ref, (el_r, dt_r, end_r) = _start(ref_python, ref_config, [])
    new, (el_n, dt_n, end_n) = _start(new_python, config, new_overrides, new_threads)
    until = float(until_s or min(end_r, end_n))
    rows = []
    load = [os.getloadavg()[0]]
    for k in range(spans):
        t = until * (k + 1) / spans
        order = (ref, new) if k % 2 == 0 else (new, ref)
        got = {id(p): _ask(p, t) for p in order}
        rows.append((got[id(ref)], got[id(new)]))
        load.append(os.getloadavg()[0])
    curves = {}
    for name, p in (("ref", ref), ("new", new)):
        p.stdin.write("curve\n")
        p.stdin.flush()
        pts = [tuple(map(float, w.split(","))) for w in p.stdout.readline().split()]
        curves[name] = pts
    for p in (ref, new):
        p.stdin.write("quit\n")
        p.stdin.flush()
        p.wait(timeout=60)
    cpu_r = sum(r[0][0] for r in rows)
    cpu_n = sum(r[1][0] for r in rows)
    per_span = [r[0][0] / r[1][0] for r in rows if r[1][0] > 0]
    return {"until_s": until, "spans": spans, "elements": el_n, "dt_ref_s": dt_r, "dt_new_s": dt_n,
            "steps_ref": sum(r[0][2] for r in rows), "steps_new": sum(r[1][2] for r in rows),
            "cpu_ref_s": cpu_r, "cpu_new_s": cpu_n, "wall_ref_s": sum(r[0][1] for r in rows),
            "wall_new_s": sum(r[1][1] for r in rows), "speedup": cpu_r / cpu_n,
            "speedup_median_span": statistics.median(per_span) if per_span else float("nan"),
            "per_span": per_span, "load_cell_ref_N": rows[-1][0][4], "load_cell_new_N": rows[-1][1][4],
            "load_min": min(load), "load_max": max(load), "new_overrides": list(new_overrides),
            "curve_ref": curves["ref"], "curve_new": curves["new"],
            "curve_window_error": curve_window_error(curves["ref"], curves["new"], until)}


def curve_window_error(ref, new, until_s: float, windows: int = 5) -> float:
    """Largest difference of the two load-cell curves' means over ``windows`` equal windows of
    simulated time (the same windows of U: both sides follow the same loading), relative to the
    largest window mean of ``ref``. Five windows of paper-40's loading are its 0.23 mm windows of U."""
    import numpy as np
    if not ref or not new:
        return float("nan")
    tr, fr = np.array(ref).T
    tn, fn = np.array(new).T
    edges = np.linspace(0.0, until_s * (1 + 1e-9), windows + 1)
    mr = np.array([fr[(tr >= a) & (tr < b)].mean() for a, b in zip(edges[:-1], edges[1:])])
    mn = np.array([fn[(tn >= a) & (tn < b)].mean() for a, b in zip(edges[:-1], edges[1:])])
    return float(np.max(np.abs(mn - mr)) / max(np.max(np.abs(mr)), 1e-30))


def lines(r: dict, reference: str) -> list[str]:
    return [f"| {' '.join(r['new_overrides']) or 'same settings'} | {r['until_s'] * 1e3:.3g} ms | {r['spans']} | "
            f"{r['steps_ref']} / {r['steps_new']} | {r['cpu_ref_s']:.1f} | {r['cpu_new_s']:.1f} | **{r['speedup']:.2f}×** | "
            f"{r['speedup_median_span']:.2f}× | {r['wall_ref_s'] / r['wall_new_s']:.2f}× | "
            f"{r['load_cell_ref_N']:.4g} / {r['load_cell_new_N']:.4g} | "
            f"{100 * r['curve_window_error']:.2f} % | {r['load_min']:.1f}–{r['load_max']:.1f} |"]


HEADER = ["| current side | simulated time | spans | steps ref / new | CPU ref (s) | CPU new (s) | ref / new | median span | wall ref / new | load cell ref / new (N) | load-cell curve, 5 window means | load average |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]


def _time(s: str) -> float:
    from fiberpipe.units import to_si
    return to_si(s, "time")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", required=True, type=Path, help="checkout of the reference commit (with .venv)")
    ap.add_argument("--config", type=Path, default=None, help="current side's config (default configs/paper-40.yaml)")
    ap.add_argument("--until", default=None, help="simulated time, e.g. 12ms (default: the loading's end)")
    ap.add_argument("--spans", type=int, default=20)
    ap.add_argument("--new", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--threads", type=int, default=1,
                    help="numba threads of the current side's worker (with --new solver.threads=N); compare the "
                         "wall-time ratio then, on an idle machine")
    ap.add_argument("--save", type=Path, default=None, help="write the figures and curves as JSON here")
    a = ap.parse_args(argv)
    from fiberpipe.bench import default_paper40_config
    cfg = (a.config or default_paper40_config()).resolve()
    r = measure(a.reference.resolve(), cfg, (a.reference / "configs" / "paper-40.yaml").resolve(),
                _time(a.until) if a.until else None, a.spans, a.new, new_threads=a.threads)
    print("\n".join(HEADER + lines(r, str(a.reference))))
    print("per span ref/new:", " ".join(f"{x:.3f}" for x in r["per_span"]))
    if a.save:
        from fiberpipe.artifacts import write_json_atomic

        write_json_atomic(a.save, r)
    return r


if __name__ == "__main__":
    main()
