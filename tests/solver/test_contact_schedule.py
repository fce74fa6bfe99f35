"""The contact pass's work-saving bookkeeping is exact.

* per-pair skip refreshed by a path bound (``c_gap``/``reach`` of ``contact_forces_pot``): a pair is
  skipped only while it cannot have closed its gap, so forces equal those of evaluating every pair;
* the list of pairs in contact (``c_active``);
* time-stamped friction histories (fiber–fiber and fiber–plane): the same forces and histories as
  clearing a history whenever its contact opens.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fiberpipe.solver import laws as L
from _contact_geometry import LE, R, assemble, fiber
from fiberpipe.solver.contact_pairs import gauss_points
from fiberpipe.solver.contact_potential import contact_forces_pot
from fiberpipe.solver.contact_state import PairRecords
from fiberpipe.solver.geometry import pair_gap
from fiberpipe.solver.friction import friction_forces_ex


def _bundle(rng):
    """Six short fibers crossing at small angles, some touching, some up to ≈ 40 µm apart."""
    fibers = []
    for k in range(6):
        p0 = [-0.75e-3, (k % 3) * (2 * R + rng.uniform(-1e-6, 40e-6)), (k // 3) * (2 * R + rng.uniform(-1e-6, 40e-6))]
        d = [1.0, rng.normal(0, 0.05), rng.normal(0, 0.05)]
        fibers.append(fiber(p0, d, 5))
    x, seg, rad, fib, _ = assemble(*fibers)
    pairs = np.array([[i, j] for i in range(len(seg)) for j in range(i + 1, len(seg)) if fib[i] != fib[j]], np.int64)
    return x, seg, rad, pairs


def _squeezed(rng, x, steps=60, d=1.5e-6, release=0):
    """``steps`` steps of motion, each node moving by at most d per step (the bundle squeezed
    together, with noise), then ``release`` steps of the bundle let go (moving apart): yields the
    positions and the reach 2D (D the path bound since the build)."""
    path = 0.0
    for step in range(steps + release):
        move = rng.normal(size=x.shape)
        move *= d / np.maximum(np.linalg.norm(move, axis=1), 1e-30)[:, None] * rng.uniform(0, 1, (len(x), 1))
        towards = 1.0 if step < steps else -1.0  # the middle, then away from it
        move[:, 1:] -= towards * 0.5 * d * np.sign(x[:, 1:] - x[:, 1:].mean(axis=0))
        move *= d / max(np.linalg.norm(move, axis=1).max(), d)
        x = x + move
        path += np.linalg.norm(move, axis=1).max()
        yield x, 2.0 * path


def _potential_bundle(rng):
    """:func:`_bundle` with what the potential kernel takes besides: the segments' arc lengths, the
    default law and two Gauss points per segment."""
    x, seg, rad, pairs = _bundle(rng)
    arc = np.zeros((len(seg), 2))
    arc[:, 1] = np.linalg.norm(x[seg[:, 1]] - x[seg[:, 0]], axis=1)
    gxi, gw = gauss_points(2)
    return x, seg, rad, pairs, arc, L.make_law("hertz_oriented", E_pa=15e9, nu=0.3), gxi, gw


def _arc(x, seg):
    """Each segment's reference length as the arc lengths of its ends (its length at ``x``)."""
    arc = np.zeros((len(seg), 2))
    arc[:, 1] = np.linalg.norm(x[seg[:, 1]] - x[seg[:, 0]], axis=1)
    return arc


def _records(n, c_gap, c_active):
    out = [np.zeros(n) for _ in range(7)]
    return PairRecords(out[0], np.zeros((n, 3)), out[1], out[2], out[3], out[4], out[5], out[6], c_gap, c_active)


def _pass(x, seg, rad, pairs, law, c_gap, reach, c_active, arc=None):
    n = len(pairs)
    gxi, gw = gauss_points(2)
    f = np.zeros_like(x)
    rec = _records(n, c_gap, c_active)
    arc = _arc(x, seg) if arc is None else arc
    e, na = contact_forces_pot(x, seg, rad, arc, pairs, n, law.law_id, law.params(), gxi, gw, 0.0, f, rec,
                               np.zeros(0), reach)
    return f, rec.fn, na


