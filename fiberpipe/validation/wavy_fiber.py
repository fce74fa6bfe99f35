"""Validation case 1: one wavy fiber between frictionless plates, against the continuous beam.

# Reference (derived here; docs/validation.md): a long fiber whose mid-line is a sinusoid of
# wavelength λ, pressed by rigid frictionless plates at its crests (upper plate) and troughs (lower
# plate), carries alternating point loads P. By symmetry the slope is zero at every crest and
# trough, and by antisymmetry the moment is zero midway; no horizontal force acts (frictionless
# plates, free ends), so the moment depends on the horizontal distance only and the shear between
# a crest and the next trough is P/2. Each half-wave is then a beam of length λ/2 guided at both
# ends (slopes zero) with relative transverse displacement δ under the shear V = P/2:
#     δ = V (λ/2)³ / (12 EI) + V (λ/2) / (κ G A) = P λ³/(192 EI) · (1 + 48 EI / (κ G A λ²)),
# the second term Timoshenko's shear (κ Cowper's 6(1+ν)/(7+6ν), as fiberpipe's beams use). With
# one crest per wave on each plate the plate stiffness is 192 EI/λ³ per wave (Euler–Bernoulli), less
# the shear term (2.4 % at λ = 9.6 mm, r = 0.25 mm). Conditions: small displacement (δ ≪ a), shallow
# waves (the arc-length correction to ∫M²ds/EI is below (ak)²/2 = 0.2 % at a = 0.1 mm, k = 2π/λ),
# frictionless plates, no gravity, and the fiber's centre line (the plates' penetration is the
# contact's compliance, reported apart).
#
# A finite fiber with free ends is softer: its end crests carry less (0.18 P at the last crest).
# The same beam theory solves it exactly (point loads on a straight free–free beam, the contact
# forces unknown, every crest on the upper plate and every trough on the lower one displaced
# alike: :func:`finite_fiber_stiffness`); it gives (N − 0.866) waves' worth of 192 EI/λ³ for N ≥ 4,
# so adding waves adds exactly 192 EI/λ³ per wave. The case checks (1) each fiber's stiffness
# against its finite-beam reference and (2) the stiffness added per wave between a fiber of N₁ and
# one of N₂ waves against the periodic 192 EI/λ³ (with the shear term), both within 3 %.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..config import load_config
from .rows import ValidationRow

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "validation" / "wavy-fiber.yaml"
SOURCE = ("continuous beam under alternating crest loads (derived in docs/validation.md: each half-wave a guided "
          "beam, δ = P λ³/(192 EI) + P λ/(4 κ G A))")
TOLERANCE = 0.03


class WavyFiberGeometry(NamedTuple):
    """The fiber's shape: y = amplitude_m · cos(2π x / wavelength_m) over ``waves`` whole waves."""

    wavelength_m: float = 9.6e-3
    amplitude_m: float = 0.1e-3
    waves: int = 8


class BeamSection(NamedTuple):
    """EI (N m²) and κGA (N) of the fiber's section."""

    bending_stiffness_n_m2: float
    shear_stiffness_n: float


def section_of(cfg) -> BeamSection:
    """EI and κGA of ``cfg``'s material and fiber radius (Cowper's κ for a solid circle)."""
    from ..solver.build import material_from_config

    material = material_from_config(cfg)
    radius_m = float(cfg.fiber.radius)
    nu = material.nu
    kappa = 6 * (1 + nu) / (7 + 6 * nu)
    return BeamSection(material.youngs_modulus_pa * math.pi * radius_m**4 / 4,
                       kappa * material.G * math.pi * radius_m**2)


def periodic_stiffness_per_wave(wavelength_m: float, section: BeamSection, shear: bool = True) -> float:
    """Plate stiffness per wave of the infinite periodic fiber: 192 EI/λ³ / (1 + 48 EI/(κGA λ²))."""
    ei, kga = section
    k = 192 * ei / wavelength_m**3
    return k / (1 + 48 * ei / (kga * wavelength_m**2)) if shear else k


