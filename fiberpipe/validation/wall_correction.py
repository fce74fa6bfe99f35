"""Validation case 8: the walls' share of a bundle's response, measured and extrapolated to a bulk sample.

The literature compacts bulk samples in periodic cells; fiberpipe's cells are closed by walls (its
contact and planes have no periodic boundaries). This case measures what the walls change: case 4's
aligned wavy bundle is compacted in cassettes of three widths w at the same v_f0 (the fiber count in
proportion to w, the depth and the fibers unchanged), Gutowski's law is fitted to each, and each
parameter is extrapolated to w → ∞ by a straight line in 1/w: the side walls' area over the sample's
volume is 2/w, so a wall effect per unit wall area enters the averages as c/w (least squares over the
widths, y(w) = y_∞ + c/w). The correction of the case's own width w_0 is y(w_0)/y_∞ − 1.

The same runs give the walls' friction loss: ln(F_u/F_l) = −2 μ_w K h/w (Janssen, case 6) is
linear in 1/w and extrapolates to 0 at w → ∞ when K does not change with the width; the row reports
its extrapolated value. The rows are informational: they state the correction, they do not judge a
law (case 4 does)."""

from __future__ import annotations

import math

import numpy as np

from .compaction_runs import paired, runs_over_seeds, seeds_for
from .network_cases import MIN_FIT_R2, QUICK
from .rows import ValidationRow

#: (fiber count, cell width) of the cassettes, the case's own (100 fibers, 7.5 mm) in the middle:
#: the same v_f0 at every width (the count in proportion to the width)
WIDTHS_FULL = ((50, "3.75 mm"), (100, "7.5 mm"), (200, "15 mm"))
#: the quick variant: case 4's quick bundle (20 fibers, 3 mm) and one and a half times it (a narrower
#: cassette jams the random placement at v_f0 = 0.35)
WIDTHS_QUICK = ((20, "3 mm"), (30, "4.5 mm"))
#: the quick tolerance: the extrapolated friction loss ln(F_u/F_l) at w → ∞ within ±0.2 of 0
QUICK_BOUNDS = (-0.2, 0.2)
SOURCE = ("walls' share measured: y(w) = y_∞ + c/w over the cassette widths (side-wall area over volume 2/w); "
          "Gutowski's law fitted to each width (case 4)")
SOURCE_JANSSEN = "Janssen 1895: ln(F_u/F_l) = −2 μ_w K h/w → 0 as w → ∞ (K constant)"


def width_overrides(quick: bool) -> list[dict]:
    """The overrides of each cassette width; the case's own width has none (its runs are case 4's)."""
    widths = WIDTHS_QUICK if quick else WIDTHS_FULL
    base = QUICK["wavy-bundle.yaml"] if quick else {}
    own = (base.get("specimen.n_fibers", 100), base.get("specimen.width", "7.5 mm"))
    return [dict(base) if (n, w) == own else {**base, "specimen.n_fibers": n, "specimen.width": w}
            for n, w in widths]


def extrapolate_inverse_width(widths_m, values) -> tuple[float, float]:
    """Least-squares line y = y_∞ + c/w through (1/w, y); returns (y_∞, c). Two widths at least."""
    x = 1.0 / np.asarray(widths_m, float)
    y = np.asarray(values, float)
    slope, intercept = np.polyfit(x, y, 1)
    return float(intercept), float(slope)


def width_figures(run, quick: bool) -> dict:
    """One run's cassette width, Gutowski parameters (nan below the fit's R² gate in the full
    case) and the end's friction loss ln(F_u/F_l)."""
    fit = run.summary.get("mesoscale_laws", {}).get("gutowski", {})
    good = quick or fit.get("r2_log", -1.0) >= MIN_FIT_R2
    history = run.simulation.history
    rows = max(1, int(0.05 * len(history["time"])))
    lower, upper = np.asarray(history["plate_force"], float)[-rows:].mean(axis=0)
    loss = math.log(upper / lower) if upper > 0 and lower > 0 else float("nan")
    return {"width_m": run.specimen["width_m"], "n_fibers": run.specimen["generator"]["n_fibers"],
            "beta": fit.get("beta", math.nan) if good else math.nan, "v0": fit.get("v0", math.nan) if good else math.nan,
            "va": fit.get("va", math.nan) if good else math.nan, "log_force_ratio": loss}


def extrapolated(per_seed: list[list[dict]], key: str, own_width_m: float) -> tuple[list, list, list]:
    """Per seed: y_∞, the correction y(w_0)/y_∞ − 1 at the case's width and the values by width."""
    limits, corrections, values = [], [], []
    for figures in per_seed:
        y = [f[key] for f in figures]
        values.append(y)
        if not all(math.isfinite(v) for v in y):
            limits.append(math.nan)
            corrections.append(math.nan)
            continue
        y_inf, slope = extrapolate_inverse_width([f["width_m"] for f in figures], y)
        limits.append(y_inf)
        corrections.append((y_inf + slope / own_width_m) / y_inf - 1 if y_inf else math.nan)
    return limits, corrections, values


def validate(quick: bool = False) -> list[ValidationRow]:
    from .compaction_runs import validation_config

    by_width = [runs_over_seeds("wavy-bundle.yaml", overrides, seeds_for(quick)) for overrides in width_overrides(quick)]
    per_seed = [[width_figures(run, quick) for run in runs] for runs in paired(*by_width)]
    widths = sorted({round(f["width_m"] * 1e3, 4) for figures in per_seed for f in figures})
    own_width = 3e-3 if quick else 7.5e-3
    wave = validation_config("wavy-bundle.yaml").specimen.wave
    case = "8 walls' share (wavy bundle)"
    method = f"widths {', '.join(f'{w:g}' for w in widths)} mm, linear in 1/w"
    rows = []
    for key, label in (("beta", "β from Gutowski's A_s"), ("v0", "Gutowski's V_0")):
        limits, corrections, values = extrapolated(per_seed, key, own_width)
        note = (f"{method}; by width per seed " + "; ".join(", ".join(f"{v:.3g}" for v in y) for y in values)
                + "; the case's width is off by " + ", ".join(f"{100 * c:+.2g} %" for c in corrections))
        reference = wave.span / wave.rise if key == "beta" else math.nan
        rows.append(ValidationRow(case, f"{label} at infinite width", reference, limits, 0.30, SOURCE,
                                  informational=True, note=note,
                                  data={"values_by_width": values, "corrections": corrections, "widths_mm": widths}))
    limits, _, values = extrapolated(per_seed, "log_force_ratio", own_width)
    rows.append(ValidationRow(case, "ln(F_u/F_l) at infinite width (the walls' friction loss)", 0.0, limits, 0.02,
                              SOURCE_JANSSEN, relative=False, informational=not quick,
                              note=f"{method}; by width per seed "
                                   + "; ".join(", ".join(f"{v:.3g}" for v in y) for y in values),
                              data={"values_by_width": values, "widths_mm": widths},
                              bounds=QUICK_BOUNDS if quick else None))
    return rows
