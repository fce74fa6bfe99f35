"""Line-to-line / point contact kernel on static geometry (docs/verification.md, case 5)."""

import math

import numpy as np
import pytest

from fiberpipe.solver import laws as L
from fiberpipe.solver.contact import compute_contact
from fiberpipe.solver.neighbours import VerletList, segment_arclength

# hertz_oriented with ℓ_blend = 1 mm: these checks are of the point part at crossings up to 1 µm
# deep (the default 0.05 mm hands the smaller angles to the line part)

from _contact_geometry import LE, R, all_pairs_between, assemble, fiber

ESTAR = 15e9 / (2 * (1 - 0.09))


def _force_on(f, rng):
    return f[rng[0]:rng[1]].sum(axis=0)


def _crossed(phi_deg, delta, n=40, shift=(0.011e-3, 0.017e-3)):
    c = math.radians(phi_deg)
    xa = fiber([-n / 2 * LE, 0, 0], [1, 0, 0], n)
    xb = fiber([-n / 2 * LE * math.cos(c) + shift[0], -n / 2 * LE * math.sin(c) + shift[1], 2 * R - delta],
               [math.cos(c), math.sin(c), 0], n)
    return assemble(xa, xb)


@pytest.mark.parametrize("delta", [2e-7, 1e-6, 5e-6])
@pytest.mark.parametrize("law", [L.HertzParallelLaw(), L.HertzOrientedLaw(blend_length_m=1e-3)], ids=["parallel", "oriented"])
def test_parallel_fibers_total_force_is_P_times_overlap(law, delta):
    xa = fiber([0, 0, 0], [1, 0, 0], 20)
    xb = fiber([0.13e-3, 0, 2 * R - delta], [1, 0, 0], 20)
    x, seg, rad, fib, rng = assemble(xa, xb)
    pairs = all_pairs_between(fib, 0, 1)
    f = np.zeros_like(x)
    e, nact, buf = compute_contact(x, seg, rad, pairs, len(pairs), law, f)
    p = L.hertz_parallel_line(delta, ESTAR, R, R)[0]
    ref = p * (20 * LE - 0.13e-3)
    fa = _force_on(f, rng[0])
    assert abs(-fa[2] / ref - 1) < 0.02  # tolerance < 2 %; measured ~1e-14
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * ref  # equal and opposite
    assert abs(fa[0]) < 1e-12 * ref and abs(fa[1]) < 1e-12 * ref


@pytest.mark.parametrize("phi", [2.0, 6.0, 10.0, 90.0])
@pytest.mark.parametrize("kind", ["crossed", "oriented"])
def test_crossed_fibers_vs_hertz(phi, kind):
    law = L.HertzCrossedLaw(phi) if kind == "crossed" else L.HertzOrientedLaw(blend_length_m=1e-3)
    K = L.HertzCrossedLaw(phi).stiffness()
    for delta in (1e-7, 1e-6):
        x, seg, rad, fib, rng = _crossed(phi, delta)
        pairs = all_pairs_between(fib, 0, 1)
        f = np.zeros_like(x)
        e, nact, buf = compute_contact(x, seg, rad, pairs, len(pairs), law, f)
        assert abs(-_force_on(f, rng[0])[2] / (K * delta**1.5) - 1) < 0.02
        assert np.abs(f.sum(axis=0)).max() < 1e-12 * K * delta**1.5
        act = buf.fn[: len(pairs)] > 0
        assert np.allclose(buf.phi[: len(pairs)][act], math.radians(phi), atol=1e-9)
        assert e == pytest.approx(0.4 * K * delta**2.5, rel=1e-6)


def test_contact_at_exact_joint_counted_once():
    """Crossing point exactly on a node of both fibers (rounding at s = 0/1): counted once."""
    for phi in (3.0, 5.0, 45.0, 90.0):
        x, seg, rad, fib, rng = _crossed(phi, 1e-6, shift=(0.0, 0.0))
        pairs = all_pairs_between(fib, 0, 1)
        f = np.zeros_like(x)
        compute_contact(x, seg, rad, pairs, len(pairs), L.HertzCrossedLaw(phi), f)
        K = L.HertzCrossedLaw(phi).stiffness()
        assert abs(-_force_on(f, rng[0])[2] / (K * 1e-9) - 1) < 1e-6


def test_no_contact_between_adjacent_elements_of_same_fiber():
    """A sharply kinked fiber: its own adjacent segments overlap geometrically but are excluded."""
    pts = np.array([[0, 0, 0], [LE, 0, 0], [LE * 0.2, 0.1e-3, 0], [LE, 0.2e-3, 0]])
    x, seg, rad, fib, rng = assemble(pts)
    # segments 0 and 2 are 0.2 mm apart (< 2r) but only 0.26 mm of arc apart (< s_excl = 2r)
    vl = VerletList(seg, rad, fib, segment_arclength(seg, fib, x), skin_m=0.1e-3)
    vl.build(x)
    f = np.zeros_like(x)
    e, nact, _ = compute_contact(x, seg, rad, vl.pairs, vl.n_pairs, L.HertzOrientedLaw(blend_length_m=1e-3), f)
    assert vl.n_pairs == 0 and nact == 0 and np.all(f == 0)


