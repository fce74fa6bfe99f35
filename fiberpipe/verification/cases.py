"""Verification cases of docs/verification.md (beams), each returning one table row.

Every case runs the real solver (``simulate``) on the scene of its config in ``configs/verify/``
(:mod:`fiberpipe.verification.case_config`: material, radius, element length, the fiber, clamps,
loads, damping, plates, end time), the study's fiber: r = 0.25 mm, E = 15 GPa, ν = 0.3,
ρ = 1380 kg/m³, L = 15 mm, 0.3 mm elements (50), at the stable time step × 0.9; the references
are computed from the same config values. ``quick=True`` runs a shorter variant of the same case
(fewer periods / faster loading) for the default test suite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..solver import Clamp, Clamps, Damping, Material, Plates, State, build_model
from .case_config import CaseSetup, case_setup
from .energy_residual import recorded_simulate as simulate

# The study's fiber (docs/verification.md), as its configs give it; the contact references (K_CROSSED_REF) hold for it.
E_PA = 15e9
NU = 0.3
RHO = 1380.0
R_M = 0.25e-3
L_M = 15e-3
N_EL = 50
MATERIAL = Material(E_PA, RHO, NU)
I_M4 = math.pi * R_M**4 / 4
A_M2 = math.pi * R_M**2
EI = E_PA * I_M4


@dataclass
class Row:
    """One verification result.

    ``passed``: ``error < tolerance``, or ``error > tolerance`` for a row whose criterion is to
    depart (``must_exceed``, e.g. the undamped rearrangement run must leave the reference's band).
    ``informational``: a documented comparison the code is known not to reproduce (its note says
    what was measured); it is printed as such and does not set the exit status, and its test
    asserts the measured behaviour instead.
    """

    case: str
    reference: float
    measured: float
    error: float        # relative, |measured − reference| / |reference| (or absolute drift)
    tolerance: float
    unit: str = ""
    note: str = ""
    must_exceed: bool = False
    informational: bool = False
    data: dict = field(default_factory=dict)  # measured figures behind the note, for tests

    @property
    def passed(self) -> bool:
        if not np.isfinite(self.error):
            return False
        return bool(self.error > self.tolerance if self.must_exceed else self.error < self.tolerance)

    @property
    def status(self) -> str:
        if self.informational:
            return "reproduced (info)" if self.passed else "NOT REPRODUCED (info)"
        return "PASS" if self.passed else "FAIL"


def straight_fiber(n_el: int = N_EL, length_m: float = L_M, axis: int = 0):
    x = np.zeros((n_el + 1, 3))
    x[:, axis] = np.linspace(0.0, length_m, n_el + 1)
    return build_model(x, [0, n_el + 1], R_M, MATERIAL)


def _tip_force_z(s: CaseSetup) -> float:
    """Downward tip force P (N) of the case's single point load ``at: end`` along −z."""
    ld = s.load(0)
    if ld.force is None or ld.at != "end" or abs(ld.force[0]) + abs(ld.force[1]) > 0:
        raise ValueError(f"{s.path}: the case needs one point load at the fiber's end along z")
    return -float(ld.force[2])


def _omega1(s: CaseSetup) -> float:
    """Clamped-free first natural frequency 1.8751² √(EI/(ρ A L⁴)), rad/s."""
    return 1.8751**2 * math.sqrt(s.EI / (s.rho * s.A * s.lengths()[0] ** 4))


def _cantilever_run(case: str):
    """The clamped fiber of ``case`` under its tip load, damped to rest: (setup, L [m], P [N], result)."""
    s = case_setup(case)
    res = simulate(s.model(), [s.clamps(), s.loads(), Damping(s.damping_alpha)], s.settings())
    return s, s.lengths()[0], _tip_force_z(s), res


def cantilever_small(quick: bool = False) -> Row:
    """Tip deflection of a clamped fiber under a small tip load vs P L³/(3 E I) (< 1 %).

    ``quick`` is ignored: the case already takes a few seconds, so its slow variant repeats it."""
    s, L, P, res = _cantilever_run("cantilever_small")
    ref = P * L**3 / (3 * s.EI)
    meas = -res.frames_positions[-1, -1, 2]
    return Row("cantilever small tip load: deflection", ref, meas, abs(meas - ref) / ref, 0.01, "m")


def elastica_tip(lam: float) -> tuple[float, float]:
    """Tip displacement (u_axial/L, w/L) of the inextensible elastica, clamped at s = 0, under a
    tip force of fixed direction perpendicular to the undeformed axis, λ = P L²/(E I).
    Solves θ'' = −λ cos θ, θ(0) = 0, θ'(1) = 0 (scipy solve_bvp); x' = cos θ, w' = sin θ."""
    from scipy.integrate import solve_bvp, cumulative_trapezoid

    s = np.linspace(0, 1, 401)

    def f(s, y):
        return np.vstack([y[1], -lam * np.cos(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1]])

    y0 = np.vstack([lam * (s - s**2 / 2), lam * (1 - s)])
    sol = solve_bvp(f, bc, s, y0, tol=1e-10, max_nodes=100000)
    th = sol.sol(s)[0]
    x = cumulative_trapezoid(np.cos(th), s, initial=0)[-1]
    w = cumulative_trapezoid(np.sin(th), s, initial=0)[-1]
    return 1.0 - x, w


def cantilever_large(quick: bool = False) -> Row:
    """Large tip deflection vs the elastica (λ = P L²/EI = 2 in the config), vertical tip deflection (< 2 %).

    ``quick`` is ignored: the case already takes a few seconds, so its slow variant repeats it."""
    s, L, P, res = _cantilever_run("cantilever_large")
    lam = P * L**2 / s.EI
    _, w_ref = elastica_tip(lam)
    meas = -res.frames_positions[-1, -1, 2] / L
    return Row(f"cantilever large deflection (PL²/EI = {lam:.4g}): w/L vs elastica", w_ref, meas,
               abs(meas - w_ref) / w_ref, 0.02)


def _mode1_state(model, amplitude_m: float, length_m: float = L_M) -> State:
    """State with the clamped-free first Euler–Bernoulli mode shape (transverse z) imposed, at rest
    (fiber along x from x = 0)."""
    L = length_m
    b = 1.8751040687 / L
    sig = (math.cosh(b * L) + math.cos(b * L)) / (math.sinh(b * L) + math.sin(b * L))
    xs = model.nodes_m[:, 0] - model.nodes_m[0, 0]
    w = np.cosh(b * xs) - np.cos(b * xs) - sig * (np.sinh(b * xs) - np.sin(b * xs))
    dw = b * (np.sinh(b * xs) + np.sin(b * xs) - sig * (np.cosh(b * xs) - np.cos(b * xs)))
    scale = amplitude_m / w[-1]
    st = State.at_rest(model)
    st.x[:, 2] += scale * w
    phi = -np.arctan(scale * dw)  # rotation about y taking e_x to the tangent (1, 0, w')
    qr = np.column_stack([np.cos(phi / 2), np.zeros_like(phi), np.sin(phi / 2), np.zeros_like(phi)])
    st.q[:] = _qmul(qr, st.q)
    return st


def _qmul(a, b):
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.column_stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _period_from_zero_crossings(t, y):
    y = y - np.mean(y)
    s = np.sign(y)
    idx = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    tc = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])
    if tc.size < 2:
        return float("nan")
    return float((tc[-1] - tc[0]) / (tc.size - 1))


