"""The yarn specimen (``specimen.kind: yarn``): N aligned fibers packed in an elliptical
cross-section at the target v_f0, with optional twist, orientation spread and waviness, for
transverse compaction between the plates (along y), with or without the cassette's walls.

# Strategy: packing by relaxation instead of fiber-by-fiber drops and settling (the cassette kind's
# cost grows faster than N). (1) The cross-section: N discs of diameter (2r + gap)/cos α (α the
# surface's helix angle: an inclined fiber cuts the plane in an ellipse 2r/cos α long) start at uniform random positions in the ellipse of the fiber centres (semi-axes a − r, b − r)
# and every overlap is pushed apart (each disc by half of it, Gauss–Seidel sweeps over a cell grid,
# the discs kept inside the ellipse) until the smallest gap is ≥ half the clearance: the soft-disc
# energy minimisation that jams near v = 0.84 in 2D (O'Hern et al., Phys. Rev. E 68, 011306, 2003;
# the growth-free cousin of Lubachevsky & Stillinger, J. Stat. Phys. 60, 561, 1990). (2) Each disc
# centre is extruded into a line along z: the cross-section turned by 2πT(z − L/2) (a helix of
# helix angle tan α = 2πTρ at radius ρ; in an ellipse the turn is made on the unit disc of
# (x/a, y/b)), tilted by the fiber's random angles (σ = Φ/√π per component, the cassette's Φ) and
# waved by a sinusoid of random direction and phase. (3) The residual 3D overlaps (tilted and
# twisted neighbours cross) are pushed apart on the fibers' segments (closest points, Ericson,
# Real-Time Collision Detection, 2005, §5.1.9), the nodes moving in x–y only, the layers of
# segments binned on a cell grid. Every sweep is O(N) in numba; the specimen is deterministic by
# seed (sequential sweeps, one random generator).
# The cross-section's area holds the fibers' true volume: A = N π r² ⟨ℓ⟩ / (L v_f0), ⟨ℓ⟩ the mean
# arc length of the twisted, tilted and waved fibers spanning z ∈ [0, L].
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from fiberpipe.errors import ConfigError

#: Gauss–Seidel sweeps of the cross-section's disc packing before the v_f0 is refused
MAX_DISC_SWEEPS = 20000
#: sweeps at each 1 % smaller diameter while the densest packable v_f0 is sought (the error's figure)
JAM_SWEEPS = 500
#: sweeps of the 3D segment relaxation before the residual overlap is checked
MAX_SEGMENT_SWEEPS = 400
#: the first sweeps of the 3D relaxation are each followed by a smoothing along the fibers
SMOOTHING_SWEEPS = 40


class YarnSection(NamedTuple):
    """The cross-section: fiber surfaces inside the ellipse of semi-axes ``semi_width_m`` (x) and
    ``semi_height_m`` (y) centred on (0, ``centre_y_m``); the twist ``turns_per_m`` about z."""

    semi_width_m: float
    semi_height_m: float
    centre_y_m: float
    turns_per_m: float


class FiberDraws(NamedTuple):
    """Each fiber's random shape parameters (rad, rad, rad, rad)."""

    tilt_x_rad: np.ndarray
    tilt_y_rad: np.ndarray
    wave_direction_rad: np.ndarray
    wave_phase_rad: np.ndarray


def draw_fibers(yarn, n_fibers: int, rng) -> FiberDraws:
    """The fibers' tilts (σ = Φ/√π per component, Φ the mean angle between two fibers) and wave
    directions and phases, drawn before the packing (their arc lengths set the section's area)."""
    sigma = yarn.orientation_spread / math.sqrt(math.pi)
    return FiberDraws(rng.normal(0.0, sigma, n_fibers), rng.normal(0.0, sigma, n_fibers),
                      rng.uniform(0.0, 2 * math.pi, n_fibers), rng.uniform(0.0, 2 * math.pi, n_fibers))


