"""Stable time step of the explicit central-difference scheme for the beam model.

Central difference is stable for Δt ≤ 2/ω_max (with a fraction ξ of critical damping in the top
mode: Δt ≤ (2/ω_max)(√(1+ξ²) − ξ)); the element-by-element maximum frequency bounds the mesh's
from above (Abaqus "Definition of the stability limit", Getting Started with Abaqus/Explicit §3.3;
Belytschko, Liu & Moran 2000, §6.3). For one element of rest length L with lumped translational
mass ρAL/2 and the isotropic lumped rotary inertia s·ρJ_pL/2 per node (J_p = 2I, see
:func:`fiberpipe.solver.model.build_model`), the element modes give (derivation in docs/solver.md):

* axial:     ω² = 4E/(ρL²)                   → Δt = L/c,          c = √(E/ρ)
* torsion:   ω² = 4G/(ρL²s)                  → Δt = √s · L/√(G/ρ)
* bending (antisymmetric nodal rotations): ω² = 4EI/(ρJ_pL²s) = 2E/(ρL²s) → Δt = √(2s) · L/c
* shear (symmetric rotations coupled with antisymmetric transverse translation):
             ω² = 4 k_s G/ρ · (1/L² + A/(4 J_p s)) = 4 k_s G/ρ · (1/L² + 1/(2 s r²))

With the study's 0.3 mm polyester elements and s = 1 the axial mode governs,
Δt = 9.1e-8 s (full 12×12 Timoshenko eigenvalues, docs/solver.md).
Stiffness-proportional damping β adds ξ = β ω/2 in every mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ._kernels_beam import beam_forces
from .model import Model


#: The fraction of the stable step a run uses by default (``solver.dt_safety`` of the config schema,
#: ``SimulationSettings.dt_safety``); the step-scaled penalties are chosen against it
#: (:func:`penalty_time_step`).
DEFAULT_DT_SAFETY = 0.9


def penalty_time_step(model: Model, dt_s: float, *, beta_s: float = 0.0) -> float:
    """The step Δt_pen [s] the step-scaled penalties (plates and walls ``c m (2/Δt_pen)²``, the
    tangential friction spring) are chosen against: the larger of the step in use and
    :data:`DEFAULT_DT_SAFETY` × the element stable step.

    Why: a penalty ``k ∝ 1/Δt²`` keeps ω Δt fixed, so the central-difference error of every contact
    it carries stays the same fraction of the contact's energy at any step (measured on the
    six-fiber scene at 1000 N/m: up to +4 % of the loads' work at `dt_safety` 0.45, 0.2 and 0.1
    alike). Held at the default step's stiffness below it, a smaller step resolves the contacts
    better (the same runs: ≤ +0.5 % at 0.2, ≤ +0.2 % at 0.1); at and above the default nothing changes.
    """
    return max(float(dt_s), DEFAULT_DT_SAFETY * stable_time_step(model, beta_s=beta_s).dt_stable_s)


@dataclass(frozen=True)
class TimeStepReport:
    """Stable time step of a model (s), the mode and element that govern it, and each mode's minimum."""

    dt_stable_s: float
    governing_mode: str
    governing_element: int
    per_mode_s: dict
    rotary_inertia_scale: float
    beta_s: float

    def summary(self) -> str:
        modes = ", ".join(f"{k} {v:.3g} s" for k, v in self.per_mode_s.items())
        return (f"stable dt {self.dt_stable_s:.4g} s ({self.governing_mode} mode of element "
                f"{self.governing_element}; {modes}; rotary inertia scale {self.rotary_inertia_scale:g})")


