"""Validation case 7: the compaction runs are quasi-static (the study's Eq. 5).

For the random 3D network of case 2 (the same specimens and settings), each seed is compacted again
at half the loading speed: the load-cell curve F(U) may change by at most 5 % (window means over ten
windows of U, relative to the largest load), and in the loaded phase (p above 1 % of its peak) the
kinetic energy stays below 1 % of the strain energy (K_e ≤ 0.01 S_e) in every seed's run.

The K_e row's note names where the kinetic energy comes from (:func:`kinetic_sources`): the fibers
the plate carries at its speed, ½ M v² with the solver's (scaled) mass, which meet a strain energy
that has only started where the load starts; and events (a fiber sliding off or snapping through)
whose K_e exceeds what the plate's speed gives."""

from __future__ import annotations

import math

import numpy as np

from .compaction_runs import curve_change
from .network_cases import runs_by_seed
from .rows import ValidationRow

CURVE_TOLERANCE = 0.05
KINETIC_BOUND = 0.01
#: the quick tolerances (a 24-fiber network at three times the speed, one seed): the curves at the
#: two speeds agree within half the largest load, and the kinetic energy stays below the strain
#: energy in the loaded phase (the loading is no impact)
QUICK_BOUNDS = {"curve": (0.0, 0.5), "kinetic": (0.0, 1.0)}
SOURCE_SPEED = "quasi-static: the response does not depend on the loading speed (half of it: ≤ 5 %)"
SOURCE_KE = "the study's Eq. 5: K_e ≤ 0.01 S_e in the loaded phase (Abaqus' quasi-static criterion)"


def kinetic_over_strain(run) -> float:
    """Largest K_e/S_e over the loaded phase (upper plate force above 1 % of its peak)."""
    h, e = run.simulation.history, run.simulation.energy
    force = np.asarray(h["plate_force"], float)[:, 1]
    loaded = force > 0.01 * force.max()
    strain = np.asarray(e["strain"], float)[loaded]
    return float(np.max(np.asarray(e["kinetic"], float)[loaded] / np.maximum(strain, 1e-300)))


def carried_kinetic_energy(run) -> float:
    """½ M v² [J]: the kinetic energy of every fiber moving at the loading speed, with the solver's
    (scaled) mass. The fibers the plate pushes ahead of the load carry a share of it into the loaded
    phase, where the strain energy starts from nearly nothing."""
    cfg = run.config
    specimen = run.specimen
    mass_kg = (specimen["generator"]["n_fibers"] * float(cfg.material.density) * math.pi
               * float(cfg.fiber.radius) ** 2 * specimen["length_m"] * float(cfg.solver.mass_scaling))
    return 0.5 * mass_kg * float(cfg.scene.loading.velocity) ** 2


def kinetic_sources(run) -> dict:
    """Where the loaded phase's kinetic energy comes from: at its first row (the load has just
    started; the fibers the plate pushes move with it) K_e/S_e and K_e over ½ M v² (the share of the
    fibers carried at the plate's speed), and the largest K_e of the phase over ½ M v² (above 1: energy
    released by an event, a fiber snapping through or sliding off, not the plate's speed)."""
    h, e = run.simulation.history, run.simulation.energy
    force = np.asarray(h["plate_force"], float)[:, 1]
    loaded = np.flatnonzero(force > 0.01 * force.max())
    kinetic, strain = np.asarray(e["kinetic"], float), np.asarray(e["strain"], float)
    carried = carried_kinetic_energy(run)
    first = loaded[0]
    return {"start_ratio": float(kinetic[first] / max(strain[first], 1e-300)),
            "start_carried_share": float(kinetic[first] / carried),
            "largest_over_carried": float(kinetic[loaded].max() / carried),
            "rows_above_bound": float(np.mean(kinetic[loaded] > KINETIC_BOUND * strain[loaded])),
            "carried_J": carried}


def kinetic_note(runs, slow) -> str:
    """The K_e/S_e row's note: each seed's sources (:func:`kinetic_sources`) and the half-speed peaks."""
    parts = []
    for run in runs:
        k = kinetic_sources(run)
        parts.append(f"seed {run.seed}: at the load's start K_e/S_e {k['start_ratio']:.3g} with K_e "
                     f"{k['start_carried_share']:.2g} of ½Mv², largest K_e {k['largest_over_carried']:.3g} × ½Mv², "
                     f"{100 * k['rows_above_bound']:.3g} % of the loaded rows above 1 %")
    return "; ".join(parts) + "; half speed: " + ", ".join(f"{kinetic_over_strain(r):.3g}" for r in slow)


def validate(quick: bool = False) -> list[ValidationRow]:
    from .compaction_runs import paired, validation_config

    base_runs = runs_by_seed("network-3d.yaml", quick)
    speed = (float(next(iter(base_runs.values())).config.scene.loading.velocity) if base_runs
             else validation_config("network-3d.yaml").scene.loading.velocity)
    pairs = paired(base_runs, runs_by_seed("network-3d.yaml", quick, {"scene.loading.velocity": speed / 2}))
    base, slow = list(base_runs.values()), [s for _, s in pairs]  # K_e/S_e of every seed's run, paired or not
    changes = [curve_change(b, s) for b, s in pairs]
    ratios = [kinetic_over_strain(r) for r in base]
    case = "7 quasi-static (network 3D)"
    bounds = QUICK_BOUNDS if quick else {}
    return [
        ValidationRow(case, f"F(U) change at half the speed ({speed * 6e4:.4g} → {speed * 3e4:.4g} mm/min), "
                      "window means / max F", 0.0, changes, CURVE_TOLERANCE, SOURCE_SPEED, relative=False,
                      bounds=bounds.get("curve")),
        ValidationRow(case, "largest K_e/S_e in the loaded phase", 0.0, ratios, KINETIC_BOUND, SOURCE_KE,
                      relative=False, note=kinetic_note(base, slow),
                      bounds=bounds.get("kinetic")),
    ]
