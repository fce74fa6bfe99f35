"""The contact pass on static geometry: parallel fibers (the line part with its end weights), the
neighbour list's exclusions, the crossing angle."""

import math

import numpy as np
import pytest

from fiberpipe.solver import laws as L
from fiberpipe.solver.neighbours import VerletList, segment_arclength

from _contact_geometry import LE, R, all_pairs_between, assemble, contact_pass, fiber

ESTAR = 15e9 / (2 * (1 - 0.09))


def _force_on(f, rng):
    return f[rng[0]:rng[1]].sum(axis=0)


@pytest.mark.parametrize("delta", [2e-7, 1e-6, 5e-6])
@pytest.mark.parametrize("law", [L.HertzParallelLaw(), L.HertzOrientedLaw(blend_length_m=1e-3)], ids=["parallel", "oriented"])
def test_parallel_fibers_total_force_is_P_times_overlap(law, delta):
    xa = fiber([0, 0, 0], [1, 0, 0], 20)
    xb = fiber([0.13e-3, 0, 2 * R - delta], [1, 0, 0], 20)
    x, seg, rad, fib, rng = assemble(xa, xb)
    pairs = all_pairs_between(fib, 0, 1)
    f = np.zeros_like(x)
    e, nact, buf = contact_pass(x, seg, rad, pairs, len(pairs), law, f)
    p = L.hertz_parallel_line(delta, ESTAR, R, R)[0]
    ref = p * (20 * LE - 0.13e-3)
    fa = _force_on(f, rng[0])
    assert abs(-fa[2] / ref - 1) < 0.02  # tolerance < 2 %; measured 3e-4 (4 Gauss points per segment)
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * ref  # equal and opposite
    # the potential is e(δ) per length of overlap, so its gradient along the fibers is e(δ): the ends
    # push each other out of the overlap with the energy per length (the end weights' gradient)
    e_per_length = e / (20 * LE - 0.13e-3)
    assert abs(fa[0] / e_per_length + 1.0) < 0.02 and abs(fa[1]) < 1e-12 * ref


def test_no_contact_between_adjacent_elements_of_same_fiber():
    """A sharply kinked fiber: its own adjacent segments overlap geometrically but are excluded."""
    pts = np.array([[0, 0, 0], [LE, 0, 0], [LE * 0.2, 0.1e-3, 0], [LE, 0.2e-3, 0]])
    x, seg, rad, fib, rng = assemble(pts)
    # segments 0 and 2 are 0.2 mm apart (< 2r) but only 0.26 mm of arc apart (< s_excl = 2r)
    vl = VerletList(seg, rad, fib, segment_arclength(seg, fib, x), skin_m=0.1e-3)
    vl.build(x)
    f = np.zeros_like(x)
    e, nact, _ = contact_pass(x, seg, rad, vl.pairs, vl.n_pairs, L.HertzOrientedLaw(blend_length_m=1e-3), f)
    assert vl.n_pairs == 0 and nact == 0 and np.all(f == 0)


def test_parallel_sliding_across_joints_constant_force():
    """A 6-element fiber pressed on a long parallel neighbour slides by 8 element lengths:
    total normal force constant within 1 % (measured: 1.0e-4, 4 Gauss points per segment); unequal
    element lengths too."""
    law = L.HertzOrientedLaw(blend_length_m=1e-3)
    delta = 1e-6
    xb = fiber([0, 0, 0], [1, 0, 0], 20, le=LE * 0.87)
    forces = []
    for sh in np.linspace(0, 8 * LE, 161):
        xa = fiber([0.5e-3 + sh, 0, 2 * R - delta], [1, 0, 0], 6)
        x, seg, rad, fib, rng = assemble(xa, xb)
        pairs = all_pairs_between(fib, 0, 1)
        f = np.zeros_like(x)
        contact_pass(x, seg, rad, pairs, len(pairs), law, f)
        forces.append(_force_on(f, rng[0])[2])  # A lies above B: pushed up
    forces = np.array(forces)
    ref = L.hertz_parallel_line(delta, ESTAR, R, R)[0] * 6 * LE
    assert np.max(np.abs(forces / ref - 1)) < 0.01


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