def stable_time_step(model: Model, *, beta_s: float = 0.0) -> TimeStepReport:
    """Element-by-element stable time step (s) of ``model`` (see the module docstring).

    Parameters
    ----------
    model : Model
    beta_s : float, s — stiffness-proportional damping coefficient (reduces the limit).
    """
    mat = model.material
    E, G, rho = mat.youngs_modulus_pa, mat.G, mat.density_kg_m3
    s = model.rotary_inertia_scale
    rho = rho * model.mass_scale
    L = model.el_L0
    r = model.el_radius
    ks = mat.shear_factor
    w2 = {
        "axial": np.full_like(L, 4.0 * E / rho) / L**2,
        "torsion": 4.0 * G / (rho * s) / L**2,
        "bending": 2.0 * E / (rho * s) / L**2,
        "shear": 4.0 * ks * G / rho * (1.0 / L**2 + 1.0 / (2.0 * s * r**2)),
    }
    per_mode = {}
    best = (math.inf, "", -1)
    for name, om2 in w2.items():
        om = np.sqrt(om2)
        xi = 0.5 * beta_s * om
        dt = 2.0 / om * (np.sqrt(1.0 + xi**2) - xi)
        k = int(np.argmin(dt))
        per_mode[name] = float(dt[k])
        if dt[k] < best[0]:
            best = (float(dt[k]), name, k)
    return TimeStepReport(best[0], best[1], best[2], per_mode, s, float(beta_s))


@dataclass(frozen=True)
class ModalTimeStep:
    """The stable step of the constrained, assembled beam system (s) from its highest eigenvalue.

    ``omega_max_rad_s``: √λ_max of M⁻¹K with the fixed degrees of freedom removed;
    ``dt_beams_s = 2/ω_max`` (with the damping reduction); ``dt_stable_s`` = that × √(1 − c_pen)
    (the plane penalty's share, c_pen = penalty factor: module docstring of :func:`modal_time_step`);
    ``iterations``: the tangent's finite-difference probes (18 for the banded beam tangent) or
    Lanczos matrix–vector products (with extra forces).
    """

    dt_stable_s: float
    dt_beams_s: float
    omega_max_rad_s: float
    penalty_factor: float
    free_dofs: int
    iterations: int

    def summary(self) -> str:
        return (f"modal stable dt {self.dt_stable_s:.4g} s (constrained beams 2/ω_max = {self.dt_beams_s:.4g} s, "
                f"ω_max = {self.omega_max_rad_s:.4g} rad/s, {self.free_dofs} free dofs; plane penalty factor "
                f"{self.penalty_factor:g})")


def _free_dofs(n_nodes: int, fix_mask: np.ndarray, axis_bits) -> np.ndarray:
    """(N, 6) bool: the translational (x, y, z) and rotational degrees of freedom left free by the
    fixity mask of the scene (``layout`` bits: FIX_X/Y/Z, FIX_ROT, DRIVEN)."""
    from .layout import DRIVEN, FIX_ROT, FIX_X, FIX_Y, FIX_Z

    free = np.ones((n_nodes, 6), bool)
    if fix_mask.shape[0] == n_nodes:
        m = fix_mask.astype(np.int64)
        driven = (m & DRIVEN) != 0
        for c, bit in enumerate((FIX_X, FIX_Y, FIX_Z)):
            free[:, c] = ((m & bit) == 0) & ~driven
        free[:, 3:] = (((m & FIX_ROT) == 0) & ~driven)[:, None]
    return free


@njit(cache=True, error_model="numpy")
def _rotate_into(q, phi, out):
    """``out = exp(φ) ⊗ q`` for spatial spins φ (N, 3) and unit quaternions q (N, 4) (w, x, y, z),
    renormalised."""
    for i in range(q.shape[0]):
        a = math.sqrt(phi[i, 0] * phi[i, 0] + phi[i, 1] * phi[i, 1] + phi[i, 2] * phi[i, 2])
        half = 0.5 * a
        s = math.sin(half) / a if a > 0.0 else 0.5
        pw = math.cos(half)
        px, py, pz = s * phi[i, 0], s * phi[i, 1], s * phi[i, 2]
        qw, qx, qy, qz = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        ow = pw * qw - px * qx - py * qy - pz * qz
        ox = pw * qx + px * qw + py * qz - pz * qy
        oy = pw * qy - px * qz + py * qw + pz * qx
        oz = pw * qz + px * qy - py * qx + pz * qw
        inv = 1.0 / math.sqrt(ow * ow + ox * ox + oy * oy + oz * oz)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = ow * inv, ox * inv, oy * inv, oz * inv


