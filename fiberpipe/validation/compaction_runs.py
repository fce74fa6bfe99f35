"""Specimens built by ``fiberpipe specimen`` and compacted by ``fiberpipe run``, for the validation cases.

Each run builds the specimen of a validation config (``configs/validation/``) for one seed into a
folder, runs the pipeline on its ready config (mesh, simulate, post) and returns what the cases
read: post's summary (its mesoscale-law fits), the curve p(v_f), the history and the final frame."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

#: the validation configs (tests monkeypatch it)
CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "validation"
#: where the specimens and runs go: ``fiberpipe validate --out DIR`` sets DIR/work; a run already
#: there (its post summary written) is read, not rerun, so cases that share runs build them once
WORK = {"dir": None, "reuse_only": False}


class MissingRun(Exception):
    """``fiberpipe validate --reuse``: the work folder holds no finished run of this name."""


def work_dir() -> Path:
    if WORK["dir"] is None:
        WORK["dir"] = Path(tempfile.mkdtemp(prefix="fiberpipe-validate-"))
    return Path(WORK["dir"])


class CompactionRun(NamedTuple):
    """One specimen compacted: its specimen.json, post's summary.json, the simulation artifact."""

    specimen: dict
    summary: dict
    simulation: object  # fiberpipe.post.history.SimulationData
    run_dir: Path
    config: object  # the ready config (fiberpipe.config.Config)
    seed: int


def run_folder(config_name: str, seed: int, overrides: dict | None = None, work: Path | None = None) -> Path:
    """The folder of ``config_name``'s run for ``seed`` with ``overrides``: named by the config, the
    seed and the overrides' last key parts and values ("base" without any)."""
    tag = "-".join(f"{k.split('.')[-1]}={v}" for k, v in sorted((overrides or {}).items())) or "base"
    return (work or work_dir()) / f"{Path(config_name).stem}-seed{seed}-{tag}".replace("/", "_").replace(" ", "")


def compact(config_name: str, seed: int, work: Path | None = None, overrides: dict | None = None) -> CompactionRun:
    """Build ``config_name``'s specimen for ``seed`` with ``overrides`` (dotted keys) and compact it
    (or read the run of the same name already in ``work``)."""
    from ..artifacts import read_json_mapping
    from ..config import load_config, load_raw, set_dotted
    from ..model.virtual_specimen import build_specimen
    from ..pipeline import run_pipeline
    from ..post.history import load_simulation

    path = CONFIG_DIR / config_name
    raw = load_raw(str(path))
    for key, value in (overrides or {}).items():
        set_dotted(raw, key, value)
    folder = run_folder(config_name, seed, overrides, work)
    run_dir = folder / "run"
    if (run_dir / "post" / "summary.json").exists() and (folder / "specimen.json").exists():
        specimen = read_json_mapping(folder / "specimen.json")
    elif WORK["reuse_only"]:
        raise MissingRun(folder.name)
    else:
        specimen = build_specimen(raw, folder, where=str(path), seed=seed, echo=lambda *_: None)
        run_pipeline(load_config(folder / "config.yaml"), run_dir)
    summary = read_json_mapping(run_dir / "post" / "summary.json")
    return CompactionRun(specimen, summary, load_simulation(run_dir / "simulation.h5"), run_dir,
                         load_config(folder / "config.yaml"), seed)


def runs_over_seeds(config_name: str, overrides: dict, seeds) -> dict:
    """seed → run for ``seeds``; with ``--reuse`` the seeds without a finished run are left out."""
    out = {}
    for seed in seeds:
        try:
            out[seed] = compact(config_name, seed, overrides=overrides)
        except MissingRun:
            continue
    return out


def paired(*by_seed: dict) -> list[tuple]:
    """The runs of the seeds every dict holds, seed by seed (runs of one specimen compared)."""
    common = sorted(set.intersection(*(set(d) for d in by_seed)))
    return [tuple(d[s] for d in by_seed) for s in common]


