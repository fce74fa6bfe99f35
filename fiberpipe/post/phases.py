"""The compaction's phases (the study, section 4): rearrangement, transition, steep rise.

The study reads its load curve in three phases: a rearrangement with a near-zero load ("≈ 98 %
lower than the maximum load", U from 0 to 0.55 mm), a transition in which the load rises
progressively (0.55 to 1.12 mm), and the fibers' locking, where the load rises steeply. This module
finds the same boundaries on any F(U) curve with stated, reproducible criteria, so that a run's
report says where its phases are instead of leaving it to the eye.
"""

from __future__ import annotations

import numpy as np

ONSET_FRACTION = 0.02  # rearrangement ends where the load first exceeds 2 % of its peak (the study's "≈ 98 % lower")
STEEP_FACTOR = 1.5  # a steep phase: the last segment's slope ≥ 1.5 × the mean slope since the onset
WINDOW_M = 0.05e-3  # window of the load means (contact bursts average out; the fast-settings windows)
MIN_SEGMENT_WINDOWS = 2  # each of the two fitted segments spans at least this many windows


def compaction_phases(U_m, F_N, *, window_m: float = WINDOW_M, onset_fraction: float = ONSET_FRACTION,
                      steep_factor: float = STEEP_FACTOR) -> dict:
    """Phase boundaries of a compaction curve.

    # Strategy: on the loading branch (up to the largest U), average F in U windows of
    # ``window_m`` (a paper-40 curve is a sequence of contact bursts: single samples scatter by
    # ±0.05 N). The rearrangement ends where the window means first cross ``onset_fraction`` of
    # their peak (linear between window centres; the loading's start if the first window already
    # does). Between that onset and the peak window, fit a
    # continuous two-segment line (slopes b₁ then b₂, breakpoint at a window centre, least squares);
    # the load "rises steeply" from the breakpoint if b₂ ≥ ``steep_factor`` × the mean slope
    # s̄ = (F̄_peak − F̄_onset)/(U_peak − U_onset). A straight rise gives b₂ ≈ s̄ (no steep phase); a
    # flat transition then a rise over its last third gives b₂ ≈ 3 s̄.

    Parameters
    ----------
    U_m : (T,) float, m — plate travel (increasing during the loading).
    F_N : (T,) float, N — load.

    Returns
    -------
    dict — ``rearrangement_end_U_m`` (None if the load never exceeds zero), ``steep_start_U_m``
    (None when there is no steep phase), ``mean_slope_N_per_m`` s̄, ``transition_slope_N_per_m``
    b₁, ``steep_slope_N_per_m`` b₂, ``steepness`` b₂/s̄, ``peak_window_load_N``, ``peak_U_m``
    (centre of the peak window) and the criteria used.
    """
    U = np.asarray(U_m, float)
    F = np.asarray(F_N, float)
    out = {"window_m": float(window_m), "onset_fraction": float(onset_fraction), "steep_factor": float(steep_factor),
           "rearrangement_end_U_m": None, "steep_start_U_m": None, "mean_slope_N_per_m": None,
           "transition_slope_N_per_m": None, "steep_slope_N_per_m": None, "steepness": None,
           "peak_window_load_N": None, "peak_U_m": None}
    if U.size < 2 or not np.all(np.isfinite(U)) or not np.all(np.isfinite(F)):
        return out
    k = int(np.argmax(U)) + 1
    U, F = U[:k], F[:k]
    edges = np.arange(max(float(U.min()), 0.0), float(U.max()) + window_m, window_m)
    idx = np.digitize(U, edges) - 1
    uc, fm = [], []
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            uc.append(0.5 * (edges[b] + edges[b + 1]))
            fm.append(float(F[sel].mean()))
    uc, fm = np.asarray(uc), np.asarray(fm)
    if fm.size == 0 or fm.max() <= 0.0:
        return out
    p = int(np.flatnonzero(fm == fm.max())[-1])
    thr = onset_fraction * fm[p]
    i = int(np.flatnonzero(fm > thr)[0])
    if i == 0:  # loaded from the first window on: no rearrangement
        u1 = float(edges[0])
    else:  # the crossing, linear between the window centres
        u1 = float(uc[i - 1] + (thr - fm[i - 1]) * (uc[i] - uc[i - 1]) / (fm[i] - fm[i - 1]))
    out.update(rearrangement_end_U_m=u1, peak_window_load_N=float(fm[p]), peak_U_m=float(uc[p]))
    if uc[p] <= u1:
        return out
    sbar = (fm[p] - thr) / (uc[p] - u1)
    out["mean_slope_N_per_m"] = float(sbar)
    x = np.r_[u1, uc[i:p + 1]]
    y = np.r_[thr, fm[i:p + 1]]
    best = None
    for j in range(MIN_SEGMENT_WINDOWS, len(x) - MIN_SEGMENT_WINDOWS):
        A = np.c_[np.ones_like(x), np.minimum(x - x[j], 0.0), np.maximum(x - x[j], 0.0)]
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        sse = float(np.sum((A @ coef - y) ** 2))
        if best is None or sse < best[0]:
            best = (sse, j, coef)
    if best is None:  # too short a rise to split in two
        return out
    _, j, (_, b1, b2) = best
    out.update(transition_slope_N_per_m=float(b1), steep_slope_N_per_m=float(b2),
               steepness=float(b2 / sbar) if sbar > 0 else None)
    if sbar > 0 and b2 >= steep_factor * sbar:
        out["steep_start_U_m"] = float(x[j])
    return out


def describe(ph: dict) -> str:
    """One line for a report: the three phases' U ranges (mm)."""
    u1 = ph.get("rearrangement_end_U_m")
    if u1 is None:
        return "no load: rearrangement only"
    pct = 100 * ph["onset_fraction"]
    text = f"rearrangement 0–{u1 * 1e3:.2f} mm (load < {pct:g} % of its peak)"
    u2 = ph.get("steep_start_U_m")
    s = ph.get("steepness")
    if u2 is not None:
        text += (f", transition {u1 * 1e3:.2f}–{u2 * 1e3:.2f} mm, steep rise from {u2 * 1e3:.2f} mm "
                 f"(slope {s:.1f}× the mean since the onset)")
    else:
        text += f", then a rise with no steep phase" + (f" (last segment {s:.1f}× the mean slope, < {ph['steep_factor']:g})"
                                                          if s is not None else "")
    return text
