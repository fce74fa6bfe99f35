"""Validation case 1: one wavy fiber between frictionless plates against the continuous beam."""

import math

import pytest

from fiberpipe.validation.wavy_fiber import (BeamSection, WavyFiberGeometry, finite_fiber_stiffness,
                                             periodic_stiffness_per_wave, validate, wavy_nodes)

E_PA, R_M, NU = 15e9, 0.25e-3, 0.3
SECTION = BeamSection(E_PA * math.pi * R_M**4 / 4, 6 * (1 + NU) / (7 + 6 * NU) * E_PA / (2 * (1 + NU)) * math.pi * R_M**2)


def test_finite_beam_reference_tends_to_192_EI_over_lambda_cubed_per_wave():
    """The free-ended fiber's beam solution adds exactly the periodic stiffness per added wave, and
    its stiffness per wave tends to it as the fiber grows (Euler–Bernoulli: 192 EI/λ³)."""
    lam = 9.6e-3
    per_wave = periodic_stiffness_per_wave(lam, SECTION, shear=False)
    assert per_wave == pytest.approx(192 * SECTION.bending_stiffness_n_m2 / lam**3, rel=1e-12)
    k8, k16 = (finite_fiber_stiffness(n, lam, SECTION, shear=False) for n in (8, 16))
    assert (k16 - k8) / 8 == pytest.approx(per_wave, rel=1e-6)
    assert finite_fiber_stiffness(200, lam, SECTION, shear=False) / 200 == pytest.approx(per_wave, rel=5e-3)
    with_shear = periodic_stiffness_per_wave(lam, SECTION)
    k8s, k16s = (finite_fiber_stiffness(n, lam, SECTION) for n in (8, 16))
    assert (k16s - k8s) / 8 == pytest.approx(with_shear, rel=1e-6)


def test_one_wave_with_free_ends_is_a_quarter_of_the_periodic_stiffness():
    """One wave, crests at both ends: two half-waves each with a free crest; the beam solution gives
    1/4 of the periodic value (Euler–Bernoulli), an independent closed form: each half-wave is then a
    cantilever pair with the trough clamped by symmetry, δ = (P/2)(λ/2)³/(3EI) per side."""
    lam = 9.6e-3
    k = finite_fiber_stiffness(1, lam, SECTION, shear=False)
    assert k == pytest.approx(0.25 * 192 * SECTION.bending_stiffness_n_m2 / lam**3, rel=1e-9)


def test_nodes_fall_on_every_crest_and_trough():
    g = WavyFiberGeometry(waves=2)
    nodes = wavy_nodes(g, 0.3e-3)
    per_half = (len(nodes) - 1) // 4
    assert nodes[::per_half, 1] == pytest.approx([g.amplitude_m * (-1) ** k for k in range(5)], abs=1e-12)


def test_wavy_fiber_plate_stiffness_within_3_percent_quick():
    """The quick variant (the 4- and 8-wave fibers at the config's mesh and speed) passes every row."""
    rows = validate(quick=True)
    assert len(rows) == 3
    for row in rows:
        assert row.passed, (row.quantity, row.measured, row.reference, row.error)
        assert row.error < 0.03


@pytest.mark.slow
def test_wavy_fiber_converged_in_mesh_and_loading_speed():
    """Full variant: halving or doubling the element length and halving the speed moves each
    stiffness by less than 1 %, and every row passes."""
    rows = validate(quick=False)
    for row in rows:
        assert row.passed
        for value in row.data["convergence"].values():
            assert abs(value - row.measured) / row.measured < 0.01
