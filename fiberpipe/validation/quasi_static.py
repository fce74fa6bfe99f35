"""Validation case 7: the compaction runs are quasi-static (the study's Eq. 5).

For the random 3D network of case 2 (the same specimens and settings), each seed is compacted again
at half the loading speed: the load-cell curve F(U) may change by at most 5 % (window means over ten
windows of U, relative to the largest load), and in the loaded phase (p above 1 % of its peak) the
kinetic energy stays below 1 % of the strain energy (K_e ≤ 0.01 S_e)."""

from __future__ import annotations

import numpy as np

from .network_cases import runs_by_seed
from .rows import ValidationRow

CURVE_TOLERANCE = 0.05
KINETIC_BOUND = 0.01
#: the quick tolerances (a 24-fiber network at three times the speed, one seed): the curves at the
#: two speeds agree within half the largest load, and the kinetic energy stays below the strain
#: energy in the loaded phase (the loading is no impact)
QUICK_BOUNDS = {"curve": (0.0, 0.5), "kinetic": (0.0, 1.0)}
WINDOWS = 10
SOURCE_SPEED = "quasi-static: the response does not depend on the loading speed (half of it: ≤ 5 %)"
SOURCE_KE = "the study's Eq. 5: K_e ≤ 0.01 S_e in the loaded phase (Abaqus' quasi-static criterion)"


def window_means(travel, force, edges) -> np.ndarray:
    idx = np.digitize(travel, edges) - 1
    return np.array([force[idx == k].mean() if np.any(idx == k) else np.nan for k in range(len(edges) - 1)])


def curve_change(base, slow) -> float:
    """Largest change of the window means of the upper plate's force between two runs over their
    first loading, relative to the base run's largest force."""
    def curve(run):
        h = run.simulation.history
        return np.asarray(h["plate_displacement"], float).sum(axis=1), np.asarray(h["plate_force"], float)[:, 1]

    (u0, f0), (u1, f1) = curve(base), curve(slow)
    edges = np.linspace(0.0, min(u0.max(), u1.max()), WINDOWS + 1)
    return float(np.nanmax(np.abs(window_means(u1, f1, edges) - window_means(u0, f0, edges))) / np.max(f0))


def kinetic_over_strain(run) -> float:
    """Largest K_e/S_e over the loaded phase (upper plate force above 1 % of its peak)."""
    h, e = run.simulation.history, run.simulation.energy
    force = np.asarray(h["plate_force"], float)[:, 1]
    loaded = force > 0.01 * force.max()
    strain = np.asarray(e["strain"], float)[loaded]
    return float(np.max(np.asarray(e["kinetic"], float)[loaded] / np.maximum(strain, 1e-300)))


def validate(quick: bool = False) -> list[ValidationRow]:
    from .compaction_runs import paired, validation_config

    base_runs = runs_by_seed("network-3d.yaml", quick)
    speed = (float(next(iter(base_runs.values())).config.scene.loading.velocity) if base_runs
             else validation_config("network-3d.yaml").scene.loading.velocity)
    pairs = paired(base_runs, runs_by_seed("network-3d.yaml", quick, {"scene.loading.velocity": speed / 2}))
    base, slow = [b for b, _ in pairs], [s for _, s in pairs]
    changes = [curve_change(b, s) for b, s in pairs]
    ratios = [kinetic_over_strain(r) for r in base]
    case = "7 quasi-static (network 3D)"
    bounds = QUICK_BOUNDS if quick else {}
    return [
        ValidationRow(case, f"F(U) change at half the speed ({speed * 6e4:.4g} → {speed * 3e4:.4g} mm/min), "
                      "window means / max F", 0.0, changes, CURVE_TOLERANCE, SOURCE_SPEED, relative=False,
                      bounds=bounds.get("curve")),
        ValidationRow(case, "largest K_e/S_e in the loaded phase", 0.0, ratios, KINETIC_BOUND, SOURCE_KE,
                      relative=False, note="half speed: " + ", ".join(f"{kinetic_over_strain(r):.3g}" for r in slow),
                      bounds=bounds.get("kinetic")),
    ]
