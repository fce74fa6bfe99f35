"""Synthetic specimens that resemble the study's: quasi-parallel fibers packed in a cassette.

The study's specimen (40 polyester fibers, Ø 0.5 mm, 15 mm long, in a 3 mm wide cassette at an
initial fiber volume fraction v_f0 = 37.7 %) was scanned, not published; this builds a bundle with
the same numbers so the study's scene can be run and shipped. Random sequential addition jams
below 40 % area fraction for wavy fibers of this aspect, so fibers start from a jittered lattice.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from numba import njit

from fiberpipe.polylines import Polylines


class CassetteLayout(NamedTuple):
    """What :func:`cassette_specimen` builds: the cassette, the fibers and how they are placed (every
    field with its default; the docstring of :func:`cassette_specimen` says what each does)."""

    n_fibers: int = 40
    width_m: float = 3e-3
    volume_fraction: float = 0.377
    length_m: float = 15e-3
    radius_m: float = 0.25e-3
    columns: int = 5
    jitter: float = 0.6
    tilt_rad: float | tuple[float, float] = 0.03
    waviness_m: float = 5e-6
    points_per_fiber: int = 61
    seed: int = 0
    placement: str = "push"
    curvature_per_m: float = 0.0
    gap_m: float = 1e-6
    max_iterations: int = 5000
    y_tilt_scale: float = 1.0
    top: str = "plate"
    settle: str = "slide"
    slide_cost: float = 1e-3
    candidates: int = 1
    wave_curvature_per_m: float = 0.0
    wave_lengths_m: tuple[float, float] = (1.8e-3, 2.5e-3)
    wave_modes: int = 2
    bow_plane: str = "random"


def cassette_specimen(layout: CassetteLayout | None = None, *, curvatures_per_m=None, progress=None,
                      **fields) -> tuple[Polylines, dict]:
    """Quasi-parallel fibers along z in a box of ``width_m`` (x) × height (y) × ``length_m`` (z):
    the specimen of ``layout`` (:class:`CassetteLayout`; keywords replace its fields).

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

    ``wave_curvature_per_m`` > 0 (``placement="deposit"`` only) adds a smooth waviness to each
    fiber's shape before it is dropped (:func:`_wave_offsets`): in x and in y independently, a sum
    of ``wave_modes`` sines of random phase, wavelengths log-uniform in ``wave_lengths_m``, each
    mode the same curvature amplitude, the sum scaled so that the curve's own projected curvature
    (the Table-4 measure, converged in the point spacing) is ``wave_curvature_per_m`` on XZ and on
    YZ; coarser polylines measure less (2 mm waves: −5 % at 0.25 mm, −10 % at 0.3 mm). With
    Φ ≈ 6° and v_f0 ≈ 38 % only short waves fit (data-samples/paper-40-wavy/README.md). 0 (the
    default) draws nothing: the other specimens are unchanged, bit for bit.

    ``bow_plane`` (``placement="deposit"`` only) is the bow's plane: ``"random"`` (stratified over
    360°, :func:`_bow_planes`), ``"flat"`` (horizontal, x-z: the fiber lies on its bow) or
    ``"upright"`` (vertical, y-z); the same draws are made for each, so the other draws stay the
    same. ``curvatures_per_m`` (one per fiber) replaces ``curvature_per_m`` fiber by fiber (a
    spool radius distribution). ``progress`` (``placement="deposit"`` only): called as
    ``progress(fibers placed, n_fibers)`` after each fiber comes to rest.

    Returns
    -------
    Polylines, and a dict with ``height_m``, ``width_m``, ``volume_fraction`` and the box bounds
    (with ``placement="rigid"`` also ``relaxation``: sweeps, closest centre lines, largest move).
    """
    layout = (layout or CassetteLayout())._replace(**fields)
    if layout.placement not in ("push", "rigid", "deposit"):
        raise ValueError(f"placement must be 'push', 'rigid' or 'deposit', got {layout.placement!r}")
    if layout.top not in ("plate", "pile"):
        raise ValueError(f"top must be 'plate' or 'pile', got {layout.top!r}")
    rng = np.random.default_rng(layout.seed)
    area = layout.n_fibers * np.pi * layout.radius_m**2
    height = area / (layout.volume_fraction * layout.width_m)
    z = np.linspace(0.0, layout.length_m, layout.points_per_fiber)
    if layout.placement == "deposit":
        return _deposit_specimen(rng, layout, height, z, curvatures_per_m=curvatures_per_m, progress=progress)
    rows = int(np.ceil(layout.n_fibers / layout.columns))
    px, py = layout.width_m / layout.columns, height / rows
    centres = []
    for k in range(layout.n_fibers):
        i, j = k % layout.columns, k // layout.columns
        cx = -layout.width_m / 2 + (i + 0.5) * px + layout.jitter * (px / 2 - layout.radius_m) * rng.uniform(-1, 1)
        cy = (j + 0.5) * py + layout.jitter * (py / 2 - layout.radius_m) * rng.uniform(-1, 1)
        centres.append((cx, cy))
    if layout.placement == "rigid":
        return _rigid_specimen(
            np.asarray(centres), rng, width_m=layout.width_m, height_m=height, length_m=layout.length_m,
            radius_m=layout.radius_m, tilt_rad=layout.tilt_rad, curvature_per_m=layout.curvature_per_m, z=z,
            gap_m=layout.gap_m, max_iterations=layout.max_iterations,
        )
    return _push_specimen(centres, rng, layout, height, z)


def _push_specimen(centres, rng, layout: CassetteLayout, height: float, z) -> tuple[Polylines, dict]:
    """``placement="push"`` of :func:`cassette_specimen`: tilted, wavy fibers on the jittered
    lattice, clipped into the cassette and pushed apart where they cross."""
    n_fibers, length_m, radius_m = layout.n_fibers, layout.length_m, layout.radius_m
    width_m, points_per_fiber = layout.width_m, layout.points_per_fiber
    lines = []
    for cx, cy in centres:
        ax, ay = rng.normal(0, 1, 2) * np.broadcast_to(np.asarray(layout.tilt_rad, float), (2,))
        phase = rng.uniform(0, 2 * np.pi, 2)
        wx = layout.waviness_m * np.sin(2 * np.pi * z / length_m + phase[0])
        wy = layout.waviness_m * np.sin(2 * np.pi * z / length_m + phase[1])
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
    return fibers, _box_info(width_m, height, length_m, n_fibers * np.pi * radius_m**2 * length_m)


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
    sag = _arc_sagitta(zc, length_m, curvature_per_m)
    ends = np.zeros((n, 2, 2))  # (x, y) of each fiber's mid-line at z = 0 and z = L
    bows = np.zeros((n, len(z), 2))  # the arc's offset from the chord, in a random plane
    planes = _bow_planes(rng, n)
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


def _arc_sagitta(zc, length_m, curvature_per_m):
    """Offset (m) from its chord of a circular arc of ``curvature_per_m`` through the fiber's ends,
    at ``zc`` from the middle (0 for a straight fiber)."""
    if curvature_per_m <= 0:
        return np.zeros_like(zc)
    rr = 1.0 / curvature_per_m
    return (rr - np.sqrt(rr**2 - zc**2)) - (rr - np.sqrt(rr**2 - (length_m / 2) ** 2))


def _bow_planes(rng, n):
    """Bending planes (rad) stratified over [0, 2π), then shuffled: with 40 fibers the XZ and YZ
    projections share the curvature evenly, as in the study's Table 4 (0.241 and 0.248 1/m)."""
    return 2 * np.pi * (rng.permutation(n) + rng.uniform(0, 1, n)) / max(n, 1)


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


