"""Abaqus/Explicit input decks of a fiberpipe scene (SI units: m, N, Pa, kg/m³, s).

:func:`abaqus_deck` writes the whole scene of a config (docs/abaqus.md):

* a part ``FIBERS`` with the nodes, one ``B31`` element set per fiber, ``*BEAM SECTION,
  SECTION=CIRC`` with each fiber's radius (n1 perpendicular to the fiber's chord), one node set per
  fiber; an instance ``FIBERS-1`` in the assembly;
* ``*MATERIAL`` with ``*ELASTIC``, ``*DENSITY`` and ``*DAMPING, ALPHA, BETA`` (Abaqus' material
  damping: the same mass- and stiffness-proportional damping as ``scene.damping``);
* plates and walls as analytical rigid surfaces (``*SURFACE, TYPE=CYLINDER``: a straight profile
  swept along a generator) on ``*RIGID BODY`` reference points; the moving plate's reference
  point follows ``*BOUNDARY, TYPE=VELOCITY`` with ``*AMPLITUDE, DEFINITION=SMOOTH STEP``;
* gravity as ``*DLOAD, GRAV``; clamps, point and line loads, drives and the axial lock as
  ``*BOUNDARY``, ``*CLOAD`` and ``*DLOAD, PX/PY/PZ``;
* general contact with the chosen law as a tabular pressure–overclosure
  (:func:`pressure_overclosure`) and ``*FRICTION``;
* one ``*DYNAMIC, EXPLICIT`` step of the solver's time period, with the energies ALLKE, ALLSE,
  ALLPW, ALLFD, ALLVD, ALLWK, ALLIE, ETOTAL and each plate's reference-point reaction RF and
  displacement U as history output.

:func:`write_abaqus_inp` writes the mesh alone (nodes, elements, sections, material). Both read
back with ``meshio.read`` (nodes and line cells).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fiberpipe.artifacts import write_text_atomic
from fiberpipe.errors import ConfigError

AXES = "xyz"
#: overclosure range of the fitted Hertz tables: 3× the largest fiber–fiber penetration of the
#: paper-40 runs (0.68 µm); Abaqus continues the last segment's slope beyond it
HERTZ_TABLE_MAX_OVERCLOSURE_M = 2e-6
HERTZ_TABLE_ROWS = 40
#: crossing angle of the single law that stands for ``hertz_oriented`` (Abaqus takes one law for
#: the whole model): the study's oblique model
ORIENTED_STANDIN_ANGLE_DEG = 6.0


def _n1_direction(tangent: np.ndarray) -> np.ndarray:
    t = tangent / (np.linalg.norm(tangent) or 1.0)
    other = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    n1 = np.cross(other, t)
    return n1 / np.linalg.norm(n1)


def _f(x: float) -> str:
    return f"{float(x):.9e}"


def _part_lines(mesh, ref_points=()) -> list[str]:
    """Nodes, one element set per fiber, node sets, sections: the body of the part.

    ``ref_points``: (name, xyz) of rigid-body reference nodes, labelled after the fiber nodes in
    the same ``*NODE`` block (one block keeps the file readable by meshio, which keeps the last
    ``*NODE`` block only); each gets a node set of its name."""
    out = ["*NODE"]
    out += [f"{i}, {_f(x)}, {_f(y)}, {_f(z)}" for i, (x, y, z) in enumerate(mesh.nodes_m, start=1)]
    out += [f"{mesh.n_nodes + 1 + k}, {_f(x)}, {_f(y)}, {_f(z)}" for k, (_, (x, y, z)) in enumerate(ref_points)]
    elements = mesh.elements() + 1
    eoff = mesh.elem_offsets
    for f in range(mesh.n_fibers):
        out.append(f"*ELEMENT, TYPE=B31, ELSET=FIBER{f}")
        out += [f"{e + 1}, {elements[e, 0]}, {elements[e, 1]}" for e in range(eoff[f], eoff[f + 1])]
    for f in range(mesh.n_fibers):
        a, b = mesh.node_offsets[f], mesh.node_offsets[f + 1]
        out += [f"*NSET, NSET=FIBER{f}_NODES, GENERATE", f"{a + 1}, {b}, 1"]
    names = [f"FIBER{f}" for f in range(mesh.n_fibers)]
    out.append("*ELSET, ELSET=FIBERS")
    out += [", ".join(names[k : k + 8]) for k in range(0, len(names), 8)]
    out += ["*NSET, NSET=ALL_NODES, GENERATE", f"1, {mesh.n_nodes}, 1"]
    for k, (name, _) in enumerate(ref_points):
        out += [f"*NSET, NSET={name}", str(mesh.n_nodes + 1 + k)]
    for f in range(mesh.n_fibers):
        nodes = mesh.fiber_nodes(f)
        n1 = _n1_direction(nodes[-1] - nodes[0])
        out += [f"*BEAM SECTION, ELSET=FIBER{f}, MATERIAL=FIBER, SECTION=CIRC", _f(mesh.radius_m[f]),
                f"{n1[0]:.6f}, {n1[1]:.6f}, {n1[2]:.6f}"]
    return out


def _material_lines(E: float, nu: float, rho: float, alpha: float = 0.0, beta: float = 0.0,
                    damping: bool = False) -> list[str]:
    out = ["*MATERIAL, NAME=FIBER", "*ELASTIC", f"{_f(E)}, {nu:.6f}", "*DENSITY", _f(rho)]
    if damping:
        out += [f"*DAMPING, ALPHA={_f(alpha)}, BETA={_f(beta)}"]
    return out


def write_abaqus_inp(path, mesh, *, youngs_modulus_pa: float, poisson_ratio: float, density_kg_m3: float,
                     heading: str = "fiberpipe beam model") -> Path:
    """Write ``mesh`` alone as an Abaqus input file in SI units (nodes, B31 elements, one node and
    element set per fiber, circular sections, an elastic material with density)."""
    out = ["*HEADING", f"{heading} (SI units: m, N, Pa, kg/m^3)", *_part_lines(mesh),
           *_material_lines(youngs_modulus_pa, poisson_ratio, density_kg_m3), ""]
    write_text_atomic(path, "\n".join(out))
    return Path(path)


# -- contact law as a pressure–overclosure table -------------------------------------------------

@dataclass
class ContactTable:
    """Rows (pressure Pa, overclosure m) of ``*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=TABULAR``."""

    rows: list[tuple[float, float]]
    law: str  # what the table represents, one line
    force_to_pressure: str  # how a force (per length) became a pressure
    fit_error_full_scale: float  # largest |table − law| over the range / law at the range's end
    fit_error_relative: float  # largest |table − law| / law above 5 % of the range
    range_m: float


def _fit_error(table_d, table_p, exact, range_m) -> tuple[float, float]:
    d = np.linspace(0.0, range_m, 4001)[1:]
    approx = np.interp(d, table_d, table_p)
    ref = np.array([exact(x) for x in d])
    full = float(np.max(np.abs(approx - ref)) / ref[-1])
    m = d >= 0.05 * range_m
    rel = float(np.max(np.abs(approx[m] - ref[m]) / ref[m]))
    return full, rel


def _grid(range_m: float, n: int) -> np.ndarray:
    # denser near zero, where δ^1.5 and the line law bend most
    return range_m * (np.arange(n + 1) / n) ** 2


def pressure_overclosure(cfg, mesh) -> ContactTable:
    """The scene's normal contact law as a tabular pressure–overclosure for Abaqus' general contact.

    Overclosure is fiberpipe's penetration δ = r_i + r_j − centre-line distance. A law per unit
    length (N/m) becomes a pressure over the fiber diameter, p / 2R; a law per contact (N) over the
    diameter times the element length, F / (2R ℓ_e). The study's Eq. 1 presets are piecewise linear
    in δ, so their table is exact in δ (rows at δ = i d, i = 0 … n); the Hertz laws are sampled on
    a grid of :data:`HERTZ_TABLE_ROWS` rows up to :data:`HERTZ_TABLE_MAX_OVERCLOSURE_M` and the fit
    error is returned. ``hertz_oriented`` has no Abaqus equivalent (one law per model): it is
    exported as the crossed law at :data:`ORIENTED_STANDIN_ANGLE_DEG`.
    """
    from fiberpipe.solver.laws import SCALED_PRESETS, _e_star, hertz_crossed_exact

    c = cfg.scene.contact
    r = float(np.mean(mesh.radius_m))
    le = float(np.mean(mesh.element_lengths_m()))
    m = cfg.material
    e_star = _e_star(float(m.youngs_modulus), float(m.poisson_ratio_value))
    per_length = f"p / 2R (2R = {_f(2 * r)} m)"
    per_contact = f"F / (2R l_e) (2R = {_f(2 * r)} m, l_e = {_f(le)} m)"

    if c.law == "linear":
        k = float(c.stiffness)  # N/m² per unit length: p = k δ
        d1 = r
        return ContactTable([(0.0, 0.0), (k * d1 / (2 * r), d1)], f"linear, p = k delta, k = {_f(k)} N/m^2",
                            per_length, 0.0, 0.0, d1)
    if c.law == "scaled_stiffness":
        if c.preset is not None:
            d, S, S0, K, per, _, _ = SCALED_PRESETS[c.preset]
            name = f"scaled stiffness (Eq. 1), preset {c.preset}"
        else:
            d, S, S0, K, per = float(c.d), float(c.s), float(c.s0), float(c.k_def), "contact"
            name = "scaled stiffness (Eq. 1)"
        n = 1000  # the law's segments (ScaledStiffnessLaw's default); its last slope continues
        i = np.arange(n + 1)
        geo = i.astype(float) if abs(S - 1.0) < 1e-15 else np.expm1(i * math.log(S)) / (S - 1.0)
        force = S0 * K * d * geo
        area = 2 * r if per == "length" else 2 * r * le
        rows = [(float(f / area), float(x)) for f, x in zip(force, i * d)]
        return ContactTable(rows, f"{name}: K_i = S0 K_def S^(i-1) on [(i-1)d, id], d = {_f(d)} m, S = {S}, "
                            f"S0 = {S0}, K_def = {_f(K)} N/m{'^2' if per == 'length' else ''}",
                            per_length if per == "length" else per_contact, 0.0, 0.0, float(n * d))

    rng = HERTZ_TABLE_MAX_OVERCLOSURE_M
    d = _grid(rng, HERTZ_TABLE_ROWS)
    if c.law == "hertz_parallel":
        line = _johnson_line_load(e_star, r)
        p = np.array([line(x) for x in d]) / (2 * r)
        full, rel = _fit_error(d, p, lambda x: line(x) / (2 * r), rng)
        return ContactTable([(float(a), float(b)) for a, b in zip(p, d)],
                            "Johnson line contact of parallel cylinders (Lambert W inversion), fitted",
                            per_length, full, rel, rng)
    phi = float(c.angle) * 180 / math.pi if c.law == "hertz_crossed" else ORIENTED_STANDIN_ANGLE_DEG
    k_hat = hertz_crossed_exact(phi * math.pi / 180)[0]
    K = k_hat * e_star * math.sqrt(r)
    area = 2 * r * le
    p = K * d**1.5 / area
    full, rel = _fit_error(d, p, lambda x: K * x**1.5 / area, rng)
    what = (f"crossed Hertz F = K delta^1.5 at phi = {phi:g} deg, K = {_f(K)} N/m^1.5, fitted"
            + (" (hertz_oriented has one law per model in Abaqus: the study's oblique angle)"
               if c.law == "hertz_oriented" else ""))
    return ContactTable([(float(a), float(b)) for a, b in zip(p, d)], what, per_contact, full, rel, rng)


def _johnson_line_load(e_star: float, r: float):
    """P(δ) [N/m] of two parallel cylinders of radius r (Johnson 1985): δ(P) inverted by bisection."""
    from scipy.optimize import brentq

    def delta(P):
        b = math.sqrt(4 * P * (r / 2) / (math.pi * e_star))
        return P / (math.pi * e_star) * (2 * math.log(4 * r / b) - 1)

    def load(x):
        if x <= 0:
            return 0.0
        hi = math.pi * e_star * x  # δ(P) ≥ P/πE* while b < 4R e^(-1/2): the root lies below
        while delta(hi) < x:
            hi *= 2.0
        return brentq(lambda P: delta(P) - x, hi * 1e-12, hi, xtol=1e-300, rtol=1e-14, maxiter=500)

    return load


# -- the scene -------------------------------------------------------------------------------------

def _step_time_s(cfg) -> float:
    """The solver's time period: ``solver.end_time``, else the longest prescribed motion."""
    scene, solver = cfg.scene, cfg.solver
    if solver.end_time is not None:
        return float(solver.end_time)
    t = 0.0
    if "plates" in scene.effects and "moving" in (scene.plates.lower, scene.plates.upper):
        loading = scene.loading
        T = float(loading.displacement) / float(loading.velocity)
        t = max(t, T / (1 - float(loading.ramp_fraction)) if loading.ramp == "smooth" else T)
        if loading.path is not None:  # a loading path: its moves and holds
            t = max(t, _path_plates(loading).loading_time_s)
    if "drives" in scene.effects:
        for d in scene.drives:
            t = max(t, float(np.linalg.norm(d.displacement)) / float(d.velocity) / (1 - 0.1))  # smooth, 10 % ramps
    if t <= 0:
        raise ConfigError("the scene has no moving plate or drive to set the step's time period: give "
                          "solver.end_time", where="solver.end_time")
    return t