def test_path_bound_skip_is_exact_and_refreshes():
    rng = np.random.default_rng(3)
    x, seg, rad, pairs = _bundle(rng)
    arc = _arc(x, seg)
    law = L.make_law("hertz_oriented", E_pa=15e9, nu=0.3)
    n = len(pairs)
    c_gap = np.array([pair_gap(x, seg, rad, pairs, k) for k in range(n)])  # the build
    c_active = np.zeros(n, np.int64)
    skipped_total = 0
    for x, reach in _squeezed(rng, x):
        skipped_total += int(np.sum(c_gap > reach))
        f_skip, fn_skip, na_skip = _pass(x, seg, rad, pairs, law, c_gap, reach, c_active, arc)
        f_all, fn_all, na_all = _pass(x, seg, rad, pairs, law, np.zeros(0), 0.0, np.zeros(0, np.int64), arc)
        assert np.array_equal(f_skip, f_all) and np.array_equal(fn_skip, fn_all) and na_skip == na_all
        # the pairs in contact, listed in order
        assert np.array_equal(c_active[:na_skip], np.flatnonzero(fn_all > 0))
        # every threshold is still a valid bound: gap now >= threshold − reach for every pair
        gap_now = np.array([pair_gap(x, seg, rad, pairs, k) for k in range(n)])
        assert np.all(gap_now >= c_gap - reach - 1e-15)
    assert na_all > 0  # the test reaches contacts
    assert skipped_total > 10 * n  # and the skip did skip (most pairs, most steps)


def test_potential_pass_visits_only_pairs_within_reach_and_keeps_their_records():
    """The potential kernel lists the pairs within reach first and visits only those: with records
    kept from step to step (as the hook keeps them; fn = 0 at the build), forces, energies, normal
    forces and the list of pairs in contact equal a pass that evaluates every pair with fresh records."""
    from fiberpipe.solver.contact_potential import contact_forces_pot
    from fiberpipe.solver.contact_state import new_records

    rng = np.random.default_rng(5)
    x, seg, rad, pairs, arc, law, gxi, gw = _potential_bundle(rng)
    n = len(pairs)
    kept = new_records(n)
    kept.gap[:] = [pair_gap(x, seg, rad, pairs, k) for k in range(n)]  # the build
    visited_less = 0
    for x, reach in _squeezed(rng, x):
        visited_less += int(np.sum(kept.gap[:n] > reach))
        f_skip = np.zeros_like(x)
        e_skip, na_skip = contact_forces_pot(x, seg, rad, arc, pairs, n, law.law_id, law.params(), gxi, gw, 1e-9,
                                             f_skip, kept, np.zeros(0), reach)
        fresh = new_records(n)
        fresh = fresh._replace(gap=np.zeros(0))
        f_all = np.zeros_like(x)
        e_all, na_all = contact_forces_pot(x, seg, rad, arc, pairs, n, law.law_id, law.params(), gxi, gw, 1e-9,
                                           f_all, fresh, np.zeros(0), 0.0)
        assert np.array_equal(f_skip, f_all) and e_skip == e_all and na_skip == na_all
        assert np.array_equal(kept.fn[:n], fresh.fn[:n])
        assert np.array_equal(kept.active[:na_skip], np.flatnonzero(fresh.fn[:n] > 0))
    assert na_all > 0 and visited_less > 10 * n


