"""Verification cases of docs/verification.md, cases 5–8 (fiber–fiber contact and friction), through the dynamics.

Every case runs the real solver (``simulate``) with the contact hook of
:mod:`fiberpipe.solver.terms.contact` on the scene of its config in ``configs/verify/``
(:mod:`fiberpipe.verification.case_config`: material, radius, element length, fibers, loads, damping,
gravity, friction, plates, walls, drives, contact law, end time) — the study's fiber (r = 0.25 mm,
E = 15 GPa, ν = 0.3, ρ = 1380 kg/m³, 0.3 mm elements) at 0.9 × the stable step — and returns
:class:`Row` (or a list). ``quick=True`` is a shorter variant of the same case for the default test
suite. ``sliding_parallel`` (not a docs/verification.md case: two element lengths, an initial velocity) has no config.

* ``contact_pair_*``: two fibers pressed together (parallel: a line load; crossed at Φ: a point
  load over the crossing), damped to rest; δ read from the settled centre lines, F = the applied
  load (equilibrium); reference: Johnson's line law / exact elliptical Hertz K(Φ)δ^{3/2}.
* ``three_beam_static``: the study's Fig. 11 / appendix Eqs. 6–7, β from the set-up.
* ``rearrangement``: the study's Figs. 8–10: beam 1 driven down onto beams 2 and 3 (μ = 0.2);
  u_y(u_z) against the quasi-static kinematic curve and a slow reference run.
* ``inclined_plate``: gravity tilted by θ on a flat plate, μ = 0.2: stick / a = g(sin θ − μ cos θ).
* ``sliding_parallel``: a fiber sliding along a parallel neighbour across many element joints,
  normal force constant.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..solver import (Clamp, Clamps, Damping, Drive, Drives, Gravity, LineLoad, Loads, Plates,
                      SimulationSettings, State, Walls, build_model, choose_time_step)
from ..solver._kernels_boundary import plane_static_penetration
from ..solver.contact_pairs import gauss_points
from ..solver.laws import make_law
from ..solver.neighbours import build_pairs
from .case_config import CaseSetup, case_setup, contact_hook
from .cases import E_PA, MATERIAL, NU, R_M, Row
from .energy_residual import recorded_simulate as simulate

E_STAR = E_PA / (2 * (1 - NU**2))


def _fiber_nodes(p0, p1, n_el):
    p0 = np.asarray(p0, float)
    p1 = np.asarray(p1, float)
    s = np.linspace(0.0, 1.0, n_el + 1)[:, None]
    return p0 + s * (p1 - p0)


def _model(polys):
    """polys: list of (p0, p1, n_el) straight fibers."""
    xs = [_fiber_nodes(*p) for p in polys]
    off = np.cumsum([0] + [len(x) for x in xs])
    return build_model(np.vstack(xs), off, R_M, MATERIAL)


def johnson_delta(p_n_per_m, r=R_M, e_star=E_STAR):
    """Approach δ [m] of two equal parallel cylinders under line load P (Johnson 1985, line contact)."""
    b = math.sqrt(4 * p_n_per_m * (r / 2) / (math.pi * e_star))
    return p_n_per_m / (math.pi * e_star) * (2 * math.log(4 * r / b) - 1)


def johnson_line_load(delta_m, r=R_M, e_star=E_STAR):
    """Line load P [N/m] at approach δ [m]: :func:`johnson_delta` inverted numerically (brentq), so the
    reference does not go through the contact law under test (its Lambert-W inverse is checked
    against this in tests/verification/test_contact_references.py)."""
    from scipy.optimize import brentq

    if not 0.0 < delta_m < 8 * r / math.e**2:
        raise ValueError(f"δ = {delta_m} m is outside the line-contact range (0, 8R/e²)")
    # δ(P) increases monotonically on P < 8πE*R/e² (dδ/dP ∝ ln(8πE*R/P) − 2)
    hi = 8 * math.pi * e_star * r / math.e**2
    return brentq(lambda p: johnson_delta(p, r, e_star) - delta_m, 1e-30 * hi, hi, xtol=1e-300, rtol=1e-14, maxiter=200)


# Exact elliptical Hertz K(Φ) [N/m^1.5] (F = K δ^{3/2}) of two of the study's fibers (E = 15 GPa,
# ν = 0.3, R = 0.25 mm) crossing at Φ: docs/verification.md (Johnson,
# Contact Mechanics, eq. 3.64: B/A = [E(e)/(1−e²) − K(e)]/[K(e) − E(e)], A = sin²(Φ/2)/R,
# B = cos²(Φ/2)/R; at 90° K = (4/3)E*√R). Written here as numbers, not computed by the law under
# test; tests/verification/test_contact_references.py recomputes them with scipy's elliptic integrals
# (rounding ≤ 0.04 %).
K_CROSSED_REF = {2.0: 2.288e9, 6.0: 9.275e8, 10.0: 6.205e8, 90.0: 1.738e8}


def _clamp_all(model, fiber):
    n = int(model.node_offsets[fiber + 1] - model.node_offsets[fiber])
    return [Clamp(fiber, k) for k in range(n)]


def _segments(model):
    seg = np.empty((model.n_elements, 2), np.int64)
    seg[:, 0] = model.el_n1
    seg[:, 1] = model.el_n1 + 1
    return seg


def pair_force(model, x, law, fa, fb, *, n_gauss=None):
    """Force vector (N) that fiber ``fa`` exerts on fiber ``fb`` at positions ``x``, from the normal
    contact kernel with ``n_gauss`` points per segment and the onset of the config schema (defaults:
    the schema's, as the runs' hooks have them)."""
    from ..config import ContactConfig
    from ..solver.contact_potential import contact_forces_pot
    from ..solver.contact_state import new_records

    cc = ContactConfig()
    n_gauss = int(cc.gauss_points) if n_gauss is None else n_gauss
    seg = _segments(model)
    E = len(seg)
    arc = np.zeros((E, 2))
    cap = 64 * E
    pairs = np.zeros((cap, 2), np.int64)
    keys = np.zeros(cap, np.int64)
    n = build_pairs(x, seg, model.el_radius.astype(float), model.el_fiber.astype(np.int64), arc, 1e-5, 0.0,
                    pairs, keys)
    pf = model.el_fiber[pairs[:n]]
    sel = ((pf[:, 0] == fa) & (pf[:, 1] == fb)) | ((pf[:, 0] == fb) & (pf[:, 1] == fa))
    pr = np.ascontiguousarray(pairs[:n][sel])
    m = len(pr)
    f = np.zeros_like(x)
    gxi, gw = gauss_points(n_gauss)
    radius = model.el_radius.astype(float)
    L0 = np.asarray(model.el_L0, dtype=float)
    arc = np.c_[np.zeros(E), L0]  # the kernel needs each segment's reference length only
    contact_forces_pot(x, seg, radius, arc, pr, m, law.law_id, law.params(), gxi, gw, float(cc.onset), f,
                       new_records(max(m, 1)), np.zeros(0), 0.0)
    nodes = model.node_fiber == fb
    return f[nodes].sum(axis=0)


# ---------------------------------------------------------------------------------------------
# Case 5: two fibers pressed together
# ---------------------------------------------------------------------------------------------

def _line_load_z(s: CaseSetup, fiber: int) -> float:
    """Downward line load (N/m) of the case's single ``scene.loads`` entry, a line force along −z on ``fiber``."""
    ld = s.load(0)
    if ld.line_force is None or ld.fiber != fiber or abs(ld.line_force[0]) + abs(ld.line_force[1]) > 0:
        raise ValueError(f"{s.path}: the case needs one line load along z on fiber {fiber}")
    return -float(ld.line_force[2])