def _deposit_specimen(rng, layout: CassetteLayout, height_m: float, z, *, curvatures_per_m=None, progress=None):
    """``placement="deposit"`` of :func:`cassette_specimen`: a gravity-deposited loose pile.

    # Strategy: random sequential deposition of rigid fibers, each the smooth arc of the
    # ``"rigid"`` placement (chord of random tilt plus a circular bow in a random plane). A fiber's
    # x-path is drawn and kept (x centre uniform over where it fits between the walls); its
    # vertical pose is its height h (of the chord's midpoint) and y-slope s. For a slope s it is
    # dropped straight down from above the pile until first contact (:func:`_drop_height`, exact
    # conservative advancement), which gives the lowest reachable height h_min(s); it then turns
    # about that contact in its y-z plane, which walks h_min(s) downhill (the centre of mass of a
    # symmetric arc is at z = L/2, so dh/ds = L/2 − z_contact) until a local minimum: a kink where
    # the touching point passes from one side of the centre of mass to the other, i.e. the fiber
    # rests on two points on either side of it (or on the plate). Contacts touch at ``gap_m``
    # clearance (no initial overlap: the solver's contact starts at zero force). The y-tilt drawn
    # for the drop is σ·``y_tilt_scale``: steeper drops land on fewer, higher supports and leave
    # a looser pile. ``top="plate"`` keeps the nominal cassette height (from ``volume_fraction``);
    # ``top="pile"`` sets it to the pile's top (+ ``gap_m``), so the upper plate touches it.
    """
    n, width_m, length_m, radius_m = layout.n_fibers, layout.width_m, layout.length_m, layout.radius_m
    gap_m, tilt_rad, candidates = layout.gap_m, layout.tilt_rad, layout.candidates
    wave = (layout.wave_curvature_per_m, layout.wave_lengths_m, layout.wave_modes)
    r, need = radius_m, 2 * radius_m + gap_m
    sigma = np.broadcast_to(np.asarray(tilt_rad, float), (2,))
    zc = z - length_m / 2
    sag = _arc_sagitta(zc, length_m, layout.curvature_per_m)
    planes = _plane_angles(_bow_planes(rng, n), layout.bow_plane)
    waves = _wave_offsets(rng, n, z, *wave) if wave[0] > 0 else None
    xlo, xhi = -width_m / 2 + r + gap_m, width_m / 2 - r - gap_m
    cassette = _Cassette(z, r, need, gap_m, xlo, xhi)
    X = np.zeros((n, len(z)))
    Y = np.zeros((n, len(z)))
    supports = []
    for k in range(n):
        if curvatures_per_m is not None:
            sag = _arc_sagitta(zc, length_m, float(curvatures_per_m[k]))
        bow = sag[:, None] * np.array([np.cos(planes[k]), np.sin(planes[k])])
        if waves is not None:
            bow = bow + waves[k]
        best = None
        for _c in range(candidates):  # keep the lowest of a few trial drops ("careful placement")
            for _ in range(1000):
                a = rng.normal(0, 1, 2) * sigma * np.array([1.0, layout.y_tilt_scale])
                xs = a[0] * zc + bow[:, 0]
                if xs.max() - xs.min() <= 0.9 * (xhi - xlo):
                    break
            else:  # pragma: no cover - only for absurd tilts
                raise ValueError(f"tilt_rad={tilt_rad!r}: a fiber does not fit the cassette")
            x0 = rng.uniform(xlo - xs.min(), xhi - xs.max()) + xs
            if layout.settle == "slide":
                xk, yk, contact = _settle(x0, bow[:, 1], a[1], X[:k], Y[:k], cassette,
                                          _SlideSteps(slide_cost=layout.slide_cost))
            else:
                h, s, contact = _rest(x0, bow[:, 1], a[1], X[:k], Y[:k], z, r, need, gap_m)
                xk, yk = x0, h + s * zc + bow[:, 1]
            if best is None or yk.mean() < best[1].mean():
                best = (xk, yk, contact)
        X[k], Y[k], contact = best
        supports.append(contact)
        if progress is not None:
            progress(k + 1, n)
    pts = np.stack([X, Y, np.broadcast_to(z, X.shape)], axis=2)
    top_m = float((Y + r).max())
    if layout.top == "pile":
        height_m = top_m + gap_m
    fibers = Polylines.from_list(list(pts), radius_m)
    info = _box_info(width_m, height_m, length_m, n * np.pi * radius_m**2 * length_m)
    touching = set()
    for k in range(1, n):  # fiber pairs within 0.1 µm of touching (at the ``gap_m`` clearance)
        g, _, _, which = _pair_gaps(X[k], Y[k], X[:k], Y[:k], z, need)
        touching.update((int(j), k) for j in np.unique(which[g <= 1e-7]))
    info["deposit"] = {
        "candidates": candidates,
        **({"wave_curvature_per_m": float(wave[0]), "wave_lengths_m": [float(v) for v in wave[1]],
            "wave_modes": int(wave[2])} if waves is not None else {}),
        "slide_cost": layout.slide_cost,
        "pile_top_m": top_m,
        "top_clearance_m": float(height_m - top_m),
        "contacts": len(touching),
        "fibers_on_lower_plate": int(np.sum((Y - r).min(axis=1) <= gap_m + 1e-7)),
        "fibers_at_upper_plate": int(np.sum((Y + r).max(axis=1) >= height_m - gap_m - 1e-7)),
        "supports": supports,
    }
    return fibers, info


