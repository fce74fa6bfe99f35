"""Fibre–fibre contact conserves energy: six fibres pressed together, undamped and frictionless, gain
no energy their loads did not supply (state functions only: the leapfrog kinetic term
½ v_{n−½}·M v_{n+½} + ALLSE + the stored contact potential of planes and fibres against the loads'
work f·(x_n − x0)).

Scene: four parallel fibres on a fixed plate between walls, two on top crossing them at ±3°, a line
load on the top two. With the potential formulation every law stays at or below the loads' work
(measured ≤ +0.001 of max|W| at 3 N/m); the legacy kernel of hertz_oriented creates +22 % here
(blend and K(Φ) without their derivatives, with ℓ_blend = 1 mm; see docs/contact.md)."""

import numpy as np
import pytest

from fiberpipe.config import ContactConfig
from fiberpipe.solver.laws import make_law
from fiberpipe.verification.six_fibres import energy_excess, six_fibres_run


def _excess(law, q, formulation, t_end=2e-3, dt_safety=0.9, penalty_factor=0.1):
    """max over the rows of (state energy − loads' work)/max|W|, and the kinetic energy per row."""
    _, res = six_fibres_run(law, q, formulation=formulation, t_end_s=t_end, dt_safety=dt_safety,
                            penalty_factor=penalty_factor)
    return energy_excess(res)


LAWS = [("hertz_oriented", {}), ("hertz_parallel", {}), ("linear", {"stiffness": 1e9}),
        ("hertz_crossed", {"phi_deg": 90.0}), ("scaled_stiffness", {"preset": "table1_phi6"}),
        ("scaled_stiffness", {"preset": "table1_parallel"}), ("scaled_stiffness", {"preset": "table3_identified"})]


def _law(name, kw):
    """The law as a config builds it: with the schema's blend length (the patch criterion)."""
    return make_law(name, E_pa=15e9, nu=0.3, blend_length_m=float(ContactConfig().blend_length), **kw)


# at 300 N/m the plate and wall penalty of the default step (penalty_factor 0.1) gains up to 2.3 % of W
# on some trajectories of this chaotic scene (table1_phi6, top fibres lifted by 0.5–2 nm; docs/contact.md,
# the plane penalty): the fibre–fibre contact is checked there with the penalty that resolves it, 0.05
# (measured ≤ −0.0005 on the same six trajectories)
@pytest.mark.parametrize("q,penalty_factor", [(3.0, 0.1), (300.0, 0.05)])
@pytest.mark.parametrize("law_name,kw", LAWS)
def test_six_fibres_create_no_energy_with_the_potential_formulation(law_name, kw, q, penalty_factor):
    excess, ke = _excess(_law(law_name, kw), q, "potential", penalty_factor=penalty_factor)
    assert excess < 0.01, excess
    n = len(ke) // 4
    assert np.max(ke[-n:]) < 2.0 * np.max(ke[:n]) + 1e-12  # no secular growth


@pytest.mark.parametrize("lift_m", [0.0, 1e-9])
@pytest.mark.parametrize("law_name,kw", LAWS)
def test_six_fibres_create_no_energy_at_1000_n_per_m_on_a_converged_step(law_name, kw, lift_m):
    # the sudden 1000 N/m load rattles the fibres on the plate and walls; at dt_safety 0.9 the stiff
    # plane penalty gains up to 54 % of W here (docs/contact.md), at 0.45 nothing is created
    # (measured ≤ 0 for every law on four seeds); two seeds of the chaotic scene (lift_m: top fibres raised)
    _, res = six_fibres_run(_law(law_name, kw), 1000.0, dt_safety=0.45, lift_m=lift_m)
    excess, _ = energy_excess(res)
    assert excess < 0.01, excess


@pytest.mark.xfail(strict=True, reason="known defect of the point part: without the patch criterion the angle "
                   "window gives the 3° crossings to the point law, whose force hops across element joints "
                   "(measured +5.7 % of the loads' work for table1_phi6)")
def test_six_fibres_create_no_energy_with_the_point_part_alone_at_300_n_per_m():
    law = make_law("scaled_stiffness", preset="table1_phi6", E_pa=15e9, nu=0.3)  # blend_length_m None: off
    excess, _ = _excess(law, 300.0, "potential")
    assert excess < 0.01, excess


@pytest.mark.xfail(strict=True, reason="known defect of the legacy kernel: hertz_oriented's blend and K(Φ) enter "
                   "without their derivatives (measured +22 % of the loads' work)")
def test_six_fibres_create_no_energy_with_the_legacy_hertz_oriented():
    excess, _ = _excess(make_law("hertz_oriented", E_pa=15e9, nu=0.3, blend_length_m=1e-3), 3.0, "legacy")
    assert excess < 0.01, excess