def pressure_curve(run: CompactionRun) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(U, v_f, p) over the history rows: the upper (fixed) plate's force, the load cell's, over the
    plate area (the cell's width × depth; the moving plate's force also carries the damping's drag
    on the fibers it pushes), v_f = N π r² L / (area × the plate gap)."""
    spec, h = run.specimen, run.simulation.history
    area = spec["width_m"] * spec["depth_m"]
    solid = spec["volume_fraction"] * area * spec["height_m"]
    travel = np.asarray(h["plate_displacement"], float).sum(axis=1)
    gap = spec["height_m"] - travel
    force = np.asarray(h["plate_force"], float)[:, 1]
    return travel, solid / (area * gap), force / area


def final_contacts_per_fiber(run: CompactionRun, tolerance_m: float = 0.5e-6) -> float:
    """Fiber pairs whose centre lines come within 2r + ``tolerance_m`` in the last frame, × 2 / N."""
    from ..model.specimen_settle import fiber_contacts

    mesh = run.simulation.mesh
    x = run.simulation.frames_positions[-1]
    pairs = fiber_contacts(x, mesh.node_offsets, float(np.mean(mesh.radius_m)), tol_m=tolerance_m)
    return 2.0 * pairs / mesh.n_fibers


def final_orientation_averages(run: CompactionRun) -> dict:
    """Toll's f = ⟨|sin γ|⟩, g = ⟨|cos γ|⟩ over fiber pairs, from the last frame's end-to-end directions."""
    from ..model.specimen_networks import orientation_averages

    mesh = run.simulation.mesh
    x = run.simulation.frames_positions[-1]
    off = mesh.node_offsets
    return orientation_averages(np.array([x[off[i + 1] - 1] - x[off[i]] for i in range(mesh.n_fibers)]))


def final_volume_fraction(run: CompactionRun) -> float:
    _, vf, _ = pressure_curve(run)
    return float(vf[-1])


#: the specimen seeds of the full cases and of the quick variants (one seed: they check that a case
#: runs and gives a figure in its physical range, not the spread over specimens)
FULL_SEEDS = (0, 1, 2)
QUICK_SEEDS = (0,)
#: the seeds ``fiberpipe validate --seeds`` chose (None: the defaults above)
SEEDS = {"seeds": None}


def seeds_for(quick: bool) -> list[int]:
    """The specimen seeds of every compaction case: ``--seeds`` when given, else three for the full
    cases and one for the quick variants."""
    if SEEDS["seeds"] is not None:
        return list(SEEDS["seeds"])
    return list(QUICK_SEEDS if quick else FULL_SEEDS)


def validation_config(config_name: str):
    """The validated config of a specimen config in :data:`CONFIG_DIR` (its input is the specimen)."""
    from ..config import load_raw
    from ..model.virtual_specimen import specimen_config

    path = CONFIG_DIR / config_name
    return specimen_config(load_raw(str(path)), str(path))[0]


def cell_height(cfg) -> float:
    """The plate gap of a network config's specimen (its cell's height at the target v_f0)."""
    from ..model.specimen_networks import cell_of

    return cell_of(cfg.specimen, float(cfg.fiber.radius)).height_m


# windows of U over which two runs' curves are compared (their means)
WINDOWS = 10


def window_means(travel, force, edges) -> np.ndarray:
    idx = np.digitize(travel, edges) - 1
    return np.array([force[idx == k].mean() if np.any(idx == k) else np.nan for k in range(len(edges) - 1)])


def curve_change(base, slow) -> float:
    """Largest change of the window means of the upper plate's force between two runs over their
    first loading, relative to the base run's largest force."""
    def curve(run):
        h = run.simulation.history
        return np.asarray(h["plate_displacement"], float).sum(axis=1), np.asarray(h["plate_force"], float)[:, 1]

    (u0, f0), (u1, f1) = curve(base), curve(slow)
    edges = np.linspace(0.0, min(u0.max(), u1.max()), WINDOWS + 1)
    return float(np.nanmax(np.abs(window_means(u1, f1, edges) - window_means(u0, f0, edges))) / np.max(f0))
