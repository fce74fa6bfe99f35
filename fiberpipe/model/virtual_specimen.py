"""``fiberpipe specimen CONFIG``: a virtual specimen from the config's ``specimen`` section.

# Strategy: ``specimen.n_fibers`` fibers of ``fiber.radius`` and ``specimen.length``, each a
# circular arc (``specimen.bow``: one spool radius or a uniform range of them, in a random,
# horizontal or vertical plane) with an optional short-wave waviness and a random tilt of
# σ = Φ_mean/√π per component (the angle between two such fibers is Rayleigh-distributed with
# mean √π σ), are deposited under gravity in a cassette of ``specimen.width``
# (:func:`fiberpipe.model.specimen.cassette_specimen`, ``placement="deposit"``), then settled in
# the solver with friction and the axial lock (:func:`fiberpipe.model.specimen_settle.settle_pile`).
# The upper plate goes at the height of the target v_f0 (v_f0 = N π r² / (w h)), or on the
# settled pile. The command writes ``fibers.h5``, ``specimen.json`` (box, generator settings,
# statistics) and ``config.yaml``: the input config with ``input.fibers`` set to the specimen and
# the plates and walls set to the cassette, ready for ``fiberpipe run``.
"""

from __future__ import annotations

import copy
import math
import os
import time
from pathlib import Path

import numpy as np
import yaml

from fiberpipe.config import PATH_KEYS, load_raw, validate_config
from fiberpipe.errors import ConfigError


def specimen_config(raw: dict, where: str):
    """The validated config of ``raw`` (a config with a ``specimen`` section; ``input`` may be
    missing: the specimen is the input) and its specimen section."""
    raw = copy.deepcopy(raw)
    raw.setdefault("input", {"polylines": [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]})
    cfg = validate_config(raw, where=where)
    if cfg.specimen is None:
        raise ConfigError("has no specimen section (specimen: {n_fibers: 40, ...})", where=where)
    if cfg.fiber.radius is None:
        raise ConfigError("the specimen needs fiber.radius (e.g. fiber: {radius: '0.25 mm'})", where=where)
    if "plates" in cfg.scene.effects and cfg.scene.plates.axis != "y":
        raise ConfigError(f"scene.plates.axis is {cfg.scene.plates.axis}: a specimen is built with y vertical "
                          "(set scene.plates.axis: y)", where=where)
    return cfg, cfg.specimen


def target_height_m(specimen, radius_m: float) -> float:
    """The plate gap of the target v_f0: N π r² L / (w h L) = v_f0."""
    return specimen.n_fibers * math.pi * radius_m**2 / (specimen.volume_fraction * specimen.width)


def check_fits(specimen, radius_m: float, where: str) -> None:
    """Refuse, before anything is drawn, a specimen whose fibers cannot fit its cassette."""
    free = specimen.width - 2 * radius_m - 2 * specimen.gap
    if free <= 0:
        raise ConfigError(f"specimen.width = {specimen.width * 1e3:.4g} mm cannot hold a fiber of diameter "
                          f"{2 * radius_m * 1e3:.4g} mm (plus the clearance): widen the cassette", where=where)
    radii = [specimen.bow.spool_radius] if specimen.bow.spool_radius is not None else list(specimen.bow.spool_radius_range or [])
    if radii and min(radii) <= specimen.length / 2:
        raise ConfigError(f"specimen.bow: a spool radius of {min(radii) * 1e3:.4g} mm cannot bend a "
                          f"{specimen.length * 1e3:.4g} mm fiber (it must exceed half the length)", where=where)
    if radii and specimen.bow.plane != "upright":
        rmin = min(radii)
        sag = rmin - math.sqrt(rmin**2 - specimen.length**2 / 4)
        if sag > 0.9 * free:
            raise ConfigError(f"specimen: a fiber bowed by the spool radius {rmin * 1e3:.4g} mm spans {sag * 1e3:.3g} mm "
                              f"across, more than the {0.9 * free * 1e3:.3g} mm its cassette (specimen.width = "
                              f"{specimen.width * 1e3:.4g} mm) leaves: widen it, raise the spool radius or set "
                              "specimen.bow.plane: upright", where=where)
    h = target_height_m(specimen, radius_m)
    if specimen.upper_plate == "target" and h < 2 * radius_m:
        raise ConfigError(f"specimen.volume_fraction = {specimen.volume_fraction:g} makes the cassette {h * 1e3:.3g} mm high, "
                          f"less than a fiber diameter: lower it or add fibers", where=where)


