"""States of a yarn run (or any run config with moving plates) part-way through its loading, for the
profiles and the thread bench at scale: the scene of ``CONFIG`` loaded ten times faster than it says
(a quick way to a compacted pile: the profile needs its contacts, not its curve), on one thread, its
state saved at 25, 50, 75 and 100 % of the plates' travel as ``OUT_25.npz`` … ``OUT_100.npz``.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/yarn_states.py runs/specimens/yarn-1000/config.yaml runs/bench/yarn1000
    NUMBA_NUM_THREADS=2 .venv/bin/python -m fiberpipe.benchmarks.bench_threads \\
        --config runs/specimens/yarn-1000/config.yaml --state runs/bench/yarn1000_100.npz --steps 100 --rounds 6
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path


def main(argv=None) -> None:
    from fiberpipe.benchmarks.scenes import save_state, scene
    from fiberpipe.solver import State
    from fiberpipe.solver.integrator import Integrator

    config, out = (sys.argv[1:] if argv is None else argv)[:2]
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    model, effects, _, dt = scene(overrides={"scene.loading.velocity": "10000 mm/min"}, config=Path(config))
    plates = next(e for e in effects if type(e).__name__ == "Plates")
    n_steps = int(plates.loading_time_s / dt) + 1
    integrator = Integrator(model, effects, dt, history_rows=n_steps // 100 + 10, history_every=100)
    state = State.at_rest(model)
    contact = next(e for e in effects if hasattr(e, "setup_info")).setup_info
    for quarter in (1, 2, 3, 4):
        cpu = time.process_time()
        integrator.advance(state, n_steps * quarter // 4 - state.step)
        save_state(f"{out}_{25 * quarter}.npz", state)
        print(f"{25 * quarter} %: step {state.step}, {time.process_time() - cpu:.1f} s CPU, pairs {contact.n_pairs}, "
              f"in contact {contact.n_active}, load {os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
