"""Fiber-position error against reference mid-lines (the study's Fig. 16 comparison)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from fiberpipe.polylines import resample_arclength


def position_error(sim_points, sim_offsets, ref_points, ref_offsets, *, step_m: float | None = None) -> dict:
    """Mean distance from each simulated mid-line to its reference mid-line, m.

    # Strategy: densify each reference polyline (step = a tenth of the mean segment length) and
    # query the simulated nodes against a k-d tree of it; fibers are matched one to one by the
    # Hungarian method on the mean distance when the counts or order may differ.

    Returns
    -------
    dict with ``per_fiber_m`` (F,), ``mean_m``, ``max_m``, ``matched`` pairs.
    """
    n_sim, n_ref = len(sim_offsets) - 1, len(ref_offsets) - 1
    if step_m is None:
        seg = np.linalg.norm(np.diff(ref_points, axis=0), axis=1)
        step_m = max(float(np.median(seg)) / 10, 1e-9)
    trees = [cKDTree(resample_arclength(ref_points[ref_offsets[j] : ref_offsets[j + 1]], step_m)) for j in range(n_ref)]
    cost = np.full((n_sim, n_ref), np.inf)
    for i in range(n_sim):
        p = sim_points[sim_offsets[i] : sim_offsets[i + 1]]
        for j in range(n_ref):
            cost[i, j] = float(np.mean(trees[j].query(p)[0]))
    finite = np.where(np.isfinite(cost), cost, 1e9)
    rows, cols = linear_sum_assignment(finite)
    per = np.full(n_sim, np.nan)
    for r, c in zip(rows, cols):
        per[r] = cost[r, c]
    ok = np.isfinite(per)
    return {
        "per_fiber_m": per,
        "mean_m": float(np.mean(per[ok])) if ok.any() else float("nan"),
        "max_m": float(np.max(per[ok])) if ok.any() else float("nan"),
        "matched": list(zip(rows.tolist(), cols.tolist())),
    }
