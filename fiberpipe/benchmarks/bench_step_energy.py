"""Energy created by the time step in the six-fibre conservation scene, against ``dt_safety``.

The scene of :mod:`fiberpipe.verification.six_fibres` (undamped, frictionless, loaded at once) is
chaotic at high loads, so each step is run on an ensemble: the top fibres lifted by
``seed × --lift`` (seed 0 is the test's scene). For each ``dt_safety`` the table gives the mean and
the largest excess (ALLKE + ALLSE + Π − W)/max|W| over the seeds, and the kinetic energy at the
end over W. The last column asks whether the contact lowers the stable step: the modal step
(:func:`fiberpipe.solver.timestep.modal_time_step`) at seed 0's final state with the tangent of the
fibre–fibre contact forces added to the beams', over the beams' alone.

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_step_energy \\
        [--law hertz_oriented] [--load 1000] [--dt-safety 0.9 0.8 0.7 0.6 0.5 0.45] [--seeds 4]
        [--penalty-factor 0.1 0.05 0.02]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def contact_tangent_ratio(model, law, x, q, onset_m: float) -> float:
    """dt of the modal step with the contact's tangent added, over the beams' alone, at ``(x, q)``
    (all segment pairs of different fibres, the default two Gauss points)."""
    from fiberpipe.solver.contact import gauss_points
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
    from fiberpipe.solver.laws import make_law
    from fiberpipe.verification.six_fibres import energy_excess, six_fibres_run

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--law", default="hertz_oriented")
    ap.add_argument("--load", type=float, default=1000.0, help="line load on the top fibres, N/m")
    ap.add_argument("--dt-safety", type=float, nargs="+", default=[0.9, 0.8, 0.7, 0.6, 0.5, 0.45])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--lift", type=float, default=1e-9, help="perturbation per seed, m")
    ap.add_argument("--penalty-factor", type=float, nargs="+", default=[0.1],
                    help="the plate's and walls' penalty factor(s) (scene.plates/walls.penalty_factor)")
    a = ap.parse_args(argv)
    cc = ContactConfig()
    extra = {"stiffness": 1e9} if a.law == "linear" else {}  # the energy tests' linear law (N/m²)
    law = make_law(a.law, E_pa=15e9, nu=0.3, blend_length_m=float(cc.blend_length), **extra)
    print(f"# Six fibres, {a.law}, {a.load:g} N/m, undamped ({time.strftime('%Y-%m-%d %H:%M')})\n")
    print("| penalty factor | dt_safety | ω_max Δt | excess, mean over seeds | largest | ALLKE/W at the end, mean | "
          "dt with the contact's tangent / beams' |\n|---|---|---|---|---|---|---|", flush=True)
    for pf, s in ((pf, s) for pf in a.penalty_factor for s in a.dt_safety):
        ex, kw = [], []
        ratio = float("nan")
        for seed in range(a.seeds):
            m, res = six_fibres_run(law, a.load, dt_safety=s, lift_m=seed * a.lift, penalty_factor=pf)
            e, ke = energy_excess(res)
            ex.append(e)
            kw.append(ke[-1] / np.max(np.abs(res.history["energy/external"])))
            if seed == 0:
                ratio = contact_tangent_ratio(m, law, res.final_state.x, res.final_state.q, float(cc.onset))
        print(f"| {pf:g} | {s:g} | {2 * s:.2f} | {np.mean(ex):+.4f} | {np.max(ex):+.4f} | {np.mean(kw):.2f} | {ratio:.6f} |",
              flush=True)


if __name__ == "__main__":
    main()
