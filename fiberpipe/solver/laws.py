"""Normal contact laws between beams: linear, the study's scaled stiffness, and Hertz (line, crossed, oriented).

Every law exists twice:

* a small Python class holding the parameters in SI units (names carry the unit), checking them and
  offering vectorised ``line_force`` / ``point_force`` helpers for tests and plots;
* a numba kernel form, usable inside a jitted step loop: an integer ``law_id`` plus one float64
  parameter array ``params`` (:meth:`ContactLaw.params`), evaluated by :func:`law_line`,
  :func:`law_point` and :func:`law_weight`.

Two evaluations per law (see ``docs/contact.md``):

``law_line(law_id, params, δ, r1, r2) -> (p, e)``
    distributed line load ``p`` [N/m] and stored energy per unit length ``e`` [J/m] at a local
    penetration ``δ`` [m]. Used by the line-to-line (Gauss point) part of the contact kernel.
``law_point(law_id, params, δ, r1, r2, Φ) -> (F, e)``
    point force ``F`` [N] and stored energy ``e`` [J] at the closest point of two crossing
    segments, relative orientation ``Φ`` [rad] in [0, π/2].
``law_weight(law_id, params, δ, r1, r2, Φ) -> w``
    share ``w`` in [0, 1] of the point evaluation; the distributed part gets ``1 − w``.

Laws that are natively *per contact* (a force ``F(δ)`` [N], as in Abaqus' pressure-overclosure
tables) give a line load ``F(δ)/ℓ_ref`` in the distributed part, ``ℓ_ref`` [m] being the length
one contact stands for (default 0.3 mm, the study's element length); laws natively *per unit length*
give a point force ``p(δ)·ℓ_ref``. For these generic laws the point share is
``w = smoothstep((Φ − Φ_lo)/(Φ_hi − Φ_lo))`` (defaults 0.5° and 1.5°), because a closest point is
ill-posed for (nearly) parallel segments.

Sources
-------
* Johnson, K. L., *Contact Mechanics*, Cambridge University Press, 1985: §4.2 (relative curvatures
  of two bodies), §3.5 eqs. 3.60–3.64 (elliptical Hertz contact), §5.6 / pp. 99–104 (approach of two
  parallel cylinders in line contact).
* Ben Othmen et al., Applied Composite Materials 2023 (doi 10.1007/s10443-023-10105-z; "the study"):
  §3.2, Eq. 1 ``K_i = S0·K_def·S^(i−1)`` for ``δ ∈ [(i−1)d, id]``, Tables 1 and 3.
* Meier, Popp & Wall, CMAME 308 (2016) and the "ABC" all-angle contact (CMAME 2017): point
  contact above a crossing angle, line contact below, smooth blend in between.

Units: SI throughout (m, N, Pa). ``E_star = [(1−ν1²)/E1 + (1−ν2²)/E2]^−1``; one material for the
whole scene (identical fibers: ``E_star = E/(2(1−ν²))``, 8.24 GPa for E = 15 GPa, ν = 0.3).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit

from fiberpipe.errors import ConfigError

# ---------------------------------------------------------------------------------------------
# law ids and parameter layout (kernel encoding)
# ---------------------------------------------------------------------------------------------
LAW_LINEAR = 0
LAW_SCALED = 1
LAW_HERTZ_PARALLEL = 2
LAW_HERTZ_CROSSED = 3
LAW_HERTZ_ORIENTED = 4

P_ESTAR = 0  # Pa, contact modulus E*
P_LREF = 1  # m, length one point contact stands for
P_PHI_LO = 2  # rad, generic blend: below, distributed only
P_PHI_HI = 3  # rad, generic blend: above, point only
P_PER_LENGTH = 4  # 1.0: native law is per unit length (N/m); 0.0: per contact (N)
P_K = 5  # linear stiffness, N/m² (per length) or N/m (per contact)
P_D = 6  # m, scaled stiffness interpolation step d
P_S = 7  # scaled stiffness growth factor S
P_S0 = 8  # scaled stiffness initial factor S0
P_KDEF = 9  # scaled stiffness K_def (N/m² per length, N/m per contact)
P_NSEG = 10  # number of segments n, last slope continues beyond n·d
P_PHI_FIXED = 11  # rad, hertz_crossed: the model-wide crossing angle
P_LBLEND = 12  # m, hertz_oriented: straight length available to the contact ellipse
P_XI_LO = 13  # hertz_oriented: a/ℓ_blend below which the point law is used alone
P_XI_HI = 14  # hertz_oriented: a/ℓ_blend above which the line law is used alone
P_NTAB = 15  # number of table entries
P_LNPHI0 = 16  # ln(Φ0 / rad) of the first table entry
P_DLNPHI = 17  # table step in ln Φ
N_HEADER = 18  # table: k̂ (NTAB values), then â (NTAB values), on the grid uniform in ln Φ

DEG = math.pi / 180.0

# ---------------------------------------------------------------------------------------------
# exact elliptical Hertz contact of crossed cylinders (Johnson 1985, eqs. 3.60–3.64)
# ---------------------------------------------------------------------------------------------


def hertz_crossed_exact(phi_rad: float) -> tuple[float, float, float]:
    """Exact elliptical Hertz solution for two crossed cylinders of equal radius, dimensionless.

    Relative curvatures (Johnson §4.2): ``A = sin²(Φ/2)/R``, ``B = cos²(Φ/2)/R`` (``A + B = 1/R``).
    With the contact ellipse semi-axes ``a ≥ b`` (``a`` along the direction of the smaller
    curvature ``A``), eccentricity ``e² = 1 − b²/a²``, and complete elliptic integrals ``K(e)``,
    ``E(e)`` (scipy parameter ``m = e²``), Johnson eq. 3.64 gives ``e`` from

        B/A = [E(e)/(1 − e²) − K(e)] / [K(e) − E(e)],

    and eqs. 3.60–3.62 (``p0`` peak pressure): ``A = p0 b [K − E]/(E* a² e²)``,
    ``δ = p0 b K(e)/E*``, ``F = (2/3)π a b p0``. Everything scales with ``a``, so ``F = K δ^{3/2}``.

    Returns ``(k_hat, a_hat, b_over_a)`` with ``K = k_hat·E*·√R`` (N/m^1.5) and the semi-major axis
    ``a = a_hat·√(R δ)``; at Φ = 90° ``k_hat = 4/3`` (sphere on flat of radius R) and ``a_hat = 1``.
    Here ``R`` stands for ``1/(A + B)``; for unequal radii use Φ_eq (see :func:`equivalent_angle`).
    """
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipkm1

    R = 1.0
    A = math.sin(phi_rad / 2.0) ** 2 / R
    B = math.cos(phi_rad / 2.0) ** 2 / R
    if A <= 0.0:
        raise ValueError("Φ must be > 0 for the crossed-cylinder solution")
    ratio = B / A
    if abs(ratio - 1.0) < 1e-13:
        return 4.0 / 3.0, 1.0, 1.0

    def g(lm1):  # ln m1, m1 = 1 − e² = (b/a)²
        m1 = math.exp(lm1)
        K = float(ellipkm1(m1))
        E = float(ellipe(1.0 - m1))
        return math.log((E / m1 - K) / (K - E)) - math.log(ratio)

    lm1 = brentq(g, -80.0, -1e-14, xtol=1e-15, rtol=1e-15, maxiter=500)
    m1 = math.exp(lm1)
    m = 1.0 - m1
    K = float(ellipkm1(m1))
    E = float(ellipe(m))
    a = 1.0
    b = math.sqrt(m1)
    p0 = A * a * a * m / (b * (K - E))  # with E* = 1
    delta = p0 * b * K
    F = 2.0 / 3.0 * math.pi * a * b * p0
    return F / delta**1.5, a / math.sqrt(R * delta), b / a


@lru_cache(maxsize=8)
def crossed_table(n: int = 512, phi_min_deg: float = 0.01) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Tabulate ``k̂`` and ``â`` of :func:`hertz_crossed_exact` on a grid uniform in ln Φ.

    Grid: ``n`` points from ``phi_min_deg`` to 90° (inclusive). Returns
    ``(ln Φ0, Δ ln Φ, khat[n], ahat[n])``. The kernels interpolate the values linearly in ln Φ
    (:func:`_table_lookup_d`): within 5.6e-5 of the exact solution between grid points (1e-4 tested).
    """
    l0 = math.log(phi_min_deg * DEG)
    l1 = math.log(90.0 * DEG)
    dl = (l1 - l0) / (n - 1)
    khat = np.empty(n)
    ahat = np.empty(n)
    for i in range(n):
        phi = math.exp(l0 + i * dl) if i < n - 1 else 90.0 * DEG
        khat[i], ahat[i], _ = hertz_crossed_exact(phi)
    return l0, dl, khat, ahat


