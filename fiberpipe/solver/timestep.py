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
    six-fibre scene at 1000 N/m: up to +4 % of the loads' work at `dt_safety` 0.45, 0.2 and 0.1
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
    ``iterations``: Lanczos matrix–vector products.
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
    (default: the rest state, where it is the material stiffness), applied matrix-free by central
    differences of :func:`fiberpipe.solver._kernels_beam.beam_forces` in positions and spatial spins;
    the symmetric ``M^{-1/2} K M^{-1/2}`` goes to Lanczos (``scipy.sparse.linalg.eigsh``).

    Penalties on top: a plane penalty ``k_i = c m_i (2/Δt)²`` adds at most ``4c/Δt²`` to ω² (a
    diagonal, positive term: Weyl's inequality), so ``(ω_max² + 4c/Δt²) Δt² ≤ 4`` holds for
    ``Δt ≤ (2/ω_max) √(1 − c)``. Fiber–fiber contact stiffness is not in the bound: it is small
    against the beams' at the study's loads (docs/benchmarks.md, "Stable step per active mode",
    measured) and ``solver.dt_safety`` keeps a margin for it.

    ``extra_forces(x) -> (N, 3)`` (optional): further position-dependent forces whose tangent is
    added to K (e.g. the fiber–fiber contact at a state, for the measurements of docs/benchmarks.md).
    """
    from scipy.sparse.linalg import LinearOperator, eigsh

    n = model.n_nodes
    x0 = np.ascontiguousarray(model.nodes_m if x is None else x, dtype=np.float64)
    q0 = np.ascontiguousarray(model.quats0 if q is None else q, dtype=np.float64)
    free = _free_dofs(n, np.asarray(fix_mask), None).ravel()
    inv_sqrt_m = np.column_stack([np.repeat(1.0 / np.sqrt(model.mass)[:, None], 3, axis=1),
                                  1.0 / np.sqrt(model.J)]).ravel()
    beams = (model.el_n1, model.el_invL0, model.el_C, model.el_Dk, model.gamma_rest, model.theta_rest)
    L = float(np.min(model.el_L0))
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
        # (K u = −(F(+h u) − F(−h u)) / (2h), exact for the linear tangent up to O(h²))
        h = 1e-6 / nrm
        diff = np.zeros((n, 6))
        _beam_force_difference(x0, q0, uu, h, beams, diff)
        if extra_forces is not None:
            diff[:, :3] += extra_forces(x0 + h * uu[:, :3]) - extra_forces(x0 - h * uu[:, :3])
        calls[0] += 1
        return ((-diff.ravel() / (2.0 * h)) * inv_sqrt_m)[free]

    nf = int(free.sum())
    op = LinearOperator((nf, nf), matvec=matvec, dtype=np.float64)
    lam = float(eigsh(op, k=1, which="LA", tol=tol, return_eigenvectors=False, ncv=min(nf, 40),
                      v0=np.random.default_rng(0).standard_normal(nf))[0])
    om = math.sqrt(max(lam, 0.0))
    xi = 0.5 * beta_s * om
    dt_b = 2.0 / om * (math.sqrt(1.0 + xi * xi) - xi) if om > 0 else math.inf
    # rounded down to 6 significant digits: the Lanczos result may differ in its last bits between
    # machines or BLAS builds, and a resumed run must find the checkpoint's step again
    dt_s = _round_down(dt_b * math.sqrt(1.0 - penalty_factor), 6)
    return ModalTimeStep(dt_s, dt_b, om, float(penalty_factor), nf, calls[0])


def _round_down(x: float, digits: int) -> float:
    """``x`` > 0 rounded down to ``digits`` significant digits."""
    if not (x > 0 and math.isfinite(x)):
        return x
    e = math.floor(math.log10(x)) - digits + 1
    return math.floor(x / 10.0**e) * 10.0**e