def finite_fiber_stiffness(waves: int, wavelength_m: float, section: BeamSection, shear: bool = True) -> float:
    """Plate stiffness (N/m) of a free-ended fiber of ``waves`` whole waves, crests at both ends.

    Straight-beam theory with point loads at the 2N + 1 crests and troughs x_i = iλ/2: the beam's
    deflection w(x) = a + b x + Σ_j s_j F_j G(x, x_j), G the clamped–free influence function
    (bending x²(3ξ − x)/6EI and shear x/κGA for x ≤ ξ), s_j = −1 at crests (upper plate) and +1 at
    troughs; compatibility w(x_i) = 0 at crests and U at troughs, with force and moment equilibrium.
    Returns the total upper-plate force over U. Raises ValueError if a contact would pull."""
    ei, kga = section
    n = 2 * waves + 1
    xs = np.arange(n) * wavelength_m / 2
    sign = np.where(np.arange(n) % 2 == 0, -1.0, 1.0)
    lo = np.minimum.outer(xs, xs)
    hi = np.maximum.outer(xs, xs)
    influence = lo**2 * (3 * hi - lo) / (6 * ei) + (lo / kga if shear else 0.0)
    system = np.zeros((n + 2, n + 2))
    system[:n, :n] = influence * sign[None, :]
    system[:n, n] = 1.0
    system[:n, n + 1] = xs
    system[n, :n] = sign
    system[n + 1, :n] = sign * xs
    rhs = np.zeros(n + 2)
    rhs[1:n:2] = 1.0  # the troughs displaced by U = 1
    forces = np.linalg.solve(system, rhs)[:n]
    if np.any(forces <= 0):
        raise ValueError("a contact of the finite wavy fiber would pull: the beam solution does not apply")
    return float(forces[0::2].sum())


def wavy_nodes(geometry: WavyFiberGeometry, element_length_m: float) -> np.ndarray:
    """Node positions of the fiber, with a node on every crest and trough (elements per half-wave
    rounded up to fit ``element_length_m``)."""
    per_half = max(2, math.ceil(geometry.wavelength_m / 2 / element_length_m))
    n_el = 2 * geometry.waves * per_half
    x = np.linspace(0.0, geometry.waves * geometry.wavelength_m, n_el + 1)
    nodes = np.zeros((n_el + 1, 3))
    nodes[:, 0] = x
    nodes[:, 1] = geometry.amplitude_m * np.cos(2 * math.pi * x / geometry.wavelength_m)
    return nodes


class WavyRun(NamedTuple):
    """One compression of the wavy fiber: plate force (N), the fiber's crest–trough approach (m),
    the plate travel (m), steps."""

    force_n: float
    approach_m: float
    travel_m: float
    steps: int


def run_wavy_fiber(geometry: WavyFiberGeometry, cfg=None, *, element_length_m: float | None = None,
                   speed_factor: float = 1.0) -> WavyRun:
    """Press the wavy fiber of ``geometry`` between the config's plates and return the static state.

    The lower plate travels the config's displacement at its velocity × ``speed_factor`` (smooth
    ramp), then the plates hold for as long again so the damped fiber comes to rest; the force is
    the mean of the two plates' over the last tenth of the hold."""
    from ..solver import Damping, Plates, build_model, simulate
    from ..solver.build import material_from_config

    cfg = cfg or load_config(CONFIG)
    h = element_length_m or float(cfg.mesh.element_length)
    nodes = wavy_nodes(geometry, h)
    model = build_model(nodes, [0, len(nodes)], float(cfg.fiber.radius), material_from_config(cfg))
    sc = cfg.scene
    travel = float(sc.loading.displacement)
    speed = float(sc.loading.velocity) * speed_factor
    plates = Plates(axis="y", lower="moving", upper="fixed", displacement_m=travel, velocity_m_s=speed,
                    ramp="smooth", penalty_factor=float(sc.plates.penalty_factor),
                    onset_fraction=float(sc.plates.onset_fraction))
    load_time = travel / speed / (1 - 0.1)
    from ..solver import SimulationSettings

    settings = SimulationSettings(dt_safety=float(cfg.solver.dt_safety), end_time_s=2 * load_time, output_frames=2)
    result = simulate(model, [plates, Damping(float(sc.damping.alpha))], settings)
    rows = result.history["time"] > 1.9 * load_time
    force = float(np.mean(result.history["plate_force"][rows]))
    per_half = (len(nodes) - 1) // (2 * geometry.waves)
    crests = np.arange(0, len(nodes), 2 * per_half)
    troughs = np.arange(per_half, len(nodes), 2 * per_half)
    y0, y1 = nodes[:, 1], result.frames_positions[-1][:, 1]
    gap0 = y0[crests].mean() - y0[troughs].mean()
    gap1 = y1[crests].mean() - y1[troughs].mean()
    return WavyRun(force, float(gap0 - gap1), travel, int(result.steps))


