"""Validation case 5: friction and loading cycles on the random 3D network of case 2.

Each seed's specimen (a random 3D network of case 2's kind and settings, 24 fibers in a 10 mm cell:
:data:`CYCLE_NETWORK`) runs a load–unload–reload cycle (U → 0.6 U → U, U 0.6 of the plate gap) with the
config's friction μ = 0.2 and again with μ = 0 (the same damping):
- the friction shift (Rodney et al., PRL 95:108004, 2005; Barbier et al., PRE 80:016115, 2009, as
  cited: friction makes the response stiffer, frictionless packings denser at a given pressure):
  the upper plate's force at U on first loading, μ = 0 over μ = 0.2, must stay below 1;
- the loop's energy balance (μ = 0.2): the plates' net work over the unload–reload cycle equals the
  friction and damping dissipation booked over it plus the change in stored energy (ALLFD + ALLVD +
  Δ(ALLSE + contact stored + ALLKE)), within 2 % of the net work;
- the loop area with μ = 0 under 5 % of the μ = 0.2 loop's (the hysteresis is friction's)."""

from __future__ import annotations

import numpy as np

from .network_cases import runs_by_seed
from .rows import ValidationRow

BALANCE_TOLERANCE = 0.02
AREA_BOUND = 0.05
#: the quick tolerances (a 24-fiber network at three times the speed, one seed): friction still
#: stiffens, the loop's energy closes within 5 %, the frictionless loop is under a fifth of the rough one
QUICK_BOUNDS = {"shift": (0.0, 1.0), "balance": (0.0, 0.05), "area": (-0.2, 0.2)}
UNLOAD_FRACTION = 0.6
#: the full case's networks: case 2's kind, fiber and settings (quasi-static) in a 10 mm × 10 mm cell of 24
#: fibers, a quarter of case 2's fibers: its cycles (1.8 times a compaction's travel, with and without
#: friction, three seeds) on case 2's 100 fibers would take several times the case's 15 min of CPU
CYCLE_NETWORK = {"specimen.n_fibers": 24, "specimen.width": "10 mm", "specimen.depth": "10 mm"}
SOURCE_SHIFT = ("Rodney et al. 2005 (PRL 95:108004), Barbier et al. 2009 (PRE 80:016115): friction stiffens the "
                "response (as cited; texts not retrieved)")
SOURCE_BALANCE = "energy balance over the cycle: W_plates = ALLFD + ALLVD + ΔE_stored (Abaqus' energy outputs)"
SOURCE_AREA = "Subramanian & Picu 2011 (PRE 83:056120): the hysteresis of non-bonded networks is friction's (as cited)"


def set_dotted_config(cfg, key: str, value) -> None:
    """Set a dotted key of a validated config (validated on assignment: units are converted)."""
    *parents, last = key.split(".")
    node = cfg
    for part in parents:
        node = getattr(node, part)
    setattr(node, last, value)


def cycle_overrides(strain: float, gap_m: float) -> dict:
    travel = strain * gap_m
    path = [travel, UNLOAD_FRACTION * travel, travel]
    return {"specimen.strain": None, "scene.loading.displacement": travel, "scene.loading.path": path}


def turning_row(run) -> int:
    """The history row where the first loading ends: the largest travel before the unloading's
    lowest point. (The rows sample the steps: the row nearest the turn may fall short of the end's
    travel by a few 1e-8 of it, so the first row at the largest travel would be the reload's end.)"""
    travel = np.asarray(run.simulation.history["plate_displacement"], float).sum(axis=1)
    near_top = int(np.argmax(travel >= 0.99 * travel.max()))
    bottom = near_top + int(np.argmin(travel[near_top:]))
    return int(np.argmax(travel[: bottom + 1]))


def loop_figures(run) -> dict:
    """Net plate work over the unload–reload, the dissipation and stored-energy change booked over it."""
    e = run.simulation.energy
    k = turning_row(run)

    def delta(name):
        v = np.asarray(e[name], float)
        return float(v[-1] - v[k])

    work = delta("external")
    dissipated = delta("friction") + delta("damping")
    stored = delta("strain") + delta("contact_stored") + delta("kinetic")
    force = np.asarray(run.simulation.history["plate_force"], float)[:, 1]
    return {"work_J": work, "dissipated_J": dissipated, "stored_change_J": stored, "force_at_turn_N": float(force[k])}


def validate(quick: bool = False) -> list[ValidationRow]:
    from .compaction_runs import cell_height, validation_config
    from .network_cases import QUICK

    cfg = validation_config("network-3d.yaml")
    network = {} if quick else CYCLE_NETWORK
    for key, value in {**(QUICK["network-3d.yaml"] if quick else {}), **network}.items():
        set_dotted_config(cfg, key, value)
    overrides = {**network, **cycle_overrides(float(cfg.specimen.strain), cell_height(cfg))}
    from .compaction_runs import paired

    pairs = paired(runs_by_seed("network-3d.yaml", quick, overrides),
                   runs_by_seed("network-3d.yaml", quick, {**overrides, "scene.friction.mu": 0.0}))
    rough = [loop_figures(r) for r, _ in pairs]
    smooth = [loop_figures(s) for _, s in pairs]
    case = "5 friction and cycles (network 3D)"
    bounds = QUICK_BOUNDS if quick else {}
    balance = [abs(f["work_J"] - f["dissipated_J"] - f["stored_change_J"]) / abs(f["work_J"]) for f in rough]
    return [
        ValidationRow(case, "force at U on first loading, μ = 0 over μ = 0.2", 0.0,
                      [s["force_at_turn_N"] / r["force_at_turn_N"] for s, r in zip(smooth, rough)], 1.0,
                      SOURCE_SHIFT, relative=False, bounds=bounds.get("shift")),
        ValidationRow(case, "loop (μ = 0.2): the size of W − ALLFD − ALLVD − ΔE over W, unload–reload", 0.0, balance,
                      BALANCE_TOLERANCE, SOURCE_BALANCE, relative=False,
                      note="W " + ", ".join(f"{f['work_J']:.3g}" for f in rough) + " J", data={"loops": rough},
                      bounds=bounds.get("balance")),
        ValidationRow(case, "loop area μ = 0 over μ = 0.2", 0.0, [s["work_J"] / r["work_J"] for s, r in zip(smooth, rough)],
                      AREA_BOUND, SOURCE_AREA, relative=False, data={"loops_frictionless": smooth},
                      bounds=bounds.get("area")),
    ]
