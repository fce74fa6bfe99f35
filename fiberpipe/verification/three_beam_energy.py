"""Where the undamped 3-beam static case's energy goes, against ``dt_safety`` and the contact law.

The case of :func:`fiberpipe.verification.contact_cases.three_beam_static` at α = 0 (beams loaded at
once, no dissipation): its state-function residual (K_lf + ALLSE + Π − W)/max|W|, with the
leapfrog's kinetic term K_lf = ½ v_{n−½}·M v_{n+½}, and the share of the kinetic energy the step's
fastest modes hold, ``K̄ − K_lf`` (the mean of the two half-step kinetic energies less the leapfrog
term, ¼Δt² Σ|f|²/m: zero for slow motion, a fraction θ²/4 of a mode's energy at ωΔt = θ). A
residual that vanishes as the step is halved is the step's error, not the law's (a force that is not
the gradient of Π would leave a residual that does not vanish). ``benchmarks/bench_three_beam_energy.py``
of a source checkout prints the table (``make three-beam-energy``).
"""

from __future__ import annotations

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


def three_beam_energy(dt_safety: float, law: str = "config", quick: bool = False) -> EnergyRow:
    """One undamped run of the 3-beam scene at the config's load; ``law``: ``config`` (the case's)
    or ``linear`` (1e9 N/m², the energy tests' linear law)."""
    from ..solver import simulate
    from ..solver.laws import make_law
    from .case_config import case_setup
    from .contact_cases import three_beam_effects

    setup = case_setup("three_beam_static")
    model = setup.model(6e-3 if quick else setup.lengths()[0])
    law_obj = None if law == "config" else make_law(law, E_pa=setup.E, nu=setup.nu, stiffness=1e9)
    effects = three_beam_effects(setup, model, 1.0, 0.0, law_obj)
    res = simulate(model, effects, setup.settings(output_frames=10 * setup.output_frames, dt_safety=dt_safety))
    h = res.history
    r = h["energy/residual"]
    w_max = float(np.max(np.abs(h["energy/external"])))
    fast = (h["energy/kinetic"] - h["energy/kinetic_leapfrog"]) / w_max
    n = len(r)
    return EnergyRow(law=law, dt_safety=dt_safety, steps=res.steps, max_abs_residual=float(np.max(np.abs(r))),
                     max_residual=float(np.max(r)), final_residual=float(r[-1]), fast_mode_share=float(fast[-1]),
                     fast_mode_share_early=float(fast[: max(n // 4, 1)].mean()))
