"""Cost per element-step of a larger bundle against paper-40, both advanced from rest, alternating
in one process (CPU time of the process, so the ratio holds on a shared machine).

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_bundle_cost.py \\
        runs/specimens/bundle-400/config.yaml [--steps 400] [--rounds 6]

The bundle's config is the run config ``fiberpipe specimen`` writes beside its specimen
(``make specimen-400``). paper-40 takes ten times the bundle's steps per round when the bundle has
ten times its elements, so both sides run for about the same time.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def measure(bundle_config: Path, steps: int = 400, rounds: int = 6) -> dict:
    from fiberpipe.benchmarks.scenes import scene
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.solver.state import State

    from fiberpipe.solver.integrator import _plan_run

    runs, total_steps = {}, {}
    for name, cfg in (("paper-40", None), ("bundle", Path(bundle_config))):
        model, effects, settings, dt = scene(config=cfg)
        total_steps[name] = _plan_run(model, effects, settings, None, None).total_steps
        integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9)
        st = State.at_rest(model)
        integ.advance(st, 300)  # compile and warm
        runs[name] = [integ, st, model.n_elements, dt, 0.0, 0]
    ratio = max(1, round(runs["bundle"][2] / runs["paper-40"][2]))
    n_steps = {"paper-40": steps * ratio, "bundle": steps}
    for r in range(rounds):
        for name in (list(runs) if r % 2 == 0 else list(runs)[::-1]):
            run = runs[name]
            t0 = time.process_time()
            run[0].advance(run[1], n_steps[name])
            run[4] += time.process_time() - t0
            run[5] += n_steps[name]
    out = {}
    for name, (integ, st, n_el, dt, cpu, done) in runs.items():
        out[name] = {"elements": n_el, "dt_s": dt, "us_per_step": cpu / done * 1e6,
                     "ns_per_element_step": cpu / done / n_el * 1e9, "t_s": st.t,
                     "contacts": int(integ.term_data("contact").stats.n_active[0]),
                     # the whole loading at the cost per step from rest: a lower bound (a compacted
                     # step costs more, paper-40's 1.6× its early one)
                     "total_steps": int(total_steps[name]), "solution_s_from_rest_cost": cpu / done * total_steps[name]}
    out["ratio"] = out["bundle"]["ns_per_element_step"] / out["paper-40"]["ns_per_element_step"]
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundle_config", type=Path)
    ap.add_argument("--steps", type=int, default=400, help="the bundle's steps per round")
    ap.add_argument("--rounds", type=int, default=6)
    a = ap.parse_args(argv)
    r = measure(a.bundle_config, a.steps, a.rounds)
    print("\n".join(table(r)))
    return r


def table(r: dict) -> list[str]:
    """The markdown table of :func:`measure` and its ratio line."""
    lines = ["| scene | elements | dt (s) | µs per step | ns per element-step | contacts at the end | steps of the loading "
             "| loading at this cost per step (min) |", "|---|---|---|---|---|---|---|---|"]
    for name in ("paper-40", "bundle"):
        x = r[name]
        lines.append(f"| {name} | {x['elements']} | {x['dt_s']:.4g} | {x['us_per_step']:.1f} | "
                     f"{x['ns_per_element_step']:.1f} | {x['contacts']} | {x['total_steps']} | "
                     f"{x['solution_s_from_rest_cost'] / 60:.1f} |")
    return lines + ["", f"cost per element-step, bundle / paper-40: **{r['ratio']:.2f}** (target ≤ 1.2); the last "
                        "column is a lower bound, from the cost of a step from rest (a compacted step costs more)."]


if __name__ == "__main__":
    main()
