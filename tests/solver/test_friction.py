"""Regularised Coulomb friction kernels: stick, slip, dissipation, history across rebuilds, plane variant."""

import numpy as np
import pytest

from fiberpipe.solver import laws as L
from _contact_geometry import LE, R, all_pairs_between, assemble, contact_pass, fiber
from fiberpipe.solver import Material, Plates, build_model
from fiberpipe.solver._kernels_boundary import DEFAULT_ONSET_FRACTION, plane_onset
from fiberpipe.solver.friction import friction_forces, plane_friction, remap_history
from fiberpipe.solver.layout import ACC_SIZE, ACC_V2_MAX
from fiberpipe.solver.terms import SceneArrays
from fiberpipe.solver.terms.planes import eval_planes, set_up_planes

MU, KT, DT = 0.2, 1e5, 1e-7


def _pressed_pair(delta=1e-6):
    xa = fiber([0, 0, 2 * R - delta], [1, 0, 0], 1)
    xb = fiber([-0.1e-3, 0.05e-3, 0], [0, 1, 0], 1)  # crossing at 90°
    xb = fiber([0.15e-3, -0.15e-3, 0], [0, 1, 0], 1)
    x, seg, rad, fib, rng = assemble(xa, xb)
    pairs = all_pairs_between(fib, 0, 1)
    f = np.zeros_like(x)
    _, nact, buf = contact_pass(x, seg, rad, pairs, len(pairs), L.HertzCrossedLaw(90.0), f)
    assert nact == 1
    return x, seg, pairs, buf, rng


def _slide(v_rel, n_steps, hist=None):
    x, seg, pairs, buf, rng = _pressed_pair()
    fn = buf.fn[0]
    v = np.zeros_like(x)
    v[rng[0][0]:rng[0][1], 0] = v_rel  # fiber A slides along x
    hist = np.zeros((1, 3)) if hist is None else hist
    diss = 0.0
    for _ in range(n_steps):
        f = np.zeros_like(x)
        diss += friction_forces(v, seg, pairs, 1, buf.fn, buf.normal, buf.s, buf.t, MU, KT, DT, hist, f)
    return f, hist, diss, fn, rng


def test_stick_below_coulomb_limit():
    """Total tangential displacement u < μF_n/k_t: elastic stick force −k_t·u exactly, no dissipation
    (the booked one is the work of the force less the spring's energy: zero to rounding)."""
    x, seg, pairs, buf, rng = _pressed_pair()
    fn = buf.fn[0]
    u = 0.5 * MU * fn / KT
    f, hist, diss, _, _ = _slide(u / (100 * DT), 100)
    assert f[rng[0][0]:rng[0][1], 0].sum() == pytest.approx(-KT * u, rel=1e-9)
    assert abs(diss) < 1e-12 * 0.5 * KT * u**2
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * fn


def test_slip_at_coulomb_limit_and_dissipation():
    """Sliding far beyond the stick range: |f_t| = μF_n, dissipation = μF_n × slip distance (< 1e-9)."""
    x, seg, pairs, buf, rng = _pressed_pair()
    fn = buf.fn[0]
    v = 1e-2
    n = 400
    f, hist, diss, _, _ = _slide(v, n)
    ft = f[rng[0][0]:rng[0][1]].sum(axis=0)
    assert np.linalg.norm(ft) == pytest.approx(MU * fn, rel=1e-12)
    assert ft[0] < 0  # opposes the motion
    slip = v * DT * n - MU * fn / KT  # total motion minus the elastic stick displacement
    assert diss == pytest.approx(MU * fn * slip, rel=1e-9)


def test_history_survives_rebuild():
    old_keys = np.array([3, 10, 42, 77], np.int64)
    old_hist = np.arange(12, dtype=float).reshape(4, 3)
    new_keys = np.array([1, 10, 42, 50, 77, 90], np.int64)
    new_hist = np.full((6, 3), -1.0)
    kept = remap_history(old_keys, 4, old_hist, new_keys, 6, new_hist)
    assert kept == 3
    assert np.array_equal(new_hist[[1, 2, 4]], old_hist[[1, 2, 3]])
    assert np.all(new_hist[[0, 3, 5]] == 0.0)
    # a stuck contact keeps its force across a "rebuild" that reorders the list
    x, seg, pairs, buf, rng = _pressed_pair()
    u = 0.3 * MU * buf.fn[0] / KT
    f1, hist, _, _, _ = _slide(u / (10 * DT), 10)
    moved = np.zeros((2, 3))
    remap_history(np.array([1], np.int64), 1, hist, np.array([0, 1], np.int64), 2, moved)
    assert np.array_equal(moved[1], hist[0]) and np.all(moved[0] == 0)
    f2, hist2, _, _, _ = _slide(0.0, 1, hist=moved[1:].copy())
    assert np.allclose(f2, f1, rtol=1e-12, atol=0)