def extrude(unit_xy: np.ndarray, section: YarnSection, draws: FiberDraws, yarn, z_m: np.ndarray):
    """Fiber centre lines (x, y), each (n_fibers, len(z_m)), from the cross-section's centres
    ``unit_xy`` on the unit disc (x/a', y/b', a' = a − r, b' = b − r at the mid-plane z = L/2)."""
    a, b = section.semi_width_m, section.semi_height_m
    zc = z_m - 0.5 * (z_m[0] + z_m[-1])
    turn = 2 * math.pi * section.turns_per_m * zc[None, :]
    u, v = unit_xy[:, :1], unit_xy[:, 1:2]
    x = a * (u * np.cos(turn) - v * np.sin(turn)) + np.tan(draws.tilt_x_rad)[:, None] * zc
    y = b * (u * np.sin(turn) + v * np.cos(turn)) + np.tan(draws.tilt_y_rad)[:, None] * zc
    if yarn.wave_amplitude > 0:
        wave = yarn.wave_amplitude * np.sin(2 * math.pi * z_m[None, :] / yarn.wave_length + draws.wave_phase_rad[:, None])
        x = x + np.cos(draws.wave_direction_rad)[:, None] * wave
        y = y + np.sin(draws.wave_direction_rad)[:, None] * wave
    return x, y + section.centre_y_m


def arc_lengths_m(x: np.ndarray, y: np.ndarray, z_m: np.ndarray) -> np.ndarray:
    """Each polyline's length (the rows of x, y over the common z_m)."""
    return np.sum(np.sqrt(np.diff(x, axis=1) ** 2 + np.diff(y, axis=1) ** 2 + np.diff(z_m)[None, :] ** 2), axis=1)


def yarn_section(sp, radius_m: float, draws: FiberDraws, z_m: np.ndarray, rng) -> YarnSection:
    """The ellipse that holds the fibers' volume at v_f0: a b = N r² ⟨ℓ⟩ / (L v_f0), a / b the aspect
    ratio; ⟨ℓ⟩ from the fibers extruded at uniform random centres (a fixed point: the twist per
    length of a given helix angle, tan α / (2π √(ab)), follows the section's size)."""
    yarn = sp.yarn
    n = sp.n_fibers
    rho = np.sqrt(rng.uniform(0.0, 1.0, n))
    angle = rng.uniform(0.0, 2 * math.pi, n)
    trial = np.column_stack([rho * np.cos(angle), rho * np.sin(angle)])
    mean_factor = 1.0
    for _ in range(6):
        ab = n * radius_m**2 * mean_factor / sp.volume_fraction
        b = math.sqrt(ab / yarn.aspect_ratio)
        a = yarn.aspect_ratio * b
        turns = (math.tan(yarn.helix_angle) / (2 * math.pi * math.sqrt(ab)) if yarn.helix_angle is not None
                 else yarn.twist_per_length)
        section = YarnSection(a, b, b, turns)
        x, y = extrude(trial, section._replace(semi_width_m=a - radius_m, semi_height_m=b - radius_m), draws, yarn, z_m)
        mean_factor = float(np.mean(arc_lengths_m(x, y, z_m))) / float(z_m[-1] - z_m[0])
    return section


@njit(cache=True)
def _grid_order(x, y, x0, y0, cell, nx, ny):
    """Counting sort of points into an nx × ny grid: (order, first index of each cell + end)."""
    n = x.shape[0]
    key = np.empty(n, np.int64)
    for i in range(n):
        cx = min(max(int((x[i] - x0) / cell), 0), nx - 1)
        cy = min(max(int((y[i] - y0) / cell), 0), ny - 1)
        key[i] = cx * ny + cy
    order = np.argsort(key, kind="mergesort")
    starts = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        starts[key[i] + 1] += 1
    for c in range(nx * ny):
        starts[c + 1] += starts[c]
    return order, starts


