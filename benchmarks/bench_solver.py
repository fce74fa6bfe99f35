"""Beam-solver throughput: element-steps per second for 40, 160 and 640 fibers of 50 elements.

No contact; clamps, damping and gravity on (the per-step cost of a compaction run without the
contact pass). Writes a markdown table to docs/bench/solver.md.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_solver.py [--steps 2000] [--threads 1]

The step loop is serial (one thread); ``--threads`` is recorded but the beam kernel does not use
prange (the notes' measurements show 10–20× slowdowns of prange on a shared 2-core machine).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fiberpipe.solver import Clamp, Clamps, Damping, Gravity, Material, State, build_model
from fiberpipe.solver.integrator import Integrator, choose_time_step, SimulationSettings

R = 0.25e-3


def bundle(n_fibers: int, n_el: int = 50, L: float = 15e-3, seed: int = 0):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n_fibers)))
    xs = []
    s = np.linspace(0, L, n_el + 1)
    for k in range(n_fibers):
        i, j = divmod(k, side)
        a, ph = 0.2e-3 * rng.random(), 2 * np.pi * rng.random()
        xs.append(np.column_stack([2.2 * R * i + a * np.sin(2 * np.pi * s / L + ph),
                                   2.2 * R * j + a * np.cos(2 * np.pi * s / L + ph), s]))
    off = np.arange(n_fibers + 1) * (n_el + 1)
    return build_model(np.vstack(xs), off, R, Material(15e9, 1380.0, 0.3))


def measure(n_fibers: int, steps: int, repeats: int = 3) -> dict:
    m = bundle(n_fibers)
    eff = [Clamps([Clamp(i, "start") for i in range(n_fibers)]), Damping(1e5), Gravity([0, 0, -9.81])]
    dt, _ = choose_time_step(m, eff, SimulationSettings())
    integ = Integrator(m, eff, dt, history_rows=steps * (repeats + 1) // 100 + 2, history_every=100)
    st = State.at_rest(m)
    integ.advance(st, 10)  # compile / load cache
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        integ.advance(st, steps)
        best = min(best, time.perf_counter() - t)
    es = m.n_elements * steps / best
    return {"fibers": n_fibers, "elements": m.n_elements, "steps": steps, "seconds": best,
            "us_per_step": 1e6 * best / steps, "ns_per_element_step": 1e9 / es, "Melem_steps_per_s": es / 1e6}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--fibers", type=int, nargs="*", default=[40, 160, 640])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs/bench/solver.md"))
    a = ap.parse_args(argv)
    import numba

    rows = [measure(n, a.steps) for n in a.fibers]
    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name"))
    except Exception:
        pass
    lines = [
        "# Beam solver throughput (no contact)",
        "",
        f"- date: {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {cpu}, {numba.config.NUMBA_NUM_THREADS} numba threads available, Python {platform.python_version()}, numba {numba.__version__}",
        f"- command: `NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_solver.py --steps {a.steps}`",
        "- scene: fibers of 50 elements (0.3 mm, r = 0.25 mm, wavy), clamps + damping (α = 1e5) + gravity, stable dt × 0.9;",
        "  one serial thread (the step loop does not use prange); best of 3 timed calls of `Integrator.advance`.",
        "",
        "| fibers | elements | steps | µs/step | ns/element-step | M element-steps/s |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['fibers']} | {r['elements']} | {r['steps']} | {r['us_per_step']:.1f} | "
                     f"{r['ns_per_element_step']:.1f} | {r['Melem_steps_per_s']:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(text)


if __name__ == "__main__":
    main()
