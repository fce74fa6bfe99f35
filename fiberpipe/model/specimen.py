"""Synthetic specimens that resemble the study's: quasi-parallel fibers packed in a cassette.

The study's specimen (40 polyester fibers, Ø 0.5 mm, 15 mm long, in a 3 mm wide cassette at an
initial fiber volume fraction v_f0 = 37.7 %) was scanned, not published; this builds a bundle with
the same numbers so the study's scene can be run and shipped. Random sequential addition jams
below 40 % area fraction for wavy fibers of this aspect, so fibers start from a jittered lattice.
"""

from __future__ import annotations

import numpy as np

from fiberpipe.polylines import Polylines


def cassette_specimen(
    *,
    n_fibers: int = 40,
    width_m: float = 3e-3,
    volume_fraction: float = 0.377,
    length_m: float = 15e-3,
    radius_m: float = 0.25e-3,
    columns: int = 5,
    jitter: float = 0.6,
    tilt_rad: float | tuple[float, float] = 0.03,
    waviness_m: float = 5e-6,
    points_per_fiber: int = 61,
    seed: int = 0,
    placement: str = "push",
    curvature_per_m: float = 0.0,
    gap_m: float = 1e-6,
    max_iterations: int = 5000,
) -> tuple[Polylines, dict]:
    """Quasi-parallel fibers along z in a box of ``width_m`` (x) × height (y) × ``length_m`` (z).

    # Strategy: the height follows from the volume fraction (v_f = N π r² L / (w h L)); fibers
    # sit on a ``columns`` × ceil(N/columns) lattice whose free space (pitch − 2r) is shared out
    # as random jitter (a fraction ``jitter`` of it), get a random tilt in x and y (fibers then
    # cross at a few degrees, as the study's did: its average contact angle is 6°) and a sine
    # waviness; then, alternately, they are clipped into the cassette and pushed apart where they
    # cross (:func:`fiberpipe.model.mesh.resolve_overlaps`), until neither moves them.

    ``placement="rigid"`` keeps every fiber a smooth curve instead: each is a straight line of
    random tilt (``tilt_rad``: standard deviation per component; redrawn until the fiber fits the
    cassette) bent into a circular arc of ``curvature_per_m`` in a random plane (the study's fibers
    came off a spool; its Table 4 gives ≈ 0.24 1/m projected, i.e. an arc of ≈ 0.38 1/m), and the
    fibers are then moved apart whole, each keeping its shape, until no two centre lines are
    closer than r_i + r_j + ``gap_m`` and every fiber is inside the cassette
    (:func:`_relax_rigid`; ``max_iterations`` bounds each of its L-BFGS passes). Clipping and node pushes, as the default ``"push"`` placement does,
    kink the fibers at node scale (a projected curvature of ≈ 17 1/m instead of ≈ 0.24).
    For independent normal tilts of standard deviation σ per component the angle between two
    fibers has a Rayleigh distribution of mean √π σ; the relaxation keeps the drawn tilts where it
    can and the walls cap them, so the measured mean of neighbours comes out a little lower
    (σ = 0.059 rad, i.e. 6°/√π: 5.8 ± 0.5° over seeds 0–5 at 37.7 %);
    :mod:`fiberpipe.model.specimen_stats` measures it.
    ``waviness_m`` is not used there. ``placement="push"`` with the other defaults is the
    original specimen, bit for bit.

    Returns
    -------
    Polylines, and a dict with ``height_m``, ``width_m``, ``volume_fraction`` and the box bounds
    (with ``placement="rigid"`` also ``relaxation``: sweeps, closest centre lines, largest move).
    """
    if placement not in ("push", "rigid"):
        raise ValueError(f"placement must be 'push' or 'rigid', got {placement!r}")
    rng = np.random.default_rng(seed)
    area = n_fibers * np.pi * radius_m**2
    height = area / (volume_fraction * width_m)
    rows = int(np.ceil(n_fibers / columns))
    px, py = width_m / columns, height / rows
    z = np.linspace(0.0, length_m, points_per_fiber)
    centres = []
    for k in range(n_fibers):
        i, j = k % columns, k // columns
        cx = -width_m / 2 + (i + 0.5) * px + jitter * (px / 2 - radius_m) * rng.uniform(-1, 1)
        cy = (j + 0.5) * py + jitter * (py / 2 - radius_m) * rng.uniform(-1, 1)
        centres.append((cx, cy))
    if placement == "rigid":
        return _rigid_specimen(
            np.asarray(centres), rng, width_m=width_m, height_m=height, length_m=length_m,
            radius_m=radius_m, tilt_rad=tilt_rad, curvature_per_m=curvature_per_m, z=z,
            gap_m=gap_m, max_iterations=max_iterations,
        )
    lines = []
    for cx, cy in centres:
        ax, ay = rng.normal(0, 1, 2) * np.broadcast_to(np.asarray(tilt_rad, float), (2,))
        phase = rng.uniform(0, 2 * np.pi, 2)
        wx = waviness_m * np.sin(2 * np.pi * z / length_m + phase[0])
        wy = waviness_m * np.sin(2 * np.pi * z / length_m + phase[1])
        x = cx + ax * (z - length_m / 2) + wx
        y = cy + ay * (z - length_m / 2) + wy
        lines.append(np.c_[x, y, z])
    pts = np.array(lines)  # (F, n, 3)
    # keep every fiber inside the cassette, and push apart fibers that cross each other
    from fiberpipe.model.mesh import Mesh, resolve_overlaps

    lo = np.array([-width_m / 2 + radius_m, radius_m])
    hi = np.array([width_m / 2 - radius_m, height - radius_m])
    offsets = np.arange(n_fibers + 1) * points_per_fiber
    for _ in range(20):
        pts[:, :, :2] = np.clip(pts[:, :, :2], lo, hi)
        mesh = Mesh(pts.reshape(-1, 3).copy(), offsets, np.full(n_fibers, radius_m * 1.002))
        info_overlap = resolve_overlaps(mesh, tolerance_m=1e-8, max_iterations=400)
        pts = mesh.nodes_m.reshape(n_fibers, points_per_fiber, 3)
        inside = np.all((pts[:, :, :2] >= lo - 1e-9) & (pts[:, :, :2] <= hi + 1e-9))
        if inside and info_overlap["max_overlap_after_m"] <= 1e-8:
            break
    fibers = Polylines.from_list(list(pts), radius_m)
    info = {
        "width_m": width_m,
        "height_m": float(height),
        "length_m": length_m,
        "volume_fraction": float(area * length_m / (width_m * height * length_m)),
        "box_min_m": [-width_m / 2, 0.0, 0.0],
        "box_max_m": [width_m / 2, float(height), length_m],
    }
    return fibers, info


