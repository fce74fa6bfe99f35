"""Stage ``skeletonize``: ``mask.h5`` -> ``skeleton.h5`` (3D thinning + local radius)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fiberpipe.artifacts import read_artifact, write_volume
from fiberpipe.config import Config
from fiberpipe.stages._chunks import chunked
from fiberpipe.stages._common import input_hashes


def run_skeletonize(cfg: Config, mask_path: Path, out: Path, *, config_sha256: str = "") -> dict:
    from fiberpipe.imaging.skeleton import skeletonize

    if chunked(cfg, mask_shape(mask_path)):
        return run_skeletonize_chunked(cfg, mask_path, out, config_sha256=config_sha256)
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


def mask_shape(mask_path: Path) -> tuple[int, ...]:
    """The shape of ``mask.h5``'s mask, without reading it."""
    from fiberpipe.artifacts import open_checked

    with open_checked(mask_path, "mask") as f:
        return tuple(int(n) for n in f["mask"].shape)


def run_skeletonize_chunked(cfg: Config, mask_path: Path, out: Path, *, config_sha256: str = "") -> dict:
    """The skeletonize stage slab by slab (``chunks``): the mask read ``chunks.slices`` slices at a
    time with a halo of ``chunks.halo_vox`` voxels, the skeleton and radius written into
    ``skeleton.h5`` as slabs finish; the same artifact as the in-memory path."""
    from fiberpipe.artifacts import artifact_writer, open_checked
    from fiberpipe.errors import InputError
    from fiberpipe.imaging.skeleton_chunked import skeletonize_chunked
    from fiberpipe.imaging._dask import connect
    from fiberpipe.imaging.trace_chunked import SliceSource
    from fiberpipe.stages._chunks import create_volume_dataset

    with open_checked(mask_path, "mask") as f:
        voxel_size = eval_list(f.attrs["voxel_size_m"])
        shape = tuple(int(n) for n in f["mask"].shape)
    src = SliceSource(mask_path, "mask")
    with connect(cfg.chunks.scheduler) as client:
        with artifact_writer(out, "skeleton", attrs={"voxel_size_m": voxel_size, "chunked": True},
                             config_sha256=config_sha256, inputs=input_hashes({"mask": Path(mask_path)})) as g:
            sk = create_volume_dataset(g, "skeleton", shape, bool, "1")
            rad = create_volume_dataset(g, "radius_vox", shape, np.float32, "voxel")
            try:
                info = skeletonize_chunked(src, sk, rad, slab=cfg.chunks.slices, halo=cfg.chunks.halo_vox,
                                           scheduler=client)
            except InputError as exc:
                if "raise the halo" in str(exc):
                    raise InputError(f"{exc} (chunks.halo_vox)", where=str(mask_path)) from None
                raise
            on = [rad[a:b][sk[a:b]] for a in range(0, shape[0], cfg.chunks.slices)
                  for b in [min(shape[0], a + cfg.chunks.slices)]]
    src.close()
    on = np.concatenate(on) if on else np.zeros(0, np.float32)
    return {"skeleton_voxels": int(info["skeleton_voxels"]), "median_radius_vox": float(np.median(on)) if on.size else 0.0,
            "chunked": True, "slabs": int(info["slabs"])}