@njit(cache=True)
def _disc_sweep(x, y, a, b, d_min, push):
    """One Gauss–Seidel sweep over the disc pairs closer than ``d_min`` (each disc moved by half the
    overlap when ``push``), then the centres kept in the ellipse (a, b); returns the largest overlap
    met (m) and the smallest centre distance."""
    cell = d_min
    nx, ny = int(2 * a / cell) + 1, int(2 * b / cell) + 1
    order, starts = _grid_order(x, y, -a, -b, cell, nx, ny)
    worst, closest = 0.0, np.inf
    for i in range(x.shape[0]):
        cx = min(max(int((x[i] + a) / cell), 0), nx - 1)
        cy = min(max(int((y[i] + b) / cell), 0), ny - 1)
        for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
            for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
                c = gx * ny + gy
                for q in range(starts[c], starts[c + 1]):
                    j = order[q]
                    if j <= i:
                        continue
                    dx, dy = x[j] - x[i], y[j] - y[i]
                    d = math.sqrt(dx * dx + dy * dy)
                    closest = min(closest, d)
                    if d >= d_min:
                        continue
                    worst = max(worst, d_min - d)
                    if not push:
                        continue
                    if d < 1e-12 * d_min:  # coincident centres: a fixed direction by the pair
                        dx, dy, d = math.cos(i + 0.5 * j), math.sin(i + 0.5 * j), 1.0
                    shift = 0.5 * (d_min - d) / d
                    x[i] -= shift * dx
                    y[i] -= shift * dy
                    x[j] += shift * dx
                    y[j] += shift * dy
    if push:
        for i in range(x.shape[0]):
            s = math.sqrt((x[i] / a) ** 2 + (y[i] / b) ** 2)
            if s > 1.0:
                x[i] /= s
                y[i] /= s
    return worst, closest


@njit(cache=True)
def _relax_discs(x, y, a, b, d_min, tolerance, max_sweeps):
    """Sweeps of :func:`_disc_sweep` until the largest overlap is ≤ ``tolerance``; returns the sweeps
    made and the largest overlap of a fresh check."""
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        worst, _ = _disc_sweep(x, y, a, b, d_min, True)
        if worst <= tolerance:
            break
    worst, _ = _disc_sweep(x, y, a, b, d_min, False)
    return sweeps, worst


def densest_reached(x, y, a, b, d_min: float, tolerance: float) -> float:
    """The jammed discs (x, y) shrunk by 1 % steps, relaxed ``JAM_SWEEPS`` sweeps at each, until
    they clear: the ratio of that packing's v_f0 to the asked one (decompression from the jam,
    the reverse of Lubachevsky–Stillinger's growth)."""
    diameter = d_min
    for _ in range(60):
        diameter *= 0.99
        _, worst = _relax_discs(x, y, a, b, diameter, tolerance, JAM_SWEEPS)
        if worst <= tolerance:
            break
    return (diameter / d_min) ** 2


def pack_cross_section(sp, radius_m: float, section: YarnSection, rng, where: str) -> tuple[np.ndarray, int]:
    """The discs' centres on the unit disc (x/a', y/b') and the sweeps made; a one-line error naming
    specimen.volume_fraction, with the densest v_f0 reached, when the discs jam before they clear."""
    a, b = section.semi_width_m - radius_m, section.semi_height_m - radius_m
    if a <= 0 or b <= 0:
        raise ConfigError(f"specimen.n_fibers = {sp.n_fibers}: the yarn's cross-section is narrower than a fiber "
                          "(raise n_fibers or lower specimen.yarn.aspect_ratio)", where=where)
    n = sp.n_fibers
    rho = np.sqrt(rng.uniform(0.0, 1.0, n))
    angle = rng.uniform(0.0, 2 * math.pi, n)
    x, y = a * rho * np.cos(angle), b * rho * np.sin(angle)
    # a fiber inclined by the helix angle α cuts the plane in an ellipse 2r/cos α long along the turn:
    # the discs are spaced for the surface's α, so that the helices clear each other in 3D
    tan_alpha = 2 * math.pi * section.turns_per_m * max(section.semi_width_m, section.semi_height_m)
    d_min = (2 * radius_m + sp.gap) * math.sqrt(1 + tan_alpha**2)
    sweeps, worst = _relax_discs(x, y, a, b, d_min, 0.5 * sp.gap, MAX_DISC_SWEEPS)
    if worst > 0.5 * sp.gap:
        reached = densest_reached(x, y, a, b, d_min, 0.5 * sp.gap) * sp.volume_fraction
        raise ConfigError(f"specimen.volume_fraction = {sp.volume_fraction:g} cannot be packed in the yarn's "
                          f"cross-section: the discs jam, the densest overlap-free v_f0 reached is ≈ {reached:.3f} "
                          f"({sweeps} sweeps at the asked one); lower it", where=where)
    return np.column_stack([x / a, y / b]), sweeps


