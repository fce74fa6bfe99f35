"""Numba kernels of the geometrically exact (Simo–Reissner) 2-node beam with one-point quadrature.

Formulation (Simo & Vu-Quoc, "A three-dimensional finite-strain rod model. Part II", CMAME 58,
1986; Crisfield & Jelenić, Proc. R. Soc. A 455, 1999, for the interpolation of rotations; the
reduced one-point rule is the B31 choice of Abaqus, "Beam element formulation", Abaqus Theory
Manual 3.5):

* every node carries a position ``x`` (m) and a rotation ``R`` stored as a unit quaternion
  ``q = (w, x, y, z)``, with the columns of ``R`` the material directors ``d1, d2, d3`` (``d3``
  along the fiber at rest);
* the element midpoint rotation is the geodesic mid-point ``R_m = R_1 exp(θ/2)``, where
  ``θ = log(R_1ᵀ R_2)`` is the relative rotation vector. For quaternions in the same hemisphere
  this is ``q_m = (q_1 + q_2)/|q_1 + q_2|``;
* strains at the single Gauss point (the midpoint), in the material frame:
  ``Γ = R_mᵀ (x_2 − x_1)/L_0 − Γ_rest`` (shear 1, shear 2, axial; Γ_rest includes ``e_3``) and
  ``κ = (θ − θ_rest)/L_0`` (bending 1, bending 2, torsion). θ is an eigenvector of
  ``exp(θ/2)``, so its components are the same in the node-1 and the midpoint frame.
  Subtracting the rest values ``Γ_rest`` and ``θ_rest`` of the traced geometry makes an
  initially curved fiber stress-free;
* stress resultants ``n = R_m C Γ`` with ``C = diag(k_s G A, k_s G A, E A)`` (Cowper's shear
  factor ``k_s = 6(1+ν)/(7+6ν)``) and ``m = R_m D κ`` with ``D = diag(E I, E I, G J)``;
* internal nodal forces and moments: the exact gradient of the element's strain energy
  ``W = ½ L_0 (Γ·CΓ + κ·Dκ)`` with respect to the node positions and the nodes' spins ``δφ_i``
  (``R_i ← exp(δφ_i) R_i``), so the semi-discrete rod is conservative at any rest curvature.
  With the variations ``δθ = J_r(θ)^{-1} (δψ_2 − exp(−θ) δψ_1)`` (body spins ``δψ_i = R_iᵀ δφ_i``)
  and ``δψ_m = a_1 + ½ (a_2 − a_1) − tan(|θ|/4)/(2|θ|) θ × (a_2 − a_1)`` (``a_i = R_mᵀ δφ_i``), and
  ``μ = (R_mᵀ (x_2 − x_1)) × C Γ`` the moment of the force about the element's middle: node 1 gets
  ``+n`` and ``+m + ½ (x_2 − x_1) × n``, node 2 ``−n`` and ``−m + ½ (x_2 − x_1) × n``, with
  ``m = R_m [(I + d θ×²) D κ − v × μ / (2 (1 + q_1·q_2))]`` (``v`` the vector part of
  ``conj(q_1) ⊗ q_2``, ``d = 1/|θ|² − 1/(2|θ| sin(|θ|/2))``; ``R_m (I + d θ×²) = R_2 J_r(θ)^{-T}``).
  The first-order pair (``m = R_m D κ``, midpoint spin ``(δφ_1 + δφ_2)/2``) dropped the two
  O(|θ|) terms; its tangent stiffness was unsymmetric by O(|θ|) × the shear stiffness, and a
  free fiber with ≈ 0.1–0.2 rad of rest rotation per element gained energy without bound (flutter).
  Elements with a straight rest shape (rest rotation ≤ ``EXACT_MIN_REST_ROTATION`` = 1e-3 rad)
  keep the first-order pair, which costs ≈ 6 ns per element less; their |θ| is the deformation's
  only (measured: moment error vs −∂W/∂φ 0.4 % at 0.05 rad per element).
* strain energy ``½ L_0 (Γ·CΓ + κ·Dκ)``.

All kernels take flat arrays only (structure of arrays by field, fibers joined in CSR order); the
element ``e`` joins nodes ``el_n1[e]`` and ``el_n1[e] + 1``. The step loops' beam pass
(:func:`beam_pass_nodes`) runs one branch-free loop over all nodes, the element parameters indexed
by the element's first node (:func:`node_beams`, zero where no element starts), and writes the
resultants by first node + 1 to nine arrays (:class:`~fiberpipe.solver.step_data.ElementForces`)
for the update to gather per node (no scatter): LLVM vectorises that loop (``_vectorise``). :func:`beam_resultants` is the per-element
form with the exact rotation logarithm and the stiffness-proportional damping, which the step loops
use for a step where an element rotates by more than 0.64 rad or β > 0.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._specialise import specialise
from .geometry import asin_tail
from .step_data import ElementForces


# rest rotation per element [rad] above which the element uses the exact conjugate moments: 1e-3 rad
# is 3.3 1/m of rest curvature at 0.3 mm elements (the shipped paper-40 fibers: ≈ 1e-4 rad; the wavy
# variant's 2 mm waves: up to 0.2 rad)
EXACT_MIN_REST_ROTATION = 1e-3
EXACT_MIN_REST_ROTATION2 = EXACT_MIN_REST_ROTATION**2


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _relative_rotation(w1, x1, y1, z1, w2, x2, y2, z2):
    """Relative quaternion ``conj(q1) ⊗ q2 = (rw, v)``, ``v = (rx, ry, rz)`` (q2 already in q1's
    hemisphere), the factor ``fac`` of ``θ = log(R_1ᵀ R_2) = fac · v`` (rad, node-1 frame) and the
    factor ``dd`` of the exact bending moment ``exp(θ/2) J_r(θ)^{-T} = I + dd · v×²``.

    With ``s = |v| = sin(|θ|/2)``: ``fac = 2 asin(s)/s`` and ``dd = (1 − fac/2)/s²`` (``= d fac²`` for
    ``d = 1/|θ|² − 1/(2 |θ| s)``, the θ×² coefficient; ``dd → −1/6`` as ``s → 0``).
    """
    rw = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
    rx = w1 * x2 - w2 * x1 - (y1 * z2 - z1 * y2)
    ry = w1 * y2 - w2 * y1 - (z1 * x2 - x1 * z2)
    rz = w1 * z2 - w2 * z1 - (x1 * y2 - y1 * x2)
    s2 = rx * rx + ry * ry + rz * rz
    if s2 < 1e-2:
        # asin(s)/s = 1 + s²/6 + 3s⁴/40 + 5s⁶/112 + 35s⁸/1152, relative error < 3e-12 at s = 0.1
        tail = 1.0 / 6.0 + s2 * (3.0 / 40.0 + s2 * (5.0 / 112.0 + s2 * (35.0 / 1152.0)))
        fac = 2.0 * (1.0 + s2 * tail)
        dd = -tail
    else:
        s = math.sqrt(s2)
        fac = 2.0 * math.atan2(s, rw) / s
        dd = (1.0 - 0.5 * fac) / s2
    return rw, rx, ry, rz, fac, dd


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _relative_rotation_vector(w1, x1, y1, z1, w2, x2, y2, z2):
    """Rotation vector ``log(R_1ᵀ R_2)`` (rad, in the node-1 frame); q2 already in q1's hemisphere."""
    rw, rx, ry, rz, fac, dd = _relative_rotation(w1, x1, y1, z1, w2, x2, y2, z2)
    return fac * rx, fac * ry, fac * rz


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _midpoint_matrix(w1, x1, y1, z1, w2, x2, y2, z2, dot):
    """Rotation matrix entries (row major) of the element midpoint rotation ``q_m ∝ q1 + q2``
    (unit q1, q2 in the same hemisphere, ``dot = q1·q2 ≥ 0``), then ``1/(1 + dot)``.

    ``R(q) = I + 2/|q|² (…)`` holds for any q ≠ 0 and ``|q1 + q2|² = 2 + 2 q1·q2``: no square root,
    one division.
    """
    mw = w1 + w2
    mx = x1 + x2
    my = y1 + y2
    mz = z1 + z2
    s2 = 2.0 / (2.0 + 2.0 * dot)
    xx = mx * mx * s2
    yy = my * my * s2
    zz = mz * mz * s2
    xy = mx * my * s2
    xz = mx * mz * s2
    yz = my * mz * s2
    wx = mw * mx * s2
    wy = mw * my * s2
    wz = mw * mz * s2
    return (
        1.0 - (yy + zz), xy - wz, xz + wy,
        xy + wz, 1.0 - (xx + zz), yz - wx,
        xz - wy, yz + wx, 1.0 - (xx + yy),
        s2,
    )


