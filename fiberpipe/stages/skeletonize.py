"""Stage ``skeletonize``: ``mask.h5`` -> ``skeleton.h5`` (3D thinning + local radius)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_artifact, write_volume
from fiberpipe.config import Config
from fiberpipe.stages._common import input_hashes


def run_skeletonize(cfg: Config, mask_path: Path, out: Path, *, config_sha256: str = "") -> dict:
    from fiberpipe.imaging.skeleton import skeletonize

    art = read_artifact(mask_path, "mask")
    mask = art["mask"]
    voxel_size = art.attrs["voxel_size_m"]
    skeleton, radius_vox = skeletonize(mask)
    write_volume(
        out,
        "skeleton",
        skeleton.astype(bool),
        eval_list(voxel_size),
        extra={"radius_vox": radius_vox.astype(np.float32)},
        config_sha256=config_sha256,
        inputs=input_hashes({"mask": Path(mask_path)}),
    )
    on = radius_vox[skeleton]
    return {"skeleton_voxels": int(skeleton.sum()), "median_radius_vox": float(np.median(on)) if on.size else 0.0}


def eval_list(v):
    """Voxel size attribute (stored as JSON text or array) -> list of 3 floats (dz, dy, dx), m."""
    import json

    from fiberpipe.imaging._util import voxel_size_zyx

    return [float(x) for x in voxel_size_zyx(json.loads(v) if isinstance(v, str) else v)]