def _plane_angles(planes, mode):
    """The drawn bow planes ``planes`` (rad) for ``mode``: as drawn (random), turned to the
    horizontal (flat, x-z) or to the vertical (upright, y-z), keeping the side the bow points to."""
    if mode == "random":
        return planes
    if mode == "flat":
        return np.where(np.cos(planes) >= 0, 0.0, np.pi)
    if mode == "upright":
        return np.where(np.sin(planes) >= 0, np.pi / 2, 3 * np.pi / 2)
    raise ValueError(f"bow_plane must be 'random', 'flat' or 'upright', got {mode!r}")


def _wave_offsets(rng, n, z, curvature_per_m, wavelengths_m, modes, refine=8, iterations=4):
    """Smooth waviness of ``n`` fibers sampled at ``z``: (n, len(z), 2) offsets in x and y.

    Each component of each fiber is Σ_j A_j sin(2π z / λ_j + φ_j) over ``modes`` modes, λ_j
    log-uniform in ``wavelengths_m``, φ_j uniform, A_j ∝ λ_j² (every mode the same curvature
    amplitude); the sum is scaled so that its projected curvature, measured as the post stage
    does (:func:`fiberpipe.post.geometry.projected_curvature`), is ``curvature_per_m`` on a
    ``refine``-times finer sampling than ``z``: the curve's own (converged) curvature, which the
    points ``z`` measure a few per cent lower (2 mm waves: −5 % at 0.25 mm spacing). The measure
    is nearly linear in the scale (slopes ≪ 1), so a few fixed-point rescalings converge.
    """
    from fiberpipe.post.geometry import projected_curvature

    lo, hi = (float(v) for v in wavelengths_m)
    zf = np.linspace(z[0], z[-1], refine * (len(z) - 1) + 1)
    out = np.zeros((n, len(z), 2))
    offs = np.array([0, len(zf)])

    def wave(zz, lam, phase):
        return np.sum((lam[:, None] / (2 * np.pi)) ** 2 * np.sin(2 * np.pi * zz[None, :] / lam[:, None] + phase[:, None]),
                      axis=0)

    for k in range(n):
        for c in range(2):
            lam = np.exp(rng.uniform(np.log(lo), np.log(hi), modes))
            phase = rng.uniform(0, 2 * np.pi, modes)
            w, scale = wave(zf, lam, phase), 1.0
            for _ in range(iterations):
                scale *= curvature_per_m / projected_curvature(np.c_[scale * w, np.zeros_like(zf), zf], offs, "xz")
            out[k, :, c] = scale * wave(z, lam, phase)
    return out


