"""Unit tests of the beam solver core: model, stable step, invariances, effects, energies, API."""

import math

import numpy as np
import pytest

from fiberpipe.errors import FiberpipeError, SimulationDiverged
from fiberpipe.solver import (Clamp, Clamps, ContactHook, Damping, Drive, Drives, Gravity, LineLoad, Loads,
                              Material, Plates, PointLoad, SimulationSettings, State, Walls, build_model,
                              simulate, stable_time_step)
from fiberpipe.solver._kernels_beam import beam_forces
from fiberpipe.solver.layout import ACC_V2_MAX
from fiberpipe.solver.integrator import Integrator

MAT = Material(15e9, 1380.0, 0.3)
R = 0.25e-3


def straight(n_el=50, L=15e-3):
    x = np.zeros((n_el + 1, 3))
    x[:, 0] = np.linspace(0, L, n_el + 1)
    return x


def helix(n=41, radius=2e-3, pitch=6e-3, turns=1.2):
    s = np.linspace(0, turns * 2 * np.pi, n)
    return np.column_stack([radius * np.cos(s), radius * np.sin(s), pitch * s / (2 * np.pi)])


def internal_forces(model, x, q):
    f = np.zeros((model.n_nodes, 3))
    m = np.zeros((model.n_nodes, 3))
    se, _ = beam_forces(x, q, model.el_n1, model.el_invL0, model.el_C, model.el_Dk, model.gamma_rest,
                        model.theta_rest, f, m, True, 0.0, np.zeros((0, 6)))
    return f, m, se


def rot_z(a):
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def test_model_masses_and_offsets():
    x = np.vstack([straight(10), straight(20) + [0, 1e-3, 0]])
    m = build_model(x, [0, 11, 32], [R, 2 * R], MAT)
    assert m.n_elements == 30 and m.n_fibers == 2
    A = np.pi * R**2
    assert m.mass[:11].sum() == pytest.approx(1380 * A * 15e-3)
    assert m.mass[11:].sum() == pytest.approx(1380 * 4 * A * 15e-3)
    assert np.all(m.el_fiber[:10] == 0) and np.all(m.el_fiber[10:] == 1)
    assert m.fiber_node_index(1, "end") == 31 and m.fiber_node_index(1, -2) == 30


def test_bad_inputs_rejected():
    with pytest.raises(FiberpipeError):
        build_model(np.zeros((3, 3)), [0, 3], R, MAT)  # zero-length elements
    with pytest.raises(FiberpipeError):
        build_model(straight(4), [0, 2, 5], -1.0, MAT)
    with pytest.raises(FiberpipeError):
        Material(-1.0, 1000.0)


def test_stable_time_step_matches_notes_table():
    # Timoshenko B31-like, 0.3 mm elements, physical rotary inertia → 9.10e-8 s (axial)
    rep = stable_time_step(build_model(straight(), [0, 51], R, MAT))
    assert rep.dt_stable_s == pytest.approx(9.10e-8, rel=0.01)
    assert rep.governing_mode == "axial"
    assert rep.per_mode_s["torsion"] == pytest.approx(1.47e-7, rel=0.01)
    small = stable_time_step(build_model(straight(), [0, 51], R, MAT, rotary_inertia_scale=0.01))
    assert small.dt_stable_s == pytest.approx(1.287e-8, rel=0.02)  # bending, √(2s) L/c (isotropic rotary inertia)


def test_curved_fiber_is_stress_free_and_objective():
    x = helix()
    m = build_model(x, [0, len(x)], R, MAT)
    f, mom, se = internal_forces(m, m.nodes_m.copy(), m.quats0.copy())
    assert se == pytest.approx(0.0, abs=1e-25)
    assert np.abs(f).max() < 1e-9 and np.abs(mom).max() < 1e-12
    # rigid rotation + translation of the rest configuration: still no forces
    Q = rot_z(0.7) @ np.array([[1, 0, 0], [0, math.cos(0.4), -math.sin(0.4)], [0, math.sin(0.4), math.cos(0.4)]])
    from fiberpipe.solver.model import matrices_to_quats, quats_to_matrices

    x2 = m.nodes_m @ Q.T + [1e-3, -2e-3, 5e-3]
    q2 = matrices_to_quats(Q[None] @ quats_to_matrices(m.quats0))
    f, mom, se = internal_forces(m, x2, q2)
    assert se < 1e-20 and np.abs(f).max() < 1e-8 and np.abs(mom).max() < 1e-11


