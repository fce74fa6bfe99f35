"""Mesoscale compaction laws fitted to a compaction run's pressure against v_f.

- van Wyk (J. Textile Inst. 37:T285, 1946) and Toll (Polym. Eng. Sci. 38:1337, 1998):
  p = k E (v_f^n − v_0^n); n = 3 for a random 3D assembly (van Wyk's inverse-cube law), n = 5 for a
  planar random mat (Toll). Fitted: k, n, v_0.
- Gutowski et al. (J. Compos. Mater. 21:650, 1987), an aligned bundle of wavy fibers:
  p = A_s (√(v_f/V_0) − 1) / (√(V_a/v_f) − 1)⁴, A_s = 3πE/β⁴ with β the span/rise ratio of the
  fibers' waviness; V_0 the volume fraction where the bundle starts to carry load, V_a the largest
  attainable. Fitted: A_s, V_0, V_a; β = (3πE/A_s)^¼ follows.

Both are fitted by least squares on log p over the loaded part of the curve (p > 0), with the
bounds the laws need (0 < v_0 < the first v_f of the range; V_a above the range's last v_f, below
the hexagonal packing limit π/(2√3)); each fit reports its range (v_f and p), its points and R² on
log p. A range with fewer points than the law's parameters is refused (:class:`FitRangeError`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from ..errors import FiberpipeError

#: hexagonal packing of parallel cylinders, the largest V_a the fit may take
HEXAGONAL_PACKING = math.pi / (2 * math.sqrt(3))


class FitRangeError(FiberpipeError):
    """A fit range holding fewer points than the law has parameters."""


def _range(vf, pressure_pa, law: str, n_parameters: int, vf_range):
    vf = np.asarray(vf, float)
    p = np.asarray(pressure_pa, float)
    keep = np.isfinite(vf) & np.isfinite(p) & (p > 0)
    if vf_range is not None:
        keep &= (vf >= vf_range[0]) & (vf <= vf_range[1])
    if np.count_nonzero(keep) < n_parameters or (np.count_nonzero(keep) and np.ptp(vf[keep]) <= 0):
        span = "" if vf_range is None else f" v_f in [{vf_range[0]:.4g}, {vf_range[1]:.4g}]"
        raise FitRangeError(f"the fit range{span} holds {np.count_nonzero(keep)} points with p > 0 at distinct v_f, "
                            f"fewer than the {n_parameters} parameters of {law}: widen the range", where="post")
    return vf[keep], p[keep]


def _summary(vf, p, model, params: dict) -> dict:
    residual = np.log(model) - np.log(p)
    total = float(np.sum((np.log(p) - np.log(p).mean()) ** 2)) or 1e-300
    return {**params, "r2_log": 1 - float(np.sum(residual**2)) / total, "points": int(len(vf)),
            "vf_range": [float(vf.min()), float(vf.max())], "pressure_range_pa": [float(p.min()), float(p.max())]}


def van_wyk_pressure(vf, k: float, n: float, vf0: float, youngs_modulus_pa: float):
    """p = k E (v_f^n − v_0^n) (van Wyk 1946; Toll 1998)."""
    return k * youngs_modulus_pa * (np.asarray(vf, float) ** n - vf0**n)


def fit_toll(vf, pressure_pa, youngs_modulus_pa: float, *, vf_range=None) -> dict:
    """Fit k, n and v_0 of p = k E (v_f^n − v_0^n) on log p; returns k, n, vf0, r2_log, points, ranges."""
    vf, p = _range(vf, pressure_pa, "van Wyk/Toll (k, n, v_0)", 3, vf_range)
    lo = float(vf.min())

    def residual(x):
        n, ratio = x[0], x[1]
        shape = vf**n - (ratio * lo) ** n
        return np.log(np.maximum(shape, 1e-300)) + x[2] - np.log(p)

    best = None
    for n0 in (2.0, 3.0, 5.0, 8.0):
        for ratio0 in (0.5, 0.9, 0.99):
            shape = vf**n0 - (ratio0 * lo) ** n0
            x0 = [n0, ratio0, float(np.median(np.log(p) - np.log(np.maximum(shape, 1e-300))))]
            fit = least_squares(residual, x0, bounds=([0.5, 0.0, -np.inf], [30.0, 1.0 - 1e-9, np.inf]))
            if best is None or fit.cost < best.cost:
                best = fit
    n, ratio, log_scale = best.x
    k = math.exp(log_scale) / youngs_modulus_pa
    vf0 = ratio * lo
    return _summary(vf, p, van_wyk_pressure(vf, k, n, vf0, youngs_modulus_pa), {"k": k, "n": float(n), "vf0": vf0})


def gutowski_pressure(vf, a_s_pa: float, v0: float, va: float):
    """p = A_s (√(v_f/V_0) − 1)/(√(V_a/v_f) − 1)⁴ (Gutowski et al. 1987)."""
    vf = np.asarray(vf, float)
    return a_s_pa * (np.sqrt(vf / v0) - 1) / (np.sqrt(va / vf) - 1) ** 4


def fit_gutowski(vf, pressure_pa, youngs_modulus_pa: float, *, vf_range=None) -> dict:
    """Fit A_s, V_0 and V_a of Gutowski's law on log p; also β = (3πE/A_s)^¼."""
    vf, p = _range(vf, pressure_pa, "Gutowski (A_s, V_0, V_a)", 3, vf_range)
    lo, hi = float(vf.min()), float(vf.max())
    if hi >= HEXAGONAL_PACKING:
        raise FitRangeError(f"the fit range reaches v_f = {hi:.4g}, at or above the hexagonal packing "
                            f"{HEXAGONAL_PACKING:.4f}: Gutowski's V_a cannot exceed it", where="post")

    def residual(x):
        v0, va, log_a = x
        return np.log(np.maximum(gutowski_pressure(vf, 1.0, v0, va), 1e-300)) + log_a - np.log(p)

    best = None
    for v0_ratio in (0.5, 0.9, 0.99):
        for va0 in (hi + 0.25 * (HEXAGONAL_PACKING - hi), hi + 0.75 * (HEXAGONAL_PACKING - hi)):
            v00 = v0_ratio * lo
            shape = gutowski_pressure(vf, 1.0, v00, va0)
            x0 = [v00, va0, float(np.median(np.log(p) - np.log(np.maximum(shape, 1e-300))))]
            fit = least_squares(residual, x0, bounds=([1e-6, hi * (1 + 1e-9), -np.inf],
                                                      [lo * (1 - 1e-9), HEXAGONAL_PACKING, np.inf]))
            if best is None or fit.cost < best.cost:
                best = fit
    v0, va, log_a = best.x
    a_s = math.exp(log_a)
    return _summary(vf, p, gutowski_pressure(vf, a_s, v0, va),
                    {"a_s_pa": a_s, "v0": float(v0), "va": float(va),
                     "beta": (3 * math.pi * youngs_modulus_pa / a_s) ** 0.25})