@njit(cache=True, fastmath=True, error_model="numpy")
def element_rest_strains(x, q, el_n1, el_invL0, gamma_rest, theta_rest):
    """Rest strains of every element.

    Parameters
    ----------
    x : (N, 3) float64, m — rest node positions.
    q : (N, 4) float64 — rest node quaternions.
    el_n1 : (E,) int64 — first node of each element.
    el_invL0 : (E,) float64, 1/m — inverse rest lengths.
    gamma_rest : (E, 3) float64 — out: ``R_mᵀ (x_2 − x_1)/L_0`` at rest (≈ e_3).
    theta_rest : (E, 3) float64, rad — out: rest relative rotation ``log(R_1ᵀ R_2)``.
    """
    for e in range(el_n1.shape[0]):
        a = el_n1[e]
        b = a + 1
        w1, x1, y1, z1 = q[a, 0], q[a, 1], q[a, 2], q[a, 3]
        w2, x2, y2, z2 = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        dot = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
        if dot < 0.0:
            w2, x2, y2, z2 = -w2, -x2, -y2, -z2
            dot = -dot
        tx, ty, tz = _relative_rotation_vector(w1, x1, y1, z1, w2, x2, y2, z2)
        theta_rest[e, 0] = tx
        theta_rest[e, 1] = ty
        theta_rest[e, 2] = tz
        # the same formula as the step loop's (the rest state's strain is rounding only)
        r00, r01, r02, r10, r11, r12, r20, r21, r22, inv1p = _midpoint_matrix(w1, x1, y1, z1, w2, x2, y2, z2, dot)
        il = el_invL0[e]
        dx = (x[b, 0] - x[a, 0]) * il
        dy = (x[b, 1] - x[a, 1]) * il
        dz = (x[b, 2] - x[a, 2]) * il
        gamma_rest[e, 0] = r00 * dx + r10 * dy + r20 * dz
        gamma_rest[e, 1] = r01 * dx + r11 * dy + r21 * dz
        gamma_rest[e, 2] = r02 * dx + r12 * dy + r22 * dz


