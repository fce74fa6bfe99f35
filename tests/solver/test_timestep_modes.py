"""The stable step of the assembled, constrained beam system (``solver.stable_step: modes``)."""

import numpy as np
import pytest

from fiberpipe.errors import FiberpipeError
from fiberpipe.solver import Material, build_model
from fiberpipe.solver.terms import AxialLock, Damping
from fiberpipe.solver.integrator import SimulationSettings, choose_time_step
from fiberpipe.solver.layout import FIX_Z
from fiberpipe.solver.timestep import modal_time_step, stable_time_step

E, NU, RHO, R = 15e9, 0.3, 1380.0, 0.25e-3


def straight_fiber(n_el=50, length=15e-3):
    s = np.linspace(0.0, length, n_el + 1)
    return build_model(np.column_stack([0 * s, 0 * s, s]), np.array([0, n_el + 1]), R, Material(E, RHO, NU))


def chain_shear_bending_omega(model):
    """ω_max of one transverse plane of a straight fiber, assembled by hand: per element the
    one-point Timoshenko strains γ = (u₂ − u₁)/L − (θ₁ + θ₂)/2 and κ = (θ₂ − θ₁)/L with
    W = ½ L (k_s G A γ² + E I κ²), the model's lumped masses and rotary inertias."""
    G = E / (2 * (1 + NU))
    ks = 6 * (1 + NU) / (7 + 6 * NU)
    A, I = np.pi * R**2, np.pi * R**4 / 4
    N = model.n_nodes
    L = float(model.el_L0[0])
    K = np.zeros((2 * N, 2 * N))
    for e in range(N - 1):
        g = np.zeros(2 * N)
        g[[2 * e, 2 * e + 2]] = -1 / L, 1 / L
        g[[2 * e + 1, 2 * e + 3]] = -0.5
        k = np.zeros(2 * N)
        k[[2 * e + 1, 2 * e + 3]] = -1 / L, 1 / L
        K += L * (ks * G * A * np.outer(g, g) + E * I * np.outer(k, k))
    mi = np.empty(2 * N)
    mi[0::2] = 1 / np.sqrt(model.mass)
    mi[1::2] = 1 / np.sqrt(model.J[:, 0])
    return float(np.sqrt(np.linalg.eigvalsh(mi[:, None] * K * mi[None, :]).max()))


def test_unconstrained_fiber_is_governed_by_the_axial_mode():
    """Nothing fixed: the assembled step equals the axial element bound L/c within 0.1 % (a free
    chain's top axial mode, ω = (2c/L) cos(π/2N) up to end effects)."""
    m = straight_fiber()
    c = np.sqrt(E / RHO)
    r = modal_time_step(m, np.zeros(0, np.uint8))
    assert r.dt_stable_s == pytest.approx(float(m.el_L0[0]) / c, rel=1e-3)
    assert r.dt_stable_s >= stable_time_step(m).dt_stable_s * (1 - 1e-5)  # rounded down to 6 digits


def test_axial_lock_leaves_the_shear_bending_mode():
    """Every node's z fixed (the fiber along z): ω_max is the hand-assembled shear–bending chain's
    (1e-4), and the step is ≥ 1.3 × the element bound's axial L/c."""
    m = straight_fiber()
    r = modal_time_step(m, np.full(m.n_nodes, FIX_Z, np.uint8))
    assert r.omega_max_rad_s == pytest.approx(chain_shear_bending_omega(m), rel=1e-4)
    assert r.dt_stable_s > 1.3 * stable_time_step(m).dt_stable_s


def test_plane_penalty_share_and_damping_reduce_the_step():
    """dt = (2/ω)(√(1+ξ²) − ξ) √(1 − c) with ξ = βω/2 and c the plane penalty factor."""
    m = straight_fiber(20)
    mask = np.full(m.n_nodes, FIX_Z, np.uint8)
    r0 = modal_time_step(m, mask)
    beta = 1e-9
    r = modal_time_step(m, mask, beta_s=beta, penalty_factor=0.1)
    xi = 0.5 * beta * r0.omega_max_rad_s
    assert r.dt_stable_s == pytest.approx(2 / r0.omega_max_rad_s * (np.sqrt(1 + xi**2) - xi) * np.sqrt(0.9), rel=1e-5)
    assert r.dt_stable_s <= r.dt_beams_s * np.sqrt(0.9)


def test_settings_choose_the_modal_step_with_the_scene_fixity():
    """``stable_step: modes`` in choose_time_step: the axial lock and the plates' penalty factor
    come from the effects; ``element`` (default) keeps the element bound."""
    m = straight_fiber()
    eff = [Damping(1e5), AxialLock("z", "all")]
    dt_e, rep_e = choose_time_step(m, eff, SimulationSettings(dt_safety=1.0))
    dt_m, rep_m = choose_time_step(m, eff, SimulationSettings(dt_safety=1.0, stable_step="modes"))
    assert rep_e.governing_mode == "axial" and dt_e == pytest.approx(rep_e.per_mode_s["axial"])
    ref = modal_time_step(m, np.full(m.n_nodes, FIX_Z, np.uint8)).dt_stable_s
    assert dt_m == pytest.approx(ref, rel=1e-9)
    assert rep_m.dt_stable_s == dt_m and rep_m.governing_mode.startswith("assembled")


def test_unknown_stable_step_is_refused():
    """A misspelt ``stable_step`` is a one-line error naming the key."""
    with pytest.raises(FiberpipeError, match="stable_step"):
        SimulationSettings(stable_step="mode")


def test_banded_tangent_matches_the_matrix_free_lanczos_estimate():
    """Two curved fibers of different element lengths, some degrees of freedom fixed: the top
    eigenvalue from the banded tangent (18 probes, fiber by fiber) equals the matrix-free Lanczos
    estimate on the whole system (the path taken with extra forces, here zero) within 1e-5."""
    s = np.linspace(0.0, 1.0, 31)
    a = np.column_stack([1e-3 * np.sin(3 * s), 0.2e-3 * s**2, 9e-3 * s])
    t = np.linspace(0.0, 1.0, 21)
    b = np.column_stack([2e-3 + 0.5e-3 * t**2, 1e-3 * np.cos(2 * t), 8e-3 * t])
    m = build_model(np.vstack([a, b]), np.array([0, 31, 52]), R, Material(E, RHO, NU))
    mask = np.zeros(m.n_nodes, np.uint8)
    mask[[0, 31]] = FIX_Z
    banded = modal_time_step(m, mask)
    lanczos = modal_time_step(m, mask, extra_forces=lambda x: np.zeros_like(x), tol=1e-10)
    assert banded.iterations == 18 and lanczos.iterations > 18
    assert banded.omega_max_rad_s == pytest.approx(lanczos.omega_max_rad_s, rel=1e-5)