def _path_plates(ld):
    """The solver's plates effect for a ``scene.loading.path`` (its travel table and times)."""
    from fiberpipe.solver.terms.planes import Plates

    return Plates(displacement_m=float(ld.displacement), velocity_m_s=float(ld.velocity), ramp=ld.ramp,
                  ramp_fraction=float(ld.ramp_fraction), path_m=[float(u) for u in ld.path], hold_s=float(ld.hold))


def _path_velocity_points(ld) -> list[tuple[float, float]]:
    """The plate-velocity amplitude (× ``loading.velocity``) of a loading path, on the solver's own
    entry times: per move ±1 with smooth-step rises and falls over its acceleration time (``smooth``),
    or ±1 from its start to its end (``linear``, switched over 1e-6 of the time); 0 in the holds."""
    u_end, dur, t_acc = _path_plates(ld).travel_table()
    pts, t0, u0 = [(0.0, 0.0)], 0.0, 0.0
    for u, T, ta in zip(u_end, dur, t_acc):
        t1, d = t0 + T, float(np.sign(u - u0))
        if d != 0.0 and pts[-1][0] < t0:  # after a hold: at rest until the move starts
            pts.append((t0, 0.0))
        if d != 0.0 and ld.ramp == "smooth":
            pts += [(t0 + ta, d), (t1 - ta, d), (t1, 0.0)]
        elif d != 0.0:
            eps = 1e-6 * T
            pts += [(t0 + eps, d), (t1 - eps, d), (t1, 0.0)]
        t0, u0 = t1, u
    return pts