# element resultant buffer (``eb``, (E, 9)): columns 0–2 the spatial force n, 3–5 the moment m,
# 6–8 the lever term h = ½ (x_2 − x_1) × n; node 1 gets (+n, m + h), node 2 (−n, h − m)
EB_SIZE = 9


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _resultants_range(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, eb,
                      record, beta_over_dt, strain_prev, e_lo, e_hi):
    """Stress resultants of the elements ``e_lo … e_hi − 1`` into ``eb`` (returns their two energies)."""
    # Strategy: no scatter. Each element writes only its own row of ``eb``; the nodes gather
    # their two elements' rows afterwards (gather_resultants, or the step loop's update).
    # Without the read-modify-write of shared nodes the element loop has no dependence between
    # iterations, and the per-fiber prange variant needs no care about races.
    se = 0.0
    pd = 0.0
    use_beta = beta_over_dt > 0.0
    for e in range(e_lo, e_hi):
        a = el_n1[e]
        b = a + 1
        w1, x1, y1, z1 = q[a, 0], q[a, 1], q[a, 2], q[a, 3]
        w2, x2, y2, z2 = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        dot = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
        if dot < 0.0:
            w2, x2, y2, z2 = -w2, -x2, -y2, -z2
            dot = -dot
        rw, rx, ry, rz, fac, dd = _relative_rotation(w1, x1, y1, z1, w2, x2, y2, z2)
        tx = fac * rx
        ty = fac * ry
        tz = fac * rz
        r00, r01, r02, r10, r11, r12, r20, r21, r22, inv1p = _midpoint_matrix(w1, x1, y1, z1, w2, x2, y2, z2, dot)
        ex = x[b, 0] - x[a, 0]
        ey = x[b, 1] - x[a, 1]
        ez = x[b, 2] - x[a, 2]
        il = el_invL0[e]
        # chord in the midpoint material frame, strains
        bx = r00 * ex + r10 * ey + r20 * ez
        by = r01 * ex + r11 * ey + r21 * ez
        bz = r02 * ex + r12 * ey + r22 * ez
        g0 = bx * il - gamma_rest[e, 0]
        g1 = by * il - gamma_rest[e, 1]
        g2 = bz * il - gamma_rest[e, 2]
        k0 = tx - theta_rest[e, 0]
        k1 = ty - theta_rest[e, 1]
        k2 = tz - theta_rest[e, 2]
        c0 = el_C[e, 0]
        c1 = el_C[e, 1]
        c2 = el_C[e, 2]
        d0 = el_Dk[e, 0]
        d1 = el_Dk[e, 1]
        d2 = el_Dk[e, 2]
        nb0 = c0 * g0
        nb1 = c1 * g1
        nb2 = c2 * g2
        mb0 = d0 * k0
        mb1 = d1 * k1
        mb2 = d2 * k2
        if record:
            se += 0.5 * ((nb0 * g0 + nb1 * g1 + nb2 * g2) / il + mb0 * k0 + mb1 * k1 + mb2 * k2)
        if use_beta:
            dg0 = g0 - strain_prev[e, 0]
            dg1 = g1 - strain_prev[e, 1]
            dg2 = g2 - strain_prev[e, 2]
            dk0 = k0 - strain_prev[e, 3]
            dk1 = k1 - strain_prev[e, 4]
            dk2 = k2 - strain_prev[e, 5]
            strain_prev[e, 0] = g0
            strain_prev[e, 1] = g1
            strain_prev[e, 2] = g2
            strain_prev[e, 3] = k0
            strain_prev[e, 4] = k1
            strain_prev[e, 5] = k2
            sn0 = beta_over_dt * c0 * dg0
            sn1 = beta_over_dt * c1 * dg1
            sn2 = beta_over_dt * c2 * dg2
            sm0 = beta_over_dt * d0 * dk0
            sm1 = beta_over_dt * d1 * dk1
            sm2 = beta_over_dt * d2 * dk2
            # energy dissipated this step: damping stress · Δstrain · L0
            pd += ((sn0 * dg0 + sn1 * dg1 + sn2 * dg2) / il + sm0 * dk0 + sm1 * dk1 + sm2 * dk2)
            nb0 += sn0
            nb1 += sn1
            nb2 += sn2
            mb0 += sm0
            mb1 += sm1
            mb2 += sm2
        # spatial resultants
        n0 = r00 * nb0 + r01 * nb1 + r02 * nb2
        n1 = r10 * nb0 + r11 * nb1 + r12 * nb2
        n2 = r20 * nb0 + r21 * nb1 + r22 * nb2
        eb[e, 0] = n0
        eb[e, 1] = n1
        eb[e, 2] = n2
        # exact conjugate moments (module docstring, "internal nodal forces"), in the midpoint frame:
        # mm = mb + dd v × (v × mb) − v × μ / (2 (1 + rw)), μ = (R_mᵀ e) × nb the moment of the force;
        # for elements whose rest shape is curved (|θ_rest| > EXACT_MIN_REST_ROTATION). Straight ones
        # keep the first-order pair mm = mb (the O(|θ|) terms cost ≈ 6 ns per element, +34 % on the
        # beam pass, and with a straight rest shape |θ| stays that of the deformation: quasi-static
        # compactions, α = 1e5, are not affected; tests/solver/test_beam_conservation.py)
        mm0 = mb0
        mm1 = mb1
        mm2 = mb2
        tr0 = theta_rest[e, 0]
        tr1 = theta_rest[e, 1]
        tr2 = theta_rest[e, 2]
        if tr0 * tr0 + tr1 * tr1 + tr2 * tr2 > EXACT_MIN_REST_ROTATION2:
            c0 = ry * mb2 - rz * mb1
            c1 = rz * mb0 - rx * mb2
            c2 = rx * mb1 - ry * mb0
            hw = 0.5 * inv1p  # 1/(2 (1 + rw)), rw = q1·q2
            u0 = dd * c0 - hw * (by * nb2 - bz * nb1)
            u1 = dd * c1 - hw * (bz * nb0 - bx * nb2)
            u2 = dd * c2 - hw * (bx * nb1 - by * nb0)
            mm0 = mb0 + (ry * u2 - rz * u1)
            mm1 = mb1 + (rz * u0 - rx * u2)
            mm2 = mb2 + (rx * u1 - ry * u0)
        eb[e, 3] = r00 * mm0 + r01 * mm1 + r02 * mm2
        eb[e, 4] = r10 * mm0 + r11 * mm1 + r12 * mm2
        eb[e, 5] = r20 * mm0 + r21 * mm1 + r22 * mm2
        # ½ (x2 − x1) × n
        eb[e, 6] = 0.5 * (ey * n2 - ez * n1)
        eb[e, 7] = 0.5 * (ez * n0 - ex * n2)
        eb[e, 8] = 0.5 * (ex * n1 - ey * n0)
    return se, pd


