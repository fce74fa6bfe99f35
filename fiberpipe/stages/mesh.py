"""Stage ``mesh``: ``fibers.h5`` -> ``mesh.h5``, ``mesh.vtu`` (ParaView) and ``model.inp`` (the scene as an
Abaqus/Explicit deck)."""

from __future__ import annotations

from pathlib import Path

from fiberpipe.artifacts import read_fibers, read_mesh, write_mesh
from fiberpipe.config import Config
from fiberpipe.errors import ConfigError
from fiberpipe.io.abaqus import write_abaqus_deck, write_abaqus_inp
from fiberpipe.io.vtk import mesh_vtu
from fiberpipe.model.mesh import mesh_polylines, resolve_overlaps
from fiberpipe.stages._common import input_hashes


def run_mesh(cfg: Config, fibers_path: Path, out: Path, *, config_sha256: str = "") -> dict:
    polylines = read_fibers(fibers_path)
    mesh = mesh_polylines(
        polylines,
        cfg.mesh.element_length,
        smooth_sigma_m=cfg.mesh.smooth_sigma,
        radius_m=cfg.fiber.radius,
    )
    overlaps = resolve_overlaps(mesh, max_shift_m=cfg.mesh.max_overlap_shift) if cfg.mesh.resolve_overlaps else None
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
