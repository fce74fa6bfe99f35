"""Fiber-position error against reference mid-lines (the study's Fig. 16 comparison)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from fiberpipe.polylines import resample_arclength


class ReferenceMidlines:
    """Reference mid-lines prepared once for :func:`position_error`: each polyline densified (step:
    a tenth of the median segment length unless given), with a k-d tree and a bounding box of its
    points. Build it once when several frames are compared with the same reference."""

    def __init__(self, ref_points, ref_offsets, *, step_m: float | None = None):
        ref_points = np.asarray(ref_points, float)
        ref_offsets = np.asarray(ref_offsets)
        if step_m is None:
            seg = np.linalg.norm(np.diff(ref_points, axis=0), axis=1)
            step_m = max(float(np.median(seg)) / 10, 1e-9)
        self.step_m = float(step_m)
        dense = [resample_arclength(ref_points[ref_offsets[j] : ref_offsets[j + 1]], step_m)
                 for j in range(len(ref_offsets) - 1)]
        self.trees = [cKDTree(d) for d in dense]
        self.lo = np.array([d.min(axis=0) for d in dense]).reshape(-1, 3)
        self.hi = np.array([d.max(axis=0) for d in dense]).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self.trees)


@njit(cache=True, fastmath=True, error_model="numpy")
def _mean_box_distance(points, offsets, lo, hi):
    """(F, B): the mean over each fiber's points (``offsets``) of their distances to each of the B
    axis-aligned boxes ``lo``, ``hi``: a lower bound of the mean distance of those points to any
    point set inside a box."""
    n_fib = offsets.shape[0] - 1
    out = np.zeros((n_fib, lo.shape[0]))
    for i in range(n_fib):
        n = offsets[i + 1] - offsets[i]
        for b in range(lo.shape[0]):
            acc = 0.0
            for q in range(offsets[i], offsets[i + 1]):
                g2 = 0.0
                for c in range(3):
                    g = max(lo[b, c] - points[q, c], points[q, c] - hi[b, c], 0.0)
                    g2 += g * g
                acc += math.sqrt(g2)
            out[i, b] = acc / max(n, 1)
    return out


def _fill_costs(cost, todo, sim_points, fiber_of_node, n_nodes, ref):
    """The mean distances ``cost[i, j]`` of simulated fiber i's nodes to reference j's points, for
    the pairs ``todo`` (bool (F_sim, F_ref)): one tree query per reference line over the nodes of
    every simulated fiber it is asked for."""
    for j in np.nonzero(todo.any(axis=0))[0]:
        take = todo[fiber_of_node, j]
        d = ref.trees[j].query(sim_points[take])[0]
        sums = np.bincount(fiber_of_node[take], weights=d, minlength=len(n_nodes))
        rows = np.nonzero(todo[:, j])[0]
        cost[rows, j] = sums[rows] / n_nodes[rows]


def position_error(sim_points, sim_offsets, ref_points=None, ref_offsets=None, *, step_m: float | None = None,
                   reference: ReferenceMidlines | None = None) -> dict:
    """Mean distance from each simulated mid-line to its reference mid-line, m.

    # Strategy: the reference polylines densified (step = a tenth of the median segment length) in
    # one k-d tree each (:class:`ReferenceMidlines`, or ``reference`` prepared once); fibers are
    # matched one to one by the Hungarian method on the mean distance of a fiber's nodes to a
    # reference line. The mean distance of the nodes to a reference line's bounding box bounds that
    # mean from below, so the means are computed only for each fiber's pairs below a threshold (at
    # first its four nearest boxes), the others enter the assignment at their bound; while the
    # assignment takes a pair at its bound, the thresholds double and it is solved again. The pairs
    # it keeps are then exact and no other assignment costs less, since every cost is at least its
    # bound: the assignment of the full cost matrix, at a fraction of its k-d tree queries.

    Returns
    -------
    dict with ``per_fiber_m`` (F,), ``mean_m``, ``max_m``, ``matched`` pairs; ``per_fiber_p95_m``
    (F,), the 95th percentile of each simulated fiber's node distances to its matched reference,
    and ``p95_m`` over every matched node.
    """
    ref = reference if reference is not None else ReferenceMidlines(ref_points, ref_offsets, step_m=step_m)
    sim_points = np.asarray(sim_points, float)
    sim_offsets = np.asarray(sim_offsets)
    n_sim, n_ref = len(sim_offsets) - 1, len(ref)
    n_nodes = np.diff(sim_offsets)
    fiber_of_node = np.repeat(np.arange(n_sim), n_nodes)
    bound = _mean_box_distance(sim_points, sim_offsets.astype(np.int64), ref.lo, ref.hi)
    cost = bound.copy()
    exact = np.zeros(bound.shape, bool)
    # first thresholds: each simulated fiber's 4 nearest reference boxes
    k = min(4, n_ref) - 1
    threshold = np.partition(bound, k, axis=1)[:, k] if n_sim and n_ref else np.zeros(n_sim)
    while True:
        todo = (bound <= threshold[:, None]) & ~exact
        _fill_costs(cost, todo, sim_points, fiber_of_node, n_nodes, ref)
        exact |= todo
        finite = np.where(np.isfinite(cost), cost, 1e9)
        rows, cols = linear_sum_assignment(finite)
        if exact[rows, cols].all():
            break
        # the thresholds double, and each pair the assignment took at its bound is computed next
        # (so the loop ends: every pass computes at least one more pair)
        threshold = 2.0 * threshold
        took = ~exact[rows, cols]
        threshold[rows[took]] = np.maximum(threshold[rows[took]], bound[rows[took], cols[took]])
    per = np.full(n_sim, np.nan)
    per95 = np.full(n_sim, np.nan)
    nodes = []
    for r, c in zip(rows, cols):
        per[r] = cost[r, c]
        if np.isfinite(cost[r, c]):
            d = ref.trees[c].query(sim_points[sim_offsets[r] : sim_offsets[r + 1]])[0]
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