def _pairs(points) -> list[str]:
    """(time, value) pairs of an ``*AMPLITUDE``, four to a data line (Abaqus' limit of 8 entries)."""
    flat = [f"{_f(t)}, {a:g}" for t, a in points]
    return [", ".join(flat[k : k + 4]) for k in range(0, len(flat), 4)]


def _node(mesh, fiber: int, at) -> int:
    """1-based label of node ``at`` (start | end | local index) of ``fiber``."""
    a, b = int(mesh.node_offsets[fiber]), int(mesh.node_offsets[fiber + 1])
    k = {"start": 0, "end": b - a - 1}.get(at, at)
    if not 0 <= int(k) < b - a:
        raise ConfigError(f"node {at} is not on fiber {fiber} ({b - a} nodes)", where="scene")
    return a + int(k) + 1


def _plane_surface(name: str, ax: int, pos: float, sign: float, centre: np.ndarray, half: float) -> list[str]:
    """A flat analytical rigid surface normal to axis ``ax`` at ``pos``, facing ``sign`` along it.

    Local system: origin a on the plane, x' = u (in the plane), generator z' = u × n, so that
    the profile START (−half, 0) → LINE (half, 0) runs along x' and its outward normal (x' turned
    90° about z') is y' = n."""
    n = np.zeros(3)
    n[ax] = sign
    u = np.zeros(3)
    u[(ax + 1) % 3] = 1.0
    g = np.cross(u, n)
    a = centre.copy()
    a[ax] = pos
    b, c = a + u, a + g
    xyz = lambda v: ", ".join(_f(t) for t in v)  # noqa: E731
    return [f"*SURFACE, TYPE=CYLINDER, NAME={name}", f"{xyz(a)}, {xyz(b)}", xyz(c),
            f"START, {_f(-half)}, 0.", f"LINE, {_f(half)}, 0."]


