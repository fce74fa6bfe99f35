"""Accuracy of traced mid-lines against ground truth (docs/imaging.md, accuracy)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from ..polylines import Polylines
from ._util import resample_polyline, voxel_size_zyx, xyz_m_to_voxel

_DENSE_VOX = 0.2  # truth resampling step for point-to-line distances (error < 0.01 voxel)


def trace_accuracy(traced: Polylines, truth: Polylines, *, voxel_size_m) -> dict:
    """Compare traced mid-lines with true ones.

    Parameters
    ----------
    traced, truth : Polylines
        Mid-lines (x y z, m) and radii (m).
    voxel_size_m : float or (dz, dy, dx)
        Voxel size, m; distances are reported in voxels (of the voxel grid, per axis).

    Returns
    -------
    dict
        ``n_true``, ``n_traced``, ``n_matched``; ``recall`` (matched / true), ``precision``
        (matched / traced), ``f1``; ``mean_error_vox``, ``p95_error_vox``, ``max_error_vox``: distance
        of the traced points of matched fibers to their true mid-line, over the part of the trace
        alongside the true fiber; ``coverage``: fraction of the true length (all true fibers) that
        has a matched trace within one radius; ``n_merged``: traced fibers lying within 1.25 radius
        of two or more true fibers; ``n_split``: true fibers followed by two or more traced pieces;
        ``matches``: list of (traced index, true index, mean distance in voxels).
    """
    # Strategy: densify the true lines (0.2 voxel) into KD-trees, so point-to-line distances are
    # nearest-neighbour queries. Cost of a (traced, true) pair = mean distance of the traced points
    # whose nearest true point is not a true end point (i.e. alongside the true fiber), if at least
    # half of the trace is alongside. Hungarian assignment on that cost; a pair is a match if its
    # cost is below the true radius.
    v = voxel_size_zyx(voxel_size_m)
    T = [xyz_m_to_voxel(f, v) for f in truth]
    S = [xyz_m_to_voxel(f, v) for f in traced]
    r_true = np.asarray(truth.radius_m) / v[2]
    nt, ns = len(T), len(S)
    Td = [resample_polyline(t, _DENSE_VOX) for t in T]
    trees = [cKDTree(t) for t in Td]
    cost = np.full((ns, nt), np.inf)
    dists: dict = {}
    # candidate pairs by bounding-box proximity
    lo_t = np.array([t.min(0) for t in T]) if nt else np.zeros((0, 3))
    hi_t = np.array([t.max(0) for t in T]) if nt else np.zeros((0, 3))
    for i, s in enumerate(S):
        if len(s) == 0:
            continue
        pad = 3 * (r_true.max() if nt else 0)
        near = np.all((s.min(0) - pad <= hi_t) & (s.max(0) + pad >= lo_t), axis=1)
        for j in np.flatnonzero(near):
            d, idx = trees[j].query(s, distance_upper_bound=3 * r_true[j] + 1)
            along = (idx > 0) & (idx < len(Td[j]) - 1)
            if along.sum() < 0.5 * len(s):
                continue
            cost[i, j] = float(np.mean(d[along]))
            dists[(i, j)] = d[along]
    matches = []
    if ns and nt:
        C = np.where(np.isfinite(cost), cost, 1e9)
        rows, cols = linear_sum_assignment(C)
        for i, j in zip(rows, cols):
            if cost[i, j] < r_true[j]:
                matches.append((int(i), int(j), float(cost[i, j])))
    n_m = len(matches)
    errs = np.concatenate([dists[(i, j)] for i, j, _ in matches]) if matches else np.zeros(0)
    # coverage of the true length by the matched trace
    covered = 0.0
    total = 0.0
    matched_of_true = {j: i for i, j, _ in matches}
    for j, td in enumerate(Td):
        seg = np.linalg.norm(np.diff(td, axis=0), axis=1)
        total += seg.sum()
        if j in matched_of_true and len(td) > 1:
            sd = resample_polyline(S[matched_of_true[j]], _DENSE_VOX)
            d, _ = cKDTree(sd).query(td)
            ok = d < r_true[j]
            covered += seg[ok[:-1] & ok[1:]].sum()
    finite = np.isfinite(cost)
    near_merge = finite & (cost < 1.25 * r_true[None, :]) if nt else finite
    n_merged = int(np.sum(near_merge.sum(axis=1) >= 2))
    near_split = finite & (cost < r_true[None, :]) if nt else finite
    n_split = int(np.sum(near_split.sum(axis=0) >= 2))
    recall = n_m / nt if nt else float("nan")
    precision = n_m / ns if ns else float("nan")
    f1 = 2 * recall * precision / (recall + precision) if (recall + precision) > 0 else 0.0
    return {
        "n_true": nt, "n_traced": ns, "n_matched": n_m,
        "recall": recall, "precision": precision, "f1": f1,
        "mean_error_vox": float(errs.mean()) if errs.size else float("nan"),
        "p95_error_vox": float(np.percentile(errs, 95)) if errs.size else float("nan"),
        "max_error_vox": float(errs.max()) if errs.size else float("nan"),
        "coverage": covered / total if total > 0 else float("nan"),
        "n_merged": n_merged, "n_split": n_split, "matches": matches,
    }


_COLUMNS = [("n_true", "true", "{:d}"), ("n_traced", "traced", "{:d}"), ("n_matched", "matched", "{:d}"),
            ("recall", "recall", "{:.3f}"), ("precision", "precision", "{:.3f}"), ("f1", "F1", "{:.3f}"),
            ("mean_error_vox", "mean err (vox)", "{:.3f}"), ("p95_error_vox", "p95 err (vox)", "{:.3f}"),
            ("coverage", "coverage", "{:.3f}"), ("n_merged", "merged", "{:d}"), ("n_split", "split", "{:d}")]


def format_accuracy(rows, labels=None) -> str:
    """Format one accuracy dict, or a list of them, as a markdown table.

    Parameters
    ----------
    rows : dict or list of dict
        Outputs of :func:`trace_accuracy`.
    labels : list of str, optional
        First-column label of each row (e.g. "slices, seed 0").
    """
    if isinstance(rows, dict):
        rows = [rows]
    labels = labels or [str(i) for i in range(len(rows))]
    head = "| case | " + " | ".join(c[1] for c in _COLUMNS) + " |"
    sep = "| --- " * (len(_COLUMNS) + 1) + "|"
    lines = [head, sep]
    for lab, a in zip(labels, rows):
        cells = []
        for key, _, fmt in _COLUMNS:
            val = a.get(key, float("nan"))
            try:
                cells.append(fmt.format(val))
            except (ValueError, TypeError):
                cells.append(str(val))
        lines.append(f"| {lab} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