def fiber_stiffness(run: WavyRun) -> float:
    """The fiber's own plate stiffness: force over its crest–trough approach (N/m)."""
    return run.force_n / run.approach_m


def validate(quick: bool = False) -> list[ValidationRow]:
    """Case 1's rows: the 4- and 8-wave fibers against their finite-beam references, and the
    stiffness per added wave against 192 EI/λ³ (shear term included). The full variant adds the
    convergence figures (element length halved and doubled, loading speed halved) in the rows' data."""
    cfg = load_config(CONFIG)
    section = section_of(cfg)
    short, long = WavyFiberGeometry(waves=4), WavyFiberGeometry(waves=8)
    runs = {g.waves: run_wavy_fiber(g, cfg) for g in (short, long)}
    convergence = {}
    if not quick:
        h = float(cfg.mesh.element_length)
        for label, kwargs in (("element length × 2", {"element_length_m": 2 * h}),
                              ("element length / 2", {"element_length_m": h / 2}),
                              ("loading speed / 2", {"speed_factor": 0.5})):
            convergence[label] = {g.waves: fiber_stiffness(run_wavy_fiber(g, cfg, **kwargs)) for g in (short, long)}
    rows = []
    for g in (short, long):
        run = runs[g.waves]
        reference = finite_fiber_stiffness(g.waves, g.wavelength_m, section)
        rows.append(ValidationRow(
            "1 wavy fiber between plates", f"plate stiffness of a {g.waves}-wave fiber (free ends)", reference,
            [fiber_stiffness(run)], TOLERANCE, SOURCE, unit="N/m",
            note=(f"λ = {g.wavelength_m * 1e3:.3g} mm, a = {g.amplitude_m * 1e3:.3g} mm; the plates' penetration adds "
                  f"{(run.travel_m - run.approach_m) / run.travel_m:.1%} of the travel (K with it "
                  f"{run.force_n / run.travel_m:.4g} N/m)"),
            data={"force_n": run.force_n, "approach_m": run.approach_m, "travel_m": run.travel_m, "steps": run.steps,
                  "convergence": {k: v[g.waves] for k, v in convergence.items()}}))
    for row in rows:  # the full variant's convergence, relative to the case's own value
        row.note += "".join(f"; {label}: {value / row.measured - 1:+.2%}" for label, value in row.data["convergence"].items())
    per_wave = (fiber_stiffness(runs[8]) - fiber_stiffness(runs[4])) / 4
    rows.append(ValidationRow(
        "1 wavy fiber between plates", "stiffness per added wave (8 against 4 waves)",
        periodic_stiffness_per_wave(long.wavelength_m, section), [per_wave], TOLERANCE,
        "192 EI/λ³ / (1 + 48 EI/(κGA λ²)) (periodic continuous beam, derived in docs/validation.md)", unit="N/m",
        note=f"Euler–Bernoulli 192 EI/λ³ = {periodic_stiffness_per_wave(long.wavelength_m, section, shear=False):.5g} N/m",
        data={"convergence": {k: (v[8] - v[4]) / 4 for k, v in convergence.items()}}))
    rows[-1].note += "".join(f"; {label}: {value / per_wave - 1:+.2%}" for label, value in rows[-1].data["convergence"].items())
    return rows
