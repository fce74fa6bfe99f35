"""Paper-40 states for the profile and the force checks: the scene of ``configs/paper-40.yaml`` at
the study's settings, advanced from rest, with its state (x, q, v, w, t, step) saved at given steps.

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.paper40_states OUT.npz STEP [STEP ...]

The states are the ones the profile (:mod:`fiberpipe.benchmarks.bench_profile`) starts from: the
early phase (first 12 ms, ≈ 1.4e5 steps) and the compacted phase (U ≈ 1 mm, ≈ 7.1e5 steps).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np


def scene(overrides: dict | None = None, config: Path | None = None):
    """``(model, effects, settings, dt)`` of paper-40 (mesh built in memory)."""
    from fiberpipe.bench import config_mesh, default_paper40_config
    from fiberpipe.config import load_config
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.integrator import choose_time_step
    from fiberpipe.stages.simulate import clear_scene_planes

    cfg = load_config(config or default_paper40_config(), overrides or {})
    mesh = config_mesh(cfg)
    clear_scene_planes(mesh, cfg)
    model, effects, settings = build_simulation(mesh, cfg)
    dt, _ = choose_time_step(model, effects, settings)
    return model, effects, settings, dt


def scene_and_state(state: str | Path | None = None, config: str | Path | None = None):
    """``(model, effects, dt, state)``: the scene of the run config ``config`` (None: paper-40) from
    the state saved at ``state`` (:func:`save_state`; None: from rest). A state of another node count
    than the scene's stops with a one-line error."""
    from fiberpipe.solver import State

    model, effects, _, dt = scene(config=Path(config) if config is not None else None)
    if state is None:
        return model, effects, dt, State.at_rest(model)
    st = load_state(state)
    if st.x.shape[0] != model.n_nodes:
        raise SystemExit(f"error: {state}: a state of {st.x.shape[0]} nodes, the scene has {model.n_nodes} "
                         "(give the state's config)")
    return model, effects, dt, st


def save_state(path, state) -> None:
    np.savez(path, x=state.x, q=state.q, v=state.v, w=state.w, acc=state.acc, t=state.t, step=state.step)


def load_state(path):
    """A saved state; its energy accumulators fitted to this version's ``layout.ACC_SIZE`` (a state saved
    by a version with fewer slots gets zeros in the new ones: the profiles need its motion only)."""
    from fiberpipe.solver.layout import ACC_SIZE
    from fiberpipe.solver.state import State
    d = np.load(path)
    acc = np.zeros(ACC_SIZE)
    n = min(ACC_SIZE, d["acc"].size)
    acc[:n] = d["acc"][:n]
    return State(d["x"].copy(), d["q"].copy(), d["v"].copy(), d["w"].copy(), float(d["t"]), int(d["step"]), acc)


def main(argv=None) -> None:
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.solver.state import State

    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0])
    out.parent.mkdir(parents=True, exist_ok=True)
    targets = sorted(int(s) for s in argv[1:])
    model, effects, settings, dt = scene()
    integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9, threads=settings.threads)
    st = State.at_rest(model)
    t0 = time.perf_counter()
    for k in targets:
        while st.step < k:
            integ.advance(st, min(20000, k - st.step))
        save_state(out.with_name(f"{out.stem}_{k}.npz"), st)
        print(f"step {k} t {st.t:.6g} s wall {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main()
