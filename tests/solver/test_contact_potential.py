"""The potential formulation of the normal contact (fiberpipe.solver.contact_potential): every force
is minus the gradient of the energy the kernel returns, for every law, at every crossing angle
(line part, angle blend, point part), across element joints and at free ends; and the onset map."""

import math

import numpy as np
import pytest
from numba import njit

from fiberpipe.solver.contact_pairs import gauss_points
from fiberpipe.solver.contact_potential import contact_forces_pot, onset
from fiberpipe.solver.contact_state import new_records
from fiberpipe.solver.laws import make_law

from _contact_geometry import central_gradient, pot_energy_forces as _energy_forces, two_fiber_segments

R = 0.25e-3


def _two_fibers(phi_deg, depth, n=3, L=0.9e-3, shift=0.0, bend=0.0, seed=0):
    """Fiber 0 along x (n segments), fiber 1 crossing it at phi_deg in the x–y plane, above it by
    2R − depth at the crossing, offset by ``shift`` along fiber 0; small random kinks (``bend``, m)."""
    rng = np.random.default_rng(seed)
    s = np.linspace(-0.5, 0.5, n + 1)
    a = np.c_[s * L, np.zeros_like(s), np.zeros_like(s)]
    ph = math.radians(phi_deg)
    b = np.c_[shift + s * L * math.cos(ph), s * L * math.sin(ph), np.full_like(s, 2 * R - depth)]
    x = np.vstack([a, b]) + bend * rng.standard_normal((2 * (n + 1), 3))
    return (x, *two_fiber_segments(n, L / n))


LAWS = {
    "hertz_oriented": dict(),
    "hertz_parallel": dict(),
    "linear": dict(stiffness=1e9),
    "hertz_crossed": dict(phi_deg=90.0),
    "scaled_stiffness": dict(preset="table1_phi6"),
}


@pytest.mark.parametrize("law_name", sorted(LAWS))
@pytest.mark.parametrize("phi_deg,depth,shift", [
    (0.0, 0.3e-6, 0.0),      # parallel: line part only, Gauss points across the joints
    (0.2, 1e-6, 0.11e-3),    # nearly parallel, line part
    (1.0, 1e-6, 0.05e-3),    # inside the blend (0.5°–1.5°): w' and (Π_point − Π_line) enter
    (3.0, 2e-6, 0.0),        # crossing on a joint: point part, joint share
    (30.0, 1e-6, 0.07e-3),   # point part, K(Φ) and dK/dΦ (hertz_oriented)
])
def test_force_is_minus_the_gradient_of_the_energy(law_name, phi_deg, depth, shift):
    _check_gradient(make_law(law_name, E_pa=15e9, nu=0.3, **LAWS[law_name]), phi_deg, depth, shift)


@pytest.mark.parametrize("law_name,kw", [
    ("hertz_oriented", {}), ("linear", {"stiffness": 1e9, "blend_length_m": 5e-5}),
    ("scaled_stiffness", {"preset": "table1_phi6", "blend_length_m": 5e-5}),
    ("hertz_crossed", {"phi_deg": 90.0, "blend_length_m": 1e-3})])
@pytest.mark.parametrize("phi_deg,depth,shift", [(1.0, 1e-6, 0.05e-3), (3.0, 2e-6, 0.0), (30.0, 1e-6, 0.07e-3)])
def test_force_is_minus_the_gradient_with_the_patch_criterion_and_unequal_radii(law_name, kw, phi_deg, depth,
                                                                                shift):
    """The patch criterion's share (its δ and Φ derivatives from the crossed-Hertz ellipse) and, for
    hertz_oriented, K(Φ) of fibers of unequal radii (the equivalent angle's derivative enters)."""
    radius = np.r_[np.full(3, R), np.full(3, 0.7 * R)]
    _check_gradient(make_law(law_name, E_pa=15e9, nu=0.3, **kw), phi_deg, depth, shift, radius=radius,
                    lift=-0.3 * R)


