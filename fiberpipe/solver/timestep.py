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
Δt = 9.1e-8 s (the table in notes/physics.md A3: full 12×12 Timoshenko eigenvalues).
Stiffness-proportional damping β adds ξ = β ω/2 in every mode.

Translation along an axis ``a`` fixed at every node (the study's axial lock, effect
``constraints`` with ``lock_axial: all``): the axial mode can only move the nodes across ``a``, so
its stiffness along the element acts through the component ``t⊥`` of the element's unit tangent
perpendicular to ``a``: ω² = 4E/(ρL²)·|t⊥|². Fibers tilt and bend during a run, so |t⊥| is taken
as at least sin 30° (and its rest value if larger): the axial limit becomes ≥ 2 L/c and, for
quasi-parallel fibers along ``a``, the shear mode governs (1.19e-7 s instead of 9.1e-8 s for the
study's elements). With Δt = 0.95 × the shear limit the axial mode stays stable up to a tilt of
53° from ``a``.
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


# smallest |t⊥| assumed for an element whose nodes' translation along the locked axis is fixed
LOCKED_AXIAL_MIN_SIN = 0.5  # sin 30°: the fibers may tilt that far during the run


def stable_time_step(model: Model, *, beta_s: float = 0.0, locked_axis: int | None = None) -> TimeStepReport:
    """Element-by-element stable time step (s) of ``model`` (see the module docstring).

    Parameters
    ----------
    model : Model
    beta_s : float, s — stiffness-proportional damping coefficient (reduces the limit).
    locked_axis : 0, 1, 2 or None — the axis along which every node's translation is fixed (the
        axial lock of all nodes): the axial mode acts only through the tangent's component across it.
    """
    mat = model.material
    E, G, rho = mat.youngs_modulus_pa, mat.G, mat.density_kg_m3
    s = model.rotary_inertia_scale
    rho = rho * model.mass_scale
    L = model.el_L0
    r = model.el_radius
    ks = mat.shear_factor
    axial_factor = np.ones_like(L)
    if locked_axis is not None:
        a = model.nodes_m[model.el_n1]
        b = model.nodes_m[model.el_n1 + 1]
        t = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
        t_perp2 = 1.0 - t[:, int(locked_axis)] ** 2
        axial_factor = np.maximum(t_perp2, LOCKED_AXIAL_MIN_SIN**2)
    w2 = {
        "axial": 4.0 * E / rho / L**2 * axial_factor,
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