def test_history_rotated_into_tangent_plane():
    x, seg, pairs, buf, rng = _pressed_pair()
    hist = np.array([[0.3, 0.0, 0.4]])  # has a normal (z) component
    f = np.zeros_like(x)
    friction_forces(np.zeros_like(x), seg, pairs, 1, buf.fn, buf.normal, buf.s, buf.t, 10.0, KT, DT, hist, f)
    assert abs(hist[0] @ buf.normal[0]) < 1e-12 and np.linalg.norm(hist[0]) == pytest.approx(0.5)


def _plate_under_fiber(n_el=2, mu=MU, kt=KT):
    """A fiber along x resting 1 µm deep on a fixed plate at z = 0 (pushing +z) with friction μ, k_t:
    ``(model, plane arrays, the planes' friction data)`` (terms.planes.set_up_planes)."""
    s = np.linspace(0.0, 1.0, n_el + 1)[:, None]
    m = build_model(np.array([0.0, 0.0, R - 1e-6]) + s * np.array([1e-3, 0.0, 0.0]), np.array([0, n_el + 1]), R,
                    Material(15e9, 1380.0, 0.3))
    scene = SceneArrays(m, DT)
    Plates(axis="z", lower="fixed", upper="none", lower_position_m=0.0, mu=mu,
           friction_stiffness_n_per_m=kt).setup(m, scene)
    planes, terms = set_up_planes(m, scene)
    assert [t.name for t, _, _ in terms] == ["plane_friction"]
    return m, planes, terms[0][1]


def _plane_pass(m, planes, x, v):
    """The step loop's plane pass at positions ``x``: the listed nodes' normal forces into ``planes.cand_fn``."""
    acc = np.zeros(ACC_SIZE)
    acc[ACC_V2_MAX] = -1.0  # list the nodes anew
    eval_planes(planes, x, v, m.radius_node, np.zeros_like(x), acc, 0.0, DT)


def test_plane_friction_stick_and_slip():
    """Nodes on a plane z = 0 pressed by the plane pass's k g(δ) g'(δ); the friction takes that normal
    force, slides at μF_n and dissipates μF_n·slip."""
    m, planes, data = _plate_under_fiber()
    x = m.nodes_m.copy()
    v = np.zeros_like(x)
    v[:, 0] = 1.0
    _plane_pass(m, planes, x, v)
    g, gp = plane_onset(1e-6, DEFAULT_ONSET_FRACTION * R)
    fn = planes.k_pen * g * gp  # the plane penalty's normal force per node
    listed = planes.cand_idx[:planes.cand_off[1]]
    assert np.allclose(planes.cand_fn[:listed.size], fn[listed], rtol=1e-12)
    diss = 0.0
    n = 300
    for step in range(n):
        data.ff[:] = 0.0
        diss += plane_friction(v, data, DT, step)[0]
    assert np.allclose(data.ff[:, 0], -MU * fn, rtol=1e-12) and data.tforce[0, 0] == pytest.approx(MU * fn.sum())
    # the stick length μF_n/k_t is shorter than a step's travel (100 nm): the force jumps from 0 to
    # μF_n in the first step, whose work the step loop books with the trapezoid, half of μF_n·Δu; the
    # booked dissipation is that work less the spring's energy, so it misses ½μF_n(Δu − μF_n/k_t) of the
    # continuous μF_n × slip
    lim, du = MU * fn, 1.0 * DT
    assert diss == pytest.approx(np.sum(lim * (du * n - lim / KT) - 0.5 * lim * (du - lim / KT)), rel=1e-9)


def test_plane_friction_forgets_a_node_that_left_the_plane():
    """A node lifted off the plane for a few steps loses its history (its entry cleared, no force);
    back on the plane its spring starts afresh: the same force as at its first touch."""
    m, planes, data = _plate_under_fiber(mu=10.0)  # sticks: the force is the spring's, −k_t Δu
    x_on = m.nodes_m.copy()
    v = np.zeros_like(x_on)
    v[:, 0] = 1e-3
    forces = []
    for step in range(8):
        x = x_on + [0.0, 0.0, 1e-5] if 3 <= step < 5 else x_on
        _plane_pass(m, planes, x, v)
        data.ff[:] = 0.0
        plane_friction(v, data, DT, step)
        forces.append(data.ff[:, 0].copy())
        if 3 <= step < 5:
            assert np.all(data.ff == 0.0) and np.all(data.hist[:, 0, :3] == 0.0)
    assert np.allclose(forces[0], -KT * 1e-3 * DT, rtol=1e-12)  # first touch: one step of stick
    assert np.allclose(forces[1], 2 * forces[0], rtol=1e-12)    # the spring keeps its history
    assert np.array_equal(forces[5], forces[0])                 # afresh after leaving the plane