def equivalent_angle(phi_rad, r1, r2):
    """Φ_eq of two crossed cylinders of radii r1, r2 at angle Φ: the equal-radius angle with the same B/A.

    Johnson §4.2 with one zero principal curvature per cylinder: ``A + B = (1/r1 + 1/r2)/2``,
    ``B − A = ½√(1/r1² + 1/r2² + 2cos(2Φ)/(r1 r2))``; ``cos Φ_eq = (B − A)/(A + B)``. Equal radii:
    ``Φ_eq = Φ``.
    """
    return _equivalent_angle(float(phi_rad), float(r1), float(r2))


# ---------------------------------------------------------------------------------------------
# numba kernels
# ---------------------------------------------------------------------------------------------


@njit(cache=True, fastmath=True, error_model="numpy")
def smoothstep(x):
    """C¹ step 3x² − 2x³ on [0, 1], clamped."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


@njit(cache=True, error_model="numpy")
def lambertw_m1(z):
    """Lower branch W₋₁(z) of the Lambert W function for z in [−1/e, 0) (Halley iterations).

    Initial guess: branch-point series ``−1 + p − p²/3 + 11p³/72``, ``p = −√(2(1 + e z))`` near
    −1/e; asymptotic ``L1 − L2 + L2/L1`` (L1 = ln(−z), L2 = ln(−L1)) near 0 (Corless et al.,
    Adv. Comput. Math. 5, 1996). Accurate to ~1e-15 relative.
    """
    if z >= 0.0:
        return -np.inf
    ez1 = 1.0 + math.e * z
    if ez1 <= 0.0:
        return -1.0
    if z < -0.25:
        p = -math.sqrt(2.0 * ez1)
        w = -1.0 + p - p * p / 3.0 + 11.0 / 72.0 * p * p * p
    else:
        l1 = math.log(-z)
        l2 = math.log(-l1)
        w = l1 - l2 + l2 / l1
    for _ in range(30):
        ew = math.exp(w)
        f = w * ew - z
        wp1 = w + 1.0
        if wp1 == 0.0:
            break
        dw = f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1))
        w -= dw
        if abs(dw) <= 1e-15 * abs(w):
            break
    return w


_EM2 = math.exp(-2.0)


# Tabulated inverse of Johnson's line-contact relation, for the kernels (the Halley iteration of
# ``lambertw_m1`` with an exp per step cost ~90 ns per Gauss point). With ``x = P/C`` and
# ``u = δ/(4(R1+R2))``: ``u = x(−ln x − 1)`` on the branch ln x < −2, i.e. ``g = ln x`` solves
# ``g + ln(−g − 1) = λ``, ``λ = ln u``, with ``dg/dλ = (−g − 1)/(−g − 2)``. The table holds
# ``r = x/u = 1/(−g − 1)``, a slowly varying function of λ (from ≈ 1/(−λ) at small u to 1 at the branch
# point), and ``dr/dλ = r² dg/dλ`` on a uniform grid in λ; cubic Hermite interpolation between its
# nodes has a relative error in P and e below 1e-10 (7e-11 at most; tests/solver/test_laws.py).
# From r alone: ``P = C u r`` and, with ``ln x = −1 − 1/r``, ``e = C (R1 + R2) u² (2r − r²)``: one log
# (for λ), no exp, no division. Outside [λ₀, λ₁] the exact iteration runs.
_LT_LAM0 = math.log(1e-14)               # δ ≈ 2e-17 m for our fibers
_LT_LAM1 = math.log(0.5 * math.exp(-2.0))  # half the range of the law (δ ≈ 0.14 mm)
_LT_N = 4097
_LT_H = (_LT_LAM1 - _LT_LAM0) / (_LT_N - 1)
_LT_INVH = 1.0 / _LT_H


def _line_table():
    """(N, 2) rows ``(r, h dr/dλ)`` at ``λ_k = λ₀ + k h`` (Newton on ``f(g) = g + ln(−g − 1) − λ``)."""
    lam = _LT_LAM0 + _LT_H * np.arange(_LT_N)
    g = lam - np.log(-lam)  # start below the root; Newton on f(g) = g + ln(−g − 1) − λ (monotone, convex)
    g = np.minimum(g, -2.0 - 1e-3)
    for _ in range(60):
        f = g + np.log(-g - 1.0) - lam
        fp = (g + 2.0) / (g + 1.0)
        g_new = np.minimum(g - f / fp, -2.0 - 1e-12)
        if np.max(np.abs(g_new - g)) < 1e-15 * np.max(np.abs(g)):
            g = g_new
            break
        g = g_new
    dg = (-g - 1.0) / (-g - 2.0)
    r = 1.0 / (-g - 1.0)
    return np.ascontiguousarray(np.column_stack([r, r * r * dg * _LT_H]))


_LINE_TABLE_R = _line_table()


@njit(cache=True, error_model="numpy")
def _line_lambert(u, c, sr):
    """Johnson's line law from the Lambert W iteration at ``u = δ/(4(R1+R2))``, ``c = 4πE*(R1+R2)``,
    ``sr = R1 + R2``: ``(P [N/m], e [J/m])`` with ``x = e^{y−1}``, ``y = W₋₁(−e u)``, ``ln x = y − 1``."""
    y = lambertw_m1(-math.e * u)
    x = math.exp(y - 1.0)
    return c * x, c * 4.0 * sr * (-0.5 * x * x * (y - 1.0) - 0.75 * x * x)


@njit(cache=True, error_model="numpy")
def _hertz_parallel_line_outside(delta, e_star, r1, r2):
    """:func:`hertz_parallel_line` outside its table: the Lambert W iteration, and beyond 0.99 of the
    law's range the linear continuation with the secant stiffness there (a separate function, so the
    table path stays small enough to inline)."""
    sr = r1 + r2
    c = 4.0 * math.pi * e_star * sr
    umax = 0.99 * _EM2
    u = delta / (4.0 * sr)
    if u <= umax:
        return _line_lambert(u, c, sr)
    pm, em = _line_lambert(umax, c, sr)
    dm = umax * 4.0 * sr
    ks = pm / dm
    return ks * delta, em + 0.5 * ks * (delta * delta - dm * dm)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def hertz_parallel_line(delta, e_star, r1, r2):
    """Line load p [N/m] and energy per length [J/m] of two parallel cylinders (Johnson 1985, line contact).

    Johnson's approach of two cylinders under load P per unit length:
    ``δ = (P/πE*)[ln(4R1/b) + ln(4R2/b) − 1]``, ``b = √(4 P R_r/(π E*))``, ``1/R_r = 1/R1 + 1/R2``.
    Writing ``x = P/C``, ``C = 4πE*(R1 + R2)``: ``δ = 4(R1 + R2)·x(−ln x − 1)``, which inverts with
    ``y = W₋₁(−e u)``, ``u = δ/(4(R1+R2))``: ``P = C e^{y−1}`` (equal radii:
    ``P = −πE*δ/W₋₁(−eδ/8R)``). Stored energy ``∫P dδ = C·4(R1+R2)·(−x² ln x /2 − 3x²/4)``.
    Valid for ``u < e⁻²`` (δ < 4(R1+R2)/e², 0.27 mm for our fibers); beyond 0.99 of that the law
    continues linearly with its secant stiffness there. ``x/u`` comes from a table uniform in
    ``ln u`` with cubic Hermite interpolation (relative error < 1e-10; outside the table
    :func:`_hertz_parallel_line_outside`).
    """
    if delta <= 0.0:
        return 0.0, 0.0
    sr = r1 + r2
    c = 4.0 * math.pi * e_star * sr
    u = delta / (4.0 * sr)
    v = (math.log(u) - _LT_LAM0) * _LT_INVH
    if v >= 0.0 and v < _LT_N - 1:
        # the integer clamp keeps the read inside the table even for a NaN v (fastmath may drop the
        # float test)
        i = min(max(int(v), 0), _LT_N - 2)
        t = v - i
        t2 = t * t
        tb = _LINE_TABLE_R
        r = (((2.0 * t - 3.0) * t2 + 1.0) * tb[i, 0] + ((t2 - 2.0 * t + 1.0) * t) * tb[i, 1]
             + ((3.0 - 2.0 * t) * t2) * tb[i + 1, 0] + ((t - 1.0) * t2) * tb[i + 1, 1])
        return c * u * r, c * sr * u * u * r * (2.0 - r)
    return _hertz_parallel_line_outside(delta, e_star, r1, r2)


def hertz_parallel_line_exact(delta, e_star, r1, r2):
    """Reference of :func:`hertz_parallel_line` with the Lambert W iteration (no table); for tests."""
    sr = r1 + r2
    return _line_lambert(delta / (4.0 * sr), 4.0 * math.pi * e_star * sr, sr)


@njit(cache=True, fastmath=True, error_model="numpy")
def scaled_stiffness_force(delta, d, s, s0, kdef, nseg):
    """The study's Eq. 1: piecewise-linear force with slope K_i = S0·K_def·S^(i−1) on [(i−1)d, id].

    ``F(δ) = S0 K_def [d (S^m − 1)/(S − 1) + S^m (δ − m d)]``, ``m = min(⌊δ/d⌋, n − 1)``; the last
    slope continues beyond ``n d``. Energy ``∫F dδ`` in closed form. Returns (F, e).
    """
    if delta <= 0.0:
        return 0.0, 0.0
    k1 = s0 * kdef
    m = math.floor(delta / d)
    if m > nseg - 1.0:
        m = nseg - 1.0
    r = delta - m * d
    if abs(s - 1.0) < 1e-15:
        geo = m  # Σ_{k<m} S^k
        sm = 1.0
        sum_geo = 0.5 * m * (m - 1.0)  # Σ_{k<m} (Σ_{l<k} S^l)
    else:
        ls = math.log(s)
        sm = math.exp(m * ls)
        geo = math.expm1(m * ls) / (s - 1.0)
        sum_geo = (geo - m) / (s - 1.0)
    f_m = k1 * d * geo  # force at δ = m d
    # energy up to m d: Σ_k [F_k d + K_{k+1} d²/2], F_k = k1 d Σ_{l<k} S^l
    e_m = k1 * d * d * sum_geo + 0.5 * k1 * d * d * geo
    km = k1 * sm
    return f_m + km * r, e_m + f_m * r + 0.5 * km * r * r


@njit(cache=True, error_model="numpy")
def _equivalent_angle(phi, r1, r2):
    return _equivalent_angle_d(phi, r1, r2)[0]


@njit(cache=True, fastmath=True, error_model="numpy")
def hertz_crossed_point(params, delta, r1, r2, phi):
    """F = K(Φ) δ^{3/2} [N], energy (2/5)Kδ^{5/2}, and ellipse semi-major axis a [m].

    ``K = k̂(Φ_eq)·E*·√R_e``, ``1/R_e = A + B = (1/r1 + 1/r2)/2``; ``a = â(Φ_eq)√(R_e δ)``
    (:func:`hertz_crossed_point_d` without the angle derivatives).
    """
    f, e, a, de, da = hertz_crossed_point_d(params, delta, r1, r2, phi)
    return f, e, a


@njit(cache=True, error_model="numpy")
def _equivalent_angle_d(phi, r1, r2):
    """(Φ_eq, dΦ_eq/dΦ) of :func:`_equivalent_angle`: with ``S = a² + b² + 2ab cos 2Φ``
    (a = 1/r1, b = 1/r2), ``cos Φ_eq = √S/(a + b)``, so ``dΦ_eq/dΦ = 2ab sin 2Φ/(√S (a + b) sin Φ_eq)``,
    which tends to ``2√(ab)/(a + b)`` as Φ → 0."""
    if r1 == r2:
        return phi, 1.0
    a = 1.0 / r1
    b = 1.0 / r2
    s = math.sqrt(max(a * a + b * b + 2.0 * math.cos(2.0 * phi) * a * b, 0.0))
    c = s / (a + b)
    if c >= 1.0:
        return 0.0, 2.0 * math.sqrt(a * b) / (a + b)
    sin_eq = math.sqrt(1.0 - c * c)
    if sin_eq < 1e-12 or s <= 0.0:
        return math.acos(c), 2.0 * math.sqrt(a * b) / (a + b)
    return math.acos(c), 2.0 * a * b * math.sin(2.0 * phi) / (s * (a + b) * sin_eq)


@njit(cache=True, fastmath=True, error_model="numpy")
def _table_lookup_d(params, phi_eq):
    """(k̂, â, dk̂/dΦ_eq, dâ/dΦ_eq) at Φ_eq from the table in ``params``: k̂ and â interpolated linearly
    in ln Φ, clamped to the grid (within 5.6e-5 of the exact solution between the 512 grid points, 1e-4
    tested in tests/solver/test_laws.py; a NaN angle reads the first row). The interpolant is linear in
    ln Φ within a cell, so its derivative is the cell's slope over Φ_eq dlnΦ (0 where it clamps)."""
    nt = int(params[P_NTAB])
    dl = params[P_DLNPHI]
    u = (math.log(phi_eq) - params[P_LNPHI0]) / dl if phi_eq > 0.0 else 0.0
    if not (u == u) or u <= 0.0:
        return params[N_HEADER], params[N_HEADER + nt], 0.0, 0.0
    if u >= nt - 1:
        return params[N_HEADER + nt - 1], params[N_HEADER + 2 * nt - 1], 0.0, 0.0
    i = min(max(int(u), 0), nt - 2)  # integer clamp: NaN-safe even under fastmath
    t = u - i
    kk = N_HEADER + i
    ka = N_HEADER + nt + i
    dk = params[kk + 1] - params[kk]
    da = params[ka + 1] - params[ka]
    inv = 1.0 / (phi_eq * dl)
    return params[kk] + dk * t, params[ka] + da * t, dk * inv, da * inv