@njit(cache=True)
def _closest_on_segments(p0, p1, q0, q1, gap):
    """Parameters (s, t) of the closest points of segments p0–p1 and q0–q1 (Ericson 2005, §5.1.9)
    and their distance; ``gap`` (3,) receives q(t) − p(s). Scalar arithmetic: no allocation in the
    sweeps' inner loop."""
    a = e = f = c = b = 0.0
    for m in range(3):
        d1, d2, r = p1[m] - p0[m], q1[m] - q0[m], p0[m] - q0[m]
        a += d1 * d1
        e += d2 * d2
        f += d2 * r
        c += d1 * r
        b += d1 * d2
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > 1e-30 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    distance = 0.0
    for m in range(3):
        gap[m] = (q0[m] + t * (q1[m] - q0[m])) - (p0[m] + s * (p1[m] - p0[m]))
        distance += gap[m] * gap[m]
    return s, t, math.sqrt(distance)


@njit(cache=True)
def _push_segments(x, y, i, k, j, kk, s, t, n_xy, overlap):
    """Move the nodes of segments (i, k) and (j, kk) apart along ``n_xy`` (unit, x–y) so that their
    closest points part by ``overlap`` (half each, shared by the nodes by their weights)."""
    share_i = 0.5 * overlap / max((1 - s) ** 2 + s**2, 0.5)
    share_j = 0.5 * overlap / max((1 - t) ** 2 + t**2, 0.5)
    x[i, k] -= (1 - s) * share_i * n_xy[0]
    y[i, k] -= (1 - s) * share_i * n_xy[1]
    x[i, k + 1] -= s * share_i * n_xy[0]
    y[i, k + 1] -= s * share_i * n_xy[1]
    x[j, kk] += (1 - t) * share_j * n_xy[0]
    y[j, kk] += (1 - t) * share_j * n_xy[1]
    x[j, kk + 1] += t * share_j * n_xy[0]
    y[j, kk + 1] += t * share_j * n_xy[1]