def _pair_geometry(x, y, X, Y, z, need, reach=2):
    """Closest distances (minus ``need``) between the new fiber (x, y)(z) and placed fibers
    (X, Y)(z), over segment pairs at most ``reach`` segments apart; the unit separation (new minus
    placed, (M, 3)), the z of the closest point on the new fiber and the placed fiber's index.
    Rows are placed fiber by placed fiber, then by the new fiber's segment and the placed one's."""
    m = len(X)
    i, kk = _segment_pairs(len(z) - 1, reach)
    g = np.empty(m * len(i))
    nvec = np.empty((m * len(i), 3))
    zp = np.empty(m * len(i))
    X = np.ascontiguousarray(X, dtype=float)
    Y = np.ascontiguousarray(Y, dtype=float)
    _pair_geometry_kernel(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(y, dtype=float), X, Y,
                          np.ascontiguousarray(z, dtype=float), float(need), i, kk, g, nvec, zp)
    return g, nvec, zp, np.repeat(np.arange(m), len(i))


@functools.lru_cache(maxsize=8)
def _segment_pairs(ns: int, reach: int):
    """The segment pairs (i of the new fiber, k of a placed one) with |i − k| ≤ ``reach`` of two
    fibers of ``ns`` segments on the same z grid, by i then k (read-only: shared by every call)."""
    i = np.repeat(np.arange(ns), 2 * reach + 1)
    kk = i + np.tile(np.arange(-reach, reach + 1), ns)
    ok = (kk >= 0) & (kk < ns)
    i, kk = i[ok], kk[ok]
    i.flags.writeable = False
    kk.flags.writeable = False
    return i, kk