def test_threaded_potential_pass_equals_the_serial_pass_bit_for_bit():
    """solver.threads > 1: the potential pass evaluates its pairs in prange tasks and adds their force
    blocks in the serial order, so forces, energy, records and the list of pairs in contact equal the
    serial pass's bit for bit at every step of a bundle squeezed and let go (records kept from step to
    step; pairs that come apart are reset in the tasks)."""
    from fiberpipe.solver.contact_potential import PAIR_TASK_MIN, contact_forces_pot, contact_forces_pot_threads
    from fiberpipe.solver.contact_state import new_records

    if os.environ.get(_THREADS_ENV):  # the run of test_tasks_on_two_threads_... below
        import numba

        assert numba.get_num_threads() == int(os.environ[_THREADS_ENV])
    elif (os.cpu_count() or 1) >= 2:
        # on one numba thread the tasks run in turn: the check that matters runs on two threads, in
        # the process of test_tasks_on_two_threads_equal_the_serial_passes (compiling the threaded
        # pass twice would cost the suite half a minute)
        pytest.skip("checked on two threads by test_tasks_on_two_threads_equal_the_serial_passes")

    rng = np.random.default_rng(7)
    x, seg, rad, pairs, arc, law, gxi, gw = _potential_bundle(rng)
    n = len(pairs)
    kept = [new_records(n), new_records(n)]
    for r in kept:
        r.gap[:] = [pair_gap(x, seg, rad, pairs, k) for k in range(n)]
    most_looked = 0
    opened = 0  # pairs in contact at one step and apart at the next: their fn reset in the tasks
    for x, reach in _squeezed(rng, x, steps=40, d=2.5e-6, release=15):
        fn_before = kept[1].fn[:n].copy()
        most_looked = max(most_looked, int(np.sum(kept[0].gap[:n] <= reach)))
        res = []
        for kernel, r in zip((contact_forces_pot, contact_forces_pot_threads), kept):
            f = np.zeros_like(x)
            e, na = kernel(x, seg, rad, arc, pairs, n, law.law_id, law.params(), gxi, gw, 1e-9, f, r, np.zeros(0),
                           reach)
            res.append((f, e, na))
        (f1, e1, na1), (f2, e2, na2) = res
        assert np.array_equal(f1, f2) and e1 == e2 and na1 == na2
        for name in ("fn", "normal", "s", "t", "phi", "delta", "share", "fsum", "gap"):
            assert np.array_equal(getattr(kept[0], name), getattr(kept[1], name)), name
        assert np.array_equal(kept[0].active[:na1], kept[1].active[:na2])
        opened += int(np.sum((fn_before > 0) & (kept[1].fn[:n] == 0)))
    assert na1 > 0 and opened > 0
    assert most_looked >= 2 * PAIR_TASK_MIN  # two tasks or more ran


# set by test_tasks_on_two_threads_equal_the_serial_passes, which checks that its run got them
_THREADS_ENV = "FIBERPIPE_TEST_THREADS"


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs two CPUs")
def test_tasks_on_two_threads_equal_the_serial_passes():
    """The threaded contact pass's check above, the threaded friction's (tests/solver/test_friction.py)
    and the threaded neighbour build's (tests/solver/test_neighbours.py) with two threads running the
    tasks, in a process of their own: the suite itself runs numba on one thread (tests/conftest.py),
    where the tasks run in turn."""
    env = dict(os.environ, NUMBA_NUM_THREADS="2", **{_THREADS_ENV: "2"})
    here = Path(__file__)
    tests = [f"{here}::test_threaded_potential_pass_equals_the_serial_pass_bit_for_bit",
             f"{here.with_name('test_friction.py')}::test_friction_in_tasks_gives_the_serial_forces_and_histories_bit_for_bit",
             f"{here.with_name('test_neighbours.py')}::test_threaded_build_lists_the_serial_builds_pairs"]
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests], env=env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "3 passed" in r.stdout


def _pair_in_contact(delta):
    xa = fiber([0, 0, 2 * R - delta], [1, 0, 0], 1)
    xb = fiber([0.15e-3, -0.15e-3, 0], [0, 1, 0], 1)
    x, seg, rad, fib, rng = assemble(xa, xb)
    return x, seg, rad, np.array([[0, 1]], np.int64), rng