def _check_spec_fiber(s: CaseSetup) -> None:
    """The contact references (K_CROSSED_REF) hold for the study's fiber only."""
    if not (math.isclose(s.E, E_PA, rel_tol=1e-9) and math.isclose(s.nu, NU, rel_tol=1e-9)
            and math.isclose(s.r, R_M, rel_tol=1e-9)):
        raise ValueError(f"{s.path}: the reference K(Φ) values are for E = 15 GPa, ν = 0.3, r = 0.25 mm; the config "
                         f"gives E = {s.E:g} Pa, ν = {s.nu:g}, r = {s.r:g} m")


def contact_pair_parallel(quick: bool = False) -> list[Row]:
    """Parallel fibers (15 mm), lower clamped, upper pressed by a line load p, damped to rest
    (configs/verify/contact-parallel.yaml; the full variant also runs p/10 and 10 p).

    F(δ) against Johnson's line contact (docs/verification.md), independent of the contact law the run uses:
    reference = Johnson's P at the simulated δ (:func:`johnson_line_load`), measured = the applied p
    (at rest the contact carries it). δ = 2r − centre-line distance, mean over the inner nodes."""
    s = case_setup("contact_parallel")
    (a0, a1), (b0, b1) = s.fibers()
    if not (np.allclose(a1 - a0, b1 - b0) and np.allclose((b0 - a0)[:2], 0.0) and b0[2] > a0[2]):
        raise ValueError(f"{s.path}: the case needs two equal parallel fibers, fiber 1 above fiber 0 along z")
    p0 = _line_load_z(s, 1)
    loads = [p0] if quick else [p0 / 10, p0, 10 * p0]
    law = s.law()
    rows = []
    for p in loads:
        m = s.model()
        eff = [s.clamps(), s.loads(p / p0), Damping(s.damping_alpha), contact_hook(m, law=law)]
        res = simulate(m, eff, s.settings())
        x = res.frames_positions[-1]
        d = 2 * s.r - (x[m.node_fiber == 1, 2] - x[m.node_fiber == 0, 2])
        delta = float(np.mean(d[1:-1]))
        ref = johnson_line_load(delta, s.r, s.E_star)
        rows.append(Row(f"contact parallel, p = {p:g} N/m: Johnson P(δ = {delta * 1e9:.2f} nm)", ref, p,
                        abs(p - ref) / ref, 0.02, "N/m",
                        f"Johnson δ(p) = {johnson_delta(p, s.r, s.E_star) * 1e9:.2f} nm; "
                        f"δ spread {np.ptp(d[1:-1]) / delta:.1e}"))
    return rows


