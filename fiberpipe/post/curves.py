"""Force–displacement curve of the compaction (the study's Figs. 12 and 17)."""

from __future__ import annotations

import numpy as np


def force_displacement(sim, *, load_cell: str = "upper") -> tuple[np.ndarray, np.ndarray]:
    """Compaction displacement U (m) and load F (N), sampled on the history times.

    U is the displacement magnitude of the moving plate; F is the force the fibers exert on the
    plate carrying the load cell (``upper`` as in the study, else ``lower``), positive when
    pressing. The caller picks the other plate when the load-cell one is absent (``none``).

    Returns
    -------
    U_m : (T,) float64, m
    F_N : (T,) float64, N
    """
    h = sim.history
    if "plate_displacement" not in h or "plate_force" not in h:
        raise KeyError("the simulation has no plates: no force–displacement curve")
    disp = np.atleast_2d(np.asarray(h["plate_displacement"], dtype=float))
    force = np.atleast_2d(np.asarray(h["plate_force"], dtype=float))
    if disp.shape[0] != len(h["time"]):
        disp, force = disp.T, force.T
    moving = int(np.argmax(np.abs(disp).max(axis=0))) if disp.size else 0
    U = np.abs(disp[:, moving])
    col = 1 if load_cell == "upper" else 0
    return U, force[:, col]


def curve_error(U_ref, F_ref, U, F, *, scale: float | None = None) -> float:
    """Relative L2 error of a force–displacement curve against a reference on the reference's U.

    error = ||F(U_ref) − F_ref||₂ / ||F_ref||₂ (or / ``scale`` × √n if given), with F interpolated
    linearly in U; U beyond the tested run's range counts as missing (error 1 on that part).
    """
    U_ref, F_ref = np.asarray(U_ref), np.asarray(F_ref)
    order = np.argsort(U)
    Fi = np.interp(U_ref, np.asarray(U)[order], np.asarray(F)[order], left=np.nan, right=np.nan)
    Fi = np.where(np.isfinite(Fi), Fi, 0.0)
    denom = np.linalg.norm(F_ref) if scale is None else scale * np.sqrt(len(F_ref))
    return float(np.linalg.norm(Fi - F_ref) / max(denom, 1e-300))