@njit(cache=True, error_model="numpy")
def _beam_force_difference(x0, q0, u, h, beams, out):
    """``out`` (N, 6) = F(+h u) − F(−h u): the beam forces and moments (:func:`beam_forces`) at the
    positions ``x0 ± h u[:, :3]`` and the rotations ``exp(±h u[:, 3:]) ⊗ q0``."""
    el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest = beams
    n = x0.shape[0]
    x = np.empty((n, 3))
    q = np.empty((n, 4))
    f = np.empty((n, 3))
    mom = np.empty((n, 3))
    no_strain = np.zeros((0, 6))
    for sign in (1.0, -1.0):
        x[:] = x0 + (sign * h) * u[:, :3]
        _rotate_into(q0, (sign * h) * u[:, 3:], q)
        f[:] = 0.0
        mom[:] = 0.0
        beam_forces(x, q, el_n1, el_invL0, el_C, el_Dk, gamma_rest, theta_rest, f, mom, False, 0.0, no_strain)
        out[:, :3] += sign * f
        out[:, 3:] += sign * mom


def modal_time_step(model: Model, fix_mask: np.ndarray, *, beta_s: float = 0.0, penalty_factor: float = 0.0,
                    x: np.ndarray | None = None, q: np.ndarray | None = None, tol: float = 1e-6,
                    extra_forces=None) -> ModalTimeStep:
    """Stable time step from the highest eigenvalue of the assembled, constrained beam system.

    Central differences are stable for ``Δt ω_max ≤ 2`` with ω_max² the largest eigenvalue of
    ``M⁻¹K`` on the free degrees of freedom (Belytschko, Liu & Moran 2000, §6.3). The element-by-
    element bound of :func:`stable_time_step` includes every element mode, the axial one too; when
    the scene fixes the translation along the fibers (``scene.constraints.lock_axial: all``) the axial
    mode of an element along that axis has no free degree of freedom, and ω_max is the next mode's
    (shear for the study's 0.3 mm elements). ``K`` is the tangent of the beam forces at ``(x, q)``
    (default: the rest state, where it is the material stiffness), by central differences of
    :func:`fiberpipe.solver._kernels_beam.beam_forces` in positions and spatial spins.

    An element couples its two nodes only, so ``K`` is block-tridiagonal along each fiber: it is
    assembled column by column from 18 probes (each of the six degrees of freedom of every third node
    at once, :func:`_beam_tangent_banded`), and ω_max² is the top eigenvalue of the symmetric banded
    ``M^{-1/2} K M^{-1/2}``, fiber by fiber (``scipy.linalg.eigvals_banded``, LAPACK). With ``extra_forces(x) -> (N, 3)``, further
    position-dependent forces whose tangent is added to K (e.g. the fiber–fiber contact at a state,
    for the measurements of docs/benchmarks.md), which couple any nodes, the operator is applied
    matrix-free to Lanczos vectors instead (``scipy.sparse.linalg.eigsh``, relative tolerance ``tol``).

    Penalties on top: a plane penalty ``k_i = c m_i (2/Δt)²`` adds at most ``4c/Δt²`` to ω² (a
    diagonal, positive term: Weyl's inequality), so ``(ω_max² + 4c/Δt²) Δt² ≤ 4`` holds for
    ``Δt ≤ (2/ω_max) √(1 − c)``. Fiber–fiber contact stiffness is not in the bound: it is small
    against the beams' at the study's loads (docs/benchmarks.md, "Stable step per active mode",
    measured) and ``solver.dt_safety`` keeps a margin for it.
    """
    n = model.n_nodes
    x0 = np.ascontiguousarray(model.nodes_m if x is None else x, dtype=np.float64)
    q0 = np.ascontiguousarray(model.quats0 if q is None else q, dtype=np.float64)
    free = _free_dofs(n, np.asarray(fix_mask), None).ravel()
    inv_sqrt_m = np.column_stack([np.repeat(1.0 / np.sqrt(model.mass)[:, None], 3, axis=1),
                                  1.0 / np.sqrt(model.J)]).ravel()
    beams = (model.el_n1, model.el_invL0, model.el_C, model.el_Dk, model.gamma_rest, model.theta_rest)
    L = float(np.min(model.el_L0))
    if extra_forces is None:
        lam, calls = _top_eigenvalue_banded(x0, q0, beams, L, free, inv_sqrt_m, model.node_offsets)
    else:
        lam, calls = _top_eigenvalue_lanczos(x0, q0, beams, L, free, inv_sqrt_m, extra_forces, tol)
    om = math.sqrt(max(lam, 0.0))
    xi = 0.5 * beta_s * om
    dt_b = 2.0 / om * (math.sqrt(1.0 + xi * xi) - xi) if om > 0 else math.inf
    # rounded down to 6 significant digits: the eigenvalue may differ in its last bits between
    # machines or BLAS builds, and a resumed run must find the checkpoint's step again
    dt_s = _round_down(dt_b * math.sqrt(1.0 - penalty_factor), 6)
    return ModalTimeStep(dt_s, dt_b, om, float(penalty_factor), int(free.sum()), calls)


