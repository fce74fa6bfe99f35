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

    # Strategy: on the loading branch (from the first sample to the largest U), average F in U
    # windows of ``window_m`` (a paper-40 curve is a sequence of contact bursts: single samples
    # scatter by ±0.05 N); each window is placed at the mean U of its samples. The rearrangement
    # ends where the window means cross ``onset_fraction`` of their peak for the last time before
    # the peak (linear between the windows; a burst that falls back below it is still
    # rearrangement); if no window before the peak is below it, the bundle carries load from the
    # start and there is no rearrangement. From the onset (U₁, F₁) to the peak window, fit a
    # continuous two-segment line (slopes b₁ then b₂, breakpoint at a window, least squares, at
    # least ``MIN_SEGMENT_WINDOWS`` windows each side); the load "rises steeply" from the breakpoint
    # if b₂ ≥ ``steep_factor`` × the mean slope s̄ = (F̄_peak − F₁)/(U_peak − U₁). A straight rise
    # gives b₂ ≈ s̄ (no steep phase); a flat transition then a rise over its last third gives
    # b₂ ≈ 3 s̄. The breakpoint cannot be placed in the last ``MIN_SEGMENT_WINDOWS`` windows before
    # the peak: a steep rise found at the latest testable window (``steep_start_censored``) may
    # begin later (a locking at U = 1.12 mm of a run that ends at 1.15 mm cannot be resolved with
    # 0.05 mm windows).

    Parameters
    ----------
    U_m : (T,) float, m — plate travel (increasing during the loading).
    F_N : (T,) float, N — load.

    Returns
    -------
    dict — ``status`` ("ok"; "no load": the window means never exceed 0; "undetermined": NaN,
    fewer than two samples or no increasing travel; "too short": too few windows to split),
    ``start_U_m`` (first sample's U), ``rearrangement_end_U_m`` (= ``start_U_m`` when loaded from
    the start; None unless "ok" or "too short"), ``steep_start_U_m`` (None when there is no steep
    phase), ``steep_start_censored``, ``mean_slope_N_per_m`` s̄, ``transition_slope_N_per_m`` b₁,
    ``steep_slope_N_per_m`` b₂, ``steepness`` b₂/s̄ (None if s̄ ≤ 0), ``peak_window_load_N``,
    ``peak_U_m`` (mean U of the peak window) and the criteria used.
    """
    U = np.asarray(U_m, float).ravel()
    F = np.asarray(F_N, float).ravel()
    out = {"window_m": float(window_m), "onset_fraction": float(onset_fraction), "steep_factor": float(steep_factor),
           "status": "undetermined", "start_U_m": None, "rearrangement_end_U_m": None, "steep_start_U_m": None,
           "steep_start_censored": False, "mean_slope_N_per_m": None, "transition_slope_N_per_m": None,
           "steep_slope_N_per_m": None, "steepness": None, "peak_window_load_N": None, "peak_U_m": None}
    if U.size < 2 or U.size != F.size or not np.all(np.isfinite(U)) or not np.all(np.isfinite(F)):
        return out
    k = int(np.argmax(U)) + 1
    U, F = U[:k], F[:k]
    u0 = float(U[0])
    if not U[-1] > u0:
        return out
    out["start_U_m"] = u0
    # window index by floor division, the last sample kept in the last window (no rounding edge)
    nwin = max(int(np.ceil((U[-1] - u0) / window_m - 1e-6)), 1)  # a sliver of < 1e-6 window joins the last
    idx = np.clip(np.floor((U - u0) / window_m).astype(np.int64), 0, nwin - 1)
    uc, fm = [], []
    for b in range(nwin):
        sel = idx == b
        if sel.any():
            uc.append(float(U[sel].mean()))
            fm.append(float(F[sel].mean()))
    uc, fm = np.asarray(uc), np.asarray(fm)
    if fm.max() <= 0.0:
        out["status"] = "no load"
        return out
    p = int(np.flatnonzero(fm == fm.max())[-1])
    thr = onset_fraction * fm[p]
    out.update(peak_window_load_N=float(fm[p]), peak_U_m=float(uc[p]))
    below = np.flatnonzero(fm[:p] <= thr)
    if below.size == 0:  # loaded from the first window on: no rearrangement
        u1, f1, i = u0, float(fm[0]), 0
        x, y = uc[: p + 1], fm[: p + 1]
    else:
        i = int(below[-1]) + 1  # the first window of the last crossing
        u1 = float(uc[i - 1] + (thr - fm[i - 1]) * (uc[i] - uc[i - 1]) / (fm[i] - fm[i - 1]))
        f1 = thr
        x, y = np.r_[u1, uc[i:p + 1]], np.r_[thr, fm[i:p + 1]]
    out["rearrangement_end_U_m"] = u1
    last = len(x) - MIN_SEGMENT_WINDOWS - 1  # the latest breakpoint with enough windows after it
    if last < MIN_SEGMENT_WINDOWS or uc[p] <= u1:
        out["status"] = "too short"
        return out
    out["status"] = "ok"
    sbar = (fm[p] - f1) / (uc[p] - u1)
    out["mean_slope_N_per_m"] = float(sbar)
    best = None
    for j in range(MIN_SEGMENT_WINDOWS, last + 1):
        A = np.c_[np.ones_like(x), np.minimum(x - x[j], 0.0), np.maximum(x - x[j], 0.0)]
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        sse = float(np.sum((A @ coef - y) ** 2))
        if best is None or sse < best[0]:
            best = (sse, j, coef)
    _, j, (_, b1, b2) = best
    steep = float(b2 / sbar) if sbar > 0 else None
    out.update(transition_slope_N_per_m=float(b1), steep_slope_N_per_m=float(b2), steepness=steep)
    if steep is not None and steep >= steep_factor:
        out["steep_start_U_m"] = float(x[j])
        out["steep_start_censored"] = bool(j == last)
    return out


def describe(ph: dict) -> str:
    """One line for a report: the three phases' U ranges (mm)."""
    status = ph.get("status", "ok")
    if status == "undetermined":
        return "phases undetermined (no increasing plate travel with finite loads)"
    if status == "no load":
        return "no load: rearrangement only"
    u0, u1 = ph["start_U_m"] * 1e3, ph["rearrangement_end_U_m"] * 1e3
    pct = 100 * ph["onset_fraction"]
    text = (f"rearrangement {u0:.2f}–{u1:.2f} mm (load < {pct:g} % of its peak)" if u1 > u0
            else f"loaded from the start (U = {u0:.2f} mm): no rearrangement")
    if status == "too short":
        return text + "; too few windows after it to test for a steep rise"
    u2, s = ph.get("steep_start_U_m"), ph.get("steepness")
    if u2 is not None:
        later = " or later (the last breakpoint the fit can place)" if ph.get("steep_start_censored") else ""
        text += (f", transition {u1:.2f}–{u2 * 1e3:.2f} mm, steep rise from {u2 * 1e3:.2f} mm{later} "
                 f"(slope {s:.1f}× the mean since the onset)")
    elif s is None:
        text += ", then no rise (the load does not grow after the onset)"
    else:
        text += f", then a rise with no steep phase (last segment {s:.1f}× the mean slope, < {ph['steep_factor']:g})"
    return text