def _planes(cfg, mesh) -> list[dict]:
    """Plates and walls: name, axis, position, facing sign, moving travel, history column."""
    scene = cfg.scene
    out = []
    r_node = np.repeat(mesh.radius_m, np.diff(mesh.node_offsets))
    if "plates" in scene.effects:
        p = scene.plates
        ax = AXES.index(p.axis)
        c = mesh.nodes_m[:, ax]
        lo = float(np.min(c - r_node)) if p.lower_position is None else float(p.lower_position)
        hi = float(np.max(c + r_node)) if p.upper_position is None else float(p.upper_position)
        for kind, sign, pos in (("lower", 1.0, lo), ("upper", -1.0, hi)):
            state = getattr(p, kind)
            if state != "none":
                travel = float(scene.loading.displacement) if state == "moving" else 0.0
                out.append({"name": f"PLATE_{kind.upper()}", "ax": ax, "pos": pos, "sign": sign, "travel": travel})
    if "walls" in scene.effects:
        for axis in AXES:
            pair = getattr(scene.walls, axis)
            if pair is not None:
                ax = AXES.index(axis)
                for tag, sign, pos in (("LO", 1.0, float(pair[0])), ("HI", -1.0, float(pair[1]))):
                    out.append({"name": f"WALL_{axis.upper()}_{tag}", "ax": ax, "pos": pos, "sign": sign, "travel": 0.0})
    return out