def _check_gradient(law, phi_deg, depth, shift, radius=None, lift=0.0):
    x, seg, pairs, L0 = _two_fibers(phi_deg, depth, shift=shift, bend=0.2e-6, seed=int(10 * phi_deg))
    x[4:, 2] += lift
    ds = 1e-7
    ef = lambda xx: _energy_forces(xx, seg, pairs, L0, law, ds, radius=radius)  # noqa: E731
    e, f, n_act = ef(x)
    assert n_act > 0 and e > 0, "not in contact: the case tests nothing"
    g = central_gradient(lambda xx: ef(xx)[0], x, 1e-9)  # below the onset length
    scale = np.abs(f).max()
    assert scale > 0
    err = np.abs(f + g).max() / scale
    assert err < 1e-4, (err, f, -g)
    # linear momentum: the forces sum to zero
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale


_BLEND_ON_KINK = pytest.mark.xfail(strict=True, reason=(
    "inside the angle blend each pair weighs its Gauss points by its own (1 − w(Φ)): where a kinked "
    "joint hands a Gauss point to the neighbouring segment, Φ and the weight change with the owner "
    "(a jump of ≈ 2 % of the contact energy at Φ = 1°, 2 µm kink)"))
_POINT = {"blend_length_m": 1e-3}  # the point law at 3° (the default ℓ_blend hands 3° to the line part)


@pytest.mark.parametrize("law_name,kw,phi_deg,kink", [
    ("hertz_oriented", _POINT, 3.0, 0.0), ("hertz_oriented", _POINT, 3.0, 2e-6),
    ("hertz_oriented", _POINT, 3.0, -2e-6), ("hertz_oriented", {}, 3.0, 2e-6),
    ("hertz_parallel", {}, 0.0, 0.0), ("hertz_parallel", {}, 0.0, 2e-6), ("hertz_parallel", {}, 0.0, -2e-6),
    ("hertz_parallel", {}, 0.3, 0.0), ("hertz_parallel", {}, 0.3, 2e-6), ("hertz_parallel", {}, 0.3, -2e-6),
    pytest.param("linear", {"stiffness": 1e9}, 1.0, 2e-6, marks=_BLEND_ON_KINK),
])
def test_energy_is_continuous_as_a_contact_slides_over_joints(law_name, kw, phi_deg, kink):
    """The pair potentials add up to one continuous function while a contact moves along fiber 0
    across its element joints, straight or kinked (convex, concave) by ``kink`` at its inner nodes:
    ownership is handed over where the distances are equal, nothing is counted twice or lost."""
    law = make_law(law_name, E_pa=15e9, nu=0.3, **kw)

    def largest_step(n):
        es = []
        for sh in np.linspace(-0.2e-3, 0.2e-3, n):
            x, seg, pairs, L0 = _two_fibers(phi_deg, 1e-6, shift=sh)
            x[1:3, 2] += kink
            es.append(_energy_forces(x, seg, pairs, L0, law, 1e-7)[0])
        es = np.array(es)
        assert es.max() > 0
        return np.abs(np.diff(es)).max() / es.max()

    # continuous: the largest change between neighbouring shifts halves with the shift step (a lost
    # or doubled Gauss point would leave a jump of O(1/n_gauss) of the energy at every resolution)
    coarse, fine = largest_step(201), largest_step(401)
    assert fine <= 0.6 * coarse + 1e-12, (coarse, fine)


def test_onset_map_starts_with_zero_force_and_slope():
    ds = 1e-7
    g0, gp0 = onset(0.0, ds)
    assert g0 == 0.0 and gp0 == 0.0
    # C¹ at δ_s: value δ_s/2 and slope 1 from both sides
    ga, gpa = onset(ds * (1 - 1e-9), ds)
    gb, gpb = onset(ds * (1 + 1e-9), ds)
    assert abs(ga - gb) < 1e-15 and abs(gpa - gpb) < 1e-8
    # g' is the derivative of g
    for d in (0.1 * ds, 0.5 * ds, 0.9 * ds, 2 * ds):
        hh = 1e-6 * ds
        num = (onset(d + hh, ds)[0] - onset(d - hh, ds)[0]) / (2 * hh)
        assert abs(num - onset(d, ds)[1]) < 1e-6


