"""Stage ``phantom``: a synthetic CT volume of curved, touching fibers and its ground truth."""

from __future__ import annotations

from pathlib import Path

from fiberpipe.artifacts import ensure_output_dir, write_fibers
from fiberpipe.config import PhantomConfig


def run_phantom(pcfg: PhantomConfig, out_dir: Path, *, config_sha256: str = "") -> dict:
    """Render ``out_dir/volume.tif`` (with voxel-size metadata) and ``out_dir/truth.h5``."""
    from fiberpipe.imaging.io import save_volume_tif
    from fiberpipe.imaging.phantom import make_phantom

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    volume, truth = make_phantom(
        n_fibers=pcfg.n_fibers,
        shape=tuple(pcfg.shape),
        radius_vox=pcfg.radius_vox,
        voxel_size_m=pcfg.voxel_size,
        touching_fraction=pcfg.touching_fraction,
        contrast_to_noise=pcfg.contrast_to_noise,
        blur_sigma_vox=pcfg.blur_sigma_vox,
        seed=pcfg.seed,
    )
    save_volume_tif(out_dir / "volume.tif", volume, pcfg.voxel_size)
    write_fibers(out_dir / "truth.h5", truth, config_sha256=config_sha256)
    return {"fibers": int(truth.n_fibers), "shape": list(volume.shape), "voxel_size_m": pcfg.voxel_size}


def render_simulation_frame(sim_path: Path, frame: int, voxel_size_m: float, out_dir: Path, **render_kw) -> dict:
    """Render frame ``frame`` of a simulation into ``out_dir/volume.tif`` + ``truth.h5`` (closed loop).
    The simulation and its frame are read before ``out_dir`` is made: a refused call leaves no folder."""
    from fiberpipe.imaging.io import save_volume_tif
    from fiberpipe.polylines import Polylines
    from fiberpipe.post.closed_loop import frame_index, frame_polylines, render_for_tracing
    from fiberpipe.post.history import load_simulation

    sim = load_simulation(sim_path)
    frame = frame_index(sim, frame)
    fibers = frame_polylines(sim, frame)
    out_dir = ensure_output_dir(out_dir)
    vol, origin = render_for_tracing(fibers, voxel_size_m, **render_kw)
    save_volume_tif(out_dir / "volume.tif", vol, voxel_size_m)
    shifted = Polylines(fibers.points_m - origin, fibers.offsets, fibers.radius_m)
    write_fibers(out_dir / "truth.h5", shifted, attrs={"origin_m": [float(v) for v in origin], "frame": int(frame)})
    return {"shape": list(vol.shape), "origin_m": [float(v) for v in origin], "frame": frame}
