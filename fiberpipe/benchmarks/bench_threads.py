"""``solver.threads: 2`` against one thread, alternating in one process on the same scene.

Scene: the bundle of :mod:`fiberpipe.benchmarks.bench_solver` (fibers of 50 elements, contact
with friction, clamps, damping, gravity). Two integrators (1 thread and ``--threads``) advance
their own copies of the state by ``--steps`` steps alternately, ``--rounds`` times; wall time per
call (threads share the wall clock, not the CPU clock). The load average is recorded: the ratio
means something only on an idle machine (each thread needs a core).

    NUMBA_NUM_THREADS=2 .venv/bin/python -m fiberpipe.benchmarks.bench_threads [--fibers 160 640]
    NUMBA_NUM_THREADS=2 .venv/bin/python -m fiberpipe.benchmarks.bench_threads --fibers 1000 --pitch 1.98 --steps 100 --rounds 6
    NUMBA_NUM_THREADS=2 .venv/bin/python -m fiberpipe.benchmarks.bench_threads --state runs/bench/p40_708000.npz

``--state``: paper-40 at the study's settings from states saved by ``benchmarks/paper40_states.py``
of a source checkout (``make profile-paper40``) instead of the bench bundle.
``--config``: the scene of a run config (mesh built in memory) from rest, after 300 steps, e.g. the
400-fiber specimen's (``make bench-400-threads``):

    NUMBA_NUM_THREADS=2 .venv/bin/python -m fiberpipe.benchmarks.bench_threads \\
        --config runs/specimens/bundle-400/config.yaml --steps 200 --rounds 6
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from fiberpipe.benchmarks.scenes import scene_and_state


def _bench_scene(n_fibers: int, contact: bool, pitch_r: float):
    """The bench bundle of ``n_fibers`` at grid pitch ``pitch_r`` radii: (model, effects, dt, state at rest)."""
    from fiberpipe.benchmarks.bench_solver import bench_effects, bundle
    from fiberpipe.solver import State
    from fiberpipe.solver.integrator import SimulationSettings, choose_time_step

    m = bundle(n_fibers, pitch_r=pitch_r)
    effects = bench_effects(m, n_fibers, contact, pitch_r)
    dt, _ = choose_time_step(m, effects, SimulationSettings())
    return m, effects, dt, State.at_rest(m)


def measure(n_fibers: int, steps: int, rounds: int, threads: int = 2, contact: bool = True,
            state: str | None = None, config: str | None = None, pitch_r: float = 2.2) -> dict:
    from fiberpipe.solver.integrator import Integrator

    runs = {}
    for th in (1, threads):
        if config or state:  # a saved state, a config's scene, or both (scene_and_state)
            m, effects, dt, saved_state = scene_and_state(state, config)
        else:
            m, effects, dt, saved_state = _bench_scene(n_fibers, contact, pitch_r)
        integrator = Integrator(m, effects, dt, history_rows=steps * (rounds + 1) // 100 + 2, history_every=100, threads=th)
        integrator.advance(saved_state, 300 if config and not state else 10)  # compile (from rest: past the first contacts)
        runs[th] = (integrator, saved_state, m.n_elements)
    # the row's label: the bench bundle's fiber count, or the scene and where it starts
    if config:
        start = f"state {os.path.basename(state)}" if state else "from rest"
        label = f"{m.n_fibers} ({os.path.basename(os.path.dirname(os.path.abspath(config)))} {start})"
    elif state:
        label = f"{m.n_fibers} (paper-40 state {os.path.basename(state)})"
    else:
        label = n_fibers
    t = {1: [], threads: []}
    cpu = {1: [], threads: []}
    load = [os.getloadavg()[0]]
    for r in range(rounds):
        for th in ((1, threads) if r % 2 == 0 else (threads, 1)):
            integrator, saved_state, _ = runs[th]
            t0, c0 = time.perf_counter(), time.process_time()
            integrator.advance(saved_state, steps)
            t[th].append(time.perf_counter() - t0)
            cpu[th].append(time.process_time() - c0)
        load.append(os.getloadavg()[0])
    per = [a / b for a, b in zip(t[1], t[threads])]
    return {"fibers": label,
            "elements": runs[1][2], "threads": threads, "contact": contact, "steps": steps, "rounds": rounds,
            "s_1": min(t[1]), "s_n": min(t[threads]), "ratio_best": min(t[1]) / min(t[threads]),
            "ratio_median": statistics.median(per), "load_min": min(load), "load_max": max(load),
            # CPU seconds of the n-thread calls over their wall seconds: ≈ n when every thread had a core
            "cpu_per_wall_n": sum(cpu[threads]) / sum(t[threads]), "cpu_per_wall_1": sum(cpu[1]) / sum(t[1])}


def table(rows) -> list[str]:
    out = ["| fibers | elements | contact and friction | steps × rounds | 1 thread (s, best) | n threads (s, best) | 1 / n, best | 1 / n, median of rounds | CPU/wall, 1 and n threads | load average |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['fibers']} | {r['elements']} | {'on' if r['contact'] else 'off'} | "
                   f"{r['steps']} × {r['rounds']} | {r['s_1']:.3f} | "
                   f"{r['s_n']:.3f} ({r['threads']}) | **{r['ratio_best']:.2f}×** | {r['ratio_median']:.2f}× | "
                   f"{r.get('cpu_per_wall_1', float('nan')):.2f}, {r.get('cpu_per_wall_n', float('nan')):.2f} | "
                   f"{r['load_min']:.1f}–{r['load_max']:.1f} |")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fibers", type=int, nargs="+", default=[160, 640])
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--pitch", type=float, default=2.2,
                    help="grid pitch of the bench bundle in radii (1.98: squeezed, contacts active)")
    ap.add_argument("--no-contact", action="store_true",
                    help="beams, clamps, damping and gravity only: the part that runs in parallel")
    ap.add_argument("--state", nargs="+", default=[],
                    help="states saved by paper40_states (paper-40) or yarn_states (with the --config they are of)")
    ap.add_argument("--config", nargs="+", default=[],
                    help="run configs whose scenes run from rest (instead of the bench bundle)")
    a = ap.parse_args(argv)
    if a.config and a.state:  # the config's scene from each state
        rows = [measure(0, a.steps, a.rounds, a.threads, state=s, config=a.config[0]) for s in a.state]
    elif a.config:
        rows = [measure(0, a.steps, a.rounds, a.threads, config=p) for p in a.config]
    elif a.state:
        rows = [measure(0, a.steps, a.rounds, a.threads, state=p) for p in a.state]
    else:
        rows = [measure(n, a.steps, a.rounds, a.threads, contact=not a.no_contact, pitch_r=a.pitch) for n in a.fibers]
    print("\n".join(table(rows)))
    return rows


if __name__ == "__main__":
    main()