def test_forces_are_balanced():
    x = helix()
    m = build_model(x, [0, len(x)], R, MAT)
    rng = np.random.default_rng(0)
    x2 = m.nodes_m + 2e-6 * rng.standard_normal(m.nodes_m.shape)
    f, mom, _ = internal_forces(m, x2, m.quats0.copy())
    assert np.allclose(f.sum(0), 0, atol=1e-12)
    # total moment about the origin vanishes: Σ (x × f + m) = 0
    assert np.allclose((np.cross(x2, f) + mom).sum(0), 0, atol=1e-12)


def test_free_curved_fiber_conserves_energy_3d():
    # bending, torsion and shear at once, no damping. The imposed nodal spins excite the shear
    # mode near 2/Δt, whose leapfrog energy measure oscillates by O((ωΔt)²): check that the energy
    # error converges at second order in Δt, and the momentum. Below Δt ≈ 0.1 × the limit the error
    # levels off at ~1e-3 of the energy (measured down to 0.025 ×, with the old anisotropic and the
    # isotropic rotary inertia alike): the moment pair is exact only to first order in the element's
    # relative rotation (docs/solver.md), so the order is checked at 0.4 and 0.2 × the limit.
    x = helix()
    m = build_model(x, [0, len(x)], R, MAT)
    dts = stable_time_step(m).dt_stable_s
    s = np.linspace(0, 1, m.n_nodes)[:, None]
    errs = []
    for frac in (0.4, 0.2):
        st = State.at_rest(m)
        st.v[:] = 0.05 * np.hstack([np.sin(np.pi * s), np.cos(2 * np.pi * s), np.sin(3 * np.pi * s)])
        st.w[:] = 300.0 * np.hstack([np.cos(np.pi * s), np.sin(2 * np.pi * s), np.cos(np.pi * s)])
        res = simulate(m, [], SimulationSettings(dt_s=frac * dts, end_time_s=1.5e-4, output_frames=2,
                                                 history_every=10), state=st)
        tot = res.history["energy/total"]
        e0 = res.history["energy/kinetic"][0] + res.history["energy/strain"][0]
        errs.append(np.max(np.abs(tot - tot[0])) / e0)
        p = (m.mass[:, None] * res.final_state.v).sum(0)
        assert np.allclose(p, (m.mass[:, None] * st.v).sum(0), atol=1e-12)
    # K_e is the mean of the half-step energies (exact work balance), whose swing for a mode near
    # 2/Δt is O((ωΔt)²): 1.0e-2 at 0.2 ×, 4.9e-2 at 0.4 × the limit (measured)
    assert errs[1] < 2e-2
    assert errs[0] / errs[1] > 3.0


def test_gravity_free_fall_and_external_work():
    m = build_model(straight(10), [0, 11], R, MAT)
    T = 1e-3
    res = simulate(m, [Gravity([0, 0, -9.81])], SimulationSettings(end_time_s=T, output_frames=2))
    t = res.frames_time[-1]
    assert res.frames_positions[-1, :, 2].mean() == pytest.approx(-0.5 * 9.81 * t**2, rel=1e-3)
    h = res.history
    assert h["energy/external"][-1] == pytest.approx(h["energy/kinetic"][-1], rel=1e-3)
    assert abs(h["energy/residual"][-1]) < 1e-3