def mesoscale_fits(vf, pressure_pa, youngs_modulus_pa: float, *, vf_range=None) -> dict:
    """Both laws fitted to one curve, for post's summary.json; a law whose fit is refused records
    its one-line reason under ``error``."""
    out = {}
    for name, fit in (("toll", fit_toll), ("gutowski", fit_gutowski)):
        try:
            out[name] = fit(vf, pressure_pa, youngs_modulus_pa, vf_range=vf_range)
        except FitRangeError as exc:
            out[name] = {"error": str(exc)}
    return out


def report_lines(summary: dict, fmt) -> list[str]:
    """The report's section on the fitted laws (nothing when the run has no fit)."""
    fits = summary.get("mesoscale_laws")
    if not fits:
        return []
    lines = ["", "## Mesoscale laws fitted (docs/outputs.md)", "",
             "| law | parameters | fit range v_f | points | R² (log p) |", "| --- | --- | --- | --- | --- |"]
    toll, gut = fits.get("toll", {}), fits.get("gutowski", {})
    for label, f, params in (
            ("van Wyk/Toll p = kE(v_f^n − v_0^n)", toll, lambda f: f"k {fmt(f['k'])}, n {fmt(f['n'])}, v_0 {fmt(f['vf0'])}"),
            ("Gutowski", gut, lambda f: f"A_s {fmt(f['a_s_pa'], 'Pa')}, V_0 {fmt(f['v0'])}, V_a {fmt(f['va'])}, "
                                        f"β {fmt(f['beta'])}")):
        if "error" in f:
            lines.append(f"| {label} | {f['error']} | – | – | – |")
        elif f:
            lines.append(f"| {label} | {params(f)} | {fmt(f['vf_range'][0])}–{fmt(f['vf_range'][1])} | {f['points']} | "
                         f"{fmt(f['r2_log'])} |")
    return lines
