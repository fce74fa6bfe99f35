"""Where the undamped 3-beam static case's energy goes, against ``dt_safety`` and the contact law.

The case of :func:`fiberpipe.verification.contact_cases.three_beam_static` at α = 0 (beams loaded at
once, no dissipation): its state-function residual (K_lf + ALLSE + Π − W)/max|W|, with the
leapfrog's kinetic term K_lf = ½ v_{n−½}·M v_{n+½}, drifts negative over the run. The table tells
a contact that creates or loses energy from the time step's error on the fastest modes:

- ``K̄ − K_lf`` is the mean of the two half-step kinetic energies less the leapfrog term,
  ¼Δt² Σ|f|²/m: zero for slow motion, and for a mode at ωΔt = θ a fraction θ²/4 of its energy
  (0.81 at θ = 1.8, the default step's fastest mode). K_lf + U conserves a linear mode exactly
  (central differences), but it undercounts a mode near the step's limit against its amplitude, so
  energy that a nonlinear law hands from the slow to the fastest modes reads as lost, and the
  column grows with it.
- With the linear law (a quadratic potential) the modes hardly exchange energy; with Johnson's
  line law they do.
- A residual that vanishes as the step is halved is the step's error, not the law's (a force
  that is not the gradient of Π would leave a residual that does not vanish).

    NUMBA_NUM_THREADS=1 .venv/bin/python -m fiberpipe.benchmarks.bench_three_beam_energy \\
        [--dt-safety 0.9 0.45 0.225] [--law config linear] [--quick]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EnergyRow:
    law: str
    dt_safety: float
    steps: int
    max_abs_residual: float   # max |residual| over the run
    max_residual: float       # the largest (signed) residual: > 0 is energy created
    final_residual: float
    fast_mode_share: float    # (K̄ − K_lf)/max|W| at the end of the run
    fast_mode_share_early: float  # the same, mean over the first quarter


def run(dt_safety: float, law: str = "config", quick: bool = False) -> EnergyRow:
    """One undamped run of the 3-beam scene at the config's load; ``law``: ``config`` (the case's)
    or ``linear`` (1e9 N/m², the energy tests' linear law)."""
    from fiberpipe.solver import simulate
    from fiberpipe.solver.laws import make_law
    from fiberpipe.verification.case_config import case_setup
    from fiberpipe.verification.contact_cases import three_beam_effects

    s = case_setup("three_beam_static")
    m = s.model(6e-3 if quick else s.lengths()[0])
    law_obj = None if law == "config" else make_law(law, E_pa=s.E, nu=s.nu, stiffness=1e9)
    eff = three_beam_effects(s, m, 1.0, 0.0, law_obj)
    res = simulate(m, eff, s.settings(output_frames=10 * s.output_frames, dt_safety=dt_safety))
    h = res.history
    r = h["energy/residual"]
    w_max = float(np.max(np.abs(h["energy/external"])))
    fast = (h["energy/kinetic"] - h["energy/kinetic_leapfrog"]) / w_max
    n = len(r)
    return EnergyRow(law=law, dt_safety=dt_safety, steps=res.steps, max_abs_residual=float(np.max(np.abs(r))),
                     max_residual=float(np.max(r)), final_residual=float(r[-1]), fast_mode_share=float(fast[-1]),
                     fast_mode_share_early=float(fast[: max(n // 4, 1)].mean()))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dt-safety", type=float, nargs="+", default=[0.9, 0.45, 0.225])
    ap.add_argument("--law", nargs="+", default=["config", "linear"], help="'config' (the case's law) or 'linear'")
    ap.add_argument("--quick", action="store_true", help="the quick variant's 6 mm beams")
    a = ap.parse_args(argv)
    print(f"# Undamped 3-beam static case, {'6' if a.quick else '15'} mm beams, 66 N/m "
          f"({time.strftime('%Y-%m-%d %H:%M')})\n")
    print("| law | dt_safety | steps | max \\|residual\\| | largest residual | final residual | "
          "(K̄ − K_lf)/W, first quarter | (K̄ − K_lf)/W, end |\n|---|---|---|---|---|---|---|---|", flush=True)
    for law in a.law:
        for dts in a.dt_safety:
            e = run(dts, law, a.quick)
            print(f"| {law} | {dts:g} | {e.steps} | {e.max_abs_residual:.4f} | {e.max_residual:+.4f} | "
                  f"{e.final_residual:+.4f} | {e.fast_mode_share_early:.4f} | {e.fast_mode_share:.4f} |", flush=True)


if __name__ == "__main__":
    main()
