"""The compaction literature's specimens for ``fiberpipe specimen``: random 3D networks, planar
random mats and aligned wavy bundles (``specimen.kind``).

# Strategy: random sequential addition. Fiber after fiber, a centre is drawn uniformly in the cell
# and a direction by the kind (isotropic on the sphere; uniform in the horizontal x-z plane; along z
# with a sinusoid of span and rise in y and a random phase); the fiber is kept if it lies inside the
# cell (a radius plus the clearance from the walls and plates) and clears every fiber placed before
# by 2r + clearance (closest distances between their segments), else another draw is made. The
# specimens are force free and contact free at U = 0 (the literature's initial states: Toll 1998,
# Rodney et al. 2005, Barbier et al. 2009, Subramanian & Picu 2011); the cell's height is set by the
# target v_f0 (h = N π r² L / (w · depth · v_f0)), the walls close the cell in x and z.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fiberpipe.errors import ConfigError

#: draws per fiber before the command gives up (the cell is too full for random addition)
MAX_DRAWS_PER_FIBER = 4000
#: a fiber's length must span at least this many elements, a wave's span at least this many
MIN_ELEMENTS_PER_FIBER = 4
MIN_ELEMENTS_PER_SPAN = 4


class Cell(NamedTuple):
    """The cell: x in [−width/2, width/2], y in [0, height], z in [0, depth] (m)."""

    width_m: float
    height_m: float
    depth_m: float


def cell_of(sp, radius_m: float) -> Cell:
    """The cell of the specimen section ``sp``: its height from the target v_f0."""
    depth = sp.depth if sp.depth is not None else sp.width
    height = sp.n_fibers * math.pi * radius_m**2 * sp.length / (sp.volume_fraction * sp.width * depth)
    return Cell(float(sp.width), float(height), float(depth))


def check_network_fits(cfg, sp, where: str) -> Cell:
    """Refuse, before anything is drawn, a cell or a mesh that cannot hold the specimen."""
    r = float(cfg.fiber.radius)
    cell = cell_of(sp, r)
    for key, size in (("specimen.width", cell.width_m), ("specimen.depth", cell.depth_m)):
        if size < 4 * r:
            raise ConfigError(f"{key} = {size * 1e3:.4g} mm is narrower than two fiber diameters "
                              f"({4 * r * 1e3:.4g} mm): widen the cell", where=where)
    if cell.height_m < 4 * r:
        raise ConfigError(f"specimen.volume_fraction = {sp.volume_fraction:g} makes the cell {cell.height_m * 1e3:.3g} mm "
                          f"high, less than two fiber diameters: lower it or add fibers", where=where)
    h = float(cfg.mesh.element_length)
    if sp.length / h < MIN_ELEMENTS_PER_FIBER:
        raise ConfigError(f"specimen.length = {sp.length * 1e3:.4g} mm (L/d = {sp.length / (2 * r):.3g}) spans "
                          f"{sp.length / h:.2g} elements of mesh.element_length = {h * 1e3:.4g} mm: the mesh cannot "
                          f"resolve it (at least {MIN_ELEMENTS_PER_FIBER}); shorten the elements", where=where)
    if sp.kind == "wavy_bundle":
        if sp.wave.span / h < MIN_ELEMENTS_PER_SPAN:
            raise ConfigError(f"specimen.wave.span = {sp.wave.span * 1e3:.4g} mm spans {sp.wave.span / h:.2g} elements "
                              f"of mesh.element_length = {h * 1e3:.4g} mm: the mesh cannot resolve the waviness "
                              f"(at least {MIN_ELEMENTS_PER_SPAN}); shorten the elements", where=where)
        if cell.depth_m < sp.length + 2 * (r + sp.gap):
            raise ConfigError(f"specimen.depth = {cell.depth_m * 1e3:.4g} mm cannot hold the aligned fibers "
                              f"(specimen.length = {sp.length * 1e3:.4g} mm plus a radius and the clearance at each "
                              "end): lengthen the cell", where=where)
        if sp.wave.rise + 2 * r > cell.height_m:
            raise ConfigError(f"specimen.wave.rise = {sp.wave.rise * 1e3:.4g} mm does not fit the cell's height "
                              f"{cell.height_m * 1e3:.4g} mm with a fiber's diameter", where=where)
    elif sp.length > min(cell.width_m, cell.depth_m) * (math.sqrt(2) if sp.kind == "planar_mat" else math.sqrt(3)):
        raise ConfigError(f"specimen.length = {sp.length * 1e3:.4g} mm does not fit the cell "
                          f"({cell.width_m * 1e3:.4g} × {cell.depth_m * 1e3:.4g} mm) in every direction: widen it "
                          "(specimen.width, specimen.depth)", where=where)
    return cell


def fiber_shape(kind: str, sp, points: int, rng) -> np.ndarray:
    """One fiber's points relative to its centre, drawn for ``kind``."""
    s = np.linspace(-0.5, 0.5, points)[:, None] * sp.length
    if kind == "network_3d":
        d = rng.normal(size=3)
        return s * (d / np.linalg.norm(d))
    if kind == "planar_mat":
        angle = rng.uniform(0.0, math.pi)
        return s * np.array([math.cos(angle), 0.0, math.sin(angle)])
    phase = rng.uniform(0.0, 2 * math.pi)
    z = s[:, 0]
    shape = np.zeros((points, 3))
    shape[:, 1] = 0.5 * sp.wave.rise * np.sin(math.pi * z / sp.wave.span + phase)
    shape[:, 2] = z
    return shape