def test_damping_energy_balance_and_line_load():
    m = build_model(straight(), [0, 51], R, MAT)
    q = 0.5  # N/m
    eff = [Clamps([Clamp(0, "start")]), Loads([LineLoad(0, [0, -q, 0])]), Damping(9000.0)]
    res = simulate(m, eff, SimulationSettings(end_time_s=4e-3, output_frames=2))
    I = np.pi * R**4 / 4
    ref = q * 0.015**4 / (8 * 15e9 * I)
    assert -res.frames_positions[-1, -1, 1] == pytest.approx(ref, rel=0.01)
    h = res.history
    assert h["energy/damping"][-1] > 0
    assert np.max(np.abs(h["energy/residual"])) < 1e-3
    # static: W_ext = 2 SE
    assert h["energy/external"][-1] == pytest.approx(2 * h["energy/strain"][-1], rel=1e-3)


def test_heavy_damping_is_booked_in_step_with_the_leapfrog_kinetic_term():
    """A suddenly loaded cantilever under α Δt = 0.16, a row every step: with the damping booked in
    step with ½ v_{n−½}·M v_{n+½} (``damping_leapfrog``) the state-function balance of this nearly
    quadratic potential closes to rounding; with ALLVD (half of each step's dissipation at its row)
    it is off by O(αΔt) of the kinetic energy's swing."""
    m = build_model(straight(), [0, 51], R, MAT)
    eff = [Clamps([Clamp(0, "start")]), Loads([LineLoad(0, [0, -0.5, 0])]), Damping(2e6)]
    res = simulate(m, eff, SimulationSettings(end_time_s=0.2e-3, output_frames=2, history_every=1))
    h = res.history
    assert res.dt_s * 2e6 > 0.15
    scale = np.max(np.maximum(np.abs(h["energy/external"]), h["energy/strain"] + h["energy/kinetic"]))
    r_allvd = h["energy/residual"] + (h["energy/damping"] - h["energy/damping_leapfrog"]) / scale
    assert np.max(np.abs(h["energy/residual"])) < 1e-9  # measured 1.2e-12
    assert np.max(np.abs(r_allvd)) > 1e-6  # measured 4.8e-6
    # the two bookings differ by less than a step's dissipation and agree in sum
    assert h["energy/damping_leapfrog"][-1] == pytest.approx(h["energy/damping"][-1], rel=1e-3)


def test_plate_reaction_equals_weight_and_walls():
    x = straight(20, 6e-3)
    m = build_model(x, [0, 21], R, MAT)
    g = 200.0  # strong gravity to make the force large compared with noise
    eff = [Gravity([0, 0, -g]), Plates(axis="z", lower="fixed", upper="none"), Damping(2e4),
           Walls({"x": (-R - 1e-6, 6e-3 + R + 1e-6)})]
    res = simulate(m, eff, SimulationSettings(end_time_s=2e-3, output_frames=2))
    W = m.mass.sum() * g
    assert res.history["plate_force"][-1, 0] == pytest.approx(W, rel=1e-3)
    assert res.history["plate_force"][-1, 1] == 0.0
    assert res.history["wall_force"].shape[1] == 2
    assert np.all(res.history["wall_force"] == 0.0)
    pen = R - (res.frames_positions[-1, :, 2] - (-R))
    assert pen.max() > 0 and pen.max() < 0.01 * R  # penalty penetration is small


def test_moving_plate_compresses_and_balances_energy():
    # two crossed short fibers on top of each other, squeezed: here one fiber with its axis along x
    x = straight(20, 6e-3)
    m = build_model(x, [0, 21], R, MAT)
    eff = [Plates(axis="y", lower="moving", upper="fixed", displacement_m=2e-6, velocity_m_s=0.05),
           Damping(1e4)]
    res = simulate(m, eff, SimulationSettings(output_frames=3))
    h = res.history
    assert h["plate_displacement"][-1, 0] == pytest.approx(2e-6, rel=1e-6)
    assert h["plate_force"][-1, 0] > 0 and h["plate_force"][-1, 1] > 0
    assert h["energy/external"][-1] > 0
    assert abs(h["energy/residual"][-1]) < 0.02


