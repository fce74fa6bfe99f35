"""Energy accounting as Abaqus reports it (ALLKE, ALLSE, ALLVD, ALLFD, ALLWK, ALLPW).

ETOTAL = ALLKE + ALLIE + ALLVD + ALLFD − ALLWK − ALLPW should stay ≈ constant (Abaqus Theory
Manual, "Energy balance"); the run is quasi-static where kinetic energy is a small fraction of
the strain energy (the study asks K_e < 1e-2 S_e).
"""

from __future__ import annotations

import numpy as np

from ..solver.integrator import state_energy

#: Our energy names and the Abaqus output identifiers they correspond to.
ABAQUS_NAMES = {
    "kinetic": "ALLKE",
    "strain": "ALLSE",
    "damping": "ALLVD",
    "friction": "ALLFD",
    "external": "ALLWK",
    "contact": "ALLPW",
}


def state_total(energy: dict[str, np.ndarray]) -> np.ndarray:
    """E = K + SE + E_contact + VD + FD − WK over time, J, (T,), from state functions: the stored
    contact energy (``contact_stored``) instead of the booked contact work ALLPW and the leapfrog's
    kinetic term ½ v_{n−½}·M v_{n+½} (``kinetic_leapfrog``, which central differences conserve
    exactly for a quadratic potential; ALLKE exceeds it by ¼Δt² Σ|f|²/m) with the damping booked in
    step with it (``damping_leapfrog``, where the history has it), so E stays
    constant only if the contact creates no energy. A history without ``contact_stored`` (written
    before it existed) gives Abaqus' ETOTAL = KE + SE + VD + FD − WK − PW, which closes whatever the
    contact does."""
    z = np.zeros_like(next(iter(energy.values())), dtype=float)
    g = lambda k: np.asarray(energy.get(k, z), dtype=float)  # noqa: E731
    if "contact_stored" in energy:
        ke = g("kinetic_leapfrog") if "kinetic_leapfrog" in energy else g("kinetic")
        vd = g("damping_leapfrog") if "damping_leapfrog" in energy and "kinetic_leapfrog" in energy else g("damping")
        return state_energy(ke, g("strain"), g("contact_stored"), vd, g("friction"), g("external"))
    return g("kinetic") + g("strain") + g("damping") + g("friction") - g("external") - g("contact")


def energy_balance(energy: dict[str, np.ndarray]) -> np.ndarray:
    """Relative energy balance residual over time, (T,): r(t) = |E(t) − E(t0)| / max(max |WK|,
    max(KE + SE), tiny) with E of :func:`state_total`."""
    z = np.zeros_like(next(iter(energy.values())), dtype=float)
    g = lambda k: np.asarray(energy.get(k, z), dtype=float)  # noqa: E731
    total = state_total(energy)
    scale = max(np.max(np.abs(g("external"))), np.max(g("kinetic") + g("strain")), 1e-300)
    return np.abs(total - total[0]) / scale


def quasi_static_ratio(energy: dict[str, np.ndarray]) -> np.ndarray:
    """K_e / S_e over time (inf where the strain energy is zero)."""
    ke = np.asarray(energy.get("kinetic", 0.0), dtype=float)
    se = np.asarray(energy.get("strain", 0.0), dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(se > 0, ke / np.where(se > 0, se, 1.0), np.inf)


def contact_energy_created(energy: dict[str, np.ndarray]) -> np.ndarray:
    """The energy the contact created so far, J, (T,): with the stored contact energy in the
    history, the largest excess of :func:`state_total` over its start; without it, a lower bound:

    The contact and friction forces' work is booked as work (ALLPW = the work of the normal and the
    friction forces on the fibers + the friction loss ALLFD, docs/contact.md), so the balance residual
    closes whatever the contact does. The normal forces' work is ``W_n = ALLPW − ALLFD − W_f`` with
    ``W_f`` the friction forces' work (history ``energy/friction_work``), and for a conservative law
    ``W_n`` is minus the energy stored in the penalties (≥ 0): so ``max(0, W_n)`` bounds the created
    energy from below, tight up to that stored energy. A history without ``friction_work`` (written
    before it existed) gives ``max(0, ALLPW − ALLFD)``, which also subtracts the friction's loss and
    its springs' energy: a weaker bound. docs/contact.md has what creates energy.
    """
    if "contact_stored" in energy:
        # the energy no load supplied, from state functions (exact, not a bound)
        return np.maximum(np.maximum.accumulate(state_total(energy) - state_total(energy)[0]), 0.0)
    z = np.zeros_like(next(iter(energy.values())), dtype=float)
    pw = np.asarray(energy.get("contact", z), dtype=float)
    fd = np.asarray(energy.get("friction", z), dtype=float)
    wf = np.asarray(energy.get("friction_work", z), dtype=float)
    return np.maximum(pw - fd - wf, 0.0)


def contact_energy_created_figures(energy: dict[str, np.ndarray]) -> tuple[float, float]:
    """(largest :func:`contact_energy_created` over the run [J], that over max |ALLWK| [–]; NaN
    without external work) — the figures of ``summary.json`` and ``fiberpipe compare``."""
    created = float(np.max(contact_energy_created(energy)))
    wk = float(np.max(np.abs(np.asarray(energy.get("external", [0.0]), dtype=float))))
    return created, (created / wk if wk > 0 else float("nan"))