@njit(cache=True, fastmath=True, error_model="numpy")
def hertz_crossed_point_d(params, delta, r1, r2, phi):
    """:func:`hertz_crossed_point` with its angle derivatives in one table look-up:
    ``(F [N], e [J], a [m], ∂e/∂Φ [J/rad], ∂a/∂Φ [m/rad])`` at fixed δ, from
    ``e = (2/5) k̂(Φ_eq) E* √R_e δ^{5/2}`` and ``a = â(Φ_eq) √(R_e δ)``."""
    if delta <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    re = 2.0 * r1 * r2 / (r1 + r2)
    phe, dphe = _equivalent_angle_d(phi, r1, r2)
    kh, ah, dkh, dah = _table_lookup_d(params, phe)
    sre = math.sqrt(re)
    sd = math.sqrt(delta)
    c = params[P_ESTAR] * sre * delta * sd
    f = kh * c
    return f, 0.4 * f * delta, ah * sre * sd, 0.4 * c * delta * dkh * dphe, sre * sd * dah * dphe


@njit(cache=True, fastmath=True, error_model="numpy")
def _native(law_id, params, delta, r1, r2, phi):
    """The law's native evaluation: (value, energy); per length or per contact per P_PER_LENGTH."""
    if law_id == LAW_LINEAR:
        k = params[P_K]
        return k * delta, 0.5 * k * delta * delta
    if law_id == LAW_SCALED:
        return scaled_stiffness_force(
            delta, params[P_D], params[P_S], params[P_S0], params[P_KDEF], params[P_NSEG]
        )
    if law_id == LAW_HERTZ_CROSSED:
        f, e, a = hertz_crossed_point(params, delta, r1, r2, params[P_PHI_FIXED])
        return f, e
    return hertz_parallel_line(delta, params[P_ESTAR], r1, r2)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def law_line(law_id, params, delta, r1, r2):
    """Distributed line load p [N/m] and energy per unit length [J/m] at penetration δ [m].

    Inlined into the Gauss-point loop (its Hertz path is a few dozen instructions; as a call, with
    the other laws' branches, it cost ≈ 50 ns per contact pair in paper-40)."""
    if delta <= 0.0:
        return 0.0, 0.0
    if law_id == LAW_HERTZ_PARALLEL or law_id == LAW_HERTZ_ORIENTED:
        return hertz_parallel_line(delta, params[P_ESTAR], r1, r2)
    v, e = _native(law_id, params, delta, r1, r2, 0.0)
    if params[P_PER_LENGTH] > 0.5:
        return v, e
    inv = 1.0 / params[P_LREF]
    return v * inv, e * inv


