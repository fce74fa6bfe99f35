"""Make the study-like 40-fiber specimen in data-samples/paper-40/ (committed with its outputs).

Run from the repository root: ``python data-samples/make_paper40.py``. Deterministic (seed 0).
With the shipped options it is one call of ``fiberpipe specimen configs/specimens/paper-40.yaml
--out data-samples/paper-40`` (docs/specimen.md), which also writes a ready ``config.yaml``; the
variants below keep their own path.
40 quasi-parallel fibers, Ø 0.5 mm, 15 mm long, along z, in a 3 mm wide cassette (x from −1.5 to
1.5 mm) at v_f0 = 37.7 % (height ≈ 6.94 mm along y, from 0), as in the study, shaped to match the
statistics the study gives for its scanned specimen (data-samples/paper-40/README.md):

- relative orientation of neighbouring fibers: mean 6° (the study's Φ_average; range 2–10°).
  Tilts are normal with σ = Φ_mean/√π per component (the mean of the Rayleigh-distributed angle
  between two such fibers), and the packing keeps them (``placement="rigid"``);
- projected curvature ≈ 0.24 1/m on XZ and YZ (Table 4: 0.241 and 0.248 1/m at U = 0): each
  fiber is a circular arc of κ = (π/2)·0.2445 1/m (a random plane projects 2/π of it on average);
- no overlaps (closest centre lines ≥ 2r + 1 µm) and every fiber inside the cassette;
- a loose pile resting under gravity (``placement="deposit"``): each fiber dropped and settled
  on the plate or on fibers below (supported on both sides of its centre of mass), contacts at
  1 µm clearance, the upper plate placed touching the pile's top (``top="pile"``), as the study
  placed its specimen "in contact with the upper plate". Two trial drops per fiber, the lower
  kept, give the study's v_f0 (one gives ≈ 30 %); the cassette height and v_f0 follow the pile.

Writes ``fibers.h5`` (the reference mid-lines) and ``specimen.json`` (box, volume fraction, the
generator's parameters and the measured statistics). The original specimen (up to this change:
``placement="push"``, tilt 0.03 rad, sine waviness 5 µm, seed 0) is ``--original``; the
lattice specimen matched to the statistics but with no contacts (``placement="rigid"``) is ``--rigid``.
``--phi-mean-deg 10 --out DIR`` makes the variant at the study's upper bound, for comparison.

Then (``--settle``, the default; ``--no-settle`` keeps the pile as
placed) the pile settles in the solver itself (:func:`settle_pile`), because the frictionless
rest of the placement is not an equilibrium with point contacts and μ = 0.2: meshed as the
paper-40 scene, lower plate and walls fixed, no upper plate, gravity, contact, Coulomb friction
μ = 0.2, damping α = ``--settle-alpha`` (300 1/s), the axial lock ``--settle-lock`` (all nodes,
``scene.constraints``, as the paper-40 scene), for ``--settle-time`` (150 ms, until the kinetic
energy has died out); the settled node positions become the mid-lines (rest shape) and the upper
plate is put on the settled pile's top (+1 µm). The solver runs on one thread: deterministic
(about 6.5 min on one core).

``--wavy`` makes the variant of data-samples/paper-40-wavy/ instead (the study's Table 4 curvature
read as 0.24 1/mm): the same deposit with a smooth 1.8–2.5 mm waviness of that projected
curvature (``cassette_specimen(wave_curvature_per_m=...)``), settled with the work-around for the
axial-lock instability of curved fibers described at ``WAVY_SETTLE_MASS_SCALING``. The default
output (data-samples/paper-40/) is unchanged.
"""

import argparse
import json
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_fibers
from fiberpipe.model.specimen import cassette_specimen
from fiberpipe.model.specimen_stats import STUDY_CURVATURE_XZ_PER_M, STUDY_CURVATURE_YZ_PER_M, specimen_statistics

OUT = Path(__file__).resolve().parent / "paper-40"
PHI_MEAN_DEG = 6.0  # the study's Φ_average (section 3.2)
CURVATURE_PER_M = float(np.pi / 2 * (STUDY_CURVATURE_XZ_PER_M + STUDY_CURVATURE_YZ_PER_M) / 2)