def test_parallel_sliding_across_joints_constant_force():
    """A 6-element fiber pressed on a long parallel neighbour slides by 8 element lengths:
    total normal force constant within 1 % (measured: ~1e-13); unequal element lengths too."""
    law = L.HertzOrientedLaw(blend_length_m=1e-3)
    delta = 1e-6
    xb = fiber([0, 0, 0], [1, 0, 0], 20, le=LE * 0.87)
    forces = []
    for sh in np.linspace(0, 8 * LE, 161):
        xa = fiber([0.5e-3 + sh, 0, 2 * R - delta], [1, 0, 0], 6)
        x, seg, rad, fib, rng = assemble(xa, xb)
        pairs = all_pairs_between(fib, 0, 1)
        f = np.zeros_like(x)
        compute_contact(x, seg, rad, pairs, len(pairs), law, f)
        forces.append(_force_on(f, rng[0])[2])  # A lies above B: pushed up
    forces = np.array(forces)
    ref = L.hertz_parallel_line(delta, ESTAR, R, R)[0] * 6 * LE
    assert np.max(np.abs(forces / ref - 1)) < 0.01


def test_crossing_contact_moving_across_joint_is_continuous():
    """Fiber B (crossing at 10°) translated along A so the contact passes a joint of A:
    force and its nodal distribution change continuously (max step ≤ 1 % between 1 µm moves)."""
    law = L.HertzOrientedLaw(blend_length_m=1e-3)
    c = math.radians(10.0)
    fa_all, fnode = [], []
    for sh in np.linspace(-0.2e-3, 0.2e-3, 401):
        xa = fiber([-10 * LE, 0, 0], [1, 0, 0], 20)  # joint of A at x = 0
        xb = fiber([sh - 10 * LE * math.cos(c), -10 * LE * math.sin(c) + 1e-5, 2 * R - 1e-6],
                   [math.cos(c), math.sin(c), 0], 20)
        x, seg, rad, fib, rng = assemble(xa, xb)
        pairs = all_pairs_between(fib, 0, 1)
        f = np.zeros_like(x)
        compute_contact(x, seg, rad, pairs, len(pairs), law, f)
        fa_all.append(-_force_on(f, rng[0])[2])
        fnode.append(-f[10, 2])  # the joint node of A
    fa_all = np.array(fa_all)
    fnode = np.array(fnode)
    ref = L.HertzCrossedLaw(10.0).stiffness() * 1e-9
    assert np.max(np.abs(fa_all / ref - 1)) < 1e-6
    assert np.max(np.abs(np.diff(fnode))) < 0.01 * ref


def test_oriented_kernel_continuous_and_monotone_in_phi():
    """Two 12 mm fibers crossing at their middles, δ = 1 µm: kernel total force non-increasing in Φ
    from 0° to 20°, line law × length at 0°, crossed Hertz beyond 2°, no jumps."""
    law = L.HertzOrientedLaw(blend_length_m=1e-3)
    phis = np.concatenate([np.arange(0, 3.0, 0.05), [4, 6, 10, 20]])
    fs = []
    for phi in phis:
        c = math.radians(phi)
        xa = fiber([-20 * LE, 0, 0], [1, 0, 0], 40)
        xb = fiber([-20 * LE * math.cos(c), -20 * LE * math.sin(c), 2 * R - 1e-6], [math.cos(c), math.sin(c), 0], 40)
        x, seg, rad, fib, rng = assemble(xa, xb)
        pairs = all_pairs_between(fib, 0, 1)
        f = np.zeros_like(x)
        compute_contact(x, seg, rad, pairs, len(pairs), law, f)
        fs.append(-_force_on(f, rng[0])[2])
    fs = np.array(fs)
    assert fs[0] == pytest.approx(L.hertz_parallel_line(1e-6, ESTAR, R, R)[0] * 40 * LE, rel=1e-9)
    assert np.all(np.diff(fs) <= 1e-9 * fs[:-1])
    assert np.max(np.abs(np.diff(fs[:60])) / fs[1:60]) < 0.2  # 0.05° steps (line-law overlap geometry)
    for phi in (2.0, 6.0, 10.0, 20.0):
        k = list(phis).index(phi) if phi in phis else None
        if k is not None:
            assert fs[k] == pytest.approx(L.HertzCrossedLaw(phi).stiffness() * 1e-9, rel=1e-6)


def test_crossing_angle_series_and_acos_branches():
    """Φ from the cross product and the asin series (below 15°) and from acos (above) against
    atan2(|t_A × t_B|, |t_A·t_B|), from 1e-6 rad to 90°, across the 15° switch."""
    import math

    from fiberpipe.solver.geometry import crossing_angle as _crossing_angle

    rng = np.random.default_rng(2)
    for phi in np.concatenate([np.geomspace(1e-6, math.pi / 2, 60), np.radians([14.999, 15.0, 15.001])]):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        w = np.cross(u, rng.normal(size=3))
        w /= np.linalg.norm(w)
        ta = 0.3e-3 * u
        tb = 0.31e-3 * (math.cos(phi) * u + math.sin(phi) * w) * (-1 if phi > 0.5 else 1)
        aa, bb, ab = ta @ ta, tb @ tb, ta @ tb
        ref = math.atan2(np.linalg.norm(np.cross(ta, tb)), abs(ab))
        got = _crossing_angle(*ta, *tb, aa, bb, ab)
        tol = 1e-10 * ref if ref < math.radians(15.0) else 1e-8 * ref  # acos near 1 loses digits
        assert abs(got - ref) <= tol + 1e-15, (phi, got, ref)