# probes of the banded beam tangent: three colours of nodes × six degrees of freedom
BANDED_PROBES = 3 * 6


def _probe_steps(L: float) -> np.ndarray:
    """The finite-difference step of each of a node's six degrees of freedom: 1e-6 of the shortest
    element in translation, 1e-6 rad in rotation (K e = −(F(+h e) − F(−h e)) / (2h), exact for the
    linear tangent up to O(h²))."""
    return np.array([1e-6 * L] * 3 + [1e-6] * 3)


def _beam_tangent_banded(x0, q0, beams, L: float) -> np.ndarray:
    """The beam tangent K (6N × 6N) in LAPACK's lower band storage ``band[d, c] = K[c + d, c]``,
    d = 0 … 11, symmetrised as (K + Kᵀ)/2 (K is symmetric at rest; the spatial-spin tangent of a
    deformed state nearly so).

    Strategy: a node's force depends on its own and its two neighbours' degrees of freedom, and
    three consecutive nodes have different colours ``node % 3``; perturbing degree of freedom a of
    every node of one colour at once, the force change at node r comes from the one perturbed node
    among r − 1, r, r + 1 (nodes of different fibers do not interact), so 3 × 6 probes give every
    column."""
    n = x0.shape[0]
    h = _probe_steps(L)
    K_rows = np.zeros((3, n, 6, 6))  # K_rows[o, c, b, a] = K[6(c + o − 1) + b, 6c + a]
    u = np.zeros((n, 6))
    diff = np.zeros((n, 6))
    nodes = np.arange(n)
    for colour in range(3):
        cols = nodes[colour::3]
        for a in range(6):
            u[:] = 0.0
            u[cols, a] = 1.0
            diff[:] = 0.0
            _beam_force_difference(x0, q0, u, h[a], beams, diff)
            col = -diff / (2.0 * h[a])
            for o in range(3):  # rows c − 1, c, c + 1 of column (c, a)
                r = cols + o - 1
                ok = (r >= 0) & (r < n)
                K_rows[o, cols[ok], :, a] = col[r[ok]]
    # lower band: column j = 6c + a, row i = 6(c + o − 1) + b ≥ j for o = 1 (the node itself, b ≥ a)
    # and o = 2 (the next node); (K[i, j] + K[j, i]) / 2 with K[j, i] = K_rows[2 − o, c + o − 1, a, b]
    band = np.zeros((12, 6 * n))
    a_idx, b_idx = np.meshgrid(np.arange(6), np.arange(6), indexing="ij")  # [a, b]
    for o in (1, 2):
        c = np.arange(n - (o - 1))
        rr = c + o - 1
        kij = K_rows[o, c].transpose(0, 2, 1)             # [c, a, b] = K[6rr + b, 6c + a]
        kji = K_rows[2 - o, rr]                           # [c, a, b] = K[6c + a, 6rr + b]
        d = 6 * (o - 1) + b_idx - a_idx                   # i − j
        keep = d >= 0
        j = (6 * c)[:, None, None] + a_idx[None]
        band[np.broadcast_to(d, kij.shape)[:, keep], j[:, keep]] = 0.5 * (kij[:, keep] + kji[:, keep])
    return band


