"""Solver throughput: element-steps per second for 40, 160 and 640 fibers of 50 elements, with and
without fiber–fiber contact.

Scene: fibers of 50 elements (0.3 mm, r = 0.25 mm) on a square grid of pitch 2.2 r, slightly wavy
(amplitude ≤ 0.02 mm, random phase: neighbours come within the Verlet skin but do not overlap),
clamped at one end, damping α = 1e5 1/s, gravity across the fibers; with contact: the
``hertz_oriented`` hook with friction (μ = 0.2). Stable dt × 0.9; best of ``--repeats`` timed calls of
``Integrator.advance`` after a warm-up. Writes a markdown table to docs/bench/solver.md.

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_solver [--steps 1000]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import time
from pathlib import Path

import numpy as np

from fiberpipe.solver import Clamp, Clamps, Damping, Gravity, Material, State, build_model
from fiberpipe.solver.integrator import Integrator, choose_time_step, SimulationSettings

R = 0.25e-3


def bundle(n_fibers: int, n_el: int = 50, L: float = 15e-3, seed: int = 0, wave: float = 0.02e-3):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n_fibers)))
    xs = []
    s = np.linspace(0, L, n_el + 1)
    for k in range(n_fibers):
        i, j = divmod(k, side)
        a, ph = wave * rng.random(), 2 * np.pi * rng.random()
        xs.append(np.column_stack([2.2 * R * i + a * np.sin(2 * np.pi * s / L + ph),
                                   2.2 * R * j + a * np.cos(2 * np.pi * s / L + ph), s]))
    off = np.arange(n_fibers + 1) * (n_el + 1)
    return build_model(np.vstack(xs), off, R, Material(15e9, 1380.0, 0.3))


def measure(n_fibers: int, steps: int, repeats: int = 3, contact: bool = False) -> dict:
    m = bundle(n_fibers)
    effects = [Clamps([Clamp(i, "start") for i in range(n_fibers)]), Damping(1e5), Gravity([0, -9.81, 0])]
    if contact:
        from fiberpipe.benchmarks.scenes import default_contact
        effects.append(default_contact(m, friction=True))
    dt, _ = choose_time_step(m, effects, SimulationSettings())
    integrator = Integrator(m, effects, dt, history_rows=steps * (repeats + 1) // 100 + 2, history_every=100)
    state = State.at_rest(m)
    integrator.advance(state, 10)  # compile / load cache
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        integrator.advance(state, steps)
        best = min(best, time.perf_counter() - t)
    es = m.n_elements * steps / best
    row = {"fibers": n_fibers, "elements": m.n_elements, "contact": contact, "steps": steps, "seconds": best,
           "us_per_step": 1e6 * best / steps, "ns_per_element_step": 1e9 / es, "Melem_steps_per_s": es / 1e6}
    if contact:
        info = effects[-1].setup_info
        row["pairs"] = info.n_pairs
        row["active"] = info.n_active
    return row


def table(rows) -> list[str]:
    lines = ["| fibers | elements | contact | steps | µs/step | ns/element-step | M element-steps/s | candidate pairs | in contact |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['fibers']} | {r['elements']} | {'on' if r['contact'] else 'off'} | {r['steps']} | "
                     f"{r['us_per_step']:.1f} | {r['ns_per_element_step']:.1f} | {r['Melem_steps_per_s']:.2f} | "
                     f"{r.get('pairs', '')} | {r.get('active', '')} |")
    for c in (False, True):
        rs = [r for r in rows if r["contact"] == c]
        r40 = next((r for r in rs if r["fibers"] == 40), None)
        r640 = next((r for r in rs if r["fibers"] == 640), None)
        if r40 and r640:
            lines.append("")
            lines.append(f"Cost per element-step at 640 fibers / at 40 fibers, contact {'on' if c else 'off'}: "
                         f"**{r640['ns_per_element_step'] / r40['ns_per_element_step']:.2f}** (target ≤ 1.3).")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--fibers", type=int, nargs="*", default=[40, 160, 640])
    ap.add_argument("--out", default="docs/bench/solver.md")
    a = ap.parse_args(argv)
    import numba

    rows = [measure(n, a.steps, a.repeats, c) for c in (False, True) for n in a.fibers]
    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name"))
    except Exception:
        pass
    lines = [
        "# Solver throughput (beams, with and without contact)",
        "",
        f"- date: {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {cpu}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the end, "
        f"Python {platform.python_version()}, numba {numba.__version__}",
        f"- command: `NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_solver --steps {a.steps}`",
        "- scene: see the module docstring; one thread; best of "
        f"{a.repeats} timed calls of `Integrator.advance`.",
        "",
    ] + table(rows)
    text = "\n".join(lines) + "\n"
    print(text)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(text)
    return rows


if __name__ == "__main__":
    main()