def fiber_curvatures(specimen, seed: int):
    """One curvature (1/m) per fiber: 1/spool_radius, or 1/R with R uniform over the range
    (its own random stream, so the deposit's draws do not depend on it)."""
    if specimen.bow.spool_radius is not None:
        return None, 1.0 / specimen.bow.spool_radius
    lo, hi = specimen.bow.spool_radius_range
    rr = np.random.default_rng([seed, 1]).uniform(lo, hi, specimen.n_fibers)
    return 1.0 / rr, float(np.mean(1.0 / rr))


def cassette_height_m(specimen, radius_m: float, top_m: float, pile: str, where: str) -> float:
    """The cassette's height over the ``pile`` (settled or deposited) whose top is at ``top_m``: the
    pile's top plus the gap with ``upper_plate: pile``, else the height of the target v_f0, which
    the pile must fit under (a one-line error naming the keys to change if it does not)."""
    if specimen.upper_plate == "pile":
        return top_m + specimen.gap
    height = target_height_m(specimen, radius_m)
    if specimen.upper_plate == "close":  # closed onto the target height (close_cassette checked the top)
        return height
    if top_m > height:
        vmax = specimen.n_fibers * math.pi * radius_m**2 / (specimen.width * top_m)
        raise ConfigError(
            f"specimen: the {pile} pile (top {top_m * 1e3:.4g} mm) does not fit its "
            f"cassette under the upper plate at {height * 1e3:.4g} mm (v_f0 = {specimen.volume_fraction:g}): lower "
            f"specimen.volume_fraction to at most {vmax:.4g}, raise specimen.candidates (a denser pile) or set "
            "specimen.upper_plate: pile", where=where)
    return height


def close_cassette(fibers, raw: dict, specimen, radius_m: float, *, where: str, progress: bool = False):
    """``upper_plate: close``: the settled pile ``fibers`` closed in the solver to the target v_f0's
    height and relaxed (:func:`fiberpipe.model.specimen_settle.close_pile`); returns the closed
    pile and the closing's figures (``{"needed": False}`` when the pile already fits under the target
    height: nothing to close)."""
    from fiberpipe.model.specimen_settle import ClosingPlan, close_pile
    from fiberpipe.progress import progress_bar

    top = float(np.max(fibers.points_m[:, 1] + radius_m))
    height = target_height_m(specimen, radius_m)
    if top + specimen.gap <= height:
        return fibers, {"needed": False, "pile_top_m": top, "target_height_m": height, "residual_load_N": 0.0}
    plan = ClosingPlan(width_m=specimen.width, start_m=top + specimen.gap, target_m=height,
                       velocity_m_s=specimen.close.velocity, relax_time_s=specimen.close.relax_time)
    with progress_bar("close", progress) as bar:
        closed, figures = close_pile(fibers, raw, plan, specimen.close, specimen.settle, where=where, progress=bar)
    return closed, {"needed": True, **figures}


#: specimen.kind -> (module, builder, report) of the kinds beside the cassette: the builder
#: ``build(cfg, raw, out, *, where, seed, ready_config_text) -> specimen.json's dict``, the report
#: ``report(info, out) -> str``
SPECIMEN_KINDS = {
    "network_3d": ("fiberpipe.model.specimen_networks", "build_network_specimen", "network_report"),
    "planar_mat": ("fiberpipe.model.specimen_networks", "build_network_specimen", "network_report"),
    "wavy_bundle": ("fiberpipe.model.specimen_networks", "build_network_specimen", "network_report"),
    "yarn": ("fiberpipe.model.specimen_yarn", "build_yarn_specimen", "yarn_report"),
}


def specimen_kind(kind: str):
    """The (builder, report) of a specimen kind of :data:`SPECIMEN_KINDS` (imported on demand)."""
    import importlib

    module, build, report = SPECIMEN_KINDS[kind]
    loaded = importlib.import_module(module)
    return getattr(loaded, build), getattr(loaded, report)