def _top_eigenvalue_banded(x0, q0, beams, L, free, inv_sqrt_m, node_offsets) -> tuple[float, int]:
    """λ_max of M^{-1/2} K M^{-1/2} on the free degrees of freedom from the banded tangent, fiber by
    fiber (the beams couple no two fibers: K is block-diagonal by fiber); returns (λ_max, probes)."""
    from scipy.linalg import eigvals_banded

    band = _beam_tangent_banded(x0, q0, beams, L)
    lam_max = 0.0
    for f in range(len(node_offsets) - 1):
        lo, hi = 6 * int(node_offsets[f]), 6 * int(node_offsets[f + 1])
        idx = lo + np.flatnonzero(free[lo:hi])
        if idx.size == 0:
            continue
        # the free degrees of freedom keep their order, so the band (offset ≤ 11) stays one
        pos = np.full(hi - lo, -1)
        pos[idx - lo] = np.arange(idx.size)
        sub = np.zeros((12, idx.size))
        for d in range(12):
            j = np.arange(lo, hi - d)
            i = j + d
            keep = free[i] & free[j]
            i, j = i[keep], j[keep]
            sub[pos[i - lo] - pos[j - lo], pos[j - lo]] = band[d, j] * inv_sqrt_m[i] * inv_sqrt_m[j]
        lam_max = max(lam_max, float(np.max(eigvals_banded(sub, lower=True))))
    return lam_max, BANDED_PROBES


def _top_eigenvalue_lanczos(x0, q0, beams, L, free, inv_sqrt_m, extra_forces, tol) -> tuple[float, int]:
    """λ_max of M^{-1/2} (K + K_extra) M^{-1/2} on the free degrees of freedom by Lanczos, the
    operator applied matrix-free; returns (λ_max, products)."""
    from scipy.sparse.linalg import LinearOperator, eigsh

    n = x0.shape[0]
    calls = [0]

    def matvec(y):
        y = np.asarray(y).ravel()
        u = np.zeros(6 * n)
        u[free] = y
        u *= inv_sqrt_m
        uu = u.reshape(n, 6)
        nrm = max(float(np.max(np.abs(uu[:, :3]))) / L, float(np.max(np.abs(uu[:, 3:]))))
        if nrm == 0.0:
            return np.zeros_like(y)
        # one scalar step: at most 1e-6 of an element in translation and 1e-6 rad in rotation
        h = 1e-6 / nrm
        diff = np.zeros((n, 6))
        _beam_force_difference(x0, q0, uu, h, beams, diff)
        diff[:, :3] += extra_forces(x0 + h * uu[:, :3]) - extra_forces(x0 - h * uu[:, :3])
        calls[0] += 1
        return ((-diff.ravel() / (2.0 * h)) * inv_sqrt_m)[free]

    nf = int(free.sum())
    op = LinearOperator((nf, nf), matvec=matvec, dtype=np.float64)
    lam = float(eigsh(op, k=1, which="LA", tol=tol, return_eigenvectors=False, ncv=min(nf, 40),
                      v0=np.random.default_rng(0).standard_normal(nf))[0])
    return lam, calls[0]


def _round_down(x: float, digits: int) -> float:
    """``x`` > 0 rounded down to ``digits`` significant digits."""
    if not (x > 0 and math.isfinite(x)):
        return x
    e = math.floor(math.log10(x)) - digits + 1
    return math.floor(x / 10.0**e) * 10.0**e


