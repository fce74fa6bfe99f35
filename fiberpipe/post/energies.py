"""Energy accounting as Abaqus reports it (ALLKE, ALLSE, ALLVD, ALLFD, ALLWK, ALLPW).

ETOTAL = ALLKE + ALLIE + ALLVD + ALLFD − ALLWK − ALLPW should stay ≈ constant (Abaqus Theory
Manual, "Energy balance"); the run is quasi-static where kinetic energy is a small fraction of
the strain energy (the study asks K_e < 1e-2 S_e).
"""

from __future__ import annotations

import numpy as np

#: Our energy names and the Abaqus output identifiers they correspond to.
ABAQUS_NAMES = {
    "kinetic": "ALLKE",
    "strain": "ALLSE",
    "damping": "ALLVD",
    "friction": "ALLFD",
    "external": "ALLWK",
    "contact": "ALLPW",
}


def energy_balance(energy: dict[str, np.ndarray]) -> np.ndarray:
    """Relative energy balance residual over time, (T,).

    r(t) = |KE + SE + VD + FD − WK − PW − (same at t0)| / max(max |WK|, max(KE + SE), tiny).
    """
    z = np.zeros_like(next(iter(energy.values())), dtype=float)
    g = lambda k: np.asarray(energy.get(k, z), dtype=float)  # noqa: E731
    total = g("kinetic") + g("strain") + g("damping") + g("friction") - g("external") - g("contact")
    scale = max(np.max(np.abs(g("external"))), np.max(g("kinetic") + g("strain")), 1e-300)
    return np.abs(total - total[0]) / scale


def quasi_static_ratio(energy: dict[str, np.ndarray]) -> np.ndarray:
    """K_e / S_e over time (inf where the strain energy is zero)."""
    ke = np.asarray(energy.get("kinetic", 0.0), dtype=float)
    se = np.asarray(energy.get("strain", 0.0), dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(se > 0, ke / np.where(se > 0, se, 1.0), np.inf)