def place_fibers(kind: str, sp, radius_m: float, cell: Cell, seed: int, where: str) -> list[np.ndarray]:
    """Random sequential addition of ``sp.n_fibers`` fibers in ``cell`` (one-line error when the
    cell is too full for it)."""
    from fiberpipe.model.specimen_stats import segment_distances

    rng = np.random.default_rng([seed, 7])
    clear = radius_m + sp.gap
    lo = np.array([-cell.width_m / 2, 0.0, 0.0]) + clear
    hi = np.array([cell.width_m / 2, cell.height_m, cell.depth_m]) - clear
    if kind == "wavy_bundle":  # points every quarter of a span at most: the sinusoid's segments
        points = max(sp.points_per_fiber, int(math.ceil(4 * sp.length / sp.wave.span)) + 1)
    else:
        points = 2
    placed: list[np.ndarray] = []
    # every fiber has ``points`` points: its segments are rows k of these (fibers, points − 1, 3) arrays
    starts = np.zeros((sp.n_fibers, points - 1, 3))
    ends = np.zeros((sp.n_fibers, points - 1, 3))
    box_lo = np.zeros((sp.n_fibers, 3))
    box_hi = np.zeros((sp.n_fibers, 3))
    reach = 2 * radius_m + sp.gap
    for k in range(sp.n_fibers):
        for _ in range(MAX_DRAWS_PER_FIBER):
            shape = fiber_shape(kind, sp, points, rng)
            span_lo, span_hi = lo - shape.min(axis=0), hi - shape.max(axis=0)
            if np.any(span_lo > span_hi):
                continue
            centre = rng.uniform(span_lo, span_hi)
            if kind == "wavy_bundle":
                centre[2] = cell.depth_m / 2
            fiber = centre + shape
            # only the fibers whose bounding boxes come within the clearance can be closer than it
            near = np.all((box_lo[:k] <= fiber.max(axis=0) + reach) & (box_hi[:k] >= fiber.min(axis=0) - reach), axis=1)
            if np.any(near):
                d, _, _ = segment_distances(fiber[:-1, None, :], fiber[1:, None, :],
                                            starts[:k][near].reshape(1, -1, 3), ends[:k][near].reshape(1, -1, 3))
                if d.min() < reach:
                    continue
            placed.append(fiber)
            starts[k], ends[k] = fiber[:-1], fiber[1:]
            box_lo[k], box_hi[k] = fiber.min(axis=0), fiber.max(axis=0)
            break
        else:
            raise ConfigError(f"specimen: random addition placed {k} of {sp.n_fibers} fibers in the cell at v_f0 = "
                              f"{sp.volume_fraction:g} ({MAX_DRAWS_PER_FIBER} draws for the next): lower "
                              "specimen.volume_fraction or the fibers' length", where=where)
    if kind != "wavy_bundle":  # straight fibers: resample at points_per_fiber for the record
        t = np.linspace(0.0, 1.0, sp.points_per_fiber)[:, None]
        placed = [f[0] + t * (f[-1] - f[0]) for f in placed]
    return placed


def orientation_averages(directions: np.ndarray) -> dict:
    """Toll's orientation averages over fiber pairs: f = ⟨|sin γ|⟩ and g = ⟨|cos γ|⟩, γ the angle
    between two fibers' directions (all distinct pairs); isotropic 3D: π/4 and 1/2."""
    u = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    c = np.abs(u @ u.T)
    iu = np.triu_indices(len(u), 1)
    cos = np.clip(c[iu], 0.0, 1.0)
    return {"f_mean_abs_sin": float(np.mean(np.sqrt(1 - cos**2))), "g_mean_abs_cos": float(np.mean(cos))}