#: ``solver.stable_step: adaptive`` looks at the contact's stiffness every this many steps (the run's
#: chunks are at most this long): the window over which the step lags a stiffening contact
ADAPTIVE_LOOK_STEPS = 50

#: the most sub-steps a step of an adaptive run is split into (a contact stiffer than that is a
#: warning: the run goes on at the smallest step)
MAX_SUBSTEPS = 256


class AdaptiveStep:
    """The sub-steps of ``solver.stable_step: adaptive``: each step Δt₀ of the run's grid (dt_safety ×
    the element bound) is taken as m equal sub-steps Δt₀/m, m chosen from the contact's stiffness.

    Bound: central differences are stable while (ω Δt)² ≤ 4 in every mode (Belytschko, Liu & Moran
    2000, §6.3). A penalty k on a node of mass m_min adds 2k/m_min to the ω² of the beam modes it
    couples with (shear and bending; :func:`fiberpipe.solver.terms.contact.penalty_step_bound`),
    the plane penalty ``c m (2/Δt_pen)²`` adds 4c/Δt_pen² (Weyl's inequality, as in
    :func:`modal_time_step`), so the step keeps the run's margin when

        Δt ≤ dt_safety · 2 / √(ω_beam² + 2k/m_min + 4c/Δt_pen²).

    ``k`` is the law's tangent at the largest penetration since the last look (a law that stiffens
    with the penetration) or 3/2 of the largest secant F_n/δ (Hertz), read from the contact's
    :class:`~fiberpipe.solver.terms.contact.ContactSlopeWatch` every :data:`ADAPTIVE_LOOK_STEPS`
    steps. m rises at once to what the stiffness needs and does not fall again: the step shrinks
    with a stiffening contact and never grows (a compaction's contacts stiffen as it goes). Why not
    grow: each change of the step shifts the leapfrog's invariant by ¼(Δt_old² − Δt_new²) Σ m|a_n|²,
    which :func:`step_change_kick` books for a shrinking step to within rounding, but a growing one
    in a rattling contact created 2.6–4.5 % of the loads' work on the six-fiber scene (scaled_stiffness
    table1_phi2 at 1000 N/m, the step doubled after 20 or 100 looks in a row found half the sub-steps
    enough for twice the stiffness). The choice
    depends on the state only, at step numbers fixed by the run's grid, so a resumed run makes it
    again bit for bit.
    """

    def __init__(self, model: Model, dt_s: float, dt_safety: float, penalty_factor: float, penalty_dt_s: float,
                 watch=None):
        rep = stable_time_step(model)
        self.dt_s = float(dt_s)
        self.dt_safety = min(float(dt_safety), 1.0)
        self.watch = watch
        self.m_min = float(np.min(model.mass)) if model.n_nodes else 1.0
        # the beam modes a contact couples with, and the plane penalty's share of ω²
        omega2_beam = max((2.0 / rep.per_mode_s[mode]) ** 2 for mode in ("shear", "bending"))
        self.omega2_fixed = omega2_beam + 4.0 * float(penalty_factor) / float(penalty_dt_s) ** 2
        self.warning: str | None = None

    def needed_substeps(self, k_node_n_per_m: float) -> int:
        """The fewest sub-steps of Δt₀ that carry a contact stiffness ``k`` [N/m] per node with the margin."""
        omega2 = self.omega2_fixed + 2.0 * max(k_node_n_per_m, 0.0) / self.m_min
        dt_ok = self.dt_safety * 2.0 / math.sqrt(omega2)
        return max(1, int(math.ceil(self.dt_s / dt_ok * (1.0 - 1e-12))))

    def look(self, substeps: np.ndarray, t_s: float) -> None:
        """After a look at the contact's stiffness (it resets its peaks), the sub-steps of the next
        stretch into ``substeps[0]`` (in place: the integrator's checkpointed array)."""
        k = self.watch.stiffness()[0] if self.watch is not None else 0.0
        needed = self.needed_substeps(k)
        if needed > MAX_SUBSTEPS:
            if self.warning is None:
                self.warning = (f"by t = {t_s:.4g} s the contact ({k:.3g} N/m per node) needs {needed} sub-steps of "
                                f"the step {self.dt_s:.3g} s, more than {MAX_SUBSTEPS}: the run goes on at "
                                f"{self.dt_s / MAX_SUBSTEPS:.3g} s (energy may be created); use a law that stiffens less")
            needed = MAX_SUBSTEPS
        substeps[0] = max(int(substeps[0]), needed)