@njit(cache=True)
def _pair_geometry_kernel(x, y, X, Y, z, need, seg_a, seg_b, g, nvec, zp):
    """:func:`_pair_geometry`'s loop: for each placed fiber f and segment pair (seg_a[p] of the new
    fiber, seg_b[p] of fiber f), row f·P + p of ``g``, ``nvec``, ``zp``.

    The arithmetic is :func:`fiberpipe.model.specimen_stats.segment_distances`' operation by
    operation (no fast-math, sums of three terms left to right, as numpy reduces them), so the
    deposit is the same to the bit as with the vectorised numpy form."""
    n_pairs = seg_a.shape[0]
    for f in range(X.shape[0]):
        for p in range(n_pairs):
            ia = seg_a[p]
            ib = seg_b[p]
            a0 = (x[ia], y[ia], z[ia])
            a1 = (x[ia + 1], y[ia + 1], z[ia + 1])
            b0 = (X[f, ib], Y[f, ib], z[ib])
            b1 = (X[f, ib + 1], Y[f, ib + 1], z[ib + 1])
            ta = (a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2])
            tb = (b1[0] - b0[0], b1[1] - b0[1], b1[2] - b0[2])
            r = (a0[0] - b0[0], a0[1] - b0[1], a0[2] - b0[2])
            aa = ta[0] * ta[0] + ta[1] * ta[1] + ta[2] * ta[2]
            bb = tb[0] * tb[0] + tb[1] * tb[1] + tb[2] * tb[2]
            ab = ta[0] * tb[0] + ta[1] * tb[1] + ta[2] * tb[2]
            ar = ta[0] * r[0] + ta[1] * r[1] + ta[2] * r[2]
            br = tb[0] * r[0] + tb[1] * r[1] + tb[2] * r[2]
            den = aa * bb - ab * ab
            s = min(max((ab * br - ar * bb) / den, 0.0), 1.0) if den > 1e-12 * aa * bb else 0.0
            t = (ab * s + br) / bb
            if t < 0.0:
                s = min(max(-ar / aa, 0.0), 1.0)
            elif t > 1.0:
                s = min(max((ab - ar) / aa, 0.0), 1.0)
            t = min(max(t, 0.0), 1.0)
            d0 = r[0] + s * ta[0] - t * tb[0]
            d1 = r[1] + s * ta[1] - t * tb[1]
            d2 = r[2] + s * ta[2] - t * tb[2]
            d = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            inv = max(d, 1e-300)
            row = f * n_pairs + p
            pa2 = a0[2] + s * ta[2]
            for c in range(3):
                nvec[row, c] = ((a0[c] + s * ta[c]) - (b0[c] + t * tb[c])) / inv
            g[row] = d - need
            zp[row] = pa2


def _pair_gaps(x, y, X, Y, z, need, reach=2):
    """:func:`_pair_geometry` with only the vertical component of the unit separation."""
    g, nvec, zp, which = _pair_geometry(x, y, X, Y, z, need, reach)
    return g, nvec[:, 1], zp, which


def _supports(x, y, X, Y, z, r, need, gap_m, tol=2e-8):
    """What the fiber (x, y)(z) rests on within ``tol`` of touching: the plate and placed fibers
    (JSON-ready dicts with the z of the contact and, for fibers, its clearance)."""
    pts = [{"on": "plate", "z_m": float(z[i])} for i in np.flatnonzero(y - r - gap_m <= tol)]
    if len(X):
        g, _, zp, which = _pair_gaps(x, y, X, Y, z, need)
        for f in np.unique(which[g <= tol]):
            sel = (which == f) & (g <= tol)
            pts.append({"on": int(f), "z_m": float(np.mean(zp[sel])), "gap_m": float(g[sel].min() + gap_m)})
    return pts


