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

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_three_beam_energy.py \\
        [--dt-safety 0.9 0.45 0.225] [--law config linear] [--quick]
"""

from __future__ import annotations

import argparse
import time

from fiberpipe.verification.three_beam_energy import three_beam_energy


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
            e = three_beam_energy(dts, law, a.quick)
            print(f"| {law} | {dts:g} | {e.steps} | {e.max_abs_residual:.4f} | {e.max_residual:+.4f} | "
                  f"{e.final_residual:+.4f} | {e.fast_mode_share_early:.4f} | {e.fast_mode_share:.4f} |", flush=True)


if __name__ == "__main__":
    main()
