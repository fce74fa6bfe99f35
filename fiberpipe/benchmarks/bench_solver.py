"""Solver throughput: element-steps per second for 40, 160, 640 and 1000 fibers of 50 elements,
with and without fiber–fiber contact.

Scene: fibers of 50 elements (0.3 mm, r = 0.25 mm) on a grid of pitch 2.2 r, 8 × 5 fibers at 40
and the same grid scaled laterally above (16 × 10, 32 × 20, 40 × 25), slightly wavy (amplitude
≤ 0.02 mm, random phase: neighbours come within the Verlet skin but do not overlap), clamped at
one end, damping α = 1e5 1/s, gravity across the fibers; with contact: the ``hertz_oriented`` hook
with friction (μ = 0.2). ``--pitch 1.98``: the same bundle squeezed, every fiber pressed on its four
neighbours (1 % of the diameter) and the outer ones on four frictionless walls as hard, so every
bundle size keeps the same packing and nearly the same pairs in contact per element (the interior's
share of them grows with the size: 1.66 at 40 fibers, 1.91 at 1000); the contact and friction
passes work on active pairs (the scale rows: the cost per element-step at 1000 fibers against 40).
Stable dt × 0.9; best of ``--repeats`` timed calls of ``Integrator.advance`` after a warm-up (wall
and process CPU time of the same calls). Writes a markdown table to docs/bench/solver.md.

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_solver [--steps 1000]
    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_solver --fibers 40 1000 --pitch 1.98
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


#: the grid pitch of the bench bundle, in radii: neighbours 0.2 r apart, within the Verlet skin
SPACED_PITCH_R = 2.2


#: columns over rows of the bench bundle's grid: 40, 160, 640 and 1000 fibers fill 8 × 5, 16 × 10,
#: 32 × 20 and 40 × 25 (the 40-fiber grid scaled laterally, the same share of every fiber's neighbours)
GRID_ASPECT = 1.6


def grid_shape(n_fibers: int) -> tuple[int, int]:
    """(columns, rows) of the bench grid: ``GRID_ASPECT`` wide, the last row partly filled when
    ``n_fibers`` is not ``GRID_ASPECT`` k² for an integer k."""
    columns = max(1, int(round(np.sqrt(n_fibers * GRID_ASPECT))))
    return columns, -(-n_fibers // columns)


def bundle(n_fibers: int, n_el: int = 50, L: float = 15e-3, seed: int = 0, wave: float = 0.02e-3,
           pitch_r: float = SPACED_PITCH_R):
    """The bench bundle: ``n_fibers`` wavy fibers on a rectangular grid (:func:`grid_shape`) of pitch
    ``pitch_r`` radii (below 2: every fiber overlaps its four neighbours by 2 − ``pitch_r`` radii),
    fibers in row order, built in well under a second."""
    rng = np.random.default_rng(seed)
    columns, _ = grid_shape(n_fibers)
    xs = []
    s = np.linspace(0, L, n_el + 1)
    for k in range(n_fibers):
        j, i = divmod(k, columns)
        a, ph = wave * rng.random(), 2 * np.pi * rng.random()
        xs.append(np.column_stack([pitch_r * R * i + a * np.sin(2 * np.pi * s / L + ph),
                                   pitch_r * R * j + a * np.cos(2 * np.pi * s / L + ph), s]))
    off = np.arange(n_fibers + 1) * (n_el + 1)
    return build_model(np.vstack(xs), off, R, Material(15e9, 1380.0, 0.3))


def confining_walls(n_fibers: int, pitch_r: float):
    """The squeezed bundle's walls (``pitch_r`` < 2): four frictionless planes along x and y at the
    grid's outer fibers, each pressing them by half the fibers' mutual overlap (1 − ``pitch_r``/2)
    r, so every fiber stays pressed as in the bundle's interior, whatever the bundle's size; None
    for a spaced grid (no wall)."""
    from fiberpipe.solver import Walls

    if pitch_r >= 2.0:
        return None
    columns, rows = grid_shape(n_fibers)
    press = (1.0 - 0.5 * pitch_r) * R
    span = lambda count: (-R + press, pitch_r * R * (count - 1) + R - press)  # noqa: E731
    return Walls({"x": span(columns), "y": span(rows)})


def bench_effects(model, n_fibers: int, contact: bool, pitch_r: float) -> list:
    """The bench scene's effects: clamps at the fibers' start, damping α = 1e5 1/s, gravity across,
    the squeezed bundle's walls, and with ``contact`` the ``hertz_oriented`` contact with friction."""
    from fiberpipe.benchmarks.scenes import default_contact

    effects = [Clamps([Clamp(i, "start") for i in range(n_fibers)]), Damping(1e5), Gravity([0, -9.81, 0])]
    walls = confining_walls(n_fibers, pitch_r)
    if walls is not None:
        effects.append(walls)
    if contact:
        effects.append(default_contact(model, friction=True))
    return effects


