"""Fragments and gaps: join the broken pieces of one fiber, drop fibers too short to mesh.

A real scan breaks fibers into pieces (a dim stretch below the threshold, a crossing the skeleton
cuts, a ring artefact), and leaves short bits (fiber ends at the volume's faces, debris). Both
tracers then return more, shorter fibers than there are. :func:`join_fragments` chains pieces whose
ends continue each other; :func:`drop_short` removes what is left below a length.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from ..polylines import Polylines, resample_arclength


def _end_direction(pts: np.ndarray, at_end: bool, reach_m: float) -> np.ndarray:
    """Unit outward tangent at one end of a polyline: from the mean of the points within
    ``reach_m`` of that end (at least the neighbouring point) to the end point."""
    p = pts if at_end else pts[::-1]
    e = p[-1]
    d = np.linalg.norm(p - e, axis=1)
    near = p[d <= reach_m]
    if len(near) < 2:
        near = p[-2:]
    u = e - near.mean(axis=0)
    n = np.linalg.norm(u)
    return u / n if n > 0 else np.zeros(3)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def join_fragments(polylines: Polylines, *, max_gap_m: float, max_offset_m: float,
                   max_angle_deg: float = 25.0, max_radius_ratio: float = 1.5,
                   spacing_m: float | None = None) -> tuple[Polylines, int]:
    """Chain fiber pieces whose ends continue each other across a gap.

    Two ends ``a`` (of piece i) and ``b`` (of piece j) are joined when all of these hold:

    - close: the gap ``|e_b - e_a|`` is at most ``max_gap_m``;
    - collinear: the outward tangents are nearly opposite (``angle(t_a, -t_b) <= max_angle_deg``)
      and, for a gap longer than ``max_offset_m``, the gap itself runs along both tangents (same
      bound);
    - in line: each end lies within ``max_offset_m`` of the other piece's extrapolated axis;
    - one fiber: the radii differ by at most the factor ``max_radius_ratio``.

    Candidate pairs are accepted greedily by increasing cost (gap, angle and offset, each relative
    to its bound), each end at most once and never closing a loop.

    Parameters
    ----------
    polylines : Polylines
        Traced mid-lines (x y z, m), each ordered along its fiber.
    max_gap_m, max_offset_m : float, m
    max_angle_deg : float
    max_radius_ratio : float (>= 1)
    spacing_m : float, optional
        Resampling step of a joined fiber (default: the mean point spacing of its pieces).

    Returns
    -------
    joined : Polylines
        Unjoined pieces unchanged and in their order, then the joined fibers; a joined fiber's
        radius is the length-weighted mean of its pieces'. ``meta`` is copied.
    n_joins : int
        Number of gaps bridged.
    """
    n = polylines.n_fibers
    if n < 2 or max_gap_m <= 0:
        return polylines, 0
    fibers = [polylines.fiber(i) for i in range(n)]
    lengths = polylines.lengths_m()
    radius = polylines.radius_m
    bounds = _JoinBounds(max_gap_m, max_offset_m, max_angle_deg, max_radius_ratio)
    cand = _join_candidates(fibers, lengths, radius, bounds)
    if not cand:
        return polylines, 0
    partner, n_joins = _pair_ends(sorted(cand), n)
    if n_joins == 0:
        return polylines, 0
    out_f, out_r = _chain_pieces(fibers, lengths, radius, partner, spacing_m if spacing_m is not None else max_gap_m / 4,
                                 spacing_m is None)
    res = Polylines.from_list(out_f, np.asarray(out_r))
    res.meta.update(polylines.meta)
    return res, n_joins


class _JoinBounds(NamedTuple):
    max_gap_m: float
    max_offset_m: float
    max_angle_deg: float
    max_radius_ratio: float


def _join_candidates(fibers: list, lengths, radius, b: _JoinBounds) -> list:
    """(cost, end a, end b) of every pair of piece ends that may be joined (:func:`join_fragments`'s
    rules); end 2 i is piece i's first point, 2 i + 1 its last."""
    # Strategy: a k-d tree over all end points finds the candidate pairs within max_gap; the
    # tangents come from the last ~2 gap lengths of each piece (the tracers' smoothing bends the
    # last point or two, a longer reach averages that out).
    n = len(fibers)
    reach = max(2.0 * b.max_gap_m, 4.0 * float(np.median(radius)))
    ends = np.empty((2 * n, 3))
    tang = np.empty((2 * n, 3))
    for i, p in enumerate(fibers):
        for side in (0, 1):  # 0: first point, 1: last point
            ends[2 * i + side] = p[-1] if side else p[0]
            tang[2 * i + side] = _end_direction(p, bool(side), min(reach, 0.5 * lengths[i]) if lengths[i] > 0 else reach)
    cand = []
    for a, c in cKDTree(ends).query_pairs(b.max_gap_m, output_type="ndarray"):
        i, j = a // 2, c // 2
        if i == j or max(radius[i], radius[j]) > b.max_radius_ratio * min(radius[i], radius[j]):
            continue
        ta, tb = tang[a], tang[c]
        if not (np.any(ta) and np.any(tb)):
            continue
        ang = _angle_deg(ta, -tb)
        if ang > b.max_angle_deg:
            continue
        g = ends[c] - ends[a]
        d = float(np.linalg.norm(g))
        if d > b.max_offset_m:
            u = g / d
            if _angle_deg(ta, u) > b.max_angle_deg or _angle_deg(-tb, u) > b.max_angle_deg:
                continue
        off_b = np.linalg.norm(g - np.dot(g, ta) * ta)  # c from a's extrapolated axis
        off_a = np.linalg.norm(g - np.dot(g, tb) * tb)
        off = max(off_a, off_b)
        if off > b.max_offset_m:
            continue
        cand.append((d / b.max_gap_m + ang / b.max_angle_deg + off / b.max_offset_m, int(a), int(c)))
    return cand


