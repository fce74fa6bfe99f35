"""The largest stable step of paper-40, measured, against the eigenvalue estimate.

From a saved state (``benchmarks/paper40_states.py``), the scene is advanced by the same
simulated time at time steps ``f × dt_modes`` (``dt_modes``: :func:`fiberpipe.solver.timestep.modal_time_step`
with the scene's axial lock and plane penalty factor, no safety factor) and at the element bound's
step; a run is unstable when it stops with a blow-up status or its largest node speed exceeds 10 ×
that of the element-bound run. By default the plane penalty and the friction springs follow the
step (``c m (2/Δt)²``), as in a run started at that step; ``--fixed-penalties`` keeps their
stiffness at the element-bound run's (penalty factor × (Δt/Δt₀)², ``scene.friction.stiffness``
fixed), so that a run switched to another step at a saved state changes nothing but the step.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_stable_step.py STATE.npz \\
        [--span 2ms] [--factors 0.95 1.0 1.05 1.1 1.2 1.3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fiberpipe.benchmarks.scenes import load_state, scene


def run_at(model, effects, dt: float, state_path, span_s: float) -> dict:
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.solver.layout import STATUS_OK

    integ = Integrator(model, effects, dt, history_rows=10, history_every=10**9)
    st = load_state(state_path)
    # the integrator's clock is step × Δt: re-base the saved step count on this Δt (a shift of
    # < Δt/2), else the plates would jump to the time the old step count gives at the new step
    st.step = int(round(st.t / dt))
    st.t = st.step * dt
    n = int(round(span_s / dt))
    vmax = 0.0
    status, done = STATUS_OK, 0
    t0 = time.process_time()
    while done < n and status == STATUS_OK:
        k = min(500, n - done)
        status, d, _ = integ.advance(st, k)
        done += d
        if np.isfinite(st.v).all():
            vmax = max(vmax, float(np.sqrt(np.max(np.sum(st.v**2, axis=1)))))
        else:
            vmax = np.inf
    return {"dt_s": dt, "steps": done, "status": int(status), "vmax_m_s": vmax,
            "cpu_s": time.process_time() - t0, "load_cell_N": float(integ.planes.force[-1] if integ.planes.force.size else 0.0)}


def _with_fixed_penalties(dt: float, dt0: float, kt0: float):
    """The scene's effects with the plane penalty and the friction springs as stiff as at ``dt0``."""
    model, effects, _, _ = scene({"scene.friction.stiffness": f"{kt0!r} N/m"})
    for e in effects:
        if e.name in ("plates", "walls"):
            e.penalty_factor = e.penalty_factor * (dt / dt0) ** 2
    return model, effects


def main(argv=None) -> list[str]:
    from fiberpipe.solver.terms import SceneArrays
    from fiberpipe.solver.timestep import modal_time_step, stable_time_step

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("state")
    ap.add_argument("--span", type=float, default=2e-3, help="simulated time per run [s]")
    ap.add_argument("--factors", type=float, nargs="+", default=[0.95, 1.0, 1.05, 1.1, 1.2, 1.3])
    ap.add_argument("--fixed-penalties", action="store_true")
    a = ap.parse_args(argv)
    model, effects, settings, _ = scene()
    probe = SceneArrays(model, 1.0)
    for e in effects:
        if e.kernels() is None:
            e.setup(model, probe)
    st = load_state(a.state)
    mt = modal_time_step(model, probe.fix_mask, penalty_factor=probe.penalty_factor, x=st.x, q=st.q)
    dt_el = stable_time_step(model).dt_stable_s
    ref = run_at(model, effects, 0.95 * dt_el, a.state, a.span)
    lines = [f"state t = {st.t * 1e3:.2f} ms; {mt.summary()}; element bound {dt_el:.4g} s", "",
             "| dt | dt / dt_modes | steps | status | largest speed (m/s) | stable | load cell (N) | CPU (s) |",
             "|---|---|---|---|---|---|---|---|",
             f"| {ref['dt_s']:.4g} s (0.95 × element bound) | {ref['dt_s'] / mt.dt_stable_s:.3f} | {ref['steps']} | "
             f"{ref['status']} | {ref['vmax_m_s']:.3g} | yes | {ref['load_cell_N']:.4g} | {ref['cpu_s']:.1f} |"]
    print("\n".join(lines), flush=True)
    kt0 = None
    if a.fixed_penalties:
        from fiberpipe.solver.integrator import Integrator
        kt0 = float(Integrator(model, effects, ref["dt_s"]).term_data("contact").params.kt_n_per_m)
        lines[0] += f"; penalties fixed at the 0.95 × element-bound step's (k_t = {kt0:.4g} N/m)"
    for f in a.factors:
        dt = f * mt.dt_stable_s
        m_, e_ = _with_fixed_penalties(dt, ref["dt_s"], kt0) if a.fixed_penalties else (model, effects)
        r = run_at(m_, e_, dt, a.state, a.span)
        ok = r["status"] == 0 and r["vmax_m_s"] < 10 * ref["vmax_m_s"]
        lines.append(f"| {r['dt_s']:.4g} s | {f:.3f} | {r['steps']} | {r['status']} | {r['vmax_m_s']:.3g} | "
                     f"{'yes' if ok else 'no'} | {r['load_cell_N']:.4g} | {r['cpu_s']:.1f} |")
        print(lines[-1], flush=True)
    return lines


if __name__ == "__main__":
    main()
