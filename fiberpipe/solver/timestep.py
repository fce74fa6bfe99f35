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

from .model import Model


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