def build_specimen(raw: dict, out: Path, *, where: str, seed: int | None = None, echo=print,
                   progress: bool = False) -> dict:
    """Build the specimen of ``raw``'s specimen section into ``out``; returns specimen.json's dict.
    ``progress``: bars for the deposit and the settling on a terminal
    (:func:`fiberpipe.progress.progress_bar`)."""
    from fiberpipe.artifacts import write_fibers, write_json_atomic, write_text_atomic
    from fiberpipe.model.specimen import cassette_specimen
    from fiberpipe.model.specimen_settle import fiber_contacts
    from fiberpipe.model.specimen_stats import neighbour_orientations, specimen_statistics
    from fiberpipe.progress import progress_bar

    cfg, specimen = specimen_config(raw, where)
    seed = specimen.seed if seed is None else int(seed)
    if specimen.kind != "cassette":  # the literature's specimens and the yarn (SPECIMEN_KINDS)
        builder, _ = specimen_kind(specimen.kind)
        return builder(cfg, raw, out, where=where, seed=seed, ready_config_text=ready_config_text)
    r = float(cfg.fiber.radius)
    check_fits(specimen, r, where)
    curvatures, kappa = fiber_curvatures(specimen, seed)
    params = {
        "seed": seed, "n_fibers": specimen.n_fibers, "width_m": specimen.width, "length_m": specimen.length, "radius_m": r,
        "volume_fraction": specimen.volume_fraction, "points_per_fiber": specimen.points_per_fiber, "placement": "deposit",
        "tilt_rad": float(specimen.phi_mean / math.sqrt(math.pi)), "curvature_per_m": float(kappa),
        "candidates": specimen.candidates, "top": "pile", "gap_m": specimen.gap, "y_tilt_scale": specimen.y_tilt_scale,
        "bow_plane": specimen.bow.plane,
    }
    if specimen.waviness.curvature_per_m > 0:
        params.update(wave_curvature_per_m=specimen.waviness.curvature_per_m,
                      wave_lengths_m=tuple(specimen.waviness.wavelengths), wave_modes=specimen.waviness.modes)
    t0 = time.perf_counter()
    with progress_bar("deposit", progress) as bar:
        try:
            fibers, info = cassette_specimen(**params, curvatures_per_m=curvatures, progress=bar)
        except ValueError as exc:
            if "does not fit the cassette" in str(exc):
                raise ConfigError(f"specimen: a fiber tilted by specimen.phi_mean = {math.degrees(specimen.phi_mean):.3g} deg "
                                  f"does not fit the {specimen.width * 1e3:.4g} mm cassette: lower phi_mean or widen it",
                                  where=where) from None
            raise
    deposit = {k: v for k, v in info["deposit"].items() if k != "supports"}
    deposit["wall_time_s"] = time.perf_counter() - t0
    fibers, settle = _settle_deposit(fibers, raw, specimen, where, progress) if specimen.settle.enabled else (fibers, None)
    closing = close_cassette(fibers, raw, specimen, r, where=where, progress=progress) \
        if specimen.upper_plate == "close" else None
    fibers = closing[0] if closing else fibers
    pts = fibers.points_m
    top = float(np.max(pts[:, 1] + r))
    lowest = float(np.min(pts[:, 1] - r))
    height = cassette_height_m(specimen, r, top, "settled" if settle else "deposited", where)
    box_min, box_max = [-specimen.width / 2, 0.0, 0.0], [specimen.width / 2, height, specimen.length]
    stats = specimen_statistics(fibers, box_min_m=box_min, box_max_m=box_max)
    off = fibers.offsets
    nb = neighbour_orientations(fibers)
    edges = np.arange(0.0, max(20.0, math.ceil(float(nb["phi_deg"].max()) if nb["phi_deg"].size else 0.0)) + 1.0)
    counts, _ = np.histogram(nb["phi_deg"], bins=edges)
    per_fiber_low = np.array([np.min(pts[off[i]:off[i + 1], 1]) - r for i in range(fibers.n_fibers)])
    per_fiber_top = np.array([np.max(pts[off[i]:off[i + 1], 1]) + r for i in range(fibers.n_fibers)])
    if settle:  # the settled pile's own figures (contacts within 0.1 µm: pressed by the weight)
        settled_top = closing[1]["start_height_m"] - specimen.gap if closing and closing[1]["needed"] else top
        settle.update(pile_top_before_m=float(deposit["pile_top_m"]), pile_top_m=settled_top, top_clearance_m=float(height - top),
                      fiber_contacts=fiber_contacts(pts, off, r), lowest_surface_m=lowest,
                      fibers_on_lower_plate=int(np.sum(per_fiber_low <= 1e-7)))
    info = {
        "width_m": specimen.width, "height_m": float(height), "length_m": specimen.length,
        "volume_fraction": float(specimen.n_fibers * math.pi * r**2 / (specimen.width * height)),
        "target_volume_fraction": specimen.volume_fraction,
        "pile_volume_fraction": float(specimen.n_fibers * math.pi * r**2 / (specimen.width * top)),
        "box_min_m": box_min, "box_max_m": box_max,
        "pile_top_m": top, "top_clearance_m": float(height - top), "lowest_surface_m": lowest,
        "contacts_at_U0": {
            "fiber_fiber": fiber_contacts(pts, off, r, tol_m=specimen.gap + 1e-7),
            "fibers_on_lower_plate": int(np.sum(per_fiber_low <= specimen.gap + 1e-7)),
            "fibers_at_upper_plate": int(np.sum(per_fiber_top >= height - specimen.gap - 1e-7)),
        },
        "phi_histogram_deg": {"edges": edges.tolist(), "counts": counts.astype(int).tolist()},
        "deposit": deposit,
        **({"settle": {k: v for k, v in settle.items() if k != "wall_time_s"}} if settle else {}),
        **({"closing": closing[1]} if closing else {}),
        "generator": {"function": "fiberpipe.model.specimen.cassette_specimen",
                      **{k: (list(v) if isinstance(v, tuple) else v) for k, v in params.items()},
                      "spool_radius_m": specimen.bow.spool_radius, "spool_radius_range_m": specimen.bow.spool_radius_range,
                      **({"settle": {k: settle[k] for k in ("alpha_per_s", "time_s", "mu", "lock_axial", "mass_scaling",
                                                            "gravity_scale") if k in settle}} if settle else {}),
                      "specimen": specimen.model_dump(mode="json")},
        "statistics": stats,
    }
    out.mkdir(parents=True, exist_ok=True)
    write_fibers(out / "fibers.h5", fibers)
    write_json_atomic(out / "specimen.json", info)
    write_text_atomic(out / "config.yaml", ready_config_text(raw, out, height, specimen.width, where, strain=specimen.strain))
    if settle:
        info["settle_wall_time_s"] = settle["wall_time_s"]
    return info