def test_stamped_friction_history_equals_clearing_it():
    """A contact that slides, opens for a few steps and closes again: the stamped history (visit the
    pairs in contact only) gives the forces and histories of clearing every open pair's history."""
    law = L.HertzCrossedLaw(90.0)
    mu, kt, dt = 0.2, 1e5, 1e-7
    hist_clear = np.zeros((1, 4))
    hist_stamp = np.zeros((1, 5))
    for step in range(40):
        delta = 1e-6 if (step < 15 or step >= 20) else -1e-6  # open for steps 15–19
        x, seg, rad, pairs, rng = _pair_in_contact(delta)
        c_active = np.zeros(1, np.int64)
        f0, fn, na = _pass(x, seg, rad, pairs, law, np.zeros(0), 0.0, c_active)
        gxi, gw = gauss_points(2)
        rec = _records(1, np.zeros(0), c_active)
        contact_forces_pot(x, seg, rad, _arc(x, seg), pairs, 1, law.law_id, law.params(), gxi, gw, 0.0,
                           np.zeros_like(x), rec, np.zeros(0), 0.0)
        v = np.zeros_like(x)
        v[rng[0][0]:rng[0][1], 0] = 0.3 * (1 + 0.1 * np.sin(step))
        f1 = np.zeros_like(x)
        f2 = np.zeros_like(x)
        d1, e1, _ = friction_forces_ex(v, seg, pairs, 1, rec._replace(active=np.zeros(0, np.int64)), mu, kt, dt,
                                    hist_clear, f1, 0, 0)
        d2, e2, _ = friction_forces_ex(v, seg, pairs, 1, rec, mu, kt, dt, hist_stamp, f2, na, step)
        assert np.array_equal(f1, f2) and d1 == d2 and e1 == e2
        if na:
            assert np.array_equal(hist_clear[0, :4], hist_stamp[0, :4])
    assert np.any(hist_clear[0, :3] != 0)


def test_loading_ramp_fraction_reaches_the_plates(tmp_path):
    from fiberpipe.config import load_config
    from fiberpipe.errors import FiberpipeError
    from fiberpipe.model.mesh import Mesh
    from fiberpipe.solver.build import build_simulation
    from fiberpipe.solver.terms import Plates

    cfg_text = """
name: ramp
input: {polylines: [[[0, "0.25 mm", 0], [0, "0.25 mm", "3 mm"]]]}
fiber: {radius: "0.25 mm"}
scene:
  effects: [plates]
  plates: {axis: y, lower: moving, upper: fixed, lower_position: 0, upper_position: "0.5 mm"}
  loading: {displacement: "0.05 mm", velocity: "1000 mm/min", ramp_fraction: 0.02}
"""
    p = tmp_path / "c.yaml"
    p.write_text(cfg_text)
    cfg = load_config(p)
    assert cfg.scene.loading.ramp_fraction == 0.02
    x = np.zeros((11, 3))
    x[:, 1] = 0.25e-3
    x[:, 2] = np.linspace(0, 3e-3, 11)
    _, effects, _ = build_simulation(Mesh(x, np.array([0, 11]), np.array([0.25e-3])), cfg)
    plates = [e for e in effects if isinstance(e, Plates)][0]
    assert plates.ramp_fraction == 0.02
    with pytest.raises(FiberpipeError, match="ramp_fraction"):
        load_config(p, {"scene.loading.ramp_fraction": 0.5})


def test_positions_moved_from_outside_are_seen():
    """A state edited between calls (a fiber pushed 25 µm into its neighbour without a velocity) gets
    the contact force at once, as a fresh integrator gives it: the hook rebuilds when a node is
    farther from its build position than the path bound allows. Non-unit quaternions handed in are
    normalised."""
    from fiberpipe.solver import Material, build_model
    from fiberpipe.verification.case_config import contact_hook
    from fiberpipe.solver.integrator import Integrator
    from fiberpipe.solver.state import State

    xa = fiber([0, 0, 0], [1, 0, 0], 10)
    xb = fiber([0, 2 * R + 20e-6, 0], [1, 0, 0], 10)  # 20 µm apart: inside the skin, skipped
    m = build_model(np.vstack([xa, xb]), np.array([0, 11, 22]), R, Material(15e9, 1380.0, 0.3))
    integ = Integrator(m, [contact_hook(m)], 1e-9, history_rows=2, history_every=10**9)
    st = State.at_rest(m)
    integ.advance(st, 20)
    st.x[11:, 1] -= 25e-6  # 5 µm overlap now
    st.q[3] *= 1.5  # a non-unit quaternion from outside
    fresh = st.copy()
    integ.advance(st, 1)
    integ2 = Integrator(m, [contact_hook(m)], 1e-9, history_rows=2, history_every=10**9)
    integ2.advance(fresh, 1)
    assert np.all(st.v[11:, 1] > 0)  # pushed apart
    assert np.allclose(st.v, fresh.v, rtol=1e-9, atol=1e-15)
    assert np.allclose(np.linalg.norm(st.q, axis=1), 1.0, atol=1e-12)