@njit(cache=True, fastmath=True, error_model="numpy")
def law_point(law_id, params, delta, r1, r2, phi):
    """Point force F [N] and energy [J] at penetration δ [m] and crossing angle Φ [rad]."""
    if delta <= 0.0:
        return 0.0, 0.0
    if law_id == LAW_HERTZ_ORIENTED:
        f, e, a = hertz_crossed_point(params, delta, r1, r2, phi)
        return f, e
    v, e = _native(law_id, params, delta, r1, r2, phi)
    if params[P_PER_LENGTH] > 0.5:
        lr = params[P_LREF]
        return v * lr, e * lr
    return v, e


@njit(cache=True, fastmath=True, error_model="numpy")
def patch_weight(params, delta, r1, r2, phi):
    """The patch criterion's point share: ``w = 1 − smoothstep((ξ − ξ_lo)/(ξ_hi − ξ_lo))``,
    ``ξ = a(δ, Φ)/ℓ_blend``, ``a`` the semi-major axis of the Hertz contact ellipse of the crossing at
    penetration δ: the point law holds while the contact patch fits in the straight length ℓ_blend,
    the line law takes over when it outgrows it (Φ → 0). 1 when ``ℓ_blend`` is 0 (off) or δ ≤ 0."""
    if delta <= 0.0 or params[P_LBLEND] <= 0.0:
        return 1.0
    f, e, a = hertz_crossed_point(params, delta, r1, r2, phi)
    return _patch_share(params, a)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _patch_share(params, a):
    """The point share of a crossing whose Hertz ellipse has the semi-major axis ``a`` [m]."""
    xi = a / params[P_LBLEND]
    return 1.0 - smoothstep((xi - params[P_XI_LO]) / (params[P_XI_HI] - params[P_XI_LO]))


