"""The undamped 3-beam static case's energy residual is the time step's error, not the contact's.

Reference: a force that is minus the gradient of the stored potential Π leaves a state-function
residual (K_lf + ALLSE + Π − W)/max|W| that vanishes as Δt → 0; a force that is not would leave one
that does not. Measured on the quick variant (6 mm beams, 66 N/m at once, 0.6 ms, the case's
``hertz_oriented``): max |residual| 0.032 at ``dt_safety`` 0.9, 0.014 at 0.45 (2.3×); the full
case's table is in docs/verification.md (``make three-beam-energy``).
"""

from fiberpipe.verification.three_beam_energy import three_beam_energy as run


def test_undamped_three_beam_residual_shrinks_with_the_step_and_creates_no_energy():
    coarse = run(0.9, quick=True)
    fine = run(0.45, quick=True)
    # tolerance: the residual must fall by more than the step's first order (2×) when Δt halves
    assert fine.max_abs_residual < 0.5 * coarse.max_abs_residual, (coarse, fine)
    # energy goes missing into the fastest modes, it is not created: at most +1 % of W at any frame
    # (measured +0.49 % and +0.06 %)
    assert coarse.max_residual < 1e-2 and fine.max_residual < 1e-2, (coarse, fine)
    assert coarse.final_residual < 0 and fine.final_residual < 0, (coarse, fine)
    # the missing energy sits in the modes near the step's limit: K̄ − K_lf grows over the run
    assert coarse.fast_mode_share > 5 * coarse.fast_mode_share_early, coarse