@njit(cache=True)
def _segment_sweep(x, y, z, a, b, d_min, push):
    """One Gauss–Seidel sweep over the pairs of segments (fiber i, layer k) closer than ``d_min``,
    layers k − 1 … k + 1 of the other fibers binned on a cell grid of their midpoints, the nodes
    moved in x–y and kept in the ellipse (a, b) when ``push``; returns the largest overlap met (m)."""
    n, points = x.shape
    layers = points - 1
    mx = 0.5 * (x[:, 1:] + x[:, :-1])
    my = 0.5 * (y[:, 1:] + y[:, :-1])
    reach = np.max(np.sqrt((x[:, 1:] - x[:, :-1]) ** 2 + (y[:, 1:] - y[:, :-1]) ** 2))
    cell = d_min + reach
    x0, y0 = min(-a, mx.min()) - cell, min(-b, my.min()) - cell
    nx = int((max(a, mx.max()) - x0) / cell) + 2
    ny = int((max(b, my.max()) - y0) / cell) + 2
    flat_x = np.empty(n * layers)
    flat_y = np.empty(n * layers)
    for i in range(n):  # the grid is per layer: offset each layer's x by a column block
        for k in range(layers):
            flat_x[i * layers + k] = mx[i, k] + k * nx * cell
            flat_y[i * layers + k] = my[i, k]
    order, starts = _grid_order(flat_x, flat_y, x0, y0, cell, nx * layers, ny)
    worst = 0.0
    p0, p1, q0, q1, gap = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    n_xy = np.empty(2)
    for i in range(n):
        for k in range(layers):
            cx = min(max(int((mx[i, k] - x0) / cell), 0), nx - 1)
            cy = min(max(int((my[i, k] - y0) / cell), 0), ny - 1)
            for kk in range(max(k - 1, 0), min(k + 2, layers)):
                for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
                    for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
                        c = (kk * nx + gx) * ny + gy
                        for q in range(starts[c], starts[c + 1]):
                            j = order[q] // layers
                            if j <= i:
                                continue
                            p0[0], p0[1], p0[2] = x[i, k], y[i, k], z[k]
                            p1[0], p1[1], p1[2] = x[i, k + 1], y[i, k + 1], z[k + 1]
                            q0[0], q0[1], q0[2] = x[j, kk], y[j, kk], z[kk]
                            q1[0], q1[1], q1[2] = x[j, kk + 1], y[j, kk + 1], z[kk + 1]
                            s, t, d = _closest_on_segments(p0, p1, q0, q1, gap)
                            if d >= d_min:
                                continue
                            worst = max(worst, d_min - d)
                            if not push:
                                continue
                            lateral = math.sqrt(gap[0] ** 2 + gap[1] ** 2)
                            if lateral < 1e-9 * d_min:  # crossing centre lines: a fixed direction by the pair
                                n_xy[0], n_xy[1], lateral = math.cos(i + 0.5 * j), math.sin(i + 0.5 * j), 1.0
                                overlap = d_min - d
                            else:
                                n_xy[0], n_xy[1] = gap[0] / lateral, gap[1] / lateral
                                overlap = (d_min - d) * d / max(lateral, 0.5 * d)
                            _push_segments(x, y, i, k, j, kk, s, t, n_xy, overlap)
    if push:
        for i in range(n):
            for k in range(points):
                e = math.sqrt((x[i, k] / a) ** 2 + (y[i, k] / b) ** 2)
                if e > 1.0:
                    x[i, k] /= e
                    y[i, k] /= e
    return worst


@njit(cache=True)
def _smooth_lines(x, y, weight):
    """One pass of a (w, 1 − 2w, w) filter along each fiber (the end nodes drawn by w towards the
    line through their two neighbours): spreads the local pushes over the fiber, fewer kinks."""
    n, points = x.shape
    for line in (x, y):
        for i in range(n):
            last = line[i, points - 1] + weight * (2 * line[i, points - 2] - line[i, points - 3] - line[i, points - 1])
            previous = line[i, 0]
            line[i, 0] += weight * (2 * line[i, 1] - line[i, 2] - line[i, 0])
            for k in range(1, points - 1):
                here = line[i, k]
                line[i, k] = weight * previous + (1 - 2 * weight) * here + weight * line[i, k + 1]
                previous = here
            line[i, points - 1] = last


@njit(cache=True)
def _relax_segments(x, y, z, a, b, d_min, tolerance, max_sweeps):
    """Sweeps of :func:`_segment_sweep` until the largest overlap is ≤ ``tolerance``, the first
    ``SMOOTHING_SWEEPS`` followed by a smoothing pass of a weight falling from ¼ to 0 (the pushes
    spread along the fibers first, then the last overlaps cleared); returns the sweeps made and the
    largest overlap of a fresh check."""
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        if _segment_sweep(x, y, z, a, b, d_min, True) <= tolerance and sweeps > SMOOTHING_SWEEPS:
            break
        if sweeps < SMOOTHING_SWEEPS:
            _smooth_lines(x, y, 0.25 * (1.0 - sweeps / SMOOTHING_SWEEPS))
    return sweeps, _segment_sweep(x, y, z, a, b, d_min, False)