@njit(cache=True, fastmath=True, error_model="numpy")
def law_weight(law_id, params, delta, r1, r2, phi):
    """Point share w ∈ [0, 1] (the distributed line part gets 1 − w).

    * hertz_parallel: 0 (always distributed).
    * hertz_oriented: the patch criterion (:func:`patch_weight`).
    * others: ``smoothstep((Φ − Φ_lo)/(Φ_hi − Φ_lo))`` times the patch criterion when ℓ_blend is set.
    """
    if law_id == LAW_HERTZ_PARALLEL:
        return 0.0
    wp = patch_weight(params, delta, r1, r2, phi)
    if law_id == LAW_HERTZ_ORIENTED:
        return wp
    return wp * smoothstep((phi - params[P_PHI_LO]) / (params[P_PHI_HI] - params[P_PHI_LO]))


@njit(cache=True, fastmath=True, error_model="numpy")
def law_weight_point(law_id, params, delta, r1, r2, phi):
    """``(law_weight(...), *law_point(...))`` at the same δ and Φ: (w, F [N], energy [J]).

    For hertz_oriented the weight needs the Hertz solution itself (the ellipse axis ``a``), so the
    point force comes from the same evaluation (one table look-up and logarithm instead of two).
    """
    if law_id == LAW_HERTZ_ORIENTED:
        if delta <= 0.0:
            return 1.0, 0.0, 0.0
        f, e, a = hertz_crossed_point(params, delta, r1, r2, phi)
        return _patch_share(params, a), f, e
    fp, ep = law_point(law_id, params, delta, r1, r2, phi)
    return law_weight(law_id, params, delta, r1, r2, phi), fp, ep


_GL16_X, _GL16_W = np.polynomial.legendre.leggauss(16)


@njit(cache=True, fastmath=True, error_model="numpy")
def law_blended(law_id, params, delta, r1, r2, phi, length):
    """Total force [N] of two straight fibers of length ``length`` [m] crossing at their middles.

    Same split as the contact kernel: ``w·F_point(δ, Φ) + (1 − w)·∫ p(δ(s)) ds``, the line part
    integrated (16-point Gauss on the touching interval) over the crossing geometry
    ``δ(s) = r1 + r2 − √(D² + 4 s² sin²(Φ/2))``, ``D = r1 + r2 − δ``, ``|s| ≤ length/2``
    (s along either axis from the closest point). At Φ = 0 this is ``p(δ)·length``.
    Used to check that hertz_oriented is continuous in Φ.
    """
    w = law_weight(law_id, params, delta, r1, r2, phi)
    fp, ep = law_point(law_id, params, delta, r1, r2, phi)
    if delta <= 0.0:
        return 0.0
    rr = r1 + r2
    dd = rr - delta
    sh = math.sin(0.5 * phi)
    half = 0.5 * length
    if sh > 0.0:
        smax = math.sqrt(max(rr * rr - dd * dd, 0.0)) / (2.0 * sh)
        if smax < half:
            half = smax
    fl = 0.0
    for g in range(_GL16_X.shape[0]):
        s = half * 0.5 * (_GL16_X[g] + 1.0)
        dg = rr - math.sqrt(dd * dd + 4.0 * s * s * sh * sh)
        p, e = law_line(law_id, params, dg, r1, r2)
        fl += p * _GL16_W[g] * 0.5 * half
    return w * fp + (1.0 - w) * 2.0 * fl


# ---------------------------------------------------------------------------------------------
# Python classes
# ---------------------------------------------------------------------------------------------


def _e_star(E_pa: float, nu: float) -> float:
    if not E_pa > 0:
        raise ConfigError(f"Young's modulus must be > 0 Pa, got {E_pa}")
    if not -1.0 < nu < 0.5:
        raise ConfigError(f"Poisson's ratio must be in (−1, 0.5), got {nu}")
    return E_pa / (2.0 * (1.0 - nu * nu))