def step_change_kick(state, v_before: np.ndarray, w_before: np.ndarray, dt_old_s: float, dt_new_s: float,
                     coef: tuple, fixity, mass: np.ndarray, inertia: np.ndarray) -> float:
    """Set right the first step after the step changed from ``dt_old_s`` to ``dt_new_s`` (in place);
    returns the shift [J] of the leapfrog's kinetic term that the change makes.

    Central differences with a variable step kick the half-step velocity by the mean of the two
    steps, v_{n+½} = v_{n−½} + ½(Δt_old + Δt_new) a_n (Belytschko, Liu & Moran 2000, §6.2.1); the
    step loop, which keeps its step, kicked by Δt_new. ``state`` is the state after that first step
    (``v_before``, ``w_before``: the half-step velocities before it; ``coef``: the step's
    ``(c_keep, dt_c)`` of :func:`fiberpipe.solver._kernels_integrate.damping_factors`), from which
    a_n = (v_{n+½} − c_keep v_{n−½}) / dt_c on the free degrees of freedom; the missing
    ½(Δt_old − Δt_new) a_n is added to the velocities and Δt_new times it to the positions, and the
    body-frame spins' share rotates the quaternions (q ⊗ exp(½Δt_new δΩ), to first order in δΩ).
    Without it a change of the step in a stiff contact created 68 × the loads' work on the six-fiber
    scene (scaled_stiffness table1_phi2 at 1000 N/m).

    The shift: the leapfrog's kinetic term ½ v_{n−½}·M v_{n+½} is the mean of the half-step kinetic
    energies less ¼Δt² Σ m|a_n|² (``_kernels_integrate.update_range``), so at the same motion it moves
    by ¼(Δt_old² − Δt_new²) Σ (m|a_n|² + J|α_n|²) when the step changes: a term of the step, not of
    the motion, which the energy balance takes out (``energy/step_change`` of the history).
    """
    c_keep, dt_c = coef
    half = 0.5 * (dt_old_s - dt_new_s) / dt_c
    free = np.column_stack([fixity.free_x, fixity.free_y, fixity.free_z])
    acc = (state.v - c_keep * v_before) * free / dt_c
    alpha = (state.w - c_keep * w_before) * fixity.free_rot[:, None] / dt_c
    shift = 0.25 * (dt_old_s ** 2 - dt_new_s ** 2) * float(np.sum(mass[:, None] * acc ** 2) + np.sum(inertia * alpha ** 2))
    dv = half * (state.v - c_keep * v_before) * free
    state.v += dv
    state.x += dt_new_s * dv
    dw = half * (state.w - c_keep * w_before) * fixity.free_rot[:, None]
    state.w += dw
    h = 0.5 * dt_new_s * dw  # q ⊗ (cos|h|, sin|h| ĥ)
    a = np.linalg.norm(h, axis=1)
    s = np.where(a > 0.0, np.sin(a) / np.where(a > 0.0, a, 1.0), 1.0)
    pw, px, py, pz = np.cos(a), s * h[:, 0], s * h[:, 1], s * h[:, 2]
    q = state.q
    qw, qx, qy, qz = q[:, 0].copy(), q[:, 1].copy(), q[:, 2].copy(), q[:, 3].copy()
    q[:, 0] = qw * pw - qx * px - qy * py - qz * pz
    q[:, 1] = qw * px + qx * pw + qy * pz - qz * py
    q[:, 2] = qw * py - qx * pz + qy * pw + qz * px
    q[:, 3] = qw * pz + qx * py - qy * px + qz * pw
    q /= np.linalg.norm(q, axis=1)[:, None]
    return shift