class YarnFibers(NamedTuple):
    """The built yarn: centre lines (n_fibers, points) in x, y (centred on the yarn's axis) and the
    common z (m); the sweeps of the disc packing and of the 3D relaxation; the largest overlap left."""

    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    disc_sweeps: int
    segment_sweeps: int
    max_overlap_m: float


def pack_yarn(sp, radius_m: float, seed: int, where: str) -> tuple[YarnFibers, YarnSection]:
    """The yarn of the specimen section ``sp`` (steps (1)–(3) of the module's strategy); one-line
    errors naming specimen.volume_fraction when the cross-section or the 3D fibers cannot be cleared."""
    rng = np.random.default_rng([seed, 53])
    yarn = sp.yarn
    z = np.linspace(0.0, sp.length, sp.points_per_fiber)
    draws = draw_fibers(yarn, sp.n_fibers, rng)
    section = yarn_section(sp, radius_m, draws, z, rng)
    unit_xy, disc_sweeps = pack_cross_section(sp, radius_m, section, rng, where)
    centres = section._replace(semi_width_m=section.semi_width_m - radius_m,
                               semi_height_m=section.semi_height_m - radius_m, centre_y_m=0.0)
    x, y = extrude(unit_xy, centres, draws, yarn, z)
    x, y = np.ascontiguousarray(x), np.ascontiguousarray(y)
    d_min = 2 * radius_m + sp.gap
    segment_sweeps, worst = _relax_segments(x, y, z, centres.semi_width_m, centres.semi_height_m, d_min,
                                            0.5 * sp.gap, MAX_SEGMENT_SWEEPS)
    overlap = max(worst - sp.gap, 0.0)
    if overlap > yarn.overlap_tolerance * radius_m:
        reached = sp.volume_fraction * (1 - overlap / (2 * radius_m)) ** 2
        raise ConfigError(f"specimen.volume_fraction = {sp.volume_fraction:g} cannot be packed with this yarn's twist, "
                          f"orientation spread and waviness: {overlap / radius_m:.3g} r of overlap is left after "
                          f"{segment_sweeps} sweeps (the densest overlap-free v_f0 ≈ {reached:.3f}); lower it or "
                          "specimen.yarn.orientation_spread / wave_amplitude", where=where)
    return YarnFibers(x, y, z, disc_sweeps, segment_sweeps, overlap), section


def measured_volume_fraction(fibers: YarnFibers, section: YarnSection, radius_m: float) -> float:
    """The built yarn's v_f0: the fibers' volume (π r² × their arc lengths) over the smallest
    ellipse of the asked aspect ratio around the fibers' surfaces (× the length along z)."""
    a, b = section.semi_width_m - radius_m, section.semi_height_m - radius_m
    scale = float(np.max(np.sqrt((fibers.x_m / a) ** 2 + (fibers.y_m / b) ** 2)))
    volume = math.pi * radius_m**2 * float(np.sum(arc_lengths_m(fibers.x_m, fibers.y_m, fibers.z_m)))
    length = float(fibers.z_m[-1] - fibers.z_m[0])
    return volume / (math.pi * (scale * a + radius_m) * (scale * b + radius_m) * length)