def _box_info(width_m, height_m, length_m, fiber_volume_m3) -> dict:
    return {
        "width_m": width_m,
        "height_m": float(height_m),
        "length_m": length_m,
        "volume_fraction": float(fiber_volume_m3 / (width_m * height_m * length_m)),
        "box_min_m": [-width_m / 2, 0.0, 0.0],
        "box_max_m": [width_m / 2, float(height_m), length_m],
    }


def _rigid_specimen(centres, rng, *, width_m, height_m, length_m, radius_m, tilt_rad,
                    curvature_per_m, z, gap_m, max_iterations):
    """``placement="rigid"`` of :func:`cassette_specimen`: smooth fibers moved apart whole."""
    n = len(centres)
    lo = np.array([-width_m / 2 + radius_m, radius_m])
    hi = np.array([width_m / 2 - radius_m, height_m - radius_m])
    sigma = np.broadcast_to(np.asarray(tilt_rad, float), (2,))
    zc = z - length_m / 2
    if curvature_per_m > 0:  # circular arc through the fiber's ends: sagitta from the chord
        rr = 1.0 / curvature_per_m
        sag = (rr - np.sqrt(rr**2 - zc**2)) - (rr - np.sqrt(rr**2 - (length_m / 2) ** 2))
    else:
        sag = np.zeros_like(zc)
    ends = np.zeros((n, 2, 2))  # (x, y) of each fiber's mid-line at z = 0 and z = L
    bows = np.zeros((n, len(z), 2))  # the arc's offset from the chord, in a random plane
    # bending planes stratified over [0, 2π) (then shuffled), so that with 40 fibers the XZ and YZ
    # projections share the curvature evenly, as in the study's Table 4 (0.241 and 0.248 1/m)
    planes = 2 * np.pi * (rng.permutation(n) + rng.uniform(0, 1, n)) / max(n, 1)
    for k in range(n):
        for _ in range(1000):
            a = rng.normal(0, 1, 2) * sigma
            if np.all(np.abs(a) * length_m <= 0.9 * (hi - lo)):
                break
        else:  # pragma: no cover - only for absurd tilts
            raise ValueError(f"tilt_rad={tilt_rad!r}: a fiber does not fit the cassette")
        bows[k] = sag[:, None] * np.array([np.cos(planes[k]), np.sin(planes[k])])
        ends[k, 0] = centres[k] - a * length_m / 2
        ends[k, 1] = centres[k] + a * length_m / 2
    ends, relax = _relax_rigid(ends, bows, z, lo, hi, 2 * radius_m + gap_m, max_iterations=max_iterations)
    pts = _rigid_points(ends, bows, z, np.arange(len(z)))
    fibers = Polylines.from_list(list(pts), radius_m)
    # the nominal v_f (N π r² L over the box, as the study computes it); a tilted fiber is
    # ≈ 0.2 % longer than the box (specimen_stats reports v_f from the arc lengths)
    info = _box_info(width_m, height_m, length_m, n * np.pi * radius_m**2 * length_m)
    info["relaxation"] = relax
    return fibers, info