# A law with its own jitted kernels (as `laws.register_law` takes them): linear, with a point share
# that rises with Φ from 10° to 20° and a point stiffness that grows with Φ, so the kernel's
# central-difference derivatives of both enter the forces.
@njit(cache=False)
def _own_line(law_id, params, delta, r1, r2):
    return params[0] * delta, 0.5 * params[0] * delta * delta


@njit(cache=False)
def _own_point(law_id, params, delta, r1, r2, phi):
    k = params[0] * params[1] * (1.0 + phi)
    return k * delta, 0.5 * k * delta * delta


@njit(cache=False)
def _own_weight_point(law_id, params, delta, r1, r2, phi):
    u = min(max((phi - 0.1745) / 0.1745, 0.0), 1.0)
    f, e = _own_point(law_id, params, delta, r1, r2, phi)
    return u * u * (3.0 - 2.0 * u), f, e


class _OwnKernelsLaw:
    law_id = -1
    kernels = (_own_line, _own_point, _own_weight_point)

    def params(self):
        return np.array([1e9, 0.3e-3])


@pytest.mark.parametrize("phi_deg", [5.0, 15.0, 30.0])
def test_a_law_with_its_own_kernels_gets_minus_the_gradient(phi_deg):
    from fiberpipe.solver.contact_potential import potential_kernels_for

    law = _OwnKernelsLaw()
    kernel = potential_kernels_for(law)
    x, seg, pairs, arc = _two_fibers(phi_deg, 1e-6, shift=0.05e-3, bend=0.2e-6, seed=3)
    gxi, gw = gauss_points(2)

    def ef(xx):
        f = np.zeros_like(xx)
        e, n = kernel(xx, seg, np.full(seg.shape[0], R), arc, pairs, pairs.shape[0], law.law_id, law.params(),
                      gxi, gw, 0.0, f, new_records(pairs.shape[0]), np.zeros(0), 0.0)
        return e, f, n

    e, f, n_act = ef(x)
    assert n_act > 0 and e > 0
    g = central_gradient(lambda xx: ef(xx)[0], x, 1e-9)
    assert np.abs(f + g).max() < 1e-4 * np.abs(f).max()


def _parallel_pair(shift, n_a, le_a, n_b=20, le_b=0.3e-3, depth=0.3e-6, kink=0.0):
    """Fiber 0 (``n_b`` segments of ``le_b``) along x, fiber 1 (``n_a`` of ``le_a``) parallel above it at
    penetration ``depth``, starting at 1 mm + ``shift``; fiber 0's inner nodes lifted alternately by
    ±``kink``. Returns (x, seg, pairs, arc, nodes of fiber 1)."""
    xb = np.c_[np.arange(n_b + 1) * le_b, np.zeros(n_b + 1), np.zeros(n_b + 1)]
    xb[1:-1:2, 2] += kink
    xb[2:-1:2, 2] -= kink
    xa = np.c_[1e-3 + shift + np.arange(n_a + 1) * le_a, np.zeros(n_a + 1), np.full(n_a + 1, 2 * R - depth)]
    seg = np.array([[k, k + 1] for k in range(n_b)] + [[n_b + 1 + k, n_b + 2 + k] for k in range(n_a)], np.int64)
    pairs = np.array([[i, n_b + j] for i in range(n_b) for j in range(n_a)], np.int64)
    arc = np.zeros((n_b + n_a, 2))
    arc[:n_b, 1] = le_b
    arc[n_b:, 1] = le_a
    return np.vstack([xb, xa]), seg, pairs, arc, slice(n_b + 1, None)


