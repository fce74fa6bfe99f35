"""Traced fibers as the per-fiber CSV of FeatureScout (FiberScout) in open_iA.

The layout is open_iA's "FCP fiber format" (``iACsvConfig::getFCPFiberFormat``), the one its
FeatureScout tool assumes for a fiber CSV: five lines it skips (the second must not read
``Voids``, which marks a pore file), then one line per fiber, comma-separated, "." decimals, no
header row, 14 columns in micrometres::

    Label, X1, Y1, Z1, X2, Y2, Z2, StraightLength, CurvedLength, Diameter, Surface, Volume,
    SeperatedFibre, CurvedFibre

(the column names are open_iA's, "Seperated" included). open_iA computes each fiber's angles
phi (azimuth in the x-y plane) and theta (from z) from the start and end points when it loads the
file (the FCP format has no columns for them); :func:`fiber_angles_deg` gives them by the same
rule for readers without open_iA. The five skipped lines here name the columns.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_text_atomic

#: open_iA's FCP fiber columns, in order (micrometres; the last two are 0/1 flags).
COLUMNS = ("Label", "X1[µm]", "Y1[µm]", "Z1[µm]", "X2[µm]", "Y2[µm]", "Z2[µm]", "StraightLength[µm]",
           "CurvedLength[µm]", "Diameter[µm]", "Surface[µm²]", "Volume[µm³]", "SeperatedFibre", "CurvedFibre")
#: A fiber whose curved length exceeds its straight length by more than this fraction is flagged curved.
CURVED_EXCESS = 0.01


def fiber_angles_deg(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per fiber: phi, the azimuth of the end-to-end direction in the x-y plane (0-360 deg from x),
    and theta, its angle from the z axis (0-90 deg; the direction's sign does not matter)."""
    d = np.asarray(end, float) - np.asarray(start, float)
    d = np.where((d[:, 2] < 0)[:, None], -d, d)  # one of the two equivalent directions: dz >= 0
    phi = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360.0
    theta = np.degrees(np.arccos(np.clip(d[:, 2] / np.maximum(np.linalg.norm(d, axis=1), 1e-300), -1, 1)))
    return phi, theta


def write_fiberscout_csv(path: str | Path, fibers) -> Path:
    """Write ``fibers`` (:class:`~fiberpipe.polylines.Polylines`, m) as an open_iA FCP fiber CSV
    (micrometres), atomically: one row per fiber, labels from 1; surface and volume of a cylinder
    of the fiber's diameter and curved length."""
    um = 1e6
    n = fibers.n_fibers
    start = np.array([fibers.fiber(i)[0] for i in range(n)]).reshape(-1, 3) * um
    end = np.array([fibers.fiber(i)[-1] for i in range(n)]).reshape(-1, 3) * um
    curved = fibers.lengths_m() * um
    straight = np.linalg.norm(end - start, axis=1)
    diameter = 2.0 * np.broadcast_to(np.asarray(fibers.radius_m, float), (n,)) * um
    surface = np.pi * diameter * curved
    volume = 0.25 * np.pi * diameter ** 2 * curved
    head = ["fiberpipe traced fibers (open_iA FCP fiber format; lengths in micrometres)", "Fibers",
            "columns: " + ", ".join(COLUMNS),
            "phi (azimuth from x in the x-y plane) and theta (from z) of X2-X1: computed by open_iA on load",
            f"{n} fibers"]
    rows = []
    for i in range(n):
        values = (*start[i], *end[i], straight[i], curved[i], diameter[i], surface[i], volume[i])
        rows.append(",".join([str(i + 1), *(f"{v:.6f}" for v in values), "0",
                              "1" if curved[i] > (1 + CURVED_EXCESS) * straight[i] else "0"]))
    write_text_atomic(path, "\n".join(head + rows) + "\n")
    return Path(path)
