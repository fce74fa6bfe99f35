"""Per-step cost of the paper-40 scene with subsets of its effects (docs/benchmarks.md, "Round 3").

Builds the mesh of ``configs/paper-40.yaml`` (or the config given), then for each effect set times
``Integrator.advance`` after 20 000 settling steps: best of 3 × 10 000 steps, one thread.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/profile_paper40.py [CONFIG] [--late STATE.npz]

``--late STATE.npz`` profiles the compacted bundle instead (the state at step 700 000 of the full
run, U ≈ 0.98 mm, where the contact pass costs most): the state is computed once with every effect
on (≈ 2 min) and kept in STATE.npz for the next calls (delete it when the specimen changes). The
contact hook starts afresh from that state: its friction histories are empty and the penetrations
it finds at its first call (≥ 5 % of r) are released over 0.1 ms as initial overlaps, so the
first 2000 steps (not timed) are not the run's own; the timed steps see the same bundle.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from fiberpipe.artifacts import read_fibers
from fiberpipe.config import load_config
from fiberpipe.model.mesh import mesh_polylines, resolve_overlaps
from fiberpipe.solver.build import build_simulation
from fiberpipe.solver.integrator import Integrator, choose_time_step
from fiberpipe.solver.state import State

# every set with the axial lock of configs/paper-40.yaml (without it the squeezed fibers leave along z)
EFFECT_SETS = (
    ["gravity", "damping", "constraints"],
    ["gravity", "damping", "constraints", "plates", "walls"],
    ["gravity", "damping", "constraints", "contact", "plates", "walls"],
    ["gravity", "damping", "constraints", "contact", "friction", "plates", "walls"],
)


LATE_STEP = 700_000


def _late_state(path: Path, mesh, config: str) -> State:
    import numpy as np

    if path.exists():
        d = np.load(path)
        if d["x"].shape != mesh.nodes_m.shape:
            raise SystemExit(f"{path} holds a state of another specimen ({d['x'].shape[0]} nodes, the mesh has "
                             f"{mesh.nodes_m.shape[0]}): delete it to recompute")
        return State(d["x"], d["q"], d["v"], d["w"], float(d["t"]), int(d["step"]), d["acc"])
    model, effects, settings = build_simulation(mesh, load_config(Path(config)))
    dt, _ = choose_time_step(model, effects, settings)
    st = State.at_rest(model)
    Integrator(model, effects, dt, history_rows=10, history_every=10**9).advance(st, LATE_STEP)
    np.savez(path, x=st.x, q=st.q, v=st.v, w=st.w, t=st.t, step=st.step, acc=st.acc)
    return st


def main(config: str = "configs/paper-40.yaml", late: str | None = None) -> None:
    base = load_config(Path(config))
    mesh = mesh_polylines(read_fibers(base.input.fibers), base.mesh.element_length, radius_m=base.fiber.radius)
    resolve_overlaps(mesh)
    start = _late_state(Path(late), mesh, config) if late else None
    print("| effects | µs/step |\n|---|---|")
    for eff in EFFECT_SETS:
        cfg = load_config(Path(config), overrides={"scene.effects": eff})
        model, effects, settings = build_simulation(mesh, cfg)
        dt, _ = choose_time_step(model, effects, settings)
        integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9)
        st = start.copy() if start is not None else State.at_rest(model)
        integ.advance(st, 2000 if start is not None else 20000)
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            integ.advance(st, 10000)
            best = min(best, (time.perf_counter() - t0) / 10000)
        print(f"| {', '.join(eff)} | {best * 1e6:.1f} |", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    late = None
    if "--late" in args:
        i = args.index("--late")
        late = args[i + 1]
        del args[i:i + 2]
    main(*args, late=late)