def _along_x(s: CaseSetup) -> float:
    """Length of the case's single fiber, which must run along +x (mode shapes, axial velocity)."""
    (a, b), = s.fibers()
    d = b - a
    if abs(d[1]) + abs(d[2]) > 1e-12 * abs(d[0]) or d[0] <= 0:
        raise ValueError(f"{s.path}: the case needs one fiber along +x")
    return float(d[0])


def cantilever_frequency(quick: bool = False) -> Row:
    """First natural frequency of the cantilever vs 1.8751² √(EI/ρAL⁴) (< 1 %), free vibration
    from the first mode shape, period by upward zero crossings of the tip deflection."""
    s = case_setup("cantilever_frequency")
    m = s.model()
    L = _along_x(s)
    om1 = _omega1(s)
    periods = 3 if quick else 10
    T1 = 2 * math.pi / om1
    st = _mode1_state(m, 1e-5, L)
    frames = 60 * periods + 1
    res = simulate(m, [s.clamps()], s.settings(end_time_s=(periods + 0.3) * T1, output_frames=frames), state=st)
    T = _period_from_zero_crossings(res.frames_time, res.frames_positions[:, -1, 2])
    f_ref = om1 / (2 * math.pi)
    f = 1.0 / T
    return Row("cantilever first natural frequency", f_ref, f, abs(f - f_ref) / f_ref, 0.01, "Hz")


def axial_wave_speed(quick: bool = False) -> Row:
    """Bar wave speed √(E/ρ) (< 2 %) from the fundamental axial mode of a free–free fiber,
    c = 2 L f, started with the velocity field v = v₀ cos(π x/L)."""
    s = case_setup("axial_wave_speed")
    m = s.model()
    L = _along_x(s)
    c = math.sqrt(s.E / s.rho)
    T = 2 * L / c
    periods = 5 if quick else 20
    st = State.at_rest(m)
    x0 = m.nodes_m[:, 0] - m.nodes_m[0, 0]
    st.v[:, 0] = 1e-3 * np.cos(math.pi * x0 / L)
    res = simulate(m, [], s.settings(end_time_s=(periods + 0.3) * T, output_frames=40 * periods + 1), state=st)
    u = res.frames_positions[:, -1, 0] - m.nodes_m[-1, 0]
    Tm = _period_from_zero_crossings(res.frames_time, u)
    cm = 2 * L / Tm
    return Row("axial wave speed", c, cm, abs(cm - c) / c, 0.02, "m/s")