def _drop_height(ys, x, X, Y, z, r, need, gap_m, tol=2e-9):
    """Lowest height h reached by the fiber (x, h + ys)(z) dropped straight down from above the
    pile: returns h, the z of the touching point(s) and what it touches (fiber index or -1: plate).

    Conservative advancement: the distance between two segments, one translated by h along y, is
    convex in h, so a pair at gap g whose separation has vertical component u_y > 0 allows a drop of
    g / u_y and no more; the fiber moves by the smallest such step until a gap closes to ``tol``.
    """
    h_plate = float(np.max(r + gap_m - ys))
    near = np.flatnonzero(np.min(np.abs(X - x), axis=1) < need + 1e-9) if len(X) else np.zeros(0, int)
    Xn, Yn = X[near], Y[near]
    if len(near) == 0:
        return h_plate, z[np.argmax(r + gap_m - ys)], -1
    h = max(h_plate, float(np.max(Yn - ys))) + 2 * need  # above every fiber in reach
    for _ in range(10000):
        g, uy, zc, which = _pair_gaps(x, h + ys, Xn, Yn, z, need)
        down = uy > 0
        step = np.min(g[down] / uy[down]) if down.any() else np.inf
        if g.min() < -tol:  # pragma: no cover - guarded by the advancement
            raise RuntimeError("deposit: a dropped fiber overlaps the pile")
        if h - h_plate <= step:  # the plate comes first
            h = h_plate
            break
        if step <= tol:
            hit = g <= tol
            return h, zc[hit], near[which[hit]]
        h -= step
    g, uy, zc, which = _pair_gaps(x, h + ys, Xn, Yn, z, need)
    hit = g <= tol
    if hit.any():
        return h, np.r_[zc[hit], z[np.argmax(r + gap_m - ys)]], np.r_[near[which[hit]], -1]
    return h, z[np.argmax(r + gap_m - ys)], -1


def _rest(x, bow_y, s0, X, Y, z, r, need, gap_m, ds0=2e-3, ds_min=1e-7, support_tol=2e-8):
    """Height h and y-slope s at which the fiber (x, h + s (z − L/2) + bow_y)(z), dropped at slope
    ``s0``, comes to rest by turning about its contact; and its supports (JSON-ready dict)."""
    zmid = 0.5 * (z[0] + z[-1])
    zc = z - zmid

    def drop(s):
        return _drop_height(s * zc + bow_y, x, X, Y, z, r, need, gap_m)

    s = s0
    h, zt, _ = drop(s)
    ds = ds0
    while ds > ds_min:
        zt = np.atleast_1d(zt) - zmid  # the touching points, from the centre of mass
        if zt.min() <= 0 <= zt.max():  # supported on both sides (or right under it)
            break
        step = -ds if zt.max() < 0 else ds  # turn the free side down
        h2, zt2, _ = drop(s + step)
        if h2 < h:
            s, h, zt, ds = s + step, h2, zt2, min(2 * ds, ds0)
        else:
            ds /= 2
    return float(h), float(s), _supports(x, h + s * zc + bow_y, X, Y, z, r, need, gap_m, support_tol)


class _Cassette(NamedTuple):
    """The deposit's cassette: the fibers' z stations, radius, the centre distance of two touching
    fibers (2r + gap), the contact clearance and the x range of fiber centres between the walls."""

    z: np.ndarray
    r: float
    need: float
    gap_m: float
    xlo: float
    xhi: float


class _SlideSteps(NamedTuple):
    """The settling's linear programs: the cost per metre of sideways and vertical motion, the
    trust region (first and largest), the clearance each linearised gap keeps, the step budget."""

    slide_cost: float = 1e-3
    trust0: float = 5e-5
    trust_max: float = 2e-4
    margin: float = 5e-9
    max_steps: int = 400


