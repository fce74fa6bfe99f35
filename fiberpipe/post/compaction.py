"""Compaction laws fitted to the simulated curve (verification case 9 of docs/verification.md; reported, not tested).

van Wyk (J. Textile Inst. 37:T285, 1946) and Toll (Polym. Eng. Sci. 38:1337, 1998):
P = k E (v_f^n − v_f0^n), n = 3 for random bending-dominated assemblies; Gutowski et al.
(J. Compos. Mater. 21, 1987) for aligned bundles. Mean-field contacts per fiber for random
straight fibers: n_c ≈ 2 (L/D) v_f (Dodson, after Kerekes & Schell).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import curve_fit


def fit_van_wyk(vf: np.ndarray, pressure_pa: np.ndarray, youngs_modulus_pa: float, *, n: float | None = None) -> dict:
    """Fit P = k E (v_f^n − v_f0^n) with v_f0 the first v_f; n free unless given.

    Returns ``{"k", "n", "vf0", "r2"}``; NaNs when the loaded part is too short to fit.
    """
    vf = np.asarray(vf, float)
    p = np.asarray(pressure_pa, float)
    ok = np.isfinite(vf) & np.isfinite(p)
    vf, p = vf[ok], p[ok]
    out = {"k": float("nan"), "n": float("nan") if n is None else n, "vf0": float(vf[0]) if len(vf) else float("nan"), "r2": float("nan")}
    if len(vf) < 5 or np.ptp(vf) <= 0 or not np.any(p > 0):
        return out
    vf0 = vf[0]
    E = youngs_modulus_pa
    if n is None:
        f = lambda v, k, nn: k * E * (v**nn - vf0**nn)  # noqa: E731
        p0 = [1e-3, 3.0]
    else:
        f = lambda v, k: k * E * (v**n - vf0**n)  # noqa: E731
        p0 = [1e-3]
    try:
        popt, _ = curve_fit(f, vf, p, p0=p0, maxfev=20000)
    except (RuntimeError, ValueError):
        return out
    pred = f(vf, *popt)
    ss_res = float(np.sum((p - pred) ** 2))
    ss_tot = float(np.sum((p - p.mean()) ** 2)) or 1e-300
    out.update({"k": float(popt[0]), "n": float(popt[1]) if n is None else n, "r2": 1 - ss_res / ss_tot})
    return out


def mean_field_contacts(vf, length_m: float, diameter_m: float):
    """Contacts per fiber of random straight fibers, n_c ≈ 2 (L/D) v_f."""
    return 2 * (length_m / diameter_m) * np.asarray(vf, float)
