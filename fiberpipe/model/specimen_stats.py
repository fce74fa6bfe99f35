"""Statistics of a fiber specimen that the study reports for its scanned bundle.

The study (sections 3.2 and 4) characterises its 40-fiber specimen by the relative orientation Φ of
neighbouring fibers (an average of 6°, ranging 2–10°, which it uses as the one angle of its oblique
contact model) and by the average curvature of the fibers projected on the XZ and YZ planes (its
Table 4: 0.241 and 0.248 1/m at U = 0). These functions measure the same quantities on a set of
mid-lines, so a synthetic specimen can be compared with the scanned one.
"""

from __future__ import annotations

import numpy as np

from fiberpipe.polylines import Polylines
from fiberpipe.post.geometry import projected_curvature

# The study's numbers (sections 3.2 and 4, Table 4) the specimen is compared with.
STUDY_PHI_AVERAGE_DEG = 6.0
STUDY_PHI_RANGE_DEG = (2.0, 10.0)
STUDY_CURVATURE_XZ_PER_M = 0.241
STUDY_CURVATURE_YZ_PER_M = 0.248
STUDY_VOLUME_FRACTION = 0.377


def segment_distances(a0, a1, b0, b1):
    """Closest distances between segments [a0, a1] and [b0, b1], vectorised.

    Parameters
    ----------
    a0, a1, b0, b1 : (..., 3) float64 arrays, broadcast together

    Returns
    -------
    dist, s, t : arrays of the broadcast shape; the closest points are a0 + s (a1 − a0) and
    b0 + t (b1 − b0), s and t in [0, 1].
    """
    ta = np.asarray(a1, float) - a0
    tb = np.asarray(b1, float) - b0
    r = np.asarray(a0, float) - b0
    aa = np.sum(ta * ta, axis=-1)
    bb = np.sum(tb * tb, axis=-1)
    ab = np.sum(ta * tb, axis=-1)
    ar = np.sum(ta * r, axis=-1)
    br = np.sum(tb * r, axis=-1)
    den = aa * bb - ab * ab
    ok = den > 1e-12 * aa * bb
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(ok, np.clip((ab * br - ar * bb) / np.where(ok, den, 1.0), 0.0, 1.0), 0.0)
        t = (ab * s + br) / bb
        lo, hi = t < 0.0, t > 1.0
        s = np.where(lo, np.clip(-ar / aa, 0.0, 1.0), s)
        s = np.where(hi, np.clip((ab - ar) / aa, 0.0, 1.0), s)
        t = np.clip(t, 0.0, 1.0)
    d = r + s[..., None] * ta - t[..., None] * tb
    return np.linalg.norm(d, axis=-1), s, t


def _point_at(pts: np.ndarray, cum: np.ndarray, s: float) -> np.ndarray:
    s = min(max(s, 0.0), cum[-1])
    return np.array([np.interp(s, cum, pts[:, k]) for k in range(3)])


def neighbour_orientations(
    fibers: Polylines, *, reach_diameters: float = 1.2, window_m: float = 1e-3
) -> dict:
    """Relative orientation Φ of every pair of neighbouring fibers.

    Two fibers are neighbours when their centre lines come within ``reach_diameters`` × (r_i + r_j)
    of each other (1.2 diameters for equal fibers). Φ is the angle between their tangents at that
    closest approach, each tangent being the chord of the fiber over ``window_m`` of arc length
    centred on the closest point (1 mm = two diameters by default, so a node-scale kink does not
    count as an orientation), folded into [0°, 90°] (fibers have no direction).

    # Strategy: a k-d tree on the points (with a segment-length margin) lists the candidate fiber
    # pairs; for each, every segment pair is measured (:func:`segment_distances`) and the closest
    # one kept. One value per pair of fibers: quasi-straight fibers approach each other once.

    Returns
    -------
    dict of arrays, one entry per neighbour pair: ``i``, ``j`` (fiber indices, i < j),
    ``distance_m`` (closest centre-line distance), ``phi_deg``.
    """
    from scipy.spatial import cKDTree

    pts = fibers.points_m
    off = fibers.offsets
    nf = fibers.n_fibers
    seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cums, seg_max = [], 0.0
    for f in range(nf):
        ln = seg_len[off[f] : off[f + 1] - 1]
        cums.append(np.concatenate([[0.0], np.cumsum(ln)]))
        if ln.size:
            seg_max = max(seg_max, float(ln.max()))
    rad = fibers.radius_m
    reach_max = reach_diameters * 2 * float(rad.max()) if nf else 0.0
    node_fiber = np.repeat(np.arange(nf), np.diff(off))
    pairs = cKDTree(pts).query_pairs(reach_max + seg_max, output_type="ndarray")
    fp = np.unique(np.sort(node_fiber[pairs], axis=1), axis=0) if len(pairs) else np.zeros((0, 2), int)
    fp = fp[fp[:, 0] != fp[:, 1]]
    out = {"i": [], "j": [], "distance_m": [], "phi_deg": []}
    for i, j in fp:
        a, b = pts[off[i] : off[i + 1]], pts[off[j] : off[j + 1]]
        if len(a) < 2 or len(b) < 2:
            continue
        dist, s, t = segment_distances(a[:-1, None], a[1:, None], b[None, :-1], b[None, 1:])
        k = np.unravel_index(np.argmin(dist), dist.shape)
        d = float(dist[k])
        if d >= reach_diameters * (rad[i] + rad[j]):
            continue
        ta, tb = [], []
        for p, cum, seg, u, tang in ((a, cums[i], k[0], s[k], ta), (b, cums[j], k[1], t[k], tb)):
            sc = cum[seg] + u * (cum[seg + 1] - cum[seg])
            lo = max(0.0, min(sc - window_m / 2, cum[-1] - window_m))
            hi = min(cum[-1], lo + window_m)
            tang.append(_point_at(p, cum, hi) - _point_at(p, cum, lo))
        c = abs(float(np.dot(ta[0], tb[0]))) / (np.linalg.norm(ta[0]) * np.linalg.norm(tb[0]))
        out["i"].append(int(i))
        out["j"].append(int(j))
        out["distance_m"].append(d)
        out["phi_deg"].append(float(np.degrees(np.arccos(min(c, 1.0)))))
    return {k: np.asarray(v, dtype=np.int64 if k in "ij" else np.float64) for k, v in out.items()}