def _settle_deposit(fibers, raw: dict, specimen, where: str, progress: bool):
    """The deposited pile settled in the solver by ``specimen.settle`` (with its own contact law
    where it gives one): (settled fibers, the settling's figures)."""
    from fiberpipe.model.specimen_settle import settle_pile
    from fiberpipe.progress import progress_bar

    settle_cfg = specimen.settle
    settle_raw = raw if settle_cfg.contact is None else \
        {**raw, "scene": {**(raw.get("scene") or {}), "contact": settle_cfg.contact}}
    with progress_bar("settle", progress) as bar:
        return settle_pile(
            fibers, settle_raw, width_m=specimen.width, alpha_per_s=settle_cfg.damping_alpha, time_s=settle_cfg.time,
            mu=settle_cfg.mu, lock=None if settle_cfg.lock_axial == "none" else settle_cfg.lock_axial,
            frames=settle_cfg.frames, mass_scaling=settle_cfg.mass_scaling, gravity_scale=settle_cfg.gravity_scale,
            where=where, progress=bar)


def ready_config_text(raw: dict, out: Path, height_m: float, width_m: float, where: str,
                      strain: float | None = None) -> str:
    """``raw`` without its specimen section, its input the specimen (``fibers.h5`` next to it), its
    plates at 0 and ``height_m`` and its x walls at ±``width_m``/2; paths relative to ``out``.
    ``strain``: the loading's displacement set to ``strain × height_m`` (the specimen compacted by
    the same nominal strain U/h0 as another of a different height)."""
    ready = copy.deepcopy(raw)
    ready.pop("specimen", None)
    source = (ready.get("input") or {}).get("fibers")
    ready["input"] = {"fibers": "fibers.h5"}
    post = ready.get("post")
    if isinstance(post, dict) and post.get("reference_fibers") is not None and post["reference_fibers"] == source:
        post["reference_fibers"] = "fibers.h5"  # the base compared with its own specimen: so does this
    for section, key in PATH_KEYS:
        sec = ready.get(section)
        if isinstance(sec, dict) and isinstance(sec.get(key), str) and os.path.isabs(sec[key]):
            sec[key] = os.path.relpath(sec[key], out.resolve())
    scene = ready.setdefault("scene", {})
    if isinstance(scene.get("plates"), dict):
        scene["plates"] = {**scene["plates"], "lower_position": 0.0, "upper_position": float(height_m)}
    if isinstance(scene.get("walls"), dict) or "walls" in scene.get("effects", []):
        scene["walls"] = {**(scene.get("walls") or {}), "x": [-width_m / 2, width_m / 2]}
    loading = ""
    if strain is not None:
        scene["loading"] = {**(scene.get("loading") or {}), "displacement": float(strain * height_m)}
        loading = f" loading U = {strain:.6g} × the gap = {strain * height_m * 1e3:.6g} mm."
    head = (f"# Made by `fiberpipe specimen` from {where}: the specimen in fibers.h5 (specimen.json: its\n"
            f"# box, generator settings and statistics); plate gap {height_m * 1e3:.6g} mm, cassette {width_m * 1e3:.6g} mm."
            f"{loading}\n")
    return head + yaml.safe_dump(ready, sort_keys=False, default_flow_style=None, width=110)


