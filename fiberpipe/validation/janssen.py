"""Validation case 6: wall friction in a confined cassette against Janssen's formula.

A bundle between two side walls of gap w, pressed by the lower plate, loses force to the walls'
friction on its way up. Janssen (Z. Ver. Dtsch. Ing. 39:1045, 1895; the formula as textbooks give
it, the paper not retrieved): with a lateral pressure coefficient K = σ_h/σ_v and wall friction μ_w,
a slice's balance w dσ_v/dy = −2 μ_w K σ_v gives σ_v(y) = σ_v(0) exp(−2 μ_w K y / w), so the upper
plate receives F_u/F_l = exp(−2 μ_w K h / w) of the lower plate's force over a bundle of height h.
K is measured in the same run: the side walls' mean normal force over their area (h × depth)
against the plates' mean force over theirs (w × depth). The runs are case 4's (the aligned wavy
bundle in its cassette, μ_w = μ = 0.2 on the walls), read at the end of the compaction."""

from __future__ import annotations

import math

import numpy as np

from .network_cases import runs_of
from .rows import ValidationRow

TOLERANCE = 0.10
#: the quick tolerance (a 20-fiber bundle in a 3 mm cassette, one seed): within 30 %
QUICK_BOUNDS = (0.7, 1.3)
SOURCE = "Janssen 1895: F_u/F_l = exp(−2 μ_w K h / w), K measured from the side walls' forces (formula as textbooks give it)"


def janssen_figures(run, tail: float = 0.05) -> dict:
    """K, the measured F_u/F_l and Janssen's, from the last ``tail`` of the run's history rows."""
    spec, h = run.specimen, run.simulation.history
    rows = max(1, int(tail * len(h["time"])))
    plates = np.asarray(h["plate_force"], float)[-rows:].mean(axis=0)  # lower, upper
    walls = np.asarray(h["wall_force"], float)[-rows:].mean(axis=0)     # x low, x high, z low, z high
    travel = float(np.asarray(h["plate_displacement"], float)[-rows:].sum(axis=1).mean())
    height = spec["height_m"] - travel
    sigma_h = 0.5 * (walls[0] + walls[1]) / (height * spec["depth_m"])
    sigma_v = 0.5 * (plates[0] + plates[1]) / (spec["width_m"] * spec["depth_m"])
    mu = float(run.config.scene.friction.mu)
    k = sigma_h / sigma_v
    return {"K": k, "mu_w": mu, "height_m": height, "ratio_measured": plates[1] / plates[0],
            "ratio_janssen": math.exp(-2 * mu * k * height / spec["width_m"])}


def validate(quick: bool = False) -> list[ValidationRow]:
    figures = [janssen_figures(run) for run in runs_of("wavy-bundle.yaml", quick)]
    ratios = [f["ratio_measured"] / f["ratio_janssen"] for f in figures]
    return [ValidationRow("6 wall friction (Janssen)", "F_u/F_l over Janssen's exp(−2 μ_w K h/w), K measured", 1.0,
                          ratios, TOLERANCE, SOURCE,
                          note="K " + ", ".join(f"{f['K']:.3g}" for f in figures) + "; F_u/F_l "
                               + ", ".join(f"{f['ratio_measured']:.3g}" for f in figures),
                          data={"figures": figures}, bounds=QUICK_BOUNDS if quick else None)]
