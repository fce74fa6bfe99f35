"""Stage ``mesh``: ``fibers.h5`` -> ``mesh.h5``, ``mesh.vtu`` (ParaView) and ``model.inp`` (the scene as an
Abaqus/Explicit deck)."""

from __future__ import annotations

from pathlib import Path

from fiberpipe.artifacts import read_fibers, read_mesh, write_mesh
import numpy as np

from fiberpipe.config import MIN_FIBER_LENGTH_DIAMETERS, Config, element_length_m, max_overlap_shift_m
from fiberpipe.errors import ConfigError
from fiberpipe.io.abaqus import write_abaqus_deck, write_abaqus_inp
from fiberpipe.io.vtk import mesh_vtu
from fiberpipe.model.mesh import mesh_polylines, resolve_overlaps
from fiberpipe.stages._common import input_hashes


def run_mesh(cfg: Config, fibers_path: Path, out: Path, *, config_sha256: str = "") -> dict:
    polylines = read_fibers(fibers_path)
    radius = cfg.fiber.radius if cfg.fiber.radius is not None else float(np.median(polylines.radius_m))
    element_length = element_length_m(cfg.mesh, radius)
    min_len = (cfg.mesh.min_fiber_length if cfg.mesh.min_fiber_length is not None else
               max(MIN_FIBER_LENGTH_DIAMETERS * 2.0 * radius, 2.0 * element_length))
    polylines, dropped = _drop_short(cfg, polylines, min_len)
    mesh = mesh_polylines(
        polylines,
        element_length,
        smooth_sigma_m=cfg.mesh.smooth_sigma,
        min_fiber_length_m=min_len,
        radius_m=cfg.fiber.radius,
    )
    overlaps = (resolve_overlaps(mesh, max_shift_m=max_overlap_shift_m(cfg.mesh, radius)) if cfg.mesh.resolve_overlaps
                else None)
    m = cfg.material
    write_mesh(
        out,
        mesh,
        material={"youngs_modulus_pa": m.youngs_modulus, "shear_modulus_pa": m.shear_modulus_pa, "density_kg_m3": m.density},
        config_sha256=config_sha256,
        inputs=input_hashes({"fibers": Path(fibers_path)}),
    )
    out = Path(out)
    mesh_vtu(out.with_name("mesh.vtu"), mesh)
    write_deck(cfg, mesh, out.with_name("model.inp"))
    lengths = mesh.element_lengths_m()
    figures = {} if overlaps is None else {
        "initial_overlap_max_m": overlaps["max_overlap_before_m"],
        "overlap_adjustment_max_m": overlaps["max_shift_m"],
    }
    return {
        **figures,
        "fibers": mesh.n_fibers,
        "dropped_short_fibers": dropped,
        "min_fiber_length_m": min_len,
        "nodes": mesh.n_nodes,
        "elements": mesh.n_elements,
        "mean_element_length_m": float(lengths.mean()),
        "min_element_length_m": float(lengths.min()),
    }


def write_deck(cfg: Config, mesh, path: Path) -> None:
    """``model.inp``: the whole scene as an Abaqus/Explicit deck (docs/abaqus.md); the mesh stage
    writes it, and the simulate stage again with the scene it ran (the mesh stage's cache does not
    follow the scene). A scene without a time period (no motion, no ``solver.end_time``) gets the
    mesh alone. ``mesh``: a Mesh or the path of ``mesh.h5``."""
    if not hasattr(mesh, "nodes_m"):
        mesh = read_mesh(mesh)
    try:
        write_abaqus_deck(path, cfg, mesh)
    except ConfigError:
        m = cfg.material
        write_abaqus_inp(path, mesh, youngs_modulus_pa=m.youngs_modulus, poisson_ratio=m.poisson_ratio_value,
                         density_kg_m3=m.density, heading=f"fiberpipe {cfg.name}")


def _drop_short(cfg: Config, polylines, min_len: float):
    """Drop the fibers shorter than ``min_len`` (``mesh.min_fiber_length``; by default the trace
    stage's rule, :data:`MIN_FIBER_LENGTH_DIAMETERS` fiber diameters and at least two elements), with
    one warning line; refuse when the scene refers to fibers by index (dropping one renumbers them)."""
    import logging

    import numpy as np

    from fiberpipe.errors import InputError
    from fiberpipe.model.mesh import short_fibers
    from fiberpipe.polylines import Polylines

    short = short_fibers(polylines, min_len)
    if len(short) == 0:
        return polylines, 0
    lengths = polylines.lengths_m()
    what = f"{len(short)} of {polylines.n_fibers} fibers are shorter than mesh.min_fiber_length = {min_len * 1e3:.3g} mm"
    if len(short) == polylines.n_fibers:
        raise InputError(f"all {polylines.n_fibers} fibers are shorter than mesh.min_fiber_length = {min_len * 1e3:.3g} "
                         f"mm (longest {lengths.max() * 1e3:.3g} mm); lower mesh.min_fiber_length or mesh.element_length")
    by_index = [n for n in ("clamps", "loads", "drives") if n in cfg.scene.effects and getattr(cfg.scene, n)]
    if by_index:
        raise InputError(f"{what} (fiber {int(short[0])}: {lengths[short[0]] * 1e3:.3g} mm) and would be dropped, "
                         f"which renumbers the fibers scene.{by_index[0]} refers to; remove them from the input or "
                         "lower mesh.min_fiber_length")
    keep = np.setdiff1d(np.arange(polylines.n_fibers), short)
    kept = Polylines.from_list([polylines.fiber(i) for i in keep], polylines.radius_m[keep])
    logging.getLogger("fiberpipe").warning("mesh: dropped %s", what)
    return kept, int(len(short))