@njit(cache=True, fastmath=True, error_model="numpy")
def beam_resultants(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, eb,
                    record, beta_over_dt, strain_prev, node_offsets):
    """Stress resultants of all elements into ``eb`` (the serial beam pass of the step loops).

    Parameters
    ----------
    x : (N, 3) float64, m — node positions.
    q : (N, 4) float64 — node quaternions (unit).
    el_n1 : (E,) int64 — first node of each element (second is ``el_n1 + 1``).
    el_invL0 : (E,) float64, 1/m — inverse rest lengths.
    el_C : (E, 3) float64, N — ``(k_s G A, k_s G A, E A)``.
    el_Dk : (E, 3) float64, N·m/rad — ``(E I, E I, G J) / L_0``.
    gamma_rest, theta_rest : (E, 3) float64 — rest strains (see :func:`element_rest_strains`).
    eb : (E, 9) float64 — out: per element the spatial force ``n`` (N), moment ``m`` (N·m) and
        ``h = ½ (x_2 − x_1) × n`` (N·m); node 1 of the element gets ``(+n, m + h)``, node 2
        ``(−n, h − m)`` (:func:`gather_resultants`).
    record : bool — return the strain energy (J) if true (else 0).
    beta_over_dt : float, 1 — stiffness-proportional damping β/Δt (0: off).
    strain_prev : (E, 6) float64 — previous ``(Γ, θ)`` per element (only read/written if
        ``beta_over_dt > 0``); the damping stress is ``β C Γ̇`` and ``β D κ̇`` (backward difference).
    node_offsets : (F+1,) int64 — unused here.

    Returns
    -------
    (strain_energy_J, damping_energy_J) : the stored energy if ``record``; the energy dissipated
    in this step by the stiffness-proportional damping stress (0 if off).
    """
    return _resultants_range(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, eb,
                             record, beta_over_dt, strain_prev, 0, el_n1.shape[0])


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def node_resultant(eb, node_offsets_k, node_end_k, k, i):
    """Force and moment (6 scalars) of the beam elements on node ``i`` of fiber ``k``, whose nodes
    are ``node_offsets_k … node_end_k − 1``: ``(+n, m + h)`` of the element starting at ``i``,
    ``(−n, h − m)`` of the element ending there."""
    fx = 0.0
    fy = 0.0
    fz = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    if i < node_end_k - 1:
        e = i - k
        fx = eb[e, 0]
        fy = eb[e, 1]
        fz = eb[e, 2]
        mx = eb[e, 3] + eb[e, 6]
        my = eb[e, 4] + eb[e, 7]
        mz = eb[e, 5] + eb[e, 8]
    if i > node_offsets_k:
        e = i - k - 1
        fx -= eb[e, 0]
        fy -= eb[e, 1]
        fz -= eb[e, 2]
        mx += eb[e, 6] - eb[e, 3]
        my += eb[e, 7] - eb[e, 4]
        mz += eb[e, 8] - eb[e, 5]
    return fx, fy, fz, mx, my, mz