def build_yarn_specimen(cfg, raw: dict, out: Path, *, where: str, seed: int, ready_config_text) -> dict:
    """``fiberpipe specimen`` for ``kind: yarn``: pack the yarn, write fibers.h5, specimen.json and the
    ready config.yaml (plates at 0 and the yarn's height 2b + clearance, the walls at x = ±a or none);
    returns specimen.json's dict."""
    import copy
    import time

    from fiberpipe.artifacts import write_fibers, write_json_atomic, write_text_atomic
    from fiberpipe.polylines import Polylines

    sp = cfg.specimen
    r = float(cfg.fiber.radius)
    h = float(cfg.mesh.element_length)
    if sp.yarn.wave_amplitude > 0 and sp.yarn.wave_length < 4 * h:
        raise ConfigError(f"specimen.yarn.wave_length = {sp.yarn.wave_length * 1e3:.4g} mm spans fewer than 4 elements "
                          f"of mesh.element_length = {h * 1e3:.4g} mm: lengthen it", where=where)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    fibers, section = pack_yarn(sp, r, seed, where)
    a, b = section.semi_width_m, section.semi_height_m
    height = 2 * b + sp.gap
    points = np.stack([fibers.x_m, fibers.y_m + b + 0.5 * sp.gap,
                       np.broadcast_to(fibers.z_m, fibers.x_m.shape)], axis=-1)
    polylines = Polylines.from_list(list(points), r)
    vf = measured_volume_fraction(fibers, section, r)
    tan_alpha = 2 * math.pi * section.turns_per_m * math.sqrt(a * b)
    info = {
        "kind": "yarn", "width_m": 2 * a, "height_m": height, "depth_m": sp.length, "length_m": sp.length,
        "semi_axes_m": [a, b], "volume_fraction": vf, "target_volume_fraction": sp.volume_fraction,
        "pile_volume_fraction": vf, "pile_top_m": float(points[..., 1].max() + r),
        "box_min_m": [-a, 0.0, 0.0], "box_max_m": [a, height, sp.length],
        "twist": {"turns_per_m": section.turns_per_m, "surface_helix_angle_deg": math.degrees(math.atan(tan_alpha))},
        "max_overlap_m": fibers.max_overlap_m, "max_overlap_fraction_of_radius": fibers.max_overlap_m / r,
        "packing": {"disc_sweeps": fibers.disc_sweeps, "segment_sweeps": fibers.segment_sweeps,
                    "wall_time_s": time.perf_counter() - wall0, "cpu_time_s": time.process_time() - cpu0},
        "generator": {"function": "fiberpipe.model.specimen_yarn.pack_yarn", "seed": seed,
                      "n_fibers": sp.n_fibers, "specimen": sp.model_dump(mode="json")},
    }
    ready = copy.deepcopy(raw)
    # no scan to compare with: the position error (a one-to-one matching of the fibers, quadratic in
    # their number) would compare the yarn with its own start at every frame
    if isinstance(ready.get("post"), dict):
        ready["post"].pop("reference_fibers", None)
    scene = ready.setdefault("scene", {})
    effects = scene.setdefault("effects", [])
    if sp.yarn.walls and "walls" not in effects:
        effects.append("walls")
    elif not sp.yarn.walls:
        scene["effects"] = [e for e in effects if e != "walls"]
        scene.pop("walls", None)
    out.mkdir(parents=True, exist_ok=True)
    write_fibers(out / "fibers.h5", polylines)
    write_json_atomic(out / "specimen.json", info)
    write_text_atomic(out / "config.yaml", ready_config_text(ready, out, height, 2 * a, where, strain=sp.strain))
    return info


def yarn_report(info: dict, out: Path) -> str:
    """The command's summary for ``kind: yarn``."""
    a, b = info["semi_axes_m"]
    p = info["packing"]
    return "\n".join([
        f"wrote {out}/fibers.h5 ({info['generator']['n_fibers']} fibers, yarn), {out}/specimen.json, {out}/config.yaml",
        f"  cross-section {2 * a * 1e3:.4g} x {2 * b * 1e3:.4g} mm (plate gap {info['height_m'] * 1e3:.5g} mm), "
        f"length {info['length_m'] * 1e3:.4g} mm; v_f0 {info['volume_fraction']:.4f} (target "
        f"{info['target_volume_fraction']:.4f}); surface helix angle {info['twist']['surface_helix_angle_deg']:.3g} deg",
        f"  packed in {p['disc_sweeps']} disc sweeps and {p['segment_sweeps']} 3D sweeps, {p['wall_time_s']:.1f} s wall, "
        f"{p['cpu_time_s']:.1f} s CPU; largest fiber-fiber overlap {info['max_overlap_fraction_of_radius']:.2g} r",
    ])