def energy_drift(quick: bool = False) -> Row:
    """Undamped free vibration: max |ETOTAL − ETOTAL₀| / ETOTAL₀ over 1e5 steps (< 0.5 %).

    The cantilever is first deflected statically (damped) by the config's tip load (P L²/EI = 0.5:
    tip deflection ≈ 16 % of L, geometrically nonlinear), then the load and damping are removed and
    it vibrates freely; ETOTAL is then KE + SE (clamp reactions do no work)."""
    from ..solver import choose_time_step

    s = case_setup("energy_drift")
    m = s.model()
    _tip_force_z(s)
    pre = simulate(m, [s.clamps(), s.loads(), Damping(s.damping_alpha)], s.settings(output_frames=2))
    st = pre.final_state.copy()
    st.v[:] = 0.0
    st.w[:] = 0.0
    st.t, st.step, st.acc[:] = 0.0, 0, 0.0
    n_steps = 20_000 if quick else 100_000
    dt, _ = choose_time_step(m, [], s.settings())
    res = simulate(m, [s.clamps()],
                   s.settings(end_time_s=n_steps * dt * (1 - 1e-12), output_frames=2, history_every=50),
                   state=st)
    h = res.history
    tot = h["energy/total"]
    e0 = h["energy/strain"][0] + h["energy/kinetic"][0]
    drift = float(np.max(np.abs(tot - tot[0])) / e0)
    span = "; the 1e5-step case in the slow variant only" if quick else ""
    return Row(f"energy drift, undamped free vibration ({res.steps} steps{span})", 0.0, drift, drift, 0.005)


def euler_buckling(quick: bool = False) -> Row:
    """Critical load of a pinned–pinned fiber compressed between plates vs π² E I / L² (< 2 %).

    The fiber stands along z (the config's) with a stress-free half-sine imperfection e₀ = L/2000
    along x; both end nodes are pinned laterally (x, y fixed, rotations free), the lower plate is
    fixed and the upper one closes slowly (damped; the config's travel and speed, twice as fast in
    the quick variant, smoothstep ramp). Pcr from a Southwell fit δ/P = δ/Pcr + e₀/Pcr of the
    mid-span additional deflection δ against the upper plate force P."""
    s = case_setup("euler_buckling")
    (a, b), = s.fibers()
    L = float(np.linalg.norm(b - a))
    if abs(b[0] - a[0]) + abs(b[1] - a[1]) > 1e-12 * L or b[2] <= a[2] or s.plates.axis != "z":
        raise ValueError(f"{s.path}: the case needs one fiber along +z between plates normal to z")
    n = s.n_elements(L)
    t = np.linspace(0.0, 1.0, n + 1)
    e0 = L / 2000
    x = a + t[:, None] * (b - a)
    x[:, 0] += e0 * np.sin(math.pi * t)
    m = s.model(nodes_m=x)
    Pcr = math.pi**2 * s.EI / L**2
    U = float(s.loading.displacement)
    v = float(s.loading.velocity) * (2.0 if quick else 1.0)
    p = s.plates
    eff = [Clamps([Clamp(0, "start", "xy"), Clamp(0, "end", "xy")]),
           Plates(axis=p.axis, lower=p.lower, upper=p.upper, displacement_m=U, velocity_m_s=v, ramp="smoothstep",
                  lower_position_m=p.lower_position, upper_position_m=p.upper_position, **s.plane_penalty("plates")),
           Damping(s.damping_alpha)]
    res = simulate(m, eff, s.settings())
    tf = res.frames_time
    a_mid = res.frames_positions[:, n // 2, 0]
    h = res.history
    P = np.interp(tf, h["time"], h["plate_force"][:, 1])
    d = a_mid - a[0] - e0
    sel = (d > 2 * e0) & (d < 20 * e0) & (P > 0)
    if np.count_nonzero(sel) < 5:
        return Row("Euler buckling load (Southwell)", Pcr, float("nan"), float("nan"), 0.02, "N",
                   "not enough points")
    slope, _ = np.polyfit(d[sel], d[sel] / P[sel], 1)
    meas = 1.0 / slope
    return Row("Euler buckling load pinned-pinned (Southwell)", Pcr, meas, abs(meas - Pcr) / Pcr, 0.02, "N",
               f"plateau {P[-1]:.4g} N")


CASES = {
    "cantilever_small": cantilever_small,
    "cantilever_large": cantilever_large,
    "cantilever_frequency": cantilever_frequency,
    "euler_buckling": euler_buckling,
    "axial_wave_speed": axial_wave_speed,
    "energy_drift": energy_drift,
}


def run_all(quick: bool = False, only: list[str] | None = None) -> list[Row]:
    return [fn(quick=quick) for name, fn in CASES.items() if not only or name in only]
