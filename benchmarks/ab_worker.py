"""A/B timing worker: one paper-40-like scene advanced on request, timed by its own CPU clock.

Run by path with the interpreter of the checkout under test (it imports whatever ``fiberpipe``
that interpreter has installed), so the same file drives the current code and a reference commit:

    PYTHON ab_worker.py CONFIG [KEY=VALUE ...]

Protocol on stdin/stdout, one line each: it prints ``ready <elements> <dt_s> <end_time_s>``; then
for every ``to <t_s>`` it advances to the first step at or after ``t_s`` (chunks of ≤ 2000 steps)
and prints ``<cpu_s> <wall_s> <steps> <t_s> <load_cell_N>``; ``curve`` prints the load cell's
force after every chunk of ≤ 2000 steps so far as ``t,F`` pairs; ``quit`` ends it. Only the solver
API that has not changed since the reference commit is used (``build_simulation``,
``choose_time_step``, ``Integrator.advance``). The step loop is compiled (or loaded from numba's
cache) on a second copy of the scene before ``ready``, so no span includes it.
"""

import sys
import tempfile
import time
from pathlib import Path


def main():
    from fiberpipe.artifacts import read_mesh
    from fiberpipe.config import load_config
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.integrator import Integrator, choose_time_step
    from fiberpipe.solver.state import State
    from fiberpipe.stages.mesh import run_mesh
    from fiberpipe.stages.simulate import clear_scene_planes
    import yaml

    config = sys.argv[1]
    overrides = {k: yaml.safe_load(v) for k, v in (a.split("=", 1) for a in sys.argv[2:])}
    cfg = load_config(config, overrides)
    with tempfile.TemporaryDirectory() as td:
        run_mesh(cfg, Path(cfg.input.fibers), Path(td) / "mesh.h5")
        mesh = read_mesh(Path(td) / "mesh.h5")
    clear_scene_planes(mesh, cfg)
    model, effects, settings = build_simulation(mesh, cfg)
    dt, _ = choose_time_step(model, effects, settings)
    threads = int(getattr(settings, "threads", 1) or 1)
    kw = {"threads": threads} if threads > 1 else {}
    integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9, **kw)
    from fiberpipe.solver.terms import SceneArrays
    probe = SceneArrays(model, dt)
    for e in effects:
        if e.name in ("plates", "drives"):
            e.setup(model, probe)
    end = float(settings.end_time_s or probe.end_time_hint)
    # compile (or load from the cache) the step loop before the first timed span, on a scene of its own
    m2, e2, _ = build_simulation(mesh, cfg)
    Integrator(m2, e2, dt, history_rows=10, history_every=10**9, **kw).advance(State.at_rest(m2), 2)
    st = State.at_rest(model)
    print(f"ready {model.n_elements} {dt:.9g} {end:.9g}", flush=True)
    upper = int(integ.planes.force.shape[0] > 1)
    curve = []
    for line in sys.stdin:
        words = line.split()
        if not words or words[0] == "quit":
            break
        if words[0] == "curve":
            print(" ".join(f"{t:.9g},{f:.6g}" for t, f in curve), flush=True)
            continue
        target = float(words[1])
        c0, w0, s0 = time.process_time(), time.perf_counter(), st.step
        while st.t < target * (1.0 - 1e-12):
            n = min(2000, max(1, int(round((target - st.t) / dt + 0.5))))
            integ.advance(st, n)
            curve.append((st.t, float(integ.planes.force[upper])))
        c1, w1 = time.process_time(), time.perf_counter()
        print(f"{c1 - c0:.6f} {w1 - w0:.6f} {st.step - s0} {st.t:.9g} {float(integ.planes.force[upper]):.6g}", flush=True)


if __name__ == "__main__":
    main()