def abaqus_deck(cfg, mesh) -> tuple[str, dict]:
    """The scene of ``cfg`` on ``mesh`` as an Abaqus/Explicit input deck, and its key figures."""
    scene = cfg.scene
    T = _step_time_s(cfg)
    figures: dict = {"time_period_s": T}
    lines = ["*HEADING",
             f"fiberpipe {cfg.name}: {mesh.n_fibers} fibers, {mesh.n_elements} B31 elements, "
             f"effects {', '.join(scene.effects) or 'none'} (SI units: m, N, Pa, kg/m^3, s)",
             "** written by fiberpipe (docs/abaqus.md says what matches fiberpipe exactly and what approximately)",
             "*PREPRINT, ECHO=NO, MODEL=NO, HISTORY=NO, CONTACT=NO",
             "**", "** PARTS", "**"]
    planes = _planes(cfg, mesh)
    assembly, held = _assembly_lines(scene, mesh, planes)
    lines += assembly
    lines += _amplitude_lines(scene, planes, T, figures)
    lines += _material_and_interaction_lines(cfg, mesh, planes, figures)
    lines += ["**", "** STEP", "**", "*STEP, NAME=LOADING, NLGEOM=YES",
              f"*DYNAMIC, EXPLICIT, SCALE FACTOR={float(cfg.solver.dt_safety):g}", f", {_f(T)}"]
    if float(cfg.solver.mass_scaling) != 1.0:
        lines += [f"*FIXED MASS SCALING, FACTOR={float(cfg.solver.mass_scaling):g}"]
    lines += _boundary_lines(scene, planes, held)
    lines += _load_lines(scene, mesh)
    lines += _contact_lines(scene, planes)
    lines += _output_lines(cfg, planes, T)
    figures["planes"] = [pl["name"] for pl in planes]
    return "\n".join(lines), figures