#: the contact laws by config name (``scene.contact.law``): one class each, added by :func:`register_law`
LAWS: dict = {}


def _node_stiffness(k, per_length, element_length_m, ref_length_m):
    """The largest stiffness [N/m] a contact of slope ``k`` (N/m² per length, N/m per contact) puts
    on a node: its line part over a whole element or its point part, whichever is larger."""
    if per_length:
        return k * max(element_length_m, ref_length_m)
    return k * max(1.0, element_length_m / ref_length_m)


def register_law(cls):
    """Class decorator: make ``cls`` selectable as ``scene.contact.law: <cls.name>``.

    A law class has a ``name``, a ``law_id`` the contact kernels dispatch on, validates its
    parameters in ``__init__``, encodes them in ``params()`` and builds itself from the config's
    ``contact`` block in ``from_config(contact_cfg, E_pa=..., nu=...)``. A law with its own
    formula also gives ``kernels``, the jitted ``(line, point, weight_point)`` functions the
    contact kernels are specialised on (see docs/solver.md, "Adding a contact law").
    """
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    LAWS[cls.name] = cls
    return cls


def law_from_config(contact_cfg, material_cfg):
    """The :class:`ContactLaw` of the scene's ``contact`` block (SI values) for a material section
    (``youngs_modulus``, ``poisson_ratio_value``: given, or derived from the shear modulus)."""
    cls = LAWS.get(contact_cfg.law)
    if cls is None:
        raise ConfigError(f"unknown contact law {contact_cfg.law!r}; choose from {sorted(LAWS)}", where="scene.contact.law")
    return cls.from_config(contact_cfg, E_pa=float(material_cfg.youngs_modulus), nu=float(material_cfg.poisson_ratio_value))


class ContactLaw:
    """Base class: a normal contact law with SI parameters and its numba encoding."""

    law_id: int = -1
    name: str = ""
    #: None: the built-in kernels (dispatch on law_id); else the jitted (line, point, weight_point)
    kernels = None

    @classmethod
    def from_config(cls, cfg, *, E_pa: float, nu: float) -> "ContactLaw":
        """The law from the ``scene.contact`` block (the base: no parameters of its own)."""
        return cls(E_pa=E_pa, nu=nu, **cls._common_config(cfg))

    @staticmethod
    def _common_config(cfg) -> dict:
        """The keywords every law takes from ``scene.contact``: the patch criterion's ℓ_blend."""
        return {"blend_length_m": float(cfg.blend_length)}

    @classmethod
    def check_config(cls, cfg) -> None:
        """Refuse a ``scene.contact`` block this law cannot run with (raise ValueError naming the key)."""

    def __init__(
        self,
        *,
        E_pa: float = 15e9,
        nu: float = 0.3,
        ref_length_m: float = 0.3e-3,
        phi_lo_deg: float = 0.5,
        phi_hi_deg: float = 1.5,
        blend_length_m: float | None = None,
        xi_lo: float = 1.0,
        xi_hi: float = 2.0,
    ):
        self.E_pa = float(E_pa)
        self.nu = float(nu)
        self.e_star_pa = _e_star(self.E_pa, self.nu)
        if not ref_length_m > 0:
            raise ConfigError(f"ref_length_m must be > 0, got {ref_length_m}")
        if not 0.0 <= phi_lo_deg < phi_hi_deg <= 90.0:
            raise ConfigError(f"need 0 <= phi_lo_deg < phi_hi_deg <= 90, got {phi_lo_deg}, {phi_hi_deg}")
        self.ref_length_m = float(ref_length_m)
        self.phi_lo_deg = float(phi_lo_deg)
        self.phi_hi_deg = float(phi_hi_deg)
        self.per_length = True
        if blend_length_m is not None and not blend_length_m > 0:
            raise ConfigError(f"blend_length_m must be > 0, got {blend_length_m}")
        if not 0 < xi_lo < xi_hi:
            raise ConfigError(f"need 0 < xi_lo < xi_hi, got {xi_lo}, {xi_hi}")
        # None: the point part by the angle window alone (the patch criterion off)
        self.blend_length_m = None if blend_length_m is None else float(blend_length_m)
        self.xi_lo, self.xi_hi = float(xi_lo), float(xi_hi)

    def _header(self) -> np.ndarray:
        l0, dl, khat, ahat = crossed_table()
        p = np.zeros(N_HEADER + 2 * khat.size)
        p[P_ESTAR] = self.e_star_pa
        p[P_LREF] = self.ref_length_m
        p[P_PHI_LO] = self.phi_lo_deg * DEG
        p[P_PHI_HI] = self.phi_hi_deg * DEG
        p[P_PER_LENGTH] = 1.0 if self.per_length else 0.0
        p[P_NSEG] = 1.0
        p[P_S] = 1.0
        p[P_D] = 1.0
        # the patch criterion (law_weight): 0 switches it off
        p[P_LBLEND] = 0.0 if self.blend_length_m is None else self.blend_length_m
        p[P_XI_LO], p[P_XI_HI] = self.xi_lo, self.xi_hi
        p[P_NTAB] = khat.size
        p[P_LNPHI0] = l0
        p[P_DLNPHI] = dl
        # the values themselves: the kernels interpolate them linearly in ln Φ (no exp per contact)
        p[N_HEADER : N_HEADER + khat.size] = khat
        p[N_HEADER + khat.size :] = ahat
        return p

    def params(self) -> np.ndarray:
        """float64 parameter array for the kernels (with the crossed-Hertz table appended)."""
        return self._header()

    #: whether the law's slope grows with the penetration in steps the run can outgrow (the scaled
    #: stiffness of the study's Eq. 1): then the run watches it (``terms.contact.ContactSlopeWatch``)
    stiffens = False

    #: the largest ratio of the law's tangent dF/dδ to its secant F/δ, for a law without a
    #: piecewise-constant slope: the run watches its tangent as this times the largest F_n/δ of a
    #: pair in contact. Hertz: F ∝ δ^{3/2} for crossings (Johnson's line law grows more slowly),
    #: so 3/2; None: not watched that way
    tangent_over_secant: float | None = 1.5

    def node_stiffness_n_per_m(self, element_length_m: float, delta_m: float = 0.0) -> float | None:
        """The largest stiffness [N/m] one contact puts on a node of an element of that length, at the
        (mapped) penetration ``delta_m``, for a law whose slope is piecewise constant (None: it grows
        continuously with the penetration, as Hertz's)."""
        return None

    # vectorised helpers (Python loops over the kernels; for tests and plots)
    def line_force(self, delta_m, r1_m=0.25e-3, r2_m=0.25e-3):
        """Line load p(δ) [N/m] (array in, array out)."""
        p = self.params()
        d = np.atleast_1d(np.asarray(delta_m, float))
        return np.array([law_line(self.law_id, p, x, r1_m, r2_m)[0] for x in d]).reshape(np.shape(delta_m))

    def point_force(self, delta_m, phi_deg=90.0, r1_m=0.25e-3, r2_m=0.25e-3):
        """Point force F(δ, Φ) [N] (array in, array out)."""
        p = self.params()
        d = np.atleast_1d(np.asarray(delta_m, float))
        return np.array(
            [law_point(self.law_id, p, x, r1_m, r2_m, phi_deg * DEG)[0] for x in d]
        ).reshape(np.shape(delta_m))

    def __repr__(self):
        keys = [k for k in vars(self) if k.endswith(("_pa", "_m", "_deg", "_n_per_m", "_n_per_m2"))]
        return f"{type(self).__name__}(" + ", ".join(f"{k}={getattr(self, k)!r}" for k in keys) + ")"


