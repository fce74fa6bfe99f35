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
    dict with ``per_fiber_m`` (F,), ``mean_m``, ``max_m``, ``matched`` pairs; ``per_fiber_p95_m``
    (F,), the 95th percentile of each simulated fiber's node distances to its matched reference,
    and ``p95_m`` over every matched node.
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
    per95 = np.full(n_sim, np.nan)
    nodes = []
    for r, c in zip(rows, cols):
        per[r] = cost[r, c]
        if np.isfinite(cost[r, c]):
            d = trees[c].query(sim_points[sim_offsets[r] : sim_offsets[r + 1]])[0]
            per95[r] = float(np.percentile(d, 95))
            nodes.append(d)
    ok = np.isfinite(per)
    return {
        "per_fiber_p95_m": per95,
        "p95_m": float(np.percentile(np.concatenate(nodes), 95)) if nodes else float("nan"),
        "per_fiber_m": per,
        "mean_m": float(np.mean(per[ok])) if ok.any() else float("nan"),
        "max_m": float(np.max(per[ok])) if ok.any() else float("nan"),
        "matched": list(zip(rows.tolist(), cols.tolist())),
    }


def frame_at(U_frames, frames, U_m: float):
    """Node positions at the plate displacement ``U_m``: linear between the two output frames
    that bracket it (frames of a monotonic loading; the nearest end frame outside their range).
    Returns ``(positions, U_used)``."""
    U_frames = np.asarray(U_frames, float)
    k = int(np.searchsorted(U_frames, U_m))
    if k <= 0:
        return frames[0], float(U_frames[0])
    if k >= len(U_frames):
        return frames[-1], float(U_frames[-1])
    u0, u1 = U_frames[k - 1], U_frames[k]
    w = 0.0 if u1 <= u0 else (U_m - u0) / (u1 - u0)
    return (1 - w) * frames[k - 1] + w * frames[k], float(U_m)


def reference_stage_errors(stages, U_frames, frames, node_offsets, read) -> tuple[list[dict], list[dict]]:
    """The position error at each reference stage (the study's scan series, its Fig. 16): for each
    ``{displacement_m, fibers}``, the simulated mid-lines at that U (:func:`frame_at`) against the
    stage's scanned ones (``read(path)`` -> Polylines), matched one to one (:func:`position_error`).

    Returns one row per stage (``stage``, ``displacement_m``, ``U_m`` used, ``fibers_matched``,
    ``mean_m``, ``p95_m``, ``max_fiber_mean_m``) and one row per stage and simulated fiber
    (``stage``, ``fiber``, ``reference_fiber``, ``mean_m``, ``p95_m``)."""
    overall, per_fiber = [], []
    for k, st in enumerate(stages):
        ref = read(st["fibers"])
        pos, u_used = frame_at(U_frames, frames, st["displacement_m"])
        e = position_error(pos, node_offsets, ref.points_m, ref.offsets)
        overall.append({"stage": k, "displacement_m": float(st["displacement_m"]), "U_m": u_used,
                        "fibers_matched": int(np.sum(np.isfinite(e["per_fiber_m"]))), "mean_m": e["mean_m"],
                        "p95_m": e["p95_m"], "max_fiber_mean_m": e["max_m"]})
        match = dict(e["matched"])
        for f in range(len(node_offsets) - 1):
            per_fiber.append({"stage": k, "fiber": f, "reference_fiber": int(match.get(f, -1)),
                              "mean_m": float(e["per_fiber_m"][f]), "p95_m": float(e["per_fiber_p95_m"][f])})
    return overall, per_fiber


def write_reference_stages(out_dir, cfg, sim, U_frames, summary: dict) -> list[str]:
    """``post.reference_stages``: ``reference_stages.csv`` (one row per stage), ``reference_stages_fibers.csv``
    (per stage and fiber) and ``reference_stages.png``; the rows also go to ``summary``."""
    from pathlib import Path

    from fiberpipe.artifacts import read_fibers
    from fiberpipe.errors import ConfigError
    from fiberpipe.post.tables import write_csv

    if U_frames is None:
        raise ConfigError("post.reference_stages needs plates (the stages are given by the plate displacement U)")
    out_dir = Path(out_dir)
    stages = [{"displacement_m": st.displacement, "fibers": st.fibers} for st in cfg.post.reference_stages]
    overall, per_fiber = reference_stage_errors(stages, U_frames, np.asarray(sim.frames_positions),
                                                np.asarray(sim.mesh.node_offsets), read_fibers)
    write_csv(out_dir / "reference_stages.csv", {k: [r[k] for r in overall] for k in overall[0]})
    write_csv(out_dir / "reference_stages_fibers.csv", {k: [r[k] for r in per_fiber] for k in per_fiber[0]})
    summary["reference_stages"] = overall
    made = ["reference_stages.csv", "reference_stages_fibers.csv"]
    if cfg.post.plots:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from fiberpipe.post.plots import _save

        fig, ax = plt.subplots(figsize=(6, 4))
        u = np.array([r["U_m"] for r in overall]) * 1e3
        for r in per_fiber:
            ax.plot(overall[r["stage"]]["U_m"] * 1e3, r["mean_m"] * 1e3, ".", color="0.6", ms=3)
        ax.plot(u, [r["mean_m"] * 1e3 for r in overall], "o-", label="mean over fibers")
        ax.plot(u, [r["p95_m"] * 1e3 for r in overall], "s--", label="p95 over nodes")
        ax.set_xlabel("plate displacement U [mm]")
        ax.set_ylabel("distance to the scanned mid-lines [mm]")
        ax.set_title("position error at the reference stages (grey: per fiber)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend()
        _save(fig, out_dir / "reference_stages.png")
        made.append("reference_stages.png")
    return made
