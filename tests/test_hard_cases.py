"""Hard cases that must stay numerically stable (docs/reliability.md).

Each case asserts boundedness (no NaN, energy balance residual small, penetration bounded, no fiber
leaving the box) and the physically right outcome. Small scenes (3 mm fibers, 0.3 mm elements, the
study's polyester fiber r = 0.25 mm) through the real solver; a property-based test over random
scenes sits on top. Deterministic (hypothesis derandomized), no timing assertions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fiberpipe.errors import FiberpipeError, InputError, SimulationDiverged
from fiberpipe.solver import (Clamp, Clamps, Damping, Drive, Drives, Gravity, LineLoad, Loads, Material, Plates,
                              SimulationSettings, State, Walls, build_model, simulate, stable_time_step)
from fiberpipe.verification.case_config import contact_hook
from fiberpipe.solver.integrator import choose_time_step
from fiberpipe.solver.laws import make_law

R = 0.25e-3
MAT = Material(15e9, 1380.0, 0.3)
LAW = "hertz_oriented"


def fibers_model(polys):
    """polys: list of (p0, p1, n_el) straight fibers or (k,3) arrays of nodes."""
    xs = []
    for p in polys:
        if isinstance(p, tuple):
            a, b, n = p
            s = np.linspace(0.0, 1.0, n + 1)[:, None]
            xs.append(np.asarray(a, float) + s * (np.asarray(b, float) - np.asarray(a, float)))
        else:
            xs.append(np.asarray(p, float))
    off = np.cumsum([0] + [len(x) for x in xs])
    return build_model(np.vstack(xs), off, R, MAT)


def hook(m, friction=False, mu=0.2):
    return contact_hook(m, law=make_law(LAW, E_pa=15e9, nu=0.3), friction=friction, mu=mu)


def _seg_dist(p0, p1, q0, q1):
    """Closest distance between segments p0p1 and q0q1 (vectorised over leading axes)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.sum(d1 * d1, -1)
    e = np.sum(d2 * d2, -1)
    f = np.sum(d2 * r, -1)
    c = np.sum(d1 * r, -1)
    b = np.sum(d1 * d2, -1)
    den = a * e - b * b
    s = np.where(den > 1e-30 * a * e, np.clip((b * f - c * e) / np.where(den > 0, den, 1), 0, 1), 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    cp = p0 + s[..., None] * d1
    cq = q0 + t[..., None] * d2
    return np.linalg.norm(cp - cq, axis=-1)


def max_penetration(m, x):
    """Largest fiber–fiber penetration δ = 2r − centre-line distance (m) over element pairs of different fibers."""
    e1 = m.el_n1
    p0, p1 = x[e1], x[e1 + 1]
    fib = m.el_fiber
    i, j = np.triu_indices(len(e1), 1)
    sel = fib[i] != fib[j]
    i, j = i[sel], j[sel]
    if len(i) == 0:
        return 0.0
    d = _seg_dist(p0[i], p1[i], p0[j], p1[j])
    return float(np.max(2 * R - d))


def energy_residual(res, floor_j=1e-9, *, state=False):
    """max |ETOTAL − ETOTAL₀| over the run / the largest energy that moved (external work, KE + SE,
    contact work), at least ``floor_j`` (a scene at rest has nothing to normalise by). ``state``: the
    history's ``energy/residual`` instead (state functions: the stored contact energy in place of
    the booked contact work; the booked ETOTAL counts the release of initial overlaps twice, as
    prescribed work and as the contact forces' work)."""
    h = {k: np.asarray(v, float) for k, v in res.history.items()}
    if state:
        return float(np.max(np.abs(h["energy/residual"])))
    tot = h["energy/total"]
    scale = max(np.max(np.abs(h["energy/external"])), np.max(h["energy/kinetic"] + h["energy/strain"]),
                np.max(np.abs(h["energy/contact"])), floor_j)
    return float(np.max(np.abs(tot - tot[0])) / scale)


def assert_bounded(res, m, *, box=None, residual=0.05, pen=0.1, state=False):
    """No NaN; |energy residual| < ``residual``; penetration < ``pen`` radii; nodes inside ``box``."""
    X = res.frames_positions
    assert np.all(np.isfinite(X)), "NaN/inf in the positions"
    for k, v in res.history.items():
        assert np.all(np.isfinite(np.asarray(v, float))), f"NaN/inf in history {k}"
    resid = energy_residual(res, state=state)
    assert resid < residual, f"energy balance residual {resid:.3g}"
    assert max_penetration(m, X[-1]) < pen * R, f"penetration {max_penetration(m, X[-1]) / R:.3g} r"
    if box is not None:
        lo, hi = np.asarray(box[0]), np.asarray(box[1])
        assert np.all(X[-1] >= lo - R) and np.all(X[-1] <= hi + R), "a fiber left the box"


# ---------------------------------------------------------------------------------------------
# Initial interpenetration (tracing errors)
# ---------------------------------------------------------------------------------------------

def test_half_diameter_overlap_is_resolved_by_the_mesh_stage_then_runs_quietly():
    """Two fibers traced half a diameter into each other (δ = r): the mesh stage's strain-free
    adjustment separates them; the run then starts without stored contact energy and stays at rest."""
    from fiberpipe.model.mesh import Mesh, resolve_overlaps

    L, n = 3e-3, 10
    s = np.linspace(0, L, n + 1)
    a = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    b = np.column_stack([s, np.zeros_like(s), np.full_like(s, R)])  # centre distance r: δ = r
    mesh = Mesh(np.vstack([a, b]), np.array([0, n + 1, 2 * n + 2]), np.array([R, R]))
    with pytest.raises(FiberpipeError, match="overlap|shift"):
        resolve_overlaps(Mesh(mesh.nodes_m.copy(), mesh.node_offsets, mesh.radius_m), max_shift_m=0.1e-3)
    info = resolve_overlaps(mesh, max_shift_m=0.3e-3)
    # the least shift is r/2 per fiber (125 um); the adjustment moves nodes by up to ~1.9x that, as a
    # node's shift sums the pushes of every overlapping segment pair it belongs to
    assert 0.5 * R <= info["max_shift_m"] < 1.0 * R
    m = build_model(mesh.nodes_m, mesh.node_offsets, R, MAT)
    assert max_penetration(m, m.nodes_m) < 1e-3 * R
    res = simulate(m, [Damping(1e4), hook(m)], SimulationSettings(end_time_s=0.1e-3, output_frames=3))
    assert_bounded(res, m)
    assert np.max(np.abs(res.frames_positions[-1] - m.nodes_m)) < 1e-3 * R  # nothing pushed


def test_half_diameter_overlap_in_the_solver_is_pushed_apart_without_explosion():
    """The same overlap given straight to the solver (no adjustment), damped: pushed apart to
    (was xfail: ~1.6 J stored, divergence at step 6; now the hook's initial-overlap offset, released
    over ``contact.overlap_release`` = 0.1 ms, pushes the fibers apart gradually)
    contact (δ → 0), no NaN, speeds bounded (no divergence), energy balanced."""
    L, n = 3e-3, 10
    m = fibers_model([((0, 0, 0), (L, 0, 0), n), ((0, 0, R), (L, 0, R), n)])
    res = simulate(m, [Damping(1e5), hook(m)], SimulationSettings(end_time_s=1.0e-3, output_frames=5))
    x = res.frames_positions[-1]
    gap = np.mean(x[m.node_fiber == 1, 2]) - np.mean(x[m.node_fiber == 0, 2])
    assert gap > 2 * R * 0.99  # apart
    assert gap < 20 * R  # not blown away
    assert_bounded(res, m, residual=0.05, pen=0.01, state=True)  # measured 0.0054


# ---------------------------------------------------------------------------------------------
# Exactly parallel, exactly perpendicular, sliding across joints (verification cases reused)
# ---------------------------------------------------------------------------------------------

def test_exactly_parallel_contact_matches_johnson():
    from fiberpipe.verification.contact_cases import contact_pair_parallel

    (row,) = contact_pair_parallel(quick=True)
    assert math.isfinite(row.measured) and row.error < row.tolerance, row


def test_exactly_perpendicular_contact_matches_hertz():
    from fiberpipe.verification.contact_cases import contact_pair_crossed

    row = contact_pair_crossed(90.0, quick=True)
    assert math.isfinite(row.measured) and row.error < row.tolerance, row


def test_sliding_across_element_joints_keeps_the_normal_force():
    from fiberpipe.verification.contact_cases import sliding_parallel

    row = sliding_parallel(quick=True)
    assert math.isfinite(row.measured) and row.error < row.tolerance, row


@pytest.mark.parametrize("pressed", [False, True], ids=["touching", "pressed"])
def test_crossing_fiber_dragged_across_joints_does_not_snag(pressed):
    """A fiber crossing another at 90°, dragged by a drive along the lower fiber's axis across
    several element joints (damped, α = 2e4): it follows the drive, nothing penetrates, the energy
    balance closes.

    touching: the upper fiber just touching the fully clamped lower one (the
    drive prescribes all its translations, so its line load acts on the drive only and the contact
    stays inactive). The damping dissipation of the driven nodes (α m v² t, ALLVD) has its
    counterpart in the drive's reaction work (ALLWK): residual 2.8e-7.
    pressed: the upper fiber 0.02 r into the lower one, which is clamped at its ends only and bends
    under the contact: the contact stays active along the whole drag (no snag, no loss of contact);
    residual 2.3e-3 of the booked balance; from state functions 3.1 %: the point part's crossing
    hops across the bent fiber's joints (docs/contact.md, "Where it stops").
    """
    L, n = 3e-3, 10
    z1 = (2.0 - 0.02) * R if pressed else 2 * R
    m = fibers_model([((0, 0, 0), (L, 0, 0), n),
                      ((0.6e-3, -L / 2, z1), (0.6e-3, L / 2, z1), n)])
    if pressed:
        clamps = Clamps([Clamp(0, "start"), Clamp(0, "end")])
        contact = contact_hook(m, law=make_law(LAW, E_pa=15e9, nu=0.3), overlap_release_s=0.0)
    else:
        clamps = Clamps([Clamp(0, k) for k in range(n + 1)])
        contact = hook(m)
    eff = [clamps, Loads([LineLoad(1, [0, 0, -1.0])]), Damping(2e4),
           Drives([Drive(1, [1.5e-3, 0, 0], 5.0)]), contact]
    res = simulate(m, eff, SimulationSettings(output_frames=31))
    assert res.completed
    x = res.frames_positions[-1]
    assert abs(np.mean(x[m.node_fiber == 1, 0]) - 2.1e-3) < 1e-5
    if pressed:
        assert np.min(res.history["contacts"]) > 0
        assert_bounded(res, m, residual=1e-2, pen=0.03)
    else:
        assert_bounded(res, m, residual=1e-3, pen=0.02)


# ---------------------------------------------------------------------------------------------
# Pinched, dense, fast
# ---------------------------------------------------------------------------------------------

def _three_beams(L=3e-3, n=10):
    h = math.sqrt(3.0) * R
    return fibers_model([((0, 0, R + h), (L, 0, R + h), n), ((0, -R, R), (L, -R, R), n), ((0, R, R), (L, R, R), n)])


def test_fiber_pinched_between_a_plate_and_other_fibers():
    """Beam 1 on beams 2 and 3 (on a fixed plate, walls at y = ±2r); the upper plate comes down and
    pinches beam 1 onto them: upper and lower plate forces balance at the end, penetration stays
    small, nothing escapes the walls."""
    m = _three_beams()
    # the plate travels 6 µm, past the planes' 5 µm penalty onset (2 % of r), so the pinch is a hard one
    eff = [Plates(axis="z", lower="fixed", upper="moving", displacement_m=6e-6, velocity_m_s=0.05, mu=0.2),
           Walls({"y": (-2 * R, 2 * R)}, mu=0.2), Damping(1e5), hook(m, friction=True)]
    res = simulate(m, eff, SimulationSettings(end_time_s=0.4e-3, output_frames=5))  # loading 130 us, then settle
    F = np.asarray(res.history["plate_force"])
    walls = np.asarray(res.history["wall_force"])[-1]
    lower, upper = F[-1, 0], F[-1, 1]
    assert upper > 0.05  # pinched: a real load
    # vertical equilibrium: what the lower plate does not carry, wall friction does (at most mu N_wall
    # on each wall; beams 2/3 slide on the walls while the wedge closes, so friction is saturated)
    assert lower <= upper
    # (within 5 %: the plane penalties' onset lets some wall contacts stick; measured 0.4 % below)
    assert upper - lower == pytest.approx(0.2 * walls.sum(), rel=0.05)
    h = math.sqrt(3.0) * R
    assert_bounded(res, m, box=([0, -2 * R, 0], [3e-3, 2 * R, 2 * R + h]), residual=0.05, pen=0.05)


def _grid_bundle(nx=3, ny=3, L=3e-3, n=10, pitch_y=3.2 * R, seed=0):
    rng = np.random.default_rng(seed)
    polys = []
    for j in range(ny):
        for i in range(nx):
            x0 = (i - (nx - 1) / 2) * 2.1 * R + rng.uniform(-0.02, 0.02) * R
            y0 = R + j * pitch_y + rng.uniform(-0.05, 0.05) * R
            polys.append(((x0, y0, 0.0), (x0, y0, L), n))
    return fibers_model(polys)


def test_dense_bundle_compacted_to_vf_07():
    """9 fibers in a cassette of width 6.4 r, compacted by the lower plate until v_f = 0.7 (from
    0.41): completes, no NaN, the plates carry the load, penetration bounded, nobody escapes."""
    m = _grid_bundle()
    w = 6.4 * R
    y_top = float(m.nodes_m[:, 1].max() + R)
    h_final = 9 * math.pi * R**2 / (0.7 * w)
    U = y_top - h_final
    eff = [Plates(axis="y", lower="moving", upper="fixed", displacement_m=U, velocity_m_s=0.5,
                  lower_position_m=0.0, upper_position_m=y_top, mu=0.2),
           Walls({"x": (-w / 2, w / 2)}, mu=0.2), Damping(1e5), hook(m, friction=True)]
    res = simulate(m, eff, SimulationSettings(output_frames=5))
    assert res.completed
    vf = 9 * math.pi * R**2 / (w * (y_top - U))
    assert vf == pytest.approx(0.7, abs=1e-9)
    assert_bounded(res, m, box=([-w / 2, U, 0], [w / 2, y_top, 3e-3]), residual=0.05, pen=0.05)


def test_high_loading_velocity_without_damping():
    """Compaction at 6e4 mm/min (1 m/s) with no damping at all: stays bounded (no NaN, no divergence,
    energy balanced within 5 %), no fiber escapes the cassette."""
    m = _grid_bundle(seed=1)
    w = 6.4 * R
    y_top = float(m.nodes_m[:, 1].max() + R)
    U = 0.25e-3
    eff = [Plates(axis="y", lower="moving", upper="fixed", displacement_m=U, velocity_m_s=1.0,
                  lower_position_m=0.0, upper_position_m=y_top, mu=0.2),
           Walls({"x": (-w / 2, w / 2)}, mu=0.2), hook(m, friction=True)]
    res = simulate(m, eff, SimulationSettings(output_frames=5))
    assert res.completed
    assert_bounded(res, m, box=([-w / 2, U, 0], [w / 2, y_top, 3e-3]), residual=0.05, pen=0.05)


# ---------------------------------------------------------------------------------------------
# Time step: just below the limit for a long run; above it detected
# ---------------------------------------------------------------------------------------------

def _wavy_fiber(n=10, L=3e-3):
    s = np.linspace(0, L, n + 1)
    return fibers_model([np.column_stack([s, 0.1e-3 * np.sin(2 * np.pi * s / L), 0.05e-3 * np.cos(3 * np.pi * s / L)])])


def test_long_run_just_below_the_stable_limit_conserves_energy():
    """Free undamped vibration at dt = 0.99 × the stable step for 1e5 steps: total energy drift
    below 3 % and no growth."""
    m = _wavy_fiber()
    dt = 0.99 * stable_time_step(m).dt_stable_s
    st = State.at_rest(m)
    rng = np.random.default_rng(3)
    s = np.linspace(0, 1, m.n_nodes)
    st.v[:, 2] = 0.05 * np.sin(np.pi * s)  # the fundamental transverse shape (no high-mode noise)
    res = simulate(m, [], SimulationSettings(dt_s=dt, end_time_s=1e5 * dt, output_frames=3), state=st)
    assert res.steps >= 99_999
    e = res.history["energy/kinetic"] + res.history["energy/strain"]
    assert np.all(np.isfinite(e))
    # measured 1.7 % (verification case 4's 0.5 % is at 0.9 x the limit; the half-step-mean kinetic energy of
    # the modes near ω dt = 2 oscillates more at 0.99 x); bounded, not growing
    assert np.max(np.abs(e - e[0])) / e[0] < 3e-2
    n10 = max(len(e) // 10, 1)
    assert abs(np.mean(e[-n10:]) - np.mean(e[:n10])) / e[0] < 2e-2


def test_dt_above_the_limit_is_refused_with_the_limit_named():
    m = _wavy_fiber()
    lim = stable_time_step(m).dt_stable_s
    with pytest.raises(FiberpipeError, match="above the stable limit"):
        choose_time_step(m, [], SimulationSettings(dt_s=1.01 * lim))


def test_dt_above_the_limit_forced_is_detected_as_divergence():
    m = _wavy_fiber()
    lim = stable_time_step(m).dt_stable_s
    st = State.at_rest(m)
    st.v[:, 1] = 1e-3
    with pytest.raises(SimulationDiverged) as ei:
        simulate(m, [], SimulationSettings(dt_s=1.5 * lim, force_dt=True, end_time_s=2e4 * lim), state=st)
    msg = str(ei.value)
    assert "step" in msg and ("dt" in msg or "time step" in msg)


def test_dt_above_the_limit_in_a_config_is_reported(tmp_path):
    from fiberpipe.config import validate_config
    from fiberpipe.pipeline import run_pipeline

    raw = {"name": "dt-too-big", "input": {"polylines": [[[0, 0, 0], ["3 mm", 0, 0]]]},
           "fiber": {"radius": "0.25 mm"}, "mesh": {"element_length": "0.3 mm"},
           "scene": {"effects": []}, "solver": {"dt": "1e-6 s", "end_time": "1e-5 s"}}
    with pytest.raises(FiberpipeError, match="stable limit"):
        run_pipeline(validate_config(raw), tmp_path / "run")


# ---------------------------------------------------------------------------------------------
# Degenerate input polylines
# ---------------------------------------------------------------------------------------------

def test_duplicate_points_and_zero_length_segments_are_cleaned():
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines

    p = np.array([[0, 0, 0], [0, 0, 0], [1e-3, 0, 0], [1e-3, 0, 0], [1e-3, 0, 0], [2e-3, 0, 0], [3e-3, 0, 0],
                  [3e-3, 0, 0]], float)
    pl = Polylines(p, np.array([0, len(p)]), np.array([R]))
    mesh = mesh_polylines(pl, 0.3e-3)
    L = np.linalg.norm(np.diff(mesh.nodes_m, axis=0), axis=1)
    assert len(mesh.nodes_m) == 11 and np.allclose(L, 0.3e-3)
    m = build_model(mesh.nodes_m, mesh.node_offsets, R, MAT)
    res = simulate(m, [Damping(1e4)], SimulationSettings(end_time_s=2e-5, output_frames=2))
    assert np.all(np.isfinite(res.frames_positions))


def test_very_short_fiber_is_rejected_with_a_clear_message():
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines

    p = np.array([[0, 0, 0], [3e-3, 0, 0], [0, 1e-3, 0], [0.2e-3, 1e-3, 0]], float)
    with pytest.raises(InputError, match="fiber 1 .*shorter than the minimum"):
        mesh_polylines(Polylines(p, np.array([0, 2, 4]), np.array([R, R])), 0.3e-3)


def test_all_points_identical_is_rejected():
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines

    p = np.zeros((4, 3))
    with pytest.raises(InputError, match="fiber 0"):
        mesh_polylines(Polylines(p, np.array([0, 4]), np.array([R])), 0.3e-3)


@pytest.mark.parametrize("angle_deg", [90.0, 150.0])
def test_sharp_kink_is_meshed_stress_free_and_stays_at_rest(angle_deg):
    """A polyline with a sharp kink: turning by 90°, meshed stress free in its traced shape (rest
    strains) and at rest when nothing acts on it; turning by 150° (folded back, a tracing
    artefact), rejected by the mesh stage with a message naming the fiber."""
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines

    th = math.radians(angle_deg)
    p = np.array([[0, 0, 0], [1.5e-3, 0, 0], [1.5e-3 + 1.5e-3 * math.cos(th), 1.5e-3 * math.sin(th), 0]])
    if angle_deg > 120:
        with pytest.raises(InputError, match="fiber 0 turns by 150 deg"):
            mesh_polylines(Polylines(p, np.array([0, 3]), np.array([R])), 0.3e-3)
        return
    mesh = mesh_polylines(Polylines(p, np.array([0, 3]), np.array([R])), 0.3e-3)
    m = build_model(mesh.nodes_m, mesh.node_offsets, R, MAT)
    res = simulate(m, [], SimulationSettings(end_time_s=2e-5, output_frames=2))
    assert np.all(np.isfinite(res.frames_positions))
    assert np.max(np.abs(res.frames_positions[-1] - m.nodes_m)) < 1e-9


def test_hairpin_polyline_is_cleaned_or_rejected():
    """A polyline that doubles back on itself (a 180° reversal, a tracing artefact): either rejected with
    a clear message or meshed into something the solver runs stably."""
    from fiberpipe.model.mesh import mesh_polylines
    from fiberpipe.polylines import Polylines

    p = np.array([[0, 0, 0], [1.5e-3, 0, 0], [0.3e-3, 0, 0]], float)
    try:
        mesh = mesh_polylines(Polylines(p, np.array([0, 3]), np.array([R])), 0.3e-3)
    except InputError as exc:
        assert "fiber 0" in str(exc)
        return
    m = build_model(mesh.nodes_m, mesh.node_offsets, R, MAT)
    res = simulate(m, [Damping(1e4)], SimulationSettings(end_time_s=2e-5, output_frames=2))
    assert np.all(np.isfinite(res.frames_positions))
    assert np.max(np.abs(res.frames_positions[-1] - m.nodes_m)) < 1e-6


# ---------------------------------------------------------------------------------------------
# Effects that cannot act: warnings / errors
# ---------------------------------------------------------------------------------------------

def _scene(**kw):
    from fiberpipe.config import validate_config

    raw = {"name": "w", "input": {"polylines": [[[0, 0, "0.25 mm"], ["3 mm", 0, "0.25 mm"]]]},
           "fiber": {"radius": "0.25 mm"}, "scene": kw}
    return validate_config(raw)


def test_friction_without_contact_warns():
    cfg = _scene(effects=["friction", "gravity"], friction={"mu": 0.2})
    assert any("friction cannot act" in w for w in cfg.scene.warnings())


def test_block_configured_but_not_listed_warns():
    cfg = _scene(effects=["gravity"], damping={"alpha": "1e5 1/s"})
    assert any("scene.damping is configured but not listed" in w for w in cfg.scene.warnings())


def test_plates_out_of_reach_are_an_error():
    from fiberpipe.solver.terms.planes import check_scene_geometry

    m = fibers_model([((0, 0, R), (3e-3, 0, R), 10)])
    pl = Plates(axis="z", lower="moving", upper="fixed", displacement_m=0.1e-3, velocity_m_s=0.1,
                lower_position_m=-1e-3, upper_position_m=2 * R)
    with pytest.raises(FiberpipeError, match="never touch"):
        check_scene_geometry(m, [pl])


# ---------------------------------------------------------------------------------------------
# Property-based: random small scenes stay bounded
# ---------------------------------------------------------------------------------------------

hyp = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, Phase, given, settings, strategies as st  # noqa: E402


@settings(max_examples=6, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate],
          suppress_health_check=list(HealthCheck))
@given(n_fibers=st.integers(2, 4), tilt_deg=st.floats(0.0, 90.0), overlap=st.floats(0.0, 0.05),
       alpha=st.sampled_from([0.0, 1e4, 1e5]), mu=st.sampled_from([0.0, 0.2, 0.5]),
       speed=st.sampled_from([0.05, 0.5]), seed=st.integers(0, 1000))
def test_random_scene_stays_bounded(n_fibers, tilt_deg, overlap, alpha, mu, speed, seed):
    """Fibers stacked in a cassette with random in-plane tilts and initial overlaps up to 0.05 r,
    compacted by a plate at a random speed with random damping and friction: no NaN, no
    divergence, energy balanced within 10 %, penetration < 0.35 r (the imposed squeeze is 0.3 r),
    nobody escapes."""
    rng = np.random.default_rng(seed)
    L, n = 3e-3, 10
    w = 8 * R
    polys = []
    y = R
    for k in range(n_fibers):
        th = math.radians(tilt_deg) * rng.uniform(-1, 1)
        c = np.array([rng.uniform(-1.5, 1.5) * R, y, L / 2])
        u = np.array([math.sin(th), 0.0, math.cos(th)])
        half = min(L / 2, (w / 2 - R - abs(c[0])) / max(abs(u[0]), 1e-9))
        polys.append((c - half * u, c + half * u, n))
        y += (2 - overlap) * R
    m = fibers_model(polys)
    y_top = float(m.nodes_m[:, 1].max() + R)
    eff = [Plates(axis="y", lower="moving", upper="fixed", displacement_m=0.3 * R, velocity_m_s=speed,
                  lower_position_m=0.0, upper_position_m=y_top),
           Walls({"x": (-w / 2, w / 2)}), Gravity([0, -9.81, 0]), hook(m, friction=mu > 0, mu=max(mu, 1e-3))]
    if alpha > 0:
        eff.append(Damping(alpha))
    res = simulate(m, eff, SimulationSettings(output_frames=3))
    assert res.completed
    # the stack touches both plates at t = 0, so squeezing it by 0.3 r is geometrically impossible
    # without penetration: the plates and the contacts share the 0.3 r by their stiffnesses (a soft
    # crossing point takes most of it); bounded means not beyond that plus margin
    assert_bounded(res, m, box=([-w / 2, 0.3 * R, -L], [w / 2, y_top, 2 * L]), residual=0.1, pen=0.35)
