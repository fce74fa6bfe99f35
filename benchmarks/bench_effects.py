"""What each effect costs per step, and what a beam-only scene costs over the bare beam kernel.

A scene's ``effects:`` decide what the step loop does: an effect that is not listed allocates
nothing and calls no kernel. This measures, on the same 40-fiber bundle (50 elements each), the
time per element-step of

- the bare beam kernel: ``Integrator.advance`` with no effect at all (beam forces + update);
- a beam-only scene through the public run API (``simulate``: history, frames, checks, chunking);
- the beam-only loop plus one effect at a time (gravity, damping, clamps, loads, plates, walls,
  drives, contact, contact + friction), the difference being that effect's cost per step.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_effects.py [--steps 3000]

Writes docs/bench/effects.md.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from fiberpipe.benchmarks.bench_solver import bundle  # noqa: E402

from fiberpipe.solver import (  # noqa: E402
    Clamp, Clamps, Damping, Drive, Drives, Gravity, LineLoad, Loads, Plates, State, Walls,
)
from fiberpipe.benchmarks.scenes import default_contact  # noqa: E402
from fiberpipe.solver.integrator import Integrator, SimulationSettings, choose_time_step, simulate  # noqa: E402

R = 0.25e-3


def _prepare(model, effects, steps, repeats):
    dt, _ = choose_time_step(model, effects, SimulationSettings())
    integrator = Integrator(model, effects, dt, history_rows=steps * (repeats + 1) // 100 + 4, history_every=100)
    state = State.at_rest(model)
    integrator.advance(state, 20)  # compile or load from cache
    return integrator, state, dt


def _round_robin(prepared: dict, steps: int, repeats: int) -> dict:
    """Best time per step of each scene, timing the scenes in turn so that a load on the other
    core shifts all of them alike."""
    best = {k: np.inf for k in prepared}
    for _ in range(repeats):
        for k, (integrator, state, _) in prepared.items():
            t = time.perf_counter()
            integrator.advance(state, steps)
            best[k] = min(best[k], time.perf_counter() - t)
    return {k: v / steps for k, v in best.items()}


def _time_simulate(model, steps, dt, repeats=3):
    best = np.inf
    # same history cadence as the bare-kernel timing (a real run records ~2000 rows over 1e5+ steps)
    settings = SimulationSettings(dt_s=dt, end_time_s=steps * dt, output_frames=5, history_every=100)
    simulate(model, [], SimulationSettings(dt_s=dt, end_time_s=20 * dt, output_frames=2))  # warm
    for _ in range(repeats):
        t = time.perf_counter()
        res = simulate(model, [], settings)
        best = min(best, time.perf_counter() - t)
    return best / res.steps


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--fibers", type=int, default=40)
    ap.add_argument("--out", default="docs/bench/effects.md")
    a = ap.parse_args(argv)
    m = bundle(a.fibers)
    E = m.n_elements
    nf = a.fibers
    ymin, ymax = float(m.nodes_m[:, 1].min()) - R, float(m.nodes_m[:, 1].max()) + R
    xmin, xmax = float(m.nodes_m[:, 0].min()) - R, float(m.nodes_m[:, 0].max()) + R
    scenes = {
        "gravity": lambda: [Gravity([0, 0, -9.81])],
        "damping (alpha)": lambda: [Damping(1e5)],
        "clamps (every fiber's start)": lambda: [Clamps([Clamp(i, "start") for i in range(nf)])],
        "loads (line force on every fiber)": lambda: [Loads([LineLoad(i, [0, -1.0, 0]) for i in range(nf)])],
        "plates (y, lower moving)": lambda: [Plates(axis="y", lower="moving", upper="fixed", displacement_m=1e-4, velocity_m_s=0.1,
                                                    lower_position_m=ymin, upper_position_m=ymax)],
        "walls (x, two planes)": lambda: [Walls({"x": (xmin, xmax)})],
        "drives (one fiber)": lambda: [Drives([Drive(0, [0, -1e-4, 0], 0.1)])],
        "contact (hertz_oriented)": lambda: [default_contact(m)],
        "contact + friction": lambda: [default_contact(m, friction=True)],
    }
    repeats = 5
    prepared = {"bare": _prepare(m, [], a.steps, repeats)}
    prepared.update({name: _prepare(m, make(), a.steps, repeats) for name, make in scenes.items()})
    prepared["bare (again, last)"] = _prepare(m, [], a.steps, repeats)  # the first-timed slot runs slow
    times = _round_robin(prepared, a.steps, repeats)
    bare, dt = min(times["bare"], times["bare (again, last)"]), prepared["bare"][2]
    api = _time_simulate(m, a.steps, dt, repeats)
    rows = [(name, times[name]) for name in scenes]
    try:
        cpu = next(l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name"))
    except Exception:
        cpu = platform.machine()
    load = os.getloadavg()[0]
    ns = lambda t: 1e9 * t / E  # noqa: E731
    lines = [
        "# What each effect costs (what a scene leaves out costs nothing)",
        "",
        f"- date: {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}; machine: {cpu}, 1 thread, load average {load:.2f}",
        f"- command: `NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_effects.py --steps {a.steps}`",
        f"- scene: {nf} fibers × 50 elements ({E} elements, 0.3 mm, r = 0.25 mm, wavy, not touching), stable dt × 0.9 = {dt:.3g} s;"
        f" best of {repeats} timed calls of {a.steps} steps, scenes timed in turn",
        "",
        "| scene | µs/step | ns/element-step | cost of the effect, µs/step | × bare kernel |",
        "| --- | --- | --- | --- | --- |",
        f"| bare beam kernel (`Integrator.advance`, no effect) | {1e6 * bare:.1f} | {ns(bare):.1f} | — | 1.00 |",
        f"| beam-only scene through `simulate()` (history, frames, checks) | {1e6 * api:.1f} | {ns(api):.1f} | {1e6 * (api - bare):+.1f} | {api / bare:.3f} |",
    ]
    for name, t in rows:
        lines.append(f"| + {name} | {1e6 * t:.1f} | {ns(t):.1f} | {1e6 * (t - bare):+.1f} | {t / bare:.2f} |")
    lines += [
        "",
        f"The beam-only scene runs within {100 * (api / bare - 1):+.1f} % of the bare kernel (target: within 10 %).",
        "An effect that is not listed is not in the loop at all: its cost is zero by construction (no kernel call,",
        "no allocation); the rows above are what listing it adds. Contact cost grows with the number of touching",
        "pairs: this bundle is loose (fibers 2.2 r apart); see docs/bench/contact.md for packed bundles.",
        "",
    ]
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
