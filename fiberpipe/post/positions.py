"""Fiber-position error against reference mid-lines (the study's Fig. 16 comparison)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.optimize import linear_sum_assignment

from fiberpipe.polylines import resample_arclength


# densified points per block of a reference line (the nearest-point search's unit, see _nearest)
_BLOCK = 16


class ReferenceMidlines:
    """Reference mid-lines prepared once for :func:`position_error`: each polyline densified (step:
    a tenth of the median segment length unless given), its points in blocks of ``_BLOCK``
    consecutive ones with their bounding boxes, and the bounding box of each line. Build it once
    when several frames are compared with the same reference."""

    def __init__(self, ref_points, ref_offsets, *, step_m: float | None = None):
        ref_points = np.asarray(ref_points, float)
        ref_offsets = np.asarray(ref_offsets)
        if step_m is None:
            seg = np.linalg.norm(np.diff(ref_points, axis=0), axis=1)
            step_m = max(float(np.median(seg)) / 10, 1e-9)
        self.step_m = float(step_m)
        dense = [resample_arclength(ref_points[ref_offsets[j] : ref_offsets[j + 1]], step_m)
                 for j in range(len(ref_offsets) - 1)]
        self.points = np.ascontiguousarray(np.concatenate(dense) if dense else np.zeros((0, 3)))
        counts = np.array([len(d) for d in dense], np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        # blocks: each line's points cut every _BLOCK from its start, with their bounding boxes
        starts = [np.arange(self.offsets[j], self.offsets[j + 1], _BLOCK, dtype=np.int64) for j in range(len(dense))]
        self.block_offsets = np.concatenate([[0], np.cumsum([len(b) for b in starts])]).astype(np.int64)
        self.block_start = np.concatenate(starts) if starts else np.zeros(0, np.int64)
        self.block_end = np.append(self.block_start[1:], len(self.points)).astype(np.int64)
        self.block_lo, self.block_hi, self.lo, self.hi = (np.zeros((0, 3)),) * 4
        if len(self.points):
            self.block_lo = np.minimum.reduceat(self.points, self.block_start, axis=0)
            self.block_hi = np.maximum.reduceat(self.points, self.block_start, axis=0)
            self.lo = np.minimum.reduceat(self.points, self.offsets[:-1], axis=0)
            self.hi = np.maximum.reduceat(self.points, self.offsets[:-1], axis=0)

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def distances(self, points, j: int) -> np.ndarray:
        """Distance [m] of each of ``points`` to the nearest densified point of reference line j."""
        points = np.ascontiguousarray(points, dtype=float)
        out = np.empty(len(points))
        _distances_to_line(points, j, self.points, self.block_start, self.block_end, self.block_offsets,
                           self.block_lo, self.block_hi, out)
        return out


@njit(cache=True, error_model="numpy", inline="always")
def _box_distance2(p0, p1, p2, lo, hi, b):
    """Squared distance of a point to box ``b`` of ``lo``, ``hi`` (0 inside)."""
    g0 = max(lo[b, 0] - p0, p0 - hi[b, 0], 0.0)
    g1 = max(lo[b, 1] - p1, p1 - hi[b, 1], 0.0)
    g2 = max(lo[b, 2] - p2, p2 - hi[b, 2], 0.0)
    return g0 * g0 + g1 * g1 + g2 * g2


@njit(cache=True, error_model="numpy", inline="always")
def _block_min2(p0, p1, p2, pts, a, e, best):
    """The smaller of ``best`` and the squared distances of the point to ``pts[a:e]``."""
    for q in range(a, e):
        d0 = pts[q, 0] - p0
        d1 = pts[q, 1] - p1
        d2 = pts[q, 2] - p2
        best = min(best, d0 * d0 + d1 * d1 + d2 * d2)
    return best


@njit(cache=True, error_model="numpy")
def _nearest(p0, p1, p2, j, pts, b_start, b_end, b_off, b_lo, b_hi):
    """Distance of the point to the nearest densified point of line j, exactly: its blocks' boxes
    bound each block's points from below, so a block whose box is not nearer than the best point
    found so far is skipped; the search starts from the block with the nearest box."""
    first = b_off[j]
    best_b = first
    best_box = np.inf
    for b in range(first, b_off[j + 1]):
        d2 = _box_distance2(p0, p1, p2, b_lo, b_hi, b)
        if d2 < best_box:
            best_box = d2
            best_b = b
    best = _block_min2(p0, p1, p2, pts, b_start[best_b], b_end[best_b], np.inf)
    for b in range(first, b_off[j + 1]):
        if b != best_b and _box_distance2(p0, p1, p2, b_lo, b_hi, b) < best:
            best = _block_min2(p0, p1, p2, pts, b_start[b], b_end[b], best)
    return math.sqrt(best)


@njit(cache=True, error_model="numpy")
def _distances_to_line(points, j, pts, b_start, b_end, b_off, b_lo, b_hi, out):
    for q in range(points.shape[0]):
        out[q] = _nearest(points[q, 0], points[q, 1], points[q, 2], j, pts, b_start, b_end, b_off, b_lo, b_hi)


@njit(cache=True, error_model="numpy")
def _mean_distances(sim_points, sim_offsets, rows, cols, pts, b_start, b_end, b_off, b_lo, b_hi, cost):
    """``cost[rows[k], cols[k]]``: the mean distance of simulated fiber rows[k]'s nodes to the
    nearest densified points of reference line cols[k]."""
    for k in range(rows.shape[0]):
        i = rows[k]
        acc = 0.0
        for q in range(sim_offsets[i], sim_offsets[i + 1]):
            acc += _nearest(sim_points[q, 0], sim_points[q, 1], sim_points[q, 2], cols[k], pts, b_start, b_end,
                            b_off, b_lo, b_hi)
        cost[i, cols[k]] = acc / max(sim_offsets[i + 1] - sim_offsets[i], 1)


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
                acc += math.sqrt(_box_distance2(points[q, 0], points[q, 1], points[q, 2], lo, hi, b))
            out[i, b] = acc / max(n, 1)
    return out


def _fill_costs(cost, todo, sim_points, sim_offsets, ref):
    """The mean distances ``cost[i, j]`` of simulated fiber i's nodes to reference line j's
    densified points, for the pairs ``todo`` (bool (F_sim, F_ref))."""
    rows, cols = np.nonzero(todo)
    _mean_distances(sim_points, sim_offsets, rows.astype(np.int64), cols.astype(np.int64), ref.points,
                    ref.block_start, ref.block_end, ref.block_offsets, ref.block_lo, ref.block_hi, cost)


def position_error(sim_points, sim_offsets, ref_points=None, ref_offsets=None, *, step_m: float | None = None,
                   reference: ReferenceMidlines | None = None) -> dict:
    """Mean distance from each simulated mid-line to its reference mid-line, m.

    # Strategy: the reference polylines densified (step = a tenth of the median segment length) in
    # blocks of points (:class:`ReferenceMidlines`, or ``reference`` prepared once); fibers are
    # matched one to one by the Hungarian method on the mean distance of a fiber's nodes to a
    # reference line. The mean distance of the nodes to a reference line's bounding box bounds that
    # mean from below, so the means are computed only for each fiber's pairs below a threshold (at
    # first its four nearest boxes), the others enter the assignment at their bound; while the
    # assignment takes a pair at its bound, the thresholds double and it is solved again. The pairs
    # it keeps are then exact and no other assignment costs less, since every cost is at least its
    # bound: the assignment of the full cost matrix, at a fraction of its cost.

    Returns
    -------
    dict with ``per_fiber_m`` (F,), ``mean_m``, ``max_m``, ``matched`` pairs; ``per_fiber_p95_m``
    (F,), the 95th percentile of each simulated fiber's node distances to its matched reference,
    and ``p95_m`` over every matched node.
    """
    ref = reference if reference is not None else ReferenceMidlines(ref_points, ref_offsets, step_m=step_m)
    sim_points = np.asarray(sim_points, float)
    sim_offsets = np.asarray(sim_offsets, dtype=np.int64)
    n_sim, n_ref = len(sim_offsets) - 1, len(ref)
    bound = _mean_box_distance(sim_points, sim_offsets, ref.lo, ref.hi)
    cost = bound.copy()
    exact = np.zeros(bound.shape, bool)
    # first thresholds: each simulated fiber's 4 nearest reference boxes
    k = min(4, n_ref) - 1
    threshold = np.partition(bound, k, axis=1)[:, k] if n_sim and n_ref else np.zeros(n_sim)
    while True:
        todo = (bound <= threshold[:, None]) & ~exact
        _fill_costs(cost, todo, sim_points, sim_offsets, ref)
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
            d = ref.distances(sim_points[sim_offsets[r] : sim_offsets[r + 1]], c)
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
    for k, stage in enumerate(stages):
        ref = read(stage["fibers"])
        pos, u_used = frame_at(U_frames, frames, stage["displacement_m"])
        e = position_error(pos, node_offsets, ref.points_m, ref.offsets)
        overall.append({"stage": k, "displacement_m": float(stage["displacement_m"]), "U_m": u_used,
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
    stages = [{"displacement_m": stage.displacement, "fibers": stage.fibers} for stage in cfg.post.reference_stages]
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