@pytest.mark.parametrize("n_gauss,n_a,le_a,limit", [(2, 12, 0.25e-3, 5e-3), (2, 11, 0.27e-3, 5e-3),
                                                    (4, 12, 0.25e-3, 1e-3)])
def test_a_fiber_sliding_along_a_parallel_one_keeps_its_normal_force(n_gauss, n_a, le_a, limit):
    """A fiber sliding along a longer parallel one (other element lengths, 241 poses over two of its
    elements): the normal force stays within ``limit`` of Johnson's line load × the fiber's length.
    With each way's Gauss points fixed and no end weights the force read 0.9–2.5 % apart (1.6 % with
    4 points) as the other fiber's end passed them."""
    from fiberpipe.solver.laws import law_line

    law = make_law("hertz_parallel", E_pa=15e9, nu=0.3)
    depth = 0.3e-6
    forces = []
    for shift in np.linspace(0.0, 0.6e-3, 241):
        x, seg, pairs, arc, top = _parallel_pair(shift, n_a, le_a, depth=depth)
        forces.append(_energy_forces(x, seg, pairs, arc, law, n_gauss=n_gauss)[1][top, 2].sum())
    ref = law_line(law.law_id, law.params(), depth, R, R)[0] * n_a * le_a
    err = np.abs(np.array(forces) / ref - 1.0).max()
    assert err < limit, err


@pytest.mark.parametrize("n_a,le_a,shift,kink", [
    (3, 0.25e-3, 0.07e-3, 0.0),     # fiber 1's ends inside fiber 0's segments
    (3, 0.25e-3, 0.07e-3, 0.4e-6),  # ... fiber 0 kinked at every inner node
    (2, 0.25e-3, 0.21e-3, 0.4e-6),  # two segments: the first's neighbour is the last
    (1, 0.4e-3, 0.13e-3, 0.4e-6),   # one segment, free at both ends
    (4, 0.3e-3, 3.0e-3, 0.4e-6),    # fiber 1 beyond fiber 0's end (6 mm) by part of its length
])
def test_end_weights_forces_are_minus_the_gradient(n_a, le_a, shift, kink):
    """Where a fiber ends inside another's contact, each way's end weight ½(1 + a_A − a_B) and its
    gradient (the other fiber's end nearness at the Gauss point's projection, also read from the
    neighbouring segment at a kinked joint) enter the forces: forces = −∇Π by central differences."""
    law = make_law("hertz_parallel", E_pa=15e9, nu=0.3)
    x, seg, pairs, arc, _ = _parallel_pair(shift, n_a, le_a, depth=1e-6, kink=kink)
    rng = np.random.default_rng(n_a)
    x = x + 0.05e-6 * rng.standard_normal(x.shape)
    ef = lambda xx: _energy_forces(xx, seg, pairs, arc, law, 1e-7)  # noqa: E731
    e, f, n_act = ef(x)
    assert n_act > 0 and e > 0
    g = central_gradient(lambda xx: ef(xx)[0], x, 1e-9)
    scale = np.abs(f).max()
    assert np.abs(f + g).max() < 1e-4 * scale
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale


@pytest.mark.parametrize("kink", [0.0, 0.4e-6, -0.4e-6])
def test_energy_is_continuous_as_a_fiber_end_slides_along_another(kink):
    """The potential stays one continuous function while fiber 1's ends slide across fiber 0's joints
    and past fiber 0's end (straight or kinked): the largest step between neighbouring poses halves
    with the pose step."""
    law = make_law("hertz_parallel", E_pa=15e9, nu=0.3)

    def largest_step(n):
        es = np.array([_energy_forces(*_parallel_pair(sh, 3, 0.25e-3, kink=kink)[:4], law, 1e-7)[0]
                       for sh in np.linspace(4.5e-3, 5.3e-3, n)])
        assert es.max() > 0
        return np.abs(np.diff(es)).max() / es.max()

    coarse, fine = largest_step(201), largest_step(401)
    assert fine <= 0.6 * coarse + 1e-12, (coarse, fine)