def _sliding_contact_point(n_steps=400, V=0.05, mu=100.0):
    """A stuck crossing whose contact point slides along segment A (s from 0.3 to 0.7) while A
    turns about the contact normal (its ends move ±V across): the spring is loaded and its point
    moves. friction_forces_ex with the (C, 7) history on prescribed records and velocities;
    returns (booked dissipation per step, the first-order exchange scale Σ ½|p·Δu'−p·Δu|, springs'
    energy at the end)."""
    from fiberpipe.solver.friction import friction_forces_ex
    from fiberpipe.solver.contact_state import PairRecords

    seg = np.array([[0, 1], [2, 3]], np.int64)
    pairs = np.array([[0, 1]], np.int64)
    v = np.zeros((4, 3))
    v[0, 1], v[1, 1] = V, -V  # segment A turns about z
    hist = np.zeros((1, 7))
    one = np.ones(1)
    ds, scale, booked = 0.4 / n_steps, 0.0, []
    for n in range(n_steps):
        s = 0.3 + ds * n
        rec = PairRecords(one.copy(), np.array([[0.0, 0.0, 1.0]]), np.array([s]), np.array([0.5]), one, one,
                          one.copy(), one, np.zeros(0), np.zeros(1, np.int64))
        p_y = hist[0, 1]
        f = np.zeros((4, 3))
        d, e, back = friction_forces_ex(v, seg, pairs, 1, rec, mu, KT, DT, hist, f, 1, n)
        booked.append(d)
        scale += 0.5 * abs(p_y * ds * (-2 * V) * DT) if n else 0.0
    return np.array(booked), scale, e


def test_spring_stretched_at_the_midpoint_of_a_sliding_contact_point():
    """A stuck contact whose point slides under a loaded spring: the spring stretches at the middle
    of the point's path over the step, so its energy and the trapezoidal work of the forces (each at
    the point it acted at) differ by ¼(f_{n−1} − f_n)·(Δu − Δu'), second order; the booked
    dissipation stays below 1 % of the first-order exchange ½ f_{n−1}·(Δu − Δu') the contact point's
    own displacement would give, each step and in sum."""
    booked, scale, e_spring = _sliding_contact_point()
    assert e_spring > 0.0 and scale > 1e-3 * e_spring  # the spring is loaded and its point moves
    assert abs(booked.sum()) < 0.01 * scale
    assert np.max(np.abs(booked)) < 0.01 * scale / len(booked) * 10


def test_friction_in_tasks_gives_the_serial_forces_and_histories_bit_for_bit():
    """solver.threads > 1 runs the fiber–fiber friction's pairs in prange tasks
    (``friction_forces_tasks``); each pair's force goes to its row and the rows are added in pair
    order, so forces and histories equal the serial pass's exactly; the sums only to rounding."""
    from fiberpipe.solver.contact_state import PairRecords
    from fiberpipe.solver.friction import FRICTION_TASK_MIN, friction_forces_ex, friction_forces_tasks

    rng = np.random.default_rng(7)
    n_seg, n_pairs = 200, 6 * FRICTION_TASK_MIN  # enough pairs for six tasks
    seg_nodes = np.stack([np.arange(n_seg), np.arange(n_seg) + 1], axis=1).astype(np.int64)
    pairs = np.sort(rng.choice(n_seg, size=(n_pairs, 2), replace=True), axis=1).astype(np.int64)
    v = 1e-3 * rng.standard_normal((n_seg + 1, 3))
    normal = rng.standard_normal((n_pairs, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    rec = PairRecords(rng.uniform(0.01, 0.1, n_pairs), normal, rng.uniform(0, 1, n_pairs), rng.uniform(0, 1, n_pairs),
                      np.zeros(n_pairs), np.zeros(n_pairs), rng.uniform(0.2, 1.0, n_pairs), np.zeros(0), np.zeros(0),
                      np.arange(n_pairs, dtype=np.int64))
    step = 5
    hist = np.zeros((n_pairs, 7))
    hist[:, :3] = 1e-3 * rng.standard_normal((n_pairs, 3))  # loaded springs, some beyond the cone: slip
    hist[:, 3] = 1e4
    hist[:, 4] = np.where(rng.uniform(size=n_pairs) < 0.8, step - 1, step - 3)  # a fifth start afresh
    hist[:, 5:] = rng.uniform(0, 1, (n_pairs, 2))
    out = []
    for kernel in (friction_forces_ex, friction_forces_tasks):
        h, f = hist.copy(), np.zeros_like(v)
        sums = kernel(v, seg_nodes, pairs, n_pairs, rec, 0.2, 2e4, 1e-7, h, f, n_pairs, step)
        out.append((h, f, sums))
    (h1, f1, s1), (h2, f2, s2) = out
    assert np.any(f1 != 0.0) and s1[0] != 0.0
    assert np.array_equal(f1, f2) and np.array_equal(h1, h2)
    assert s2 == pytest.approx(s1, rel=1e-12, abs=1e-30)
