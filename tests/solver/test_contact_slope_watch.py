"""A contact law that stiffens with the penetration (the study's Eq. 1) is watched during the run: the
first slope the time step cannot carry gives one warning line naming the step it needs."""

import math

import pytest

from fiberpipe.config import ContactConfig
from fiberpipe.solver.terms.contact import ContactSlopeWatch, penalty_step_bound
from fiberpipe.solver.contact_state import new_stats
from fiberpipe.solver.laws import make_law
from fiberpipe.verification.six_fibers import six_fibers, six_fibers_run


def _preset(name):
    return make_law("scaled_stiffness", preset=name, E_pa=15e9, nu=0.3,
                    blend_length_m=float(ContactConfig().blend_length))


def test_scaled_stiffness_slope_follows_eq_1_and_stops_growing_after_n_segments():
    law = _preset("table1_phi2")  # per contact: K_i = S0 K_def S^(i−1) on [(i−1)d, id]
    L = 0.3e-3
    k1 = law.S0 * law.K_def * max(1.0, L / law.ref_length_m)
    assert law.node_stiffness_n_per_m(L) == pytest.approx(k1, rel=1e-12)
    assert law.node_stiffness_n_per_m(L, delta_m=10.5 * law.d_m) == pytest.approx(k1 * law.S**10, rel=1e-12)
    last = k1 * law.S ** (law.n - 1)
    assert law.node_stiffness_n_per_m(L, delta_m=5 * law.n * law.d_m) == pytest.approx(last, rel=1e-12)
    assert law.stiffens and not make_law("linear", stiffness=1e9, E_pa=15e9, nu=0.3).stiffens


def test_the_watch_warns_once_when_the_slope_outgrows_the_step_and_resets_its_peak():
    model, _ = six_fibers()
    dt = 0.9 * model.material.wave_speed_m_s ** -1 * float(model.el_L0.min())
    law = _preset("table1_phi2")
    stats = new_stats()
    watch = ContactSlopeWatch(model, dt, law, stats, onset_m=0.0)
    # δ where the slope needs a step below dt: (ωΔt)² of the slope above 4
    deep = 100 * law.d_m
    while penalty_step_bound(model, dt, law.node_stiffness_n_per_m(float(model.el_L0.max()), deep))[0] <= 4.0:
        deep *= 1.5
    stats.delta_peak_m[0] = 1e-9
    assert watch(1e-4) is None and stats.delta_peak_m[0] == 0.0
    stats.delta_peak_m[0] = deep
    msg = watch(2e-4)
    assert msg and "scaled_stiffness" in msg and "dt ≤" in msg and "solver.dt_safety" in msg
    total, dt_ok, _ = penalty_step_bound(model, dt, law.node_stiffness_n_per_m(float(model.el_L0.max()), deep))
    assert dt_ok < dt and math.isclose(dt_ok, 2 * dt / math.sqrt(total))
    stats.delta_peak_m[0] = deep
    assert watch(3e-4) is None  # one warning per run


def test_a_run_whose_law_stiffens_past_the_step_says_so():
    # the 2° preset loaded at once: under 1000 N/m the penetration reaches slopes the default step
    # cannot carry at all (measured: 4.4 µm, 7.3e6 N/m per node, stable for dt ≤ 7.9e-8 s against
    # 8.19e-8 s); under 300 N/m (ωΔt)² reaches 3.6, inside the stability limit 4 but past the
    # 4 × 0.9² the run's dt_safety keeps for the beams, and the run creates 12 % of its work; under
    # 30 N/m 3.0, and it creates none
    for q in (1000.0, 300.0):
        _, res = six_fibers_run(_preset("table1_phi2"), q)
        assert len(res.warnings) == 1 and "needs dt ≤" in res.warnings[0] and "dt_safety" in res.warnings[0]
    for q in (30.0, 3.0):
        _, res = six_fibers_run(_preset("table1_phi2"), q)
        assert res.warnings == []


def test_the_watch_keeps_the_runs_dt_safety_margin():
    model, _ = six_fibers()
    dt = 0.9 * model.material.wave_speed_m_s ** -1 * float(model.el_L0.min())
    law = make_law("hertz_crossed", phi_deg=90.0, E_pa=15e9, nu=0.3)
    _, _, k_lim = penalty_step_bound(model, dt, 0.0)
    margins = {}
    for safety in (1.0, 0.9):
        stats = new_stats()
        watch = ContactSlopeWatch(model, dt, law, stats, onset_m=0.0, dt_safety=safety)
        stats.secant_peak_n_per_m[0] = 0.9 * k_lim / 1.5  # 90 % of the stiffness the step carries
        margins[safety] = watch(1e-4)
    assert margins[1.0] is None and margins[0.9] and "0.9 of its stable step" in margins[0.9]


def test_the_watch_takes_a_hertz_laws_tangent_as_three_halves_of_its_largest_secant():
    # F ∝ δ^{3/2}: dF/dδ = 3/2 F/δ; the watch reads the largest F_n/δ of the pairs since its last look
    model, _ = six_fibers()
    dt = 0.9 * model.material.wave_speed_m_s ** -1 * float(model.el_L0.min())
    law = make_law("hertz_crossed", phi_deg=90.0, E_pa=15e9, nu=0.3)
    assert law.tangent_over_secant == 1.5 and ContactSlopeWatch.watched(law)
    assert not ContactSlopeWatch.watched(make_law("linear", stiffness=1e9, E_pa=15e9, nu=0.3))
    stats = new_stats()
    watch = ContactSlopeWatch(model, dt, law, stats, onset_m=0.0)
    _, _, k_lim = penalty_step_bound(model, dt, 0.0)  # the node stiffness the step carries
    stats.secant_peak_n_per_m[0] = 0.95 * k_lim / 1.5
    assert watch(1e-4) is None and stats.secant_peak_n_per_m[0] == 0.0
    stats.secant_peak_n_per_m[0] = 1.05 * k_lim / 1.5
    msg = watch(2e-4)
    assert msg and "hertz_crossed" in msg and "needs dt ≤" in msg
    assert watch(3e-4) is None  # one warning per run


def test_a_run_records_the_largest_secant_of_its_pairs_and_a_hertz_law_too_stiff_for_the_step_warns():
    # the crossed law with a modulus 100× the fibers' under 30 N/m: its tangent needs a step below
    # the run's (measured over 2 ms: 100× creates 7 % of W and warns, 60× warns, 30× is silent and
    # conservative, 150× diverges); the fibers' own modulus stays silent
    stiff = make_law("hertz_crossed", phi_deg=90.0, E_pa=100 * 15e9, nu=0.3)
    _, res = six_fibers_run(stiff, 30.0, t_end_s=4e-4)
    assert len(res.warnings) == 1 and "'hertz_crossed' reached a tangent" in res.warnings[0]
    _, res = six_fibers_run(make_law("hertz_crossed", phi_deg=90.0, E_pa=15e9, nu=0.3), 30.0, t_end_s=4e-4)
    assert res.warnings == []