def _pair_ends(cand: list, n: int) -> tuple[np.ndarray, int]:
    """Accept candidate pairs in order (sorted by cost), each end at most once, never closing a
    loop (union-find over pieces). Returns each end's partner end (-1: free) and the joins."""
    partner = -np.ones(2 * n, dtype=np.int64)
    root = np.arange(n)

    def find(x):
        while root[x] != x:
            root[x] = root[root[x]]
            x = root[x]
        return x

    n_joins = 0
    for _, a, b in cand:
        if partner[a] >= 0 or partner[b] >= 0:
            continue
        ra, rb = find(a // 2), find(b // 2)
        if ra == rb:  # would close a loop
            continue
        partner[a], partner[b] = b, a
        root[ra] = rb
        n_joins += 1
    return partner, n_joins


def _chain_pieces(fibers: list, lengths, radius, partner: np.ndarray, step_m: float, mean_step: bool):
    """The fibers after joining: unjoined pieces unchanged and in order, then each chain of pieces
    (from a piece with a free end, following the partners) as one resampled line with the
    length-weighted mean radius. ``mean_step``: resample at the pieces' mean point spacing, else
    at ``step_m``."""
    n = len(fibers)
    out_f, out_r = [], []
    done = np.zeros(n, dtype=bool)
    for i in range(n):
        if partner[2 * i] < 0 and partner[2 * i + 1] < 0:
            out_f.append(fibers[i])
            out_r.append(radius[i])
            done[i] = True
    for i in range(n):
        if done[i] or (partner[2 * i] >= 0 and partner[2 * i + 1] >= 0):
            continue  # start chains at a piece with a free end
        # orient i so that its joined end is last
        chain = [(i, 1 if partner[2 * i + 1] >= 0 else 0)]
        done[i] = True
        while partner[2 * chain[-1][0] + chain[-1][1]] >= 0:
            nb = int(partner[2 * chain[-1][0] + chain[-1][1]])
            chain.append((nb // 2, 1 - nb % 2))
            done[nb // 2] = True
        line, r, spacing = _join_chain(fibers, lengths, radius, chain)
        out_f.append(resample_arclength(line, float(np.mean(spacing)) if mean_step and spacing else step_m))
        out_r.append(r)
    return out_f, out_r


def _join_chain(fibers: list, lengths, radius, chain: list):
    """One chain's points in order (each piece's points behind the previous end dropped: overlapping
    ends), its length-weighted radius and its pieces' point spacings."""
    pts, wsum, rsum, spacing = [], 0.0, 0.0, []
    for j, side_out_j in chain:
        p = fibers[j] if side_out_j == 1 else fibers[j][::-1]
        if pts:
            e, t = pts[-1][-1], pts[-1][-1] - pts[-1][-2] if len(pts[-1]) > 1 else np.zeros(3)
            ahead = (p - e) @ t > 0 if np.any(t) else np.ones(len(p), dtype=bool)
            p = p[int(np.argmax(ahead)) if ahead.any() else len(p):]
            if len(p) == 0:
                continue
        pts.append(p)
        wsum += lengths[j]
        rsum += lengths[j] * radius[j]
        if len(fibers[j]) > 1:
            spacing.append(lengths[j] / (len(fibers[j]) - 1))
    r = rsum / wsum if wsum > 0 else float(np.mean([radius[j] for j, _ in chain]))
    return np.concatenate(pts), r, spacing


def drop_short(polylines: Polylines, min_length_m: float) -> tuple[Polylines, np.ndarray]:
    """Remove fibers shorter than ``min_length_m``.

    Returns
    -------
    kept : Polylines
        The fibers of at least ``min_length_m``, in their order (``meta`` copied).
    dropped : (k,) int64 ndarray
        Indices (in ``polylines``) of the removed fibers.
    """
    lengths = polylines.lengths_m()
    short = lengths < min_length_m
    if not short.any():
        return polylines, np.zeros(0, dtype=np.int64)
    keep = np.flatnonzero(~short)
    res = Polylines.from_list([polylines.fiber(i) for i in keep], polylines.radius_m[keep])
    res.meta.update(polylines.meta)
    return res, np.flatnonzero(short)


def _cut(points: np.ndarray, s_cut: float) -> tuple[np.ndarray, np.ndarray]:
    """Split a polyline at arc length ``s_cut``; both halves keep the cut point."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    k = int(np.clip(np.searchsorted(s, s_cut), 1, len(points) - 1))
    w = (s_cut - s[k - 1]) / seg[k - 1] if seg[k - 1] > 0 else 0.0
    c = points[k - 1] + w * (points[k] - points[k - 1])
    return np.vstack([points[:k], c]), np.vstack([c, points[k:]])


def split_folds(polylines: Polylines, resample, *, max_turn_deg: float = 90.0,
                max_splits: int = 10_000) -> tuple[Polylines, int]:
    """Cut fibers where they fold back on themselves at the scale of their mesh.

    A skeleton path that runs into a junction and back out along a neighbour (a hairpin), or two
    fibers chained at a sharp corner, is not one fiber. Each fiber is resampled by ``resample``
    (the mesh's own node placement, e.g. ``lambda p: mesh.resample_polyline(p, element_length)``);
    where the turn between two consecutive elements exceeds ``max_turn_deg``, the fiber is cut at
    that node, and the pieces are checked again.

    Returns
    -------
    (Polylines, n_cuts)
    """
    cos_max = np.cos(np.radians(max_turn_deg))
    todo = [(polylines.fiber(i), float(polylines.radius_m[i])) for i in range(polylines.n_fibers)]
    out_f, out_r, n_cuts = [], [], 0
    while todo:
        p, r = todo.pop()
        nodes = resample(p) if len(p) > 1 else p
        seg = np.diff(nodes, axis=0)
        if len(seg) > 1 and n_cuts < max_splits:
            u = seg / np.maximum(np.linalg.norm(seg, axis=1, keepdims=True), 1e-300)
            c = np.sum(u[:-1] * u[1:], axis=1)
            k = int(np.argmin(c))
            if c[k] < cos_max:
                s_node = float(np.linalg.norm(seg[: k + 1], axis=1).sum())
                total = float(np.linalg.norm(seg, axis=1).sum())
                s_full = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
                a, b = _cut(p, s_node * s_full / total if total > 0 else 0.0)
                todo += [(a, r), (b, r)]
                n_cuts += 1
                continue
        out_f.append(p)
        out_r.append(r)
    if n_cuts == 0:
        return polylines, 0
    res = Polylines.from_list(out_f[::-1], np.asarray(out_r[::-1]))
    res.meta.update(polylines.meta)
    return res, n_cuts