def test_drive_moves_fiber_rigidly():
    x = np.vstack([straight(10, 3e-3), straight(10, 3e-3) + [0, 1e-3, 0]])
    m = build_model(x, [0, 11, 22], R, MAT)
    d = [0.0, 0.0, -0.3e-3]
    res = simulate(m, [Drives([Drive(1, d, 1000e-3 / 60)])], SimulationSettings(output_frames=3))
    disp = res.frames_positions[-1, 11:] - m.nodes_m[11:]
    assert np.allclose(disp, d, atol=1e-12)
    assert np.allclose(res.frames_positions[-1, :11], m.nodes_m[:11])
    # smooth ramp: velocity is zero at the end
    assert np.abs(res.final_state.v[11:]).max() < 1e-6


def test_absent_effects_cost_no_memory():
    m = build_model(straight(10), [0, 11], R, MAT)
    integrator = Integrator(m, [], 1e-8)
    scene = integrator.scene
    assert scene.f_ext.size == 0 and scene.fix_mask.size == 0 and scene.pl_axis.size == 0
    assert integrator.strain_prev.size == 0 and not integrator.plan.terms and integrator.plan.chain == ()


def test_user_dt_above_limit_refused_and_forced_run_diagnosed():
    m = build_model(straight(), [0, 51], R, MAT)
    with pytest.raises(FiberpipeError, match="above the stable limit"):
        simulate(m, [], SimulationSettings(dt_s=2e-7, end_time_s=1e-4))
    st = State.at_rest(m)
    st.x[25, 2] += 1e-7  # a small perturbation that the unstable step amplifies
    with pytest.raises(SimulationDiverged) as ei:
        simulate(m, [Clamps([Clamp(0, "start")])],
                 SimulationSettings(dt_s=1.3e-7, force_dt=True, end_time_s=2e-3, output_frames=5), state=st)
    exc = ei.value
    assert "fiber 0" in str(exc) and "stable limit" in str(exc)
    pr = exc.partial_result
    assert not pr.completed and len(pr.frames_time) >= 1 and np.all(np.isfinite(pr.frames_positions))


def test_contact_hook_is_called():
    from _hooks import lift  # a fake contact pass (the hooks tests' too): f[:, 2] += 1e-4 N, 7 contacts

    m = build_model(straight(10), [0, 11], R, MAT)
    hook = ContactHook(lift, (np.array([1e-4, 7.0]),))
    res = simulate(m, [Clamps([Clamp(0, "start")]), hook, Damping(2e4)],
                   SimulationSettings(end_time_s=2e-3, output_frames=2))
    assert np.all(res.history["contacts"] == 7)
    assert res.frames_positions[-1, -1, 2] > 0  # pushed up
    assert "contact" in res.effects


def test_effects_parameter_checks():
    with pytest.raises(FiberpipeError):
        Damping(-1.0)
    with pytest.raises(FiberpipeError):
        Plates(axis="w")
    with pytest.raises(FiberpipeError):
        Plates(lower="moving", displacement_m=0.0)
    with pytest.raises(FiberpipeError):
        Walls({"x": (1.0, 0.0)})
    m = build_model(straight(10), [0, 11], R, MAT)
    with pytest.raises(FiberpipeError, match=r"clamps\[0\]\.fiber = 3: the model has 1 fiber"):
        simulate(m, [Clamps([Clamp(3, "start")])], SimulationSettings(end_time_s=1e-6))