def _settle(x, bow_y, s0, X, Y, cassette: _Cassette, steps: _SlideSteps = _SlideSteps()):
    """Rest pose of a fiber dropped at slope ``s0``: it may sink, turn in its y-z plane and slide
    sideways (x) as a whole, its x-tilt and shape kept; returns its points' x, y and supports.

    # Strategy: the pose is (Δx, y_A, y_B): a sideways shift and the heights of the chord's ends
    # (z = 0 and L). After a straight drop to first contact (:func:`_drop_height`), a sequence of
    # small linear programs lowers the centre of mass (y_A + y_B)/2 within a trust region, each
    # fiber pair near contact linearised (gap + n·∂p/∂q Δq ≥ ``margin``, n the unit separation at
    # the closest points), the plate and walls exact. A step is kept if the true gaps stay ≥ 0,
    # otherwise the trust region halves. ``slide_cost`` per metre of |Δx|, |Δy_A|, |Δy_B| (a
    # small fraction of the height gained) stops zero-cost drifts; it acts like a tiny friction.
    # Converged, the fiber rests in a frictionless equilibrium: on the plate, or on ≥ 2 points
    # on either side of its centre of mass and, in x, in a groove.
    """
    from scipy.optimize import linprog

    z, r, need, gap_m, xlo, xhi = cassette
    slide_cost, trust0, trust_max, margin, max_steps = steps
    length = z[-1] - z[0]
    u = (z - z[0]) / length
    zmid = 0.5 * (z[0] + z[-1])
    h, _, _ = _drop_height(s0 * (z - zmid) + bow_y, x, X, Y, z, r, need, gap_m)
    yA, yB, dx = h - s0 * length / 2, h + s0 * length / 2, 0.0
    # fibers within reach of a sideways slide: the whole cassette up to 3 mm wide (5 mm reach),
    # the neighbourhood in wider ones (a slide is a few radii)
    reach = min(2 * (xhi - xlo), 5e-3)
    near = np.flatnonzero(np.min(np.abs(X - x), axis=1) < need + reach) if len(X) else np.zeros(0, int)

    def ycurve(a, b):
        return a * (1 - u) + b * u + bow_y

    def gaps(dx_, a, b):
        yc_ = ycurve(a, b)
        # only fibers whose distance at equal z comes within reach: a pair's closest points are at
        # most 3 segments apart in z, so the others' gaps exceed 3 trust_max (slopes below 0.5) and
        # enter neither the linear program nor the overlap check (the same result, far fewer pairs)
        cand = near
        if len(near):
            d_same = np.min(np.hypot(X[near] - (x + dx_), Y[near] - yc_), axis=1)
            cand = near[d_same < need + 3 * trust_max + 1e-3]
        if len(cand) == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0)
        g, nvec, zp, _which = _pair_geometry(x + dx_, yc_, X[cand], Y[cand], z, need)
        return g, nvec, (zp - z[0]) / length

    trust = trust0
    c = np.r_[slide_cost, slide_cost, 0.5 + slide_cost, -0.5 + slide_cost, 0.5 + slide_cost, -0.5 + slide_cost]
    # variables: Δx⁺, Δx⁻, ΔyA⁺, ΔyA⁻, ΔyB⁺, ΔyB⁻ (all ≥ 0)
    for _ in range(max_steps):
        g, n, up = gaps(dx, yA, yB)
        sel = g < 3 * trust
        # linearised pair gaps: g + n_x Δx + n_y ((1−u) ΔyA + u ΔyB) ≥ margin
        rows = np.c_[n[sel, 0], -n[sel, 0], n[sel, 1] * (1 - up[sel]), -n[sel, 1] * (1 - up[sel]),
                     n[sel, 1] * up[sel], -n[sel, 1] * up[sel]]
        A = [-rows]
        bub = [g[sel] - margin]
        # plate: y(z) − r − gap ≥ 0 at every point (exact)
        yc = ycurve(yA, yB)
        A.append(-np.c_[np.zeros((len(u), 2)), 1 - u, -(1 - u), u, -u])
        bub.append(yc - r - gap_m)
        # walls, exact: xlo ≤ x + dx + Δx ≤ xhi
        lo_x, hi_x = xlo - (x.min() + dx), xhi - (x.max() + dx)
        A.append(np.array([[1.0, -1.0, 0, 0, 0, 0], [-1.0, 1.0, 0, 0, 0, 0]]))
        bub.append(np.array([max(hi_x, 0.0), max(-lo_x, 0.0)]))
        # in µm, so that HiGHS' feasibility tolerance (1e-7) is far below the clearance
        res = linprog(c, A_ub=np.vstack(A), b_ub=np.concatenate(bub) * 1e6, bounds=[(0, trust * 1e6)] * 6,
                      method="highs")
        if res.status != 0:
            break
        v = res.x * 1e-6
        ddx, dA, dB = v[0] - v[1], v[2] - v[3], v[4] - v[5]
        drop_ = -(dA + dB) / 2
        if drop_ < 1e-10:
            if trust <= 1e-7:
                break
            trust /= 4
            continue
        g2 = gaps(dx + ddx, yA + dA, yB + dB)[0]
        if g2.size and g2.min() < 0:
            trust /= 2
            continue
        dx, yA, yB = dx + ddx, yA + dA, yB + dB
        trust = min(trust * 1.5, trust_max)
    xs, ys = x + dx, ycurve(yA, yB)
    return xs, ys, _supports(xs, ys, X, Y, z, r, need, gap_m)