def contact_pair_crossed(phi_deg: float, quick: bool = False) -> Row:
    """Crossed fibers at Φ (configs/verify/contact-crossed-<Φ>.yaml): lower clamped, upper pressed
    at the crossing by a point force F, damped to rest; F against K(Φ)δ^{3/2} with the exact Hertz
    K(Φ) of docs/verification.md (:data:`K_CROSSED_REF`, numbers, not the law under test), δ from the settled
    centre lines. The quick variant settles for half the config's end time."""
    if phi_deg not in K_CROSSED_REF:
        raise ValueError(f"no reference K for Φ = {phi_deg}°: the references give {sorted(K_CROSSED_REF)}")
    s = case_setup(f"contact_crossed_{phi_deg:g}")
    _check_spec_fiber(s)
    (a0, a1), (b0, b1) = s.fibers()
    ta, tb = (a1 - a0) / np.linalg.norm(a1 - a0), (b1 - b0) / np.linalg.norm(b1 - b0)
    phi_cfg = math.degrees(math.acos(min(1.0, abs(float(ta @ tb)))))
    if abs(phi_cfg - phi_deg) > 1e-6:
        raise ValueError(f"{s.path}: its fibers cross at {phi_cfg:.6g}°, not {phi_deg:g}°")
    ld = s.load(0)
    if ld.force is None or ld.fiber != 1 or not isinstance(ld.at, int):
        raise ValueError(f"{s.path}: the case needs one point load on a node of fiber 1 (the crossing)")
    force_n = -float(ld.force[2])
    m = s.model()
    law = s.law()
    K = K_CROSSED_REF[phi_deg]
    eff = [s.clamps(), s.loads(), Damping(s.damping_alpha), contact_hook(m, law=law)]
    T = s.end_time / 2 if quick else s.end_time
    res = simulate(m, eff, s.settings(end_time_s=T))
    x = res.frames_positions[-1]
    # δ at the crossing: distance from B's loaded node (over the crossing) to A's (clamped, straight) axis
    ia = np.nonzero(m.node_fiber == 0)[0]
    pa0, pa1 = x[ia[0]], x[ia[-1]]
    pb = x[int(m.node_offsets[1]) + ld.at]
    ua = (pa1 - pa0) / np.linalg.norm(pa1 - pa0)
    dist = float(np.linalg.norm(np.cross(pb - pa0, ua)))
    delta = 2 * s.r - dist
    ref = K * delta**1.5
    f_meas = pair_force(m, x, law, 0, 1)[2]
    return Row(f"contact crossed Φ = {phi_deg:g}°: K(Φ)δ^1.5, K = {K:.4g} N/m^1.5 (exact Hertz), δ = {delta * 1e9:.2f} nm",
               ref, force_n, abs(force_n - ref) / ref, 0.02, "N",
               f"Hertz δ(F) = {(force_n / K) ** (2 / 3) * 1e9:.2f} nm; kernel force at rest {f_meas:.6g} N")


# ---------------------------------------------------------------------------------------------
# Case 6: the study's static 3-beam case (Fig. 11, appendix Eqs. 6-7)
# ---------------------------------------------------------------------------------------------

def three_beam_effects(s: CaseSetup, model, q_over_config: float, alpha: float, law=None) -> list:
    """The effects of the 3-beam static scene (configs/verify/three-beam-static.yaml) on ``model``:
    gravity, the config's line load × ``q_over_config``, the fixed plate, the walls, the contact
    (``law``, default the config's) and, for ``alpha`` > 0, mass damping α [1/s]."""
    p = s.plates
    eff = [Gravity(s.gravity), s.loads(q_over_config),
           Plates(axis=p.axis, lower=p.lower, upper=p.upper, lower_position_m=p.lower_position,
                  upper_position_m=p.upper_position, **s.plane_penalty("plates")),
           Walls(s.walls, **s.plane_penalty("walls")),
           contact_hook(model, law=s.law() if law is None else law)]
    if alpha > 0:
        eff.append(Damping(alpha))
    return eff