class _Held(NamedTuple):
    """The assembly's node sets the step holds: the constrained set (None: no constraint) and the
    clamped nodes."""

    lock: str | None
    clamp_nodes: list


def _assembly_lines(scene, mesh, planes: list[dict]) -> tuple[list[str], _Held]:
    """The part (fibers and the planes' reference points), the assembly with its rigid planes, and
    the node sets of the constraints and clamps."""
    effects = set(scene.effects)
    lo_box, hi_box = mesh.nodes_m.min(axis=0), mesh.nodes_m.max(axis=0)
    centre = 0.5 * (lo_box + hi_box)
    half = float(np.max(hi_box - lo_box)) + 10 * float(np.max(mesh.radius_m))  # larger than the bundle
    refs = []
    for pl in planes:
        rp = centre.copy()
        rp[pl["ax"]] = pl["pos"]
        pl["rp"] = f"FIBERS-1.RP_{pl['name']}"
        refs.append((f"RP_{pl['name']}", rp))
    lines = ["*PART, NAME=FIBERS", *_part_lines(mesh, refs),
             "*SURFACE, TYPE=ELEMENT, NAME=FIBERS_SURF", "FIBERS,", "*END PART"]
    lines += ["**", "** ASSEMBLY", "**", "*ASSEMBLY, NAME=ASSEMBLY", "*INSTANCE, NAME=FIBERS-1, PART=FIBERS",
              "*END INSTANCE"]
    for pl in planes:
        lines += [*_plane_surface(pl["name"], pl["ax"], pl["pos"], pl["sign"], centre, half),
                  f"*RIGID BODY, REF NODE={pl['rp']}, ANALYTICAL SURFACE={pl['name']}"]
    lock = None
    if "constraints" in effects:
        lock = "FIBERS-1.ALL_NODES"
        if scene.constraints.lock_axial == "ends":
            ends = [str(int(mesh.node_offsets[f]) + 1) for f in range(mesh.n_fibers)]
            ends += [str(int(mesh.node_offsets[f + 1])) for f in range(mesh.n_fibers)]
            lines += ["*NSET, NSET=LOCK_ENDS, INSTANCE=FIBERS-1"] + [", ".join(ends[k:k + 16]) for k in range(0, len(ends), 16)]
            lock = "LOCK_ENDS"
    clamp_nodes = sorted({_node(mesh, c.fiber, c.at) for c in scene.clamps}) if "clamps" in effects else []
    if clamp_nodes:
        lines += ["*NSET, NSET=CLAMPS, INSTANCE=FIBERS-1", ", ".join(map(str, clamp_nodes))]
    lines.append("*END ASSEMBLY")
    return lines, _Held(lock, clamp_nodes)


def _drives(scene) -> list:
    return list(scene.drives) if "drives" in scene.effects else []