@njit(cache=True, fastmath=True, error_model="numpy")
def gather_resultants(eb, node_offsets, f, mom):
    """Add the element resultants ``eb`` of :func:`beam_resultants` to the nodes' ``f`` and ``mom``."""
    for k in range(node_offsets.shape[0] - 1):
        lo = node_offsets[k]
        hi = node_offsets[k + 1]
        for i in range(lo, hi):
            fx, fy, fz, mx, my, mz = node_resultant(eb, lo, hi, k, i)
            f[i, 0] += fx
            f[i, 1] += fy
            f[i, 2] += fz
            mom[i, 0] += mx
            mom[i, 1] += my
            mom[i, 2] += mz


@njit(cache=True, fastmath=True, error_model="numpy")
def beam_forces(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, f, mom,
                record, beta_over_dt, strain_prev):
    """Add the internal forces and moments of all elements to ``f`` (N) and ``mom`` (N·m, spatial).

    Same parameters and returns as :func:`beam_resultants` (``f``, ``mom``: (N, 3), accumulated
    into, instead of ``eb``). For analyses and tests; the step loops gather ``eb`` in their update.
    """
    E = el_n1.shape[0]
    eb = np.empty((E, EB_SIZE))
    se, pd = _resultants_range(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, eb,
                               record, beta_over_dt, strain_prev, 0, E)
    # nodes of each element to the nodes' accumulators (any element order)
    for e in range(E):
        a = el_n1[e]
        b = a + 1
        for c in range(3):
            f[a, c] += eb[e, c]
            f[b, c] -= eb[e, c]
            mom[a, c] += eb[e, 3 + c] + eb[e, 6 + c]
            mom[b, c] += eb[e, 6 + c] - eb[e, 3 + c]
    return se, pd