def specimen_statistics(
    fibers: Polylines,
    *,
    box_min_m=None,
    box_max_m=None,
    reach_diameters: float = 1.2,
    window_m: float = 1e-3,
) -> dict:
    """The study's specimen statistics measured on ``fibers`` (plain floats, JSON-ready).

    Keys: ``neighbour_pairs``, ``neighbours_per_fiber`` and the distribution of Φ over the
    neighbour pairs (``phi_mean_deg``, ``phi_median_deg``, ``phi_std_deg``, ``phi_p10_deg``,
    ``phi_p90_deg``, ``phi_max_deg``, ``phi_share_2_to_10_deg``); the length-weighted mean
    projected curvature ``curvature_xz_per_m`` and ``curvature_yz_per_m`` (the post stage's
    Table-4 measure, :func:`fiberpipe.post.geometry.projected_curvature`); the largest overlap
    of centre lines ``max_overlap_m`` (r_i + r_j − distance, ≤ 0 when no fibers overlap) and the
    smallest gap; with a box, ``volume_fraction`` (Σ π r² L over the box volume) and
    ``max_outside_m``, how far a fiber surface reaches outside the box in x or y (≤ 0: inside).
    """
    nb = neighbour_orientations(fibers, reach_diameters=reach_diameters, window_m=window_m)
    phi = nb["phi_deg"]
    r = fibers.radius_m
    gap = nb["distance_m"] - (r[nb["i"]] + r[nb["j"]]) if phi.size else np.zeros(0)

    def q(p):
        return float(np.percentile(phi, p)) if phi.size else float("nan")

    stats = {
        "neighbour_reach_diameters": reach_diameters,
        "orientation_window_m": window_m,
        "neighbour_pairs": int(phi.size),
        "neighbours_per_fiber": 2.0 * phi.size / max(fibers.n_fibers, 1),
        "phi_mean_deg": float(phi.mean()) if phi.size else float("nan"),
        "phi_median_deg": q(50),
        "phi_std_deg": float(phi.std()) if phi.size else float("nan"),
        "phi_p10_deg": q(10),
        "phi_p90_deg": q(90),
        "phi_max_deg": float(phi.max()) if phi.size else float("nan"),
        "phi_share_2_to_10_deg": float(np.mean((phi >= 2.0) & (phi <= 10.0))) if phi.size else float("nan"),
        "curvature_xz_per_m": projected_curvature(fibers.points_m, fibers.offsets, "xz"),
        "curvature_yz_per_m": projected_curvature(fibers.points_m, fibers.offsets, "yz"),
        "max_overlap_m": float(-gap.min()) if gap.size else float("nan"),
        "min_gap_m": float(gap.min()) if gap.size else float("nan"),
    }
    if box_min_m is not None and box_max_m is not None:
        lo, hi = np.asarray(box_min_m, float), np.asarray(box_max_m, float)
        vol = float(np.sum(np.pi * r**2 * fibers.lengths_m()))
        stats["volume_fraction"] = vol / float(np.prod(hi - lo))
        rp = np.repeat(r, np.diff(fibers.offsets))[:, None]
        xy = fibers.points_m[:, :2]
        stats["max_outside_m"] = float(max(np.max(lo[:2] - (xy - rp)), np.max((xy + rp) - hi[:2])))
    return stats
