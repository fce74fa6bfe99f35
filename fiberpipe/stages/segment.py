"""Stage ``segment``: volume file -> ``mask.h5`` (binary fiber mask, volume fraction)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_volume
from fiberpipe.config import Config
from fiberpipe.errors import InputError
from fiberpipe.stages._common import input_hashes


def run_segment(cfg: Config, volume_path: Path, out: Path, *, voxel_size_m=None, config_sha256: str = "") -> dict:
    from fiberpipe.imaging.io import load_volume
    from fiberpipe.imaging.segment import segment

    inp = cfg.input
    volume, voxel_size, source = load_volume(
        volume_path,
        voxel_size_m=voxel_size_m if voxel_size_m is not None else inp.voxel_size,
        dataset=inp.dataset,
        shape=tuple(inp.shape) if inp.shape else None,
        dtype=inp.dtype,
    )
    s = cfg.segment
    mask, info = segment(
        volume,
        method=s.method,
        threshold=s.threshold,
        smooth_sigma_vox=s.smooth_sigma_vox,
        min_object_vox=s.min_object_vox,
        fill_holes=s.fill_holes,
    )
    if not mask.any():
        raise InputError("segmentation found no fiber voxels; check segment.threshold", where=str(volume_path))
    info = {k: (float(v) if isinstance(v, (np.floating, float)) else v) for k, v in dict(info).items()}
    write_volume(
        out,
        "mask",
        mask.astype(bool),
        voxel_size,
        attrs={"segment": info, "voxel_size_source": str(source), "volume_shape": list(volume.shape)},
        config_sha256=config_sha256,
        inputs=input_hashes({"volume": Path(volume_path)}),
    )
    vs = np.broadcast_to(np.asarray(voxel_size, float), (3,))
    return {
        "shape": list(volume.shape),
        "voxel_size_m": [float(v) for v in vs],
        "voxel_size_source": str(source),
        "volume_fraction": float(info.get("volume_fraction", mask.mean())),
        "threshold": info.get("threshold"),
    }
