"""Energy created in the six-fiber conservation scene, per law, load, plane penalty and step.

The scene of :mod:`fiberpipe.verification.six_fibers` (undamped, frictionless, loaded at once) is
chaotic at high loads, so each cell is run on an ensemble: the top fibers lifted by
``seed × --lift`` (seed 0 is the test's scene). Each row gives the mean and the largest excess
(ALLKE + ALLSE + Π − W)/max|W| over the seeds (the leapfrog kinetic term, the stored contact
energy of planes and fibers) and the kinetic energy at the end over W. ``--tangent`` adds whether
the contact lowers the stable step: the modal step (:func:`fiberpipe.solver.timestep.modal_time_step`)
at seed 0's final state with the tangent of the fiber–fiber contact forces added to the beams',
over the beams' alone.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_step_energy.py \\
        [--law hertz_oriented ...] [--load 3 30 300 1000] [--dt-safety 0.9] [--seeds 4]
        [--penalty-factor 0.1] [--onset-fraction 0.04 0.004] [--tangent]
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np


def contact_tangent_ratio(model, law, x, q, onset_m: float) -> float:
    """dt of the modal step with the contact's tangent added, over the beams' alone, at ``(x, q)``
    (all segment pairs of different fibers, the default two Gauss points)."""
    from fiberpipe.solver.contact_pairs import gauss_points
    from fiberpipe.solver.contact_potential import contact_forces_pot
    from fiberpipe.solver.contact_state import new_records
    from fiberpipe.solver.timestep import modal_time_step

    seg = np.c_[model.el_n1, model.el_n1 + 1].astype(np.int64)
    fib = np.repeat(np.arange(model.n_fibers), np.diff(model.node_offsets) - 1)
    ii, jj = np.triu_indices(len(seg), 1)
    keep = fib[ii] != fib[jj]
    pairs = np.ascontiguousarray(np.c_[ii[keep], jj[keep]], dtype=np.int64)
    arc = np.c_[np.zeros(len(seg)), model.el_L0]
    radius = np.asarray(model.el_radius, dtype=np.float64)
    gxi, gw = gauss_points(2)

    def forces(xx):
        f = np.zeros_like(xx)
        contact_forces_pot(np.ascontiguousarray(xx), seg, radius, arc, pairs, len(pairs), law.law_id, law.params(),
                           gxi, gw, onset_m, f, new_records(len(pairs)), np.zeros(0), 0.0)
        return f

    free = np.zeros(model.n_nodes, np.int64)
    beams = modal_time_step(model, free, x=x, q=q)
    both = modal_time_step(model, free, x=x, q=q, extra_forces=forces)
    return both.dt_beams_s / beams.dt_beams_s


def main(argv=None) -> None:
    from fiberpipe.config import ContactConfig
    from fiberpipe.verification.six_fibers import LAWS, energy_excess, law_label, six_fibers_law, six_fibers_run

    names = sorted({n for n, _ in LAWS})
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--law", nargs="+", choices=names, default=None,
                    help="laws of the scene's set (default: all, every preset); a law with presets runs each")
    ap.add_argument("--load", type=float, nargs="+", default=[1000.0], help="line load on the top fibers, N/m")
    ap.add_argument("--dt-safety", type=float, nargs="+", default=[0.9])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--lift", type=float, default=1e-9, help="perturbation per seed, m")
    ap.add_argument("--penalty-factor", type=float, nargs="+", default=[0.1],
                    help="the plate's and walls' penalty factor(s) (scene.plates/walls.penalty_factor)")
    ap.add_argument("--onset-fraction", type=float, nargs="+", default=[0.04],
                    help="the plate's and walls' onset, fraction(s) of the radius (scene.plates/walls.onset_fraction)")
    ap.add_argument("--tangent", action="store_true", help="add the contact-tangent stable-step ratio (slow)")
    a = ap.parse_args(argv)
    laws = [(n, kw) for n, kw in LAWS if a.law is None or n in a.law]
    onset_m = float(ContactConfig().onset)
    print(f"# Six fibers, undamped and frictionless, {a.seeds} seeds ({time.strftime('%Y-%m-%d %H:%M')})\n")
    print("| law | load (N/m) | onset (r) | penalty factor | dt_safety | excess, mean over seeds | largest | "
          "ALLKE/W at the end, mean | dt with the contact's tangent / beams' |\n|---|---|---|---|---|---|---|---|---|",
          flush=True)
    for (name, kw), q, of, pf, s in itertools.product(laws, a.load, a.onset_fraction, a.penalty_factor, a.dt_safety):
        law = six_fibers_law(name, kw)
        ex, kw_end = [], []
        ratio = float("nan")
        for seed in range(a.seeds):
            m, res = six_fibers_run(law, q, dt_safety=s, lift_m=seed * a.lift, penalty_factor=pf, onset_fraction=of)
            e, ke = energy_excess(res)
            ex.append(e)
            kw_end.append(ke[-1] / np.max(np.abs(res.history["energy/external"])))
            if seed == 0 and a.tangent:
                ratio = contact_tangent_ratio(m, law, res.final_state.x, res.final_state.q, onset_m)
        print(f"| {law_label(name, kw)} | {q:g} | {of:g} | {pf:g} | {s:g} | {np.mean(ex):+.4f} | {np.max(ex):+.4f} | "
              f"{np.mean(kw_end):.2f} | {ratio:.6f} |", flush=True)


if __name__ == "__main__":
    main()