# |v|² = sin²(|θ|/2) of an element's relative rotation (rest rotation included) below which the
# node-wise pass's series of asin(s)/s holds: |θ| < 0.64 rad between two nodes (a 0.3 mm element on a
# 0.5 mm radius of curvature); a step with a larger one takes the exact per-element pass
SERIES_MAX_S2 = 0.1


def node_beams(el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, n_nodes: int) -> np.ndarray:
    """The element parameters indexed by their first node, (14, N), 0 where no element starts (a fiber's
    last node): rows L0 [m], 1/L0 [1/m], C (3) [N], D/L0 (3) [N·m/rad], Γ_rest (3), θ_rest (3) [rad]."""
    out = np.zeros((14, n_nodes))
    out[0, el_n1] = 1.0 / np.asarray(el_invL0, dtype=float)
    out[1, el_n1] = el_invL0
    for c in range(3):
        out[2 + c, el_n1] = el_C[:, c]
        out[5 + c, el_n1] = el_Dk[:, c]
        out[8 + c, el_n1] = gamma_rest[:, c]
        out[11 + c, el_n1] = theta_rest[:, c]
    return out


def new_element_forces(n_nodes: int) -> ElementForces:
    """The beam pass's output (:class:`~fiberpipe.solver.step_data.ElementForces`), zeroed."""
    return ElementForces(*(np.zeros(n_nodes + 1) for _ in range(EB_SIZE)))