def _rigid_points(ends, bows, z, idx):
    """Points ``idx`` of each fiber: chord from its ``ends`` (F, 2, 2) plus its bow, (F, k, 3)."""
    u = (z[idx] - z[0]) / (z[-1] - z[0])
    xy = ends[:, None, 0] + (ends[:, None, 1] - ends[:, None, 0]) * u[None, :, None] + bows[:, idx]
    return np.concatenate([xy, np.broadcast_to(z[None, idx, None], (len(ends), len(idx), 1))], axis=2)


def _relax_rigid(ends, bows, z, lo, hi, min_distance, *, max_iterations, coarse=4, keep_tilt=1e-2):
    """Move fibers apart whole until no two centre lines are closer than ``min_distance`` and
    every fiber lies within [lo, hi] in x and y; returns the new ``ends`` and a report.

    # Strategy: a soft-contact packing, as jammed packings are made: the degrees of freedom are
    # the x-y positions of each fiber's two ends (the shape between them, chord plus bow, is kept),
    # the energy is Σ (d₀ − d)² over the pairs whose closest centre lines are nearer than
    # d₀ = ``min_distance`` (+ 0.1 %), and L-BFGS-B minimises it with the cassette as bounds on
    # the ends (a chord between two ends inside the box is inside it; the bow's reach is taken
    # off the box). The gradient of a pair's distance moves the closest point of fiber i, at
    # fraction u of its length, by (1 − u) of an end-A move and u of an end-B move. A first pass
    # adds ``keep_tilt`` Σ |chord − drawn chord|² / d₀², so that fibers slide past each other
    # rather than turn to their neighbours' direction (without it the tilts shrink by about a
    # third and the mean angle of neighbours with them); a second pass without it clears what
    # overlap that left. Distances use a polyline of ``coarse`` segments with twice its chord
    # error added; the final check uses every point. Zero energy means no overlap.
    """
    from scipy.optimize import minimize

    from fiberpipe.model.specimen_stats import segment_distances

    n, length = len(ends), z[-1] - z[0]
    sel = np.unique(np.linspace(0, len(z) - 1, coarse + 1).round().astype(int))
    chord_err = max(
        (float(np.max(np.abs(bows[f] - np.stack([np.interp(z, z[sel], bows[f, sel, k]) for k in range(2)], axis=1))))
         for f in range(n)), default=0.0)
    need = (min_distance + 2 * chord_err) * (1 + 1e-3)
    margin = np.abs(bows).max(axis=1)  # (F, 2): how far the bow reaches beyond the chord
    box_lo = np.broadcast_to((lo + margin)[:, None, :], ends.shape).ravel()
    box_hi = np.broadcast_to((hi - margin)[:, None, :], ends.shape).ravel()
    iu, ju = np.triu_indices(n, 1)
    # translate each fiber into the cassette first (ends clipped only if it is wider than that)
    a, b = lo + margin, hi - margin
    shift = np.maximum(a - ends.min(axis=1), 0) - np.maximum(ends.max(axis=1) - b, 0)
    start = np.clip((ends + shift[:, None]).ravel(), box_lo, box_hi)

    def closest(e, idx):
        p = _rigid_points(e, bows, z, idx)
        a0, a1 = p[iu, :-1][:, :, None], p[iu, 1:][:, :, None]
        b0, b1 = p[ju, :-1][:, None, :], p[ju, 1:][:, None, :]
        d, s, t = segment_distances(a0, a1, b0, b1)
        flat = d.reshape(len(iu), -1)
        k = np.argmin(flat, axis=1)
        ka, kb = np.unravel_index(k, d.shape[1:])
        r = np.arange(len(iu))
        sa, tb = s[r, ka, kb], t[r, ka, kb]
        pa = a0[r, ka, 0] + sa[:, None] * (a1[r, ka, 0] - a0[r, ka, 0])
        pb = b0[r, 0, kb] + tb[:, None] * (b1[r, 0, kb] - b0[r, 0, kb])
        zi = z[idx] - z[0]
        ua = (zi[ka] + sa * (zi[ka + 1] - zi[ka])) / length
        ub = (zi[kb] + tb * (zi[kb + 1] - zi[kb])) / length
        return flat[r, k], pb - pa, ua, ub

    scale = 1.0 / min_distance  # work in units of the contact distance

    chord0 = (ends[:, 1] - ends[:, 0]) * scale  # the drawn tilts, kept where they can be

    def energy(x, keep_tilt):
        e = x.reshape(ends.shape)
        dist, vec, ua, ub = closest(e, sel)
        bad = dist < need
        ov = (need - dist[bad]) * scale
        nv = vec[bad, :2] / np.maximum(dist[bad], 1e-300)[:, None]  # unit, from i to j (x-y part)
        g = np.zeros_like(e)
        for fib, sign, u in ((iu[bad], 1.0, ua[bad]), (ju[bad], -1.0, ub[bad])):
            # dE/d(end) = −2 ov ∂d/∂(end) / d₀; moving fiber i towards j (along nv) shortens d
            f = 2 * ov[:, None] * nv * sign * scale
            np.add.at(g[:, 0], fib, f * (1 - u)[:, None])
            np.add.at(g[:, 1], fib, f * u[:, None])
        val = float(np.sum(ov**2))
        if keep_tilt:
            dc = (e[:, 1] - e[:, 0]) * scale - chord0
            val += keep_tilt * float(np.sum(dc**2))
            g[:, 1] += 2 * keep_tilt * dc * scale
            g[:, 0] -= 2 * keep_tilt * dc * scale
        return val, g.ravel()

    opts = {"maxiter": max_iterations, "maxfun": 2 * max_iterations, "ftol": 0.0, "gtol": 1e-14}
    x, nit = start, 0
    for keep in (keep_tilt, 0.0):  # with the tilt kept first, then free to clear the last overlaps
        res = minimize(energy, x, args=(keep,), jac=True, method="L-BFGS-B", bounds=list(zip(box_lo, box_hi)), options=opts)
        x, nit = res.x, nit + int(res.nit)
    e = np.clip(x, box_lo, box_hi).reshape(ends.shape)
    dist = closest(e, np.arange(len(z)))[0]
    report = {
        "iterations": nit,
        "min_centre_line_distance_m": float(dist.min()) if dist.size else float("nan"),
        "max_end_move_m": float(np.max(np.linalg.norm(e - start.reshape(ends.shape), axis=2))) if n else 0.0,
    }
    if dist.size and dist.min() < min_distance - 1e-9:
        raise ValueError(
            f"fibers still overlap after {nit} relaxation iterations (closest centre lines "
            f"{dist.min() * 1e6:.1f} um apart, {min_distance * 1e6:.1f} um needed): lower tilt_rad "
            "or volume_fraction, or raise max_iterations"
        )
    return e, report