def toll_contacts_per_fiber(volume_fraction: float, aspect_ratio: float, f: float, g: float) -> float:
    """Toll 1998's contacts per fiber, N_c = 4 v_f [(2/π)(L/d) f + g + 1] (Polym. Eng. Sci. 38:1337;
    the formula as cited, its text not retrieved); isotropic 3D it tends to 2 v_f L/d, the
    excluded-volume result (Dodson's lecture notes after Kerekes & Schell)."""
    return 4 * volume_fraction * ((2 / math.pi) * aspect_ratio * f + g + 1)


def build_network_specimen(cfg, raw: dict, out: Path, *, where: str, seed: int, ready_config_text) -> dict:
    """``fiberpipe specimen`` for the kinds network_3d, planar_mat and wavy_bundle: place the fibers,
    write fibers.h5, specimen.json and the ready config.yaml (plates at 0 and the cell's height,
    walls at the cell's x and z faces; ``ready_config_text`` is the cassette's writer,
    :func:`fiberpipe.model.virtual_specimen.ready_config_text`); returns specimen.json's dict."""
    import copy

    from fiberpipe.artifacts import write_fibers, write_json_atomic, write_text_atomic
    from fiberpipe.model.specimen_settle import fiber_contacts
    from fiberpipe.polylines import Polylines

    sp = cfg.specimen
    r = float(cfg.fiber.radius)
    cell = check_network_fits(cfg, sp, where)
    fibers = Polylines.from_list(place_fibers(sp.kind, sp, r, cell, seed, where), r)
    pts, off = fibers.points_m, fibers.offsets
    directions = np.array([pts[off[i + 1] - 1] - pts[off[i]] for i in range(fibers.n_fibers)])
    averages = orientation_averages(directions)
    vf = sp.n_fibers * math.pi * r**2 * sp.length / (cell.width_m * cell.height_m * cell.depth_m)
    aspect = sp.length / (2 * r)
    info = {
        "kind": sp.kind, "width_m": cell.width_m, "height_m": cell.height_m, "depth_m": cell.depth_m,
        "length_m": sp.length, "aspect_ratio": aspect, "volume_fraction": vf,
        "target_volume_fraction": sp.volume_fraction, "pile_volume_fraction": vf,
        "pile_top_m": float(pts[:, 1].max() + r),
        "box_min_m": [-cell.width_m / 2, 0.0, 0.0], "box_max_m": [cell.width_m / 2, cell.height_m, cell.depth_m],
        "contacts_at_U0": {"fiber_fiber": fiber_contacts(pts, off, r, tol_m=sp.gap + 1e-7),
                           "fibers_on_lower_plate": 0, "fibers_at_upper_plate": 0},
        "orientation": averages,
        "toll_contacts_per_fiber_at_v0": toll_contacts_per_fiber(vf, aspect, averages["f_mean_abs_sin"],
                                                                 averages["g_mean_abs_cos"]),
        "generator": {"function": "fiberpipe.model.specimen_networks.place_fibers", "seed": seed,
                      "n_fibers": sp.n_fibers, "specimen": sp.model_dump(mode="json")},
    }
    if sp.kind == "wavy_bundle":
        info["wave"] = {"span_m": sp.wave.span, "rise_m": sp.wave.rise, "beta": sp.wave.span / sp.wave.rise}
    ready = copy.deepcopy(raw)
    scene = ready.setdefault("scene", {})
    effects = scene.setdefault("effects", [])
    if "walls" not in effects:
        effects.append("walls")
    scene["walls"] = {**(scene.get("walls") or {}), "z": [0.0, cell.depth_m]}
    out.mkdir(parents=True, exist_ok=True)
    write_fibers(out / "fibers.h5", fibers)
    write_json_atomic(out / "specimen.json", info)
    write_text_atomic(out / "config.yaml", ready_config_text(ready, out, cell.height_m, cell.width_m, where,
                                                             strain=sp.strain))
    return info


def network_report(info: dict, out: Path) -> str:
    """The command's summary for the network kinds."""
    o = info["orientation"]
    return "\n".join([
        f"wrote {out}/fibers.h5 ({info['generator']['n_fibers']} fibers, {info['kind']}), {out}/specimen.json, "
        f"{out}/config.yaml",
        f"  cell {info['width_m'] * 1e3:.4g} x {info['height_m'] * 1e3:.5g} (plate gap) x {info['depth_m'] * 1e3:.4g} mm; "
        f"v_f0 {info['volume_fraction']:.4f}; L/d {info['aspect_ratio']:.3g}",
        f"  orientation averages over fiber pairs: <|sin|> {o['f_mean_abs_sin']:.4f}, <|cos|> {o['g_mean_abs_cos']:.4f}; "
        f"Toll's contacts per fiber at v_f0 {info['toll_contacts_per_fiber_at_v0']:.3g}",
        f"  contacts at U = 0: {info['contacts_at_U0']['fiber_fiber']} fiber-fiber",
    ])