def _amplitude_lines(scene, planes: list[dict], T: float, figures: dict) -> list[str]:
    """The velocity amplitudes of the moving plate (its ramp or path) and of each drive."""
    lines = []
    if any(pl["travel"] > 0 for pl in planes):
        loading = scene.loading
        Tl = float(loading.displacement) / float(loading.velocity)
        if loading.ramp == "smooth":  # velocity: smooth rise over f T, plateau, smooth fall (the same travel)
            Tl /= 1 - float(loading.ramp_fraction)
            ta = float(loading.ramp_fraction) * Tl
            pts = [(0.0, 0.0), (ta, 1.0), (Tl - ta, 1.0), (Tl, 0.0)]
        else:  # constant velocity from t = 0; stopped (within 1e-6 of Tl) once the travel is done
            pts = [(0.0, 1.0), (Tl, 1.0)] + ([(Tl * (1 + 1e-6), 0.0)] if T > Tl * (1 + 1e-6) else [])
        if loading.path is not None:
            pts = _path_velocity_points(loading)
        if T > pts[-1][0]:
            pts.append((T, 0.0))
        lines += ["*AMPLITUDE, NAME=PLATE_VELOCITY, DEFINITION=SMOOTH STEP", *_pairs(pts)]
        figures["plate_velocity_m_s"] = float(loading.velocity)
    for k, d in enumerate(_drives(scene)):
        Td = float(np.linalg.norm(d.displacement)) / float(d.velocity) / 0.9
        ta = 0.1 * Td
        lines += [f"*AMPLITUDE, NAME=DRIVE{k}_VELOCITY, DEFINITION=SMOOTH STEP",
                  *_pairs([(0.0, 0.0), (ta, 1.0), (Td - ta, 1.0), (Td, 0.0)])]
    return lines


def _material_and_interaction_lines(cfg, mesh, planes: list[dict], figures: dict) -> list[str]:
    """The material with its Rayleigh damping, the fiber–fiber pressure-overclosure table and
    friction, and the fiber–plane interaction."""
    scene, material = cfg.scene, cfg.material
    effects = set(scene.effects)
    damped = "damping" in effects
    lines = ["**", "** MATERIAL", "**",
             *_material_lines(material.youngs_modulus, material.poisson_ratio_value, material.density,
                              float(scene.damping.alpha) if damped else 0.0,
                              float(scene.damping.beta) if damped else 0.0, damping=damped)]
    mu = float(scene.friction.mu) if "friction" in effects else 0.0
    if "contact" in effects:
        table = pressure_overclosure(cfg, mesh)
        figures.update(contact_fit_error_full_scale=table.fit_error_full_scale,
                       contact_fit_error_relative=table.fit_error_relative)
        lines += ["**", "** INTERACTIONS", "**",
                  f"** fiber-fiber normal law: {table.law}",
                  f"** pressure = {table.force_to_pressure}",
                  f"** table fit error over 0-{_f(table.range_m)} m: {100 * table.fit_error_full_scale:.3g} % of full scale, "
                  f"{100 * table.fit_error_relative:.3g} % relative above 5 % of the range",
                  "*SURFACE INTERACTION, NAME=FIBER_FIBER"]
        if mu > 0:
            lines += ["*FRICTION", f"{mu:g}"]
        lines += ["*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=TABULAR"]
        lines += [f"{_f(p)}, {_f(h)}" for p, h in table.rows]
    if planes:
        lines += ["*SURFACE INTERACTION, NAME=FIBER_PLANE"]
        if mu > 0:
            lines += ["*FRICTION", f"{mu:g}"]
    return lines


def _boundary_lines(scene, planes: list[dict], held: _Held) -> list[str]:
    """The step's boundary conditions: planes, constraints, clamps, drives, and the velocities of the
    moving plate and the drives."""
    bnd = []
    for pl in planes:  # a fixed plane: every DOF; a moving plate: all but its travel (set by velocity below)
        ax = pl["ax"] + 1
        if pl["travel"] == 0:
            bnd.append(f"{pl['rp']}, ENCASTRE")
        else:
            bnd += [f"{pl['rp']}, {lo}, {hi}" for lo, hi in ((1, ax - 1), (ax + 1, 6)) if lo <= hi]
    if held.lock:
        axd = AXES.index(scene.constraints.axis) + 1
        bnd += [f"{held.lock}, {axd}, {axd}"]
    if held.clamp_nodes:
        bnd += ["CLAMPS, ENCASTRE"]
    drives = _drives(scene)
    for d in drives:
        bnd += [f"FIBERS-1.FIBER{d.fiber}_NODES, {dof}, {dof}" for dof in (4, 5, 6)]
    lines = ["*BOUNDARY", *bnd] if bnd else []
    for pl in planes:
        if pl["travel"] > 0:
            ax = pl["ax"] + 1
            lines += ["*BOUNDARY, TYPE=VELOCITY, AMPLITUDE=PLATE_VELOCITY",
                      f"{pl['rp']}, {ax}, {ax}, {_f(pl['sign'] * float(scene.loading.velocity))}"]
    for k, d in enumerate(drives):
        v = np.asarray(d.displacement, float) / np.linalg.norm(d.displacement) * float(d.velocity)
        lines += [f"*BOUNDARY, TYPE=VELOCITY, AMPLITUDE=DRIVE{k}_VELOCITY"]
        lines += [f"FIBERS-1.FIBER{d.fiber}_NODES, {j + 1}, {j + 1}, {_f(v[j])}" for j in range(3)]
    return lines