@register_law
class LinearLaw(ContactLaw):
    """Linear penalty: ``p = k δ`` with k in N/m² (``per='length'``) or ``F = k δ`` with k in N/m (``per='contact'``)."""

    law_id = LAW_LINEAR
    name = "linear"
    tangent_over_secant = None  # its slope is fixed and checked before the run

    def __init__(self, stiffness: float, per: str = "length", **kw):
        super().__init__(**kw)
        if per not in ("length", "contact"):
            raise ConfigError(f"per must be 'length' or 'contact', got {per!r}")
        if not stiffness > 0:
            raise ConfigError(f"linear contact stiffness must be > 0, got {stiffness}")
        self.per_length = per == "length"
        if self.per_length:
            self.stiffness_n_per_m2 = float(stiffness)
        else:
            self.stiffness_n_per_m = float(stiffness)
        self.stiffness = float(stiffness)

    @classmethod
    def check_config(cls, cfg):
        if cfg.stiffness is None:
            raise ValueError("contact.law 'linear' needs contact.stiffness (N/m², force per unit length per metre)")

    @classmethod
    def from_config(cls, cfg, *, E_pa, nu):
        return cls(stiffness=float(cfg.stiffness), E_pa=E_pa, nu=nu, **cls._common_config(cfg))

    def params(self):
        p = self._header()
        p[P_K] = self.stiffness
        return p

    def node_stiffness_n_per_m(self, element_length_m, delta_m=0.0):
        # per length: a parallel contact along a whole element gives each node k·L (half from each
        # element), a point contact k·L_ref; per contact: a point k, a line part k·L/L_ref
        return _node_stiffness(self.stiffness, self.per_length, element_length_m, self.ref_length_m)


# The study's Table 1 and Table 3 (d given in mm there). K_def, Abaqus' default penalty
# stiffness, is not given in the study: the values below were identified here by least squares
# against each Hertz target over 0 <= δ <= fit_range_m (see docs/contact.md); per='length' for
# the parallel targets (force per unit length), per='contact' for the crossed ones.
SCALED_PRESETS = {
    # name: (d_m, S, S0, K_def, per, Φ target [deg] (0 = parallel), fit range [m])
    "table1_parallel": (1e-7 * 1e-3, 1.0008, 0.74, 2.455e9, "length", 0.0, 320 * 1e-10),
    "table1_phi2": (4.6e-5 * 1e-3, 1.0101, 0.021, 1.335e8, "contact", 2.0, 130 * 4.6e-8),
    "table1_phi6": (4.6e-5 * 1e-3, 1.0047, 0.0087, 1.914e8, "contact", 6.0, 270 * 4.6e-8),
    "table1_phi10": (5e-5 * 1e-3, 1.0045, 0.013, 9.13e7, "contact", 10.0, 280 * 5e-8),
    # Table 3: identified model; K_def assumed equal to table1_parallel's (same mesh, same target kind)
    "table3_identified": (1e-7 * 1e-3, 1.001, 0.05, 2.455e9, "length", 0.0, 320 * 1e-10),
}


