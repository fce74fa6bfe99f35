"""Stage ``segment``: volume file -> ``mask.h5`` (binary fiber mask, volume fraction)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fiberpipe.artifacts import write_volume
from fiberpipe.config import Config
from fiberpipe.errors import InputError
from fiberpipe.stages._common import input_hashes


def run_segment(cfg: Config, volume_path: Path, out: Path, *, voxel_size_m=None, config_sha256: str = "") -> dict:
    from fiberpipe.imaging.io import load_volume
    from fiberpipe.imaging.segment import segment
    from fiberpipe.stages._chunks import volume_source

    chunk_src = volume_source(cfg, volume_path)
    if chunk_src is not None:
        return run_segment_chunked(cfg, volume_path, out, chunk_src, voxel_size_m=voxel_size_m,
                                   config_sha256=config_sha256)
    inp = cfg.input
    volume, voxel_size, source = load_volume(
        volume_path,
        voxel_size_m=voxel_size_m if voxel_size_m is not None else inp.voxel_size,
        dataset=inp.dataset,
        shape=tuple(inp.shape) if inp.shape else None,
        dtype=inp.dtype,
    )
    s = cfg.segment
    try:
        mask, info = segment(volume, method=s.method, threshold=s.threshold, smooth_sigma_vox=s.smooth_sigma_vox,
                             min_object_vox=s.min_object_vox, fill_holes=s.fill_holes)
    except InputError as exc:
        if exc.where:
            raise
        raise InputError(str(exc), where=str(volume_path)) from None
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


def run_segment_chunked(cfg: Config, volume_path: Path, out: Path, chunk_src, *, voxel_size_m=None,
                        config_sha256: str = "") -> dict:
    """The segment stage slab by slab (``chunks``): the volume read ``chunks.slices`` slices at a
    time, the mask written into ``mask.h5`` as it is made (a chunked, compressed dataset), never
    whole in memory; the same artifact as the in-memory path."""
    from fiberpipe.artifacts import artifact_writer
    from fiberpipe.imaging._util import voxel_size_zyx
    from fiberpipe.imaging.segment_chunked import segment_chunked
    from fiberpipe.imaging._dask import connect
    from fiberpipe.stages._chunks import create_volume_dataset

    src, file_vs, source = chunk_src
    where = str(volume_path)
    vs = voxel_size_m if voxel_size_m is not None else cfg.input.voxel_size
    vs = vs if vs is not None else file_vs
    if vs is None:
        raise InputError("no voxel size in the file's metadata; give voxel_size", where=where)
    try:
        vs = voxel_size_zyx(vs)
    except ValueError as exc:
        raise InputError(str(exc), where=where) from None
    shape = src.shape
    s = cfg.segment
    attrs = {"voxel_size_m": [float(v) for v in vs], "voxel_size_source": str(source), "volume_shape": list(shape)}
    with connect(cfg.chunks.scheduler) as client:
        with artifact_writer(out, "mask", attrs=attrs, config_sha256=config_sha256,
                             inputs=input_hashes({"volume": Path(volume_path)})) as f:
            ds = create_volume_dataset(f, "mask", shape, bool, "1")
            info = segment_chunked(src, ds, slab=cfg.chunks.slices, method=s.method, threshold=s.threshold,
                                   smooth_sigma_vox=s.smooth_sigma_vox, min_object_vox=s.min_object_vox,
                                   fill_holes=s.fill_holes, scheduler=client)
            info = {k: (float(v) if isinstance(v, (np.floating, float)) else v) for k, v in info.items()}
            info["chunked"] = True
            f.attrs["segment"] = json.dumps(info)
    src.close()
    return {
        "shape": list(shape),
        "voxel_size_m": [float(v) for v in vs],
        "voxel_size_source": str(source),
        "volume_fraction": float(info["volume_fraction"]),
        "threshold": info.get("threshold"),
        "chunked": True,
        "slab_slices": int(cfg.chunks.slices),
    }