def _load_lines(scene, mesh) -> list[str]:
    """Gravity, line loads and point loads."""
    effects = set(scene.effects)
    lines = []
    if "gravity" in effects:
        g = np.asarray(scene.gravity.acceleration, float)
        gn = float(np.linalg.norm(g))
        if gn > 0:
            lines += ["*DLOAD", f"FIBERS-1.FIBERS, GRAV, {_f(gn)}, {_f(g[0] / gn)}, {_f(g[1] / gn)}, {_f(g[2] / gn)}"]
    if "loads" in effects:
        for load in scene.loads:
            if load.line_force is not None:
                lines += ["*DLOAD"] + [f"FIBERS-1.FIBER{load.fiber}, P{'XYZ'[j]}, {_f(load.line_force[j])}"
                                       for j in range(3) if load.line_force[j] != 0]
            else:
                node = _node(mesh, load.fiber, load.at)
                lines += ["*CLOAD"] + [f"FIBERS-1.{node}, {j + 1}, {_f(load.force[j])}" for j in range(3) if load.force[j] != 0]
    return lines


def _contact_lines(scene, planes: list[dict]) -> list[str]:
    """General contact: the fibers' exterior with itself and with each plane, and the properties."""
    contact = "contact" in scene.effects
    if not (contact or planes):
        return []
    lines = ["*CONTACT"]
    if contact:
        lines += ["*CONTACT INCLUSIONS, ALL EXTERIOR"]
    if planes:
        lines += ["*CONTACT INCLUSIONS"] + [f"FIBERS-1.FIBERS_SURF, {pl['name']}" for pl in planes]
    lines += ["*CONTACT PROPERTY ASSIGNMENT"]
    if contact:
        lines += [" , , FIBER_FIBER"]
    return lines + [f"FIBERS-1.FIBERS_SURF, {pl['name']}, FIBER_PLANE" for pl in planes]


def _output_lines(cfg, planes: list[dict], T: float) -> list[str]:
    """Field output at the run's frames, the energies, the plates' reaction and travel; the step's end."""
    n_frames = max(int(cfg.solver.output_frames) - 1, 1)
    lines = ["*OUTPUT, FIELD, NUMBER INTERVAL=" + str(n_frames), "*NODE OUTPUT", "U, V, RF",
             f"*OUTPUT, HISTORY, TIME INTERVAL={_f(T / 1000)}", "*ENERGY OUTPUT",
             "ALLKE, ALLSE, ALLPW, ALLFD, ALLVD, ALLWK, ALLIE, ETOTAL"]
    for pl in planes:
        if pl["name"].startswith("PLATE"):
            ax = pl["ax"] + 1
            lines += [f"*NODE OUTPUT, NSET={pl['rp']}", f"RF{ax}, U{ax}"]
    return lines + ["*END STEP", ""]


def write_abaqus_deck(path, cfg, mesh) -> dict:
    """Write :func:`abaqus_deck` to ``path`` (atomic); returns its key figures."""
    text, figures = abaqus_deck(cfg, mesh)
    write_text_atomic(path, text)
    return figures