@njit(cache=True, fastmath=True, error_model="numpy")
def beam_pass_nodes(x, q, beams, ef, lo, hi):
    """Resultants of the elements starting at nodes ``lo … hi − 1`` into ``ef`` (:class:`ElementForces`,
    entry ``a + 1``), from the element parameters ``beams`` (:func:`node_beams`).

    The formulas of :func:`beam_resultants` (module docstring) without the stiffness-proportional
    damping, in one loop without branches: the hemisphere of q2 by its sign, ``fac = 2 asin(s)/s`` by
    its series (:func:`fiberpipe.solver.geometry.asin_tail`), the exact conjugate moments of curved elements by a select. Returns ``(strain energy
    [J], elements whose |v|² ≥ SERIES_MAX_S2)``: the caller recomputes a step with any of the latter by
    the exact pass. Where no element starts (``invL0 = 0``) every parameter is 0 and so is the row.
    """
    # Strategy: the state read through flat views (constant offsets 3a + c, 4a + c) and one write array
    # per resultant component, so that LLVM's vectoriser sees affine accesses at known distances and
    # distinct write targets it can check once per call for overlap; one loop over all
    # nodes instead of the per-fiber loops of beam_resultants (a fiber's last node simply has zero
    # parameters), because the vector loop's run-time overlap checks cost too much per fiber.
    # The views start at node lo and the loop counts from 0: an index the compiler knows is ≥ 0 needs
    # no negative-index wrap-around, which would make the accesses non-affine and the loop scalar.
    xs = x.reshape(-1)[3 * lo:]
    qs = q.reshape(-1)[4 * lo:]
    n0, n1, n2, m0, m1, m2, h0, h1, h2 = ef
    n0, n1, n2, m0, m1, m2 = n0[lo:], n1[lo:], n2[lo:], m0[lo:], m1[lo:], m2[lo:]
    h0, h1, h2 = h0[lo:], h1[lo:], h2[lo:]
    P = beams
    L0, IL, C0, C1, C2, D0, D1, D2 = P[0, lo:], P[1, lo:], P[2, lo:], P[3, lo:], P[4, lo:], P[5, lo:], P[6, lo:], P[7, lo:]
    G0, G1, G2, T0, T1, T2 = P[8, lo:], P[9, lo:], P[10, lo:], P[11, lo:], P[12, lo:], P[13, lo:]
    se = 0.0
    n_large = 0
    for a in range(hi - lo):
        b = a + 1
        w1 = qs[4 * a]
        x1 = qs[4 * a + 1]
        y1 = qs[4 * a + 2]
        z1 = qs[4 * a + 3]
        sg = 1.0 if w1 * qs[4 * b] + x1 * qs[4 * b + 1] + y1 * qs[4 * b + 2] + z1 * qs[4 * b + 3] >= 0.0 else -1.0
        w2 = sg * qs[4 * b]
        x2 = sg * qs[4 * b + 1]
        y2 = sg * qs[4 * b + 2]
        z2 = sg * qs[4 * b + 3]
        dot = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
        rx = w1 * x2 - w2 * x1 - (y1 * z2 - z1 * y2)
        ry = w1 * y2 - w2 * y1 - (z1 * x2 - x1 * z2)
        rz = w1 * z2 - w2 * z1 - (x1 * y2 - y1 * x2)
        s2 = rx * rx + ry * ry + rz * rz
        il = IL[a]
        n_large += 1 if (s2 >= SERIES_MAX_S2) & (il > 0.0) else 0  # & not and: a select, no branch
        tail = asin_tail(s2)
        fac = 2.0 * (1.0 + s2 * tail)
        r00, r01, r02, r10, r11, r12, r20, r21, r22, inv1p = _midpoint_matrix(w1, x1, y1, z1, w2, x2, y2, z2, dot)
        ex = xs[3 * b] - xs[3 * a]
        ey = xs[3 * b + 1] - xs[3 * a + 1]
        ez = xs[3 * b + 2] - xs[3 * a + 2]
        bx = r00 * ex + r10 * ey + r20 * ez
        by = r01 * ex + r11 * ey + r21 * ez
        bz = r02 * ex + r12 * ey + r22 * ez
        g0 = bx * il - G0[a]
        g1 = by * il - G1[a]
        g2 = bz * il - G2[a]
        tr0 = T0[a]
        tr1 = T1[a]
        tr2 = T2[a]
        k0 = fac * rx - tr0
        k1 = fac * ry - tr1
        k2 = fac * rz - tr2
        nb0 = C0[a] * g0
        nb1 = C1[a] * g1
        nb2 = C2[a] * g2
        mb0 = D0[a] * k0
        mb1 = D1[a] * k1
        mb2 = D2[a] * k2
        se += 0.5 * ((nb0 * g0 + nb1 * g1 + nb2 * g2) * L0[a] + mb0 * k0 + mb1 * k1 + mb2 * k2)
        f0 = r00 * nb0 + r01 * nb1 + r02 * nb2
        f1 = r10 * nb0 + r11 * nb1 + r12 * nb2
        f2 = r20 * nb0 + r21 * nb1 + r22 * nb2
        # the exact conjugate moments of a curved element (beam_resultants), dd = −tail
        c0 = ry * mb2 - rz * mb1
        c1 = rz * mb0 - rx * mb2
        c2 = rx * mb1 - ry * mb0
        hw = 0.5 * inv1p
        u0 = -tail * c0 - hw * (by * nb2 - bz * nb1)
        u1 = -tail * c1 - hw * (bz * nb0 - bx * nb2)
        u2 = -tail * c2 - hw * (bx * nb1 - by * nb0)
        curved = tr0 * tr0 + tr1 * tr1 + tr2 * tr2 > EXACT_MIN_REST_ROTATION2
        mm0 = mb0 + (ry * u2 - rz * u1) if curved else mb0
        mm1 = mb1 + (rz * u0 - rx * u2) if curved else mb1
        mm2 = mb2 + (rx * u1 - ry * u0) if curved else mb2
        n0[b] = f0
        n1[b] = f1
        n2[b] = f2
        m0[b] = r00 * mm0 + r01 * mm1 + r02 * mm2
        m1[b] = r10 * mm0 + r11 * mm1 + r12 * mm2
        m2[b] = r20 * mm0 + r21 * mm1 + r22 * mm2
        h0[b] = 0.5 * (ey * f2 - ez * f1)
        h1[b] = 0.5 * (ez * f0 - ex * f2)
        h2[b] = 0.5 * (ex * f1 - ey * f0)
    return se, n_large