# The undamped 3-beam runs last this many times the config's end time: one 0.3 ms half of a chaotic
# oscillation puts its mean NF 0.5–7 % off Eq. 6 depending on rounding; over 16 T the mean of the last
# half stays within 1.1 % of it (nine full and eight quick runs, loads perturbed by 1e-8)
UNDAMPED_SPAN = 16


def three_beam_static(quick: bool = False, alphas=None) -> list[Row]:
    """The study's static 3-beam case (Fig. 11, appendix Eqs. 6–7), β from the set-up geometry.

    Beam 1 (fiber 0) lies on beams 2 and 3 (fibers 1, 2; y = ∓r), which lie on a fixed plate (z = 0)
    between walls at y = ±2r; q on beam 1 and gravity on all, from t = 0. Every α runs from that
    same set-up, at rest, for the same time T.

    References, the study's analytical solution (hard contact, so β is the set-up's): β₀ = the angle
    from the vertical of the line from beam 2's to beam 1's prescribed initial centre line (30°);
    NF = (q + w)L/(2 cos β₀) (Eq. 6); on beam 2, RF = √((½(q+w)L tan β₀)² + (½(q+3w)L)²) (Eq. 7).

    Measured over the last quarter of the run: NF = |force of beam 1 on beam 2| from the contact
    kernel at the output frames; RF from the run's reaction history: the y = −2r wall's column of
    ``wall_force`` (beam 2's wall) and half the lower plate's ``plate_force`` (beams 2 and 3, equal by
    symmetry). Error = max over those samples of |X − ref|/ref: the static error of a run at rest,
    the swing of one that has not settled. The note gives the settled β − β₀.

    α = 0 (undamped: nothing brings the suddenly loaded beams to rest, they oscillate about the
    equilibrium) runs ``UNDAMPED_SPAN`` × T with a history row every step. Checked: the mean NF over
    the last half of the run (ten frames per config frame and T) against Eq. 6, 2 %; the energy
    gained, the largest (K_lf + ALLSE + Π − W)/max W over every step, 1 %. Informational: the
    largest |residual| against 1e-2 (energy the scheme loses into its fastest modes at the default
    step, docs/verification.md) and RF (the swing of the reactions).

    Scene, loads, α, T and frames from configs/verify/three-beam-static.yaml (15 mm beams, q = 66 N/m);
    ``alphas`` defaults to (the config's α, 0); quick: 6 mm beams, q only; full: q/4, q/2, q.
    """
    s = case_setup("three_beam_static")
    L = 6e-3 if quick else s.lengths()[0]
    q0 = _line_load_z(s, 0)
    qs = [q0] if quick else [q0 / 4, q0 / 2, q0]
    alphas = (s.damping_alpha, 0.0) if alphas is None else alphas
    T = s.end_time
    frames = s.output_frames
    law = s.law()
    g = s.gravity
    if abs(g[0]) + abs(g[1]) > 0 or s.plates.axis != "z" or set(s.walls) != {"y"}:
        raise ValueError(f"{s.path}: the case needs gravity along z, plates normal to z and walls normal to y")
    w_line = s.rho * s.A * -g[2]
    rows = []
    for alpha in alphas:
        err = {"NF": [], "RF": []}
        gained = []
        residuals = []
        for q in qs:
            m = s.model(L)
            b1, b2 = m.node_fiber == 0, m.node_fiber == 1
            x0 = m.nodes_m
            beta0 = math.atan2(x0[b1, 1].mean() - x0[b2, 1].mean(), x0[b1, 2].mean() - x0[b2, 2].mean())
            eff = three_beam_effects(s, m, q / q0, alpha, law)
            xs = []
            if alpha > 0:
                settings = s.settings(output_frames=frames)
            else:
                settings = s.settings(output_frames=10 * frames * UNDAMPED_SPAN, end_time_s=UNDAMPED_SPAN * T,
                                      history_every=1)
            res = simulate(m, eff, settings, on_frame=lambda k, t, x: xs.append(x.copy()))
            QW = (q + w_line) * L
            nf_ref = QW / (2 * math.cos(beta0))
            rf_ref = math.hypot(0.5 * QW * math.tan(beta0), 0.5 * (q + 3 * w_line) * L)
            nf_half = np.array([np.linalg.norm(pair_force(m, x, law, 0, 1)) for x in xs[len(xs) // 2:]])
            nf = nf_half[-(len(xs) // 4 + 1):]
            h = res.history
            sel = h["time"] >= 0.75 * h["time"][-1]
            wall = h["wall_force"][:, res.wall_names.index("y_lo")]  # beam 2's wall (y = −2r)
            rf = np.hypot(wall[sel], 0.5 * h["plate_force"][sel, 0])
            x = xs[-1]
            beta = math.atan2(x[b1, 1].mean() - x[b2, 1].mean(), x[b1, 2].mean() - x[b2, 2].mean())
            # undamped: the mean of the oscillation; damped: the largest deviation of the settled run
            e_nf = (float(np.max(np.abs(nf - nf_ref)) / nf_ref) if alpha > 0
                    else abs(float(nf_half.mean()) - nf_ref) / nf_ref)
            e_rf = float(np.max(np.abs(rf - rf_ref)) / rf_ref)
            err["NF"].append(e_nf)
            err["RF"].append(e_rf)
            resid = float(np.max(np.abs(h["energy/residual"])))
            residuals.append(resid)
            gained.append(float(np.max(h["energy/residual"])))
            ke = h["energy/kinetic"]
            nf_note = (f"β₀ = {math.degrees(beta0):.4f}° (set-up), {'final' if alpha == 0 else 'settled'} β − β₀ = "
                       f"{math.degrees(beta - beta0):.2e}°; "
                       f"NF over the last quarter ∈ [{nf.min():.6g}, {nf.max():.6g}] N")
            rf_note = (f"wall (y = −2r) {wall[-1]:.6g} N, plate/2 {0.5 * h['plate_force'][-1, 0]:.6g} N "
                       f"(last row); RF over the last quarter ∈ [{rf.min():.6g}, {rf.max():.6g}] N")
            if alpha == 0:
                nf_note += (f"; oscillates about Eq. 6 over {UNDAMPED_SPAN * T * 1e3:g} ms: mean NF over the last half / "
                            f"ref {nf_half.mean() / nf_ref:.4f}, NF/ref ∈ [{nf_half.min() / nf_ref:.2f}, "
                            f"{nf_half.max() / nf_ref:.2f}], kinetic energy {ke[len(ke) // 4]:.2e} → {ke[-1]:.2e} J "
                            f"over the last 3/4")
            data = {"beta0_deg": math.degrees(beta0), "settled_beta_minus_beta0_deg": math.degrees(beta - beta0),
                    "mean_nf_last_half_over_ref": float(nf_half.mean() / nf_ref),
                    "nf_over_ref": (float(nf.min() / nf_ref), float(nf.max() / nf_ref)),
                    "rf_over_ref": (float(rf.min() / rf_ref), float(rf.max() / rf_ref)),
                    "max_energy_residual": resid}
            vals = (nf_ref, float(nf[-1]), rf_ref, float(rf[-1]), nf_note, rf_note, data)
        nf_ref, NF, rf_ref, rf_last, nf_note, rf_note, data = vals
        rng = f"q ∈ {{{', '.join(f'{q:g}' for q in qs)}}} N/m"
        label = f"α = {alpha:g}" + (" (undamped)" if alpha == 0 else "")
        over = "the mean over the last half of the run" if alpha == 0 else "the last quarter of the run"
        rows.append(Row(f"3-beam static {label}: NF (Eq. 6, β₀ from the set-up), q = {qs[-1]:g} N/m "
                        f"(max error over {rng} and {over})", nf_ref, NF,
                        max(err["NF"]), 0.01 if alpha > 0 else 0.02, "N", nf_note, data=data))
        if alpha == 0:
            # the sudden impact of the touching beams gains at most 0.68 % of W at the default step (q/2),
            # at the first impact; the oscillation after it gains nothing
            rows.append(Row(f"3-beam static {label}: energy gained, max over every step of "
                            f"(state energy − loads' work)/max W, over {rng}", 0.0, max(gained),
                            max(max(gained), 0.0), 0.01, "",
                            "state functions: the leapfrog kinetic term, ALLSE and the stored contact energy, "
                            "less the loads' work; the sudden impact's step error",
                            data={"max_energy_gained": max(gained)}))
            # energy goes missing, not created: the leapfrog's kinetic term undercounts the modes near the
            # step's limit, into which the nonlinear contact hands energy; 1e-2 holds from dt_safety 0.45
            # over T (make three-beam-energy), not at the default step
            rows.append(Row(f"3-beam static α = 0 (undamped, informational): energy residual, max |state energy − "
                            f"loads' work|/max W, over {rng}", 0.0, max(residuals), max(residuals), 0.01, "",
                            "energy lost into the fastest modes at the default step, not created (row above); "
                            "≤ 1e-2 over the first 0.6 ms from dt_safety 0.45 on (docs/verification.md)",
                            informational=True, data={"max_abs_residual": max(residuals)}))
        rf_label = "α = 0 (undamped, informational)" if alpha == 0 else label
        rows.append(Row(f"3-beam static {rf_label}: RF (Eq. 7, from the wall and plate reaction history), "
                        f"q = {qs[-1]:g} N/m (max error over {rng} and the last quarter)", rf_ref, rf_last,
                        max(err["RF"]), 0.01, "N", rf_note, informational=alpha == 0, data=data))
    return rows


# ---------------------------------------------------------------------------------------------
# Case 7: the study's rearrangement case (Figs. 8-10)
# ---------------------------------------------------------------------------------------------

def kinematic_uy(uz, r=R_M):
    """Quasi-static u_y(u_z) of beams 2/3 while they stay in contact with beam 1 (rigid sections)."""
    h = math.sqrt(3.0) * r - np.asarray(uz)
    return np.sqrt(np.maximum(4 * r * r - h * h, 0.0)) - r


def rearrangement_run(velocity_m_s=None, alpha=None, *, length_m=None, setup: CaseSetup | None = None):
    """Beam 1 driven down onto beams 2/3 lying on a fixed plate (configs/verify/study-rearrangement.yaml:
    material, geometry, gravity, plate, drive, μ, α, law, frames); ``velocity_m_s`` (default: the
    drive's), ``alpha`` (default: the config's) and ``length_m`` (default: the config's beams) vary it.
    Returns (u_z (K,), u_y (K,) mean of beams 2 and 3 (outward), wall time s, result)."""
    s = setup or case_setup("rearrangement")
    (d,) = s.drives
    v = float(d.velocity) if velocity_m_s is None else velocity_m_s
    alpha = s.damping_alpha if alpha is None else alpha
    m = s.model(length_m)
    p = s.plates
    eff = [Gravity(s.gravity), Plates(axis=p.axis, lower=p.lower, upper=p.upper, lower_position_m=p.lower_position,
                                      upper_position_m=p.upper_position, mu=s.mu, **s.plane_penalty("plates")),
           Drives([Drive(d.fiber, [float(c) for c in d.displacement], v)]),
           contact_hook(m, law=s.law(), friction=True, mu=s.mu)]
    if alpha > 0:
        eff.append(Damping(alpha))
    t0 = time.perf_counter()
    res = simulate(m, eff, s.settings())
    wall = time.perf_counter() - t0
    X = res.frames_positions
    x0 = X[0]
    uz = -(X[:, m.node_fiber == 0, 2].mean(axis=1) - x0[m.node_fiber == 0, 2].mean())
    uy2 = -(X[:, m.node_fiber == 1, 1].mean(axis=1) - x0[m.node_fiber == 1, 1].mean())
    uy3 = X[:, m.node_fiber == 2, 1].mean(axis=1) - x0[m.node_fiber == 2, 1].mean()
    return uz, 0.5 * (uy2 + uy3), wall, res


def _curve_error(uz, uy, uz_ref, uy_ref):
    """max |u_y − u_y,ref| over the common u_z range / max |u_y,ref|."""
    o = np.argsort(uz_ref)
    ref = np.interp(uz, np.asarray(uz_ref)[o], np.asarray(uy_ref)[o])
    sel = uz <= np.max(uz_ref) + 1e-12
    return float(np.max(np.abs(uy[sel] - ref[sel])) / np.max(np.abs(uy_ref)))


def _num(x: float) -> str:
    """1e5 for powers of ten, else %g (row labels)."""
    e = round(math.log10(x)) if x > 0 else 0
    return f"1e{e}" if x > 0 and math.isclose(x, 10.0**e, rel_tol=1e-9) and abs(e) >= 3 else f"{x:g}"


def contact_gaps(model, X, a: int = 0, b: int = 1) -> np.ndarray:
    """(K, n) gap between the surfaces of parallel fibers ``a`` and ``b`` (same node count) at each
    node, from the centre lines in the (y, z) plane: |Δ(y, z)| − (r_a + r_b); > 0: not in contact."""
    ia, ib = model.node_fiber == a, model.node_fiber == b
    d = np.linalg.norm(X[:, ia, 1:] - X[:, ib, 1:], axis=2)
    return d - (model.radius_node[ia] + model.radius_node[ib])[None, :]


def rearrangement(quick: bool = False) -> list[Row]:
    """u_y(u_z) at 1e3 mm/min, α = 1e5 vs the quasi-static reference (< 5 %); α = 0 must depart.

    quick: 3 mm beams, reference = the quasi-static kinematic curve (beams 2/3 stay in contact with
    beam 1 and do not move unless pushed). Full: 15 mm beams (the study's), reference = a 10×
    slower run (100 mm/min, α = 1e5), plus the kinematic curve; wall times of each run reported.

    "The undamped fast run departs from it, as the study found" (docs/verification.md; the study's Fig. 8(c): its
    undamped beams lost contact with beam 1): the α = 0 row's criterion is a curve error outside
    the 5 % agreement band. It is informational: measured 2.1 % (quick and full), i.e. not
    reproduced (docs/contact.md: friction makes no moment, so our beams slide but cannot roll).
    Its note gives how far beams 2/3 separate from beam 1: they do lose contact (in 55 of the 61
    frames, by up to 2.5 % of r), but run only slightly ahead of the quasi-static curve.
    """
    s = case_setup("rearrangement")
    (d,) = s.drives
    v_fast = float(d.velocity)  # the config's 1e3 mm/min
    a_cfg = s.damping_alpha  # the config's 1e5 1/s
    L = None if quick else 15e-3  # quick: the config's 3 mm beams; full: the study's 15 mm
    damped = f"α = {_num(a_cfg)}, {_num(v_fast * 6e4)} mm/min"
    undamped = f"α = 0, {_num(v_fast * 6e4)} mm/min"
    slow = f"α = {_num(a_cfg)}, {_num(v_fast * 6e3)} mm/min (reference)"
    runs = {damped: (v_fast, a_cfg), undamped: (v_fast, 0.0)}
    if not quick:
        runs[slow] = (v_fast / 10, a_cfg)
    out = {k: rearrangement_run(v, a, length_m=L, setup=s) for k, (v, a) in runs.items()}
    model = s.model(L)
    rows = []
    if quick:
        ref_name = "kinematic"
        ref = lambda uz: kinematic_uy(uz, s.r)  # noqa: E731
    else:
        ref_name = "slow run"
        uz_r, uy_r = out[slow][:2]
        ref = lambda uz: np.interp(uz, uz_r[np.argsort(uz_r)], uy_r[np.argsort(uz_r)])  # noqa: E731
    errs = {}
    for k in (damped, undamped):
        uz, uy, wall, res = out[k]
        yref = ref(uz)
        err = float(np.max(np.abs(uy - yref)) / np.max(np.abs(yref)))
        kin = float(np.max(np.abs(uy - kinematic_uy(uz, s.r))) / np.max(np.abs(kinematic_uy(uz, s.r))))
        errs[k] = err
        gap = np.maximum(contact_gaps(model, res.frames_positions, 0, 1),
                         contact_gaps(model, res.frames_positions, 0, 2))
        lost = np.any(gap.min(axis=1, keepdims=True) > 1e-12, axis=1)  # beam 2 or 3 wholly off beam 1
        note = (f"max curve error {100 * err:.3f} %, vs kinematic {100 * kin:.3f} %, u_y(end) {uy[-1] * 1e3:.4f} mm, "
                f"surface gap beam 1–beams 2/3 up to {gap.max() * 1e6:.3g} µm ({100 * gap.max() / s.r:.3g} % r), "
                f"contact lost in {np.count_nonzero(lost)}/{len(lost)} frames; wall {wall:.1f} s, {res.steps} steps")
        if k == undamped:
            note += (f"; the damped run's error {100 * errs[damped]:.3f} %. Not reproduced: departs "
                     f"less than the 5 % band (no rolling: docs/contact.md)" if err <= 0.05 else "")
            rows.append(Row(f"rearrangement {k}: departs from the {ref_name} (the study's Fig. 8(c)): "
                            f"max |u_y − ref| / max u_y,ref beyond the 5 % band (informational)",
                            float(yref[-1]), float(uy[-1]), err, 0.05, "m", note, must_exceed=True,
                            informational=True,
                            data={"curve_error": err, "damped_curve_error": errs[damped],
                                  "max_gap_m": float(gap.max()), "frames_contact_lost": int(np.count_nonzero(lost)),
                                  "frames": len(lost)}))
        else:
            rows.append(Row(f"rearrangement {k}: max |u_y − ref| / max u_y,ref vs {ref_name}",
                            float(yref[-1]), float(uy[-1]), err, 0.05, "m", note))
    if not quick:
        uz, uy, wall, res = out[slow]
        kin = float(np.max(np.abs(uy - kinematic_uy(uz, s.r))) / np.max(np.abs(kinematic_uy(uz, s.r))))
        rows.append(Row(f"rearrangement reference ({slow.replace(' (reference)', '')}) vs kinematic curve", float(kinematic_uy(uz[-1], s.r)),
                        float(uy[-1]), kin, 0.05, "m", f"wall {wall:.1f} s, {res.steps} steps"))
    return rows


# ---------------------------------------------------------------------------------------------
# Case 8: friction on an inclined plate
# ---------------------------------------------------------------------------------------------

def inclined_plate(case: str = "friction_inclined_slide", quick: bool = False) -> Row:
    """A 3 mm fiber on a flat plate under gravity tilted by θ (equivalent to an inclined plate), μ
    (configs/verify/friction-inclined-stick.yaml, θ = 5°, and -slide.yaml, θ = 20°; θ and g from the
    config's gravity, μ from its friction). tan θ < μ: sticks (displacement vs ½ g sin θ T², must be
    < 1 % of it); else a = g(sin θ − μ cos θ) from a quadratic fit of the mean position (< 1 %).
    T = the config's end time (a third of it in the quick variant)."""
    s = case_setup(case)
    gvec = s.gravity
    if gvec[1] != 0 or not gvec[2] < 0 or s.plates.axis != "z":
        raise ValueError(f"{s.path}: the case needs gravity in the x-z plane, downwards, and a plate normal to z")
    g = math.hypot(gvec[0], gvec[2])
    th = math.atan2(gvec[0], -gvec[2])
    theta_deg = math.degrees(th)
    mu = s.mu
    probe = s.model()
    p = s.plates
    plates = dict(axis=p.axis, lower=p.lower, upper=p.upper, lower_position_m=p.lower_position,
                  upper_position_m=p.upper_position, **s.plane_penalty("plates"))
    plate = Plates(**plates)
    dt, _ = choose_time_step(probe, [Gravity(gvec), plate], s.settings())
    # start at the static penetration of the plate penalty (k = c m (2/Δt)², same δ on every node)
    d_s = plane_static_penetration(g * math.cos(th) / (plate.penalty_factor * (2.0 / dt) ** 2),
                                   plate.onset_fraction * float(probe.radius_node[0]))
    m = s.model(nodes_m=probe.nodes_m - np.array([0.0, 0.0, d_s]))
    eff = [Gravity(gvec), Plates(**plates, mu=mu)]
    T = s.end_time / 3 if quick else s.end_time
    res = simulate(m, eff, s.settings(end_time_s=T))
    t = res.frames_time
    xm = res.frames_positions[:, :, 0].mean(axis=1) - m.nodes_m[:, 0].mean()
    if math.tan(th) < mu:
        scale = 0.5 * g * math.sin(th) * T**2
        return Row(f"friction inclined θ = {theta_deg:.4g}° (tan θ < μ = {mu:g}): sticks, |u|/(½ g sin θ T²)",
                   0.0, float(abs(xm[-1])), float(abs(xm[-1]) / scale), 0.01, "m")
    sel = t > 0.1 * T
    c = np.polyfit(t[sel], xm[sel], 2)
    a = 2 * c[0]
    ref = g * (math.sin(th) - mu * math.cos(th))
    return Row(f"friction inclined θ = {theta_deg:.4g}° (tan θ > μ = {mu:g}): a = g(sin θ − μ cos θ)", ref, a,
               abs(a - ref) / ref, 0.01, "m/s²")


# ---------------------------------------------------------------------------------------------
# Sliding along a parallel neighbour across element joints
# ---------------------------------------------------------------------------------------------

def sliding_parallel(quick: bool = False, p: float = 66.0, speed_m_s: float = 5.0) -> Row:
    """A 3 mm fiber (0.25 mm elements) pressed by p onto a clamped 6 mm one (0.3 mm elements),
    sliding along it at ``speed_m_s`` (no damping, no friction) across many joints of both;
    the total normal force (kernel, each frame) stays within 1 % of p·L."""
    LA, LB = 6e-3, 3e-3
    d0 = johnson_delta(p)
    zb = 2 * R_M - d0
    m = _model([((0, 0, 0), (LA, 0, 0), 20), ((1e-3, 0, zb), (1e-3 + LB, 0, zb), 12)])
    law = make_law("hertz_oriented", E_pa=E_PA, nu=NU)
    eff = [Clamps(_clamp_all(m, 0)), Loads([LineLoad(1, [0, 0, -p])]), contact_hook(m, law=law)]
    dist = 0.6e-3 if quick else 1.8e-3
    T = dist / speed_m_s
    st = State.at_rest(m)
    st.v[m.node_fiber == 1, 0] = speed_m_s
    forces = []
    res = simulate(m, eff, SimulationSettings(end_time_s=T, output_frames=61), state=st,
                   on_frame=lambda k, t, x: forces.append(pair_force(m, x, law, 0, 1)[2]))
    F = np.array(forces)
    ref = p * LB
    err = float(np.max(np.abs(F - ref)) / ref)
    moved = float(res.frames_positions[-1, m.node_fiber == 1, 0].mean() - m.nodes_m[m.node_fiber == 1, 0].mean())
    return Row(f"sliding along a parallel fiber ({moved * 1e3:.2f} mm, {moved / 0.25e-3:.1f} × B's elements): "
               f"normal force", ref, float(F[np.argmax(np.abs(F - ref))]), err, 0.01, "N")


def _crossed(phi):
    return lambda quick=False: contact_pair_crossed(phi, quick)


CONTACT_CASES = {
    "contact_parallel": contact_pair_parallel,
    "contact_crossed_2": _crossed(2.0),
    "contact_crossed_6": _crossed(6.0),
    "contact_crossed_10": _crossed(10.0),
    "contact_crossed_90": _crossed(90.0),
    "three_beam_static": three_beam_static,
    "rearrangement": rearrangement,
    "friction_inclined_stick": lambda quick=False: inclined_plate("friction_inclined_stick", quick),
    "friction_inclined_slide": lambda quick=False: inclined_plate("friction_inclined_slide", quick),
    "sliding_parallel": sliding_parallel,
}