def measure(n_fibers: int, steps: int, repeats: int = 3, contact: bool = False,
            pitch_r: float = SPACED_PITCH_R) -> dict:
    m = bundle(n_fibers, pitch_r=pitch_r)
    effects = bench_effects(m, n_fibers, contact, pitch_r)
    dt, _ = choose_time_step(m, effects, SimulationSettings())
    integrator = Integrator(m, effects, dt, history_rows=steps * (repeats + 1) // 100 + 2, history_every=100)
    state = State.at_rest(m)
    integrator.advance(state, 10)  # compile / load cache
    builds0 = effects[-1].setup_info.n_builds if contact else 0
    best = best_cpu = np.inf
    for _ in range(repeats):
        t, cpu = time.perf_counter(), time.process_time()
        integrator.advance(state, steps)
        best = min(best, time.perf_counter() - t)
        best_cpu = min(best_cpu, time.process_time() - cpu)
    es = m.n_elements * steps / best
    row = {"fibers": n_fibers, "elements": m.n_elements, "contact": contact, "steps": steps, "seconds": best,
           "us_per_step": 1e6 * best / steps, "ns_per_element_step": 1e9 / es, "Melem_steps_per_s": es / 1e6,
           "cpu_ns_per_element_step": 1e9 * best_cpu / (m.n_elements * steps), "pitch_r": pitch_r}
    if contact:
        info = effects[-1].setup_info
        row["pairs"] = info.n_pairs
        row["active"] = info.n_active
        row["builds"] = info.n_builds - builds0
    return row


def table(rows) -> list[str]:
    lines = ["| fibers | pitch (r) | elements | contact | steps | µs/step | ns/element-step | CPU ns/element-step | "
             "M element-steps/s | candidate pairs | in contact (per element) | list builds |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        active = f"{r['active']} ({r['active'] / r['elements']:.3f})" if "active" in r else ""
        lines.append(f"| {r['fibers']} | {r.get('pitch_r', SPACED_PITCH_R):g} | {r['elements']} | "
                     f"{'on' if r['contact'] else 'off'} | {r['steps']} | {r['us_per_step']:.1f} | "
                     f"{r['ns_per_element_step']:.1f} | {r.get('cpu_ns_per_element_step', float('nan')):.1f} | "
                     f"{r['Melem_steps_per_s']:.2f} | {r.get('pairs', '')} | {active} | {r.get('builds', '')} |")
    lines += [""] + scale_ratios(rows)
    return lines


def scale_ratios(rows) -> list[str]:
    """The cost per element-step of the largest bundle over the 40-fiber one's, per contact setting
    and pitch (wall and CPU time), one sentence each."""
    out = []
    for c in (False, True):
        for pitch in sorted({r.get("pitch_r", SPACED_PITCH_R) for r in rows}):
            rs = [r for r in rows if r["contact"] == c and r.get("pitch_r", SPACED_PITCH_R) == pitch]
            r40 = next((r for r in rs if r["fibers"] == 40), None)
            big = max(rs, key=lambda r: r["fibers"], default=None)
            if r40 is None or big is None or big["fibers"] == 40:
                continue
            wall = big["ns_per_element_step"] / r40["ns_per_element_step"]
            cpu = big.get("cpu_ns_per_element_step", np.nan) / r40.get("cpu_ns_per_element_step", np.nan)
            out.append(f"Cost per element-step at {big['fibers']} fibers / at 40 fibers, pitch {pitch:g} r, contact "
                       f"{'on' if c else 'off'}: **{wall:.2f}** wall, {cpu:.2f} CPU (target ≤ 1.3).")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--fibers", type=int, nargs="*", default=[40, 160, 640, 1000])
    ap.add_argument("--pitch", type=float, default=SPACED_PITCH_R,
                    help="grid pitch in radii (below 2: the fibers pressed on their neighbours)")
    ap.add_argument("--out", default="docs/bench/solver.md")
    a = ap.parse_args(argv)
    import numba

    rows = [measure(n, a.steps, a.repeats, c, a.pitch) for c in (False, True) for n in a.fibers]
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
        f"- command: `NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_solver --steps {a.steps} "
        f"--fibers {' '.join(map(str, a.fibers))} --pitch {a.pitch:g}`",
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