REPO = Path(__file__).resolve().parents[1]
SETTLE_ALPHA_PER_S = 300.0
SETTLE_TIME_S = 0.15  # 150 ms: kinetic energy 3e-15 J (from 1e-8 J), fastest node 0.05 mm/s over the last 19 ms
SETTLE_LOCK = "all"  # settle with the axial lock the paper-40 scene uses
SETTLE_FRAMES = 9
DEPOSIT_CANDIDATES = 2  # trial drops per fiber, the lowest kept: 1 gives v_f0 ≈ 30 %, 2 ≈ 38 %, 4 ≈ 48 %
# --wavy (the study's Table 4 read as 1/mm): a smooth waviness of 0.24 1/mm projected curvature, 2 sine
# modes per component of wavelengths 1.8-2.5 mm (longer waves with that curvature give Φ ≈ 20° and
# v_f0 ≈ 19 %: data-samples/paper-40-wavy/README.md), the tilts lowered to keep Φ ≈ 6-7°, one trial
# drop per fiber (a wavy pile is denser: two give v_f0 ≈ 40 % before settling)
WAVY_OUT = Path(__file__).resolve().parent / "paper-40-wavy"
WAVE_CURVATURE_PER_M = 267.0  # the curve's own; the 0.3 mm mesh polyline measures ≈ 240 1/m (Table 4)
WAVE_LENGTHS_M = (1.8e-3, 2.5e-3)
WAVE_MODES = 2
WAVY_PHI_TILT_DEG = 3.0  # the tilts' share of Φ (the waves add the rest)
WAVY_CANDIDATES = 1
# The committed wavy pile was settled with a work-around, which these constants reproduce: an
# undamped wavy fiber with the axial lock gained energy in the solver (~1e14-fold in 13 ms). The cause
# was the beam kernel's moments, the energy gradient only to O(|θ|) on elements with a curved rest
# shape, fixed in 1d8499d (exact moments; tests/solver/test_beam_conservation.py); since then the
# plain settle (α = 300 1/s, physical mass and gravity, lock on) runs (30 ms checked). The
# work-around: mass scaled by 25 with α = 1e3 1/s and gravity × 84, so that the pile falls as fast
# as the shipped one did (the drag is α × the scaled mass: terminal velocity 84 g / (25 α) = 33 mm/s
# = g / 300 1/s); the rest state under friction, not the way to it, is kept (84 g presses the
# contacts ≈ 19× deeper: tenths of a µm).
WAVY_SETTLE_MASS_SCALING = 25.0
WAVY_SETTLE_ALPHA_PER_S = 1e3
WAVY_SETTLE_GRAVITY_SCALE = 84.0
WAVY_SETTLE_TIME_S = 0.15


def parameters(phi_mean_deg: float = PHI_MEAN_DEG, seed: int = 0, original: bool = False,
               rigid: bool = False, *, candidates: int = DEPOSIT_CANDIDATES, wave_curvature_per_m: float = 0.0,
               wave_lengths_m=WAVE_LENGTHS_M, wave_modes: int = WAVE_MODES) -> dict:
    if original:
        return {"seed": seed}
    params = {
        "seed": seed,
        "placement": "rigid" if rigid else "deposit",
        "tilt_rad": float(np.deg2rad(phi_mean_deg) / np.sqrt(np.pi)),
        "curvature_per_m": CURVATURE_PER_M,
    }
    if not rigid:
        params.update(candidates=candidates, top="pile")
        if wave_curvature_per_m > 0:
            params.update(wave_curvature_per_m=float(wave_curvature_per_m),
                          wave_lengths_m=[float(v) for v in wave_lengths_m], wave_modes=int(wave_modes))
    return params


def settle_pile(fibers, info, *, alpha_per_s=SETTLE_ALPHA_PER_S, time_s=SETTLE_TIME_S, mu=0.2, lock=None,
                frames=SETTLE_FRAMES, gap_m=1e-6, mass_scaling=None,
                gravity_scale=None):
    """Settle ``fibers`` (a deposited pile) in the solver under gravity with friction; returns the
    settled Polylines and ``info`` updated to the settled pile (height = its top + ``gap_m``, v_f0,
    contacts, the settling figures).

    The scene is configs/paper-40.yaml's (material, radius, contact law, mesh) settled by
    :func:`fiberpipe.model.specimen_settle.settle_pile` (what ``fiberpipe specimen`` runs): the
    lower plate fixed at y = 0, no upper plate, μ = ``mu``, α = ``alpha_per_s`` and, with
    ``lock`` = "all" | "ends", the axial lock.
    """
    from fiberpipe.config import load_raw
    from fiberpipe.model import specimen_settle
    from fiberpipe.model.specimen import _box_info

    raw = load_raw(REPO / "configs" / "paper-40.yaml")
    settled, fig = specimen_settle.settle_pile(
        fibers, raw, width_m=float(info["width_m"]), alpha_per_s=alpha_per_s, time_s=time_s, mu=mu, lock=lock,
        frames=frames, mass_scaling=mass_scaling, gravity_scale=gravity_scale, where="settle_pile")
    x = settled.points_m
    off = settled.offsets
    r = float(settled.radius_m[0])
    top = float(np.max(x[:, 1] + r))
    height = top + gap_m
    width, length = float(info["width_m"]), float(info["length_m"])
    out = {k: v for k, v in info.items() if k != "deposit"}
    out.update(_box_info(width, height, length, float(len(off) - 1) * np.pi * r**2 * length))
    out["deposit"] = {k: v for k, v in info["deposit"].items() if k != "supports"}
    wall = fig.pop("wall_time_s")
    out["settle"] = {
        **fig,
        "pile_top_before_m": float(info["deposit"]["pile_top_m"]), "pile_top_m": top,
        "top_clearance_m": gap_m,
        "fiber_contacts": fiber_contacts(x, off, r),
        "lowest_surface_m": float(np.min(x[:, 1] - r)),
        "fibers_on_lower_plate": int(sum(np.min(x[off[i]:off[i + 1], 1]) - r <= 1e-7 for i in range(len(off) - 1))),
    }
    out["settle_wall_time_s"] = wall  # popped by main (specimen.json stays reproducible)
    return settled, out


