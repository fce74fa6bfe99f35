"""Paper-40 states for the profile and the force checks: the scene of ``configs/paper-40.yaml`` at
the study's settings, advanced from rest, with its state (x, q, v, w, t, step) saved at given steps.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/paper40_states.py OUT.npz STEP [STEP ...]

The scene and the state files are :mod:`fiberpipe.benchmarks.scenes`'s. The states are the ones
the profile (``benchmarks/bench_profile.py``) starts from: the early phase (first 12 ms, ≈ 1.4e5
steps) and the compacted phase (U ≈ 1 mm, ≈ 7.1e5 steps).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from fiberpipe.benchmarks.scenes import save_state, scene


def main(argv=None) -> None:
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.solver.state import State

    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0])
    out.parent.mkdir(parents=True, exist_ok=True)
    targets = sorted(int(s) for s in argv[1:])
    model, effects, settings, dt = scene()
    integrator = Integrator(model, effects, dt, history_rows=10, history_every=10**9, threads=settings.threads)
    state = State.at_rest(model)
    t0 = time.perf_counter()
    for k in targets:
        while state.step < k:
            integrator.advance(state, min(20000, k - state.step))
        save_state(out.with_name(f"{out.stem}_{k}.npz"), state)
        print(f"step {k} t {state.t:.6g} s wall {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main()
