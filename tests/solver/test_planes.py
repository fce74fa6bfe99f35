"""The planes term: its own friction (walls with their own coefficient) and finite rigid plates,
against analytical references."""

import math

import numpy as np
import pytest

from fiberpipe.config import SceneConfig
from fiberpipe.errors import FiberpipeError
from fiberpipe.solver import (Clamp, Clamps, Damping, Integrator, LineLoad, Loads, Material, Plates, SimulationSettings,
                              State, Walls, build_model, choose_time_step, simulate)
from fiberpipe.solver._kernels_boundary import plane_static_penetration
from fiberpipe.solver.build import terms_from_config
from fiberpipe.solver.terms import SceneArrays

R = 0.25e-3
E_PA, RHO = 15e9, 1380.0
MAT = Material(E_PA, RHO, 0.3)


def _fiber(p0, p1, n_el):
    s = np.linspace(0.0, 1.0, n_el + 1)[:, None]
    x = np.asarray(p0, float) + s * (np.asarray(p1, float) - np.asarray(p0, float))
    return build_model(x, np.array([0, n_el + 1]), R, MAT)


def test_plates_and_friction_without_contact_run_no_contact_term():
    """scene.effects [plates, friction]: the plates carry the friction (their own per-step pass), no
    contact term runs; walls take scene.walls.mu, else scene.friction.mu."""
    m = _fiber([0, 0, R], [3e-3, 0, R], 10)
    scene = SceneConfig(effects=["friction", "plates", "walls"], friction={"mu": 0.4},
                        plates={"axis": "z", "lower": "fixed", "upper": "none", "lower_position": 0.0},
                        walls={"y": [-1e-3, 1e-3], "mu": 0.1})
    terms = terms_from_config(scene, m, None)
    assert [t.name for t in terms] == ["plates", "walls"]
    assert terms[0].mu == 0.4 and terms[1].mu == 0.1
    integ = Integrator(m, terms, 1e-8)
    assert [t.name for t, _, _ in integ.plan.terms] == ["plane_friction"]
    assert list(integ.term_data("plane_friction").mu) == [0.4, 0.1, 0.1]
    default = SceneConfig(effects=["friction", "walls"], walls={"y": [-1e-3, 1e-3]}, friction={"mu": 0.4})
    assert terms_from_config(default, m, None)[0].mu == 0.4
    frictionless = SceneConfig(effects=["walls"], walls={"y": [-1e-3, 1e-3], "mu": 0.3})
    assert terms_from_config(frictionless, m, None)[0].mu == 0.0
    assert any("walls.mu" in w for w in frictionless.warnings())
    assert [t.name for t, _, _ in Integrator(m, terms_from_config(frictionless, m, None), 1e-8).plan.terms] == []


def test_a_fiber_pulled_along_a_wall_slides_at_the_walls_mu():
    """A 3 mm fiber pressed onto the wall y = 0 by q_n = 10 N/m and pulled along it (x) by q_t = 2 N/m:
    with the wall's μ_w = 0.1 it slides at a = (q_t − μ_w q_n)/(ρA) (quadratic fit of its mean
    position, within 1 %); the fibers' μ (0.5, under which it would stick) does not act on the wall."""
    q_n, q_t, mu_w = 10.0, 2.0, 0.1
    probe = _fiber([0, R, 0], [3e-3, R, 0], 10)
    walls = dict(planes={"y": (0.0, 1e-2)}, mu=mu_w)
    dt, _ = choose_time_step(probe, [Walls(**walls)], SimulationSettings())
    # start at the static penetration of the wall's penalty (same force over stiffness on every node)
    share = q_n * probe.el_L0.sum() / probe.mass.sum()  # N per kg: the load per node over its mass
    d_s = plane_static_penetration(share / (0.1 * (2.0 / dt) ** 2), 0.02 * R)
    m = _fiber([0, R - d_s, 0], [3e-3, R - d_s, 0], 10)
    scene = SceneConfig(effects=["friction", "walls", "loads"], friction={"mu": 0.5},
                        walls={"y": [0.0, "10 mm"], "mu": mu_w}, loads=[{"fiber": 0, "line_force": [q_t, -q_n, 0]}])
    T = 1e-3
    res = simulate(m, terms_from_config(scene, m, None), SimulationSettings(end_time_s=T, output_frames=41))
    t = res.frames_time
    xm = res.frames_positions[:, :, 0].mean(axis=1) - m.nodes_m[:, 0].mean()
    sel = t > 0.1 * T
    a = 2.0 * np.polyfit(t[sel], xm[sel], 2)[0]
    rho_a = RHO * math.pi * R**2
    assert a == pytest.approx((q_t - mu_w * q_n) / rho_a, rel=0.01)


def _cantilever_under_plate(size_m, centre_m, n_el=40, L=10e-3, U=0.2e-3):
    """A cantilever (clamped at x = 0) pressed down by the upper plate (axis z) travelling U."""
    m = _fiber([0, 0, 0], [L, 0, 0], n_el)
    plate = Plates(axis="z", lower="none", upper="moving", displacement_m=U, velocity_m_s=0.1, size_m=size_m,
                   centre_m=centre_m)
    ei = E_PA * math.pi * R**4 / 4.0
    # the first bending mode critically damped: α = 2ω₁, ω₁ = 1.875² √(EI/ρA)/L²
    alpha = 2.0 * 1.875**2 * math.sqrt(ei / (RHO * math.pi * R**2)) / L**2
    effects = [Clamps([Clamp(0, "start")]), plate, Damping(alpha)]
    res = simulate(m, effects, SimulationSettings(end_time_s=2.0 * plate.loading_time_s, output_frames=3))
    return m, plate, res, ei


def test_a_short_plate_presses_a_cantilever_at_its_edge():
    """A 10 mm cantilever pressed by a plate that covers x ≥ a = 6 mm only: the plate touches the beam at
    its edge, a point load P at a with deflection w(a) = U − δ_pen (δ_pen: the penalty's static
    penetration under P); Euler–Bernoulli gives P = 3EI w(a)/a³ and the tip w(L) = w(a)(1 + 3(L − a)/(2a))
    (within 1 %). An infinite plate would press the tip instead, with (L/a)³ = 4.6 × less force."""
    a = 6e-3
    m, plate, res, ei = _cantilever_under_plate([6.2e-3, 2e-3], [a - 0.1e-3 + 3.1e-3, 0.0])
    P = float(res.history["plate_force"][-1, 1])
    k_node = float(plate.penalty_factor * m.mass[24] * (2.0 / res.dt_s) ** 2)  # the node at x = a
    w_a = plate.displacement_m - plane_static_penetration(P / k_node, plate.onset_fraction * R)
    assert P == pytest.approx(3.0 * ei * w_a / a**3, rel=0.01)
    x_end = res.final_state.x
    assert x_end[24, 0] == pytest.approx(a, abs=1e-5)
    w_tip = -float(x_end[-1, 2])
    assert w_tip == pytest.approx(w_a * (1.0 + 3.0 * (10e-3 - a) / (2.0 * a)), rel=0.01)


def test_a_plate_smaller_than_a_fiber_is_refused_naming_the_key():
    m = _fiber([0, 0, 0], [3e-3, 0, 0], 10)
    for size in ([0.4e-3, 2e-3], [2e-3, 0.1e-3]):
        with pytest.raises(FiberpipeError, match=r"scene\.plates\.size") as err:
            Plates(axis="z", lower="fixed", upper="fixed", size_m=size).setup(m, SceneArrays(m, 1e-8))
        assert "\n" not in str(err.value) and "diameter" in str(err.value)
