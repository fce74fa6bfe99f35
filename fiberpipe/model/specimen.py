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
) -> tuple[Polylines, dict]:
    """Quasi-parallel fibers along z in a box of ``width_m`` (x) × height (y) × ``length_m`` (z).

    # Strategy: the height follows from the volume fraction (v_f = N π r² L / (w h L)); fibers
    # sit on a ``columns`` × ceil(N/columns) lattice whose free space (pitch − 2r) is shared out
    # as random jitter (a fraction ``jitter`` of it), get a random tilt in x and y (fibers then
    # cross at a few degrees, as the study's did: its average contact angle is 6°) and a sine
    # waviness; then, alternately, they are clipped into the cassette and pushed apart where they
    # cross (:func:`fiberpipe.model.mesh.resolve_overlaps`), until neither moves them.

    Returns
    -------
    Polylines, and a dict with ``height_m``, ``width_m``, ``volume_fraction`` and the box bounds.
    """
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
