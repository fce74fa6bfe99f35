"""The point part's joint share (fiberpipe.solver.contact_potential._joint_share) with the study's
scaled-stiffness preset: where a crossing passes from one segment pair to the next, and where two
crossings of bent fibers merge, the pair potentials add up to a continuous function whose gradient
is the force, so the contact neither creates nor destroys energy there."""

import math

import numpy as np
import pytest

from fiberpipe.solver.laws import make_law

from _contact_geometry import central_gradient, pot_energy_forces, two_fiber_segments

R = 0.25e-3
# paper-40's law in configs/paper-40/oblique-6.yaml (the default ℓ_blend)
PRESET = dict(preset="table1_phi6", blend_length_m=5e-5)

# Two fibers of paper-40 (oblique-6, 46.34 ms; four segments each, µm about their mean) in two
# consecutive steps: they cross at 7.5°, bent by a fraction of a degree near a joint of each, so
# segment 3 of fiber A meets both segments 2 and 3 of fiber B at interior closest points whose
# depths differ by 1e-10 m. In the step the two depths change order; a share that hands the
# crossing to the nearer pair outright dropped or took up 5.5e-9 J, half the point energy; such
# switches, many a millisecond, made the run's residual of 1.2 % of its external work.
STEP = (
    [[53.202496747859044, -271.4169918011464, -599.4753526663704],
     [71.29158030247537, -252.645696626903, -299.4895507717008],
     [89.17201845573652, -233.70476674550252, 0.49367504940250884],
     [106.84466878943348, -214.52803418828705, 300.4743172214941],
     [124.31999541767078, -195.14878241013324, 600.4523673850231],
     [-50.66817026211964, 223.1648910438434, -600.5020362987046],
     [-69.8117337132512, 228.5835553764012, -300.4973218024478],
     [-88.9702368343424, 233.75042288606255, -0.49184828722868834],
     [-108.12148914794223, 238.6372311873209, 299.51438205635776],
     [-127.25912975551981, 243.30817127834158, 599.5213681141819]],
    [[53.20370225089864, -271.4184097635675, -599.4753526663704],
     [71.29139847174312, -252.64461782612773, -299.4895507717008],
     [89.17197898393796, -233.70148044302326, 0.49367504940250884],
     [106.84187041739382, -214.5229823237128, 300.4743172214941],
     [124.31912992274054, -195.14811579015006, 600.4523673850231],
     [-50.669403734549576, 223.166486550898, -600.5020362987046],
     [-69.81137726733843, 228.58242397668164, -300.4973218024478],
     [-88.96906482348066, 233.74906222650358, -0.49184828722868834],
     [-108.11908801908919, 238.6322503996098, 299.51438205635776],
     [-127.25981341186667, 243.3101262155563, 599.5213681141819]],
)


def _pot_ef(x, seg, pairs, arc, law):
    return pot_energy_forces(x, seg, pairs, arc, law)[:2]


def _law():
    return make_law("scaled_stiffness", E_pa=15e9, nu=0.3, **PRESET)


def test_the_forces_work_along_a_step_of_two_merging_crossings_equals_the_potential_drop():
    """Along the recorded step (straight path, 400 pieces), Π(end) − Π(start) + ∫ f·dx = 0 to 1e-3 of
    the energy change the share once made (5.5e-9 J), and no piece changes Π by more than twice the
    average."""
    law = _law()
    seg, pairs, arc = two_fiber_segments(4, 0.3e-3)
    xa, xb = (np.array(s) * 1e-6 for s in STEP)
    lam = np.linspace(0.0, 1.0, 401)
    es, work = [], 0.0
    f_prev = None
    for lm in lam:
        e, f = _pot_ef((1.0 - lm) * xa + lm * xb, seg, pairs, arc, law)
        if f_prev is not None:
            work += 0.5 * np.sum((f + f_prev) * (xb - xa)) * (lam[1] - lam[0])
        f_prev = f
        es.append(e)
    es = np.array(es)
    assert es.min() > 1e-9, "not in contact: the case tests nothing"
    assert abs(es[-1] - es[0] + work) < 5.5e-12, (es[-1] - es[0], work)
    steps = np.abs(np.diff(es))
    assert steps.max() <= 2.0 * (abs(es[-1] - es[0]) / steps.size) + 1e-14, (steps.max(), es[-1] - es[0])


@pytest.mark.parametrize("lam", [0.0, 0.3, 0.6, 1.0])
def test_force_is_minus_the_gradient_where_two_crossings_merge(lam):
    """Central differences (step 1e-12 m, against the share's ramps of ±(0.1 δ_c + 5 nm)) at points of
    the recorded step, inside a ramp: the share's derivative is in the force."""
    law = _law()
    seg, pairs, arc = two_fiber_segments(4, 0.3e-3)
    xa, xb = (np.array(s) * 1e-6 for s in STEP)
    x = (1.0 - lam) * xa + lam * xb
    e, f = _pot_ef(x, seg, pairs, arc, law)
    g = central_gradient(lambda xx: _pot_ef(xx, seg, pairs, arc, law)[0], x, 1e-12)
    scale = np.abs(f).max()
    assert scale > 0
    assert np.abs(f + g).max() < 1e-4 * scale, (np.abs(f + g).max() / scale)
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale


def _crossing(phi_deg, depth, shift, kink):
    """Fiber 0 along x (3 segments of 0.3 mm), its inner nodes moved by ``kink`` sideways (its crossing
    angle with fiber 1 changes at the joints by ≈ kink/0.3 mm), fiber 1 crossing it at phi_deg above
    it by 2R − depth, offset by ``shift`` along fiber 0."""
    s = np.linspace(-0.5, 0.5, 4) * 0.9e-3
    ph = math.radians(phi_deg)
    a = np.c_[s, np.zeros(4), np.zeros(4)]
    a[1:3, 1] += kink
    b = np.c_[shift + s * math.cos(ph), s * math.sin(ph), np.full(4, 2 * R - depth)]
    return np.vstack([a, b])


@pytest.mark.parametrize("phi_deg,depth,kink", [(8.0, 0.12e-6, 2e-6), (8.0, 0.12e-6, -2e-6), (10.0, 0.2e-6, 2e-6),
                                               (10.0, 0.2e-6, -2e-6)])
def test_preset_point_contact_sliding_across_a_kinked_joint_keeps_its_energy(phi_deg, depth, kink):
    """A crossing inside the patch blend (0 < w < 1, so the point share depends on the pair's Φ)
    slides 40 µm along fiber 0 across a joint kinked sideways by ``kink`` (Φ changes by ≈ 0.4° at
    the joint): the work of the forces on fiber 1 equals the drop of the potential to 1e-4 of the
    energy. A share that hands the crossing over within 1e-9 (r_i + r_j) without a force missed
    the step w(Φ₁) − w(Φ₂) of the point energy there, 11–15 % of the energy."""
    law = _law()
    seg, pairs, arc = two_fiber_segments(3, 0.3e-3)
    shifts = np.linspace(0.13e-3, 0.17e-3, 2001)
    es, fx = [], []
    for sh in shifts:
        e, f = _pot_ef(_crossing(phi_deg, depth, sh, kink), seg, pairs, arc, law)
        es.append(e)
        fx.append(f[4:, 0].sum())
    es, fx = np.array(es), np.array(fx)
    assert es.min() > 0, "not in contact: the case tests nothing"
    work = np.sum(0.5 * (fx[1:] + fx[:-1]) * np.diff(shifts))
    assert abs(es[-1] - es[0] + work) < 1e-4 * es.max(), ((es[-1] - es[0] + work) / es.max())