@register_law
class ScaledStiffnessLaw(ContactLaw):
    """The study's Eq. 1: ``K_i = S0·K_def·S^(i−1)`` for ``δ ∈ [(i−1)d, id]``, piecewise-linear force.

    Parameters: ``d_m`` interpolation step [m], ``S`` growth factor, ``S0`` initial factor,
    ``K_def`` [N/m² if per='length', N/m if per='contact'], ``n`` segments (last slope continues).
    Presets: :meth:`preset` with the names of :data:`SCALED_PRESETS`.
    """

    law_id = LAW_SCALED
    name = "scaled_stiffness"
    tangent_over_secant = None  # its slope is known at every penetration (node_stiffness_n_per_m)

    def __init__(self, d_m: float, S: float, S0: float, K_def: float, n: int = 1000, per: str = "contact", **kw):
        super().__init__(**kw)
        if not d_m > 0:
            raise ConfigError(f"d_m must be > 0, got {d_m}")
        if not S >= 1.0:
            raise ConfigError(f"S must be >= 1, got {S}")
        if not S0 > 0 or not K_def > 0:
            raise ConfigError("S0 and K_def must be > 0")
        if int(n) < 1:
            raise ConfigError(f"n must be >= 1, got {n}")
        if per not in ("length", "contact"):
            raise ConfigError(f"per must be 'length' or 'contact', got {per!r}")
        self.d_m, self.S, self.S0, self.K_def, self.n = float(d_m), float(S), float(S0), float(K_def), int(n)
        self.per_length = per == "length"
        self.target_phi_deg = None
        self.fit_range_m = None

    stiffens = True

    def node_stiffness_n_per_m(self, element_length_m, delta_m=0.0):
        # the slope of the segment of Eq. 1 that holds δ, K_m = S0·K_def·S^m, m = min(⌊δ/d⌋, n − 1):
        # at δ = 0 the first slope, which the setup refuses when the step cannot carry it
        m = min(math.floor(max(delta_m, 0.0) / self.d_m), self.n - 1)
        slope = self.S0 * self.K_def * math.exp(m * math.log(self.S))
        return _node_stiffness(slope, self.per_length, element_length_m, self.ref_length_m)

    @classmethod
    def preset(cls, name: str, **kw) -> "ScaledStiffnessLaw":
        """One of ``table1_parallel``, ``table1_phi2``, ``table1_phi6``, ``table1_phi10``, ``table3_identified``."""
        if name not in SCALED_PRESETS:
            raise ConfigError(f"unknown scaled_stiffness preset {name!r}; choose from {sorted(SCALED_PRESETS)}")
        d, S, S0, K, per, phi, rng = SCALED_PRESETS[name]
        law = cls(d, S, S0, K, per=per, **kw)
        law.target_phi_deg = phi
        law.fit_range_m = rng
        law.preset_name = name
        return law

    @classmethod
    def check_config(cls, cfg):
        if cfg.preset is None and None in (cfg.k_def, cfg.s0, cfg.s, cfg.d):
            raise ValueError("contact.law 'scaled_stiffness' needs contact.preset or all of k_def, s0, s, d")

    @classmethod
    def from_config(cls, cfg, *, E_pa, nu):
        if cfg.preset is not None:
            return cls.preset(cfg.preset, E_pa=E_pa, nu=nu, **cls._common_config(cfg))
        return cls(d_m=float(cfg.d), S=float(cfg.s), S0=float(cfg.s0), K_def=float(cfg.k_def), E_pa=E_pa, nu=nu,
                   **cls._common_config(cfg))

    def params(self):
        p = self._header()
        p[P_D], p[P_S], p[P_S0], p[P_KDEF], p[P_NSEG] = self.d_m, self.S, self.S0, self.K_def, self.n
        return p

    def native_force(self, delta_m):
        """F(δ) as the study defines it (N, or N/m for per='length')."""
        d = np.atleast_1d(np.asarray(delta_m, float))
        return np.array(
            [scaled_stiffness_force(x, self.d_m, self.S, self.S0, self.K_def, float(self.n))[0] for x in d]
        ).reshape(np.shape(delta_m))


@register_law
class HertzParallelLaw(ContactLaw):
    """Johnson line contact of parallel cylinders (Lambert-W inversion); always distributed."""

    law_id = LAW_HERTZ_PARALLEL
    name = "hertz_parallel"


@register_law
class HertzCrossedLaw(ContactLaw):
    """Elliptical Hertz contact of cylinders crossed at one fixed angle Φ for the whole model: F = K(Φ)δ^{3/2}.

    ``K(Φ)`` from the exact solution (:func:`hertz_crossed_exact`), tabulated once; reproduces
    K ≈ 2.29e9, 9.28e8, 6.21e8, 2.81e8, 1.74e8 N/m^1.5 at Φ = 2, 6, 10, 30, 90° for our fibers.
    Point contact above ``phi_hi_deg``; for near-parallel segments distributed as F/ℓ_ref per length.
    """

    law_id = LAW_HERTZ_CROSSED
    name = "hertz_crossed"

    def __init__(self, phi_deg: float | None = None, *, phi_rad: float | None = None, **kw):
        super().__init__(**kw)
        if (phi_deg is None) == (phi_rad is None):
            raise ConfigError("hertz_crossed: give the crossing angle once, phi_deg or phi_rad")
        self.phi_rad = float(phi_rad) if phi_rad is not None else float(phi_deg) * DEG
        if not 0.0 < self.phi_rad <= 0.5 * math.pi * (1 + 1e-12):
            raise ConfigError(f"the crossing angle must be in (0, 90] deg, got {math.degrees(self.phi_rad):g} deg")
        self.phi_deg = math.degrees(self.phi_rad)
        self.per_length = False

    @classmethod
    def check_config(cls, cfg):
        if cfg.angle is None:
            raise ValueError("contact.law 'hertz_crossed' needs contact.angle (e.g. '6 deg')")

    @classmethod
    def from_config(cls, cfg, *, E_pa, nu):
        return cls(phi_rad=float(cfg.angle), E_pa=E_pa, nu=nu, **cls._common_config(cfg))

    def params(self):
        p = self._header()
        p[P_PHI_FIXED] = self.phi_rad
        return p

    def stiffness(self, r1_m=0.25e-3, r2_m=0.25e-3) -> float:
        """K(Φ) [N/m^1.5] from the table."""
        return float(law_point(self.law_id, self.params(), 1.0, r1_m, r2_m, 0.0)[0])


@register_law
class HertzOrientedLaw(ContactLaw):
    """Each contact's own Φ: crossed Hertz F = K(Φ)δ^{3/2} while the contact ellipse fits, line law beyond.

    The blend uses ``ξ = a(δ, Φ)/ℓ_blend`` (``a`` the Hertz semi-major axis, ``ℓ_blend`` the straight
    fiber length available on each side of the contact): point law for ξ ≤ ξ_lo, line law
    ``p(δ)`` integrated over the segments' overlap for ξ ≥ ξ_hi, smoothstep between. At Φ = 2°,
    δ = 1 µm our fibers have a ≈ 0.83 mm.
    """

    law_id = LAW_HERTZ_ORIENTED
    name = "hertz_oriented"

    def __init__(self, blend_length_m: float = 5.0e-5, **kw):
        # the patch criterion is this law's own blend: always on
        super().__init__(blend_length_m=blend_length_m, **kw)


def make_law(name: str, **kw) -> ContactLaw:
    """Build a registered law by name with its constructor's keywords (``scaled_stiffness``:
    ``preset=`` or its parameters)."""
    cls = LAWS.get(name)
    if cls is None:
        raise ConfigError(f"unknown contact law {name!r}; choose from {sorted(LAWS)}")
    if cls is ScaledStiffnessLaw and "preset" in kw:
        return ScaledStiffnessLaw.preset(kw.pop("preset"), **kw)
    return cls(**kw)