def fiber_contacts(x, off, r, tol_m=1e-7) -> int:
    """Fiber pairs whose centre lines (node-to-node segments) come within 2r + ``tol_m``."""
    from fiberpipe.model.specimen_settle import fiber_contacts as contacts

    return contacts(x, off, r, tol_m)


# the options whose default depends on the variant: (shipped paper-40, --wavy)
VARIANT_DEFAULTS = {
    "out": (OUT, WAVY_OUT),
    "phi_mean_deg": (PHI_MEAN_DEG, WAVY_PHI_TILT_DEG),
    "wave_curvature": (0.0, WAVE_CURVATURE_PER_M),
    "candidates": (DEPOSIT_CANDIDATES, WAVY_CANDIDATES),
    "settle_alpha": (SETTLE_ALPHA_PER_S, WAVY_SETTLE_ALPHA_PER_S),
    "settle_time": (SETTLE_TIME_S, WAVY_SETTLE_TIME_S),
    "settle_mass_scaling": (None, WAVY_SETTLE_MASS_SCALING),
    "settle_gravity_scale": (None, WAVY_SETTLE_GRAVITY_SCALE),
}


def options(argv=None) -> argparse.Namespace:
    """The command line parsed, with the variant-dependent defaults resolved (VARIANT_DEFAULTS)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])

    def dflt(key: str) -> str:
        a, b = VARIANT_DEFAULTS[key]
        return f"default {a}, with --wavy {b}"

    ap.add_argument("--out", type=Path, default=None, help=dflt("out"))
    ap.add_argument("--phi-mean-deg", type=float, default=None, help=dflt("phi_mean_deg"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--original", action="store_true", help="the specimen before the statistics were matched")
    ap.add_argument("--rigid", action="store_true",
                    help="the lattice specimen matched to the statistics (placement='rigid': no contacts at U = 0)")
    ap.add_argument("--settle", action=argparse.BooleanOptionalAction, default=True,
                    help="settle the deposited pile in the solver under gravity with friction (settle_pile; the "
                         "default); --no-settle: the deposited pile as placed")
    ap.add_argument("--settle-alpha", type=float, default=None, help="damping alpha while settling, 1/s; " + dflt("settle_alpha"))
    ap.add_argument("--settle-time", type=float, default=None, help="settling time, s; " + dflt("settle_time"))
    ap.add_argument("--settle-lock", choices=["all", "ends", "none"], default=SETTLE_LOCK,
                    help="lock the fibers' z translation while settling (scene.constraints.lock_axial)")
    ap.add_argument("--wavy", action="store_true",
                    help="the wavy variant (Table 4 read as 1/mm): changes the defaults of the options that say so")
    ap.add_argument("--wave-curvature", type=float, default=None,
                    help="deposit: smooth waviness of this projected curvature, 1/m (0: none); " + dflt("wave_curvature"))
    ap.add_argument("--wave-lengths-mm", type=float, nargs=2, default=[v * 1e3 for v in WAVE_LENGTHS_M])
    ap.add_argument("--wave-modes", type=int, default=WAVE_MODES)
    ap.add_argument("--candidates", type=int, default=None, help="deposit: trial drops per fiber; " + dflt("candidates"))
    ap.add_argument("--settle-mass-scaling", type=float, default=None,
                    help="solver.mass_scaling while settling; " + dflt("settle_mass_scaling"))
    ap.add_argument("--settle-gravity-scale", type=float, default=None,
                    help="gravity × this while settling; " + dflt("settle_gravity_scale"))
    args = ap.parse_args(argv)
    # one rule for every variant-dependent option: what is given wins, else the variant's default
    for key, (plain, wavy) in VARIANT_DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, wavy if args.wavy else plain)
    return args


SPECIMEN_CONFIG = REPO / "configs" / "specimens" / "paper-40.yaml"


def main(argv=None):
    args = options(argv)
    if _is_shipped_variant(args):
        # data-samples/paper-40 is one call of `fiberpipe specimen` (configs/specimens/paper-40.yaml)
        from fiberpipe.model.virtual_specimen import run_specimen_command

        run_specimen_command(str(SPECIMEN_CONFIG), args.out, seed=args.seed)
        return
    params = parameters(args.phi_mean_deg, args.seed, args.original, args.rigid,
                        candidates=args.candidates, wave_curvature_per_m=args.wave_curvature,
                        wave_lengths_m=[v * 1e-3 for v in args.wave_lengths_mm], wave_modes=args.wave_modes)
    fibers, info = cassette_specimen(**params)
    if args.settle and params.get("placement") == "deposit":
        fibers, info = settle_pile(fibers, info, alpha_per_s=args.settle_alpha, time_s=args.settle_time,
                                   lock=None if args.settle_lock == "none" else args.settle_lock,
                                   mass_scaling=args.settle_mass_scaling, gravity_scale=args.settle_gravity_scale)
        params["settle"] = {k: info["settle"][k] for k in ("alpha_per_s", "time_s", "mu", "lock_axial", "mass_scaling",
                                                                 "gravity_scale")
                            if k in info["settle"]}
        wall = info.pop("settle_wall_time_s")
    stats = specimen_statistics(fibers, box_min_m=info["box_min_m"], box_max_m=info["box_max_m"])
    info["generator"] = {"function": "fiberpipe.model.specimen.cassette_specimen", **params}
    if not args.original:
        info["generator"]["target_phi_mean_deg"] = args.phi_mean_deg
        if args.wave_curvature:  # the tilts' share; the waves add the rest (the study's 6°)
            info["generator"]["target_phi_mean_deg"] = PHI_MEAN_DEG
            info["generator"]["tilt_phi_mean_deg"] = args.phi_mean_deg
    info["statistics"] = stats
    args.out.mkdir(parents=True, exist_ok=True)
    write_fibers(args.out / "fibers.h5", fibers)
    (args.out / "specimen.json").write_text(json.dumps(info, indent=2) + "\n")
    print(f"wrote {args.out}/fibers.h5 ({fibers.n_fibers} fibers), height {info['height_m'] * 1e3:.4f} mm, "
          f"v_f0 {info['volume_fraction']:.4f}")
    if "settle" in info:
        d = info["settle"]
        print(f"  settled {d['time_s'] * 1e3:.3g} ms at alpha {d['alpha_per_s']:.4g} 1/s (lock {d['lock_axial']}): "
              f"moved up to {d['max_displacement_m'] * 1e6:.1f} um (median fiber {d['median_fiber_max_displacement_m'] * 1e6:.1f}), "
              f"last-interval max speed {d['max_speed_last_interval_m_s'] * 1e3:.3g} mm/s, KE end {d['kinetic_energy_end_J']:.3g} J "
              f"(max {d['kinetic_energy_max_J']:.3g}); pile top {d['pile_top_m'] * 1e3:.4f} mm "
              f"(was {d['pile_top_before_m'] * 1e3:.4f}); {d['fiber_contacts']} fiber-fiber contacts, "
              f"{d['fibers_on_lower_plate']} fibers on the lower plate; {wall:.0f} s wall")
    elif "deposit" in info:
        d = info["deposit"]
        print(f"  pile top {d['pile_top_m'] * 1e3:.4f} mm; {d['contacts']} fiber-fiber contacts, "
              f"{d['fibers_on_lower_plate']} fibers on the lower plate")
    print(
        f"  neighbour angle mean {stats['phi_mean_deg']:.2f} deg (median {stats['phi_median_deg']:.2f}, "
        f"10-90 % {stats['phi_p10_deg']:.2f}-{stats['phi_p90_deg']:.2f}), {stats['neighbour_pairs']} pairs; "
        f"curvature xz {stats['curvature_xz_per_m']:.3f} yz {stats['curvature_yz_per_m']:.3f} 1/m; "
        f"min gap {stats['min_gap_m'] * 1e6:.2f} um; v_f {stats['volume_fraction']:.4f}"
    )


def _is_shipped_variant(args) -> bool:
    """The shipped specimen's options (any seed or --out): configs/specimens/paper-40.yaml says the same."""
    plain = options([])
    same = ("phi_mean_deg", "original", "rigid", "settle", "settle_alpha", "settle_time", "settle_lock", "wavy",
            "wave_curvature", "candidates", "settle_mass_scaling", "settle_gravity_scale")
    return all(getattr(args, k) == getattr(plain, k) for k in same)


if __name__ == "__main__":
    main()