def test_stiffness_proportional_damping_dissipates_and_balances():
    m = build_model(straight(), [0, 51], R, MAT)
    beta = 2e-9
    from fiberpipe.solver import choose_time_step

    dt, rep = choose_time_step(m, [Damping(0.0, beta)], SimulationSettings())
    assert rep.dt_stable_s < stable_time_step(m).dt_stable_s
    eff = [Clamps([Clamp(0, "start")]), Loads([PointLoad(0, [0, 0, -1e-3], "end")]), Damping(3000.0, beta)]
    res = simulate(m, eff, SimulationSettings(end_time_s=1e-3, output_frames=2))
    h = res.history
    assert h["energy/damping"][-1] > 0
    assert np.max(np.abs(h["energy/residual"][len(h["time"]) // 10:])) < 1e-2


def _perturbed_helices(n_fibers=5, amp_q=1e-3):
    fibers = [helix(21) + [3e-3 * k, 0, 0] for k in range(n_fibers)]
    x = np.vstack(fibers)
    offs = np.cumsum([0] + [len(f) for f in fibers])
    m = build_model(x, offs, R, MAT)
    rng = np.random.default_rng(1)
    xs = m.nodes_m + 1e-6 * rng.standard_normal(m.nodes_m.shape)
    qs = m.quats0 + amp_q * rng.standard_normal(m.quats0.shape)
    qs /= np.linalg.norm(qs, axis=1)[:, None]
    return m, xs, qs


def _node_pass(m, xs, qs, threads=1):
    """The step loop's beam pass on (xs, qs): (ElementForces, strain energy, elements beyond the series)."""
    from fiberpipe.solver._kernels_beam import beam_pass_all, beam_pass_fibers

    integ = Integrator(m, [], 1e-9)
    work = integ._kernel_args()[1]
    se, n_large = (beam_pass_fibers if threads > 1 else beam_pass_all)(xs, qs, integ.model_arrays, work)
    return [a.copy() for a in work.ef], se, n_large


def test_node_beam_pass_matches_the_exact_element_pass():
    """The vectorised node-wise pass (series of the rotation logarithm, selects) gives the per-element
    pass's resultants of curved, perturbed fibers (0.36 rad of rest rotation per element) to 1e-10 of
    each component's largest (the series holds to 7e-14; the moments are differences of larger terms), the per-fiber prange copy gives the same rows
    bit for bit, and gathering them per node gives the scatter of beam_forces."""
    from fiberpipe.solver._kernels_beam import (beam_resultants, gather_resultants, new_element_forces,
                                                scatter_element_forces)
    m, xs, qs = _perturbed_helices()
    f1, m1, se1 = internal_forces(m, xs, qs)
    ef, se, n_large = _node_pass(m, xs, qs)
    ef2, se2, _ = _node_pass(m, xs, qs, threads=2)
    assert n_large == 0
    assert all(np.array_equal(a, b) for a, b in zip(ef, ef2))
    assert se == pytest.approx(se1, rel=1e-12) and se2 == pytest.approx(se1, rel=1e-12)
    offs64 = np.asarray(m.node_offsets, np.int64)
    eb = np.zeros((m.n_elements, 9))
    beam_resultants(xs, qs, m.el_n1, m.el_invL0, m.el_C, m.el_Dk, m.gamma_rest, m.theta_rest, eb, True, 0.0,
                    np.zeros((0, 6)), offs64)
    exact = new_element_forces(m.n_nodes)
    scatter_element_forces(np.asarray(m.el_n1, np.int64), eb, exact)
    for a, b in zip(ef, exact):
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    f2 = np.zeros_like(f1)
    m2 = np.zeros_like(m1)
    gather_resultants(eb, offs64, f2, m2)
    assert np.abs(f2 - f1).max() <= 1e-12 * np.abs(f1).max() and np.abs(m2 - m1).max() <= 1e-12 * np.abs(m1).max()


def test_node_beam_pass_flags_elements_beyond_its_series_and_the_step_takes_the_exact_pass():
    """An element rotated by more than 0.64 rad is counted, and the step loop's first step from rest
    then moves every node by the exact forces: v_{1/2} = Δt f / m (no damping)."""
    m, xs, qs = _perturbed_helices(n_fibers=2)
    i = 10  # twist node 10 by 1.2 rad about its own d3: its two elements pass the series' 0.64 rad
    half = 0.6
    rot = np.array([np.cos(half), 0.0, 0.0, np.sin(half)])
    w0, x0, y0, z0 = qs[i]
    a, b, c, d = rot
    qs[i] = [w0 * a - z0 * d, x0 * a + y0 * d, y0 * a - x0 * d, z0 * a + w0 * d]
    assert _node_pass(m, xs, qs)[2] == 2
    f, _mom, _ = internal_forces(m, xs, qs)
    dt = 1e-9
    integ = Integrator(m, [], dt)
    s = State.at_rest(m)
    s.x[:] = xs
    s.q[:] = qs
    integ.advance(s, 1)
    v_exact = dt * f / m.mass[:, None]
    assert np.abs(s.v - v_exact).max() <= 1e-12 * np.abs(v_exact).max()


def test_update_rotates_fast_spinning_nodes_exactly():
    """A node whose rotation increment ½Δt|Ω| exceeds the update's series is rotated by the exact
    q ⊗ exp(ΩΔt/2)."""
    m, xs, qs = _perturbed_helices(n_fibers=1, amp_q=0.0)
    dt = 1e-6
    integ = Integrator(m, [], dt)
    s = State.at_rest(m)
    s.w[5] = [4e5, -1e5, 2e5]  # ½Δt|Ω| ≈ 0.23 rad: (…)² = 0.053 > 1e-2
    q0 = s.q[5].copy()
    integ.advance(s, 1)
    h = 0.5 * dt * s.w[5]
    hn = np.linalg.norm(h)
    e = np.concatenate([[np.cos(hn)], np.sin(hn) / hn * h])
    w0, x0, y0, z0 = q0
    ew, ex, ey, ez = e
    expect = np.array([w0 * ew - x0 * ex - y0 * ey - z0 * ez, w0 * ex + ew * x0 + (y0 * ez - z0 * ey),
                       w0 * ey + ew * y0 + (z0 * ex - x0 * ez), w0 * ez + ew * z0 + (x0 * ey - y0 * ex)])
    assert np.abs(s.q[5] - expect).max() < 1e-14


def test_threads_step_loop_follows_the_serial_run_to_rounding():
    """solver.threads > 1 (the prange beam pass and update over contiguous node ranges) follows the serial
    run to rounding: every node takes the same formulas, but a task's range puts other nodes in the vector
    loop's scalar remainder than the one loop over all nodes, whose contractions may differ in the last bit."""
    m, xs, qs = _perturbed_helices()
    st = []
    for th in (1, 2):
        integ = Integrator(m, [Gravity([0, 0, -9.81]), Damping(1e3)], 1e-8, history_rows=4, history_every=50,
                           threads=th)
        s = State.at_rest(m)
        s.x[:] = xs
        s.q[:] = qs
        integ.advance(s, 100)
        st.append(s)
    assert np.abs(st[0].x - st[1].x).max() <= 1e-15 * np.abs(st[0].x).max()
    assert np.abs(st[0].q - st[1].q).max() <= 1e-14
    assert np.abs(st[0].v - st[1].v).max() <= 1e-10 * np.abs(st[0].v).max()


@pytest.mark.parametrize("threads", [1, 2])
def test_update_leaves_the_constant_loads_and_the_largest_speed_for_the_next_step(threads):
    """The update resets the force array to the constant loads and the moments to zero for the next
    step (no separate pass at the start of a step), and leaves the largest |v_{n+½}|² in
    acc[ACC_V2_MAX] for the contact hook's path bound; a run cut into calls of one step each
    follows the run in one call bit for bit."""
    m, xs, qs = _perturbed_helices()
    load = LineLoad(0, [0.0, 3.0, 0.0])
    runs = []
    for calls in (1, 60):
        # no history rows: the perturbed helices would trip the blow-up checks (strain energy, no work)
        integ = Integrator(m, [Gravity([0, 0, -9.81]), Loads([load]), Damping(1e3)], 1e-8,
                           history_every=10**9, threads=threads)
        s = State.at_rest(m)
        s.x[:] = xs
        s.q[:] = qs
        for _ in range(calls):
            assert integ.advance(s, 60 // calls)[:2] == (0, 60 // calls)
        assert np.array_equal(integ.f, integ.scene.f_ext) and not integ.mom.any()
        v2 = np.einsum("ij,ij->i", s.v, s.v).max()
        assert v2 > 0 and s.acc[ACC_V2_MAX] == pytest.approx(v2, rel=1e-14)
        runs.append(s)
    assert np.array_equal(runs[0].x, runs[1].x) and np.array_equal(runs[0].v, runs[1].v)
