"""``post`` stage: tables (CSV), plots (PNG), ``summary.json`` and ``report.md`` of a simulation.

Every column and axis is defined, with its unit, in ``docs/outputs.md``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fiberpipe.artifacts import read_fibers, read_json_mapping, write_json_atomic, write_text_atomic
from fiberpipe.config import Config
from fiberpipe.post import plots
from fiberpipe.post.compaction import fit_van_wyk, mean_field_contacts
from fiberpipe.post.curves import force_displacement
from fiberpipe.post.energies import contact_energy_created_figures, energy_balance, quasi_static_ratio
from fiberpipe.post.geometry import fiber_volume_m3, projected_curvature, volume_fraction
from fiberpipe.post.phases import compaction_phases, describe
from fiberpipe.post.history import load_simulation
from fiberpipe.post.positions import ReferenceMidlines, position_error
from fiberpipe.post.tables import write_csv  # noqa: F401  (the post stage's CSV writer)

AXES = {"x": 0, "y": 1, "z": 2}


def _fmt(v, unit="", digits=4):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.{digits}g}{(' ' + unit) if unit else ''}"


def scene_plates_upper(cfg: Config) -> str:
    return cfg.scene.plates.upper if cfg.scene.plates is not None else "none"


class Loading(NamedTuple):
    """The plates' loading of a run: U and the load cell's force per history row, and the rows of
    its first loading (a loading path's later cycles excluded)."""

    U: np.ndarray
    F: np.ndarray
    first: np.ndarray


class Box(NamedTuple):
    """The scene's confinement: the plates' axis (z without plates), the walls' bounds per axis, and
    whether plates or walls confine the fibers at all (without them there is no volume fraction)."""

    plate_axis: int
    walls: dict
    confined: bool


def run_post(cfg: Config, sim_path: Path, out_dir: Path, *, config_sha256: str = "") -> dict:
    """Post-process ``simulation.h5`` into ``out_dir`` (CSV, PNG, summary.json, report.md)."""
    sim = load_simulation(sim_path)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_hist = np.asarray(sim.history.get("time", np.zeros(0)), float)
    summary: dict = {
        "name": cfg.name,
        "effects": sim.effects,
        "dt_s": float(sim.attrs.get("dt_s", float("nan"))),
        "steps": int(sim.attrs.get("steps", 0)),
        "elements": int(sim.attrs.get("elements", 0)),
        "solver_wall_time_s": float(sim.attrs.get("wall_time_s", float("nan"))),
    }
    made: list[str] = []
    loading = _force_displacement_outputs(cfg, sim, t_hist, out_dir, summary, made)
    U = None if loading is None else loading.U
    if sim.energy:
        _energy_outputs(cfg, sim.energy, t_hist, U, out_dir, summary, made)
    box = _box(cfg, loading is not None)
    geo = _geometry_table(cfg, sim, t_hist, U, box)
    write_csv(out_dir / "geometry.csv", geo)
    made.append("geometry.csv")
    _geometry_outputs(cfg, sim, geo, box, out_dir, summary, made)
    if loading is not None and len(sim.frames_time) >= 5:
        _compaction_fit_outputs(cfg, sim, t_hist, geo, box, loading, out_dir, summary, made)
    _stage_wall_times(Path(sim_path).parent / "summary.json", summary)

    # report.md too: written after the summary, so a stage stopped between them is not up to date
    summary["outputs"] = [*made, "report.md"]
    write_json_atomic(out_dir / "summary.json", summary)
    write_text_atomic(out_dir / "report.md", _report(cfg, summary, made))
    return {k: summary[k] for k in ("final_load_N", "energy_balance_residual_max", "peak_ke_over_se", "vf_final", "position_error_mean_m") if k in summary}


def _force_displacement_outputs(cfg: Config, sim, t_hist, out_dir: Path, summary: dict, made: list) -> Loading | None:
    """``force_displacement.csv``/``.png``, the phases and (for a loading path) its loops; None
    without plates."""
    h = sim.history
    if not ("plates" in sim.effects and "plate_force" in h and np.size(h["plate_force"]) > 0):
        return None
    load_cell = "upper" if scene_plates_upper(cfg) != "none" else "lower"
    U, F = force_displacement(sim, load_cell=load_cell)
    force = np.atleast_2d(h["plate_force"])
    write_csv(
        out_dir / "force_displacement.csv",
        {"time_s": t_hist, "U_m": U, "load_N": F, "lower_plate_force_N": force[:, 0], "upper_plate_force_N": force[:, -1]},
    )
    seg = np.asarray(h.get("segment", np.zeros(len(U))))
    first = seg == 0  # a loading path: the phases and the law fit of its first loading
    phases = compaction_phases(U[first], F[first])
    plots.plot_force_displacement(out_dir / "force_displacement.png", {cfg.name: (U, F)}, title="compaction load",
                                  phases=phases)
    made += ["force_displacement.csv", "force_displacement.png"]
    summary["final_U_m"] = float(U[-1])
    summary["final_load_N"] = float(F[-1])
    summary["max_load_N"] = float(np.max(F))
    summary["phases"] = phases
    if np.unique(seg).size > 1:  # a loading path: its cycles, loops and residual strains
        from fiberpipe.post.loops import write_loops

        files, entries = write_loops(out_dir, cfg, sim, U, F)
        made += files
        summary.update(entries)
    return Loading(U, F, first)


def _energy_outputs(cfg: Config, energy: dict, t_hist, U, out_dir: Path, summary: dict, made: list) -> None:
    """``energies.csv``/``.png``: the energies, their balance residual and the quasi-static check."""
    residual = energy_balance(energy)
    ratio = quasi_static_ratio(energy)
    limit = cfg.post.quasi_static_ratio
    # the check only means something once there is strain energy to compare with
    se = np.asarray(energy.get("strain", np.zeros_like(residual)))
    meaningful = se > 1e-6 * max(float(np.max(se)), 1e-300)
    fails = meaningful & (ratio > limit)
    cols = {"time_s": t_hist}
    if U is not None:
        cols["U_m"] = U
    cols.update({f"{k}_J": np.asarray(v) for k, v in energy.items() if k != "residual"})
    cols["balance_residual"] = residual
    cols["ke_over_se"] = np.where(np.isfinite(ratio), ratio, np.nan)
    cols["quasi_static"] = (~fails).astype(int)
    write_csv(out_dir / "energies.csv", cols)
    x, xl = (U * 1e3, "plate displacement U [mm]") if U is not None else (t_hist, "time [s]")
    plots.plot_energies(out_dir / "energies.png", x, {k: v for k, v in energy.items()}, xlabel=xl, quasi_static_fail=fails)
    made += ["energies.csv", "energies.png"]
    summary["energy_balance_residual_max"] = float(np.max(residual))
    summary["energy_balance_residual_final"] = float(residual[-1])
    summary["peak_ke_over_se"] = float(np.max(ratio[meaningful])) if meaningful.any() else float("nan")
    summary["quasi_static_fraction"] = float(1 - fails.mean()) if len(fails) else float("nan")
    summary["final_energy_J"] = {k: float(np.asarray(v)[-1]) for k, v in energy.items()}
    summary["contact_energy_created_J"], summary["contact_energy_created_over_external"] = (
        contact_energy_created_figures(energy))


def _box(cfg: Config, has_plates: bool) -> Box:
    scene = cfg.scene
    walls = {}
    if scene.walls is not None:
        for name, ax in AXES.items():
            v = getattr(scene.walls, name)
            if v is not None:
                walls[ax] = (v[0], v[1])
    return Box(AXES[scene.plates.axis] if scene.plates is not None else 2, walls, has_plates or bool(walls))


def _geometry_table(cfg: Config, sim, t_hist, U, box: Box) -> dict:
    """The columns of ``geometry.csv``, one row per frame: v_f (confined scenes only), curvature,
    contacts and the position error against ``post.reference_fibers``."""
    h, mesh, frames, ft = sim.history, sim.mesh, sim.frames_positions, sim.frames_time
    vol = fiber_volume_m3(mesh)
    gap = None
    if "plate_position" in h:
        pp = np.atleast_2d(h["plate_position"])
        gap_hist = pp[:, -1] - pp[:, 0]
        gap = np.interp(ft, t_hist, gap_hist)
    geo = {"time_s": ft}
    if U is not None:
        geo["U_m"] = np.interp(ft, t_hist, U)
    geo["volume_fraction"] = np.array(
        [volume_fraction(vol, frames[k], mesh.radius_m, plate_axis=box.plate_axis, plate_gap_m=None if gap is None else gap[k], walls=box.walls) for k in range(len(ft))]
    )
    geo["curvature_xz_per_m"] = np.array([projected_curvature(frames[k], mesh.node_offsets, "xz") for k in range(len(ft))])
    geo["curvature_yz_per_m"] = np.array([projected_curvature(frames[k], mesh.node_offsets, "yz") for k in range(len(ft))])
    if "contacts_per_fiber" in sim.frame_fields:  # evaluated on each frame (stages/simulate.py)
        geo["contacts_per_fiber"] = np.asarray(sim.frame_fields["contacts_per_fiber"], float).mean(axis=1)
        geo["max_normal_force_N"] = np.asarray(sim.frame_fields["max_normal_force"], float)
        geo["max_penetration_m"] = np.asarray(sim.frame_fields["max_penetration"], float)
    elif "contacts" in h and len(h["contacts"]) == len(t_hist):
        geo["contacts_per_fiber"] = np.interp(ft, t_hist, 2.0 * np.asarray(h["contacts"], float) / mesh.n_fibers)
    if cfg.post.reference_fibers:
        ref = read_fibers(cfg.post.reference_fibers)
        ref_lines = ReferenceMidlines(ref.points_m, ref.offsets)  # densified once for every frame
        geo["position_error_m"] = np.array(
            [position_error(frames[k], mesh.node_offsets, reference=ref_lines)["mean_m"] for k in range(len(ft))]
        )
    if not box.confined:  # without plates or walls there is no box, hence no volume fraction
        del geo["volume_fraction"]
    return geo


def _geometry_outputs(cfg: Config, sim, geo: dict, box: Box, out_dir: Path, summary: dict, made: list) -> None:
    """The plots and summary entries of the geometry table: v_f, curvature, contacts against the
    mean-field estimate, the position error and the reference stages."""
    mesh = sim.mesh
    xg, xgl = (geo["U_m"] * 1e3, "plate displacement U [mm]") if "U_m" in geo else (sim.frames_time, "time [s]")
    if box.confined:
        plots.plot_series(out_dir / "volume_fraction.png", xg, {"v_f": geo["volume_fraction"]}, xlabel=xgl, ylabel="fiber volume fraction v_f [-]")
        made.append("volume_fraction.png")
        summary["vf_initial"] = float(geo["volume_fraction"][0])
        summary["vf_final"] = float(geo["volume_fraction"][-1])
    summary["curvature_per_m"] = {
        "initial": {"xz": float(geo["curvature_xz_per_m"][0]), "yz": float(geo["curvature_yz_per_m"][0])},
        "final": {"xz": float(geo["curvature_xz_per_m"][-1]), "yz": float(geo["curvature_yz_per_m"][-1])},
    }
    if "contacts_per_fiber" in geo and box.confined and "contact" in sim.effects:
        L = float(np.mean(np.diff(mesh.node_offsets) - 1) * np.mean(mesh.element_lengths_m()))
        D = 2 * float(np.mean(mesh.radius_m))
        plots.plot_series(
            out_dir / "contacts.png",
            geo["volume_fraction"],
            {"simulated": geo["contacts_per_fiber"], "mean field 2(L/D)v_f (random fibers)": mean_field_contacts(geo["volume_fraction"], L, D)},
            xlabel="fiber volume fraction v_f [-]",
            ylabel="contacts per fiber [-]",
        )
        made.append("contacts.png")
        summary["contacts_per_fiber_final"] = float(geo["contacts_per_fiber"][-1])
    if "position_error_m" in geo:
        summary["position_error_mean_m"] = float(np.nanmean(geo["position_error_m"]))
        summary["position_error_final_m"] = float(geo["position_error_m"][-1])
        plots.plot_series(out_dir / "position_error.png", xg, {"mean": geo["position_error_m"] * 1e3}, xlabel=xgl, ylabel="fiber-position error [mm]")
        made.append("position_error.png")
    if cfg.post.reference_stages:  # scans at stages of the compaction
        from fiberpipe.post.positions import write_reference_stages

        made += write_reference_stages(out_dir, cfg, sim, geo.get("U_m"), summary)


def _compaction_fit_outputs(cfg: Config, sim, t_hist, geo: dict, box: Box, loading: Loading, out_dir: Path,
                            summary: dict, made: list) -> None:
    """van Wyk's law fitted to the first loading's pressure against v_f (free exponent and n = 3),
    and ``pressure_vf.png``."""
    mesh, walls = sim.mesh, box.walls
    vf_hist = np.interp(t_hist, sim.frames_time, geo["volume_fraction"])
    sizes = [
        (walls[ax][1] - walls[ax][0]) if ax in walls else float(np.ptp(mesh.nodes_m[:, ax]) + 2 * mesh.radius_m.max())
        for ax in range(3)
        if ax != box.plate_axis
    ]
    area = float(np.prod(sizes))
    pressure = loading.F / area
    loaded = (pressure > 0.01 * max(float(np.max(pressure)), 1e-300)) & loading.first
    fit = fit_van_wyk(vf_hist[loaded], pressure[loaded], cfg.material.youngs_modulus) if loaded.sum() >= 5 else {}
    fit3 = fit_van_wyk(vf_hist[loaded], pressure[loaded], cfg.material.youngs_modulus, n=3.0) if loaded.sum() >= 5 else {}
    summary["van_wyk_fit"] = {"free_n": fit, "n3": fit3, "plate_area_m2": area}
    plots.plot_series(out_dir / "pressure_vf.png", vf_hist, {"simulated": pressure}, xlabel="fiber volume fraction v_f [-]", ylabel="pressure P [Pa]")
    made.append("pressure_vf.png")


def _stage_wall_times(run_summary: Path, summary: dict) -> None:
    """The wall time of each of the run's stages, from the run folder's ``summary.json``."""
    if run_summary.exists():
        stages = read_json_mapping(run_summary).get("stages", {})
        if isinstance(stages, dict):
            summary["wall_time_s_per_stage"] = {k: v.get("wall_time_s") for k, v in stages.items() if isinstance(v, dict)}


# the created-energy check: above this fraction of the external work the report says so
CREATED_WARN_FRACTION = 0.05


def _created(s: dict, planes: bool = False) -> str:
    """The created-energy cell; above 5 % of ALLWK it says so, and with plates or walls (``planes``)
    it names the two settings that remove such a gain in rattling scenes (docs/contact.md, "The step
    and the plane penalty")."""
    c, r = s.get("contact_energy_created_J"), s.get("contact_energy_created_over_external")
    if c is None:
        return "n/a"
    text = f"{_fmt(c, 'J')} ({_fmt(r)})"
    if r is not None and np.isfinite(r) and r > CREATED_WARN_FRACTION:
        text += " **above 5 % of ALLWK: the contact created energy, see docs/contact.md"
        if planes:
            text += ("; fibers rattling on the plates or walls gain it when the plane penalty switches on over a "
                     "penetration too short for the step: rerun with a longer scene.plates/walls.onset_fraction "
                     "or a smaller solver.dt_safety")
        text += "**"
    return text


def _report(cfg: Config, s: dict, made: list[str]) -> str:
    lines = [f"# fiberpipe report: {cfg.name}", "", "## Key figures", "", "| figure | value |", "| --- | --- |"]
    rows = [
        ("effects", ", ".join(s.get("effects", []))),
        ("elements", s.get("elements")),
        ("time step dt", _fmt(s.get("dt_s"), "s")),
        ("steps", s.get("steps")),
        ("solver wall time", _fmt(s.get("solver_wall_time_s"), "s")),
        ("final plate displacement U", _fmt(s.get("final_U_m", float("nan")) * 1e3, "mm") if "final_U_m" in s else "n/a"),
        ("final load", _fmt(s.get("final_load_N"), "N")),
        ("peak K_e/S_e (quasi-static if < 1e-2)", _fmt(s.get("peak_ke_over_se"))),
        ("energy balance residual (max)", _fmt(s.get("energy_balance_residual_max"))),
        ("energy created by the contact, at least (× ALLWK, the external work)", _created(s, bool({"plates", "walls"} & set(cfg.scene.effects or ())))),
        ("v_f initial → final", f"{_fmt(s.get('vf_initial'))} → {_fmt(s.get('vf_final'))}"),
        ("mean fiber-position error", _fmt(s.get("position_error_mean_m", float("nan")) * 1e3, "mm") if "position_error_mean_m" in s else "n/a"),
    ]
    lines += [f"| {a} | {b} |" for a, b in rows]
    ph = s.get("phases")
    if ph:
        lines += ["", "## Compaction phases (the study's section 4)", "", describe(ph) + ".", "",
                  f"Criteria (docs/outputs.md): load means over {ph['window_m'] * 1e3:g} mm of U; rearrangement until "
                  f"they exceed {100 * ph['onset_fraction']:g} % of their peak; a steep phase where a two-segment fit's "
                  f"last slope is ≥ {ph['steep_factor']:g}× the mean slope since the onset. The study: rearrangement "
                  "0–0.55 mm, transition 0.55–1.12 mm, locking from 1.12 mm."]
    c = s.get("curvature_per_m", {})
    if c:
        lines += ["", "## Projected average curvature (the study's Table 4), 1/m", "", "| state | XZ plane | YZ plane |", "| --- | --- | --- |"]
        for state in ("initial", "final"):
            lines.append(f"| {state} | {_fmt(c[state]['xz'])} | {_fmt(c[state]['yz'])} |")
    fit = s.get("van_wyk_fit")
    if fit:
        lines += ["", "## Compaction law fit P = k E (v_f^n − v_f0^n)", "", "| fit | k | n | v_f0 | R² |", "| --- | --- | --- | --- | --- |"]
        for label, f in (("n free", fit.get("free_n", {})), ("n = 3 (van Wyk)", fit.get("n3", {}))):
            if f:
                lines.append(f"| {label} | {_fmt(f.get('k'))} | {_fmt(f.get('n'))} | {_fmt(f.get('vf0'))} | {_fmt(f.get('r2'))} |")
    from fiberpipe.post.loops import report_lines

    lines += report_lines(s, _fmt)
    walls = s.get("wall_time_s_per_stage")
    if walls:
        lines += ["", "## Wall time per stage", "", "| stage | s |", "| --- | --- |"]
        lines += [f"| {k} | {_fmt(v)} |" for k, v in walls.items()]
    lines += ["", "## Plots", ""]
    for name in made:
        if name.endswith(".png"):
            lines += [f"![{name}]({name})", ""]
    lines += ["Columns and axes are defined in docs/outputs.md.", ""]
    return "\n".join(lines)