def run_specimen_command(config: str, out: Path, *, seed: int | None = None, overrides: dict | None = None,
                         echo=print, progress: bool = False) -> dict:
    """``fiberpipe specimen``: load ``config`` (dotted ``overrides`` applied), build, report
    (``progress``: bars on a terminal, :func:`build_specimen`)."""
    from fiberpipe.config import set_dotted

    wall0, cpu0 = time.perf_counter(), time.process_time()
    raw = load_raw(config)
    for k, v in (overrides or {}).items():
        set_dotted(raw, k, v)
    info = build_specimen(raw, out, where=str(config), seed=seed, echo=echo, progress=progress)
    echo(specimen_report(info, out))
    echo(f"  built in {time.perf_counter() - wall0:.0f} s wall, {time.process_time() - cpu0:.0f} s CPU (one process)")
    return info


def specimen_report(info: dict, out: Path) -> str:
    """The command's summary: v_f0, contacts at U = 0, the Φ histogram, Table 4's curvatures."""
    if info.get("kind", "cassette") != "cassette":
        _, report = specimen_kind(info["kind"])
        return report(info, out)
    settle_cfg, c = info["statistics"], info["contacts_at_U0"]
    n = info["generator"]["n_fibers"]
    lines = [
        f"wrote {out}/fibers.h5 ({n} fibers), {out}/specimen.json, {out}/config.yaml",
        f"  cassette {info['width_m'] * 1e3:.4g} mm x {info['height_m'] * 1e3:.5g} mm (plate gap) x "
        f"{info['length_m'] * 1e3:.4g} mm; v_f0 {info['volume_fraction']:.4f} (target {info['target_volume_fraction']:.4f}; "
        f"the pile's own {info['pile_volume_fraction']:.4f}, top {info['pile_top_m'] * 1e3:.5g} mm)",
        f"  contacts at U = 0: {c['fiber_fiber']} fiber-fiber ({2 * c['fiber_fiber'] / max(n, 1):.2f} per fiber), "
        f"{c['fibers_on_lower_plate']} fibers on the lower plate, {c['fibers_at_upper_plate']} at the upper plate",
        f"  Phi of neighbours: mean {settle_cfg['phi_mean_deg']:.2f} deg (median {settle_cfg['phi_median_deg']:.2f}, "
        f"10-90 % {settle_cfg['phi_p10_deg']:.2f}-{settle_cfg['phi_p90_deg']:.2f}), {settle_cfg['neighbour_pairs']} pairs",
        "  Phi histogram (deg: pairs): " + ", ".join(
            f"{int(e)}-{int(e) + 1}: {k}" for e, k in zip(info["phi_histogram_deg"]["edges"], info["phi_histogram_deg"]["counts"])
            if k),
        f"  Table 4 curvatures at U = 0: XZ {settle_cfg['curvature_xz_per_m']:.4g} 1/m, YZ {settle_cfg['curvature_yz_per_m']:.4g} 1/m",
    ]
    if "wall_time_s" in info.get("deposit", {}):
        lines.append(f"  deposited {n} fibers in {info['deposit']['wall_time_s']:.0f} s wall")
    if "settle" in info:
        s = info["settle"]
        lines.append(f"  settled {s['time_s'] * 1e3:.3g} ms ({s['steps']} steps, "
                     f"{info.get('settle_wall_time_s', float('nan')):.0f} s wall): moved up to {s['max_displacement_m'] * 1e6:.1f} um, "
                     f"kinetic energy at the end {s['kinetic_energy_end_J']:.3g} J (max {s['kinetic_energy_max_J']:.3g} J)")
    closing = info.get("closing")
    if closing and closing["needed"]:
        lines.append(f"  closed from {closing['start_height_m'] * 1e3:.5g} mm to {closing['target_height_m'] * 1e3:.5g} mm "
                     f"({closing['steps']} steps, {closing['wall_time_s']:.0f} s wall): residual load {closing['residual_load_N']:.4g} N "
                     f"on the upper plate (peak {closing['peak_load_N']:.4g} N), left out of the compaction (its rest shape "
                     "is the closed pile)")
    elif closing:
        lines.append("  closing: the settled pile already fits under the target height (nothing to close)")
    return "\n".join(lines)