@njit(cache=True, fastmath=True, error_model="numpy")
def element_forces_exact(x, q, model, work, record, beta_over_dt):
    """The exact per-element pass (:func:`beam_resultants`: rotation logarithm by ``atan2``,
    stiffness-proportional damping with ``work.strain_prev``) into ``work.ef``, through the scratch
    ``work.eb`` (E, 9); returns its two energies."""
    se, pd = _resultants_range(x, q, model.el_n1, model.el_invL0, model.el_C, model.el_Dk, model.gamma_rest,
                               model.theta_rest, work.eb, record, beta_over_dt, work.strain_prev, 0,
                               model.el_n1.shape[0])
    scatter_element_forces(model.el_n1, work.eb, work.ef)
    return se, pd


@njit(cache=True, fastmath=True, error_model="numpy")
def scatter_element_forces(el_n1, eb, ef):
    """Copy the (E, 9) rows of :func:`beam_resultants` to :class:`ElementForces` (entry first node + 1)."""
    for e in range(el_n1.shape[0]):
        b = el_n1[e] + 1
        for c in range(EB_SIZE):
            ef[c][b] = eb[e, c]


def _beam_pass_nodes(x, q, model, work):
    """:func:`beam_pass_nodes` over every element: one call in the serial copy (``beam_pass_all``),
    ``PARALLEL_CHUNKS`` ``prange`` tasks of contiguous nodes in the parallel one (``beam_pass_fibers``,
    ``solver.threads`` > 1; the same formulas per element, the energy summed per task, then in order). Returns ``(strain energy [J],
    elements beyond the series)``."""
    offs = model.node_offsets
    nf = offs.shape[0] - 1
    if not _PARALLEL:
        return beam_pass_nodes(x, q, model.beams, work.ef, 0, offs[nf] - 1)
    # a parallel loop takes a tuple built in this function, not one nested in another structure
    n0, n1, n2, m0, m1, m2, h0, h1, h2 = work.ef
    ef = (n0, n1, n2, m0, m1, m2, h0, h1, h2)
    beams = model.beams
    # contiguous node ranges, not fibers: each task's vector loop runs long (its overlap checks once)
    n_el = offs[nf] - 1
    nch = PARALLEL_CHUNKS
    sums = work.task_sums
    for k in prange(nch):
        se_k, nl_k = beam_pass_nodes(x, q, beams, ef, k * n_el // nch, (k + 1) * n_el // nch)
        sums[k, 0] = se_k
        sums[k, 1] = nl_k
    se = 0.0
    n_large = 0
    for k in range(nch):
        se += sums[k, 0]
        n_large += int(sums[k, 1])
    return se, n_large


# tasks of the parallel node-wise passes (solver.threads > 1): contiguous node ranges. Few and long:
# each task's vector loop pays its run-time overlap checks once; on 2 cores the 8000-element beam
# pass takes 70, 67, 78 and 84 µs with 2, 4, 16 and 64 tasks (serial: 110 µs)
PARALLEL_CHUNKS = 4
_PARALLEL = False
# Both copies run without reference counts (``_nrt=False``, inherited by beam_pass_nodes; the per-task
# sums go to ``work.task_sums``): numba takes and releases a reference, an atomic count, for each view
# it makes of the state and of model.beams (≈ 46 a step on paper-40), and in the parallel copy both
# cores count on the same arrays' records, whose cache lines then travel between them (paper-40's
# pass on 2 threads: 11.0 µs with the counts, 9.0 without, 12.7 serial)
beam_pass_all = njit(cache=True, fastmath=True, error_model="numpy", _nrt=False)(_beam_pass_nodes)
# Not cached on its own: a parallel (parfor) kernel loaded from numba's disk cache and linked into a
# step loop compiled in another process makes that loop's own cache entry crash when it is loaded
# (numba 0.68; reproduced: cache a prange beam kernel in process 1, compile the contact loop in 2,
# load it in 3 -> SIGSEGV). The solver.threads > 1 loops that use it are cached whole (compiled
# with it in one process, loaded as one library; tests/solver/test_jitcache.py).
beam_pass_fibers = specialise(_beam_pass_nodes, "beam_pass_fibers", {"_PARALLEL": True}, cache=False,
                              fastmath=True, error_model="numpy", parallel=True, _nrt=False)
